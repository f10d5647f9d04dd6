//! Directory transactions: a database is built in a temporary directory beside its target,
//! fsynced, then swapped into place, so that at every instant the target is the old database or
//! the new one, never a half one and never missing (see "Crash guarantee" in docs/format.md).
//!
//! - Only an empty directory or one the caller recognises as its own is ever replaced
//!   ([`Overwrite`]); anything else at the target is refused before any work and never touched.
//! - On Linux the swap is one `renameat2(RENAME_EXCHANGE)` (creating: `RENAME_NOREPLACE`).
//!   Elsewhere, or on a filesystem without it, the old database is renamed aside to
//!   `.NAME.old-PID` and the new one renamed in: a crash between the two leaves no target, and
//!   the next [`DirTxn::begin`] renames the old one back.
//! - A killed process leaves `.NAME.tmp-PID` (and `.NAME.old-PID`); the next `begin` on the same
//!   target removes those whose process is gone and reports them in [`DirTxn::cleaned`].

use std::ffi::{OsStr, OsString};
use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use crate::error::{Error, Result, path_str};

/// Writes `bytes` to `path` and fsyncs the file.
pub fn write_file_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = File::create(path).map_err(|e| Error::io(path, e))?;
    f.write_all(bytes).map_err(|e| Error::io(path, e))?;
    f.sync_all().map_err(|e| Error::io(path, e))
}

/// Copies `from` to the new file `to` without holding it in memory, and makes the copy durable;
/// returns its length.
pub fn copy_file_synced(from: &Path, to: &Path) -> Result<u64> {
    let mut src = File::open(from).map_err(|e| Error::io(from, e))?;
    let mut dst = File::create(to).map_err(|e| Error::io(to, e))?;
    let n = std::io::copy(&mut src, &mut dst).map_err(|e| Error::io(to, e))?;
    dst.sync_all().map_err(|e| Error::io(to, e))?;
    Ok(n)
}

/// What [`DirTxn::begin`] may do with an existing target.
#[derive(Clone, Copy, Debug)]
pub enum Overwrite {
    /// Refuse any existing target ([`Error::Exists`]).
    Never,
    /// Replace an existing target only if it is an empty directory or a directory the predicate
    /// recognises as ours (an hdov database); refuse anything else ([`Error::NotOurs`]): a
    /// directory of other files, a regular file, a symlink. The predicate only sees directories.
    IfOurs(fn(&Path) -> bool),
}

/// The steps of [`DirTxn::commit`], in order. For crash tests: a process whose environment has
/// `HDOV_FAULT_STOP_AT=STEP` aborts (no destructors, no cleanup) when its commit reaches `STEP`.
///
/// - `before-sync`: nothing done yet;
/// - `synced`: every file and directory of the new database fsynced;
/// - `moved-aside` (fallback only, replacing): the old database renamed to `.NAME.old-PID`;
/// - `swapped`: the new database at the target (the old one, if any, under the temp name
///   `.NAME.tmp-PID`, or under `.NAME.old-PID` in the fallback);
/// - `parent-synced`: the parent directory fsynced, the swap is durable;
/// - `old-moved` (fallback only): the old database renamed from `.NAME.old-PID` to the temp name;
/// - `old-removed`: the old database deleted (replacing only).
pub const COMMIT_STEPS: &[&str] =
    &["before-sync", "synced", "moved-aside", "swapped", "parent-synced", "old-moved", "old-removed"];

/// Aborts the process here if `HDOV_FAULT_STOP_AT` names `step` (tests only).
fn reached(step: &str) {
    static STOP_AT: OnceLock<Option<String>> = OnceLock::new();
    debug_assert!(COMMIT_STEPS.contains(&step), "{step} is not in COMMIT_STEPS");
    if STOP_AT.get_or_init(|| std::env::var("HDOV_FAULT_STOP_AT").ok()).as_deref() == Some(step) {
        std::process::abort();
    }
}

/// A directory being written; becomes `target` on [`commit`](Self::commit), vanishes on drop.
#[derive(Debug)]
pub struct DirTxn {
    target: PathBuf,
    parent: PathBuf,
    name: OsString,
    temp: PathBuf,
    overwrite: Overwrite,
    cleaned: Vec<PathBuf>,
    restored: Option<PathBuf>,
    /// Whether what is at `temp` is ours to delete: our build, or an old database checked ours.
    owns_temp: bool,
    _writing: Writing,
}

