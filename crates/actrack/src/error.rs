//! The one error type of the `actrack` crate.
//!
//! Every variant that comes from a file names the file, and the line (or frame) where it has one.
//! [`Error::is_input_error`] tells the CLI which errors are the user's input (exit code 2) and
//! which are runtime failures (exit code 1).

use std::path::{Path, PathBuf};

/// Errors of the `actrack` crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be opened or read (missing, unreadable, not valid compressed data).
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A file could not be written (or the temporary file could not be renamed into place).
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A text file is malformed at a given line (1-based).
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong, and where possible what was expected.
        message: String,
    },
    /// A file is well-formed but its content cannot be used (no line to point at): unknown marker
    /// names, a cluster without enough markers, a model file of another version, …
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An option or parameter is out of range (not tied to a file).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// Fitting or evaluating a parametric HMM failed.
    #[error("{context}: {message}")]
    Model {
        /// What was being done (e.g. "training action `reach`").
        context: String,
        /// The underlying error, rendered.
        message: String,
    },
}

impl Error {
    /// `true` when the error is caused by the user's input (a missing or malformed file, an
    /// invalid option): the CLI exits with code 2. Other errors are runtime failures (code 1).
    pub fn is_input_error(&self) -> bool {
        match self {
            Error::Read { .. } | Error::Parse { .. } | Error::Invalid { .. } | Error::Config(_) => {
                true
            }
            Error::Write { .. } | Error::Model { .. } => false,
        }
    }

    /// A [`Error::Parse`] error for `path` at 1-based `line`.
    pub fn parse(path: &Path, line: usize, message: impl Into<String>) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    /// An [`Error::Invalid`] error for `path`.
    pub fn invalid(path: &Path, message: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// An [`Error::Read`] error for `path`.
    pub fn read(path: &Path, source: std::io::Error) -> Self {
        Error::Read {
            path: path.to_path_buf(),
            source,
        }
    }

    /// An [`Error::Write`] error for `path`.
    pub fn write(path: &Path, source: std::io::Error) -> Self {
        Error::Write {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// `Result` with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
