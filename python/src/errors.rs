//! Library errors as Python exceptions carrying the CLI's one-line messages
//! (docs/design.md §8): bad values → `ValueError`, files → `OSError`, a solve
//! that did not converge → `RuntimeError`, Ctrl-C → `KeyboardInterrupt`.

use std::error::Error;

use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::PyErr;

/// The error and its causes on one line, `outer: inner`, as the CLI prints
/// them (`{:#}` of anyhow).
pub fn one_line(e: &dyn Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let more = c.to_string();
        if !text.ends_with(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        cause = c.source();
    }
    text
}

/// `ValueError(message)`.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// `ValueError` with the error's one-line text.
pub fn invalid(e: &dyn Error) -> PyErr {
    PyValueError::new_err(one_line(e))
}

/// `OSError` with the error's one-line text.
pub fn os_error(e: &dyn Error) -> PyErr {
    PyOSError::new_err(one_line(e))
}

/// `RuntimeError` with the error's one-line text.
pub fn runtime_error(e: &dyn Error) -> PyErr {
    PyRuntimeError::new_err(one_line(e))
}
