//! Per-ray speed of the CPU backend on one thread, and the files Embree needs to cast the very same
//! rays (tools/embree/embree_ray_speed.py; tools/embree/ray_speed.sh runs both).
//!
//! Sample points: the corners of an X × Y × Z cell grid over the region a build would use
//! (`ViewGrid::resolve`, default 8 × 1 × 8 = 162 corners). At each point, on this one thread:
//! `render_ids_reference` (one `trace` per texel: the straightforward tracer), and `render_ids` (the
//! fast path, in a 1-thread rayon pool) twice: one ray at a time (`set_packets(false)`, the
//! previous fast path) and by packets of rays (the default, `cpu::PACKET_TEXELS`); each id cube
//! must equal the reference's. Each tracer is timed in its own pass over all the points (packets first), as
//! Embree's harness times its modes. Times are the process's CPU time (one thread busy at a
//! time), steadier than the wall clock on a shared machine.
//!
//! Writes into OUT_DIR: `triangles.f32` (world triangles, 9 f32 each, the order of
//! `world_triangles`), `objects.u32` (each triangle's object), `points.f32` (3 f32 per point),
//! `directions.f32` (the 6·R² texel-centre directions, face by face, row by row), `ids.u32` (the
//! fast path's id cube per point) and `hdov.json` (resolution, near, timings).
//!
//! `cargo run --release -p hdov-tools --bin ray-speed -- SCENE OUT_DIR [R] [X,Y,Z]`; with
//! `RAY_SPEED_PACKETS_ONLY=1` only the packets' pass runs (quick comparisons while tuning).

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use glam::Vec3;
use hdov::dov::{CpuBackend, DovBackend, IdCube, cubemap};
use hdov::grid::ViewGrid;
use hdov::scene::Scene;
use hdov_tools::process_cpu_time;

#[derive(Parser)]
#[command(
    name = "ray-speed",
    about = "Per-ray speed of the CPU backend on one thread (reference tracer, one ray at a time, packets), and the \
             files Embree needs to cast the same rays",
    long_about = "Per-ray speed of the CPU backend on one thread, and the files Embree needs to cast the very same rays\n\
                  (tools/embree/embree_c_speed.c, embree_ray_speed.py; tools/embree/ray_speed.sh runs them all).\n\
                  Sample points: the corners of an X × Y × Z cell grid over the region a build would use. At each\n\
                  point: the reference tracer (one `trace` per texel), and `render_ids` one ray at a time and by\n\
                  packets, each timed in its own pass in the process's CPU time; every id cube must equal the\n\
                  reference's (up to ties at equal depth), else the run fails. Writes into OUT_DIR: triangles.f32,\n\
                  objects.u32, points.f32, directions.f32, ids.u32 and hdov.json (resolution, near, timings). With\n\
                  RAY_SPEED_PACKETS_ONLY=1 in the environment only the packets' pass runs (quick comparisons while\n\
                  tuning).\n\
                  \n\
                  Makes: docs/dov.md, \"Per-ray speed against Embree\" (hdov's columns of its tables; the packets ÷\n\
                  one ray table is in docs/journal/packet-tracer.md, §4: `ray-speed /tmp/engine.obj OUT 256 4,1,4`), and docs/results.md,\n\
                  \"Per-ray speed against Embree\" (`tools/embree/ray_speed.sh SCENE OUT_DIR 256`)."
)]
struct Args {
    /// The scene: a glTF file, an OBJ file or a scene manifest .json.
    #[arg(value_name = "SCENE")]
    scene: PathBuf,
    /// Where the rays' files and hdov.json are written (created if missing).
    #[arg(value_name = "OUT_DIR")]
    out_dir: PathBuf,
    /// Cube-map resolution R (texels per face edge): 6·R² rays per point.
    #[arg(value_name = "RESOLUTION", default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..))]
    r: u32,
    /// Cells of the sample-point grid along x, y and z (its corners are the points).
    #[arg(value_name = "X,Y,Z", default_value = "8,1,8", value_parser = hdov_tools::args::triple)]
    dims: [u32; 3],
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { scene: scene_path, out_dir, r, dims } = Args::parse();
    println!("{}", hdov_tools::machine());

    let (scene, _) = Scene::load(&scene_path)?;
    let grid = ViewGrid::resolve(scene.bounds(), scene.grid.clone(), None, Some(dims), None)?;
    let points: Vec<Vec3> = (0..grid.corner_count()).map(|i| grid.corner_position(grid.corner_coords(i))).collect();
    let t0 = Instant::now();
    let mut backend = CpuBackend::new(&scene, r)?;
    println!("{}: BVH build {:.2?}, {} sample points at R = {r}", backend.name(), t0.elapsed(), points.len());

