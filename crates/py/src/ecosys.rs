//! Thin bindings of the `.dyr` reader/writer and the PMU importer (the same library calls as
//! `itaipu-calib dyr` and `itaipu-calib import`).

use std::path::PathBuf;
use std::sync::Arc;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use itaipu_dynamics::dyr::{self, DyrError, PartialBases};
use itaipu_dynamics::pmu_import::{self, ImportError, ImportOptions};

use crate::args::{event_sources, load_events};
use crate::errors::{raise, EventError, Failure, IntoPyErr, UnitModelError};
use crate::event::PyEvent;
use crate::unit::PyUnit;

fn dyr_err(py: Python<'_>, e: DyrError) -> PyErr {
    match e {
        DyrError::Bases { .. } => raise::<UnitModelError>(py, e.to_string(), Some("bases")),
        e => raise::<UnitModelError>(py, e.to_string(), Some(e.kind())),
    }
}

/// Reads one unit from a PSS/E .dyr (the models with a record: `models()`). `bus`/`id` select
/// the unit (optional when the file holds one machine). Bases come from `bases` (a side file,
/// TOML: mbase, nominal_hz, zr, zx, name), else `<stem>.bases.toml` beside the .dyr, with
/// `mbase`, `nominal_hz`, `zr`, `zx` on top. A record of a model the engine lacks raises
/// UnitModelError (kind 'unsupported'), naming the line and what the unit would lack, unless
/// `skip_unsupported`: then the unit is built without it, with an `ItaipuWarning` (a
/// `UserWarning`) naming the line. Raises UnitModelError (kind 'syntax', 'record',
/// 'unsupported', 'selection', 'bases', 'unit', 'io').
#[pyfunction]
#[pyo3(signature = (path, *, bus=None, id=None, bases=None, mbase=None, nominal_hz=None, zr=None, zx=None, skip_unsupported=false))]
#[allow(clippy::too_many_arguments)]
pub fn read_dyr(
    py: Python<'_>,
    path: PathBuf,
    bus: Option<i64>,
    id: Option<String>,
    bases: Option<PathBuf>,
    mbase: Option<f64>,
    nominal_hz: Option<f64>,
    zr: Option<f64>,
    zx: Option<f64>,
    skip_unsupported: bool,
) -> PyResult<PyUnit> {
    let over = PartialBases {
        mbase,
        nominal_hz,
        zr,
        zx,
        name: None,
    };
    let select = match (bus, id.as_deref()) {
        (Some(b), i) => Some((b, i.unwrap_or("1"))),
        (None, Some(_)) => return Err(PyValueError::new_err("id needs bus")),
        (None, None) => None,
    };
    let d = py
        .detach(|| {
            let b = dyr::resolve_bases(&path, bases.as_deref(), &over)?;
            let opts = dyr::DyrReadOptions {
                select,
                skip_unsupported,
            };
            dyr::read_dyr_with(&path, &b, &opts)
        })
        .map_err(|e| dyr_err(py, e))?;
    let texts: Vec<String> = d.warnings.iter().map(|w| w.to_string()).collect();
    crate::errors::warn_texts(py, texts.iter().map(String::as_str))?;
    Ok(PyUnit {
        inner: Arc::new(d.unit),
        path: Some(path),
    })
}

