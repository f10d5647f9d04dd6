//! Directory transactions: what may be replaced, what is refused and left untouched, stale
//! leftovers, and a crash at every step of commit (the test binary re-runs itself as a child that
//! aborts at the step named by `HDOV_FAULT_STOP_AT`).

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::sync::atomic::{AtomicUsize, Ordering};

use hdov_storage::atomic::COMMIT_STEPS;
use hdov_storage::{DirTxn, Error, Overwrite, write_file_synced};

/// A directory's files and subdirectories ("dir/"), relative path to contents.
type Tree = BTreeMap<String, Vec<u8>>;

/// What the caller takes for an hdov database: a manifest with the marker.
fn is_db(dir: &Path) -> bool {
    fs::read(dir.join("manifest.json")).is_ok_and(|m| m.starts_with(br#"{"hdov": "database""#))
}

const OURS: Overwrite = Overwrite::IfOurs(is_db);

/// A database labelled `label`; different labels have different files, so a mix shows.
fn db(label: &str) -> Tree {
    let mut t = Tree::new();
    t.insert("manifest.json".into(), format!(r#"{{"hdov": "database", "build": "{label}"}}"#).into_bytes());
    t.insert(format!("{label}.pages"), format!("{label} pages").into_bytes());
    t.insert("lods/".into(), Vec::new());
    t.insert(format!("lods/{label}.blob"), format!("{label} lods").into_bytes());
    t
}

/// A user's folder that is not ours.
fn users_folder() -> Tree {
    let mut t = Tree::new();
    t.insert("thesis.tex".into(), b"\\section{Results}".to_vec());
    t.insert("photos/".into(), Vec::new());
    t.insert("photos/cat.jpg".into(), vec![0xff, 0xd8, 0xff]);
    t
}

fn write_tree(dir: &Path, tree: &Tree) {
    fs::create_dir_all(dir).unwrap();
    for (rel, bytes) in tree {
        match rel.strip_suffix('/') {
            Some(sub) => fs::create_dir_all(dir.join(sub)).unwrap(),
            None => write_file_synced(&dir.join(rel), bytes).unwrap(),
        }
    }
}

fn read_tree(dir: &Path) -> Tree {
    fn walk(dir: &Path, prefix: &str, out: &mut Tree) {
        for e in fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = format!("{prefix}{}", e.file_name().to_string_lossy());
            if e.file_type().unwrap().is_dir() {
                out.insert(format!("{name}/"), Vec::new());
                walk(&e.path(), &format!("{name}/"), out);
            } else {
                out.insert(name, fs::read(e.path()).unwrap());
            }
        }
    }
    let mut out = Tree::new();
    walk(dir, "", &mut out);
    out
}

/// The tree at `path`, None if nothing is there.
fn state(path: &Path) -> Option<Tree> {
    path.exists().then(|| read_tree(path))
}

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<_> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

fn not_ours_message(path: &Path) -> String {
    format!("{}: not an hdov database or an empty directory; refusing to replace it", path.display())
}

/// The pid of a process that has exited (and been reaped).
#[cfg(unix)]
fn dead_pid() -> u32 {
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "no-such-test"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    child.wait().unwrap();
    child.id()
}

#[test]
fn commit_creates_target() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("sub/db");
    let txn = DirTxn::begin(&target, Overwrite::Never).unwrap();
    assert!(!target.exists());
    assert!(txn.cleaned().is_empty());
    write_tree(txn.path(), &db("new"));
    txn.commit().unwrap();
    assert_eq!(read_tree(&target), db("new"));
    assert_eq!(entries(&root.path().join("sub")), vec!["db"]);
}

#[test]
fn never_refuses_any_existing_target() {
    let root = tempfile::tempdir().unwrap();
    let folder = root.path().join("folder");
    write_tree(&folder, &users_folder());
    let ours = root.path().join("ours");
    write_tree(&ours, &db("old"));
    let empty = root.path().join("empty");
    fs::create_dir(&empty).unwrap();
    let file = root.path().join("file");
    fs::write(&file, b"a file").unwrap();
    for target in [&folder, &ours, &empty] {
        let before = read_tree(target);
        let e = DirTxn::begin(target, Overwrite::Never).unwrap_err();
        assert!(matches!(e, Error::Exists { .. }), "{e}");
        assert_eq!(e.to_string(), format!("{}: exists", target.display()));
        assert_eq!(read_tree(target), before);
    }
    let e = DirTxn::begin(&file, Overwrite::Never).unwrap_err();
    assert_eq!(e.to_string(), format!("{}: exists", file.display()));
    assert_eq!(fs::read(&file).unwrap(), b"a file");
    assert_eq!(entries(root.path()), vec!["empty", "file", "folder", "ours"]);
}

#[test]
fn a_users_folder_is_refused_and_untouched() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    write_tree(&target, &users_folder());
    let e = DirTxn::begin(&target, OURS).unwrap_err();
    assert!(matches!(e, Error::NotOurs { .. }), "{e}");
    assert_eq!(e.to_string(), not_ours_message(&target));
    assert_eq!(read_tree(&target), users_folder());
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn a_regular_file_is_refused_and_untouched() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    fs::write(&target, b"not a directory").unwrap();
    let e = DirTxn::begin(&target, OURS).unwrap_err();
    assert_eq!(e.to_string(), not_ours_message(&target));
    assert_eq!(fs::read(&target).unwrap(), b"not a directory");
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[cfg(unix)]
#[test]
fn a_symlink_is_refused_even_to_a_database() {
    let root = tempfile::tempdir().unwrap();
    let real = root.path().join("real");
    write_tree(&real, &db("old"));
    let target = root.path().join("db");
    std::os::unix::fs::symlink(&real, &target).unwrap();
    let e = DirTxn::begin(&target, OURS).unwrap_err();
    assert_eq!(e.to_string(), not_ours_message(&target));
    assert_eq!(fs::read_link(&target).unwrap(), real);
    assert_eq!(read_tree(&real), db("old"));
    assert_eq!(entries(root.path()), vec!["db", "real"]);
}

#[test]
fn an_empty_directory_is_replaced() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    fs::create_dir(&target).unwrap();
    let txn = DirTxn::begin(&target, OURS).unwrap();
    write_tree(txn.path(), &db("new"));
    txn.commit().unwrap();
    assert_eq!(read_tree(&target), db("new"));
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn a_database_is_replaced_whole_at_commit() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    write_tree(&target, &db("old"));
    let txn = DirTxn::begin(&target, OURS).unwrap();
    write_tree(txn.path(), &db("new"));
    // The old database stays whole until commit.
    assert_eq!(read_tree(&target), db("old"));
    txn.commit().unwrap();
    assert_eq!(read_tree(&target), db("new"));
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn a_target_created_after_begin_is_never_clobbered() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    for overwrite in [Overwrite::Never, OURS] {
        // A directory of someone's files, then a regular file.
        let txn = DirTxn::begin(&target, overwrite).unwrap();
        write_tree(txn.path(), &db("new"));
        write_tree(&target, &users_folder());
        let e = txn.commit().unwrap_err();
        match overwrite {
            Overwrite::Never => assert_eq!(e.to_string(), format!("{}: exists", target.display())),
            Overwrite::IfOurs(_) => assert_eq!(e.to_string(), not_ours_message(&target)),
        }
        assert_eq!(read_tree(&target), users_folder());
        assert_eq!(entries(root.path()), vec!["db"]);
        fs::remove_dir_all(&target).unwrap();

        let txn = DirTxn::begin(&target, overwrite).unwrap();
        write_tree(txn.path(), &db("new"));
        fs::write(&target, b"a file").unwrap();
        assert!(txn.commit().is_err());
        assert_eq!(fs::read(&target).unwrap(), b"a file");
        assert_eq!(entries(root.path()), vec!["db"]);
        fs::remove_file(&target).unwrap();
    }
}

#[test]
fn a_database_turned_into_a_users_folder_after_begin_is_not_replaced() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    write_tree(&target, &db("old"));
    let txn = DirTxn::begin(&target, OURS).unwrap();
    write_tree(txn.path(), &db("new"));
    fs::remove_dir_all(&target).unwrap();
    write_tree(&target, &users_folder());
    assert_eq!(txn.commit().unwrap_err().to_string(), not_ours_message(&target));
    assert_eq!(read_tree(&target), users_folder());
    assert_eq!(entries(root.path()), vec!["db"]);
}