    std::fs::create_dir_all(&out_dir)?;
    let (triangles, objects) = hdov::dov::cpu::world_triangles(&scene)?;
    write_f32(&out_dir.join("triangles.f32"), triangles.iter().flatten().flat_map(|v| v.to_array()))?;
    std::fs::write(out_dir.join("objects.u32"), objects.iter().flat_map(|o| o.to_le_bytes()).collect::<Vec<_>>())?;
    write_f32(&out_dir.join("points.f32"), points.iter().flat_map(|p| p.to_array()))?;
    let cube = backend.cube_map().clone();
    let directions = (0..cubemap::FACE_COUNT)
        .flat_map(|f| (0..r).flat_map(move |row| (0..r).map(move |col| (f, row, col))))
        .flat_map(|(f, row, col)| cube.texel_direction(f, row, col).to_array());
    write_f32(&out_dir.join("directions.f32"), directions)?;

    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut ids_file = std::io::BufWriter::new(std::fs::File::create(out_dir.join("ids.u32"))?);
    let (mut reference, mut per_ray, mut fast) = (IdCube::new(r), IdCube::new(r), IdCube::new(r));
    // Each tracer is timed in a pass of its own over all the points, as the Embree harness times
    // each of its modes (interleaved, each found the caches full of the others' data).
    let mut timed = |packets: bool, ids: &mut IdCube| -> Result<(Duration, Duration), Box<dyn std::error::Error>> {
        backend.set_packets(packets);
        // CPU time of this process (the one busy thread), and wall time beside it.
        let (mut cpu, mut wall) = (Duration::ZERO, Duration::ZERO);
        for &p in &points {
            let (t, c) = (Instant::now(), process_cpu_time());
            pool.install(|| backend.render_ids(p, ids))?;
            (wall, cpu) = (wall + t.elapsed(), cpu + (process_cpu_time() - c));
            if packets {
                ids_file.write_all(&ids.ids.iter().flat_map(|id| id.to_le_bytes()).collect::<Vec<_>>())?;
            }
        }
        Ok((cpu, wall))
    };
    let (t_fast, wall_fast) = timed(true, &mut fast)?;
    if std::env::var_os("RAY_SPEED_PACKETS_ONLY").is_some() {
        ids_file.flush()?;
        let ms = t_fast.as_secs_f64() * 1e3 / points.len() as f64;
        println!("{}: {ms:.2} ms CPU per point (RAY_SPEED_PACKETS_ONLY: nothing else run)", packets_label());
        return Ok(());
    }
    let (t_per_ray, wall_per_ray) = timed(false, &mut per_ray)?;
    ids_file.flush()?;
    let (mut t_reference, mut wall_reference) = (Duration::ZERO, Duration::ZERO);
    let (mut differing, mut ties) = (0usize, 0usize);
    for &p in &points {
        let (t, c) = (Instant::now(), process_cpu_time());
        backend.render_ids_reference(p, &mut reference)?;
        (wall_reference, t_reference) = (wall_reference + t.elapsed(), t_reference + (process_cpu_time() - c));
        // Both fast routes again, untimed, to compare texel by texel.
        for (packets, ids) in [(false, &mut per_ray), (true, &mut fast)] {
            backend.set_packets(packets);
            pool.install(|| backend.render_ids(p, ids))?;
        }
        // A difference is allowed only on a tie up to rounding: both ids among the surfaces at
        // the nearest depth (`CpuBackend::surfaces_at_nearest`).
        for cube_ids in [&per_ray, &fast] {
            for (i, (a, b)) in reference.ids.iter().zip(&cube_ids.ids).enumerate().filter(|(_, (a, b))| a != b) {
                let (f, row, col) = (i / (r * r) as usize, (i / r as usize) % r as usize, i % r as usize);
                let tied = backend.surfaces_at_nearest(p, cube.texel_direction(f, row as u32, col as u32));
                if tied.len() >= 2 && tied.contains(a) && tied.contains(b) {
                    ties += 1;
                } else {
                    differing += 1;
                }
            }
        }
    }

    let n = points.len() as f64;
    let rays = 6.0 * f64::from(r) * f64::from(r);
    let ms = |d: Duration| d.as_secs_f64() * 1e3 / n;
    let (ms_reference, ms_per_ray, ms_fast) = (ms(t_reference), ms(t_per_ray), ms(t_fast));
    let speed = |label: &str, cpu_ms: f64, wall: Duration| {
        let wall_ms = ms(wall);
        println!(
            "{label}: {cpu_ms:.2} ms CPU per point, {:.2} M rays/s per thread (wall {wall_ms:.2} ms)",
            rays / cpu_ms / 1e3
        );
    };
    speed("reference tracer", ms_reference, wall_reference);
    speed("render_ids, one ray at a time", ms_per_ray, wall_per_ray);
    speed(&packets_label(), ms_fast, wall_fast);
    println!(
        "texels differing from the reference, both fast routes: {differing} of 2 × {} (and {ties} ties up to rounding, answered by another of the tied surfaces)",
        rays as usize * points.len()
    );
    let json = format!(
        "{{\"resolution\": {r}, \"near\": {}, \"points\": {}, \"triangles\": {}, \"ms_per_point_reference\": {ms_reference}, \
         \"ms_per_point_per_ray\": {ms_per_ray}, \"ms_per_point_fast\": {ms_fast}, \"texels_differing\": {differing}}}\n",
        backend.near(),
        points.len(),
        triangles.len()
    );
    std::fs::write(out_dir.join("hdov.json"), json)?;
    if differing > 0 {
        return Err(format!("the fast path differs from the reference tracer in {differing} texels").into());
    }
    Ok(())
}

/// `render_ids, packets of C × R rays`, the packet tracer's shape.
fn packets_label() -> String {
    let (cols, rows) = hdov::dov::cpu::PACKET_TEXELS;
    format!("render_ids, packets of {cols} × {rows} rays")
}

fn write_f32(path: &std::path::Path, values: impl Iterator<Item = f32>) -> std::io::Result<()> {
    std::fs::write(path, values.flat_map(f32::to_le_bytes).collect::<Vec<_>>())
}
