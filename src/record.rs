//! Records of the scene and database files (meshes, the catalog): bincode 2 in its standard
//! configuration, decoded with a bound on what a damaged length prefix may make it allocate.

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::{Error, Result};

/// The most bytes a decoded record may claim (1 GiB): a flipped length prefix gets an error,
/// not an attempt to allocate terabytes.
const MAX_DECODED_BYTES: usize = 1 << 30;

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_DECODED_BYTES>()
}

/// Encodes `value`; `path` names the file it is for in the (unlikely) error.
pub(crate) fn encode<T: Serialize>(value: &T, path: &Path) -> Result<Vec<u8>> {
    bincode::serde::encode_to_vec(value, config()).map_err(|e| Error::bad_file(path, format!("encoding: {e}")))
}

/// Decodes one `what` from the whole of `bytes`, read from `path`: trailing bytes are an error.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], path: &Path, what: &str) -> Result<T> {
    let (value, used) = bincode::serde::decode_from_slice(bytes, config())
        .map_err(|e| Error::bad_file(path, format!("malformed {what}: {e}")))?;
    if used != bytes.len() {
        return Err(Error::bad_file(path, format!("malformed {what}: {} bytes after its end", bytes.len() - used)));
    }
    Ok(value)
}
