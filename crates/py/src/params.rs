//! lmfit-like parameter objects of a fit: one per calibrated parameter, from the stage reports
//! the library computes (value, standard error, bounds, at-bound flag, correlations).

use std::collections::BTreeMap;

use pyo3::prelude::*;

use itaipu_calib::fit::StageReport;

/// One calibrated parameter, as lmfit's `Parameter`: `name` (`block.name`), `value` (the
/// result), `stderr` (Fisher approximation; None when the data do not determine it),
/// `init_value` (the stage's start), `min`/`max` (the stage's bounds), `at_bound`, `correl`
/// (`{other: ρ}` with every other parameter of the same stage whose correlation is finite),
/// `stage` (the stage that last freed it) and `units`.
#[pyclass(name = "Parameter", module = "itaipu_calib", frozen, get_all)]
#[derive(Clone)]
pub struct PyParameter {
    name: String,
    value: f64,
    stderr: Option<f64>,
    init_value: f64,
    min: f64,
    max: f64,
    at_bound: bool,
    correl: BTreeMap<String, f64>,
    stage: String,
    units: String,
}

#[pymethods]
impl PyParameter {
    fn __repr__(&self) -> String {
        let err = match self.stderr {
            Some(s) => format!(" +/- {s:.3e}"),
            None => String::new(),
        };
        format!(
            "<Parameter '{}', value={}{}, bounds=[{}:{}]{}, stage='{}'>",
            self.name,
            self.value,
            err,
            self.min,
            self.max,
            if self.at_bound { ", at bound" } else { "" },
            self.stage
        )
    }
}

/// The parameters of one stage report, in its order.
pub(crate) fn of_stage(s: &StageReport) -> Vec<PyParameter> {
    s.parameters
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let correl = s
                .parameters
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .filter_map(|(j, q)| {
                    let rho = *s.correlation.get(i)?.get(j)?;
                    rho.is_finite().then(|| (q.param.clone(), rho))
                })
                .collect();
            PyParameter {
                name: p.param.clone(),
                value: p.result,
                stderr: p.std_error.is_finite().then_some(p.std_error),
                init_value: p.start,
                min: p.min,
                max: p.max,
                at_bound: p.at_bound,
                correl,
                stage: s.stage.clone(),
                units: p.unit.clone(),
            }
        })
        .collect()
}

/// Every parameter of `stages` (in order), each from the last stage that freed it: the values
/// of the calibrated unit.
pub(crate) fn final_params(stages: &[StageReport]) -> Vec<PyParameter> {
    let mut out: Vec<PyParameter> = vec![];
    for s in stages {
        for p in of_stage(s) {
            match out.iter_mut().find(|q| q.name == p.name) {
                Some(q) => *q = p,
                None => out.push(p),
            }
        }
    }
    out
}

impl PyParameter {
    pub(crate) fn name(&self) -> &str {
        &self.name
    }
    /// The row of `FitResult.to_pandas()`.
    pub(crate) fn row<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let d = pyo3::types::PyDict::new(py);
        d.set_item("name", &self.name)?;
        d.set_item("stage", &self.stage)?;
        d.set_item("value", self.value)?;
        d.set_item("stderr", self.stderr.unwrap_or(f64::NAN))?;
        d.set_item("init_value", self.init_value)?;
        d.set_item("min", self.min)?;
        d.set_item("max", self.max)?;
        d.set_item("at_bound", self.at_bound)?;
        d.set_item("units", &self.units)?;
        Ok(d)
    }
}
