//! The Python exception classes and the one conversion of each library error into them
//! (`Failure::into_pyerr`, `request_error`).

use pyo3::exceptions::{PyException, PyKeyboardInterrupt, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::{create_exception, PyTypeInfo};

use itaipu_calib::error::ErrorClass;

use itaipu_calib::request::{RequestError, Style};

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

create_exception!(
    itaipu_calib,
    OutputError,
    ItaipuError,
    "An output file or folder could not be written, or would overwrite something (kind: \
     'output')."
);
create_exception!(
    itaipu_calib,
    InternalError,
    ItaipuError,
    "A bug in itaipu_calib (an internal invariant broken, e.g. a caught Rust panic): never the \
     input's fault; please report it with the message."
);

create_exception!(
    itaipu_calib,
    ItaipuWarning,
    PyUserWarning,
    "A plausibility warning on the inputs (an implausible sample, a parameter far outside its \
     typical range, a starting value clamped into the spec's bounds): the run goes on; the \
     warning is also kept in the result's report."
);

/// Issues every finding as an [`ItaipuWarning`] (what the command line prints as
/// `warning: ...`).
pub(crate) fn warn_all(
    py: Python<'_>,
    findings: &[itaipu_dynamics::plausibility::Finding],
) -> PyResult<()> {
    let cat = py.get_type::<ItaipuWarning>();
    for f in findings {
        let msg = std::ffi::CString::new(f.to_string().replace('\0', " "))
            .unwrap_or_else(|_| c"warning".to_owned());
        PyErr::warn(py, &cat, &msg, 1)?;
    }
    Ok(())
}

/// Issues each of `texts` as an `ItaipuWarning` (the category every warning of the module
/// has, so that `warnings.simplefilter` and `pytest.warns` see them all).
pub(crate) fn warn_texts<'a>(
    py: Python<'_>,
    texts: impl IntoIterator<Item = &'a str>,
) -> PyResult<()> {
    let cat = py.get_type::<ItaipuWarning>();
    for t in texts {
        let msg =
            std::ffi::CString::new(t.replace('\0', " ")).unwrap_or_else(|_| c"warning".to_owned());
        PyErr::warn(py, &cat, &msg, 1)?;
    }
    Ok(())
}

/// A failure inside the GIL-free part of a call: the library's one error type, converted to a
/// Python exception afterwards by its class ([`ErrorClass`]), here and only here.
pub(crate) type Failure = itaipu_calib::Error;

/// An exception of type `T` with message `msg` and attribute `kind`.
pub(crate) fn raise<T: PyTypeInfo>(py: Python<'_>, msg: String, kind: Option<&str>) -> PyErr {
    let err = PyErr::new::<T, _>(msg);
    // Setting an attribute on a fresh exception instance cannot fail in practice; if it did,
    // the class attribute `kind = None` still answers.
    let _ = err.value(py).setattr("kind", kind);
    err
}

/// The Python form of a library error.
pub(crate) trait IntoPyErr {
    fn into_pyerr(self, py: Python<'_>) -> PyErr;
}

impl IntoPyErr for itaipu_calib::Error {
    fn into_pyerr(self, py: Python<'_>) -> PyErr {
        // The variant's own kind (`"io"`, `"syntax"`, …) where it has one, else the source.
        let full = self.kind();
        let kind = full.rsplit('.').next().unwrap_or(&full).to_string();
        let msg = match &self {
            itaipu_calib::Error::Request(r) => r.message(Style::Python),
            _ => self.to_string(),
        };
        match self.class() {
            // A ValueError (a bad argument value), with the option at fault as its `kind`.
            ErrorClass::Usage => {
                let err = PyValueError::new_err(msg);
                let _ = err.value(py).setattr("kind", kind);
                err
            }
            ErrorClass::EventData => raise::<EventError>(py, msg, Some(&kind)),
            ErrorClass::UnitModel => raise::<UnitModelError>(py, msg, Some(&kind)),
            ErrorClass::Spec | ErrorClass::Calibration => {
                raise::<CalibrationError>(py, msg, Some(&kind))
            }
            ErrorClass::Init => raise::<InitError>(py, msg, Some(&kind)),
            ErrorClass::Simulation => raise::<SimulationError>(py, msg, Some(&kind)),
            ErrorClass::Output => raise::<OutputError>(py, msg, Some(&kind)),
            // Only after a signal, which `interrupt::interruptible` raises first.
            ErrorClass::Interrupted => PyKeyboardInterrupt::new_err(msg),
            ErrorClass::Internal => raise::<InternalError>(py, msg, Some("internal")),
        }
    }
}

/// A usage error found by the binding itself: ValueError with `kind` the argument at fault.
pub(crate) fn usage_error(py: Python<'_>, arg: &str, msg: &str) -> PyErr {
    let err = PyValueError::new_err(format!("{arg}: {msg}"));
    let _ = err.value(py).setattr("kind", arg);
    err
}

/// A rejected option (the library's [`RequestError`]): ValueError, options named as in Python.
pub(crate) fn request_error(e: RequestError) -> PyErr {
    PyValueError::new_err(e.message(Style::Python))
}
