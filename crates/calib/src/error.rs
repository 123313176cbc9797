//! The crate's one error type, [`Error`]: every error of the crate, and every error of the engine
//! (`itaipu-dynamics`) that reaches a fit or a diagnosis, converts into it (`?` or `From`), so
//! that a front end maps one type, once. [`Error::kind`] names the source and the variant
//! (`"fit.stage"`, `"diagnose.interrupted"`, …); [`Error::class`] says what kind of failure it
//! is for the user ([`ErrorClass`]), which each front end turns into its own form: the command
//! line into an exit code, Python into an exception class.

use crate::bounds::BoundError;
use crate::diagnose::catalog::{CauseError, HideError};
use crate::diagnose::trial::TrialError;
use crate::diagnose::user_cause::UserCauseError;
use crate::diagnose::DiagnoseError;
use crate::fit::FitError;
use crate::practice::PracticeError;
use crate::problem::ProblemError;
use crate::pso::PsoError;
use crate::request::{RequestError, SynthFailure};
use crate::spec::SpecError;
use itaipu_dynamics::dyr::DyrError;
use itaipu_dynamics::event::EventError;
use itaipu_dynamics::pmu_import::ImportError;
use itaipu_dynamics::simulate::SimError;
use itaipu_dynamics::synthetic::SynthError;
use itaipu_dynamics::unit::UnitError;
use itaipu_dynamics::unit_file::UnitFileError;

/// What kind of failure an error is, for the user: the one thing a front end needs to choose
/// its exit code or exception class. Every [`Error`] has exactly one ([`Error::class`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorClass {
    /// A rejected option or argument (the request itself is wrong).
    Usage,
    /// Bad or implausible event data: the event file, its record, an import.
    EventData,
    /// A bad unit model (unit file, `.dyr`, a parameter edit the model refuses).
    UnitModel,
    /// A bad calibration spec or user cause file.
    Spec,
    /// The model cannot initialise at the measured operating point (or the unit and the event
    /// have different nominal frequencies).
    Init,
    /// The time integration failed (the unit as given, not a candidate: candidates that fail
    /// are penalised and never stop a run).
    Simulation,
    /// A fit or diagnosis that cannot go on for another reason.
    Calibration,
    /// An output could not be written, or would overwrite something.
    Output,
    /// Stopped by the user (a signal, Ctrl-C, a cancel flag).
    Interrupted,
    /// A bug: an invariant of the code was broken (e.g. a caught panic). Never the user's fault.
    Internal,
}

impl ErrorClass {
    /// Short stable name (`"usage"`, `"event_data"`, …).
    pub fn name(self) -> &'static str {
        match self {
            ErrorClass::Usage => "usage",
            ErrorClass::EventData => "event_data",
            ErrorClass::UnitModel => "unit_model",
            ErrorClass::Spec => "spec",
            ErrorClass::Init => "init",
            ErrorClass::Simulation => "simulation",
            ErrorClass::Calibration => "calibration",
            ErrorClass::Output => "output",
            ErrorClass::Interrupted => "interrupted",
            ErrorClass::Internal => "internal",
        }
    }

    /// The class of an engine simulation error.
    pub fn of_sim(e: &SimError) -> Self {
        match e {
            SimError::Init(_) | SimError::Frequency { .. } | SimError::ModeInit { .. } => {
                ErrorClass::Init
            }
            SimError::Solve(_) | SimError::ModeSolve { .. } => ErrorClass::Simulation,
            SimError::NoAngle { .. } | SimError::MissingChannel { .. } => ErrorClass::EventData,
            SimError::ModeSetup { .. } => ErrorClass::UnitModel,
        }
    }

    /// The class of a problem error (a simulation of the unit as given, an event window).
    pub fn of_problem(e: &ProblemError) -> Self {
        match e {
            ProblemError::Simulation { error, .. } => Self::of_sim(error),
            ProblemError::Window { .. } | ProblemError::Filter { .. } => ErrorClass::EventData,
            ProblemError::Diverged { .. } => ErrorClass::Simulation,
            ProblemError::Interrupted => ErrorClass::Interrupted,
        }
    }
}

