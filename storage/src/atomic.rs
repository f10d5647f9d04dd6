//! Directory transactions: a database is built in a temporary directory beside its target,
//! fsynced, then renamed into place, so a crashed build never leaves a half database that opens
//! and an overwritten database stays intact until its replacement is complete.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result, path_str};

/// Writes `bytes` to `path` and fsyncs the file.
pub fn write_file_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = File::create(path).map_err(|e| Error::io(path, e))?;
    f.write_all(bytes).map_err(|e| Error::io(path, e))?;
    f.sync_all().map_err(|e| Error::io(path, e))
}

/// What [`DirTxn::begin`] may do with an existing target.
#[derive(Clone, Copy, Debug)]
pub enum Overwrite {
    Never,
    /// Replace an existing target only if it is an empty directory or the predicate says it is ours.
    IfOurs(fn(&Path) -> bool),
}

/// A directory being written; becomes `target` on [`commit`](Self::commit), vanishes on drop.
#[derive(Debug)]
pub struct DirTxn {
    target: PathBuf,
    temp: PathBuf,
    force: bool,
    committed: bool,
    cleaned: Vec<PathBuf>,
}

fn check_target(target: &Path, overwrite: Overwrite) -> Result<()> {
    if !exists(target) {
        return Ok(());
    }
    match overwrite {
        Overwrite::Never => Err(Error::Exists { path: path_str(target) }),
        Overwrite::IfOurs(ours) => {
            let meta = fs::symlink_metadata(target).map_err(|e| Error::io(target, e))?;
            let empty = meta.is_dir() && fs::read_dir(target).map_err(|e| Error::io(target, e))?.next().is_none();
            if meta.is_dir() && (empty || ours(target)) { Ok(()) } else { Err(Error::NotOurs { path: path_str(target) }) }
        }
    }
}

fn split_target(target: &Path) -> Result<(PathBuf, String)> {
    let name = target
        .file_name()
        .ok_or_else(|| Error::invalid(target, "not a directory name"))?
        .to_string_lossy()
        .into_owned();
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name))
}

fn exists(path: &Path) -> bool {
    fs::symlink_metadata(path).is_ok()
}

impl DirTxn {
    /// Starts writing `target`: creates `.<name>.tmp-<pid>` beside it (and the parent, if
    /// missing). Refuses when `target` exists and `force` is false.
    pub fn begin(target: &Path, overwrite: Overwrite) -> Result<Self> {
        check_target(target, overwrite)?;
        let force = matches!(overwrite, Overwrite::IfOurs(_));
        let (parent, name) = split_target(target)?;
        fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let temp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
        if exists(&temp) {
            // Left by an earlier run that died with our pid; it never was a database.
            fs::remove_dir_all(&temp).map_err(|e| Error::io(&temp, e))?;
        }
        fs::create_dir(&temp).map_err(|e| Error::io(&temp, e))?;
        Ok(Self { target: target.to_path_buf(), temp, force, committed: false, cleaned: Vec::new() })
    }

    /// The temporary directory to write into.
    pub fn path(&self) -> &Path {
        &self.temp
    }

    /// Leftovers of dead processes removed by `begin`.
    pub fn cleaned(&self) -> &[PathBuf] {
        &self.cleaned
    }

    /// The directory this transaction will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Fsyncs every file and directory under the temporary directory, then renames it into
    /// place. An existing target (with `force`) is renamed aside first and deleted last.
    pub fn commit(mut self) -> Result<()> {
        sync_tree(&self.temp)?;
        let (parent, name) = split_target(&self.target)?;
        let old = if exists(&self.target) {
            if !self.force {
                return Err(Error::Exists { path: path_str(&self.target) });
            }
            let old = parent.join(format!(".{name}.old-{}", std::process::id()));
            if exists(&old) {
                remove_any(&old)?;
            }
            fs::rename(&self.target, &old).map_err(|e| Error::io(&self.target, e))?;
            Some(old)
        } else {
            None
        };
        fs::rename(&self.temp, &self.target).map_err(|e| Error::io(&self.target, e))?;
        self.committed = true;
        sync_dir(&parent)?;
        if let Some(old) = old {
            remove_any(&old)?;
            sync_dir(&parent)?;
        }
        Ok(())
    }
}

impl Drop for DirTxn {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: an error here leaves only a hidden temp directory behind.
            let _ = fs::remove_dir_all(&self.temp);
        }
    }
}

fn remove_any(path: &Path) -> Result<()> {
    let meta = fs::symlink_metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() { fs::remove_dir_all(path) } else { fs::remove_file(path) }.map_err(|e| Error::io(path, e))
}

fn sync_dir(dir: &Path) -> Result<()> {
    File::open(dir).and_then(|d| d.sync_all()).map_err(|e| Error::io(dir, e))
}

fn sync_tree(dir: &Path) -> Result<()> {
    for entry in fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let path = entry.path();
        let ty = entry.file_type().map_err(|e| Error::io(&path, e))?;
        if ty.is_dir() {
            sync_tree(&path)?;
        } else if ty.is_file() {
            File::open(&path).and_then(|f| f.sync_all()).map_err(|e| Error::io(&path, e))?;
        }
    }
    sync_dir(dir)
}
