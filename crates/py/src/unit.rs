//! `Unit` and `load_unit`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use pyo3::prelude::*;
use pyo3::types::PyDict;

use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::errors::{Failure, IntoPyErr};

/// A generating-unit model (machine, exciter, stabiliser, governor, further blocks).
///
/// Read with `load_unit(path)`. Parameters are per unit on `machine_mva` (or in the unit each
/// model's documentation gives, see `models()`).
#[pyclass(name = "Unit", module = "itaipu_calib", frozen)]
pub(crate) struct PyUnit {
    pub(crate) inner: Arc<Unit>,
    /// The file it was read from (None for a unit made by `fit`).
    pub(crate) path: Option<PathBuf>,
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
            .map_err(|e| Failure::from(e).into_pyerr(py))
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

/// Reads a unit model file: a unit TOML file, or a PSS/E `.dyr` with its bases in
/// `<stem>.bases.toml` beside it (the reader's warnings issued as ItaipuWarning). Raises
/// UnitModelError.
#[pyfunction]
pub(crate) fn load_unit(py: Python<'_>, path: PathBuf) -> PyResult<PyUnit> {
    let loaded = py
        .detach(|| Failure::catch("load_unit", || itaipu_calib::job::load_unit(&path)))
        .map_err(|e| e.into_pyerr(py))?;
    let cat = py.get_type::<crate::errors::ItaipuWarning>();
    for w in &loaded.warnings {
        let msg =
            std::ffi::CString::new(w.replace('\0', " ")).unwrap_or_else(|_| c"warning".to_owned());
        PyErr::warn(py, &cat, &msg, 1)?;
    }
    Ok(PyUnit {
        inner: Arc::new(loaded.unit),
        path: Some(path),
    })
}
