//! Python bindings for `itaipu-dynamics` and `itaipu-calib`: the compiled module
//! `itaipu_calib._core`.
//!
//! Thin glue only: every computation, check and message lives in the Rust crates. This file
//! converts arguments, releases the GIL while simulating and fitting, turns results into numpy
//! arrays and dicts, and maps the typed Rust errors onto a small Python exception hierarchy whose
//! messages are exactly the Rust `Display` text (what the CLI prints after `error: `).
//!
//! The pure-Python package (`python/itaipu_calib/__init__.py`) re-exports everything from here.

mod cli;
mod ecosys;
mod interrupt;
mod pandas;
mod params;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

use numpy::PyArray1;
use pyo3::exceptions::{
    PyAttributeError, PyDeprecationWarning, PyException, PyKeyError, PyKeyboardInterrupt,
    PyRuntimeError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use pyo3::{create_exception, PyTypeInfo};

use itaipu_calib::diagnose::{self as calib_diagnose, catalog, DiagnoseError, DiagnoseOptions};
use itaipu_calib::fit::{self as calib_fit, FitError, FitOptions, FitReport, Silent, StageOutput};
use itaipu_calib::spec::{CalibSpec, SpecError, Strategy, STAGES};
use itaipu_dynamics::block::Dir;
use itaipu_dynamics::event::{Event, EventError as RsEventError};
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::plausibility::{check_event, check_unit, Finding, Severity};
use itaipu_dynamics::registry::MODELS;
use itaipu_dynamics::simulate::{SimError, SimOptions, Traces};
use itaipu_dynamics::unit::{Unit, UnitError};
use itaipu_dynamics::unit_file::{read_unit, unit_to_toml, UnitFileError};

// -------------------------------------------------------------------------------------------
// Exceptions
// -------------------------------------------------------------------------------------------

create_exception!(
    itaipu_calib,
    ItaipuError,
    PyException,
    "Base class of every itaipu_calib error. `str(e)` is the Rust error message (the text the \
     command line prints); `e.kind` is a short stable identifier of the error variant where the \
     Rust error defines one (EventError, UnitModelError), otherwise None."
);
create_exception!(
    itaipu_calib,
    EventError,
    ItaipuError,
    "Bad event data: the event TOML file or its CSV recording (kind: e.g. 'io', 'unknown_column')."
);
create_exception!(
    itaipu_calib,
    UnitModelError,
    ItaipuError,
    "Bad unit model file (kind: 'io', 'syntax', 'field', 'model' or 'wiring')."
);
create_exception!(
    itaipu_calib,
    InitError,
    ItaipuError,
    "The unit cannot initialise at the event's measured operating point (or the unit and the \
     event have different nominal frequencies)."
);
create_exception!(
    itaipu_calib,
    SimulationError,
    ItaipuError,
    "The time integration failed."
);
create_exception!(
    itaipu_calib,
    CalibrationError,
    ItaipuError,
    "Bad calibration spec, or a fit or diagnosis that cannot run (kind: 'io', 'syntax', 'missing' \
     or 'field' for the spec file; 'spec', 'stage' or 'setup' for the fit; 'setup' for a \
     diagnosis, e.g. an unknown cause)."
);

/// A failure inside the GIL-free part of a call, converted to a Python exception afterwards.
enum Failure {
    Event(RsEventError),
    Unit(UnitFileError),
    Sim(SimError),
    Spec(SpecError),
    Fit(FitError),
    Diagnose(DiagnoseError),
    /// A bad argument found while running (ValueError).
    Value(String),
    /// The unit cannot initialise (InitError, kind 'init').
    Init(String),
    /// A parameter edit the library refused (UnitModelError, kind 'unknown_param' or
    /// 'bad_param').
    UnitEdit(UnitError),
}

impl From<RsEventError> for Failure {
    fn from(e: RsEventError) -> Self {
        Failure::Event(e)
    }
}
impl From<UnitFileError> for Failure {
    fn from(e: UnitFileError) -> Self {
        Failure::Unit(e)
    }
}
impl From<SimError> for Failure {
    fn from(e: SimError) -> Self {
        Failure::Sim(e)
    }
}
impl From<SpecError> for Failure {
    fn from(e: SpecError) -> Self {
        Failure::Spec(e)
    }
}
impl From<FitError> for Failure {
    fn from(e: FitError) -> Self {
        Failure::Fit(e)
    }
}
impl From<DiagnoseError> for Failure {
    fn from(e: DiagnoseError) -> Self {
        Failure::Diagnose(e)
    }
}

/// An exception of type `T` with message `msg` and attribute `kind`.
fn raise<T: PyTypeInfo>(py: Python<'_>, msg: String, kind: Option<&'static str>) -> PyErr {
    let err = PyErr::new::<T, _>(msg);
    // Setting an attribute on a fresh exception instance cannot fail in practice; if it did,
    // the class attribute `kind = None` still answers.
    let _ = err.value(py).setattr("kind", kind);
    err
}

impl Failure {
    fn into_pyerr(self, py: Python<'_>) -> PyErr {
        match self {
            Failure::Event(e) => raise::<EventError>(py, e.to_string(), Some(e.kind())),
            Failure::Unit(e) => raise::<UnitModelError>(py, e.to_string(), Some(e.kind())),
            Failure::Sim(e @ (SimError::Init(_) | SimError::Frequency { .. })) => {
                raise::<InitError>(py, e.to_string(), Some(e.kind()))
            }
            Failure::Sim(e @ SimError::Solve(_)) => {
                raise::<SimulationError>(py, e.to_string(), Some(e.kind()))
            }
            Failure::Spec(e) => raise::<CalibrationError>(py, e.to_string(), Some(e.kind())),
            Failure::Fit(e) => raise::<CalibrationError>(py, e.to_string(), Some(e.kind())),
            Failure::Diagnose(e @ DiagnoseError::Setup(_)) => {
                raise::<CalibrationError>(py, e.to_string(), Some(e.kind()))
            }
            Failure::Diagnose(e @ DiagnoseError::Simulation { .. }) => {
                raise::<SimulationError>(py, e.to_string(), Some(e.kind()))
            }
            // Only after a signal, which `interrupt::interruptible` raises first.
            Failure::Diagnose(e @ DiagnoseError::Interrupted { .. }) => {
                PyKeyboardInterrupt::new_err(e.to_string())
            }
            Failure::UnitEdit(e) => raise::<UnitModelError>(py, e.to_string(), Some(e.kind())),
            Failure::Value(msg) => PyValueError::new_err(msg),
            Failure::Init(msg) => raise::<InitError>(py, msg, Some("init")),
        }
    }
}

// -------------------------------------------------------------------------------------------
// Helpers
// -------------------------------------------------------------------------------------------

fn array<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v)
}

/// An event or unit argument: an already loaded object, or a path to load (without the GIL).
enum Source<T> {
    Loaded(Arc<T>),
    Path(PathBuf),
}

fn source<'py, C, T>(
    arg: &Bound<'py, PyAny>,
    what: &str,
    inner: impl Fn(&C) -> Arc<T>,
) -> PyResult<Source<T>>
where
    C: pyo3::PyClass<Frozen = pyo3::pyclass::boolean_struct::True> + Sync,
{
    if let Ok(obj) = arg.downcast::<C>() {
        return Ok(Source::Loaded(inner(obj.get())));
    }
    match arg.extract::<PathBuf>() {
        Ok(p) => Ok(Source::Path(p)),
        Err(_) => {
            let ty = arg
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_else(|_| "?".into());
            Err(PyTypeError::new_err(format!(
                "{what} must be a path (str or os.PathLike) or an {} object, not {ty}",
                C::NAME
            )))
        }
    }
}

