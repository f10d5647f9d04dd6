//! Directory transactions: refuse without force, replace with it, clean up when dropped.

use std::fs;

use hdov_storage::{DirTxn, Error, Overwrite, write_file_synced};

fn entries(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<_> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn commit_creates_target() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("sub/db");
    let txn = DirTxn::begin(&target, Overwrite::Never).unwrap();
    assert!(!target.exists());
    write_file_synced(&txn.path().join("a"), b"one").unwrap();
    fs::create_dir(txn.path().join("nested")).unwrap();
    write_file_synced(&txn.path().join("nested/b"), b"two").unwrap();
    txn.commit().unwrap();
    assert_eq!(fs::read(target.join("a")).unwrap(), b"one");
    assert_eq!(fs::read(target.join("nested/b")).unwrap(), b"two");
    assert_eq!(entries(&root.path().join("sub")), vec!["db"]);
}

#[test]
fn existing_target_needs_force() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    fs::create_dir(&target).unwrap();
    write_file_synced(&target.join("old"), b"old").unwrap();
    let e = DirTxn::begin(&target, Overwrite::Never).unwrap_err();
    assert!(matches!(e, Error::Exists { .. }));
    assert!(e.to_string().ends_with("exists; pass --force to overwrite"), "{e}");

    let txn = DirTxn::begin(&target, Overwrite::IfOurs(|_| true)).unwrap();
    write_file_synced(&txn.path().join("new"), b"new").unwrap();
    // The old database stays whole until commit.
    assert_eq!(fs::read(target.join("old")).unwrap(), b"old");
    txn.commit().unwrap();
    assert_eq!(entries(&target), vec!["new"]);
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn target_created_meanwhile_is_not_clobbered() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    let txn = DirTxn::begin(&target, Overwrite::Never).unwrap();
    fs::create_dir(&target).unwrap();
    assert!(matches!(txn.commit(), Err(Error::Exists { .. })));
    assert_eq!(entries(root.path()), vec!["db"]);
}

#[test]
fn drop_without_commit_removes_temp() {
    let root = tempfile::tempdir().unwrap();
    let target = root.path().join("db");
    {
        let txn = DirTxn::begin(&target, Overwrite::Never).unwrap();
        write_file_synced(&txn.path().join("a"), b"x").unwrap();
        assert!(txn.path().exists());
        assert!(txn.path().file_name().unwrap().to_string_lossy().starts_with(".db.tmp-"));
    }
    assert!(entries(root.path()).is_empty());
}
