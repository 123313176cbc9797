//! The Python exception classes and the one conversion of each library error into them
//! (`Failure::into_pyerr`, `request_error`).

use pyo3::exceptions::{PyException, PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::{create_exception, PyTypeInfo};

use itaipu_calib::diagnose::DiagnoseError;
use itaipu_calib::fit::FitError;
use itaipu_calib::spec::SpecError;
use itaipu_dynamics::event::EventError as RsEventError;
use itaipu_dynamics::simulate::SimError;
use itaipu_dynamics::unit::UnitError;
use itaipu_dynamics::unit_file::UnitFileError;

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

/// A failure inside the GIL-free part of a call, converted to a Python exception afterwards.
pub(crate) enum Failure {
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

/// `From<E> for Failure` for each library error kept as is.
macro_rules! failure_from {
    ($($err:ty => $variant:ident),* $(,)?) => {
        $(impl From<$err> for Failure {
            fn from(e: $err) -> Self {
                Failure::$variant(e)
            }
        })*
    };
}

failure_from!(
    RsEventError => Event,
    UnitFileError => Unit,
    SimError => Sim,
    SpecError => Spec,
    FitError => Fit,
    DiagnoseError => Diagnose,
);

/// An exception of type `T` with message `msg` and attribute `kind`.
pub(crate) fn raise<T: PyTypeInfo>(
    py: Python<'_>,
    msg: String,
    kind: Option<&'static str>,
) -> PyErr {
    let err = PyErr::new::<T, _>(msg);
    // Setting an attribute on a fresh exception instance cannot fail in practice; if it did,
    // the class attribute `kind = None` still answers.
    let _ = err.value(py).setattr("kind", kind);
    err
}

impl Failure {
    pub(crate) fn into_pyerr(self, py: Python<'_>) -> PyErr {
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

/// A rejected option (the library's [`RequestError`]): ValueError, options named as in Python.
pub(crate) fn request_error(e: RequestError) -> PyErr {
    PyValueError::new_err(e.message(Style::Python))
}

impl From<RequestError> for Failure {
    fn from(e: RequestError) -> Self {
        Failure::Value(e.message(Style::Python))
    }
}