// -------------------------------------------------------------------------------------------
// Event
// -------------------------------------------------------------------------------------------

/// A measured event: the PMU record played back into a unit, with its bases and windows.
///
/// Read with `load_event(path)`. Arrays are copies (numpy float64). P and Q are per unit on
/// `system_mva`, generator convention; |V| in pu; the angle in rad, unwrapped, in the
/// nominal-frequency PMU frame. `record` holds the samples inside the playback window only.
#[pyclass(name = "Event", module = "itaipu_calib", frozen)]
struct PyEvent {
    inner: Arc<Event>,
}

#[pymethods]
impl PyEvent {
    /// Short identifier (`name` in the event file).
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }
    /// Free text ('' if not given).
    #[getter]
    fn description(&self) -> &str {
        &self.inner.description
    }
    /// MVA base of p_pu and q_pu.
    #[getter]
    fn system_mva(&self) -> f64 {
        self.inner.system_mva
    }
    /// Nominal frequency of the grid and of the PMU reference frame, Hz.
    #[getter]
    fn nominal_hz(&self) -> f64 {
        self.inner.nominal_hz
    }
    /// The event TOML file (pathlib.Path).
    #[getter]
    fn toml_path(&self) -> Option<PathBuf> {
        self.inner.toml_path.clone()
    }
    /// The CSV recording (pathlib.Path).
    #[getter]
    fn csv_path(&self) -> PathBuf {
        self.inner.csv_path.clone()
    }
    /// Playback window `(start_s, end_s)`.
    #[getter]
    fn playback(&self) -> (f64, f64) {
        (self.inner.playback.start_s, self.inner.playback.end_s)
    }
    /// Pre-event (init) window `(start_s, end_s)` used by `operating_point()`.
    #[getter]
    fn init(&self) -> (f64, f64) {
        (self.inner.init.start_s, self.inner.init.end_s)
    }
    /// Fit window `(start_s, end_s)`.
    #[getter]
    fn fit(&self) -> (f64, f64) {
        (self.inner.fit.start_s, self.inner.fit.end_s)
    }
    /// Sample times, s.
    #[getter]
    fn time_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.record.time_s)
    }
    /// Terminal-voltage magnitude, pu.
    #[getter]
    fn v_mag_pu<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.record.v_mag_pu)
    }
    /// Terminal-voltage angle, rad (unwrapped, nominal-frequency frame).
    #[getter]
    fn v_ang_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.record.v_ang_rad)
    }
    /// Measured active power, pu on `system_mva` (generator convention).
    #[getter]
    fn p_pu<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.record.p_pu)
    }
    /// Measured reactive power, pu on `system_mva` (generator convention).
    #[getter]
    fn q_pu<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.record.q_pu)
    }
    /// Measured frequency, Hz, or None if the record has no `freq_hz` column.
    #[getter]
    fn freq_hz<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.record.freq_hz.as_deref().map(|v| array(py, v))
    }
    /// Measured field voltage, pu, or None.
    #[getter]
    fn efd_pu<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.record.efd_pu.as_deref().map(|v| array(py, v))
    }
    /// Measured field current, pu, or None.
    #[getter]
    fn ifd_pu<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.record.ifd_pu.as_deref().map(|v| array(py, v))
    }

    /// Pre-event operating point on the SYSTEM base, estimated over the init window: a dict
    /// with v_mag_pu, v_ang_rad (at t0_s), p_pu, q_pu, freq_hz, t0_s, n_samples.
    fn operating_point<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let op = self.inner.operating_point();
        let d = PyDict::new(py);
        d.set_item("v_mag_pu", op.v_mag_pu)?;
        d.set_item("v_ang_rad", op.v_ang_rad)?;
        d.set_item("p_pu", op.p_pu)?;
        d.set_item("q_pu", op.q_pu)?;
        d.set_item("freq_hz", op.freq_hz)?;
        d.set_item("t0_s", op.t0_s)?;
        d.set_item("n_samples", op.n_samples)?;
        Ok(d)
    }

    /// Number of samples in the playback record.
    fn __len__(&self) -> usize {
        self.inner.record.time_s.len()
    }

    fn __repr__(&self) -> String {
        let e = &self.inner;
        format!(
            "<Event '{}': {} samples, {} .. {} s, system_mva={}, nominal_hz={}>",
            e.name,
            e.record.time_s.len(),
            e.playback.start_s,
            e.playback.end_s,
            e.system_mva,
            e.nominal_hz
        )
    }
}

/// Reads an event file (TOML naming the CSV recording, the system base, the nominal frequency
/// and the windows) and validates it. Raises EventError.
#[pyfunction]
fn load_event(py: Python<'_>, path: PathBuf) -> PyResult<PyEvent> {
    py.detach(|| Event::from_toml_file(&path))
        .map(|e| PyEvent { inner: Arc::new(e) })
        .map_err(|e| Failure::from(e).into_pyerr(py))
}

/// The plausibility layer (the checks `simulate`, `fit` and `diagnose` of the command line run
/// on every event, and on the unit's parameters): a list of findings, each a dict with
/// `severity` ("error": the command line stops with exit 3; "warning"), `kind` (`time_gap`,
/// `dropout`, `angle_radians`, `frequency`, `time_scale`, `absorbing_p`, `above_rating`,
/// `absurd_value`, `spike`, `parameter_range`), `file`, `line` (CSV line, or None), `time_s`,
/// `column`, `message` and `fix`. `unit` (optional) gives the rating the P and Q checks use and
/// has its parameters checked against the library's ranges. Empty when nothing is implausible.
/// Raises EventError or UnitModelError when a path given does not read.
#[pyfunction]
#[pyo3(signature = (event, unit = None))]
fn check<'py>(
    py: Python<'py>,
    event: &Bound<'py, PyAny>,
    unit: Option<&Bound<'py, PyAny>>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let event = source::<PyEvent, _>(event, "event", |e| e.inner.clone())?;
    // The unit (None: read it from the path) and the file its findings name.
    let unit: Option<(Option<Arc<Unit>>, PathBuf)> = unit
        .map(|u| {
            source::<PyUnit, _>(u, "unit", |u| u.inner.clone()).map(|src| match src {
                Source::Loaded(inner) => {
                    let path = u
                        .downcast::<PyUnit>()
                        .ok()
                        .and_then(|o| o.get().path.clone())
                        .unwrap_or_else(|| PathBuf::from(format!("<unit '{}'>", inner.name)));
                    (Some(inner), path)
                }
                Source::Path(p) => (None, p),
            })
        })
        .transpose()?;
    let findings = py
        .detach(move || -> Result<Vec<Finding>, Failure> {
            let event = match event {
                Source::Loaded(e) => e,
                Source::Path(p) => Arc::new(Event::from_toml_file(&p)?),
            };
            let unit = match unit {
                None => None,
                Some((Some(u), p)) => Some((u, p)),
                Some((None, p)) => Some((Arc::new(read_unit(&p)?), p)),
            };
            let mut out = check_event(&event, unit.as_ref().map(|(u, _)| u.machine_mva));
            if let Some((u, p)) = &unit {
                out.extend(check_unit(u, p));
            }
            Ok(out)
        })
        .map_err(|e| e.into_pyerr(py))?;
    findings
        .iter()
        .map(|f| {
            let d = PyDict::new(py);
            d.set_item(
                "severity",
                match f.severity {
                    Severity::Error => "error",
                    Severity::Warning => "warning",
                },
            )?;
            d.set_item("kind", f.kind)?;
            d.set_item("file", f.file.display().to_string())?;
            d.set_item("line", f.line)?;
            d.set_item("time_s", f.time_s)?;
            d.set_item("column", &f.column)?;
            d.set_item("message", &f.message)?;
            d.set_item("fix", &f.fix)?;
            Ok(d)
        })
        .collect()
}

