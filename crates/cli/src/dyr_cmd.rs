//! `itaipu-calib dyr`: read a unit from a PSS/E `.dyr` into a unit file, or write a unit file
//! (e.g. `fit`'s `calibrated.toml`) as a `.dyr` and its side file of bases.

use std::path::{Path, PathBuf};

use clap::Subcommand;
use itaipu_dynamics::dyr::{
    read_dyr, resolve_bases, side_file, write_dyr, DyrError, DyrUnit, PartialBases,
};
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::{load_unit, CliError};

#[derive(clap::Args, Debug)]
pub struct DyrArgs {
    #[command(subcommand)]
    pub cmd: DyrCmd,
}

#[derive(Subcommand, Debug)]
pub enum DyrCmd {
    /// Read one unit's records (GENSAE, GENSAL, GENROU, GENCLS, SEXS, STAB3, IEEEST, HYGOV)
    /// into a unit file; other records are reported by line.
    Read(ReadArgs),
    /// Write a unit file as .dyr records and a side file of bases (<out stem>.bases.toml).
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
}

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
}

fn dyr_error(e: DyrError) -> CliError {
    CliError::new(4, e.to_string())
}

/// Reads a unit from a .dyr with bases from the options, the side file, or `<stem>.bases.toml`
/// (a missing base is a usage error, exit 2; a bad file exit 4).
pub fn load_dyr(
    path: &Path,
    bus: Option<i64>,
    id: Option<&str>,
    b: &BasesArgs,
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
    read_dyr(path, select, &bases).map_err(dyr_error)
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
            let out = r
                .out
                .clone()
                .unwrap_or_else(|| r.file.with_extension("toml"));
            refuse_existing(&out, r.force)?;
            let d = load_dyr(&r.file, r.bus, r.id.as_deref(), &r.bases)?;
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
            println!("wrote  {}", out.display());
        }
        DyrCmd::Write(w) => {
            let unit = load_unit(&w.unit)?;
            let out = w
                .out
                .clone()
                .unwrap_or_else(|| w.unit.with_extension("dyr"));
            let side = side_file(&out);
            refuse_existing(&out, w.force)?;
            refuse_existing(&side, w.force)?;
            let t = write_dyr(&unit, w.bus, &w.id);
            for m in &t.warnings {
                eprintln!("warning: {m}");
            }
            write(&out, &t.dyr)?;
            write(&side, &t.bases)?;
            println!("wrote  {}, {}", out.display(), side.display());
        }
    }
    Ok(())
}
