//! `diagnose`, its `Diagnosis`, and the catalog of causes.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use pyo3::exceptions::{PyDeprecationWarning, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use itaipu_calib::bounds::FreeBound;
use itaipu_calib::diagnose::{self as calib_diagnose, catalog};
use itaipu_calib::fit::Silent;
use itaipu_calib::job;
use itaipu_calib::request::DiagnoseRequest;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::args::{
    event_sources, load_events, source, str_or_list, swapped_events_unit, worker_pool, Source,
};
use crate::errors::{request_error, Failure, IntoPyErr};
use crate::fit::PyFitResult;
use crate::traces::traces_dict;
use crate::unit::PyUnit;
use crate::{interrupt, pandas};
use itaipu_calib::request::Search;

/// A serde_json value as the equivalent Python object (null -> None, numbers -> int or float,
/// arrays -> lists, objects -> dicts in the JSON's key order).
pub(crate) fn json_to_py<'py>(
    py: Python<'py>,
    v: &serde_json::Value,
) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::IntoPyObjectExt;
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_bound_py_any(py)?,
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i.into_bound_py_any(py)?
            } else if let Some(u) = n.as_u64() {
                u.into_bound_py_any(py)?
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_bound_py_any(py)?
            }
        }
        Value::String(s) => s.into_bound_py_any(py)?,
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(json_to_py(py, x)?)?;
            }
            l.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Result of `diagnose`: the verdict, every candidate cause tried with its gain, the residual
/// evidence, the extended and re-fitted unit of the named cause, and traces before and after.
///
/// `report` is the whole diagnosis report as a dict (non-finite numbers are None; a new dict on
/// each access); `to_json()` gives it as JSON text. `verdict` is the report's verdict (cause,
/// title, statement, key_parameters as `[path, value, unit]` lists, gains, where: `[signal,
/// window, start_s, end_s]` or None); `cause` its cause id, `none` or `unexplained`.
#[pyclass(name = "Diagnosis", module = "itaipu_calib", frozen)]
pub(crate) struct PyDiagnosis {
    /// The finished diagnosis, for [`job::write_diagnosis_files`].
    pub(crate) run: Arc<job::DiagnoseRun>,
    pub(crate) report: serde_json::Value,
    pub(crate) extended_unit: Option<Arc<Unit>>,
    pub(crate) before: Vec<(String, Traces)>,
    pub(crate) after: Vec<(String, Traces)>,
}

impl PyDiagnosis {
    fn field<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, self.report.get(key).unwrap_or(&serde_json::Value::Null))
    }
}

