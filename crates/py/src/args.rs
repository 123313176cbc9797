//! Argument conversion shared by the functions: events and units given as objects or paths.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::PyArray1;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use itaipu_calib::job::load_unit as read_unit_any;
use itaipu_dynamics::event::Event;

use crate::errors::Failure;
use crate::event::PyEvent;
use crate::unit::PyUnit;

pub(crate) fn array<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v)
}

/// An event or unit argument: an already loaded object, or a path to load (without the GIL).
pub(crate) enum Source<T> {
    Loaded(Arc<T>),
    Path(PathBuf),
}

pub(crate) fn source<'py, C, T>(
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
            let ty = type_name(arg);
            Err(PyTypeError::new_err(format!(
                "{what} must be a path (str or os.PathLike) or an {} object, not {ty}",
                C::NAME
            )))
        }
    }
}

/// Events from a path, an Event, or an iterable of them.
pub(crate) fn event_sources(arg: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Source<Event>>> {
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
            let ty = type_name(arg);
            Err(PyTypeError::new_err(format!(
                "{what} must be a path (str or os.PathLike), an Event object, or a list of them, not {ty}"
            )))
        }
    }
}

/// Whether `(events, unit)` came in the order `(unit, events)`: a Unit object first, an Event
/// or a list of events second, or two paths of which the first reads as a unit file and the
/// second does not (a unit file is small: this reads no recording).
pub(crate) fn swapped_events_unit(
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
    Ok(py.detach(|| read_unit_any(&first).is_ok() && read_unit_any(&second).is_err()))
}

/// A TypeError for `func` called with the unit first and the events second.
pub(crate) fn swap_error(func: &str) -> PyErr {
    PyTypeError::new_err(format!(
        "{func}: the first argument is a unit and the second an event; the order is \
         {func}(events, unit): swap them"
    ))
}

/// The events of `Source`s, read from file where needed.
pub(crate) fn load_events(sources: Vec<Source<Event>>) -> Result<Vec<Event>, Failure> {
    sources
        .into_iter()
        .map(|s| match s {
            Source::Loaded(e) => Ok(Arc::unwrap_or_clone(e)),
            Source::Path(p) => Ok(Event::from_toml_file(&p)?),
        })
        .collect()
}

/// The Python type name of `arg`, for messages.
pub(crate) fn type_name(arg: &Bound<'_, PyAny>) -> String {
    arg.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// A string or a list of strings (`shape`: the TypeError's message otherwise).
pub(crate) fn str_or_list(arg: &Bound<'_, PyAny>, shape: &'static str) -> PyResult<Vec<String>> {
    if let Ok(s) = arg.extract::<String>() {
        return Ok(vec![s]);
    }
    arg.extract::<Vec<String>>()
        .map_err(|_| PyTypeError::new_err(shape))
}

/// A worker pool of `threads` threads for one call (`fit`, `diagnose`), or None: rayon's global
/// pool (all cores, or `RAYON_NUM_THREADS`). The results do not depend on the number of threads.
/// (`threads` is checked by the request layer first: at least 1.)
pub(crate) fn worker_pool(threads: Option<usize>) -> PyResult<Option<rayon::ThreadPool>> {
    threads
        .map(|n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| {
                    pyo3::exceptions::PyRuntimeError::new_err(format!(
                        "cannot start {n} worker threads: {e}"
                    ))
                })
        })
        .transpose()
}

/// An argument renamed: the value of `new`, or of `old` with a DeprecationWarning; both given
/// is a TypeError.
pub(crate) fn renamed<T>(
    py: Python<'_>,
    old: &str,
    new: &str,
    old_value: Option<T>,
    new_value: Option<T>,
) -> PyResult<Option<T>> {
    match (old_value, new_value) {
        (Some(_), Some(_)) => Err(PyTypeError::new_err(format!(
            "{new} and {old} (its old name) were both given: give {new} only"
        ))),
        (Some(v), None) => {
            let msg = std::ffi::CString::new(format!(
                "{old} is deprecated: it is now {new} (it caps the local method, \
                 Levenberg-Marquardt or L-BFGS)"
            ))
            .unwrap_or_else(|_| c"deprecated argument".to_owned());
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyDeprecationWarning>(),
                &msg,
                1,
            )?;
            Ok(Some(v))
        }
        (None, v) => Ok(v),
    }
}

/// A whole-number argument (`seed`, `particles`, `pso_iterations`, ...): None when absent or
/// None; a TypeError naming `name` for a value that is not an int (a bool is not a count), a
/// ValueError naming it for a negative one or one beyond `T`'s range, so that `particles=-1`
/// says which argument and why instead of a bare OverflowError.
pub(crate) fn whole<T: TryFrom<i128>>(
    py: Python<'_>,
    arg: Option<&Bound<'_, PyAny>>,
    name: &str,
) -> PyResult<Option<T>> {
    let Some(arg) = arg.filter(|a| !a.is_none()) else {
        return Ok(None);
    };
    if arg.is_instance_of::<pyo3::types::PyBool>() || !arg.is_instance_of::<pyo3::types::PyInt>() {
        return Err(PyTypeError::new_err(format!(
            "{name} must be a whole number (int), not {}",
            type_name(arg)
        )));
    }
    let v: i128 = arg
        .extract()
        .map_err(|_| crate::errors::usage_error(py, name, &format!("{arg} is out of range")))?;
    if v < 0 {
        return Err(crate::errors::usage_error(
            py,
            name,
            &format!("must be a whole number >= 0, got {v}"),
        ));
    }
    T::try_from(v)
        .map(Some)
        .map_err(|_| crate::errors::usage_error(py, name, &format!("{v} is too large")))
}
