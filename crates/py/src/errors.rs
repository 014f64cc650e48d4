//! Python exceptions of the package and the mapping from the Rust error enums.
//!
//! Invalid input (bad shapes, NaN, inconsistent parameters, malformed files) raises
//! [`ActrackError`], a `ValueError`; failures to read or write a file raise [`ActrackOSError`], an
//! `OSError` carrying `errno`, `strerror` and `filename`. Both carry the Rust message unchanged.

use std::path::Path;

use pyo3::PyErr;
use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyValueError};

create_exception!(
    _actrack,
    ActrackError,
    PyValueError,
    "Invalid input or model: bad shapes, non-finite values, inconsistent parameters, malformed files."
);
create_exception!(
    _actrack,
    ActrackOSError,
    PyOSError,
    "A file could not be read or written (errno, strerror and filename are set)."
);

/// `ActrackError` with the given message.
pub(crate) fn value_error(msg: impl Into<String>) -> PyErr {
    ActrackError::new_err(msg.into())
}

/// `ActrackOSError(errno, message, filename)`.
pub(crate) fn os_error(path: &Path, err: &std::io::Error, message: String) -> PyErr {
    let errno = err.raw_os_error().unwrap_or(0);
    ActrackOSError::new_err((errno, message, path.display().to_string()))
}

/// A parametric-HMM error is always the caller's input (shapes, values, parameters).
pub(crate) fn phmm_error(e: &actrack::phmm::PhmmError) -> PyErr {
    value_error(e.to_string())
}

/// Errors of the `actrack` crate: I/O failures become `ActrackOSError`, the rest `ActrackError`.
pub(crate) fn actrack_error(e: &actrack::Error) -> PyErr {
    match e {
        actrack::Error::Read { path, source } | actrack::Error::Write { path, source } => {
            os_error(path, source, e.to_string())
        }
        _ => value_error(e.to_string()),
    }
}
