//! The crate's error type: every failure a user can cause names the file or argument and the reason.

use std::path::PathBuf;

/// Errors of the hdov library. `Display` is one line, fit for the CLI's `error: ...`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O failure on a named file.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file whose contents are not what they must be (malformed, truncated, corrupted).
    #[error("{}: {reason}", path.display())]
    BadFile { path: PathBuf, reason: String },
    /// A parameter that cannot be used, named as the library names it (`resolution`,
    /// `grid`, ...); a user interface maps the name to its own (the `hdov` command to a flag).
    #[error("{param}: {reason}")]
    BadParam { param: String, reason: String },
    /// An error from the storage crate (pages, layouts).
    #[error(transparent)]
    Storage(#[from] hdov_storage::Error),
    /// No graphics adapter could run the GPU backend.
    #[error("gpu: {0}")]
    Gpu(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    pub fn bad_file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::BadFile { path: path.into(), reason: reason.into() }
    }
    pub fn bad_param(param: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::BadParam { param: param.into(), reason: reason.into() }
    }
}