// -------------------------------------------------------------------------------------------
// Unit
// -------------------------------------------------------------------------------------------

/// A generating-unit model (machine, exciter, stabiliser, governor, further blocks).
///
/// Read with `load_unit(path)`. Parameters are per unit on `machine_mva` (or in the unit each
/// model's documentation gives, see `models()`).
#[pyclass(name = "Unit", module = "itaipu_calib", frozen)]
struct PyUnit {
    inner: Arc<Unit>,
    /// The file it was read from (None for a unit made by `fit`).
    path: Option<PathBuf>,
}

#[pymethods]
impl PyUnit {
    /// Unit name.
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }
    /// Free text ('' if not given).
    #[getter]
    fn description(&self) -> &str {
        &self.inner.description
    }
    /// Machine base, MVA.
    #[getter]
    fn machine_mva(&self) -> f64 {
        self.inner.machine_mva
    }
    /// The unit file it was read from (pathlib.Path), or None (e.g. `FitResult.unit`).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }
    /// Nominal frequency, Hz.
    #[getter]
    fn nominal_hz(&self) -> f64 {
        self.inner.nominal_hz
    }

    /// Every parameter as an ordered dict `{"block.name": value}` with canonical names,
    /// e.g. `{"machine.h": 4.5, "exciter.k": 100.0, ...}`, in state order of the blocks.
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (path, _, value) in self.inner.params() {
            d.set_item(path, value)?;
        }
        Ok(d)
    }

    /// Model names of the blocks in state order, e.g. `["GENSAE", "SEXS", "STAB3", "constant_pm"]`.
    fn models(&self) -> Vec<&'static str> {
        self.inner
            .instances()
            .iter()
            .map(|i| i.block.model())
            .collect()
    }

    /// Block instance names mapped to their model, e.g. `{"machine": "GENSAE", ...}`.
    fn blocks<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for i in self.inner.instances() {
            d.set_item(&i.name, i.block.model())?;
        }
        Ok(d)
    }

    /// The unit as unit-file TOML text (every parameter, with its unit and meaning as a comment).
    fn to_toml(&self) -> String {
        unit_to_toml(&self.inner)
    }

    /// A new Unit with the parameters of `values` (`{"block.name": value}`, canonical names or
    /// PSS/E aliases) set; this one is unchanged. Checked by the library as a unit file is:
    /// an unknown parameter (kind 'unknown_param') or a value outside the model's domain (a
    /// time constant <= 0, X'd above Xd, not finite: kind 'bad_param') raises UnitModelError
    /// naming the parameter. The new unit keeps `path` (its file's [calibration] table still
    /// applies to `fit`).
    fn with_params(&self, py: Python<'_>, values: BTreeMap<String, f64>) -> PyResult<PyUnit> {
        let values: Vec<(String, f64)> = values.into_iter().collect();
        self.inner
            .with_params(&values)
            .map(|u| PyUnit {
                inner: Arc::new(u),
                path: self.path.clone(),
            })
            .map_err(|e| Failure::UnitEdit(e).into_pyerr(py))
    }

    fn __repr__(&self) -> String {
        let u = &self.inner;
        format!(
            "<Unit '{}': {}, machine_mva={}, nominal_hz={}>",
            u.name,
            self.models().join(" + "),
            u.machine_mva,
            u.nominal_hz
        )
    }
}

/// Reads a unit model file (TOML). Raises UnitModelError.
#[pyfunction]
fn load_unit(py: Python<'_>, path: PathBuf) -> PyResult<PyUnit> {
    py.detach(|| read_unit(&path))
        .map(|u| PyUnit {
            inner: Arc::new(u),
            path: Some(path),
        })
        .map_err(|e| Failure::from(e).into_pyerr(py))
}

// -------------------------------------------------------------------------------------------
// Traces and simulate
// -------------------------------------------------------------------------------------------

/// Result of `simulate`: one row per event sample, named columns (numpy float64 copies).
///
/// `traces["name"]` or `traces.name` gives a column; `columns` lists the names; `time_s` the
/// sample times; `len(traces)` is the number of samples. Columns: `p_pu`, `q_pu` (simulated,
/// pu on the event's system base), `p_meas_pu`, `q_meas_pu` (measured, system base),
/// `p_mach_pu`, `q_mach_pu` (simulated, machine base), every signal of the unit (`v_term`,
/// `theta_term` [rad], `delta` [rad], `speed`, `pe`, `qe`, `te`, `efd`, `pm`, `vs`, ...: machine
/// base), every state as `block.state`, and `efd_meas_pu`, `ifd_meas_pu`, `freq_meas_hz` when
/// the event has them.
#[pyclass(name = "Traces", module = "itaipu_calib", frozen)]
struct PyTraces {
    inner: Traces,
}

impl PyTraces {
    fn column(&self, name: &str) -> Option<&[f64]> {
        self.inner.get(name)
    }
}

#[pymethods]
impl PyTraces {
    /// Sample times, s.
    #[getter]
    fn time_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        array(py, &self.inner.time_s)
    }

    /// Column names (without `time_s`), in recording order.
    #[getter]
    fn columns(&self) -> Vec<String> {
        self.inner.names.clone()
    }

    /// Integrator counters: steps_accepted, steps_rejected, rhs_evals, events.
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.inner.stats;
        let d = PyDict::new(py);
        d.set_item("steps_accepted", s.steps_accepted)?;
        d.set_item("steps_rejected", s.steps_rejected)?;
        d.set_item("rhs_evals", s.rhs_evals)?;
        d.set_item("events", s.events)?;
        Ok(d)
    }

    /// `{"time_s": array, column: array, ...}` (e.g. for `pandas.DataFrame(traces.to_dict())`).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        traces_dict(py, &self.inner)
    }

    /// The traces as a pandas DataFrame indexed by `time_s`, one column per trace. Needs pandas
    /// (ImportError naming it otherwise).
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        pandas::data_frame(py, traces_dict(py, &self.inner)?.into_any(), Some("time_s"))
    }

    fn __getitem__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyArray1<f64>>> {
        if name == "time_s" {
            return Ok(array(py, &self.inner.time_s));
        }
        self.column(name)
            .map(|c| array(py, c))
            .ok_or_else(|| PyKeyError::new_err(name.to_string()))
    }

    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.column(name).map(|c| array(py, c)).ok_or_else(|| {
            PyAttributeError::new_err(format!(
                "'Traces' object has no attribute or column '{name}' (columns: {})",
                self.inner.names.join(", ")
            ))
        })
    }

    fn __contains__(&self, name: &str) -> bool {
        name == "time_s" || self.column(name).is_some()
    }

    fn __dir__(slf: &Bound<'_, Self>) -> PyResult<Vec<String>> {
        let object = slf.py().import("builtins")?.getattr("object")?;
        let mut names: Vec<String> = object.call_method1("__dir__", (slf,))?.extract()?;
        let inner = &slf.get().inner;
        names.extend(
            inner
                .names
                .iter()
                .filter(|n| n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
                .cloned(),
        );
        Ok(names)
    }

    /// Number of samples.
    fn __len__(&self) -> usize {
        self.inner.time_s.len()
    }

    fn __repr__(&self) -> String {
        let t = &self.inner.time_s;
        let (t0, t1) = (
            t.first().copied().unwrap_or(f64::NAN),
            t.last().copied().unwrap_or(f64::NAN),
        );
        format!(
            "<Traces: {} samples, {} .. {} s, {} columns>",
            t.len(),
            t0,
            t1,
            self.inner.names.len()
        )
    }
}

