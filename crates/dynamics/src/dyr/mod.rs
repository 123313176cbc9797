//! PSS/E dynamic data files (`.dyr`): read one unit's records into a
//! [`Unit`](crate::unit::Unit), write a unit back.
//!
//! A record is `IBUS 'MODEL' ID data… /`: the bus number, the model name, the machine
//! identifier, then the model's ICONs and CONs in the order PSS/E documents them. A record may
//! span lines and ends with `/`; whatever follows the `/` on its line is a comment. Fields are
//! separated by blanks or commas; strings may be quoted with `'` or `"`; Fortran exponents
//! (`1.5D-3`) are accepted.
//!
//! | model  | ICONs     | CONs (PSS/E order)                                                     |
//! |--------|-----------|------------------------------------------------------------------------|
//! | GENSAE | —         | T'd0 T''d0 T''q0 H D Xd Xq X'd X''d Xl S(1.0) S(1.2)                    |
//! | GENSAL | —         | T'd0 T''d0 T''q0 H D Xd Xq X'd X''d Xl S(1.0) S(1.2)                    |
//! | GENROU | —         | T'd0 T''d0 T'q0 T''q0 H D Xd Xq X'd X'q X''d Xl S(1.0) S(1.2)           |
//! | GENCLS | —         | H D                                                                    |
//! | SEXS   | —         | TA/TB TB K TE EMIN EMAX                                                |
//! | ST5B   | —         | TR TC1 TB1 TC2 TB2 KR VRMAX VRMIN T1 KC TUC1 TUB1 TUC2 TUB2 TOC1 TOB1 TOC2 TOB2 |
//! | IEEET1 | —         | TR KA TA VRMAX VRMIN KE TE KF TF SWITCH E1 SE(E1) E2 SE(E2)            |
//! | ESST1A | UEL VOS   | TR VIMAX VIMIN TC TB TC1 TB1 KA TA VAMAX VAMIN VRMAX VRMIN KC KF TF KLR ILR |
//! | STAB3  | —         | Tt TX1 TX2 KX VLIM                                                     |
//! | IEEEST | IC IB     | A1 A2 A3 A4 A5 A6 T1 T2 T3 T4 T5 T6 KS LSMAX LSMIN VCU VCL              |
//! | HYGOV  | —         | R r Tr Tf Tg VELM GMAX GMIN TW At Dturb qNL                             |
//!
//! What the `.dyr` does not hold comes from the power-flow machine record, given on the command
//! line or in a small side file ([`DyrBases`], TOML): `mbase` (MVA), `nominal_hz`, `zr` (ZSORCE
//! R: the armature resistance R_a on MBASE, 0 if not given, with a warning) and `zx` (ZSORCE X:
//! GENCLS's X'd; for the other machines PSS/E's X'', checked against the record's X''d).
//! PSS/E has a single X'': GENSAE and GENSAL read it into both X''d and X''q.
//!
//! ESST1A's ICONs UEL (where V_UEL enters: 1 summed at the error, 2 or 3 an HV gate) and VOS
//! (where V_S enters: 1 at the error, 2 after the regulator) are the block's options `uel`, `vos`.
//!
//! IEEEST's input code IC selects the signal its input port is wired to: 1 rotor speed
//! deviation (`speed`), 3 electrical power (`pe`), 5 terminal voltage (`v_term`); the other codes
//! (bus frequency, accelerating power, dV/dt) and a remote bus IB ≠ 0 have no signal in the
//! engine and are refused.
//!
//! Records of the selected unit whose model the engine lacks are reported by line as warnings
//! and left out; records of other units are counted in one warning. Malformed records (no `/`,
//! a bus number that is not an integer, a CON that is not a number, the wrong number of CONs, a
//! second model in the same role, parameters the model refuses) are [`DyrError`]s naming the
//! file and the line.
//!
//! Writing is checked ([`write_dyr_file`], `round_trip.rs`): the records are read back and
//! compared with the unit, parameter by parameter and, given events, by playing both back; a
//! `.dyr` that is not the unit (X''q ≠ X''d, a set-point offset, an extension block, …) is
//! refused with J of both unless a lossy write is asked for.
//!
//! Layout: `records.rs` holds the per-model CON tables, `bases.rs` the side file of bases,
//! `read.rs` the record syntax and the reader, `write.rs` the writer, `round_trip.rs` the checked
//! writer; this file the errors and warnings they share.

use std::fmt;
use std::path::PathBuf;

use crate::unit::UnitError;

mod bases;
mod read;
mod records;
mod round_trip;
mod write;

pub use bases::{resolve_bases, side_file, DyrBases, PartialBases};
pub use read::{parse_dyr, parse_records, read_dyr, DyrUnit, RawRecord};
pub use records::supported_models;
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
            DyrError::Selection { .. } => "selection",
            DyrError::Bases { .. } => "bases",
            DyrError::Unit { .. } => "unit",
        }
    }
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
