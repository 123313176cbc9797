//! PSS/E dynamic data files (`.dyr`): read one unit's records into a
//! [`Unit`](crate::unit::Unit), write a unit back.
//!
//! A record is `IBUS 'MODEL' ID data… /`: the bus number, the model name, the machine
//! identifier, then the model's ICONs and CONs in the order PSS/E documents them. A record may
//! span lines and ends with `/`; whatever follows the `/` on its line is a comment. Fields are
//! separated by blanks or commas; strings may be quoted with `'` or `"`; Fortran exponents
//! (`1.5D-3`) are accepted.
//!
//! Which models have a record, and its layout (ICONs, CONs in PSS/E order, input codes), is
//! declared with each model ([`crate::registry::ModelInfo::dyr`], a [`DyrRecord`]):
//! `itaipu-calib models` and docs/model-library.md list them. The reader and writer here
//! interpret the layout and name no model.
//!
//! What the `.dyr` does not hold comes from the power-flow machine record, given on the command
//! line or in a small side file ([`DyrBases`], TOML): `mbase` (MVA), `nominal_hz`, `zr` (ZSORCE
//! R: the armature resistance R_a on MBASE, 0 if not given, with a warning) and `zx` (ZSORCE X:
//! GENCLS's X'd; for the other machines PSS/E's X'', checked against the record's X''d).
//! PSS/E has a single X'': GENSAE and GENSAL read it into both X''d and X''q.
//!
//! An ICON is a block option (ESST1A's UEL and VOS codes, PSS2A's M and N), an input-signal
//! code (IEEEST's IC, PSS2A's ICS1 and ICS2: 1 rotor speed deviation `speed`, 3 electrical
//! power `pe`, 5 terminal voltage `v_term`; bus frequency, accelerating power and dV/dt have no
//! signal in the engine and are refused), or a remote bus or second machine, where only 0 (the
//! unit's own) is supported.
//!
//! A record of the selected unit whose model the engine lacks is an error
//! ([`DyrError::Unsupported`]) naming the line, the model and what the unit would lack without
//! it, unless the read is asked to build the unit without it
//! ([`DyrReadOptions::skip_unsupported`]): then each is a warning and an entry of the unit's
//! [`crate::unit::Unit::lacks`], which the unit file keeps and every report repeats. Records of
//! other units are counted in one warning; [`list_units`] lists a file's units. Malformed records
//! (no `/`, a bus number that is not an integer, a CON that is not a number, the wrong number of
//! CONs, a second model in the same role, parameters the model refuses) are [`DyrError`]s naming
//! the file and the line.
//!
//! Writing is checked ([`write_dyr_file`], `round_trip.rs`): the records are read back and
//! compared with the unit, parameter by parameter and, given events, by playing both back; a
//! `.dyr` that is not the unit (X''q ≠ X''d, a set-point offset, an extension block, …) is
//! refused with J of both unless a lossy write is asked for.
//!
//! Layout: `layout.rs` holds the record layout a model declares, `bases.rs` the side file of bases,
//! `read.rs` the record syntax and the reader, `write.rs` the writer, `round_trip.rs` the checked
//! writer; this file the errors and warnings they share.

use std::fmt;
use std::path::PathBuf;

use crate::unit::UnitError;

mod bases;
mod layout;
mod read;
mod round_trip;
mod write;

pub use bases::{resolve_bases, side_file, DyrBases, PartialBases};
pub use layout::{
    DyrRecord, Icon, InputCode, MachineFields, Tie, ZsorceX, ONE_X_PP, STABILISER_INPUTS,
};
pub use read::{
    guess_role, list_units, parse_dyr, parse_dyr_with, parse_records, read_dyr, read_dyr_with,
    DyrReadOptions, DyrUnit, RawRecord, UnitListing,
};

/// The models the `.dyr` reader and writer know (those whose registry entry has a record).
pub fn supported_models() -> Vec<&'static str> {
    crate::registry::dyr_names()
}
pub use round_trip::{
    write_dyr_checked, write_dyr_file, DyrWrite, DyrWriteError, DyrWriteOptions, EventCheck, Loss,
    ROUND_TRIP_TOL_PU,
};
pub use write::{write_dyr, DyrText};

/// A bad `.dyr`, side file or unit. Messages name the file and the line or field.
#[derive(Debug, thiserror::Error)]
pub enum DyrError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A malformed record.
    #[error("{} line {line}: {msg}", path.display())]
    Syntax {
        path: PathBuf,
        line: usize,
        msg: String,
    },
    /// A record of the selected unit that cannot be used (CON count, refused values).
    #[error("{} line {line}: {model}: {msg}", path.display())]
    Record {
        path: PathBuf,
        line: usize,
        model: String,
        msg: String,
    },
    /// Records of the selected unit whose models the engine lacks, `(line, model, what the unit
    /// would lack without it)`: refused unless the unit is to be built without them
    /// ([`DyrReadOptions::skip_unsupported`]).
    #[error("{}", unsupported_message(path, *bus, id, records))]
    Unsupported {
        path: PathBuf,
        bus: i64,
        id: String,
        records: Vec<(usize, String, String)>,
    },
    /// The unit asked for is not in the file, or none was asked for and the file holds several.
    #[error("{}: {msg}", path.display())]
    Selection { path: PathBuf, msg: String },
    /// A base value missing or wrong (side file or command line).
    #[error("{}: {field}: {msg}", path.display())]
    Bases {
        path: PathBuf,
        field: String,
        msg: String,
    },
    /// The blocks do not make a unit.
    #[error("{}: {source}", path.display())]
    Unit { path: PathBuf, source: UnitError },
}

impl DyrError {
    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            DyrError::Io { .. } => "io",
            DyrError::Syntax { .. } => "syntax",
            DyrError::Record { .. } => "record",
            DyrError::Unsupported { .. } => "unsupported",
            DyrError::Selection { .. } => "selection",
            DyrError::Bases { .. } => "bases",
            DyrError::Unit { .. } => "unit",
        }
    }
}

fn unsupported_message(
    path: &std::path::Path,
    bus: i64,
    id: &str,
    records: &[(usize, String, String)],
) -> String {
    let each: Vec<String> = records
        .iter()
        .map(|(line, model, lacks)| {
            format!(
                "{} line {line}: {model} (bus {bus}, id '{id}') is not supported; without it the unit would lack {lacks}",
                path.display()
            )
        })
        .collect();
    format!(
        "{}. Nothing read: a unit without {} is not the unit of the file (models with a record: {}); build it without on purpose with skip_unsupported (the command line's --skip-unsupported), and every report will say what it lacks",
        each.join("; "),
        if records.len() == 1 { "it" } else { "them" },
        supported_models().join(", ")
    )
}

/// Something the reader or writer could not carry over, or found implausible.
#[derive(Debug, Clone, PartialEq)]
pub struct DyrWarning {
    /// The file and line it is about (`None` for the whole file or a unit being written).
    pub path: Option<PathBuf>,
    pub line: Option<usize>,
    pub msg: String,
}

impl fmt::Display for DyrWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.path, self.line) {
            (Some(p), Some(l)) => write!(f, "{} line {l}: {}", p.display(), self.msg),
            (Some(p), None) => write!(f, "{}: {}", p.display(), self.msg),
            _ => write!(f, "{}", self.msg),
        }
    }
}
