//! LOD-aware drawing of the GPU backend against full detail on a generated city.

use hdov::city::{CityParams, CityScale, generate};
use hdov::dov::gpu::GpuOptions;
use hdov::dov::{DovBackend, GpuBackend};
use hdov::lod::{LodLevel, LodParams, leaf_chain};
use hdov::scene::Scene;
use hdov_testkit::gpu::adapter_or_skip;

fn city(scale: CityScale) -> (Scene, Vec<Vec<LodLevel>>) {
    let scene = generate(&CityParams { scale, ..Default::default() }).unwrap();
    let lods = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    (scene, lods)
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
    let points = hdov::dov::open_corners(&scene.grid.clone().unwrap(), &mut full, 4).unwrap();
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
    let grid = scene.grid.clone().unwrap();
    let p = grid.corner_position(grid.corner_coords(grid.corner_count() / 2));
    assert_eq!(full.measure(p).unwrap(), lod.measure(p).unwrap());
    assert_eq!(full.triangles_drawn(), lod.triangles_drawn());
}

#[test]
fn bad_lod_options_are_refused() {
    let (scene, lods) = city(CityScale::Tiny);
    let short = GpuOptions { lods: Some(&lods[1..]), ..Default::default() };
    assert!(matches!(GpuBackend::with_options(&scene, 8, &short), Err(hdov::Error::BadParam { .. })));
    let negative = GpuOptions { lods: Some(&lods), lod_tolerance_texels: -1.0, ..Default::default() };
    assert!(matches!(GpuBackend::with_options(&scene, 8, &negative), Err(hdov::Error::BadParam { .. })));
}