/// `{"time_s": array, column: array, ...}` of `t`.
fn traces_dict<'py>(py: Python<'py>, t: &Traces) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("time_s", array(py, &t.time_s))?;
    for (name, col) in t.names.iter().zip(&t.columns) {
        d.set_item(name, array(py, col))?;
    }
    Ok(d)
}

/// Plays the measured terminal voltage of `event` into `unit` and records every signal.
///
/// `event` and `unit` are paths to the TOML files (str or os.PathLike) or objects from
/// `load_event` / `load_unit`. `method` is "dopri5" (adaptive Dormand-Prince 5(4), tolerances
/// `rtol`, `atol`) or "rk4" (fixed step of at most `step` seconds). The GIL is released while
/// files are read and the model is integrated.
///
/// Raises EventError, UnitModelError, InitError, SimulationError (and ValueError for bad
/// options, TypeError for bad argument types).
#[pyfunction]
#[pyo3(signature = (event, unit, *, method = "dopri5", rtol = 1e-6, atol = 1e-7, step = 0.001))]
fn simulate(
    py: Python<'_>,
    event: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
    method: &str,
    rtol: f64,
    atol: f64,
    step: f64,
) -> PyResult<PyTraces> {
    let opts = sim_options(method, rtol, atol, step)?;
    if swapped_events_unit(py, event, unit)? {
        return Err(swap_error("simulate"));
    }
    let event = source::<PyEvent, _>(event, "event", |e| e.inner.clone())?;
    let unit = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    let result = py.detach(move || -> Result<Traces, Failure> {
        let event = match event {
            Source::Loaded(e) => e,
            Source::Path(p) => Arc::new(Event::from_toml_file(&p)?),
        };
        let unit = match unit {
            Source::Loaded(u) => u,
            Source::Path(p) => Arc::new(read_unit(&p)?),
        };
        Ok(itaipu_dynamics::simulate(&unit, &event, &opts)?)
    });
    result
        .map(|t| PyTraces { inner: t })
        .map_err(|e| e.into_pyerr(py))
}

/// Integrator options, checked as the command line checks them.
fn sim_options(method: &str, rtol: f64, atol: f64, step: f64) -> PyResult<SimOptions> {
    let method = match method.to_ascii_lowercase().as_str() {
        "rk4" => {
            if !(step > 0.0 && step.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "step must be > 0 (got {step})"
                )));
            }
            Method::Rk4 { h: step }
        }
        "dopri5" => {
            if !(rtol > 0.0 && atol >= 0.0) {
                return Err(PyValueError::new_err(format!(
                    "rtol must be > 0 and atol >= 0 (got rtol={rtol}, atol={atol})"
                )));
            }
            // Everything but the tolerances as in the library's default options.
            let base = match SimOptions::default().method {
                Method::Dopri5(o) => o,
                Method::Rk4 { .. } => Dopri5Options::default(),
            };
            Method::Dopri5(Dopri5Options { rtol, atol, ..base })
        }
        _ => {
            return Err(PyValueError::new_err(format!(
                "method must be 'dopri5' or 'rk4' (got '{method}')"
            )))
        }
    };
    Ok(SimOptions { method })
}

// -------------------------------------------------------------------------------------------
// Fit
// -------------------------------------------------------------------------------------------

/// Result of `fit`: the report, the calibrated unit, and per stage its parameters and traces.
///
/// `report` is the fit report as a dict (the `report.json` of the command line: a new dict on
/// each access; non-finite numbers such as an undetermined standard error are None). `unit` is
/// the calibrated full unit. `stages` lists the stages run, in order (`gen`, `avr`, `pss`, `tg`,
/// and `joint` for the final joint polish, `simultaneous` first with that strategy).
/// `parameters(stage)` gives a stage's calibrated free parameters, `fitness` the fitness table of
/// the command line, `traces(stage)` the start and calibrated traces of a stage.
#[pyclass(name = "FitResult", module = "itaipu_calib", frozen)]
struct PyFitResult {
    report: FitReport,
    report_json: String,
    unit: Arc<Unit>,
    stages: Vec<StageOutput>,
    /// The calibrated set with the calibration's prior, for `diagnose(..., fit=...)`.
    calibrated_set: Vec<catalog::FreeBound>,
}

impl PyFitResult {
    fn unknown_stage(&self, stage: &str) -> PyErr {
        let names: Vec<&str> = self.stages.iter().map(|s| s.stage.as_str()).collect();
        PyKeyError::new_err(format!(
            "no stage '{stage}' in this fit (stages: {})",
            names.join(", ")
        ))
    }

    /// J = Σ(ΔP² + ΔQ²) summed over the fitted (not held-out) events.
    fn j_fitted(rows: &[calib_fit::EventFitness]) -> f64 {
        rows.iter().filter(|f| !f.held_out).map(|f| f.j_pq).sum()
    }
}

#[pymethods]
impl PyFitResult {
    /// The fit report as a dict (unit, events, held_out, strategy, seed, threads,
    /// start_fitness, stages: list of stage reports with parameters, objective_before/after,
    /// fitness, phases, identifiability, ...; wall_s).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?
            .call_method1("loads", (&self.report_json,))
    }

    /// The calibrated full unit (every block, with every stage's results).
    #[getter]
    fn unit(&self) -> PyUnit {
        PyUnit {
            inner: self.unit.clone(),
            path: None,
        }
    }

    /// Names of the stages run, in order.
    #[getter]
    fn stages(&self) -> Vec<String> {
        self.stages.iter().map(|s| s.stage.clone()).collect()
    }

    /// Calibrated values of the free parameters of `stage`: `{"block.name": value}` in the
    /// spec's order. Raises KeyError for a stage that did not run.
    fn parameters<'py>(&self, py: Python<'py>, stage: &str) -> PyResult<Bound<'py, PyDict>> {
        let rep = self
            .report
            .stages
            .iter()
            .find(|s| s.stage == stage)
            .ok_or_else(|| self.unknown_stage(stage))?;
        let d = PyDict::new(py);
        for p in &rep.parameters {
            d.set_item(&p.param, p.result)?;
        }
        Ok(d)
    }

    /// The fitness table of the command line: `[("start", J), (stage, J), ...]` with
    /// J = Σ(ΔP² + ΔQ²) over the fit window on the system base (RaPId's J), summed over the
    /// fitted events (per-event and held-out values are in `report`).
    #[getter]
    fn fitness(&self) -> Vec<(String, f64)> {
        let mut rows = vec![(
            "start".to_string(),
            Self::j_fitted(&self.report.start_fitness),
        )];
        rows.extend(
            self.report
                .stages
                .iter()
                .map(|s| (s.stage.clone(), Self::j_fitted(&s.fitness))),
        );
        rows
    }

    /// `(start, calibrated)`: Traces of the stage's unit before and after the stage, on the
    /// first fitted event or on the event named `event`. Raises KeyError for an unknown stage or
    /// event.
    #[pyo3(signature = (stage, event = None))]
    fn traces(&self, stage: &str, event: Option<&str>) -> PyResult<(PyTraces, PyTraces)> {
        let st = self
            .stages
            .iter()
            .find(|s| s.stage == stage)
            .ok_or_else(|| self.unknown_stage(stage))?;
        let found = match event {
            None => st.traces.first(),
            Some(name) => st.traces.iter().find(|(e, _, _)| e == name),
        };
        let (_, start, end) = found.ok_or_else(|| {
            let names: Vec<&str> = st.traces.iter().map(|(e, _, _)| e.as_str()).collect();
            PyKeyError::new_err(format!(
                "no event '{}' in this fit (events: {})",
                event.unwrap_or(""),
                names.join(", ")
            ))
        })?;
        Ok((
            PyTraces {
                inner: start.clone(),
            },
            PyTraces { inner: end.clone() },
        ))
    }

    /// lmfit-like parameter objects `{name: Parameter}` (value, stderr, init_value, min, max,
    /// at_bound, correl, stage, units): of `stage`, or by default of the whole fit, each
    /// parameter from the last stage that freed it (the values of `unit`). Raises KeyError for
    /// a stage that did not run.
    #[pyo3(signature = (stage = None))]
    fn params<'py>(&self, py: Python<'py>, stage: Option<&str>) -> PyResult<Bound<'py, PyDict>> {
        let ps = match stage {
            None => params::final_params(&self.report.stages),
            Some(name) => params::of_stage(
                self.report
                    .stages
                    .iter()
                    .find(|s| s.stage == name)
                    .ok_or_else(|| self.unknown_stage(name))?,
            ),
        };
        params_dict(py, &ps)
    }

    /// The fit report as text (what `itaipu-calib fit` prints): per stage the phases, the
    /// parameter table (start, bounds, result, standard error, at bound), what the data do not
    /// determine; then J per event and stage. `print(result)` prints the same.
    fn fit_report(&self) -> String {
        self.report.to_text()
    }

    fn __str__(&self) -> String {
        self.report.to_text()
    }

    /// The parameters of `params()` as a pandas DataFrame indexed by name (columns stage,
    /// value, stderr (NaN: not determined), init_value, min, max, at_bound, units). Needs
    /// pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let rows = params::final_params(&self.report.stages)
            .iter()
            .map(|p| p.row(py))
            .collect::<PyResult<Vec<_>>>()?;
        pandas::data_frame(py, pandas::rows(py, rows)?, Some("name"))
    }

    fn __repr__(&self) -> String {
        let r = &self.report;
        let rows = self.fitness();
        let (j0, j1) = (
            rows.first().map_or(f64::NAN, |r| r.1),
            rows.last().map_or(f64::NAN, |r| r.1),
        );
        format!(
            "<FitResult '{}' on {}: stages {}, J {:.5} -> {:.5}, {:.1} s>",
            r.unit,
            r.events.join(", "),
            self.stages().join(" -> "),
            j0,
            j1,
            r.wall_s
        )
    }
}

