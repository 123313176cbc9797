//! The command line's errors: a message and its exit code. Every library error is converted
//! here, once ([`exit_code`] and the `From` conversions), so that a command only writes `?`.

use itaipu_calib::diagnose::DiagnoseError;
use itaipu_calib::error::{Error, ErrorClass};
use itaipu_calib::fit::FitError;
use itaipu_calib::request::{RequestError, Style, SynthFailure};
use itaipu_calib::spec::SpecError;
use itaipu_dynamics::dyr::DyrError;
use itaipu_dynamics::event::{Event, EventError};
use itaipu_dynamics::pmu_import::ImportError;
use itaipu_dynamics::simulate::SimError;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::UnitFileError;

/// An error with its exit code.
#[derive(Debug)]
pub struct CliError {
    pub code: u8,
    pub msg: String,
}

impl CliError {
    pub fn new(code: u8, msg: impl Into<String>) -> Self {
        Self {
            code,
            msg: msg.into(),
        }
    }
}

/// The exit code of each class of library error (also in `--help`, [`crate::EXIT_CODES`]): the
/// one place the command line turns an error into a number.
pub fn exit_code(class: ErrorClass) -> u8 {
    match class {
        ErrorClass::Usage => 2,
        ErrorClass::EventData => 3,
        ErrorClass::UnitModel | ErrorClass::Spec => 4,
        ErrorClass::Init => 5,
        ErrorClass::Simulation | ErrorClass::Calibration => 6,
        ErrorClass::Output => 7,
        // A signal's own code (143 for SIGTERM) is set where the signal is known.
        ErrorClass::Interrupted => 130,
        // EX_SOFTWARE (sysexits.h): an internal error.
        ErrorClass::Internal => 70,
    }
}

impl From<Error> for CliError {
    fn from(e: Error) -> Self {
        let code = exit_code(e.class());
        let msg = match &e {
            Error::Request(r) => r.message(Style::Cli),
            Error::Diagnose(d) => format!("diagnose: {d}"),
            _ => e.to_string(),
        };
        CliError::new(code, msg)
    }
}

/// `From<E> for CliError` for each library error, through [`Error`] (one mapping).
macro_rules! cli_error_from {
    ($($err:ty),* $(,)?) => {
        $(impl From<$err> for CliError {
            fn from(e: $err) -> Self {
                CliError::from(Error::from(e))
            }
        })*
    };
}

cli_error_from!(
    RequestError,
    EventError,
    UnitFileError,
    SpecError,
    SimError,
    DiagnoseError,
    FitError,
    DyrError,
    ImportError,
);

/// A synthesis failure, the unit file named: `hides` (the `--hide` options, when any) are
/// named after a failure of the final run.
pub fn synth_error(unit_path: &std::path::Path, e: SynthFailure, hides: &[String]) -> CliError {
    let path = unit_path.display();
    let code = exit_code(Error::from(e.clone()).class());
    match e {
        SynthFailure::Synth(e) if !hides.is_empty() => CliError::new(
            code,
            format!("{path}: {e} (with the hidden cause(s) {})", hides.join(" ")),
        ),
        SynthFailure::Hide { written, error } if code == 2 => {
            CliError::new(code, format!("--hide {written}: {error}"))
        }
        SynthFailure::Hide { written, error } => {
            CliError::new(code, format!("{path}: --hide {written}: {error}"))
        }
        e => CliError::new(code, format!("{path}: {e}")),
    }
}

/// A simulation error traced back to the data ([`itaipu_calib::job::explain`]): an
/// integration failure at time t names the samples around t, an initialisation failure the
/// operating point it was given.
pub fn explain_sim_error(e: SimError, event: &Event, unit: &Unit) -> CliError {
    CliError::from(itaipu_calib::job::explain(e, event, unit))
}
