//! `simulate`.

use std::sync::Arc;

use pyo3::prelude::*;

use itaipu_calib::job::load_unit as read_unit_any;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::{simulate_mode_traces, PlaybackMode};
use itaipu_dynamics::simulate::{SimOptions, Traces};

use crate::args::{source, swap_error, swapped_events_unit, Source};
use crate::errors::{request_error, Failure, IntoPyErr};
use crate::event::PyEvent;
use crate::traces::PyTraces;
use crate::unit::PyUnit;
use itaipu_calib::options::SIMULATE;
use itaipu_calib::request::SimulateRequest;

/// Plays the measured terminal voltage of `event` into `unit` and records every signal.
///
/// `event` and `unit` are paths to the TOML files (str or os.PathLike) or objects from
/// `load_event` / `load_unit`. `method` is "dopri5" (adaptive Dormand-Prince 5(4), tolerances
/// `rtol`, `atol`) or "rk4" (fixed step of at most `step` seconds). `mode` is the playback
/// mode: "phasor" (the measured |V| and angle imposed), "exciter_alone", "machine_from_efd" or
/// "closed_loop" (records without an angle; docs/playback.md). Defaults: `options()` (the
/// declaration both front ends read). The GIL is released while files are read and the model
/// is integrated. The plausibility layer runs on the event and the unit as for the command
/// line's `simulate`: its warnings are issued as `ItaipuWarning`s, an implausible input raises
/// EventError or UnitModelError.
///
/// Raises EventError, UnitModelError, InitError, SimulationError (and ValueError for bad
/// options, TypeError for bad argument types).
#[pyfunction]
#[pyo3(signature = (event, unit, *, method = SIMULATE.method, rtol = SIMULATE.rtol, atol = SIMULATE.atol, step = SIMULATE.step, mode = SIMULATE.mode))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate(
    py: Python<'_>,
    event: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
    method: &str,
    rtol: f64,
    atol: f64,
    step: f64,
    mode: &str,
) -> PyResult<PyTraces> {
    let opts = sim_options(method, rtol, atol, step)?;
    let mode = PlaybackMode::parse(mode).ok_or_else(|| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "mode: '{mode}' is not one of {}",
            PlaybackMode::NAMES.join(", ")
        ))
    })?;
    if swapped_events_unit(py, event, unit)? {
        return Err(swap_error("simulate"));
    }
    let event = source::<PyEvent, _>(event, "event", |e| e.inner.clone())?;
    let unit = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    let unit_file = match &unit {
        Source::Path(p) => Some(p.clone()),
        Source::Loaded(_) => None,
    };
    let result = py.detach(move || -> Result<(Traces, Vec<_>), Failure> {
        let event = match event {
            Source::Loaded(e) => e,
            Source::Path(p) => Arc::new(Event::from_toml_file(&p)?),
        };
        let unit = match unit {
            Source::Loaded(u) => u,
            Source::Path(p) => Arc::new(read_unit_any(&p)?.unit),
        };
        let warnings = itaipu_calib::job::check_inputs(&[&event], &unit, unit_file.as_deref())?;
        Ok((simulate_mode_traces(&unit, &event, mode, &opts)?, warnings))
    });
    let (traces, warnings) = result.map_err(|e| e.into_pyerr(py))?;
    crate::errors::warn_all(py, &warnings)?;
    Ok(PyTraces { inner: traces })
}

/// Integrator options, checked by the library ([`SimulateRequest::options`]) as for the
/// command line.
pub(crate) fn sim_options(method: &str, rtol: f64, atol: f64, step: f64) -> PyResult<SimOptions> {
    SimulateRequest {
        method: method.to_string(),
        rtol,
        atol,
        step,
    }
    .options()
    .map_err(request_error)
}