/// Events from a path, an Event, or an iterable of them.
fn event_sources(arg: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Source<Event>>> {
    if arg.downcast::<PyEvent>().is_ok() || arg.extract::<PathBuf>().is_ok() {
        return Ok(vec![source::<PyEvent, _>(arg, what, |e| e.inner.clone())?]);
    }
    match arg.try_iter() {
        Ok(items) => items
            .enumerate()
            .map(|(k, item)| {
                source::<PyEvent, _>(&item?, &format!("{what}[{k}]"), |e| e.inner.clone())
            })
            .collect(),
        Err(_) => {
            let ty = arg
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_else(|_| "?".into());
            Err(PyTypeError::new_err(format!(
                "{what} must be a path (str or os.PathLike), an Event object, or a list of them, not {ty}"
            )))
        }
    }
}

/// Whether `(events, unit)` came in the order `(unit, events)`: a Unit object first, an Event
/// or a list of events second, or two paths of which the first reads as a unit file and the
/// second does not (a unit file is small: this reads no recording).
fn swapped_events_unit(
    py: Python<'_>,
    events: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
) -> PyResult<bool> {
    if events.downcast::<PyUnit>().is_ok() || unit.downcast::<PyEvent>().is_ok() {
        return Ok(true);
    }
    if unit.downcast::<PyUnit>().is_ok() || events.downcast::<PyEvent>().is_ok() {
        return Ok(false);
    }
    let (Ok(first), Ok(second)) = (events.extract::<PathBuf>(), unit.extract::<PathBuf>()) else {
        // A list second (events) with a path or Unit first.
        return Ok(unit.extract::<PathBuf>().is_err()
            && unit.downcast::<PyUnit>().is_err()
            && unit.try_iter().is_ok());
    };
    Ok(py.detach(|| read_unit(&first).is_ok() && read_unit(&second).is_err()))
}

/// A TypeError for `func` called with the unit first and the events second.
fn swap_error(func: &str) -> PyErr {
    PyTypeError::new_err(format!(
        "{func}: the first argument is a unit and the second an event; the order is \
         {func}(events, unit): swap them"
    ))
}

/// The stages to run from the `stages` argument, as the command line's `--stage`: "all" (None:
/// every stage the spec lists) or names among gen, avr, pss, tg (a list, or one string with
/// commas), run in that fixed order.
fn stage_list(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Vec<String>>> {
    let Some(arg) = arg else { return Ok(None) };
    let given: Vec<String> = if let Ok(s) = arg.extract::<String>() {
        vec![s]
    } else {
        arg.extract::<Vec<String>>().map_err(|_| {
            PyTypeError::new_err("stages must be 'all', a stage name, a comma-separated string or a list of stage names")
        })?
    };
    let names: Vec<String> = given
        .iter()
        .flat_map(|s| s.split(','))
        .map(|s| s.trim().to_ascii_lowercase())
        .collect();
    if names.is_empty() {
        return Err(PyValueError::new_err(
            "stages must name at least one stage (gen, avr, pss, tg) or be 'all'",
        ));
    }
    if let Some(bad) = names
        .iter()
        .find(|n| *n != "all" && !STAGES.contains(&n.as_str()))
    {
        return Err(PyValueError::new_err(format!(
            "stages: unknown stage '{bad}' (gen, avr, pss, tg or all)"
        )));
    }
    if names.iter().any(|n| n == "all") {
        return Ok(None);
    }
    Ok(Some(
        STAGES
            .iter()
            .filter(|s| names.iter().any(|n| n == *s))
            .map(|s| s.to_string())
            .collect(),
    ))
}

fn strategy(s: &str) -> PyResult<Strategy> {
    match s.to_ascii_lowercase().as_str() {
        "sequential" => Ok(Strategy::Sequential),
        "incremental" => Ok(Strategy::Incremental),
        "simultaneous-first" => Ok(Strategy::SimultaneousFirst),
        _ => Err(PyValueError::new_err(format!(
            "strategy must be 'sequential', 'incremental' or 'simultaneous-first' (got '{s}')"
        ))),
    }
}

/// The events of `Source`s, read from file where needed.
fn load_events(sources: Vec<Source<Event>>) -> Result<Vec<Event>, Failure> {
    sources
        .into_iter()
        .map(|s| match s {
            Source::Loaded(e) => Ok(Arc::unwrap_or_clone(e)),
            Source::Path(p) => Ok(Event::from_toml_file(&p)?),
        })
        .collect()
}

/// Calibrates `unit` against `events`, stage by stage (particle swarm, then L-BFGS), as the
/// command line's `fit`.
///
/// `events` (and `held_out`) are paths to event files or Event objects, or lists of them; the
/// objective sums over `events`, `held_out` events are only scored. `unit` is a path or a Unit.
/// `calib` is a file with a `[calibration]` table; by default the unit file's own (a Unit that
/// was not read from a file then needs `calib`). `stages` is "all" (every stage the spec lists)
/// or some of gen, avr, pss, tg (a list or a comma-separated string), run in that order.
/// `strategy` ('sequential', 'incremental', 'simultaneous-first'), `seed`, `particles`,
/// `pso_iterations` and `lbfgs_iterations` override the spec; `polish=False` skips the final
/// joint refinement ('joint') after several stages. Same seed, same numbers. The GIL is
/// released while files are read and the fit runs.
///
/// Raises CalibrationError (bad spec, or a fit that cannot run), EventError, UnitModelError
/// (and ValueError for bad options, TypeError for bad argument types).
#[pyfunction]
#[pyo3(
    signature = (events, unit, *, calib = None, stages = None, strategy = None, seed = None, particles = None,
                 pso_iterations = None, lbfgs_iterations = None, polish = true, held_out = None),
    text_signature = "(events, unit, *, calib=None, stages='all', strategy=None, seed=None, particles=None, \
                      pso_iterations=None, lbfgs_iterations=None, polish=True, held_out=())"
)]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    events: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
    calib: Option<PathBuf>,
    stages: Option<&Bound<'_, PyAny>>,
    strategy: Option<&str>,
    seed: Option<u64>,
    particles: Option<usize>,
    pso_iterations: Option<usize>,
    lbfgs_iterations: Option<u64>,
    polish: bool,
    held_out: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyFitResult> {
    if swapped_events_unit(py, events, unit)? {
        return Err(swap_error("fit"));
    }
    let events = event_sources(events, "events")?;
    let unit_src = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    let held_out = match held_out {
        Some(h) => event_sources(h, "held_out")?,
        None => vec![],
    };
    let calib = match calib {
        Some(p) => p,
        None => match &unit_src {
            Source::Path(p) => p.clone(),
            Source::Loaded(_) => unit.downcast::<PyUnit>()?.get().path.clone().ok_or_else(|| {
                PyValueError::new_err(
                    "calib is required: unit is a Unit that was not read from a file (e.g. FitResult.unit), \
                     so it has no [calibration] table; pass calib=<file with a [calibration] table>",
                )
            })?,
        },
    };
    let stages = stage_list(stages)?;
    let strategy = strategy.map(self::strategy).transpose()?;
    if let Some(n) = particles {
        if n < 2 {
            return Err(PyValueError::new_err(format!(
                "particles must be at least 2 (got {n})"
            )));
        }
    }
    // Ctrl-C (KeyboardInterrupt) stops the fit at its next candidate evaluation; the passes
    // finished by then are kept on the exception (see `fit`'s documentation).
    let cancel = Arc::new(AtomicBool::new(false));
    let worker_cancel = cancel.clone();
    let finished: Arc<Mutex<Vec<(calib_fit::StageReport, Unit)>>> = Arc::default();
    let worker_finished = finished.clone();
    let work = move || -> Result<(calib_fit::FitResult, Vec<catalog::FreeBound>), Failure> {
        let unit = match unit_src {
            Source::Loaded(u) => u,
            Source::Path(p) => Arc::new(read_unit(&p)?),
        };
        let spec = CalibSpec::from_file(&calib)?;
        let events = load_events(events)?;
        let held_out = load_events(held_out)?;
        let mut opts = FitOptions::from_spec(&spec);
        if let Some(s) = strategy {
            opts.strategy = s;
        }
        if let Some(s) = stages {
            opts.stages = s;
        }
        if let Some(s) = seed {
            opts.seed = s;
        }
        if !polish {
            opts.polish = false;
        }
        if let Some(n) = particles {
            opts.particles = n;
        }
        if let Some(n) = pso_iterations {
            opts.pso_iterations = n;
        }
        if let Some(n) = lbfgs_iterations {
            opts.lbfgs_iterations = n;
        }
        let on_stage = |rep: &calib_fit::StageReport,
                        _: &StageOutput,
                        master: &Unit|
         -> Result<(), FitError> {
            if let Ok(mut f) = worker_finished.lock() {
                f.push((rep.clone(), master.clone()));
            }
            Ok(())
        };
        let control = calib_fit::FitControl {
            cancel: Some(worker_cancel),
            on_stage: Some(&on_stage),
            ..Default::default()
        };
        let mut result =
            calib_fit::fit_with(&unit, &spec, &events, &held_out, &opts, &Silent, &control)?;
        // As the command line's calibrated.toml.
        result.unit.description = format!(
            "{} (calibrated by itaipu-calib fit, stages {}, seed {})",
            unit.description,
            opts.stages.join("+"),
            opts.seed
        );
        let set = calib_diagnose::calibrated_set(&spec, &opts.stages, &unit, &result.unit);
        Ok((result, set))
    };
    let result = interrupt::interruptible(py, Some(cancel), work).inspect_err(|e| {
        if let Ok(f) = finished.lock() {
            let _ = keep_finished(py, e, &f);
        }
    })?;
    let (result, calibrated_set) = result.map_err(|e| e.into_pyerr(py))?;
    let report_json = serde_json::to_string(&result.report)
        .map_err(|e| PyRuntimeError::new_err(format!("fit report: {e}")))?;
    Ok(PyFitResult {
        report: result.report,
        report_json,
        unit: Arc::new(result.unit),
        stages: result.stages,
        calibrated_set,
    })
}

