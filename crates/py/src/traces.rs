//! `Traces`: simulated (and measured) time series.

use numpy::PyArray1;
use pyo3::exceptions::{PyAttributeError, PyKeyError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use itaipu_dynamics::simulate::Traces;

use crate::args::array;
use crate::pandas;

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
pub(crate) struct PyTraces {
    pub(crate) inner: Traces,
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
pub(crate) fn traces_dict<'py>(py: Python<'py>, t: &Traces) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("time_s", array(py, &t.time_s))?;
    for (name, col) in t.names.iter().zip(&t.columns) {
        d.set_item(name, array(py, col))?;
    }
    Ok(d)
}
