//! The measurement behind docs/dov.md ("LOD-aware drawing"): the GPU backend with LOD-aware
//! drawing against full detail at 20 street points of a generated city: per-object |ΔDoV|,
//! objects seen by one side only, objects beyond the agreement tolerance, speed-up and
//! triangles drawn, at R = 128 and 256.
//!
//! `cargo run --release -p hdov-tools --bin lod-draw-accuracy -- [small|default|tiny] [T,T,..]`

use std::time::Instant;

use clap::Parser;
use hdov::city::{CityParams, CityScale, generate};
use hdov::dov::gpu::GpuOptions;
use hdov::dov::{DovBackend, GpuBackend, PointDov, open_corners};
use hdov::lod::{LodParams, leaf_chain};
use hdov_testkit::audit::DovDiff;

#[derive(Parser)]
#[command(
    name = "lod-draw-accuracy",
    about = "The GPU backend with LOD-aware drawing against full detail: |dDoV|, flips, speed-up and triangles drawn, \
             per tolerance",
    long_about = "The GPU backend with LOD-aware drawing against full detail at 20 street points of a generated city\n\
                  (seed 1), at R = 128 and 256, per LOD tolerance T (texels): per-object |dDoV| (max, mean, relative),\n\
                  objects seen by one side only, objects beyond the agreement tolerance, the speed-up, and triangles\n\
                  drawn per point. Needs a wgpu adapter (Mesa's lavapipe will do).\n\
                  \n\
                  Makes: docs/journal/gpu-backend.md, \"LOD-aware drawing: the tolerance sweep\" (docs/dov.md keeps T = 0.05)\n\
                  (`lod-draw-accuracy small 0.5,0.25,0.15,0.1,0.05`)."
)]
struct Args {
    /// The generated city: tiny, small, default, large or huge.
    #[arg(value_name = "SCALE", default_value = "small", value_parser = hdov_tools::args::city_scale)]
    scale: CityScale,
    /// LOD tolerances T in texels, comma-separated.
    #[arg(value_name = "T,T,..", value_delimiter = ',', default_value = "0.5,0.25,0.15,0.1,0.05")]
    tolerances: Vec<f32>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { scale, tolerances } = Args::parse();
    let scene = generate(&CityParams { scale, ..Default::default() })?;
    let lods: Vec<_> = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    println!(
        "city {scale}: {} objects, {} triangles; LOD chains add {} stored triangles",
        scene.objects.len(),
        scene.triangle_count(),
        lods.iter().flat_map(|c| c.iter().skip(1)).map(|l| l.faces()).sum::<usize>()
    );
    for r in [128, 256] {
        let mut full = GpuBackend::new(&scene, r)?;
        println!("R={r} adapter {}", full.adapter_name());
        let points = open_corners(&scene.grid.clone().expect("a city has a grid"), &mut full, 20)?;
        let floor = full.cube_map().texel_floor();
        let start = full.triangles_drawn();
        let t = Instant::now();
        let reference: Vec<PointDov> = points.iter().map(|&p| full.measure(p)).collect::<hdov::Result<_>>()?;
        let full_s = t.elapsed().as_secs_f64() / points.len() as f64;
        let full_tris = (full.triangles_drawn() - start) as f64 / points.len() as f64;
        println!(
            "  {} points; full detail: {:.1} ms/point, {full_tris:.0} triangles/point",
            points.len(),
            full_s * 1e3
        );
        for &tol in &tolerances {
            let options = GpuOptions { lods: Some(&lods), lod_tolerance_texels: tol, ..Default::default() };
            let mut lod = GpuBackend::with_options(&scene, r, &options)?;
            lod.measure(points[0])?; // warm-up, as the full backend had
            let start = lod.triangles_drawn();
            let t = Instant::now();
            let measured: Vec<PointDov> = points.iter().map(|&p| lod.measure(p)).collect::<hdov::Result<_>>()?;
            let lod_s = t.elapsed().as_secs_f64() / points.len() as f64;
            let lod_tris = (lod.triangles_drawn() - start) as f64 / points.len() as f64;
            let mut d = DovDiff::default();
            for (a, b) in reference.iter().zip(&measured) {
                d.add_points(a, b, floor);
            }
            println!(
                "  tolerance {tol}: {:.1} ms/point ({:.2}x), {lod_tris:.0} triangles/point ({:.1}%); {} object-points: \
                 |dDoV| max {:.3e} mean {:.3e} ({:.2} / {:.3} centre texels), relative max {:.4} mean {:.5}; \
                 flips {}; over tolerance {}",
                lod_s * 1e3,
                full_s / lod_s,
                100.0 * lod_tris / full_tris,
                d.objects,
                d.max_abs,
                d.mean_abs(),
                d.max_abs / floor,
                d.mean_abs() / floor,
                d.max_rel,
                d.mean_rel(),
                d.flips,
                d.over_tolerance
            );
        }
    }
    Ok(())
}