/// Puts what an interrupted fit finished on its KeyboardInterrupt: `finished_stages` (names,
/// in order), `unit` (the full unit after the last of them, or None), `params` (`{name:
/// Parameter}` of those stages) and `stage_reports` (their reports as dicts).
fn keep_finished(
    py: Python<'_>,
    e: &PyErr,
    finished: &[(calib_fit::StageReport, Unit)],
) -> PyResult<()> {
    let exc = e.value(py);
    let names: Vec<&str> = finished.iter().map(|(r, _)| r.stage.as_str()).collect();
    exc.setattr("finished_stages", names)?;
    exc.setattr(
        "unit",
        finished.last().map(|(_, u)| PyUnit {
            inner: Arc::new(u.clone()),
            path: None,
        }),
    )?;
    let reports: Vec<calib_fit::StageReport> = finished.iter().map(|(r, _)| r.clone()).collect();
    exc.setattr("params", params_dict(py, &params::final_params(&reports))?)?;
    let json = serde_json::to_value(&reports)
        .map_err(|e| PyRuntimeError::new_err(format!("fit report: {e}")))?;
    exc.setattr("stage_reports", json_to_py(py, &json)?)?;
    Ok(())
}

/// `{name: Parameter}` in order.
fn params_dict<'py>(py: Python<'py>, ps: &[params::PyParameter]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for p in ps {
        d.set_item(p.name(), p.clone())?;
    }
    Ok(d)
}

// -------------------------------------------------------------------------------------------
// Model library
// -------------------------------------------------------------------------------------------

