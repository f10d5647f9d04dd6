//! Scene manifest (being written).
use crate::error::{Error, Result};
pub fn read(path: &std::path::Path) -> Result<super::Scene> {
    Err(Error::bad_file(path, "manifest import not yet written"))
}
