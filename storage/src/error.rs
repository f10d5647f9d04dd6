//! The storage layer's error type. `Display` is one line: the file, then the reason.

use std::io;
use std::path::Path;

/// Errors of the storage layer. Every variant names the file it concerns.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system I/O failure.
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: io::Error,
    },
    /// The file does not start with the expected magic number: it is not an hdov file of this type.
    #[error("{path}: wrong magic number: not an hdov {expected} file")]
    WrongMagic { path: String, expected: &'static str },
    /// An hdov file, but of another kind (e.g. a tree file opened as a V-page file).
    #[error("{path}: file kind {found:?}, expected {expected:?}")]
    WrongKind { path: String, found: String, expected: String },
    /// Written by another format version.
    #[error("{path}: format version {found}, this build reads version {expected}")]
    WrongVersion { path: String, found: u32, expected: u32 },
    /// The file is shorter than its header says.
    #[error("{path}: truncated: {reason}")]
    Truncated { path: String, reason: String },
    /// A page whose stored crc32 does not match its payload.
    #[error("{path}: checksum mismatch in page {page}")]
    Checksum { path: String, page: u64 },
    /// A blob record whose stored crc32 does not match its bytes.
    #[error("{path}: checksum mismatch in record at byte {offset}")]
    RecordChecksum { path: String, offset: u64 },
    /// Any other malformed content.
    #[error("{path}: {reason}")]
    Corrupt { path: String, reason: String },
    /// A target that exists and may not be overwritten.
    #[error("{path}: exists")]
    Exists { path: String },
    /// A target that may be replaced only if it is ours, and is not: a directory of other files,
    /// a regular file, a symlink.
    #[error("{path}: not an hdov database or an empty directory; refusing to replace it")]
    NotOurs { path: String },
    /// A request the file cannot answer (a page or record outside it, a payload too large, ...).
    #[error("{path}: {reason}")]
    Invalid { path: String, reason: String },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn path_str(path: &Path) -> String {
    path.display().to_string()
}

impl Error {
    pub(crate) fn io(path: &Path, source: io::Error) -> Self {
        Error::Io { path: path_str(path), source }
    }
    pub(crate) fn corrupt(path: &Path, reason: impl Into<String>) -> Self {
        Error::Corrupt { path: path_str(path), reason: reason.into() }
    }
    pub(crate) fn truncated(path: &Path, reason: impl Into<String>) -> Self {
        Error::Truncated { path: path_str(path), reason: reason.into() }
    }
    pub(crate) fn invalid(path: &Path, reason: impl Into<String>) -> Self {
        Error::Invalid { path: path_str(path), reason: reason.into() }
    }
}
