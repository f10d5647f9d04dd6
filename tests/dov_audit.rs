//! The rate of visible zero-DoV objects (seen from inside a cell, by no corner) on a street scene,
//! and how many the floor test catches at several margins. Slow (thousands of point
//! measurements), so ignored by default; its numbers are in docs/journal/dov-sampling.md, §0 (summary: docs/dov.md, "What the floors catch"):
//!
//! `cargo test --release --test dov_audit -- --ignored --nocapture`

use hdov::dov::CpuBackend;
use hdov::dov::precompute::FloorTest;
use hdov_testkit::audit::audit_zero_dov;
use hdov_testkit::scenes::*;

#[test]
#[ignore = "slow audit; run with --ignored --release"]
fn zero_dov_rate_on_a_street_scene() {
    let (scene, grid) = audit_block();
    let bounds = scene.all_object_bounds();
    let resolution = 64;
    let dense = 32;
    let mut backend = CpuBackend::new(&scene, resolution).unwrap();
    let tests =
        [FloorTest::BoxWithin(0.0), FloorTest::BoxWithin(2.5), FloorTest::BoxWithin(10.0), FloorTest::NeighbourCorners];
    let ks = [0, 4, 8, 16];
    let start = std::time::Instant::now();
    let audits = audit_zero_dov(&mut backend, &grid, &bounds, 0..grid.cell_count(), dense, &ks, &tests).unwrap();
    println!(
        "{} objects, {} cells, R={resolution}, {dense} dense points/cell, {:.1}s",
        bounds.len(),
        grid.cell_count(),
        start.elapsed().as_secs_f64()
    );
    println!("| K | floor test | pairs seen by corners + K | zero-DoV pairs (rate) | caught by floor | false floors |");
    for a in &audits {
        let rate = a.zero_dov as f64 / (a.sparse_visible + a.zero_dov) as f64;
        println!(
            "| {} | {:?} | {} | {} ({:.1} %) | {} | {} |",
            a.interior_samples,
            a.test,
            a.sparse_visible,
            a.zero_dov,
            100.0 * rate,
            a.caught,
            a.false_floors
        );
        assert!(a.caught <= a.zero_dov && a.cells == grid.cell_count());
    }
    // Wider margins catch at least as much; more interior samples leave fewer zero-DoV objects.
    for w in audits.windows(2) {
        match (w[0].test, w[1].test) {
            (FloorTest::BoxWithin(_), FloorTest::BoxWithin(_)) if w[0].interior_samples == w[1].interior_samples => {
                assert!(w[1].caught >= w[0].caught && w[1].false_floors >= w[0].false_floors);
            }
            _ if w[0].interior_samples < w[1].interior_samples => assert!(w[1].zero_dov <= w[0].zero_dov),
            _ => {}
        }
    }
}