#[pymethods]
impl PyDiagnosis {
    /// The verdict as a dict: cause, title, statement, key_parameters, gains, where, grade,
    /// probability, competing.
    #[getter]
    fn verdict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mut v = self
            .report
            .get("verdict")
            .cloned()
            .unwrap_or(serde_json::Value::Null);
        // The Rust field is `where_` (a keyword): the dict says `where`.
        if let Some(o) = v.as_object_mut() {
            if let Some(w) = o.remove("where_") {
                o.entry("where").or_insert(w);
            }
        }
        json_to_py(py, &v)
    }

    /// The one sentence on how far the residual of the unit as given lies above the noise (the
    /// library's, as `report["headline"]` and the command line's `headline` line): for a fit's
    /// calibrated unit the same words and number as the fit's `FitResult.headline`.
    #[getter]
    fn headline(&self) -> String {
        self.run.report.headline.sentence.clone()
    }

    /// The named cause id, or `none` / `unexplained`.
    #[getter]
    fn cause(&self) -> String {
        self.report["verdict"]["cause"]
            .as_str()
            .unwrap_or_default()
            .to_string()
    }

    /// Every cause tried, by decreasing ΔBIC (not applicable ones last): dicts with cause,
    /// title, applicable, note, extension, parameters, fixed, gains, significant, signature, ...
    #[getter]
    fn candidates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.field(py, "candidates")
    }

    /// Residual evidence per event on the unit as given (dicts: event, onset_s, signals).
    #[getter]
    fn evidence<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.field(py, "evidence")
    }

    /// The whole report as a dict (what the command line writes as JSON).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.report)
    }

    /// The extended, re-fitted unit of the named cause as unit-file TOML, or None.
    #[getter]
    fn extended_unit_toml(&self) -> Option<String> {
        self.extended_unit.as_deref().map(unit_to_toml)
    }

    /// The extended, re-fitted unit of the named cause, or None.
    #[getter]
    fn extended_unit(&self) -> Option<PyUnit> {
        self.extended_unit.as_ref().map(|u| PyUnit {
            inner: u.clone(),
            path: None,
        })
    }

    /// Per event name: the traces of the unit as given (`{"time_s": array, column: array}`).
    #[getter]
    fn traces_before<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        traces_by_event(py, &self.before)
    }

    /// Per event name: the traces of the extended unit (empty when no cause is named).
    #[getter]
    fn traces_after<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        traces_by_event(py, &self.after)
    }

    /// The candidates as a pandas DataFrame indexed by cause, in the report's order (columns
    /// title, applicable, significant, passed_test, look_alike, note, and the gains: delta_bic, fit_drop, held_drop, ...;
    /// NaN where a cause was not applicable). Needs pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let empty = vec![];
        let cands = self.report["candidates"].as_array().unwrap_or(&empty);
        let rows = cands
            .iter()
            .map(|c| {
                let d = PyDict::new(py);
                for key in [
                    "cause",
                    "title",
                    "applicable",
                    "significant",
                    "passed_test",
                    "look_alike",
                    "note",
                ] {
                    d.set_item(key, json_to_py(py, &c[key])?)?;
                }
                if let Some(g) = c["gains"].as_object() {
                    for (k, v) in g {
                        if v.is_number() || v.is_null() {
                            d.set_item(k, v.as_f64().unwrap_or(f64::NAN))?;
                        }
                    }
                }
                Ok(d)
            })
            .collect::<PyResult<Vec<_>>>()?;
        pandas::data_frame(py, pandas::rows(py, rows)?, Some("cause"))
    }

    /// Writes the diagnosis' files into the folder `out` as the command line's `diagnose --out`
    /// does (diagnosis.json, extended.toml when a cause is named, warnings.json when there are
    /// warnings, manifest.json last; no plots or HTML), through a temporary folder renamed into
    /// place. An existing non-empty `out` is refused unless `overwrite=True` (and then only a
    /// folder of ours, replaced whole). Returns the folder. Raises OutputError.
    #[pyo3(signature = (out, *, overwrite = false))]
    fn write(&self, py: Python<'_>, out: PathBuf, overwrite: bool) -> PyResult<PathBuf> {
        let run = self.run.clone();
        py.detach(move || {
            Failure::catch("Diagnosis.write", || {
                let staging = itaipu_calib::output::prepare_out(Some(&out), "diagnose", overwrite)?;
                job::write_diagnosis_files(staging.path(), &run)?;
                staging.commit(
                    Some(run.report.seed),
                    vec![
                        "itaipu_calib.Diagnosis.write".into(),
                        out.display().to_string(),
                    ],
                )
            })
        })
        .map_err(|e| e.into_pyerr(py))
    }

    /// The report as JSON text (indented).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.report)
            .map_err(|e| PyRuntimeError::new_err(format!("diagnosis report: {e}")))
    }

    fn __repr__(&self) -> String {
        let r = &self.report;
        format!(
            "<Diagnosis of '{}' on {}: {} ({} candidates, {:.1} s)>",
            r["unit"].as_str().unwrap_or_default(),
            r["events"]
                .as_array()
                .map(|a| a
                    .iter()
                    .filter_map(|e| e.as_str())
                    .collect::<Vec<_>>()
                    .join(", "))
                .unwrap_or_default(),
            r["verdict"]["cause"].as_str().unwrap_or_default(),
            r["candidates"].as_array().map_or(0, |a| a.len()),
            r["wall_s"].as_f64().unwrap_or(f64::NAN)
        )
    }
}

