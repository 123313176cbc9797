//! `Event`, `load_event` and `check`.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use itaipu_calib::job::load_unit as read_unit_any;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{check_event, check_unit, Finding, Severity};
use itaipu_dynamics::unit::Unit;

use crate::args::{array, source, Source};
use crate::errors::{Failure, IntoPyErr};
use crate::unit::PyUnit;

/// A measured event: the PMU record played back into a unit, with its bases and windows.
///
/// Read with `load_event(path)`. Arrays are copies (numpy float64). P and Q are per unit on
/// `system_mva`, generator convention; |V| in pu; the angle in rad, unwrapped, in the
/// nominal-frequency PMU frame. `record` holds the samples inside the playback window only.
#[pyclass(name = "Event", module = "itaipu_calib", frozen)]
pub(crate) struct PyEvent {
    pub(crate) inner: Arc<Event>,
    /// The import's report as JSON text (`import.json`), for an event made by `import_pmu`.
    pub(crate) import_report: Option<Arc<String>>,
}

impl PyEvent {
    /// An event read or built in memory (not imported).
    pub(crate) fn new(e: Event) -> Self {
        PyEvent {
            inner: Arc::new(e),
            import_report: None,
        }
    }
}

#[pymethods]
impl PyEvent {
    /// What `import_pmu` reported (the command line's `import.json`: format, samples read, kept
    /// and declared, gaps, dropouts, warnings, channels, rates, onset) as a dict; None for an
    /// event that was not imported.
    #[getter]
    fn import_report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.import_report
            .as_ref()
            .map(|j| py.import("json")?.call_method1("loads", (j.as_str(),)))
            .transpose()
    }
    /// What the import found wrong with the recording that the record no longer shows (a data
    /// file shorter than its header declares), one line each: every command using the event
    /// warns of them again (`import_notes` in the event file).
    #[getter]
    fn import_notes(&self) -> Vec<String> {
        self.inner.import_notes.clone()
    }
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
    /// Cut-off [Hz] of the zero-phase low-pass the playback applies to the recorded |V| and
    /// angle between their discontinuities (`input_lowpass_hz` in the event file; 4.0 by default
    /// for a phasor record with uniform time stamps), or None: played back as recorded.
    #[getter]
    fn input_lowpass_hz(&self) -> Option<f64> {
        self.inner.input_lowpass_hz
    }

    /// This event with its |V| and angle played back low-passed at `hz` between their
    /// discontinuities (None: as recorded), as `input_lowpass_hz` in the event file. Raises
    /// ValueError for a cut-off not between 0 and the Nyquist frequency or a record whose time
    /// stamps are not uniform within 1 %.
    #[pyo3(signature = (hz))]
    fn with_input_lowpass(&self, py: Python<'_>, hz: Option<f64>) -> PyResult<PyEvent> {
        let mut e = (*self.inner).clone();
        e.set_input_lowpass(hz)
            .map_err(|err| crate::errors::usage_error(py, "hz", &err.to_string()))?;
        Ok(PyEvent {
            inner: Arc::new(e),
            import_report: self.import_report.clone(),
        })
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
pub(crate) fn load_event(py: Python<'_>, path: PathBuf) -> PyResult<PyEvent> {
    py.detach(|| Event::from_toml_file(&path))
        .map(PyEvent::new)
        .map_err(|e| Failure::from(e).into_pyerr(py))
}

/// The plausibility layer (the checks `simulate`, `fit` and `diagnose` of the command line run
/// on every event, and on the unit's parameters): a list of findings, each a dict with
/// `severity` ("error": the command line stops with exit 3; "warning"), `kind` (`time_gap`,
/// `dropout`, `angle_radians`, `frequency`, `time_scale`, `absorbing_p`, `above_rating`,
/// `absurd_value`, `spike`, `parameter_range`, `saturation`), `file`, `line` (CSV line, or
/// None), `time_s`, `column`, `message` and `fix`. `unit` (optional) gives the rating the P and
/// Q checks use and has its parameters checked against the library's ranges (and its machine's
/// saturation data: S(1.2) <= S(1.0) is no curve). Empty when nothing is implausible.
/// Raises EventError or UnitModelError when a path given does not read.
#[pyfunction]
#[pyo3(signature = (event, unit = None))]
pub(crate) fn check<'py>(
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
                Some((None, p)) => Some((Arc::new(read_unit_any(&p)?.unit), p)),
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
