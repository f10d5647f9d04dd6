//! Per-cell agreement of the two DoV backends on the default city: the from-region DoV of every
//! object and tree node, as `hdov build` stores them, for one shard of the grid's cells.
//!
//! `cargo run --release -p hdov-tools --bin backend-cells -- [R] [SHARD I/N]`

use clap::Parser;
use hdov::city::{CityParams, CityScale};
use hdov::dov::gpu::{DEFAULT_LOD_TOLERANCE_TEXELS, GpuOptions};
use hdov::dov::precompute::{CellDov, PrecomputeOptions, Shard, TreeShape, precompute_shard};
use hdov::dov::{CpuBackend, DovBackend, GpuBackend};
use hdov::format::tree_page::fanout;
use hdov::lod::{LodParams, leaf_chain};
use hdov::rtree::{RTree, TreeAlgorithm};
use hdov_testkit::audit::DovDiff;

#[derive(Parser)]
#[command(
    name = "backend-cells",
    about = "Per-cell agreement of the CPU and GPU DoV backends on the default city, for one shard of its cells",
    long_about = "Per-cell agreement of the CPU and GPU DoV backends on the default city (seed 1): the from-region DoV\n\
                  of every object and tree node, as `hdov build` stores them, for one shard of the grid's cells; the\n\
                  GPU backend draws with leaf LODs at the default tolerance. Prints the visible (cell, object) pairs,\n\
                  |dDoV| max and mean (also in centre texels), the pairs beyond 0.5 % + 2 texels, the pairs visible on\n\
                  one backend only, and the largest node DoV and NVO differences. Needs a wgpu adapter (Mesa's\n\
                  lavapipe will do).\n\
                  \n\
                  Makes: docs/results.md, \"DoV measurement speed and backend agreement\", the bullet \"Per cell on\n\
                  the default city\" (`backend-cells 64 0/8`)."
)]
struct Args {
    /// Cube-map resolution R of both backends (texels per face edge).
    #[arg(default_value_t = 64)]
    r: u32,
    /// The cells measured: shard I of N equal parts of the grid's cells (as `hdov build --shard I/N`).
    #[arg(value_name = "SHARD", default_value = "0/8", value_parser = hdov_tools::args::shard)]
    shard: Shard,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { r, shard } = Args::parse();
    let scene = hdov::city::generate(&CityParams { seed: 1, scale: CityScale::Default, ..Default::default() })?;
    let grid = scene.grid.clone().expect("the city brings a grid");
    let tree = RTree::build(&scene.all_object_bounds(), fanout(4096), TreeAlgorithm::Str);
    let shape = TreeShape::of(&tree);
    let lods: Vec<_> = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    let run = |b: &mut dyn DovBackend| -> hdov::Result<Vec<(u32, CellDov)>> {
        let opts = PrecomputeOptions::default();
        Ok(precompute_shard(b, &grid, &scene.all_object_bounds(), &shape, &opts, shard, &hdov::progress::Quiet)?.cells)
    };
    let cpu = run(&mut CpuBackend::new(&scene, r)?)?;
    let options =
        GpuOptions { lods: Some(&lods), lod_tolerance_texels: DEFAULT_LOD_TOLERANCE_TEXELS, ..Default::default() };
    let mut gpu_backend = GpuBackend::with_options(&scene, r, &options)?;
    let adapter = gpu_backend.name();
    let gpu = run(&mut gpu_backend)?;
    let texel = hdov::dov::CubeMap::new(r).texel_floor();
    let mut d = DovDiff::default();
    let (mut node_max, mut nvo_diff) = (0.0f64, 0u32);
    for ((_, a), (_, b)) in cpu.iter().zip(&gpu) {
        for o in 0..scene.objects.len() as u32 {
            d.add(a.object(o) as f64, b.object(o) as f64, texel);
        }
        for n in 0..tree.nodes.len() as u32 {
            let ((x, nx), (y, ny)) = (a.node(n), b.node(n));
            node_max = node_max.max(((x - y) as f64).abs());
            nvo_diff = nvo_diff.max(nx.abs_diff(ny));
        }
    }
    println!(
        "default city, cells {:?} of {}, R = {r}; cpu vs {adapter} (LOD drawing {DEFAULT_LOD_TOLERANCE_TEXELS} texels)",
        shard.cells(&grid),
        grid.cell_count()
    );
    println!(
        "objects: {} visible (cell, object) pairs; |dDoV| max {:.3e} ({:.1} centre texels), mean {:.3e} ({:.3} texels); \
         beyond 0.5 % + 2 texels: {}; visible on one backend only: {}",
        d.objects,
        d.max_abs,
        d.max_abs / texel,
        d.mean_abs(),
        d.mean_abs() / texel,
        d.over_tolerance,
        d.flips
    );
    println!("nodes: |dDoV| max {node_max:.3e} ({:.1} texels); NVO differs by at most {nvo_diff}", node_max / texel);
    Ok(())
}