/// Says whether `dir` is ours, and on its second call (commit's check) turns `dir` into a user's
/// folder right after answering: the race between commit's check and the swap.
fn ours_then_taken_over(dir: &Path) -> bool {
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let ours = is_db(dir);
    if CALLS.fetch_add(1, Ordering::SeqCst) == 1 {
        fs::remove_dir_all(dir).unwrap();
        write_tree(dir, &users_folder());
    }
    ours
}

#[test]
fn what_the_swap_took_is_checked_again_before_it_is_deleted() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    write_tree(&target, &db("old"));
    let txn = DirTxn::begin(&target, Overwrite::IfOurs(ours_then_taken_over)).unwrap();
    write_tree(txn.path(), &db("new"));
    assert_eq!(txn.commit().unwrap_err().to_string(), not_ours_message(&target));
    assert_eq!(read_tree(&target), users_folder());
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn drop_without_commit_removes_temp() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    {
        let txn = DirTxn::begin(&target, Overwrite::Never).unwrap();
        write_tree(txn.path(), &db("new"));
        assert_eq!(txn.path().file_name().unwrap().to_string_lossy(), format!(".db.tmp-{}", std::process::id()));
    }
    assert!(entries(root.path()).is_empty());
}

#[cfg(unix)]
#[test]
fn only_leftovers_of_dead_processes_are_removed() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    let dead = dead_pid();
    let parent = std::os::unix::process::parent_id();
    let kept = [
        // Named like ours, but their process is alive: pid 1, the process that runs this test.
        ".db.tmp-1".to_string(),
        ".db.old-1".to_string(),
        format!(".db.tmp-{parent}"),
        format!(".db.old-{parent}"),
        // Not exactly the pattern, or not for this target.
        format!(".db.tmp-0{dead}"),
        format!(".db.tmp-{dead}x"),
        format!(".db.tmp-{dead}.bak"),
        ".db.tmp-".to_string(),
        format!(".dbx.tmp-{dead}"),
        format!(".other.old-{dead}"),
        format!("db.tmp-{dead}"),
        ".hidden".to_string(),
    ];
    for name in &kept {
        write_tree(&root.path().join(name), &users_folder());
    }
    let stale = [format!(".db.old-{dead}"), format!(".db.tmp-{dead}")];
    write_tree(&root.path().join(&stale[0]), &db("old"));
    write_tree(&root.path().join(&stale[1]), &db("half"));
    // The target exists, so the dead `.old-` is not restored but removed.
    write_tree(&target, &db("current"));

    let txn = DirTxn::begin(&target, OURS).unwrap();
    assert_eq!(txn.cleaned(), stale.iter().map(|s| root.path().join(s)).collect::<Vec<_>>());
    assert_eq!(txn.restored(), None);
    write_tree(txn.path(), &db("new"));
    txn.commit().unwrap();
    assert_eq!(read_tree(&target), db("new"));
    for name in &kept {
        assert_eq!(read_tree(&root.path().join(name)), users_folder(), "{name}");
    }
    let mut want: Vec<_> = kept.iter().cloned().chain(["db".to_string()]).collect();
    want.sort();
    assert_eq!(entries(root.path()), want);
}

