//! LOD-aware drawing of the GPU backend against full detail on a generated city.

use std::time::Instant;

use glam::Vec3;
use hdov::city::{CityParams, CityScale, generate};
use hdov::dov::gpu::{GpuOptions, adapter_or_skip};
use hdov::dov::{DovBackend, GpuBackend, PointDov};
use hdov::lod::{LodLevel, LodParams, leaf_chain};
use hdov::scene::Scene;

fn city(scale: CityScale) -> (Scene, Vec<Vec<LodLevel>>) {
    let scene = generate(&CityParams { scale, ..Default::default() });
    let lods = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    (scene, lods)
}

/// Up to `n` grid corners in open street space (nothing seen from behind), spread over the grid.
fn street_points(scene: &Scene, full: &mut GpuBackend, n: usize) -> Vec<Vec3> {
    let grid = scene.grid.expect("a generated city has a grid");
    let corners = grid.corner_count();
    let step = (corners / (12 * n)).max(1);
    let mut points = Vec::new();
    for id in (0..corners).step_by(step) {
        let p = grid.corner_position(grid.corner_coords(id));
        if full.measure(p).unwrap().back_face == 0.0 {
            points.push(p);
        }
    }
    let keep = (points.len() / n).max(1);
    points.into_iter().step_by(keep).take(n).collect()
}

/// Per object differences between two measurements from one point.
#[derive(Default)]
struct Diff {
    objects: usize,
    max_abs: f64,
    sum_abs: f64,
    max_rel: f64,
    sum_rel: f64,
    flips: usize,
    /// Objects whose change exceeds 0.5 % of their DoV plus two centre texels.
    over_tolerance: usize,
}

fn compare(a: &PointDov, b: &PointDov, texel_floor: f64, d: &mut Diff) {
    let ids: std::collections::BTreeSet<u32> = a.objects.iter().chain(&b.objects).map(|e| e.0).collect();
    for id in ids {
        let (x, y) = (a.get(id), b.get(id));
        let delta = (x - y).abs();
        let rel = delta / x.max(y);
        d.objects += 1;
        d.max_abs = d.max_abs.max(delta);
        d.sum_abs += delta;
        d.max_rel = d.max_rel.max(rel);
        d.sum_rel += rel;
        d.flips += usize::from((x == 0.0) != (y == 0.0));
        d.over_tolerance += usize::from(delta > 0.005 * x.max(y) + 2.0 * texel_floor);
    }
}

#[test]
fn lod_drawing_matches_full_detail_and_draws_less() {
    if !adapter_or_skip() {
        return;
    }
    let (scene, lods) = city(CityScale::Small);
    let r = 64;
    let mut full = GpuBackend::new(&scene, r).unwrap();
    let options = GpuOptions { lods: Some(&lods), ..Default::default() };
    let mut lod = GpuBackend::with_options(&scene, r, &options).unwrap();
    assert!(lod.lod_drawing() && !full.lod_drawing());
    let points = street_points(&scene, &mut full, 4);
    assert!(points.len() >= 3, "the city should have open street corners");
    let floor = full.cube_map().texel_floor();
    let before = full.triangles_drawn();
    for &p in &points {
        let (a, b) = (full.measure(p).unwrap(), lod.measure(p).unwrap());
        let ids: std::collections::BTreeSet<u32> = a.objects.iter().chain(&b.objects).map(|e| e.0).collect();
        assert!(ids.len() > 10, "p={p}: a street corner should see many objects");
        for id in ids {
            let (x, y) = (a.get(id), b.get(id));
            let tol = 0.005 * x.max(y) + 2.0 * floor;
            assert!((x - y).abs() <= tol, "p={p} object {id}: full {x} LOD {y}");
        }
    }
    let (full_tris, lod_tris) = (full.triangles_drawn() - before, lod.triangles_drawn());
    println!("{} points: full detail drew {full_tris} triangles, LOD drawing {lod_tris}", points.len());
    assert!(lod_tris < full_tris, "LOD drawing should draw fewer triangles: {lod_tris} vs {full_tris}");
}

#[test]
fn zero_tolerance_is_full_detail() {
    if !adapter_or_skip() {
        return;
    }
    let (scene, lods) = city(CityScale::Tiny);
    let r = 32;
    let mut full = GpuBackend::new(&scene, r).unwrap();
    let options = GpuOptions { lods: Some(&lods), lod_tolerance_texels: 0.0, ..Default::default() };
    let mut lod = GpuBackend::with_options(&scene, r, &options).unwrap();
    assert!(!lod.lod_drawing());
    let grid = scene.grid.unwrap();
    let p = grid.corner_position(grid.corner_coords(grid.corner_count() / 2));
    assert_eq!(full.measure(p).unwrap(), lod.measure(p).unwrap());
    assert_eq!(full.triangles_drawn(), lod.triangles_drawn());
}

