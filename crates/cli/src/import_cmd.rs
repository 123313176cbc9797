//! `itaipu-calib import`: a PMU export (C37.118-style CSV) or a COMTRADE recording into an
//! event folder (`event.toml`, the canonical CSV, `import.json` with gaps and dropouts).

use std::path::PathBuf;

use itaipu_dynamics::pmu_import::{import, write_event_folder, ImportError, ImportOptions};

use crate::{prepare_out, CliError};

#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The recording: a CSV export (C37.118 style) or a COMTRADE .cfg (its .dat beside it).
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// MVA base of the event's P and Q.
    #[arg(long, value_name = "MVA")]
    pub system_mva: f64,
    /// Nominal frequency [Hz].
    #[arg(long, value_name = "HZ")]
    pub nominal_hz: f64,
    /// Rated line-to-line voltage [kV] (for voltages in V or kV).
    #[arg(long, value_name = "KV")]
    pub v_base_kv: Option<f64>,
    /// MVA base of channels given in pu (default: --system-mva).
    #[arg(long, value_name = "MVA")]
    pub pu_base_mva: Option<f64>,
    /// The voltage phasor is line-to-line (V_ab), not phase-to-neutral.
    #[arg(long)]
    pub line_voltage: bool,
    /// The current is measured flowing into the machine (P and Q are negated).
    #[arg(long)]
    pub current_into_machine: bool,
    /// Resample to this rate [samples/s] (default: keep the PMU's time stamps).
    #[arg(long, value_name = "HZ")]
    pub rate: Option<f64>,
    /// Read a column or channel as one of the known names, e.g. --map v_mag_kv=STN.VPM
    /// (repeatable).
    #[arg(long, value_name = "NAME=COLUMN")]
    pub map: Vec<String>,
    /// Event name (default: the file stem).
    #[arg(long)]
    pub name: Option<String>,
    /// Output folder (default: out/import-<name>, or a new numbered folder beside it).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    pub force: bool,
    /// Refuse (exit 3) a recording whose data file holds fewer samples than its header
    /// declares (a COMTRADE .dat cut short); without, it is imported with a warning that
    /// import.json, event.toml and every later report repeat.
    #[arg(long)]
    pub refuse_truncated: bool,
}

/// Exit code of an import error: 2 for an option, 3 for the data.
pub fn import_error(e: ImportError) -> CliError {
    let code = if matches!(e, ImportError::Options { .. }) {
        2
    } else {
        3
    };
    CliError::new(code, e.to_string())
}

pub fn cmd_import(a: &ImportArgs) -> Result<(), CliError> {
    let mut map = vec![];
    for m in &a.map {
        let (n, c) = m
            .split_once('=')
            .filter(|(n, c)| !n.trim().is_empty() && !c.trim().is_empty())
            .ok_or_else(|| CliError::new(2, format!("--map {m}: expected NAME=COLUMN")))?;
        map.push((n.trim().to_string(), c.trim().to_string()));
    }
    let opts = ImportOptions {
        name: a.name.clone(),
        system_mva: a.system_mva,
        nominal_hz: a.nominal_hz,
        v_base_kv: a.v_base_kv,
        pu_base_mva: a.pu_base_mva,
        line_voltage: a.line_voltage,
        current_into_machine: a.current_into_machine,
        rate_hz: a.rate,
        map,
        refuse_truncated: a.refuse_truncated,
    };
    crate::check_out(a.out.as_deref(), a.force)?;
    let (event, report) = import(&a.file, &opts).map_err(import_error)?;
    // Written into a temporary folder beside the target, renamed into place when complete.
    let staging = prepare_out(a.out.as_deref(), &format!("import-{}", event.name), a.force)?;
    let written = write_event_folder(&event, &report, staging.path())
        .map_err(|e| CliError::new(7, e.to_string()))?;
    let target = crate::output::commit(staging, None)?;
    let written: Vec<std::path::PathBuf> = written
        .iter()
        .filter_map(|p| p.file_name())
        .map(|f| target.join(f))
        .collect();
    print!("{report}");
    println!(
        "event  {}: {} samples, {:.3}-{:.3} s, system base {} MVA, {} Hz",
        event.name,
        event.record.len(),
        event.record.start_s(),
        event.record.end_s(),
        event.system_mva,
        event.nominal_hz
    );
    println!(
        "wrote  {}",
        written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