#[test]
fn a_live_processes_old_database_is_not_restored() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    let live = root.path().join(".db.old-1");
    write_tree(&live, &db("old"));
    let txn = DirTxn::begin(&target, OURS).unwrap();
    assert_eq!(txn.restored(), None);
    assert!(txn.cleaned().is_empty());
    drop(txn);
    assert_eq!(read_tree(&live), db("old"));
    assert_eq!(entries(root.path()), vec![".db.old-1"]);
}

#[test]
fn our_own_pid_is_live_only_while_we_write_the_target() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    let pid = std::process::id();
    // A transaction of this process is writing: a second one on the same target (even spelled
    // differently) is refused and leaves the first one's work alone.
    let first = DirTxn::begin(&target, OURS).unwrap();
    write_tree(first.path(), &db("new"));
    let e = DirTxn::begin(&root.path().join(".").join("db"), OURS).unwrap_err();
    assert!(e.to_string().ends_with("already being written by this process"), "{e}");
    assert_eq!(read_tree(first.path()), db("new"));
    first.commit().unwrap();
    assert_eq!(read_tree(&target), db("new"));

    // With none writing, `.db.tmp-OURPID` was left by an earlier process that had our pid (a
    // container's builds all get the same one): stale.
    let earlier = root.path().join(format!(".db.tmp-{pid}"));
    write_tree(&earlier, &db("half"));
    let txn = DirTxn::begin(&target, OURS).unwrap();
    assert_eq!(txn.cleaned(), [earlier]);
    drop(txn);
    assert_eq!(entries(root.path()), vec!["db"]);
}

// ---- Crash at every commit step ----

/// Where the child works (`DIR/db`), set only for the child.
const DIR_ENV: &str = "HDOV_TEST_CRASH_DIR";