#[test]
fn bad_lod_options_are_refused() {
    let (scene, lods) = city(CityScale::Tiny);
    let short = GpuOptions { lods: Some(&lods[1..]), ..Default::default() };
    assert!(matches!(GpuBackend::with_options(&scene, 8, &short), Err(hdov::Error::BadArgument { .. })));
    let negative = GpuOptions { lods: Some(&lods), lod_tolerance_texels: -1.0, ..Default::default() };
    assert!(matches!(GpuBackend::with_options(&scene, 8, &negative), Err(hdov::Error::BadArgument { .. })));
}

/// The measurement behind docs/dov.md ("LOD-aware drawing"): per object |ΔDoV|, flips and
/// speed-up over street points. `HDOV_LOD_SCALE=default` for the default city,
/// `HDOV_LOD_TOLERANCES=0.5,0.25` for the tolerances. Run with `--ignored --nocapture`.
#[test]
#[ignore]
fn measure_lod_drawing() {
    if !adapter_or_skip() {
        return;
    }
    let scale = match std::env::var("HDOV_LOD_SCALE").as_deref() {
        Ok("default") => CityScale::Default,
        Ok("tiny") => CityScale::Tiny,
        _ => CityScale::Small,
    };
    let tolerances: Vec<f32> = std::env::var("HDOV_LOD_TOLERANCES")
        .unwrap_or_else(|_| "0.5".into())
        .split(',')
        .map(|t| t.parse().unwrap())
        .collect();
    let (scene, lods) = city(scale);
    println!(
        "city {}: {} objects, {} triangles; LOD chains add {} stored triangles",
        scale.name(),
        scene.objects.len(),
        scene.triangle_count(),
        lods.iter().flat_map(|c| c.iter().skip(1)).map(|l| l.faces()).sum::<usize>()
    );
    for r in [128, 256] {
        let mut full = GpuBackend::new(&scene, r).unwrap();
        println!("R={r} adapter {}", full.adapter_name());
        let points = street_points(&scene, &mut full, 20);
        let floor = full.cube_map().texel_floor();
        let start = full.triangles_drawn();
        let t = Instant::now();
        let reference: Vec<PointDov> = points.iter().map(|&p| full.measure(p).unwrap()).collect();
        let full_s = t.elapsed().as_secs_f64() / points.len() as f64;
        let full_tris = (full.triangles_drawn() - start) as f64 / points.len() as f64;
        println!(
            "  {} points; full detail: {:.1} ms/point, {:.0} triangles/point",
            points.len(),
            full_s * 1e3,
            full_tris
        );
        for &tol in &tolerances {
            let options = GpuOptions { lods: Some(&lods), lod_tolerance_texels: tol, ..Default::default() };
            let mut lod = GpuBackend::with_options(&scene, r, &options).unwrap();
            lod.measure(points[0]).unwrap(); // warm-up, as the full backend had
            let start = lod.triangles_drawn();
            let t = Instant::now();
            let measured: Vec<PointDov> = points.iter().map(|&p| lod.measure(p).unwrap()).collect();
            let lod_s = t.elapsed().as_secs_f64() / points.len() as f64;
            let lod_tris = (lod.triangles_drawn() - start) as f64 / points.len() as f64;
            let mut d = Diff::default();
            for (a, b) in reference.iter().zip(&measured) {
                compare(a, b, floor, &mut d);
            }
            println!(
                "  tolerance {tol}: {:.1} ms/point ({:.2}x), {:.0} triangles/point ({:.1}%); {} object-points: \
                 |dDoV| max {:.3e} mean {:.3e} ({:.2} / {:.3} centre texels), relative max {:.4} mean {:.5}; \
                 flips {}; over tolerance {}",
                lod_s * 1e3,
                full_s / lod_s,
                lod_tris,
                100.0 * lod_tris / full_tris,
                d.objects,
                d.max_abs,
                d.sum_abs / d.objects as f64,
                d.max_abs / floor,
                d.sum_abs / d.objects as f64 / floor,
                d.max_rel,
                d.sum_rel / d.objects as f64,
                d.flips,
                d.over_tolerance
            );
        }
    }
}