/// Makes a realistic synthetic event from the engine (the same generator as
/// `itaipu-calib synth`): a grid-side voltage profile (`kind`: "dip", "frequency", "step" or
/// "ambient", the event at 1 s) played into the true `unit` (path or Unit), sampled at `rate`
/// samples/s, with white noise on P and Q (`pq_sigma` pu) and on |V| and the angle
/// (`v_sigma`), quantisation of P and Q (`quantum` pu), and optionally a hidden delay of the
/// power channels (`skew_ms`). Returns an Event (in memory; P and Q on `system_mva`, default
/// the unit's machine base). Deterministic for a seed. The GIL is released while it runs.
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
#[pyo3(signature = (unit, *, kind = "dip", duration = 20.0, rate = 60.0, system_mva = None, pq_sigma = 0.002, v_sigma = 0.0005, quantum = 0.0014, skew_ms = 0.0, seed = 1, name = None, hide = None, return_truth = false))]
#[allow(clippy::too_many_arguments)]
fn synth(
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
    use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, SynthError, VoltageProfile};
    let event_kind = match kind.to_ascii_lowercase().as_str() {
        "dip" => EventKind::FaultDip,
        "frequency" => EventKind::FrequencyExcursion,
        "step" => EventKind::VoltageStep,
        "ambient" => EventKind::Ambient,
        k => {
            return Err(PyValueError::new_err(format!(
                "kind '{k}' is not one of dip, frequency, step, ambient"
            )))
        }
    };
    if !(duration > 1.5 && duration.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "duration must exceed 1.5 s (got {duration})"
        )));
    }
    if !(10.0..=1000.0).contains(&rate) {
        return Err(PyValueError::new_err(format!(
            "rate must lie in 10-1000 samples/s (got {rate})"
        )));
    }
    for (n, v) in [
        ("pq_sigma", pq_sigma),
        ("v_sigma", v_sigma),
        ("quantum", quantum),
        ("skew_ms", skew_ms),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(PyValueError::new_err(format!("{n} must be >= 0 (got {v})")));
        }
    }
    if let Some(m) = system_mva {
        if !(m > 0.0 && m.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "system_mva must be > 0 (got {m})"
            )));
        }
    }
    let hides = match hide {
        Some(h) => hide_list(h)?,
        None => vec![],
    };
    let unit = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
    let name = name.unwrap_or_else(|| format!("synthetic-{}-{seed}", kind.to_ascii_lowercase()));
    // Not stoppable inside the library (one or two simulations): Ctrl-C raises at once and
    // the worker's result is dropped.
    let result =
        interrupt::interruptible(py, None, move || -> Result<(Event, Arc<Unit>), Failure> {
            let unit = match unit {
                Source::Loaded(u) => u,
                Source::Path(p) => Arc::new(read_unit(&p)?),
            };
            let profile = VoltageProfile::preset(event_kind, duration, rate, seed);
            let mva = system_mva.unwrap_or(unit.machine_mva);
            let synth_failure = |e: SynthError| match e {
                SynthError::Sim(e) => Failure::Sim(e),
                e => Failure::Value(e.to_string()),
            };
            let truth = if hides.is_empty() {
                unit
            } else {
                // The catalog's context comes from the truth as given on a noise-free run.
                let probe = synthesize(
                    &name,
                    &unit,
                    &profile,
                    mva,
                    &PmuNoise::none(),
                    &SimOptions::default(),
                )
                .map_err(synth_failure)?;
                Arc::new(hide_all(&unit, &probe, &hides)?)
            };
            let noise = PmuNoise {
                pq_sigma,
                v_sigma,
                angle_sigma: v_sigma,
                pq_quantum: quantum,
                pq_delay_s: skew_ms * 1e-3,
                seed,
            };
            let event = synthesize(&name, &truth, &profile, mva, &noise, &SimOptions::default())
                .map_err(synth_failure)?;
            Ok((event, truth))
        })?;
    let (event, truth) = result.map_err(|f| f.into_pyerr(py))?;
    let event = Bound::new(
        py,
        PyEvent {
            inner: Arc::new(event),
        },
    )?;
    if return_truth {
        let truth = Bound::new(
            py,
            PyUnit {
                inner: truth,
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

/// A cause to hide and its values in the order given.
type Hide = (String, Vec<(String, f64)>);

/// The `hide` argument of `synth`: a dict `{cause: {param: value}}` or a list of
/// `(cause, {param: value})` tuples or cause names.
fn hide_list(arg: &Bound<'_, PyAny>) -> PyResult<Vec<Hide>> {
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
    let check = |cause: String, vals: Vec<(String, f64)>| -> PyResult<Hide> {
        if catalog::find(&cause).is_none() {
            return Err(PyValueError::new_err(format!(
                "hide: unknown cause '{cause}' (known: {})",
                catalog::ids()
            )));
        }
        if let Some((k, x)) = vals.iter().find(|(_, x)| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "hide: '{cause}': {k} must be finite (got {x})"
            )));
        }
        Ok((cause, vals))
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

/// The truth with each cause of `hides` hidden in turn ([`catalog::hide`], the catalog's context
/// taken from `truth` on the noise-free `probe`), as the command line's `synth --hide`: only
/// the extension's parameters may be set (those it frees and those of the blocks it adds,
/// except tied ones).
fn hide_all(truth: &Unit, probe: &Event, hides: &[Hide]) -> Result<Unit, Failure> {
    let ctx = calib_diagnose::context(truth, probe).map_err(|e| {
        Failure::Init(format!(
            "the true unit does not simulate on the synthetic profile: {e}"
        ))
    })?;
    let mut unit = truth.clone();
    for (cause, values) in hides {
        let map: BTreeMap<String, f64> = values.iter().cloned().collect();
        unit = catalog::hide(cause, &unit, &ctx, &map)
            .map_err(|e| Failure::Value(format!("hide: {e}")))?
            .0;
    }
    let causes: Vec<&str> = hides.iter().map(|(c, _)| c.as_str()).collect();
    unit.description = format!(
        "{} (hidden by itaipu_calib.synth: {})",
        unit.description,
        causes.join(", ")
    );
    Ok(unit)
}

// -------------------------------------------------------------------------------------------
// Diagnose
// -------------------------------------------------------------------------------------------

/// A serde_json value as the equivalent Python object (null -> None, numbers -> int or float,
/// arrays -> lists, objects -> dicts in the JSON's key order).
fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
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
struct PyDiagnosis {
    report: serde_json::Value,
    extended_unit: Option<Arc<Unit>>,
    before: Vec<(String, Traces)>,
    after: Vec<(String, Traces)>,
}

impl PyDiagnosis {
    fn field<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, self.report.get(key).unwrap_or(&serde_json::Value::Null))
    }
}

