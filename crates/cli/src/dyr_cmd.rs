//! `itaipu-calib dyr`: read a unit from a PSS/E `.dyr` into a unit file, or write a unit file
//! (e.g. `fit`'s `calibrated.toml`) as a `.dyr` and its side file of bases, only if the `.dyr`
//! read back is the unit (the library's checked writer, [`write_dyr_file`]) or `--lossy`.

use std::path::{Path, PathBuf};

use clap::Subcommand;
use itaipu_dynamics::dyr::{
    list_units, read_dyr_with, resolve_bases, side_file, write_dyr_file, DyrError, DyrReadOptions,
    DyrUnit, DyrWriteError, DyrWriteOptions, PartialBases,
};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{self, Severity};
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::{bundled, explain_sim_error, load_event, load_unit, CliError};

#[derive(clap::Args, Debug)]
pub struct DyrArgs {
    #[command(subcommand)]
    pub cmd: DyrCmd,
}

#[derive(Subcommand, Debug)]
pub enum DyrCmd {
    /// Read one unit's records into a unit file (`itaipu-calib models` lists the models with a
    /// record). A record of a model the engine lacks is refused (exit 4, nothing written)
    /// naming the line, the model and what the unit would lack, unless --skip-unsupported. A
    /// file of several units: --list lists them, --bus and --id choose one.
    #[command(after_help = READ_EXIT_CODES)]
    Read(ReadArgs),
    /// Write a unit file as .dyr records and a side file of bases (<out stem>.bases.toml), only
    /// if the .dyr read back is the unit: played back on the event(s) within 1e-6 pu of the
    /// unit (parameters compared when there is no event). Otherwise refused (exit 4) with J of
    /// both and what the .dyr cannot hold, unless --lossy.
    #[command(after_help = WRITE_EXIT_CODES)]
    Write(WriteArgs),
}

/// The values a .dyr does not hold (the power-flow machine record).
#[derive(clap::Args, Debug, Default)]
pub struct BasesArgs {
    /// Side file (TOML: mbase, nominal_hz, zr, zx, name). Default: <dyr stem>.bases.toml beside
    /// the .dyr, if it exists.
    #[arg(long, value_name = "FILE")]
    pub bases: Option<PathBuf>,
    /// MBASE [MVA] (overrides the side file).
    #[arg(long)]
    pub mbase: Option<f64>,
    /// Nominal frequency [Hz] (overrides the side file).
    #[arg(long)]
    pub nominal_hz: Option<f64>,
    /// ZSORCE R: armature resistance, pu on MBASE (overrides the side file).
    #[arg(long)]
    pub zr: Option<f64>,
    /// ZSORCE X, pu on MBASE (GENCLS: X'd).
    #[arg(long)]
    pub zx: Option<f64>,
}

#[derive(clap::Args, Debug)]
pub struct ReadArgs {
    /// The .dyr file.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Bus number of the unit (needed when the file holds several machines).
    #[arg(long)]
    pub bus: Option<i64>,
    /// Machine id of the unit (default "1" with --bus).
    #[arg(long)]
    pub id: Option<String>,
    #[command(flatten)]
    pub bases: BasesArgs,
    /// Unit file to write (default: <dyr stem>.toml beside the .dyr).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Overwrite an existing --out file.
    #[arg(long)]
    pub force: bool,
    /// List the units of the file (bus, machine id, records, which are supported) and write
    /// nothing.
    #[arg(long)]
    pub list: bool,
    /// Build the unit without the records of models the engine lacks (each a warning, kept in
    /// the unit file as `lacks` and repeated by every report on the unit). Without it such a
    /// record is refused.
    #[arg(long)]
    pub skip_unsupported: bool,
}

/// `dyr read`'s exit codes.
const READ_EXIT_CODES: &str = "Exit codes: 0 read (or listed), 2 usage error (a base missing, several units and none chosen), 4 bad .dyr: a malformed record, or a record of a model the engine lacks (nothing written; --skip-unsupported builds the unit without it), 7 the output file exists (without --force) or cannot be written.";

#[derive(clap::Args, Debug)]
pub struct WriteArgs {
    /// The unit file (TOML), e.g. a fit's calibrated.toml.
    #[arg(value_name = "FILE")]
    pub unit: PathBuf,
    /// Bus number to write.
    #[arg(long, default_value_t = 1)]
    pub bus: i64,
    /// Machine id to write.
    #[arg(long, default_value = "1")]
    pub id: String,
    /// The .dyr to write (default: <unit stem>.dyr beside the unit file); the bases go to
    /// <stem>.bases.toml beside it.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Overwrite existing files.
    #[arg(long)]
    pub force: bool,
    /// Event(s) to play the unit and the written .dyr back on (repeatable). Default: the events
    /// of the fit whose folder holds the unit file (its manifest's command line), else
    /// event.toml beside the unit file; with none, the parameters are compared.
    #[arg(long, value_name = "E.toml")]
    pub event: Vec<PathBuf>,
    /// Write even when the .dyr read back is not the unit (a warning quotes J of both and what
    /// is lost).
    #[arg(long)]
    pub lossy: bool,
}

