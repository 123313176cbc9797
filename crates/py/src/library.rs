//! The model library and small helpers: `models`, `noise_sigma`.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use itaipu_dynamics::block::Dir;
use itaipu_dynamics::registry::MODELS;

/// The model library (the same catalogue unit files and the command line's `models [NAME]`
/// use): a list of dicts with name, role ('machine', 'exciter', 'pss', 'governor' or 'block'),
/// summary, parameters (dicts: name, alias (PSS/E), unit, doc, typical, range = (low, high)),
/// ports (dicts: name, direction 'in'/'out', doc) and states. `models(name)`: the dict of the
/// model named (any case), or for 'diagram' the diagram primitives as text; an unknown name
/// raises ValueError naming every model.
#[pyfunction]
#[pyo3(signature = (name = None))]
pub(crate) fn models<'py>(py: Python<'py>, name: Option<&str>) -> PyResult<Bound<'py, PyAny>> {
    use itaipu_dynamics::registry::{listing, Listing};
    match name.map(listing) {
        None => {
            let out = PyList::empty(py);
            for m in MODELS.iter() {
                out.append(model_dict(py, m)?)?;
            }
            Ok(out.into_any())
        }
        Some(Ok(Listing::Model(m))) => Ok(model_dict(py, m)?.into_any()),
        Some(Ok(Listing::DiagramPrimitives)) => Ok(pyo3::types::PyString::new(
            py,
            &itaipu_dynamics::diagram::describe_primitives(),
        )
        .into_any()),
        Some(Err(msg)) => Err(crate::errors::usage_error(py, "name", &msg)),
    }
}

/// One model of the library as a dict ([`models`]).
fn model_dict<'py>(
    py: Python<'py>,
    m: &itaipu_dynamics::registry::ModelInfo,
) -> PyResult<Bound<'py, PyDict>> {
    {
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
        Ok(d)
    }
}

/// Robust noise standard deviation of a measured signal (the fit's estimate: from its second
/// differences, so the event itself barely counts), in the signal's unit. The band the plot
/// helpers draw around a zero residual.
#[pyfunction]
pub(crate) fn noise_sigma(values: Vec<f64>) -> f64 {
    itaipu_calib::problem::noise_variance(&values).sqrt()
}

/// The defaults of the search settings, declared once in the library (what `fit` and
/// `diagnose` use where an argument is None, and what the command line's `--help` prints):
/// `{"fit": {...}, "diagnose": {...}}`, each with seed, particles, pso_iterations and
/// local_iterations (`fit`'s apply where the calibration spec does not set them).
#[pyfunction]
pub(crate) fn defaults<'py>(py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    use itaipu_calib::request::{SearchDefaults, DIAGNOSE_SEARCH, FIT_SEARCH};
    let one = |d: &SearchDefaults| -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let x = pyo3::types::PyDict::new(py);
        x.set_item("seed", d.seed)?;
        x.set_item("particles", d.particles)?;
        x.set_item("pso_iterations", d.pso_iterations)?;
        x.set_item("local_iterations", d.local_iterations)?;
        Ok(x)
    };
    let out = pyo3::types::PyDict::new(py);
    out.set_item("fit", one(&FIT_SEARCH)?)?;
    out.set_item("diagnose", one(&DIAGNOSE_SEARCH)?)?;
    Ok(out)
}

/// The calibration stages, in the fixed order they run in (`gen`, `avr`, `pss`, `tg`), then
/// `all`: the names `fit(stages=...)` and the command line's `--stage` accept.
#[pyfunction]
pub(crate) fn stages() -> Vec<&'static str> {
    itaipu_calib::request::Stage::NAMES.to_vec()
}

/// The library's check of an output folder before a run (`output::check_out`, what `fit --out`
/// and `FitResult.write` check): returns None when `out` may be written (absent, empty, or,
/// with `overwrite`, a folder of ours, which a writer then replaces whole); raises
/// OutputError otherwise. For `itaipu_calib.fleet`, which checks a job's folders before the
/// job's work.
#[pyfunction]
#[pyo3(name = "_check_out", signature = (out, overwrite = false))]
pub(crate) fn check_out(py: Python<'_>, out: std::path::PathBuf, overwrite: bool) -> PyResult<()> {
    use crate::errors::IntoPyErr;
    itaipu_calib::output::check_out(Some(&out), overwrite).map_err(|e| e.into_pyerr(py))
}

/// The options both front ends take, declared once in the library (`itaipu_calib::options`):
/// a list of dicts with command ('simulate', 'fit', 'diagnose', 'synth'), name, cli (the
/// command line's option, e.g. '--stage', or None), python (the keyword argument, or None),
/// default (what Python uses when the argument is not given; None: the command decides, as
/// `default_text` says) and help. docs/options.md is rendered from the same declaration.
#[pyfunction]
pub(crate) fn options(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    use itaipu_calib::options::{DefaultValue, OPTIONS};
    use itaipu_calib::request::Style;
    let out = PyList::empty(py);
    for o in OPTIONS {
        let d = PyDict::new(py);
        d.set_item("command", o.command.name())?;
        d.set_item("name", o.name)?;
        d.set_item("cli", o.cli.map(|c| format!("--{c}")))?;
        d.set_item("python", o.python)?;
        match o.default {
            DefaultValue::Text(t) => d.set_item("default", t)?,
            DefaultValue::Real(x) => d.set_item("default", x)?,
            DefaultValue::Int(n) => d.set_item("default", n)?,
            DefaultValue::Switch(on) => d.set_item("default", on)?,
            DefaultValue::Unset(_) | DefaultValue::Search(_) => d.set_item("default", py.None())?,
        }
        d.set_item("default_text", o.default_text())?;
        d.set_item("help", o.help(Style::Python))?;
        out.append(d)?;
    }
    Ok(out)
}
