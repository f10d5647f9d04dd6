//! The files a scene file names, read as an upload form or a pipeline would hand them to us:
//! every name resolves inside the scene file's folder (after symlinks) or is refused, and every
//! read is bounded by what the file declares, checked before anything is allocated.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The most bytes one scene file or buffer may hold: 16 GiB, past any scene one machine builds.
pub const MAX_FILE_BYTES: u64 = 1 << 34;

/// The file that `name`, written in the scene file `scene`, names: a relative path that
/// resolves (symlinks followed) to a regular file inside `scene`'s folder. Anything else (an
/// absolute path, a URL, `..` out of the folder, a link out of it, a device) is refused in one
/// line naming `scene`.
pub fn beside(scene: &Path, name: &str) -> Result<PathBuf> {
    let refuse = |why: &str| Error::bad_file(scene, format!("'{name}' {why}"));
    if name.contains("://") || Path::new(name).is_absolute() || name.starts_with('\\') {
        return Err(refuse("is not a file beside the scene"));
    }
    let folder = scene.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let folder = folder.canonicalize().map_err(|e| Error::io(folder, e))?;
    let file = folder.join(name);
    let resolved = file.canonicalize().map_err(|e| Error::io(&file, e))?;
    if !resolved.starts_with(&folder) {
        return Err(refuse("resolves outside the scene's folder"));
    }
    if !resolved.is_file() {
        return Err(refuse("is not a regular file"));
    }
    Ok(resolved)
}

/// The first `declared` bytes of `file`, which must be a regular file of `declared` bytes, or
/// up to `slack` more (padding); checked before a byte is read or allocated.
pub fn read_declared(file: &Path, declared: u64, slack: u64) -> Result<Vec<u8>> {
    let len = regular_file_len(file)?;
    if declared > MAX_FILE_BYTES {
        return Err(Error::bad_file(file, format!("declares {declared} bytes, more than {MAX_FILE_BYTES}")));
    }
    if len < declared || len > declared + slack {
        return Err(Error::bad_file(file, format!("holds {len} bytes, the scene declares {declared}")));
    }
    read_at_most(file, declared)
}

/// A whole regular file of at most [`MAX_FILE_BYTES`] bytes (a scene file itself).
pub fn read_whole(file: &Path) -> Result<Vec<u8>> {
    let len = regular_file_len(file)?;
    if len > MAX_FILE_BYTES {
        return Err(Error::bad_file(file, format!("holds {len} bytes, more than {MAX_FILE_BYTES}")));
    }
    read_at_most(file, len)
}

/// The length of `file`, refused unless it is a regular file (a device such as `/dev/zero`
/// reports no length and never ends).
fn regular_file_len(file: &Path) -> Result<u64> {
    let meta = std::fs::metadata(file).map_err(|e| Error::io(file, e))?;
    if !meta.is_file() {
        return Err(Error::bad_file(file, "is not a regular file"));
    }
    Ok(meta.len())
}

/// At most `len` bytes of `file` (fewer if it shrank meanwhile), never more.
fn read_at_most(file: &Path, len: u64) -> Result<Vec<u8>> {
    let f = std::fs::File::open(file).map_err(|e| Error::io(file, e))?;
    let mut out = Vec::with_capacity(len as usize);
    f.take(len).read_to_end(&mut out).map_err(|e| Error::io(file, e))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_inside_the_folder_or_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let inner = dir.path().join("scene");
        std::fs::create_dir(&inner).unwrap();
        std::fs::write(inner.join("a.bin"), [1u8; 8]).unwrap();
        std::fs::write(dir.path().join("secret"), b"x").unwrap();
        let scene = inner.join("s.gltf");
        assert!(beside(&scene, "a.bin").is_ok());
        for bad in ["../secret", "/etc/hostname", "http://x/y", "sub/../../secret"] {
            let e = beside(&scene, bad).unwrap_err().to_string();
            assert!(e.contains("s.gltf") || e.contains("secret") || e.contains("sub"), "{bad}: {e}");
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(dir.path().join("secret"), inner.join("link")).unwrap();
            assert!(beside(&scene, "link").unwrap_err().to_string().contains("outside"));
            std::os::unix::fs::symlink("/dev/zero", inner.join("zero")).unwrap();
            assert!(beside(&scene, "zero").unwrap_err().to_string().contains("outside"));
        }
    }

    #[test]
    fn reads_are_bounded_by_what_is_declared() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("b.bin");
        std::fs::write(&f, [7u8; 10]).unwrap();
        assert_eq!(read_declared(&f, 10, 0).unwrap().len(), 10);
        assert_eq!(read_declared(&f, 8, 3).unwrap().len(), 8);
        assert!(read_declared(&f, 8, 0).unwrap_err().to_string().contains("declares 8"));
        assert!(read_declared(&f, 12, 3).is_err());
        assert!(read_declared(&f, u64::MAX - 1, 0).unwrap_err().to_string().contains("more than"));
        #[cfg(unix)]
        {
            // A device is refused before a byte is read: /dev/zero would never end.
            assert!(read_declared(Path::new("/dev/zero"), 10, 0).unwrap_err().to_string().contains("regular"));
            assert!(read_whole(Path::new("/dev/zero")).unwrap_err().to_string().contains("regular"));
        }
    }
}
