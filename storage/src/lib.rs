//! hdov-storage: bytes on disk, no geometry (being written).

/// Errors of the storage layer.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {reason}")]
    Corrupt { path: String, reason: String },
}
