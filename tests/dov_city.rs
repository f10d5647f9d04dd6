//! The two DoV backends agree per cell on a generated city: the from-region DoV of every object
//! and every tree node, as the build stores them.

use hdov::city::{CityParams, CityScale};
use hdov::dov::precompute::{CellDov, PrecomputeOptions, Shard, TreeShape, precompute_shard};
use hdov::dov::{CpuBackend, DovBackend, GpuBackend, gpu::adapter_or_skip};
use hdov::rtree::{RTree, TreeAlgorithm};

const R: u32 = 48;

fn run(backend: &mut dyn DovBackend, scene: &hdov::scene::Scene, shape: &TreeShape) -> Vec<(u32, CellDov)> {
    let grid = scene.grid.unwrap();
    let opts = PrecomputeOptions::default();
    precompute_shard(
        backend,
        &grid,
        &scene.all_object_bounds(),
        shape,
        &opts,
        Shard { index: 1, count: 3 },
        &mut |_, _| {},
    )
    .unwrap()
    .cells
}

#[test]
fn cpu_and_gpu_give_the_same_cell_dov_on_a_city() {
    if !adapter_or_skip() {
        return;
    }
    let scene = hdov::city::generate(&CityParams { seed: 5, scale: CityScale::Tiny, ..Default::default() }).unwrap();
    let tree = RTree::build(&scene.all_object_bounds(), 8, TreeAlgorithm::Str);
    let shape =
        TreeShape { object_leaf: tree.object_leaves(), node_parent: tree.nodes.iter().map(|n| n.parent).collect() };
    let cpu = run(&mut CpuBackend::new(&scene, R).unwrap(), &scene, &shape);
    let gpu = run(&mut GpuBackend::new(&scene, R).unwrap(), &scene, &shape);
    assert_eq!(cpu.len(), gpu.len());
    // Tolerance: 1 % of the value plus a quarter row of face-centre texels. The rasteriser snaps
    // vertices to 1/256 texel, so along an axis-aligned building edge a run of texels may go
    // either way (docs/dov.md, backend agreement).
    let texel = (2.0 / R as f64).powi(2) / (4.0 * std::f64::consts::PI);
    let tol = |v: f64| 0.01 * v + (R / 4) as f64 * texel;
    let (mut compared, mut worst) = (0, 0.0f64);
    for ((c, a), (c2, b)) in cpu.iter().zip(&gpu) {
        assert_eq!(c, c2);
        for o in 0..scene.objects.len() as u32 {
            let (x, y) = (a.object(o) as f64, b.object(o) as f64);
            assert!((x - y).abs() <= tol(x.max(y)), "cell {c} object {o}: cpu {x} gpu {y}");
            worst = worst.max((x - y).abs());
            compared += usize::from(x > 0.0 || y > 0.0);
        }
        for n in 0..tree.nodes.len() as u32 {
            let ((x, nx), (y, ny)) = (a.node(n), b.node(n));
            assert!(((x - y) as f64).abs() <= tol(x.max(y) as f64), "cell {c} node {n}: cpu {x} gpu {y}");
            // Visible-object counts may differ only by objects at the edge of visibility.
            assert!(nx.abs_diff(ny) <= 1 + nx.max(ny) / 10, "cell {c} node {n}: NVO cpu {nx} gpu {ny}");
        }
    }
    assert!(compared > 100, "the comparison covers many visible objects ({compared})");
    println!("{compared} visible (cell, object) pairs, worst |ΔDoV| {worst:.2e} (one texel {texel:.2e})");
}