/// `dyr write`'s exit codes.
const WRITE_EXIT_CODES: &str = "Exit codes: 0 written, 2 usage error, 3 bad event data, 4 bad \
unit file, or a .dyr that would not be the unit (nothing written; --lossy writes it), 5 / 6 the \
unit does not initialise / integrate on an event, 7 an output file exists (without --force) or \
cannot be written.";

fn dyr_error(e: DyrError) -> CliError {
    CliError::new(4, e.to_string())
}

/// Reads a unit from a .dyr with bases from the options, the side file, or `<stem>.bases.toml`
/// (a missing base is a usage error, exit 2; a bad file or a record of a model the engine lacks
/// without `skip_unsupported`, exit 4; several units and none chosen, exit 2 with the list).
pub fn load_dyr(
    path: &Path,
    bus: Option<i64>,
    id: Option<&str>,
    b: &BasesArgs,
    skip_unsupported: bool,
) -> Result<DyrUnit, CliError> {
    let over = PartialBases {
        mbase: b.mbase,
        nominal_hz: b.nominal_hz,
        zr: b.zr,
        zx: b.zx,
        name: None,
    };
    let bases = resolve_bases(path, b.bases.as_deref(), &over).map_err(|e| match &e {
        DyrError::Bases { path: p, .. } if p == path => {
            CliError::new(2, format!("{e} (give --mbase and --nominal-hz, or a side file with --bases or beside the .dyr as {})", side_file(path).display()))
        }
        _ => dyr_error(e),
    })?;
    let select = match (bus, id) {
        (Some(b), i) => Some((b, i.unwrap_or("1"))),
        (None, Some(_)) => return Err(CliError::new(2, "--id needs --bus")),
        (None, None) => None,
    };
    let opts = DyrReadOptions {
        select,
        skip_unsupported,
    };
    read_dyr_with(path, &bases, &opts).map_err(|e| match &e {
        DyrError::Selection { .. } if select.is_none() => {
            let listing = std::fs::read_to_string(path)
                .ok()
                .and_then(|t| list_units(&t, path).ok())
                .map(|u| u.iter().map(|l| format!("\n  {l}")).collect::<String>())
                .unwrap_or_default();
            CliError::new(2, format!("{e}: give --bus and --id{listing}"))
        }
        _ => dyr_error(e),
    })
}

fn refuse_existing(p: &Path, force: bool) -> Result<(), CliError> {
    if p.exists() && !force {
        return Err(CliError::new(
            7,
            format!(
                "{} exists; refusing to overwrite (use --force, or another --out)",
                p.display()
            ),
        ));
    }
    Ok(())
}

fn write(p: &Path, text: &str) -> Result<(), CliError> {
    std::fs::write(p, text)
        .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))
}

pub fn cmd_dyr(a: &DyrArgs) -> Result<(), CliError> {
    match &a.cmd {
        DyrCmd::Read(r) => {
            if r.list {
                let text = std::fs::read_to_string(&r.file).map_err(|e| {
                    CliError::new(4, format!("{}: cannot read: {e}", r.file.display()))
                })?;
                for u in list_units(&text, &r.file).map_err(dyr_error)? {
                    println!("{u}");
                }
                return Ok(());
            }
            let out = r
                .out
                .clone()
                .unwrap_or_else(|| r.file.with_extension("toml"));
            refuse_existing(&out, r.force)?;
            let d = load_dyr(
                &r.file,
                r.bus,
                r.id.as_deref(),
                &r.bases,
                r.skip_unsupported,
            )?;
            for w in &d.warnings {
                eprintln!("warning: {w}");
            }
            write(&out, &unit_to_toml(&d.unit))?;
            println!(
                "read   {} bus {} id '{}': {} (lines {}), machine base {} MVA, {} Hz",
                r.file.display(),
                d.bus,
                d.id,
                d.used
                    .iter()
                    .map(|u| u.1.as_str())
                    .collect::<Vec<_>>()
                    .join(" + "),
                d.used
                    .iter()
                    .map(|u| u.0.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                d.unit.machine_mva,
                d.unit.nominal_hz
            );
            // The plausibility checks `simulate`, `fit` and `diagnose` run on the unit.
            for f in plausibility::check_unit(&d.unit, &r.file) {
                eprintln!("warning: {f}");
            }
            println!("wrote  {}", out.display());
        }
        DyrCmd::Write(w) => cmd_write(w)?,
    }
    Ok(())
}

/// The events `dyr write` compares on, and where they come from: `--event`, else the events of
/// the fit whose folder holds the unit file, else `event.toml` beside the unit file.
fn write_events(w: &WriteArgs) -> Result<(Vec<Event>, String), CliError> {
    if !w.event.is_empty() {
        let ev = w
            .event
            .iter()
            .map(|p| load_event(p))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok((ev, "--event".into()));
    }
    if let Some((dir, paths)) = fit_events(&w.unit) {
        let names = fit_event_names(&dir);
        let mut found = vec![];
        let mut missing = vec![];
        for p in paths {
            match load_event(&p) {
                Ok(e) if names.is_empty() || names.contains(&e.name) => found.push(e),
                _ => missing.push(p.display().to_string()),
            }
        }
        if !missing.is_empty() {
            eprintln!(
                "note: event(s) {} of the fit in {} not found or not the fit's (give --event)",
                missing.join(", "),
                dir.display()
            );
        }
        if !found.is_empty() {
            return Ok((found, format!("the fit's, from {}", dir.display())));
        }
    }
    let beside = w.unit.with_file_name("event.toml");
    if beside.is_file() {
        let e = load_event(&beside)?;
        return Ok((vec![e], format!("{} beside the unit", beside.display())));
    }
    Ok((vec![], String::new()))
}

/// The fit folder holding `unit` (the folder itself or, for a stage's `unit.toml`, its parent)
/// and the event files its manifest's command line named (`fit` without `--event`: the bundled
/// event, as `fit` does).
fn fit_events(unit: &Path) -> Option<(PathBuf, Vec<PathBuf>)> {
    let dir = match unit.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    for d in [Some(dir), dir.parent()].into_iter().flatten() {
        let Ok(text) = std::fs::read_to_string(d.join("manifest.json")) else {
            continue;
        };
        let Ok(m) = serde_json::from_str::<serde_json::Value>(&text) else {
            continue;
        };
        let cmd: Vec<&str> = m["command"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_str()).collect())
            .unwrap_or_default();
        if cmd.get(1) != Some(&"fit") {
            continue;
        }
        let mut paths = vec![];
        let mut it = cmd.iter().skip(2);
        while let Some(a) = it.next() {
            if *a == "--event" {
                if let Some(p) = it.next() {
                    paths.push(PathBuf::from(p));
                }
            } else if let Some(p) = a.strip_prefix("--event=") {
                paths.push(PathBuf::from(p));
            }
        }
        if paths.is_empty() {
            paths.extend(bundled("itaipu/event.toml").ok());
        }
        return Some((d.to_path_buf(), paths));
    }
    None
}

