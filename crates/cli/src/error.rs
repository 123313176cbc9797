//! The command line's errors: a message and its exit code. Every library error is converted
//! here, once ([`exit_code`] and the `From` conversions), so that a command only writes `?`.

use itaipu_calib::diagnose::DiagnoseError;
use itaipu_calib::request::{RequestError, Style, SynthFailure};
use itaipu_calib::spec::SpecError;
use itaipu_dynamics::event::{Event, EventError};
use itaipu_dynamics::plausibility;
use itaipu_dynamics::simulate::SimError;
use itaipu_dynamics::synthetic::SynthError;
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

/// A library error the command line maps to an exit code.
pub enum LibError<'a> {
    /// A rejected option: 2.
    Request(&'a RequestError),
    /// Bad event data: 3.
    Event(&'a EventError),
    /// Bad unit model: 4.
    Unit(&'a UnitFileError),
    /// Bad calibration spec: 4.
    Spec(&'a SpecError),
    /// Initialisation (5) or integration (6) failure.
    Sim(&'a SimError),
    /// A synthetic event that could not be made: 5, or 6 for an integration failure.
    Synth(&'a SynthError),
    /// A diagnosis that cannot run: 6, or 130 after a cancel.
    Diagnose(&'a DiagnoseError),
}

/// The exit code of each library error (also in `--help`, [`crate::EXIT_CODES`]).
pub fn exit_code(e: LibError<'_>) -> u8 {
    match e {
        LibError::Request(_) => 2,
        LibError::Event(_) => 3,
        LibError::Unit(_) | LibError::Spec(_) => 4,
        LibError::Sim(SimError::Init(_) | SimError::Frequency { .. }) => 5,
        LibError::Sim(SimError::Solve(_)) => 6,
        LibError::Synth(SynthError::Sim(SimError::Solve(_))) => 6,
        LibError::Synth(_) => 5,
        // The command line sets no cancel flag (a signal ends the process, exit 130/143).
        LibError::Diagnose(DiagnoseError::Interrupted { .. }) => 130,
        LibError::Diagnose(_) => 6,
    }
}

impl From<RequestError> for CliError {
    fn from(e: RequestError) -> Self {
        CliError::new(exit_code(LibError::Request(&e)), e.message(Style::Cli))
    }
}

/// `From<E> for CliError` for the library errors whose message is their `Display` text.
macro_rules! cli_error_from {
    ($($err:ty => $kind:ident),* $(,)?) => {
        $(impl From<$err> for CliError {
            fn from(e: $err) -> Self {
                CliError::new(exit_code(LibError::$kind(&e)), e.to_string())
            }
        })*
    };
}

cli_error_from!(
    EventError => Event,
    UnitFileError => Unit,
    SpecError => Spec,
    SimError => Sim,
);

impl From<DiagnoseError> for CliError {
    fn from(e: DiagnoseError) -> Self {
        CliError::new(exit_code(LibError::Diagnose(&e)), format!("diagnose: {e}"))
    }
}

/// A synthesis failure, the unit file named: `hides` (the `--hide` options, when any) are
/// named after a failure of the final run.
pub fn synth_error(unit_path: &std::path::Path, e: SynthFailure, hides: &[String]) -> CliError {
    let path = unit_path.display();
    match e {
        SynthFailure::Probe(e) => {
            CliError::new(exit_code(LibError::Synth(&e)), format!("{path}: {e}"))
        }
        SynthFailure::Synth(e) => {
            let err = CliError::new(exit_code(LibError::Synth(&e)), format!("{path}: {e}"));
            if hides.is_empty() {
                err
            } else {
                CliError::new(
                    err.code,
                    format!("{} (with the hidden cause(s) {})", err.msg, hides.join(" ")),
                )
            }
        }
        e @ SynthFailure::Context(_) => CliError::new(5, format!("{path}: {e}")),
        SynthFailure::Hide {
            written,
            error: itaipu_calib::diagnose::catalog::HideError::Build(msg),
        } => CliError::new(4, format!("{path}: --hide {written}: {msg}")),
        SynthFailure::Hide { written, error } => {
            CliError::new(2, format!("--hide {written}: {error}"))
        }
    }
}

/// A simulation error traced back to the data: an integration failure at time t names the
/// samples around t, an initialisation failure the operating point it was given.
pub fn explain_sim_error(e: SimError, event: &Event, unit: &Unit) -> CliError {
    use itaipu_dynamics::integrate::SolveError;
    let mut err = CliError::from(e.clone());
    let t = match &e {
        SimError::Solve(
            SolveError::NonFinite { t, .. }
            | SolveError::StepUnderflow { t, .. }
            | SolveError::TooManySteps { t, .. }
            | SolveError::EventLoop { t },
        ) => Some(*t),
        _ => None,
    };
    match (&e, t) {
        (_, Some(t)) => {
            err.msg = format!("{}; {}", err.msg, plausibility::locate_time(event, t));
        }
        (SimError::Init(_), None) => {
            err.msg = format!(
                "{}; {}",
                err.msg,
                plausibility::describe_operating_point(event, unit.machine_mva)
            );
        }
        _ => {}
    }
    err
}
