//! `itaipu-calib diagram`: the dot text of a diagram file or of a unit's diagram blocks.

use std::path::PathBuf;

use itaipu_dynamics::unit_file::{read_diagram_or_unit, DiagramFile};

use crate::CliError;

#[derive(clap::Args, Debug)]
pub struct DiagramArgs {
    /// A diagram definition (TOML with [[block]] entries) or a unit file.
    file: PathBuf,
    /// In a unit file: the block (section) to draw, e.g. exciter.
    #[arg(long)]
    block: Option<String>,
    /// Write the dot text here instead of the standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// `itaipu-calib diagram`: the dot text of a diagram file or of a unit's diagram blocks.
pub fn cmd_diagram(a: &DiagramArgs) -> Result<(), CliError> {
    let mut dots = vec![];
    match read_diagram_or_unit(&a.file).map_err(|e| CliError::new(4, e.to_string()))? {
        DiagramFile::Unit(unit) => {
            for inst in unit.instances() {
                if a.block.as_deref().is_some_and(|b| b != inst.name) {
                    continue;
                }
                if let Some(d) = inst.block.diagram() {
                    dots.push(d.to_dot().replacen(
                        "digraph diagram",
                        &format!("digraph {}", inst.name),
                        1,
                    ));
                }
            }
            if dots.is_empty() {
                return Err(CliError::new(
                    2,
                    match &a.block {
                        Some(b) => format!("{}: no diagram block named '{b}'", a.file.display()),
                        None => format!("{}: the unit has no diagram block", a.file.display()),
                    },
                ));
            }
        }
        DiagramFile::Definition(d) => dots.push(d.to_dot()),
    }
    let out = dots.join("\n");
    match &a.out {
        Some(p) => {
            std::fs::write(p, out).map_err(|e| CliError::new(7, format!("{}: {e}", p.display())))?
        }
        None => print!("{out}"),
    }
    Ok(())
}