impl DirTxn {
    /// Starts writing `target`, creating its parent if missing:
    ///
    /// 1. if `target` is missing and a dead process left `.NAME.old-PID` (a crash inside the
    ///    fallback's rename window), renames that old database back (see [`restored`](Self::restored));
    /// 2. refuses an existing `target` unless `overwrite` allows replacing it ([`Error::Exists`],
    ///    [`Error::NotOurs`]), before any other work;
    /// 3. removes the `.NAME.tmp-PID` and `.NAME.old-PID` entries left by dead processes (see
    ///    [`cleaned`](Self::cleaned));
    /// 4. creates the temporary directory `.NAME.tmp-PID` beside `target`.
    pub fn begin(target: &Path, overwrite: Overwrite) -> Result<Self> {
        let name = target.file_name().ok_or_else(|| Error::invalid(target, "not a directory name"))?.to_owned();
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let writing = Writing::start(target, &parent, &name)?;
        let mut txn = Self {
            target: target.to_path_buf(),
            temp: sibling(&parent, &name, "tmp", std::process::id()),
            parent,
            name,
            overwrite,
            cleaned: Vec::new(),
            restored: None,
            owns_temp: false,
            _writing: writing,
        };
        let mut stale = txn.stale_leftovers()?;
        // Before the check: a target missing after a crash in the fallback's window is restored.
        if !exists(&txn.target)?
            && let Some(i) = stale.iter().position(|(_, kind)| *kind == "old")
        {
            let (old, _) = stale.remove(i);
            txn.restore(&old)?;
        }
        check_target(&txn.target, &txn.target, overwrite)?;
        for (path, _) in stale {
            remove_any(&path)?;
            txn.cleaned.push(path);
        }
        fs::create_dir(&txn.temp).map_err(|e| Error::io(&txn.temp, e))?;
        txn.owns_temp = true;
        Ok(txn)
    }

    /// The temporary directory to write into.
    pub fn path(&self) -> &Path {
        &self.temp
    }

    /// The directory this transaction will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Leftovers of dead processes (`.NAME.tmp-PID`, `.NAME.old-PID`) that `begin` removed.
    pub fn cleaned(&self) -> &[PathBuf] {
        &self.cleaned
    }

    /// The `.NAME.old-PID` that `begin` renamed back to the missing target: the database a crashed
    /// replace had moved aside.
    pub fn restored(&self) -> Option<&Path> {
        self.restored.as_deref()
    }

    /// Fsyncs every file and directory under the temporary directory, checks the target again
    /// (it may have changed since `begin`), then swaps the new database in; an old one is deleted
    /// last. See [`COMMIT_STEPS`].
    pub fn commit(mut self) -> Result<()> {
        reached("before-sync");
        sync_tree(&self.temp)?;
        reached("synced");
        // Decide from what is at the target now; once more if it changes under the rename.
        for _ in 0..3 {
            let done = if check_target(&self.target, &self.target, self.overwrite)? {
                self.replace()?
            } else {
                self.create()?
            };
            if done {
                return Ok(());
            }
        }
        Err(Error::invalid(&self.target, "kept appearing and vanishing during commit"))
    }

    /// Renames the new database to the missing target. Ok(false): a target appeared meanwhile.
    fn create(&mut self) -> Result<bool> {
        let renamed = match rename_atomic(&self.temp, &self.target, Rename::NoReplace) {
            Ok(true) => Ok(()),
            // A plain rename fails on a file or a non-empty directory; it replaces an empty one.
            Ok(false) => fs::rename(&self.temp, &self.target),
            Err(e) => Err(e),
        };
        match renamed {
            Ok(()) => {}
            Err(e) if target_appeared(&e) => return Ok(false),
            Err(e) => return Err(Error::io(&self.target, e)),
        }
        self.owns_temp = false;
        reached("swapped");
        sync_dir(&self.parent)?;
        reached("parent-synced");
        Ok(true)
    }

    /// Exchanges the new database with the existing target, then deletes the old one. Ok(false):
    /// the target vanished meanwhile.
    fn replace(&mut self) -> Result<bool> {
        match rename_atomic(&self.temp, &self.target, Rename::Exchange) {
            Ok(true) => {}
            Ok(false) => return self.replace_by_renames(),
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(Error::io(&self.target, e)),
        }
        // The temp name now holds what was at the target; delete it only if it still may be.
        self.owns_temp = false;
        reached("swapped");
        if let Err(refused) = check_target(&self.temp, &self.target, self.overwrite) {
            // It changed after the check in commit: give it its place back.
            match rename_atomic(&self.temp, &self.target, Rename::Exchange) {
                Ok(true) => self.owns_temp = true,
                Ok(false) => return Err(Error::io(&self.temp, io::Error::other("could not swap back"))),
                Err(e) => return Err(Error::io(&self.temp, e)),
            }
            return Err(refused);
        }
        self.owns_temp = true;
        sync_dir(&self.parent)?;
        reached("parent-synced");
        remove_any(&self.temp)?;
        self.owns_temp = false;
        reached("old-removed");
        Ok(true)
    }

