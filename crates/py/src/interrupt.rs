//! Long calls that Ctrl-C can stop: the work runs on a worker thread while the calling thread,
//! without the GIL between checks, looks for signals every 20 ms.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use pyo3::prelude::*;

/// Runs `work` on a worker thread and returns its result. A signal (Ctrl-C: KeyboardInterrupt)
/// is raised within the polling interval: with `cancel`, after setting it and waiting for the
/// worker (the library stops at its next candidate evaluation); without, at once, the worker
/// finishing on its own in the background and its result dropped (used for work the library
/// cannot stop, e.g. one synthetic simulation).
pub(crate) fn interruptible<T: Send + 'static>(
    py: Python<'_>,
    cancel: Option<Arc<AtomicBool>>,
    work: impl FnOnce() -> T + Send + 'static,
) -> PyResult<T> {
    let worker = std::thread::Builder::new()
        .name("itaipu-calib worker".into())
        .spawn(work)
        .map_err(|e| {
            pyo3::exceptions::PyRuntimeError::new_err(format!("cannot start a worker thread: {e}"))
        })?;
    loop {
        if worker.is_finished() {
            // A panic in the worker is a bug: InternalError (an Exception), never a
            // PanicException that `except Exception` does not catch.
            return worker.join().map_err(|payload| {
                let msg = payload
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "a panic without a message".into());
                crate::errors::raise::<crate::errors::InternalError>(
                    py,
                    format!("internal error (a bug, please report it): {msg}"),
                    Some("internal"),
                )
            });
        }
        py.detach(|| std::thread::sleep(Duration::from_millis(20)));
        if let Err(e) = py.check_signals() {
            if let Some(c) = cancel {
                c.store(true, Ordering::SeqCst);
                let _ = py.detach(|| worker.join());
            }
            return Err(e);
        }
    }
}
