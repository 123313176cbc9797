//! Reading the inputs of a command: bundled data files, and the library's readers and
//! plausibility layer ([`itaipu_calib::job`]) with their warnings printed.

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::Finding;
use itaipu_dynamics::unit::Unit;

use itaipu_calib::job;

use crate::CliError;

/// Locates a bundled data file: `./data/…`, then next to the executable's repository
/// (`target/<profile>/../../data/…`), then `$ITAIPU_CALIB_DATA/…`.
pub fn bundled(rel: &str) -> Result<PathBuf, CliError> {
    let mut candidates = vec![PathBuf::from("data").join(rel)];
    if let Ok(exe) = std::env::current_exe() {
        if let Some(dir) = exe.parent() {
            candidates.push(dir.join("../../data").join(rel));
            candidates.push(dir.join("../data").join(rel));
        }
    }
    if let Some(d) = std::env::var_os("ITAIPU_CALIB_DATA") {
        candidates.push(PathBuf::from(d).join(rel));
    }
    candidates.iter().find(|p| p.is_file()).cloned().ok_or_else(|| {
        CliError::new(3, format!("bundled data file data/{rel} not found (run from the repository root, or set ITAIPU_CALIB_DATA)"))
    })
}

/// Reads an event file (exit code 3 on error).
pub fn load_event(path: &Path) -> Result<Event, CliError> {
    Ok(job::load_event(path)?)
}

/// Reads a unit file (exit code 4 on error): TOML, or a `.dyr` with the bases of
/// `<stem>.bases.toml` beside it (its warnings printed).
pub fn load_unit(path: &Path) -> Result<Unit, CliError> {
    let u = job::load_unit(path)?;
    for w in &u.warnings {
        eprintln!("warning: {w}");
    }
    Ok(u.unit)
}

/// The plausibility layer on events (against the unit's rating) and on the unit's parameters
/// ([`job::check_inputs`]): an error stops the run (exit 3, every error listed with file, line,
/// column and fix); warnings are printed and returned, for the outputs.
pub fn plausibility(
    events: &[&Event],
    unit: &Unit,
    unit_path: &Path,
) -> Result<Vec<Finding>, CliError> {
    let all = job::check_inputs(events, unit, Some(unit_path))?;
    for f in &all {
        eprintln!("warning: {f}");
    }
    Ok(all)
}

/// Writes `warnings.json` into `dir` when there are warnings.
pub fn write_warnings(dir: &Path, warnings: &[Finding]) -> Result<(), CliError> {
    job::write_warnings(dir, warnings)?;
    Ok(())
}
