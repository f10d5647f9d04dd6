//! The `view-error` tool at a small size with a fixed seed (issue 22's CI run): it builds the
//! street with two samplers, measures every viewpoint, and writes its table, CSV and chart. It
//! reports; it asserts no miss count, only that what it reports is well formed.

use std::process::Command;

#[test]
fn view_error_reports_the_street_at_a_small_size() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, svg) = (dir.path().join("street.csv"), dir.path().join("street.svg"));
    let out = Command::new(env!("CARGO_BIN_EXE_view-error"))
        .args(["street", "--samplers", "corners,probe", "--viewpoints", "2", "--resolution", "32", "--truth", "64"])
        .args(["--seed", "3", "--out", csv.to_str().unwrap(), "--chart", svg.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    println!("{stdout}");
    assert!(stdout.contains("street: 191 objects, 18 of 18 cells, 36 viewpoints"), "{stdout}");
    assert!(stdout.contains("| corners |") && stdout.contains("| probe |"), "{stdout}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), 2 * 36, "a row per sampler and viewpoint");
    for row in rows {
        let share: f64 = row.split(',').nth(7).unwrap().parse().unwrap();
        assert!((0.0..=1.0).contains(&share), "{row}");
    }
    assert!(std::fs::read_to_string(&svg).unwrap().contains("Wrong share"));
}
