//! The `build-scaling` tool at a small size: the tiny and small cities, each generated and built
//! in a child process. It asserts what the tool reports is there and consistent (rows, counts
//! that grow with the scale, the database on disk, a finite fitted exponent), never a time.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn build_scaling_measures_each_scale() {
    let tool = PathBuf::from(env!("CARGO_BIN_EXE_build-scaling"));
    if !tool.with_file_name("hdov").exists() {
        // `cargo test -p hdov-tools` alone builds no `hdov`; `.ci/run` and `cargo test --workspace` do.
        assert!(std::env::var("CI").is_err(), "no hdov beside {}", tool.display());
        hdov_testkit::skip(&format!("no hdov beside {} (cargo build --release first)", tool.display()));
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (csv, svg) = (dir.path().join("scaling.csv"), dir.path().join("scaling.svg"));
    let work = dir.path().join("work");
    let out = Command::new(&tool).arg(&work).arg(&csv).arg(&svg).arg("tiny,small").output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2, "{text}");
    let num = |r: &[&str], i: usize| r[i].parse::<f64>().unwrap();
    for r in &rows {
        let db = work.join(r[0]).join("db");
        let on_disk: u64 = std::fs::read_dir(&db).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum();
        assert_eq!(num(r, 8) as u64, on_disk, "{}: database bytes", r[0]);
        assert!(num(r, 5) > 0.0 && num(r, 7) > 0.0, "{}: time and peak RSS measured", r[0]);
    }
    assert!(num(&rows[1], 1) > num(&rows[0], 1) && num(&rows[1], 3) > num(&rows[0], 3), "{text}");
    let line = stdout.lines().find(|l| l.starts_with("exponents")).unwrap();
    let b: f64 = line.split("build time ").nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
    assert!(b.is_finite() && b > 0.0, "{line}");
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // A scale folder that exists is refused, never replaced.
    let again = Command::new(&tool).arg(&work).arg(&csv).arg(&svg).arg("tiny").output().unwrap();
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("exists"));
}
