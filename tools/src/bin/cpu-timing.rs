//! CPU backend timing on a scene file: BVH build time, then the time per sample point at R = 128
//! over an 8 × 8 lattice of points at eye height (wall clock, and the process's CPU time from
//! /proc, which a loaded machine disturbs less), and a checksum of the id cubes so that two
//! versions of the backend can be compared for identical results.
//!
//! `cargo run --release -p hdov-tools --bin cpu-timing -- SCENE.json [IDS_DUMP_FILE]`

use std::path::PathBuf;

use clap::Parser;
use glam::Vec3;
use hdov::dov::{CpuBackend, DovBackend, IdCube};
use hdov::scene::Scene;

#[derive(Parser)]
#[command(
    name = "cpu-timing",
    about = "CPU backend timing on a scene: BVH build time, time per sample point at R = 128, and a checksum of the id \
             cubes",
    long_about = "CPU backend timing on a scene file: the BVH build time, then the time per sample point at R = 128 over\n\
                  an 8 × 8 lattice of points at eye height (wall clock, and the process's CPU time, which a loaded\n\
                  machine disturbs less), and a checksum of the id cubes, so that two versions of the backend can be\n\
                  compared for identical results.\n\
                  \n\
                  Makes: docs/dov.md, \"Speed\" (the large city's table: BVH build and CPU time per sample point) and\n\
                  the default city's before/after figures with identical id checksums in docs/journal/packet-tracer.md, \"Per-ray speed\n\
                  against Embree\", and docs/results.md (`cpu-timing /tmp/large2/city.json`)."
)]
struct Args {
    /// The scene: a glTF file, an OBJ file or a scene manifest .json (e.g. `hdov generate city`'s city.json).
    #[arg(value_name = "SCENE")]
    scene: PathBuf,
    /// Also write every id cube (u32 little-endian, point after point) to this file, to compare two versions
    /// texel by texel.
    #[arg(value_name = "IDS_DUMP_FILE")]
    dump_to: Option<PathBuf>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { scene: path, dump_to } = Args::parse();
    let (scene, _) = Scene::load(&path)?;
    let t0 = std::time::Instant::now();
    let mut backend = CpuBackend::new(&scene, 128)?;
    let build = t0.elapsed();
    let b = scene.bounds();
    let mut ids = IdCube::new(128);
    let mut points = 0;
    let c1 = hdov_tools::process_cpu_time().as_secs_f64();
    let t1 = std::time::Instant::now();
    let mut checksum = 0u64;
    let mut dump = Vec::new();
    for i in 0..8 {
        for j in 0..8 {
            let f = |k: usize, lo: f32, hi: f32| lo + (hi - lo) * (k as f32 + 0.5) / 8.0;
            let p = Vec3::new(f(i, b.min.x, b.max.x), 1.7, f(j, b.min.z, b.max.z));
            backend.render_ids(p, &mut ids)?;
            checksum = ids.ids.iter().fold(checksum, |h, &id| h.wrapping_mul(31).wrapping_add(id as u64));
            if dump_to.is_some() {
                dump.extend(ids.ids.iter().flat_map(|id| id.to_le_bytes()));
            }
            points += 1;
        }
    }
    let per_point = t1.elapsed() / points;
    let cpu_per_point = (hdov_tools::process_cpu_time().as_secs_f64() - c1) / points as f64;
    if let Some(out) = dump_to {
        std::fs::write(out, dump)?;
    }
    println!(
        "{}: build {build:?}, {per_point:?} per sample point (R = 128), CPU {:.1} ms per point, ids checksum {checksum:x}",
        backend.name(),
        cpu_per_point * 1e3
    );
    Ok(())
}
