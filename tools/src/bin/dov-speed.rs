//! DoV measurement speed and backend agreement on the default city.
//!
//! For each resolution, measures the same street sample points with the CPU ray caster and the
//! wgpu backend, and prints one CSV row per (backend, R): seconds per sample point, sample points
//! per second, seconds per cell (a corners-only grid measures `corners / cells` points per cell),
//! and the per-object agreement of the two backends at those points.
//!
//! `cargo run --release -p hdov-tools --bin dov-speed -- [POINTS] [R,R,..] > docs/data/dov_speed.csv`

use std::time::Instant;

use clap::Parser;
use hdov::city::{CityParams, CityScale};
use hdov::dov::gpu::{DEFAULT_LOD_TOLERANCE_TEXELS, GpuOptions};
use hdov::dov::{CpuBackend, DovBackend, GpuBackend, PointDov};
use hdov::lod::{LodParams, leaf_chain};

#[derive(Parser)]
#[command(
    name = "dov-speed",
    about = "DoV measurement speed and backend agreement on the default city: CPU ray caster against the wgpu \
             backend, per resolution",
    long_about = "DoV measurement speed and backend agreement on the default city (seed 1). For each resolution,\n\
                  measures the same street sample points (grid corners) with the CPU ray caster and the wgpu backend\n\
                  (full detail, and with LOD-aware drawing at the default tolerance), and prints one CSV row per\n\
                  (backend, R): set-up seconds, seconds per sample point, sample points per second, seconds per cell,\n\
                  and the per-object |dDoV| of each GPU backend against the CPU's at those points. A GPU backend that\n\
                  finds no adapter is left out.\n\
                  \n\
                  Makes: docs/data/dov_speed.csv and the table of docs/results.md, \"DoV measurement speed and\n\
                  backend agreement\" (`dov-speed 16 128,256,512 > docs/data/dov_speed.csv`); the before/after speed\n\
                  table of docs/journal/gpu-backend.md, \"GPU memory\" (`dov-speed 8 128`)."
)]
struct Args {
    /// Street sample points measured per resolution (grid corners at a fixed stride).
    #[arg(default_value_t = 24, value_parser = clap::value_parser!(u64).range(1..))]
    points: u64,
    /// Cube-map resolutions R, comma-separated.
    #[arg(value_name = "R,R,..", value_delimiter = ',', default_value = "128,256,512")]
    resolutions: Vec<u32>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { points, resolutions } = Args::parse();
    let points = points as usize;
    let scene = hdov::city::generate(&CityParams { seed: 1, scale: CityScale::Default, ..Default::default() })?;
    let grid = scene.grid.clone().expect("the city brings a grid");
    let points_per_cell = grid.corner_count() as f64 / grid.cell_count() as f64;
    let lods: Vec<_> = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    let lod_options =
        GpuOptions { lods: Some(&lods), lod_tolerance_texels: DEFAULT_LOD_TOLERANCE_TEXELS, ..Default::default() };
    // Corners spread over the grid: a deterministic stride through the corner ids.
    let stride = (grid.corner_count() / points).max(1);
    let at: Vec<_> =
        (0..points).map(|i| grid.corner_position(grid.corner_coords((i * stride + 7) % grid.corner_count()))).collect();
    println!(
        "backend,adapter,resolution,points,setup_s,s_per_point,points_per_s,s_per_cell,max_abs_diff,mean_abs_diff,objects_compared"
    );
    for &r in &resolutions {
        let t = Instant::now();
        let mut cpu = CpuBackend::new(&scene, r)?;
        let cpu_setup = t.elapsed().as_secs_f64();
        let (cpu_s, cpu_dov) = measure_all(&mut cpu, &at)?;
        let mut rows = vec![("cpu", cpu.name(), cpu_setup, cpu_s, None)];
        for (label, options) in [("gpu", GpuOptions::default()), ("gpu-lod", lod_options)] {
            let options = if label == "gpu" { GpuOptions { lod_tolerance_texels: 0.0, ..options } } else { options };
            let t = Instant::now();
            if let Ok(mut gpu) = GpuBackend::with_options(&scene, r, &options) {
                // Setup includes the upload and a first, untimed measurement (pipeline warm-up).
                gpu.measure(at[0])?;
                let setup = t.elapsed().as_secs_f64();
                let (gpu_s, gpu_dov) = measure_all(&mut gpu, &at)?;
                rows.push((label, gpu.name(), setup, gpu_s, Some(agreement(&cpu_dov, &gpu_dov))));
            }
        }
        for (backend, adapter, setup, secs, agree) in rows {
            let per_point = secs / at.len() as f64;
            let (max, mean, n) = agree.unwrap_or((0.0, 0.0, 0));
            println!(
                "{backend},\"{adapter}\",{r},{},{setup:.3},{per_point:.5},{:.2},{:.5},{max:.3e},{mean:.3e},{n}",
                at.len(),
                1.0 / per_point,
                per_point * points_per_cell
            );
        }
    }
    Ok(())
}

fn measure_all(b: &mut dyn DovBackend, at: &[glam::Vec3]) -> hdov::Result<(f64, Vec<PointDov>)> {
    let t = Instant::now();
    let out = at.iter().map(|&p| b.measure(p)).collect::<hdov::Result<Vec<_>>>()?;
    Ok((t.elapsed().as_secs_f64(), out))
}
/// Max and mean |ΔDoV| over every object either backend sees, and how many that is.
fn agreement(a: &[PointDov], b: &[PointDov]) -> (f64, f64, usize) {
    let mut d = hdov_testkit::audit::DovDiff::default();
    for (x, y) in a.iter().zip(b) {
        d.add_points(x, y, 0.0);
    }
    (d.max_abs, d.mean_abs(), d.objects)
}