/// The names of the events a fit folder's `report.json` lists (empty if unreadable).
fn fit_event_names(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("report.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|r| {
            r["events"].as_array().map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(String::from))
                    .collect()
            })
        })
        .unwrap_or_default()
}

fn cmd_write(w: &WriteArgs) -> Result<(), CliError> {
    let unit = load_unit(&w.unit)?;
    let out = w
        .out
        .clone()
        .unwrap_or_else(|| w.unit.with_extension("dyr"));
    let side = side_file(&out);
    // Existing outputs are refused before anything is computed.
    refuse_existing(&out, w.force)?;
    refuse_existing(&side, w.force)?;
    let (events, source) = write_events(w)?;
    let mut findings = vec![];
    for e in &events {
        findings.extend(plausibility::check_event(e, Some(unit.machine_mva)));
    }
    let errors: Vec<String> = findings
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
    for f in &findings {
        eprintln!("warning: {f}");
    }
    if events.is_empty() {
        eprintln!(
            "note: no event to play back (give --event E.toml): the unit and the .dyr read back are compared parameter by parameter"
        );
    } else {
        println!(
            "check  write -> read -> simulate on {} ({source})",
            events
                .iter()
                .map(|e| e.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let opts = DyrWriteOptions {
        bus: w.bus,
        id: w.id.clone(),
        lossy: w.lossy,
        force: w.force,
        ..Default::default()
    };
    let r = write_dyr_file(&unit, &out, &events, &opts).map_err(|e| match e {
        DyrWriteError::Exists { .. } | DyrWriteError::Io { .. } => CliError::new(7, e.to_string()),
        DyrWriteError::Unfaithful { ref report, .. } => {
            // The plausibility of what would have been written, too.
            for f in &report.findings {
                eprintln!("warning: {f}");
            }
            CliError::new(
                4,
                format!(
                    "{e}. Nothing written: --lossy writes it anyway; or make the unit one the .dyr holds (X''q: fit again with tie = {{ \"machine.x_q_pp\" = \"machine.x_d_pp\" }} in the stage)"
                ),
            )
        }
        DyrWriteError::Simulation { event, source } => {
            match events.iter().find(|x| x.name == event) {
                Some(ev) => explain_sim_error(source, ev, &unit),
                None => CliError::from(source),
            }
        }
        DyrWriteError::ReadBack(_) => CliError::new(4, e.to_string()),
    })?;
    // The plausibility warnings reading the .dyr will give, now.
    for f in &r.findings {
        eprintln!("warning: {f}");
    }
    for n in &r.notes {
        eprintln!("warning: {n}");
    }
    for l in &r.lost {
        eprintln!("warning: not in the .dyr: {l}");
    }
    if r.faithful() {
        if r.events.is_empty() {
            println!("check  every parameter, option, wiring and block reads back unchanged");
        }
        for c in &r.events {
            println!("check  {c}: equal within {:e} pu", r.tolerance_pu);
        }
    } else {
        eprintln!(
            "warning: --lossy: written, but the .dyr read back is not the unit: {}",
            r.comparison()
        );
    }
    println!("wrote  {}, {}", out.display(), side.display());
    Ok(())
}
