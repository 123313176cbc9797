//! `to_pandas()`: pandas is optional; a missing pandas is a clear ImportError.

use pyo3::exceptions::PyImportError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// `pandas.DataFrame(data)` (data: a dict of columns or a list of row dicts), with `index` as
/// the index column when given.
pub(crate) fn data_frame<'py>(
    py: Python<'py>,
    data: Bound<'py, PyAny>,
    index: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    let pd = py.import("pandas").map_err(|e| {
        PyImportError::new_err(format!(
            "to_pandas() needs pandas, which is not installed ({e}): pip install pandas \
             (or pip install 'itaipu-calib[pandas]')"
        ))
    })?;
    let df = pd.getattr("DataFrame")?.call1((data,))?;
    match index {
        Some(col) => df.call_method1("set_index", (col,)),
        None => Ok(df),
    }
}

/// A list of dicts as rows.
pub(crate) fn rows<'py>(
    py: Python<'py>,
    rows: Vec<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyList::new(py, rows)?.into_any())
}
