//! One file per cause of the diagnosis catalog, each implementing
//! [`Cause`](super::cause::Cause), and the registry [`CAUSES`] that lists them.
//!
//! Adding a cause touches two files: write `<cause>.rs` here (its
//! [`CauseInfo`](super::cause::CauseInfo), how it extends the unit, optionally its signature
//! in the evidence and the rules that name or veto it from the evidence, and its self-test
//! scenario), then declare its module and add it to [`CAUSES`] below. The CLI (`--cause`,
//! `synth --hide`), Python (`itaipu_calib.causes()`), the diagnosis and its self-tests all read
//! the registry.

use super::cause::Cause;

pub mod exciter_limit;
pub mod governor;
pub mod measurement_skew;
pub mod oel;
pub mod pss_state;
pub mod saturation;
mod signature;
pub mod terminal_load;
pub mod torsional_mode;

/// Every cause `diagnose` knows, in the order they are tried.
pub static CAUSES: &[&dyn Cause] = &[
    &torsional_mode::TorsionalMode,
    &exciter_limit::ExciterLimit,
    &saturation::Saturation,
    &governor::Governor,
    &measurement_skew::MeasurementSkew,
    &terminal_load::TerminalLoad,
    &pss_state::PssState,
    &oel::Oel,
];
