//! The `itaipu-calib` command of the wheel: a console entry point
//! (`itaipu_calib._cli:main`) that runs the command-line crate's `run`, the same code as the
//! `itaipu-calib` binary.

use pyo3::prelude::*;

/// Runs the command line with `argv` (program name first) and returns its exit code. The GIL
/// is released for the whole run; the command installs its own SIGINT/SIGTERM handling.
#[pyfunction]
pub fn _cli_main(py: Python<'_>, argv: Vec<String>) -> u8 {
    py.detach(|| itaipu_calib_cli::run(argv))
}
