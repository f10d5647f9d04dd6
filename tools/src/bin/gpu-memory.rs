//! GPU memory of the wgpu DoV backend: the bytes its instanced layout uploads (base meshes and
//! their leaf LODs once in model space, 52 bytes per instance) against the world-space layout it
//! replaced (every instance's triangles, and every coarser level of them, as 16-byte vertices),
//! plus the cost per sample point of drawing instances, with indirect multi-draws and with
//! direct draws, at a few grid corners.
//!
//! `cargo run --release -p hdov-tools --bin gpu-memory -- [POINTS] [R] [SCENE.json | default]..`
//! (`default`: the generated default city, seed 1.)

use std::time::Instant;

use clap::Parser;
use hdov::city::{CityParams, CityScale};
use hdov::dov::gpu::{DEFAULT_LOD_TOLERANCE_TEXELS, GpuOptions};
use hdov::dov::{DovBackend, GpuBackend, IdCube};
use hdov::lod::{LodParams, leaf_chain};
use hdov::scene::Scene;

#[derive(Parser)]
#[command(
    name = "gpu-memory",
    about = "GPU memory of the wgpu DoV backend: bytes uploaded by its instanced layout against the world-space one, \
             and the cost per sample point of drawing instances",
    long_about = "GPU memory of the wgpu DoV backend: the bytes its instanced layout uploads (base meshes and their leaf\n\
                  LODs once in model space, 52 bytes per instance) against the world-space layout it replaced (every\n\
                  instance's triangles, and every coarser level of them, as 16-byte vertices), at full detail and with\n\
                  leaf LODs; then the time, draw commands and triangles per sample point at a few grid corners, with\n\
                  indirect multi-draws and with direct draws; and this process's peak RSS. Needs a wgpu adapter.\n\
                  \n\
                  Makes: docs/dov.md, \"GPU memory\" (the bytes table and the speed figures)\n\
                  (`gpu-memory 4 128 default /work/experiments/large/city.json`)."
)]
struct Args {
    /// Grid corners measured per scene for the speed figures.
    #[arg(default_value_t = 4)]
    points: usize,
    /// Cube-map resolution R (texels per face edge).
    #[arg(default_value_t = 128)]
    r: u32,
    /// Scenes: scene files (glTF, OBJ or a scene manifest .json), or `default` for the generated default city
    /// (seed 1).
    #[arg(value_name = "SCENE", default_value = "default")]
    scenes: Vec<String>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { points, r, scenes } = Args::parse();
    println!("{}", hdov_tools::machine());
    for name in scenes {
        let scene = if name == "default" {
            hdov::city::generate(&CityParams { seed: 1, scale: CityScale::Default, ..Default::default() })?
        } else {
            Scene::load(std::path::Path::new(&name))?.0
        };
        report(&name, &scene, points, r)?;
    }
    println!("peak RSS of this process: {:.2} GB", peak_rss_bytes() as f64 / 1e9);
    Ok(())
}

fn report(name: &str, scene: &Scene, points: usize, r: u32) -> Result<(), Box<dyn std::error::Error>> {
    let base: u64 = scene.meshes.iter().map(|m| m.mesh.triangle_count() as u64).sum();
    println!(
        "\n{name}: {} base meshes ({base} triangles), {} objects ({} triangles over instances)",
        scene.meshes.len(),
        scene.objects.len(),
        scene.triangle_count()
    );
    let t = Instant::now();
    let lods: Vec<_> = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    println!("leaf LODs: {:.1} s", t.elapsed().as_secs_f64());
    let full = GpuBackend::with_options(scene, r, &GpuOptions { lod_tolerance_texels: 0.0, ..Default::default() })?;
    let full_bytes = full.bytes_uploaded();
    drop(full);
    let lod_options = |direct_draws| GpuOptions {
        lods: Some(&lods),
        lod_tolerance_texels: DEFAULT_LOD_TOLERANCE_TEXELS,
        direct_draws,
        ..Default::default()
    };
    let t = Instant::now();
    let mut indirect = GpuBackend::with_options(scene, r, &lod_options(false))?;
    let setup = t.elapsed().as_secs_f64();
    let mb = |b: u64| format!("{:.1} MB", b as f64 / 1e6);
    println!("| layout | full detail | with leaf LODs |");
    println!("|---|---|---|");
    println!(
        "| world space, per instance (before) | {} | {} |",
        mb(baked_upload_bytes(scene, None)),
        mb(baked_upload_bytes(scene, Some(&lods)))
    );
    println!("| model space + instances (now) | {} | {} |", mb(full_bytes), mb(indirect.bytes_uploaded()));
    println!("instanced backend with LODs set up in {setup:.1} s on {}", indirect.adapter_name());

    let Some(grid) = &scene.grid else { return Ok(()) };
    // Corners spread over the grid: a deterministic stride through the corner ids.
    let stride = (grid.corner_count() / points.max(1)).max(1);
    let at: Vec<_> = (0..points)
        .map(|i| grid.corner_position(grid.corner_coords((i * stride + stride / 2) % grid.corner_count())))
        .collect();
    let mut direct = GpuBackend::with_options(scene, r, &lod_options(true))?;
    let mut ids = IdCube::new(r);
    for (label, backend) in [("indirect multi-draw", &mut indirect), ("direct draws", &mut direct)] {
        if label == "indirect multi-draw" && !backend.indirect_draws() {
            println!("{label}: not available on this device");
            continue;
        }
        backend.render_ids(at[0], &mut ids)?; // warm-up: pipeline compilation
        let (draws, triangles) = (backend.draw_commands(), backend.triangles_drawn());
        let (t, cpu) = (Instant::now(), hdov_tools::process_cpu_time().as_secs_f64());
        for &p in &at {
            backend.render_ids(p, &mut ids)?;
        }
        let n = at.len() as f64;
        println!(
            "{label}: {:.3} s per sample point at R = {r} ({:.3} s of CPU time, all threads), {:.0} draw commands and {:.0} triangles per point ({} points)",
            t.elapsed().as_secs_f64() / n,
            (hdov_tools::process_cpu_time().as_secs_f64() - cpu) / n,
            (backend.draw_commands() - draws) as f64 / n,
            (backend.triangles_drawn() - triangles) as f64 / n,
            at.len()
        );
    }
    println!(
        "seconds per cell = seconds per point × {:.2} shared corners per cell",
        grid.corner_count() as f64 / grid.cell_count() as f64
    );
    Ok(())
}

/// VmHWM of this process (0 where /proc is not there).
fn peak_rss_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|r| r.split_whitespace().next()?.parse::<u64>().ok())
        .map_or(0, |kib| kib * 1024)
}

/// What the world-space layout this backend replaced uploaded for `scene`: every object's
/// triangles (and, with `lods`, every coarser level of them) as three unshared 16-byte vertices
/// (position + id). For reporting the saving; nothing draws from it.
fn baked_upload_bytes(scene: &Scene, lods: Option<&[Vec<hdov::lod::LodLevel>]>) -> u64 {
    let triangles: u64 = scene
        .objects
        .iter()
        .map(|o| {
            let coarser = lods.map_or(0, |lods| lods[o.mesh as usize].iter().skip(1).map(|l| l.faces() as u64).sum());
            scene.meshes[o.mesh as usize].mesh.triangle_count() as u64 + coarser
        })
        .sum();
    triangles * 3 * std::mem::size_of::<hdov::gfx::Vertex>() as u64
}
