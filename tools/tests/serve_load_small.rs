//! The `serve-load` tool at a small size (issue 20's load test in CI): 8 clients and 2,000
//! requests against `hdov serve` on the tiny city, every answer checked against
//! `Database::query` and every mesh against `lod_glb`. It asserts no errors, never a latency:
//! speed is measured by the tool itself (docs/serve.md), not in tests.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn serve_load_answers_every_request_as_the_library_does() {
    // `hdov` beside this package's programs (cargo test --workspace builds both into one folder).
    let hdov = PathBuf::from(env!("CARGO_BIN_EXE_serve-load")).with_file_name("hdov");
    if !hdov.exists() {
        // `cargo test -p hdov-tools` alone builds no `hdov`; `.ci/run` and `cargo test --workspace` do.
        assert!(std::env::var("CI").is_err(), "{} is missing", hdov.display());
        hdov_testkit::skip(&format!("no {} (cargo build --release first)", hdov.display()));
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (_, db) = hdov_testkit::scenes::tiny_city_database(dir.path());
    let out = Command::new(env!("CARGO_BIN_EXE_serve-load"))
        .args([db.to_str().unwrap(), "--clients", "8", "--requests", "2000", "--hdov", hdov.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("errors 0;") && stdout.contains("answers checked against the library: yes"), "{stdout}");
}
