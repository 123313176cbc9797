//! `synth`: synthetic events from the engine.

use std::sync::Arc;

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use itaipu_calib::job::load_unit as read_unit_any;

use crate::args::{source, Source};
use crate::errors::{request_error, Failure, IntoPyErr};
use crate::event::PyEvent;
use crate::interrupt;
use crate::unit::PyUnit;
use itaipu_calib::options::SYNTH;
use itaipu_calib::request::{HideSpec, SynthRequest, Synthesized};

/// Makes a realistic synthetic event from the engine (the same generator as
/// `itaipu-calib synth`): a grid-side voltage profile (`kind`: "dip", "frequency", "step" or
/// "ambient", the event at 1 s) played into the true `unit` (path or Unit), sampled at `rate`
/// samples/s, with white noise on P and Q (`pq_sigma` pu) and on |V| and the angle
/// (`v_sigma`), quantisation of P and Q (`quantum` pu), and optionally a hidden delay of the
/// power channels (`skew_ms`). Returns an Event (in memory; P and Q on `system_mva`, default
/// the unit's machine base). Deterministic for a seed. Defaults: `options()` (the declaration
/// both front ends read). The GIL is released while it runs.
///
/// `hide` hides causes of the diagnosis catalog in the truth, in order, as the command line's
/// `--hide`: a list of `(cause, {param: value})` tuples (or bare cause names), or a dict
/// `{cause: {param: value}}`, e.g. `hide=[("measurement_skew", {"measurement.pq_delay_s":
/// 0.012})]`. Parameters not given keep the extension's starting values. With
/// `return_truth=True` the result is `(event, truth)`, truth being the (extended) true Unit.
///
/// Raises UnitModelError, InitError (also when a hidden cause keeps the truth from
/// initialising), SimulationError; ValueError for bad options, an unknown cause or parameter.
#[pyfunction]
#[pyo3(signature = (unit, *, kind = SYNTH.kind, duration = SYNTH.duration, rate = SYNTH.rate, system_mva = None, pq_sigma = SYNTH.pq_sigma, v_sigma = SYNTH.v_sigma, quantum = SYNTH.quantum, skew_ms = SYNTH.skew_ms, seed = SYNTH.seed, name = None, hide = None, return_truth = false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn synth(
    py: Python<'_>,
    unit: &Bound<'_, PyAny>,
    kind: &str,
    duration: f64,
    rate: f64,
    system_mva: Option<f64>,
    pq_sigma: f64,
    v_sigma: f64,
    quantum: f64,
    skew_ms: f64,
    seed: u64,
    name: Option<String>,
    hide: Option<&Bound<'_, PyAny>>,
    return_truth: bool,
) -> PyResult<Py<PyAny>> {
    let mut request = SynthRequest {
        kind: kind.parse().map_err(request_error)?,
        duration,
        rate,
        system_mva,
        pq_sigma,
        v_sigma,
        quantum,
        skew_ms,
        seed,
        name,
        hides: vec![],
    };
    request.validate().map_err(request_error)?;
    if let Some(h) = hide {
        request.hides = hide_list(h)?;
    }
    let unit = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    // Not stoppable inside the library (one or two simulations): Ctrl-C raises at once and
    // the worker's result is dropped.
    let result = interrupt::interruptible(py, None, move || -> Result<Synthesized, Failure> {
        let unit = match unit {
            Source::Loaded(u) => u,
            Source::Path(p) => Arc::new(read_unit_any(&p)?.unit),
        };
        request
            .run(&unit, "itaipu_calib.synth")
            .map_err(Failure::from)
    })?;
    let Synthesized { event, truth, .. } = result.map_err(|f| f.into_pyerr(py))?;
    let event = Bound::new(py, PyEvent::new(event))?;
    if return_truth {
        let truth = Bound::new(
            py,
            PyUnit {
                inner: Arc::new(truth),
                path: None,
            },
        )?;
        Ok(PyTuple::new(py, [event.into_any(), truth.into_any()])?
            .into_any()
            .unbind())
    } else {
        Ok(event.into_any().unbind())
    }
}

/// The `hide` argument of `synth`: a dict `{cause: {param: value}}` or a list of
/// `(cause, {param: value})` tuples or cause names.
pub(crate) fn hide_list(arg: &Bound<'_, PyAny>) -> PyResult<Vec<HideSpec>> {
    let values = |cause: &str, v: Option<Bound<'_, PyAny>>| -> PyResult<Vec<(String, f64)>> {
        let Some(v) = v.filter(|v| !v.is_none()) else {
            return Ok(vec![]);
        };
        let d = v.downcast::<PyDict>().map_err(|_| {
            PyTypeError::new_err(format!(
                "hide: the values of '{cause}' must be a dict {{param: value}}"
            ))
        })?;
        d.iter()
            .map(|(k, x)| {
                let k: String = k.extract().map_err(|_| {
                    PyTypeError::new_err(format!("hide: '{cause}': parameter names must be str"))
                })?;
                let x: f64 = x.extract().map_err(|_| {
                    PyTypeError::new_err(format!("hide: '{cause}': {k} must be a number"))
                })?;
                Ok((k, x))
            })
            .collect()
    };
    let check = |cause: String, vals: Vec<(String, f64)>| -> PyResult<HideSpec> {
        HideSpec::new(cause, vals).map_err(request_error)
    };
    if let Ok(d) = arg.downcast::<PyDict>() {
        return d
            .iter()
            .map(|(c, v)| {
                let c: String = c
                    .extract()
                    .map_err(|_| PyTypeError::new_err("hide: causes must be str"))?;
                let vals = values(&c, Some(v))?;
                check(c, vals)
            })
            .collect();
    }
    let bad = || {
        PyTypeError::new_err("hide must be a dict {cause: {param: value}} or a list of (cause, {param: value}) tuples")
    };
    if arg.extract::<String>().is_ok() {
        return Err(bad());
    }
    let items = arg.try_iter().map_err(|_| bad())?;
    items
        .map(|item| {
            let item = item?;
            if let Ok(c) = item.extract::<String>() {
                return check(c, vec![]);
            }
            let t = item.downcast::<PyTuple>().map_err(|_| bad())?;
            if t.len() != 2 {
                return Err(bad());
            }
            let c: String = t.get_item(0)?.extract().map_err(|_| bad())?;
            let vals = values(&c, Some(t.get_item(1)?))?;
            check(c, vals)
        })
        .collect()
}
