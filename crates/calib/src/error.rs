//! The crate's one error type: every error enum of the crate converts into [`Error`] (`?` or
//! `From`), so that a front end maps one type; [`Error::kind`] names the source and the
//! variant (`"fit.stage"`, `"diagnose.interrupted"`, …).

use crate::bounds::BoundError;
use crate::diagnose::catalog::{CauseError, HideError};
use crate::diagnose::trial::TrialError;
use crate::diagnose::user_cause::UserCauseError;
use crate::diagnose::DiagnoseError;
use crate::fit::FitError;
use crate::practice::PracticeError;
use crate::problem::ProblemError;
use crate::pso::PsoError;
use crate::spec::SpecError;

/// Any error of the crate (the message is the source's own).
#[derive(Debug, thiserror::Error)]
pub enum Error {
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
}

impl Error {
    /// Short stable identifier: the source (`"spec"`, `"bound"`, `"fit"`, `"pso"`, `"diagnose"`, `"cause"`,
    /// `"hide"`, `"user_cause"`, `"trial"`, `"practice"`, `"problem"`) and, where it has variants, the
    /// variant's own `kind()` after a dot.
    pub fn kind(&self) -> String {
        let (source, variant) = match self {
            Error::Spec(e) => ("spec", Some(e.kind())),
            Error::Bound(e) => ("bound", Some(e.kind())),
            Error::Fit(e) => ("fit", Some(e.kind())),
            Error::Pso(e) => ("pso", Some(e.kind())),
            Error::Diagnose(e) => ("diagnose", Some(e.kind())),
            Error::Cause(e) => ("cause", Some(e.kind())),
            Error::Hide(e) => ("hide", Some(e.kind())),
            Error::UserCause(_) => ("user_cause", None),
            Error::Trial(e) => ("trial", Some(e.kind())),
            Error::Practice(e) => ("practice", Some(e.kind())),
            Error::Problem(e) => ("problem", Some(e.kind())),
        };
        match variant {
            Some(v) => format!("{source}.{v}"),
            None => source.to_string(),
        }
    }
}