/// The `causes` argument: None (the whole catalog), a cause id, a comma-separated string or a
/// list of ids.
pub(crate) fn cause_list(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<String>> {
    let Some(arg) = arg else { return Ok(vec![]) };
    let given = str_or_list(
        arg,
        "causes must be None, a cause id, or a list of cause ids",
    )?;
    let names: Vec<String> = given
        .iter()
        .flat_map(|s| s.split(','))
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    if names.is_empty() {
        return Err(PyValueError::new_err(format!(
            "causes must name at least one cause, or be None for all ({})",
            catalog::ids()
        )));
    }
    Ok(names)
}

/// The `refit` argument of `diagnose`: None, a parameter path or a list of them (each within
/// its model's declared range), or a dict `{path: (min, max) or None}`.
pub(crate) fn refit_list(
    arg: Option<&Bound<'_, PyAny>>,
) -> PyResult<Vec<calib_diagnose::RefitRequest>> {
    let Some(arg) = arg.filter(|a| !a.is_none()) else {
        return Ok(vec![]);
    };
    let shape = "refit must be None, a parameter path, a list of paths, or a dict {path: (min, max) or None}";
    if let Ok(s) = arg.extract::<String>() {
        return Ok(vec![(s, None)]);
    }
    if let Ok(d) = arg.cast::<PyDict>() {
        let mut out = vec![];
        for (k, v) in d.iter() {
            let path: String = k.extract().map_err(|_| PyTypeError::new_err(shape))?;
            let range = if v.is_none() {
                None
            } else {
                Some(v.extract::<(f64, f64)>().map_err(|_| {
                    PyTypeError::new_err(format!("refit['{path}'] must be (min, max) or None"))
                })?)
            };
            out.push((path, range));
        }
        return Ok(out);
    }
    let names: Vec<String> = arg.extract().map_err(|_| PyTypeError::new_err(shape))?;
    Ok(names.into_iter().map(|n| (n, None)).collect())
}

/// Diagnoses what `unit` (normally already calibrated) still gets wrong on `events`: residual
/// evidence, then each cause of the catalog (or of `causes`) as a model extension re-fitted by
/// particle swarm and the local method and judged by its gain (ΔBIC, fitted and held-out χ²),
/// then a verdict, as the command line's `diagnose`: the same library job
/// ([`job::run_diagnose`]), so the same numbers, warnings and verdict.
///
/// `unit` is a path (unit TOML or `.dyr`) or a Unit; `events` and `held_out` paths to event
/// files or Event objects, or lists of them. Without `held_out`, each event is split into
/// alternating blocks, fitted and held out. `causes` (ids, see `causes()`) limits the causes
/// tried. `seed`, `particles`, `pso_iterations` and `local_iterations` set each re-fit (None:
/// `defaults()["diagnose"]`; `lbfgs_iterations` is the old name of `local_iterations`);
/// `threads` the worker threads (default: all cores). `refit` names calibrated parameters to
/// free again in every re-fit (a list of paths, or a dict of path to (min, max)). `fit` (a
/// FitResult) diagnoses that fit's calibrated unit with its whole calibrated set re-freed,
/// within the spec's bounds and with the calibration's datasheet prior, as `itaipu-calib
/// diagnose --fit`: `unit` is then left out (or is `fit.unit`). `user_causes` (a path or a list
/// of paths) adds causes written by the user, as `--user-cause`. `mode` plays a record without
/// an angle back in a playback mode ("exciter_alone", "machine_from_efd", "closed_loop"), as
/// `--mode`: its compared channels, each weighted by its noise floor, are diagnosed.
/// `look_alikes=False` leaves out the look-alikes outside the catalog, as `--no-look-alikes`
/// (faster; a wrong name is then more likely). The GIL is released while it
/// runs. Plausibility warnings on the inputs are issued as `ItaipuWarning`s and kept in the
/// report's `warnings`. Returns a Diagnosis.
///
/// Raises CalibrationError (a diagnosis that cannot run), SimulationError or InitError (the
/// unit does not simulate on an event as given), EventError, UnitModelError; ValueError for bad
/// options (an unknown cause, a bad `refit` parameter: `kind` names the option), TypeError for
/// bad argument types.
#[pyfunction]
#[pyo3(
    signature = (events, unit = None, held_out = None, *, causes = None, seed = None, particles = None,
                 pso_iterations = None, local_iterations = None, threads = None, refit = None, fit = None,
                 user_causes = None, mode = None, lbfgs_iterations = None, look_alikes = None),
    text_signature = "(events, unit=None, held_out=None, *, causes=None, seed=None, particles=None, \
                      pso_iterations=None, local_iterations=None, threads=None, refit=None, fit=None, user_causes=None, \
                      mode=None, look_alikes=None)"
)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn diagnose(
    py: Python<'_>,
    events: &Bound<'_, PyAny>,
    unit: Option<&Bound<'_, PyAny>>,
    held_out: Option<&Bound<'_, PyAny>>,
    causes: Option<&Bound<'_, PyAny>>,
    seed: Option<&Bound<'_, PyAny>>,
    particles: Option<&Bound<'_, PyAny>>,
    pso_iterations: Option<&Bound<'_, PyAny>>,
    local_iterations: Option<&Bound<'_, PyAny>>,
    threads: Option<&Bound<'_, PyAny>>,
    refit: Option<&Bound<'_, PyAny>>,
    fit: Option<&Bound<'_, PyAny>>,
    user_causes: Option<&Bound<'_, PyAny>>,
    mode: Option<&str>,
    lbfgs_iterations: Option<&Bound<'_, PyAny>>,
    look_alikes: Option<bool>,
) -> PyResult<PyDiagnosis> {
    let mode = mode
        .map(|m| {
            itaipu_dynamics::mode::PlaybackMode::parse(m).ok_or_else(|| {
                crate::errors::usage_error(
                    py,
                    "mode",
                    &format!(
                        "'{m}' is not one of {}",
                        itaipu_dynamics::mode::PlaybackMode::NAMES.join(", ")
                    ),
                )
            })
        })
        .transpose()?;
    use crate::args::whole;
    let (seed, particles, pso_iterations, threads): (
        Option<u64>,
        Option<usize>,
        Option<usize>,
        Option<usize>,
    ) = (
        whole(py, seed, "seed")?,
        whole(py, particles, "particles")?,
        whole(py, pso_iterations, "pso_iterations")?,
        whole(py, threads, "threads")?,
    );
    let (local_iterations, lbfgs_iterations): (Option<u64>, Option<u64>) = (
        whole(py, local_iterations, "local_iterations")?,
        whole(py, lbfgs_iterations, "lbfgs_iterations")?,
    );
    let local_iterations = crate::args::renamed(
        py,
        "lbfgs_iterations",
        "local_iterations",
        lbfgs_iterations,
        local_iterations,
    )?;
    let unit = unit.filter(|u| !u.is_none());
    // The old order (unit, events): still accepted, with a warning.
    let (events, unit) = match unit {
        Some(u) if swapped_events_unit(py, events, u)? => {
            PyErr::warn(
                py,
                &py.get_type::<PyDeprecationWarning>(),
                c"diagnose(unit, events) is deprecated: the order is diagnose(events, unit), as in \
                  fit(events, unit) and simulate(event, unit); the two arguments were swapped",
                1,
            )?;
            (u, Some(events))
        }
        u => (events, u),
    };
    // A FitResult: its calibrated unit, with its whole calibrated set re-freed with the
    // calibration's prior (as `itaipu-calib diagnose --fit`).
    let fit: Option<Bound<'_, PyFitResult>> = match fit {
        Some(f) if !f.is_none() => Some(
            f.cast::<PyFitResult>()
                .map_err(|_| {
                    PyTypeError::new_err("fit must be a FitResult (from itaipu_calib.fit)")
                })?
                .clone(),
        ),
        _ => None,
    };
    let (unit_src, calibrated_set): (Source<Unit>, Vec<FreeBound>) = match (unit, &fit) {
        (None, None) => {
            return Err(PyTypeError::new_err(
                "diagnose needs a unit (a path or a Unit), or fit= a FitResult",
            ))
        }
        (Some(u), None) => (source::<PyUnit, _>(u, "unit", |x| x.inner.clone())?, vec![]),
        (given, Some(f)) => {
            let f = f.get();
            if let Some(u) = given {
                let same = u
                    .cast::<PyUnit>()
                    .is_ok_and(|x| Arc::ptr_eq(&x.get().inner, &f.unit));
                if !same {
                    return Err(crate::errors::usage_error(
                        py,
                        "unit",
                        "diagnose(..., fit=r) diagnoses the fit's own calibrated unit (r.unit) \
                         with its calibrated set re-freed: leave unit out (or pass r.unit), as the \
                         command line's --fit, which conflicts with --unit",
                    ));
                }
            }
            (Source::Loaded(f.unit.clone()), f.calibrated_set.clone())
        }
    };
    let unit_path: Option<PathBuf> = match &unit_src {
        Source::Path(p) => Some(p.clone()),
        Source::Loaded(_) => None,
    };
    // Cause files written by the user (`diagnose --user-cause`): a path or a list of paths.
    let user_paths: Vec<PathBuf> = match user_causes {
        None => vec![],
        Some(a) if a.is_none() => vec![],
        Some(a) => match a.extract::<PathBuf>() {
            Ok(p) => vec![p],
            Err(_) => a.extract::<Vec<PathBuf>>().map_err(|_| {
                PyTypeError::new_err("user_causes must be None, a path or a list of paths")
            })?,
        },
    };
    let request = DiagnoseRequest {
        mode,
        causes: cause_list(causes)?,
        user_causes: user_paths,
        refit: refit_list(refit)?,
        look_alikes,
        search: Search {
            seed,
            particles,
            pso_iterations,
            local_iterations,
            threads,
        },
    };
    request.search.validate().map_err(request_error)?;
    let events = event_sources(events, "events")?;
    let held_out = match held_out {
        Some(h) if !h.is_none() => event_sources(h, "held_out")?,
        _ => vec![],
    };
    let pool = worker_pool(threads)?;
    let prepared = py.detach(move || {
        Failure::catch("diagnose", || {
            let unit = match unit_src {
                Source::Loaded(u) => Arc::unwrap_or_clone(u),
                Source::Path(p) => job::load_unit(&p)?.unit,
            };
            let events = load_events(events)?;
            let held_out = load_events(held_out)?;
            let (opts, warnings) = job::prepare_diagnose(
                &unit,
                unit_path.as_deref(),
                &events,
                &held_out,
                &request,
                &calibrated_set,
            )?;
            Ok((unit, events, held_out, opts, warnings))
        })
    });
    let (unit, events, held_out, mut opts, warnings) = prepared.map_err(|e| e.into_pyerr(py))?;
    crate::errors::warn_all(py, &warnings)?;
    let cancel = Arc::new(AtomicBool::new(false));
    opts.cancel = Some(cancel.clone());
    // Ctrl-C stops the re-fits at their next candidate evaluation: KeyboardInterrupt, nothing
    // kept (a verdict needs every cause).
    let result = interrupt::interruptible(py, Some(cancel), move || {
        Failure::catch("diagnose", || {
            let run = || job::run_diagnose(&unit, &events, &held_out, &opts, warnings, &Silent);
            match pool {
                Some(pool) => pool.install(run),
                None => run(),
            }
        })
    })?;
    let run = result.map_err(|e| e.into_pyerr(py))?;
    let report = serde_json::to_value(&run.report)
        .map_err(|e| PyRuntimeError::new_err(format!("diagnosis report: {e}")))?;
    Ok(PyDiagnosis {
        report,
        extended_unit: run.extended_unit.clone().map(Arc::new),
        before: run.before.clone(),
        after: run.after.clone(),
        run: Arc::new(run),
    })
}

/// The diagnosis catalog (the registry `diagnose`, `synth(hide=...)` and the command line's
/// `--cause` use): a list of dicts with id, title, signature (what the cause looks like in the
/// residual evidence), extension (the model extension re-fitted for it) and key_params.
#[pyfunction]
pub(crate) fn causes<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for c in catalog::CAUSES {
        let info = c.info();
        let d = PyDict::new(py);
        d.set_item("id", info.id)?;
        d.set_item("title", info.title)?;
        d.set_item("signature", info.signature)?;
        d.set_item("extension", info.extension)?;
        d.set_item("key_params", info.key_params.to_vec())?;
        out.append(d)?;
    }
    Ok(out)
}

/// `{event name: {"time_s": array, column: array}}`.
fn traces_by_event<'py>(
    py: Python<'py>,
    traces: &[(String, Traces)],
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (e, t) in traces {
        d.set_item(e, traces_dict(py, t)?)?;
    }
    Ok(d)
}