/// Writes `unit` as .dyr records for `bus`, `id` to `path` and its bases to
/// `<stem>.bases.toml` beside it, only if the .dyr read back is the unit: played back on
/// `events` (paths or Event objects, or a list) within 1e-6 pu of it, or, without events, with
/// every parameter, option, wiring and block read back unchanged (the library's checked writer,
/// the same call as `itaipu-calib dyr write`). Otherwise raises UnitModelError (kind 'lossy',
/// quoting J of both and what is lost) unless `lossy=True`, which writes it with an ItaipuWarning.
/// An existing file is kept (UnitModelError, kind 'exists') unless `force=True`. Plausibility
/// findings on what is written (parameters far outside the typical ranges, saturation data
/// that is no curve) are ItaipuWarnings. Returns a dict: `faithful`, `lost` (messages), `events`
/// (per event: `event`, `j_unit`, `j_written`, `max_dp`, `max_dq`, `failure`), `warnings`.
#[pyfunction]
#[pyo3(signature = (unit, path, *, bus=1, id="1", events=None, lossy=false, force=false))]
#[allow(clippy::too_many_arguments)]
pub fn write_dyr<'py>(
    py: Python<'py>,
    unit: &PyUnit,
    path: PathBuf,
    bus: i64,
    id: &str,
    events: Option<&Bound<'py, PyAny>>,
    lossy: bool,
    force: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let sources = match events {
        Some(e) => event_sources(e, "events")?,
        None => vec![],
    };
    let opts = dyr::DyrWriteOptions {
        bus,
        id: id.to_string(),
        lossy,
        force,
        ..Default::default()
    };
    let u = unit.inner.clone();
    let r = py
        .detach(|| {
            let events = load_events(sources)?;
            Ok::<_, Failure>(dyr::write_dyr_file(&u, &path, &events, &opts))
        })
        .map_err(|f| f.into_pyerr(py))?
        .map_err(|e| match e {
            dyr::DyrWriteError::Simulation { source, .. } => Failure::from(source).into_pyerr(py),
            dyr::DyrWriteError::Io { .. } => pyo3::exceptions::PyOSError::new_err(e.to_string()),
            e @ dyr::DyrWriteError::Unfaithful { .. } => raise::<UnitModelError>(
                py,
                format!("{e} (lossy=True writes it anyway)"),
                Some(e.kind()),
            ),
            e => raise::<UnitModelError>(py, e.to_string(), Some(e.kind())),
        })?;
    let mut warnings: Vec<String> = r.findings.iter().map(|f| f.to_string()).collect();
    warnings.extend(r.notes.iter().cloned());
    if !r.faithful() {
        warnings.push(format!(
            "lossy=True: written, but the .dyr read back is not the unit: {}",
            r.summary()
        ));
    }
    crate::errors::warn_texts(py, warnings.iter().map(String::as_str))?;
    let d = PyDict::new(py);
    d.set_item("faithful", r.faithful())?;
    d.set_item(
        "lost",
        r.lost.iter().map(|l| l.to_string()).collect::<Vec<_>>(),
    )?;
    let evs = pyo3::types::PyList::empty(py);
    for c in &r.events {
        let e = PyDict::new(py);
        e.set_item("event", &c.event)?;
        e.set_item("j_unit", c.j_unit)?;
        e.set_item("j_written", c.j_written)?;
        e.set_item("max_dp", c.max_dp)?;
        e.set_item("max_dq", c.max_dq)?;
        e.set_item("failure", &c.failure)?;
        evs.append(e)?;
    }
    d.set_item("events", evs)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// Imports a PMU recording (C37.118-style CSV, or a COMTRADE .cfg with its .dat) as an Event
/// that `simulate`, `fit` and `diagnose` take as it is, P and Q computed from the voltage and
/// current phasors (generator convention) on `system_mva`. `v_base_kv`: rated line-to-line kV
/// (for channels in V/kV); `pu_base_mva`: the base of channels in pu; `rate`: resample to this
/// rate (default: keep the PMU's stamps); `map`: {name: column} to read a column as a known
/// name; `refuse_truncated`: raise EventError for a COMTRADE .dat shorter than its .cfg
/// declares (otherwise imported with a warning). With `out`, writes the event folder
/// (event.toml, CSV, import.json). The import's report (the command line's import.json: gaps,
/// dropouts, warnings, channels, samples read and declared, rates) is `event.import_report`;
/// each of its warnings is issued as an `ItaipuWarning`. Raises EventError (kind 'data',
/// 'event', 'io') or ValueError for a bad option.
#[pyfunction]
#[pyo3(signature = (path, system_mva, nominal_hz, *, v_base_kv=None, pu_base_mva=None, line_voltage=false, current_into_machine=false, rate=None, map=None, name=None, out=None, refuse_truncated=false))]
#[allow(clippy::too_many_arguments)]
pub fn import_pmu(
    py: Python<'_>,
    path: PathBuf,
    system_mva: f64,
    nominal_hz: f64,
    v_base_kv: Option<f64>,
    pu_base_mva: Option<f64>,
    line_voltage: bool,
    current_into_machine: bool,
    rate: Option<f64>,
    map: Option<std::collections::BTreeMap<String, String>>,
    name: Option<String>,
    out: Option<PathBuf>,
    refuse_truncated: bool,
) -> PyResult<PyEvent> {
    let opts = ImportOptions {
        name,
        system_mva,
        nominal_hz,
        v_base_kv,
        pu_base_mva,
        line_voltage,
        current_into_machine,
        rate_hz: rate,
        map: map.unwrap_or_default().into_iter().collect(),
        refuse_truncated,
    };
    let (event, report) = py
        .detach(|| pmu_import::import(&path, &opts))
        .map_err(|e| match e {
            ImportError::Options { .. } => PyValueError::new_err(e.to_string()),
            e => raise::<EventError>(py, e.to_string(), Some(e.kind())),
        })?;
    if let Some(dir) = out {
        pmu_import::write_event_folder(&event, &report, &dir)
            .map_err(|e| raise::<EventError>(py, e.to_string(), Some(e.kind())))?;
    }
    crate::errors::warn_texts(py, report.warnings.iter().map(String::as_str))?;
    let json = serde_json::to_string(&report).expect("a report serialises");
    Ok(PyEvent {
        inner: Arc::new(event),
        import_report: Some(Arc::new(json)),
    })
}

/// Registers the functions of this file.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_dyr, m)?)?;
    m.add_function(wrap_pyfunction!(write_dyr, m)?)?;
    m.add_function(wrap_pyfunction!(import_pmu, m)?)?;
    Ok(())
}
