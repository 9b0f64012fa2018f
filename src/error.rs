//! Typed errors of the library. Every message is one line that names the file (or the setting) and
//! the problem; the CLI prints it as is.

use std::path::{Path, PathBuf};

/// Errors returned by herdfit's library functions.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A problem with a named file: unreadable, unwritable, malformed or holding bad values.
    #[error("{}: {msg}", path.display())]
    File { path: PathBuf, msg: String },
    /// An out-of-range setting or an impossible request (no file involved).
    #[error("{0}")]
    Invalid(String),
    /// An internal numerical failure (e.g. a tensor read-back that failed).
    #[error("internal error: {0}")]
    Internal(String),
}

impl Error {
    /// A problem with `path`.
    pub fn file(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::File {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }

    /// An invalid setting.
    pub fn invalid(msg: impl Into<String>) -> Self {
        Error::Invalid(msg.into())
    }

    /// Prefixes a file-less error with `path` (used when a value read from a file is rejected).
    pub fn in_file(self, path: impl AsRef<Path>) -> Self {
        match self {
            Error::Invalid(msg) => Error::file(path, msg),
            other => other,
        }
    }
}

/// Result alias of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;
