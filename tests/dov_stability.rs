//! Sub-texel features: a pole a fraction of a texel wide flips between 0 and a full column of
//! texels as the viewpoint moves by less than a texel. Measures the mean and the spread of its
//! DoV under sub-texel jitter of the viewpoint, for widths from 0.25 to 8 texels (numbers in
//! docs/dov.md: `cargo test --test dov_stability -- --nocapture`).

use glam::Vec3;
use hdov::dov::{CpuBackend, CubeMap, DovBackend};
use hdov_testkit::scenes::*;

/// `(width in texels, mean DoV / analytic, coefficient of variation)` for each width.
fn pole_jitter(widths: &[f32]) -> Vec<(f32, f64, f64)> {
    let r = 64;
    let distance = 20.0;
    let texel = 2.0 * distance / r as f32; // world width of a texel at the +Z face's centre
    let height = 10.0 * texel;
    let jitters = 32;
    let cube = CubeMap::new(r);
    widths
        .iter()
        .map(|&w| {
            let half = 0.5 * w * texel;
            let mut b = SceneBuilder::default();
            // A thin upright pole straight ahead on +Z (face 4), its front face at `distance`.
            b.aabox(Vec3::new(-half, -height / 2.0, distance), Vec3::new(half, height / 2.0, distance + 0.1));
            let scene = b.build();
            let mut backend = CpuBackend::new(&scene, r).unwrap();
            // Solid angle of the front rectangle (small-angle approximation is within 0.1 % here).
            let analytic = (w * texel * height) as f64 / (distance as f64).powi(2) / cube.total_weight();
            // Stratified sideways offsets across one texel: the pole's image slides over one
            // texel column.
            let dovs: Vec<f64> = (0..jitters)
                .map(|i| {
                    let dx = ((i as f32 + 0.5) / jitters as f32 - 0.5) * texel;
                    backend.measure(Vec3::new(dx, 0.0, 0.0)).unwrap().get(0)
                })
                .collect();
            let mean = dovs.iter().sum::<f64>() / jitters as f64;
            let var = dovs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / jitters as f64;
            (w, mean / analytic, var.sqrt() / mean)
        })
        .collect()
}

#[test]
fn sub_texel_poles_are_unbiased_on_average_and_flicker_when_thin() {
    let rows = pole_jitter(&[0.25, 0.5, 1.0, 1.5, 2.5, 4.0, 8.0]);
    println!("| width (texels) | mean DoV / analytic | coefficient of variation |");
    for (w, mean, cv) in &rows {
        println!("| {w} | {mean:.3} | {cv:.3} |");
    }
    for &(w, mean, _) in &rows {
        // Averaged over the jitter, coverage is unbiased at every width (texel-centre sampling
        // is a point sampler); edge and height quantisation leave a few percent.
        assert!((mean - 1.0).abs() < 0.1, "width {w}: mean DoV off by {:.1} %", 100.0 * (mean - 1.0));
    }
    // A pole n + f texels wide covers n or n + 1 texel columns (with probabilities 1 − f and f),
    // so its DoV's coefficient of variation is √(f(1 − f)) / (n + f): √3 for a quarter texel,
    // 0 for whole texels.
    for &(w, _, cv) in &rows {
        let f = (w - w.floor()) as f64;
        let want = (f * (1.0 - f)).sqrt() / w as f64;
        assert!((cv - want).abs() < 0.02, "width {w}: CV {cv:.3}, expected {want:.3}");
    }
}
