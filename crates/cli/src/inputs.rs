//! Reading the inputs of a command: bundled data files, events and units (exit codes 3 and 4),
//! the plausibility layer, and its warnings file.

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{self, Finding, Severity};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

use crate::{dyr_cmd, output, CliError};

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
    Ok(Event::from_toml_file(path)?)
}

/// Reads a unit file (exit code 4 on error). A `.dyr` is read with the bases of
/// `<stem>.bases.toml` beside it (its warnings printed).
pub fn load_unit(path: &Path) -> Result<Unit, CliError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dyr"))
    {
        let d = dyr_cmd::load_dyr(path, None, None, &dyr_cmd::BasesArgs::default())?;
        for w in &d.warnings {
            eprintln!("warning: {w}");
        }
        return Ok(d.unit);
    }
    Ok(read_unit(path)?)
}

/// The plausibility layer ([`itaipu_dynamics::plausibility`]) on events (against the unit's
/// rating) and on the unit's parameters: an error stops the run (exit 3, every error listed
/// with file, line, column and fix); warnings are printed and returned, for the outputs.
pub fn plausibility(
    events: &[&Event],
    unit: &Unit,
    unit_path: &Path,
) -> Result<Vec<Finding>, CliError> {
    let mut all = vec![];
    for e in events {
        all.extend(plausibility::check_event(e, Some(unit.machine_mva)));
    }
    all.extend(plausibility::check_unit(unit, unit_path));
    let errors: Vec<String> = all
        .iter()
        .filter(|f| f.severity == Severity::Error)
        .map(|f| f.to_string())
        .collect();
    if !errors.is_empty() {
        return Err(CliError::new(
            3,
            format!("implausible data:\n  {}", errors.join("\n  ")),
        ));
    }
    for f in &all {
        eprintln!("warning: {f}");
    }
    Ok(all)
}

/// Writes `warnings.json` into `dir` when there are warnings.
pub fn write_warnings(dir: &Path, warnings: &[Finding]) -> Result<(), CliError> {
    if warnings.is_empty() {
        return Ok(());
    }
    let text =
        serde_json::to_string_pretty(warnings).map_err(|e| CliError::new(7, e.to_string()))?;
    output::write_synced(&dir.join("warnings.json"), text.as_bytes())
}