/// The child: builds `db("new")` into `$HDOV_TEST_CRASH_DIR/db` and commits; with
/// `HDOV_FAULT_STOP_AT` set it aborts at that step. Does nothing when run by hand.
#[test]
#[ignore = "run by the crash tests as a child process"]
fn crash_child() {
    let Some(dir) = std::env::var_os(DIR_ENV) else { return };
    #[cfg(unix)]
    {
        use rustix::process::{Resource, Rlimit, getrlimit, setrlimit};
        // No core dump for the abort; 1 rather than 0 also stops one piped to a handler.
        let hard = getrlimit(Resource::Core).maximum;
        let _ = setrlimit(Resource::Core, Rlimit { current: Some(1), maximum: hard });
    }
    let txn = DirTxn::begin(&Path::new(&dir).join("db"), OURS).unwrap();
    write_tree(txn.path(), &db("new"));
    txn.commit().unwrap();
}

/// Runs the child on `dir`, stopping at `step`: its pid and exit status.
fn run_child(dir: &Path, step: &str, fallback: bool) -> (u32, ExitStatus) {
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    cmd.args(["--exact", "crash_child", "--ignored", "--nocapture", "--test-threads=1"]);
    cmd.env(DIR_ENV, dir).env("HDOV_FAULT_STOP_AT", step);
    if fallback {
        cmd.env("HDOV_FAULT_RENAME_FALLBACK", "1");
    }
    let child = cmd.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
    let pid = child.id();
    let out = child.wait_with_output().unwrap();
    if !out.status.success() && !aborted(&out.status) {
        panic!(
            "child at {step}: {}\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    (pid, out.status)
}

#[cfg(unix)]
fn aborted(status: &ExitStatus) -> bool {
    use std::os::unix::process::ExitStatusExt;
    status.signal() == Some(6)
}

#[cfg(not(unix))]
fn aborted(status: &ExitStatus) -> bool {
    !status.success()
}

/// A child crashes at every step of commit that its path goes through; afterwards the target is
/// exactly the old database (None: none) or exactly the new one, and the next begin cleans up.
fn crash_at_every_step(replacing: bool, fallback: bool) {
    let old = replacing.then(|| db("old"));
    let on_path: Vec<&str> = COMMIT_STEPS
        .iter()
        .copied()
        .filter(|s| match *s {
            "moved-aside" | "old-moved" => replacing && fallback,
            "old-removed" => replacing,
            _ => true,
        })
        .collect();
    let swapped_at = COMMIT_STEPS.iter().position(|s| *s == "swapped").unwrap();
    for (i, step) in COMMIT_STEPS.iter().enumerate() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("db");
        if let Some(old) = &old {
            write_tree(&target, old);
        }
        let (pid, status) = run_child(root.path(), step, fallback);
        let crashed = aborted(&status);
        assert_eq!(crashed, on_path.contains(step), "{step}: {status}");
        let want = if crashed && i < swapped_at { old.clone() } else { Some(db("new")) };

        // Right after the crash: the old or the new, never missing, never a mix. The one
        // exception is the fallback's documented window, which the next begin repairs.
        let window = replacing && fallback && *step == "moved-aside";
        assert_eq!(state(&target), if window { None } else { want.clone() }, "{step}");
        let leftovers: Vec<PathBuf> =
            entries(root.path()).iter().filter(|n| *n != "db").map(|n| root.path().join(n)).collect();
        for l in &leftovers {
            let name = l.file_name().unwrap().to_string_lossy();
            assert!(name == format!(".db.tmp-{pid}") || name == format!(".db.old-{pid}"), "{step}: {name}");
        }

        let txn = DirTxn::begin(&target, OURS).unwrap();
        let restored = window.then(|| root.path().join(format!(".db.old-{pid}")));
        assert_eq!(txn.restored(), restored.as_deref(), "{step}");
        let cleaned: Vec<PathBuf> = leftovers.into_iter().filter(|l| Some(l) != restored.as_ref()).collect();
        assert_eq!(txn.cleaned(), cleaned, "{step}");
        assert_eq!(state(&target), want, "{step}");
        write_tree(txn.path(), &db("next"));
        txn.commit().unwrap();
        assert_eq!(read_tree(&target), db("next"), "{step}");
        assert_eq!(entries(root.path()), vec!["db"], "{step}");
    }
}

#[test]
fn crash_at_every_step_when_creating() {
    crash_at_every_step(false, false);
}

#[test]
fn crash_at_every_step_when_replacing() {
    crash_at_every_step(true, false);
}

#[test]
fn crash_at_every_step_when_creating_by_plain_renames() {
    crash_at_every_step(false, true);
}

#[test]
fn crash_at_every_step_when_replacing_by_plain_renames() {
    crash_at_every_step(true, true);
}
