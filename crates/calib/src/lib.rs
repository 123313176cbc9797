//! # itaipu-calib
//!
//! Staged calibration of generating-unit models against PMU playback, the way the source papers
//! do it (a particle swarm for the global search, then a gradient method from its best point;
//! generator first, then AVR, PSS, governor), reproducibly and with an identifiability report.
//!
//! * [`spec`]: the calibration spec (TOML): stages, free parameters and bounds, objectives.
//! * [`problem`]: the least-squares problem, parameter coordinates, failure penalty.
//! * [`pso`]: a deterministic particle swarm evaluated in parallel (rayon).
//! * [`local`]: argmin's L-BFGS with central-difference gradients on fixed-step RK4.
//! * [`identify`]: standard errors and correlations from the Gauss-Newton approximation.
//! * [`filter`]: zero-phase low-pass filtering of measurements.
//! * [`evidence`]: residual evidence for diagnosis (windows, noise floor, whiteness,
//!   cross-correlation with the inputs, spectrum, matrix-pencil modes).
//! * [`practice`]: the practice set of independent events, its one spec and its answer keys.
//! * [`fit`]: stages, strategies and reports.
//! * [`options`]: the options of both front ends (command line, Python) declared once: names,
//!   defaults and help, from which the option reference `docs/options.md` is rendered.
//! * [`request`]: those options checked, once, for both front ends.
//! * [`job`]: the fit and the diagnosis as every front end runs them: inputs, plausibility,
//!   reports, output files.
//! * [`error`]: [`Error`], the one error type every error of the crate and the engine converts
//!   into, with its [`error::ErrorClass`] for the front ends.
//! * [`noise`]: the noise floor of a channel, one definition for every report and the diagnosis.
//! * [`output`]: output folders that are never half-written (staging, manifest, partial).
//! * [`diagnose`]: residual evidence, the catalog of causes with their model extensions,
//!   re-fits and gains, and the verdict.

// Guards are written `!(x <= limit)` on purpose: that form also catches NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bounds;
pub mod default_spec;
pub mod diagnose;
#[cfg(test)]
mod docs_examples;
pub mod error;
pub mod evidence;
/// The zero-phase low-pass of the measurement (and of the played-back input: `itaipu_dynamics`).
pub use itaipu_dynamics::filter;
pub mod fit;
pub mod identify;
pub mod job;
pub mod local;
pub mod noise;
pub mod options;
pub mod output;
pub mod practice;
pub mod problem;
pub mod pso;
pub mod request;
pub mod spec;

pub use error::Error;
pub use fit::{fit, FitOptions, FitReport, FitResult, Progress, Silent};
pub use spec::{CalibSpec, Strategy};