#[pymethods]
impl PyDiagnosis {
    /// The verdict as a dict: cause, title, statement, key_parameters, gains, where.
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
        let d = PyDict::new(py);
        for (e, t) in &self.before {
            d.set_item(e, traces_dict(py, t)?)?;
        }
        Ok(d)
    }

    /// Per event name: the traces of the extended unit (empty when no cause is named).
    #[getter]
    fn traces_after<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (e, t) in &self.after {
            d.set_item(e, traces_dict(py, t)?)?;
        }
        Ok(d)
    }

    /// The candidates as a pandas DataFrame indexed by cause, in the report's order (columns
    /// title, applicable, significant, note, and the gains: delta_bic, fit_drop, held_drop, ...;
    /// NaN where a cause was not applicable). Needs pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let empty = vec![];
        let cands = self.report["candidates"].as_array().unwrap_or(&empty);
        let rows = cands
            .iter()
            .map(|c| {
                let d = PyDict::new(py);
                for key in ["cause", "title", "applicable", "significant", "note"] {
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
fn cause_list(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<String>> {
    let Some(arg) = arg else { return Ok(vec![]) };
    let given: Vec<String> = if let Ok(s) = arg.extract::<String>() {
        vec![s]
    } else {
        arg.extract::<Vec<String>>().map_err(|_| {
            PyTypeError::new_err("causes must be None, a cause id, or a list of cause ids")
        })?
    };
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
fn refit_list(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<calib_diagnose::RefitRequest>> {
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
/// particle swarm and L-BFGS and judged by its gain (ΔBIC, fitted and held-out χ²), then a
/// verdict, as the command line's `diagnose`.
///
/// `unit` is a path or a Unit; `events` and `held_out` paths to event files or Event objects,
/// or lists of them. Without `held_out`, each event is split into alternating blocks, fitted
/// and held out. `causes` (ids, see the catalog: torsional_mode, exciter_limit, saturation,
/// governor, measurement_skew, terminal_load, pss_state, oel) limits the causes tried. `seed`,
/// `particles`, `pso_iterations` and `lbfgs_iterations` set each re-fit; `threads` the worker
/// threads (default: all cores). `refit` names calibrated parameters to free again in every
/// re-fit (a list of paths, or a dict of path to (min, max)), e.g. the stage parameters a
/// calibration may have bent for the missing cause. `fit` (a FitResult, normally the one whose
/// `.unit` is diagnosed) re-frees its whole calibrated set, within the spec's bounds and with the
/// calibration's datasheet prior, as `itaipu-calib diagnose --fit`. `user_causes` (a path or a
/// list of paths) adds causes written by the user, as `itaipu-calib diagnose --user-cause`. The
/// GIL is released while it runs. Returns a Diagnosis.
///
/// Raises CalibrationError (kind 'setup': e.g. an unknown cause), SimulationError (kind
/// 'simulation': the unit does not simulate on an event as given), EventError,
/// UnitModelError; ValueError for bad options, TypeError for bad argument types.
#[pyfunction]
#[pyo3(
    signature = (events, unit, held_out = None, *, causes = None, seed = 1, particles = 16, pso_iterations = 20,
                 lbfgs_iterations = 15, threads = None, refit = None, fit = None, user_causes = None),
    text_signature = "(events, unit, held_out=None, *, causes=None, seed=1, particles=16, pso_iterations=20, \
                      lbfgs_iterations=15, threads=None, refit=None, fit=None, user_causes=None)"
)]
#[allow(clippy::too_many_arguments)]
fn diagnose(
    py: Python<'_>,
    events: &Bound<'_, PyAny>,
    unit: &Bound<'_, PyAny>,
    held_out: Option<&Bound<'_, PyAny>>,
    causes: Option<&Bound<'_, PyAny>>,
    seed: u64,
    particles: usize,
    pso_iterations: usize,
    lbfgs_iterations: u64,
    threads: Option<usize>,
    refit: Option<&Bound<'_, PyAny>>,
    fit: Option<&Bound<'_, PyAny>>,
    user_causes: Option<&Bound<'_, PyAny>>,
) -> PyResult<PyDiagnosis> {
    // The order was (unit, events) before issue 14: still accepted, with a warning.
    let (events, unit) = if swapped_events_unit(py, events, unit)? {
        PyErr::warn(
            py,
            &py.get_type::<PyDeprecationWarning>(),
            c"diagnose(unit, events) is deprecated: the order is diagnose(events, unit), as in \
              fit(events, unit) and simulate(event, unit); the two arguments were swapped",
            1,
        )?;
        (unit, events)
    } else {
        (events, unit)
    };
    let unit_src = source::<PyUnit, _>(unit, "unit", |u| u.inner.clone())?;
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
    let user_causes = calib_diagnose::user_cause::read_all(&user_paths)
        .map_err(|e| raise::<CalibrationError>(py, e.to_string(), Some("spec")))?;
    let refit = refit_list(refit)?;
    // A FitResult: its whole calibrated set is re-freed with the calibration's prior (as
    // `itaipu-calib diagnose --fit`).
    let fit_set: Vec<catalog::FreeBound> = match fit {
        Some(f) if !f.is_none() => f
            .downcast::<PyFitResult>()
            .map_err(|_| PyTypeError::new_err("fit must be a FitResult (from itaipu_calib.fit)"))?
            .get()
            .calibrated_set
            .clone(),
        _ => vec![],
    };
    let events = event_sources(events, "events")?;
    let held_out = match held_out {
        Some(h) if !h.is_none() => event_sources(h, "held_out")?,
        _ => vec![],
    };
    let causes = cause_list(causes)?;
    if particles < 2 {
        return Err(PyValueError::new_err(format!(
            "particles must be at least 2 (got {particles})"
        )));
    }
    let pool = match threads {
        None => None,
        Some(0) => return Err(PyValueError::new_err("threads must be at least 1")),
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| {
                    PyRuntimeError::new_err(format!("cannot start {n} worker threads: {e}"))
                })?,
        ),
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let mut opts = DiagnoseOptions {
        causes,
        user_causes,
        seed,
        particles,
        pso_iterations,
        lbfgs_iterations,
        cancel: Some(cancel.clone()),
        ..Default::default()
    };
    // Ctrl-C stops the re-fits at their next candidate evaluation: KeyboardInterrupt, nothing
    // kept (a verdict needs every cause).
    let result = interrupt::interruptible(
        py,
        Some(cancel),
        move || -> Result<calib_diagnose::DiagnoseResult, Failure> {
            let unit = match unit_src {
                Source::Loaded(u) => u,
                Source::Path(p) => Arc::new(read_unit(&p)?),
            };
            opts.refit = calib_diagnose::refit_bounds(&unit, &refit)?;
            for b in fit_set {
                if !opts.refit.iter().any(|r| r.param == b.param) && unit.param(&b.param).is_ok() {
                    opts.refit.push(b);
                }
            }
            let events = load_events(events)?;
            let held_out = load_events(held_out)?;
            let run = || calib_diagnose::diagnose(&unit, &events, &held_out, &opts, &Silent);
            Ok(match pool {
                Some(pool) => pool.install(run),
                None => run(),
            }?)
        },
    )?;
    let result = result.map_err(|e| e.into_pyerr(py))?;
    let report = serde_json::to_value(&result.report)
        .map_err(|e| PyRuntimeError::new_err(format!("diagnosis report: {e}")))?;
    Ok(PyDiagnosis {
        report,
        extended_unit: result.extended_unit.map(Arc::new),
        before: result.before,
        after: result.after,
    })
}

/// The diagnosis catalog (the registry `diagnose`, `synth(hide=...)` and the command line's
/// `--cause` use): a list of dicts with id, title, signature (what the cause looks like in the
/// residual evidence), extension (the model extension re-fitted for it) and key_params.
#[pyfunction]
fn causes<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
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

/// The model library (the same catalogue unit files and the command line use): a list of dicts
/// with name, role ('machine', 'exciter', 'pss', 'governor' or 'block'), summary, parameters
/// (dicts: name, alias (PSS/E), unit, doc, typical, range = (low, high)), ports (dicts: name,
/// direction 'in'/'out', doc) and states.
#[pyfunction]
fn models<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for m in MODELS {
        let block = m.create();
        let params = PyList::empty(py);
        for s in block.params().specs() {
            let p = PyDict::new(py);
            p.set_item("name", s.name)?;
            p.set_item("alias", s.alias)?;
            p.set_item("unit", s.unit)?;
            p.set_item("doc", s.doc)?;
            p.set_item("typical", s.typical)?;
            p.set_item("range", s.range)?;
            params.append(p)?;
        }
        let ports = PyList::empty(py);
        for port in block.ports() {
            let p = PyDict::new(py);
            p.set_item("name", port.name)?;
            p.set_item("direction", if port.dir == Dir::In { "in" } else { "out" })?;
            p.set_item("doc", port.doc)?;
            ports.append(p)?;
        }
        let d = PyDict::new(py);
        d.set_item("name", m.name)?;
        d.set_item("role", m.role.section())?;
        d.set_item("summary", m.summary)?;
        d.set_item("parameters", params)?;
        d.set_item("ports", ports)?;
        d.set_item("states", block.state_names().to_vec())?;
        out.append(d)?;
    }
    Ok(out)
}

/// Robust noise standard deviation of a measured signal (the fit's estimate: from its second
/// differences, so the event itself barely counts), in the signal's unit. The band the plot
/// helpers draw around a zero residual.
#[pyfunction]
fn noise_sigma(values: Vec<f64>) -> f64 {
    itaipu_calib::problem::noise_variance(&values).sqrt()
}

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
    m.add_class::<PyEvent>()?;
    m.add_class::<PyUnit>()?;
    m.add_class::<PyTraces>()?;
    m.add_class::<PyFitResult>()?;
    m.add_class::<PyDiagnosis>()?;
    m.add_function(wrap_pyfunction!(load_event, m)?)?;
    m.add_function(wrap_pyfunction!(load_unit, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(models, m)?)?;
    m.add_function(wrap_pyfunction!(causes, m)?)?;
    m.add_function(wrap_pyfunction!(synth, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(noise_sigma, m)?)?;
    m.add_function(wrap_pyfunction!(cli::_cli_main, m)?)?;
    m.add_class::<params::PyParameter>()?;
    ecosys::register(m)?;
    Ok(())
}