    /// The fallback without an atomic exchange: between the two renames there is no target; a
    /// crash there leaves the old database as `.NAME.old-PID`, which the next `begin` restores.
    fn replace_by_renames(&mut self) -> Result<bool> {
        let old = sibling(&self.parent, &self.name, "old", std::process::id());
        match fs::rename(&self.target, &old) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(Error::io(&self.target, e)),
        }
        reached("moved-aside");
        if let Err(refused) = check_target(&old, &self.target, self.overwrite) {
            fs::rename(&old, &self.target).map_err(|e| Error::io(&old, e))?;
            return Err(refused);
        }
        if let Err(e) = fs::rename(&self.temp, &self.target) {
            // Best effort; a crash or failure here is repaired by the next begin.
            let _ = fs::rename(&old, &self.target);
            return Err(Error::io(&self.target, e));
        }
        self.owns_temp = false;
        reached("swapped");
        sync_dir(&self.parent)?;
        reached("parent-synced");
        // Under `.old-` a leftover is a whole database that begin may restore; under the temp
        // name it is garbage, which a half-deleted one is.
        fs::rename(&old, &self.temp).map_err(|e| Error::io(&old, e))?;
        self.owns_temp = true;
        reached("old-moved");
        remove_any(&self.temp)?;
        self.owns_temp = false;
        reached("old-removed");
        Ok(true)
    }

    /// Renames the database a crashed replace left at `old` back to the missing target.
    fn restore(&mut self, old: &Path) -> Result<()> {
        let renamed = match rename_atomic(old, &self.target, Rename::NoReplace) {
            Ok(true) => Ok(()),
            Ok(false) => fs::rename(old, &self.target),
            Err(e) => Err(e),
        };
        match renamed {
            Ok(()) => {}
            // Someone else created the target meanwhile; `old` stays a stale leftover.
            Err(e) if target_appeared(&e) => return Ok(()),
            Err(e) => return Err(Error::io(old, e)),
        }
        sync_dir(&self.parent)?;
        self.restored = Some(old.to_path_buf());
        Ok(())
    }

    /// `.NAME.tmp-PID` and `.NAME.old-PID` entries beside the target whose process is gone,
    /// sorted by name. The exact pattern and a dead pid are what make them ours to remove.
    fn stale_leftovers(&self) -> Result<Vec<(PathBuf, &'static str)>> {
        let mut found = Vec::new();
        for entry in fs::read_dir(&self.parent).map_err(|e| Error::io(&self.parent, e))? {
            let entry = entry.map_err(|e| Error::io(&self.parent, e))?;
            let file_name = entry.file_name();
            for kind in ["tmp", "old"] {
                if let Some(pid) = leftover_pid(&file_name, &self.name, kind) {
                    // Our own pid: a predecessor that had it, since `Writing` excludes a live
                    // transaction of this process on this target.
                    if pid == std::process::id() || !alive(pid) {
                        found.push((entry.path(), kind));
                    }
                }
            }
        }
        found.sort();
        Ok(found)
    }
}

impl Drop for DirTxn {
    fn drop(&mut self) {
        if self.owns_temp {
            // Best effort: an error here leaves a stale leftover that the next begin removes.
            let _ = remove_any(&self.temp);
        }
    }
}

/// Targets (canonical paths) that a live `DirTxn` of this process is writing: one at a time each,
/// since they would share the temp name.
#[derive(Debug)]
struct Writing(PathBuf);

static WRITING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

impl Writing {
    fn start(target: &Path, parent: &Path, name: &OsStr) -> Result<Self> {
        let key = fs::canonicalize(parent).map_err(|e| Error::io(parent, e))?.join(name);
        let mut writing = WRITING.lock().unwrap_or_else(|e| e.into_inner());
        if writing.contains(&key) {
            return Err(Error::invalid(target, "already being written by this process"));
        }
        writing.push(key.clone());
        Ok(Self(key))
    }
}

impl Drop for Writing {
    fn drop(&mut self) {
        WRITING.lock().unwrap_or_else(|e| e.into_inner()).retain(|k| *k != self.0);
    }
}

