//! Python bindings for `itaipu-dynamics` and `itaipu-calib`: the compiled module
//! `itaipu_calib._core`.
//!
//! Thin glue only: every computation, check and message lives in the Rust crates. This file
//! converts arguments, releases the GIL while simulating and fitting, turns results into numpy
//! arrays and dicts, and maps the typed Rust errors onto a small Python exception hierarchy whose
//! messages are exactly the Rust `Display` text (what the CLI prints after `error: `).
//!
//! The pure-Python package (`python/itaipu_calib/__init__.py`) re-exports everything from here.

mod args;
mod cli;
mod diagnose;
mod ecosys;
mod errors;
mod event;
mod fit;
mod interrupt;
mod library;
mod pandas;
mod params;
mod simulate;
mod synth;
mod traces;
mod unit;

use pyo3::prelude::*;

use crate::diagnose::{causes, PyDiagnosis};
use crate::errors::{
    CalibrationError, EventError, InitError, InternalError, ItaipuError, ItaipuWarning,
    OutputError, SimulationError, UnitModelError,
};
use crate::event::{check, load_event, PyEvent};
use crate::fit::PyFitResult;
use crate::library::{check_out, defaults, models, noise_sigma, options, stages};
use crate::traces::PyTraces;
use crate::unit::{load_unit, PyUnit};

// -------------------------------------------------------------------------------------------
// Module
// -------------------------------------------------------------------------------------------

/// Compiled part of itaipu_calib; import `itaipu_calib` instead.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    py.get_type::<ItaipuError>().setattr("kind", py.None())?;
    m.add("ItaipuError", py.get_type::<ItaipuError>())?;
    m.add("EventError", py.get_type::<EventError>())?;
    m.add("UnitModelError", py.get_type::<UnitModelError>())?;
    m.add("InitError", py.get_type::<InitError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("CalibrationError", py.get_type::<CalibrationError>())?;
    m.add("OutputError", py.get_type::<OutputError>())?;
    m.add("InternalError", py.get_type::<InternalError>())?;
    m.add("ItaipuWarning", py.get_type::<ItaipuWarning>())?;
    m.add_class::<PyEvent>()?;
    m.add_class::<PyUnit>()?;
    m.add_class::<PyTraces>()?;
    m.add_class::<PyFitResult>()?;
    m.add_class::<PyDiagnosis>()?;
    m.add_function(wrap_pyfunction!(load_event, m)?)?;
    m.add_function(wrap_pyfunction!(load_unit, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(models, m)?)?;
    m.add_function(wrap_pyfunction!(causes, m)?)?;
    m.add_function(wrap_pyfunction!(synth::synth, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose::diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(noise_sigma, m)?)?;
    m.add_function(wrap_pyfunction!(defaults, m)?)?;
    m.add_function(wrap_pyfunction!(options, m)?)?;
    m.add_function(wrap_pyfunction!(stages, m)?)?;
    m.add_function(wrap_pyfunction!(check_out, m)?)?;
    m.add_function(wrap_pyfunction!(cli::_cli_main, m)?)?;
    m.add_class::<params::PyParameter>()?;
    ecosys::register(m)?;
    Ok(())
}
