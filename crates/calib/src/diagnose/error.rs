//! Why a diagnosis, or one of its re-fits, could not run.

/// Why a diagnosis could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Bad request (unknown cause, no event).
    #[error("{0}")]
    Setup(String),
    /// An event lacks what the playback plays back or compares (a record without an angle
    /// diagnosed by the phasor playback, a compared channel not recorded).
    #[error("{0}")]
    Event(String),
    /// The unit does not simulate on an event as given; `error` is the engine's own error when
    /// there is one (an initialisation failure is then told apart from an integration failure).
    #[error("the unit does not simulate on event '{event}': {msg}")]
    Simulation {
        event: String,
        msg: String,
        error: Option<itaipu_dynamics::simulate::SimError>,
    },
    /// Stopped by [`super::DiagnoseOptions::cancel`]; `tried` lists the causes tried up to then (those
    /// scored side by side when it came possibly cut short). Nothing of the run is kept.
    #[error("interrupted (causes tried: {})", if tried.is_empty() { "none".to_string() } else { tried.join(", ") })]
    Interrupted { tried: Vec<String> },
}

impl DiagnoseError {
    /// [`DiagnoseError::Simulation`] on `event` from a fitness or re-fit failure, keeping the
    /// engine's error.
    pub(crate) fn simulation(event: &str, e: &crate::problem::ProblemError) -> Self {
        let error = match e {
            crate::problem::ProblemError::Simulation { error, .. } => Some(error.clone()),
            _ => None,
        };
        DiagnoseError::Simulation {
            event: event.to_string(),
            msg: e.to_string(),
            error,
        }
    }

    /// [`DiagnoseError::Simulation`] on `event` from the engine's own error.
    pub(crate) fn engine(event: &str, error: itaipu_dynamics::simulate::SimError) -> Self {
        DiagnoseError::Simulation {
            event: event.to_string(),
            msg: error.to_string(),
            error: Some(error),
        }
    }

    pub fn kind(&self) -> &'static str {
        match self {
            DiagnoseError::Setup(_) => "setup",
            DiagnoseError::Event(_) => "event",
            DiagnoseError::Simulation { .. } => "simulation",
            DiagnoseError::Interrupted { .. } => "interrupted",
        }
    }
}
/// Why one re-fit gave no result. A candidate whose re-fit fails is reported with the reason
/// (its note), never aborts the diagnosis; the reference's failure does
/// ([`DiagnoseError::Simulation`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefitError {
    /// [`super::DiagnoseOptions::cancel`] was set.
    #[error("interrupted")]
    Interrupted,
    /// A free parameter or a tie that does not resolve in the unit re-fitted.
    #[error("{0}")]
    Setup(String),
    /// The unit does not simulate at the re-fit's values.
    #[error("{0}")]
    Simulation(String),
}