/// Whether an existing `path` may be replaced: Ok(false) when nothing is there, Ok(true) for an
/// empty directory or one the predicate accepts, else the refusal, naming `shown`.
fn check_target(path: &Path, shown: &Path, overwrite: Overwrite) -> Result<bool> {
    let meta = match fs::symlink_metadata(path) {
        Ok(meta) => meta,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(Error::io(path, e)),
    };
    let ours = match overwrite {
        Overwrite::Never => return Err(Error::Exists { path: path_str(shown) }),
        Overwrite::IfOurs(ours) => ours,
    };
    // A symlink is refused whatever it points to: replacing it would not replace that.
    let empty = || fs::read_dir(path).map(|mut d| d.next().is_none()).map_err(|e| Error::io(path, e));
    if meta.is_dir() && (empty()? || ours(path)) { Ok(true) } else { Err(Error::NotOurs { path: path_str(shown) }) }
}

fn exists(path: &Path) -> Result<bool> {
    fs::symlink_metadata(path).map(|_| true).or_else(|e| match e.kind() {
        io::ErrorKind::NotFound => Ok(false),
        _ => Err(Error::io(path, e)),
    })
}

/// `PARENT/.NAME.KIND-PID`.
fn sibling(parent: &Path, name: &OsStr, kind: &str, pid: u32) -> PathBuf {
    let mut s = OsString::from(".");
    s.push(name);
    s.push(format!(".{kind}-{pid}"));
    parent.join(s)
}

/// The pid of `file_name` if it is exactly `.NAME.KIND-PID` (decimal, no leading zero).
fn leftover_pid(file_name: &OsStr, name: &OsStr, kind: &str) -> Option<u32> {
    let rest = file_name.as_encoded_bytes().strip_prefix(b".")?;
    let rest = rest.strip_prefix(name.as_encoded_bytes())?;
    let digits = rest.strip_prefix(format!(".{kind}-").as_bytes())?;
    let pid: u32 = std::str::from_utf8(digits).ok()?.parse().ok()?;
    (pid.to_string().as_bytes() == digits && pid != 0).then_some(pid)
}

/// Whether process `pid` exists (or cannot be ruled out).
#[cfg(unix)]
fn alive(pid: u32) -> bool {
    use rustix::process::{Pid, test_kill_process};
    let Some(pid) = i32::try_from(pid).ok().and_then(Pid::from_raw) else { return true };
    // EPERM: it exists, as another user's.
    !matches!(test_kill_process(pid), Err(rustix::io::Errno::SRCH))
}

/// No portable way to ask here: never take a leftover for stale.
#[cfg(not(unix))]
fn alive(_pid: u32) -> bool {
    true
}

/// Errors of a no-replace rename that mean the target exists now.
fn target_appeared(e: &io::Error) -> bool {
    matches!(e.kind(), io::ErrorKind::AlreadyExists | io::ErrorKind::DirectoryNotEmpty | io::ErrorKind::NotADirectory)
}

/// The atomic renames of `renameat2`.
#[derive(Clone, Copy)]
enum Rename {
    /// `RENAME_EXCHANGE`: swap two existing entries.
    Exchange,
    /// `RENAME_NOREPLACE`: fail with `EEXIST` if the destination exists.
    NoReplace,
}

/// `renameat2(from, to, how)`. Ok(false) where the system or the filesystem lacks it (the caller
/// falls back to plain renames), or where `HDOV_FAULT_RENAME_FALLBACK=1` asks for that (tests).
#[cfg(any(target_os = "linux", target_os = "android"))]
fn rename_atomic(from: &Path, to: &Path, how: Rename) -> io::Result<bool> {
    use rustix::fs::{CWD, RenameFlags, renameat_with};
    use rustix::io::Errno;
    static FALLBACK: OnceLock<bool> = OnceLock::new();
    if *FALLBACK.get_or_init(|| std::env::var_os("HDOV_FAULT_RENAME_FALLBACK").is_some_and(|v| v == "1")) {
        return Ok(false);
    }
    let flags = match how {
        Rename::Exchange => RenameFlags::EXCHANGE,
        Rename::NoReplace => RenameFlags::NOREPLACE,
    };
    match renameat_with(CWD, from, CWD, to, flags) {
        Ok(()) => Ok(true),
        // ENOSYS: a kernel (or seccomp filter) without renameat2; EINVAL: a filesystem without the flag.
        Err(Errno::NOSYS | Errno::INVAL) => Ok(false),
        Err(e) => Err(e.into()),
    }
}

#[cfg(not(any(target_os = "linux", target_os = "android")))]
fn rename_atomic(_from: &Path, _to: &Path, _how: Rename) -> io::Result<bool> {
    Ok(false)
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