/// Any error of the crate or of the engine (the message is the source's own).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Request(#[from] RequestError),
    #[error(transparent)]
    Event(#[from] EventError),
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error(transparent)]
    UnitFile(#[from] UnitFileError),
    #[error(transparent)]
    Dyr(#[from] DyrError),
    #[error(transparent)]
    Unit(#[from] UnitError),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Synth(#[from] SynthFailure),
    #[error(transparent)]
    Spec(#[from] SpecError),
    #[error(transparent)]
    Bound(#[from] BoundError),
    #[error(transparent)]
    Fit(#[from] FitError),
    #[error(transparent)]
    Pso(#[from] PsoError),
    #[error(transparent)]
    Diagnose(#[from] DiagnoseError),
    #[error(transparent)]
    Cause(#[from] CauseError),
    #[error(transparent)]
    Hide(#[from] HideError),
    #[error(transparent)]
    UserCause(#[from] UserCauseError),
    #[error(transparent)]
    Trial(#[from] TrialError),
    #[error(transparent)]
    Practice(#[from] PracticeError),
    #[error(transparent)]
    Problem(#[from] ProblemError),
    /// A simulation of the unit as given failed, traced back to the data (the samples around
    /// the time it failed, or the operating point it could not initialise at).
    #[error("{error}; {detail}")]
    Located { error: SimError, detail: String },
    /// The plausibility layer found errors in the inputs (each with its file, line, column and
    /// fix).
    #[error("implausible data:\n  {}", .0.join("\n  "))]
    Implausible(Vec<String>),
    /// An output file or folder (path and what went wrong).
    #[error("{0}")]
    Output(String),
    /// A caught panic: a bug, reported with what was running.
    #[error("internal error (a bug, please report it): {0}")]
    Internal(String),
}

impl Error {
    /// Short stable identifier: the source (`"request"`, `"event"`, `"spec"`, `"fit"`,
    /// `"diagnose"`, …) and, where it has variants, the variant's own `kind()` after a dot.
    pub fn kind(&self) -> String {
        let (source, variant): (&str, Option<&str>) = match self {
            Error::Request(e) => ("request", Some(e.option)),
            Error::Event(e) => ("event", Some(e.kind())),
            Error::Import(_) => ("import", None),
            Error::UnitFile(e) => ("unit_file", Some(e.kind())),
            Error::Dyr(_) => ("dyr", None),
            Error::Unit(e) => ("unit", Some(e.kind())),
            Error::Sim(e) => ("sim", Some(e.kind())),
            Error::Synth(_) => ("synth", None),
            Error::Spec(e) => ("spec", Some(e.kind())),
            Error::Bound(e) => ("bound", Some(e.kind())),
            Error::Fit(e) => ("fit", Some(e.kind())),
            Error::Pso(e) => ("pso", Some(e.kind())),
            Error::Diagnose(e) => ("diagnose", Some(e.kind())),
            Error::Cause(e) => ("cause", Some(e.kind())),
            Error::Hide(e) => ("hide", Some(e.kind())),
            // A user cause file is a spec of the user's, as a calibration spec is.
            Error::UserCause(_) => ("user_cause", Some("spec")),
            Error::Trial(e) => ("trial", Some(e.kind())),
            Error::Practice(e) => ("practice", Some(e.kind())),
            Error::Problem(e) => ("problem", Some(e.kind())),
            Error::Located { error, .. } => ("sim", Some(error.kind())),
            Error::Implausible(_) => ("event", Some("implausible")),
            Error::Output(_) => ("output", None),
            Error::Internal(_) => ("internal", None),
        };
        match variant {
            Some(v) => format!("{source}.{v}"),
            None => source.to_string(),
        }
    }

    /// What kind of failure this is for the user (see [`ErrorClass`]).
    pub fn class(&self) -> ErrorClass {
        use ErrorClass as C;
        match self {
            Error::Request(_) => C::Usage,
            Error::Event(_) | Error::Import(_) => C::EventData,
            Error::UnitFile(_) | Error::Dyr(_) | Error::Unit(_) => C::UnitModel,
            Error::Sim(e) => C::of_sim(e),
            Error::Synth(e) => match e {
                SynthFailure::Probe(s) | SynthFailure::Synth(s) => match s {
                    SynthError::Sim(sim) => C::of_sim(sim),
                    SynthError::Event(_) => C::EventData,
                },
                SynthFailure::Context(_) => C::Init,
                SynthFailure::Hide { error, .. } => hide_class(error),
            },
            Error::Spec(_) | Error::Bound(_) | Error::UserCause(_) => C::Spec,
            Error::Fit(e) => match e {
                FitError::Spec(_) => C::Spec,
                // A fit that cannot run as asked (no event, a stage the spec lacks, a resume
                // that does not match).
                FitError::Setup(_) => C::Calibration,
                // The events lack what a stage plays back or compares.
                FitError::Event(_) => C::EventData,
                FitError::Start(p) => C::of_problem(p),
                FitError::Stage { .. } => C::Calibration,
                FitError::Interrupted { .. } => C::Interrupted,
                FitError::Output(_) => C::Output,
            },
            Error::Pso(_) => C::Calibration,
            Error::Diagnose(e) => match e {
                // A diagnosis that cannot run as asked (an unknown cause, a bad re-fit request).
                DiagnoseError::Setup(_) => C::Calibration,
                DiagnoseError::Event(_) => C::EventData,
                DiagnoseError::Simulation { error, .. } => {
                    error.as_ref().map_or(C::Simulation, C::of_sim)
                }
                DiagnoseError::Interrupted { .. } => C::Interrupted,
            },
            Error::Cause(e) => match e {
                CauseError::Unknown(_) => C::Usage,
                CauseError::NotApplicable(_) | CauseError::Build(_) => C::UnitModel,
            },
            Error::Hide(e) => hide_class(e),
            Error::Trial(_) | Error::Practice(_) => C::Calibration,
            Error::Problem(e) => C::of_problem(e),
            Error::Located { error, .. } => C::of_sim(error),
            Error::Implausible(_) => C::EventData,
            Error::Output(_) => C::Output,
            Error::Internal(_) => C::Internal,
        }
    }

    /// Runs `f`, turning a panic into [`Error::Internal`] naming `what` was running: no panic
    /// crosses a front end (a pyo3 call, a fleet job). The code is written not to panic; this is
    /// the net under it.
    pub fn catch<T>(what: &str, f: impl FnOnce() -> Result<T, Error>) -> Result<T, Error> {
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
            Ok(r) => r,
            Err(payload) => {
                let msg = payload
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "a panic without a message".into());
                Err(Error::Internal(format!("{what}: {msg}")))
            }
        }
    }
}

/// A hidden cause that cannot be built on the unit is the unit's (4); anything else about it is
/// the request's (2).
fn hide_class(e: &HideError) -> ErrorClass {
    match e {
        HideError::Build(_) => ErrorClass::UnitModel,
        _ => ErrorClass::Usage,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_initialisation_failure_is_told_apart_from_an_integration_failure() {
        use itaipu_dynamics::integrate::SolveError;
        let init = Error::Fit(FitError::Start(ProblemError::Simulation {
            event: "e".into(),
            error: SimError::Frequency {
                unit: "u".into(),
                unit_hz: 50.0,
                event: "e".into(),
                event_hz: 60.0,
            },
        }));
        assert_eq!(init.class(), ErrorClass::Init);
        let solve = Error::Fit(FitError::Start(ProblemError::Simulation {
            event: "e".into(),
            error: SimError::Solve(SolveError::EventLoop { t: 1.0 }),
        }));
        assert_eq!(solve.class(), ErrorClass::Simulation);
        assert_eq!(solve.kind(), "fit.start");
    }

    #[test]
    fn a_panic_becomes_an_internal_error() {
        let r: Result<(), Error> = Error::catch("a test", || panic!("min > max"));
        let e = r.unwrap_err();
        assert_eq!(e.class(), ErrorClass::Internal);
        assert!(e.to_string().contains("a test: min > max"), "{e}");
        let ok: Result<u8, Error> = Error::catch("fine", || Ok(3));
        assert_eq!(ok.unwrap(), 3);
    }
}
