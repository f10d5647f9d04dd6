//! From-region DoV over a view grid: shared corners, max of sums, NVO, zero-DoV floor, shards.

use glam::Vec3;
use hdov::dov::precompute::{
    CellContext, CellDov, FloorTest, PrecomputeOptions, Shard, TreeShape, cell_dov, part_dov, precompute_shard,
};
use hdov::dov::{CpuBackend, CubeMap, DovBackend, IdCube, PointDov};
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;
use hdov_testkit::audit::audit_zero_dov;
use hdov_testkit::scenes::*;

/// Wraps a backend and records every point it is asked to measure.
struct Counting<B> {
    inner: B,
    points: Vec<Vec3>,
}

impl<B: DovBackend> DovBackend for Counting<B> {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn resolution(&self) -> u32 {
        self.inner.resolution()
    }
    fn cube_map(&self) -> &CubeMap {
        self.inner.cube_map()
    }
    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> hdov::Result<()> {
        self.points.push(p);
        self.inner.render_ids(p, out)
    }
}

/// A street of boxes along x; one leaf per two objects, all leaves under one root.
fn street() -> (hdov::scene::Scene, TreeShape) {
    let mut b = SceneBuilder::default();
    for i in 0..8 {
        let x = i as f32 * 3.0;
        b.aabox(Vec3::new(x, 0.0, 4.0), Vec3::new(x + 2.0, 3.0, 6.0));
        b.aabox(Vec3::new(x, 0.0, -6.0), Vec3::new(x + 2.0, 2.0, -4.0));
    }
    let scene = b.build();
    let n = scene.objects.len() as u32;
    // Node 0 is the root, nodes 1..=n/2 the leaves.
    let object_leaf = (0..n).map(|o| 1 + o / 2).collect();
    let mut node_parent = vec![None];
    node_parent.extend((0..n / 2).map(|_| Some(0)));
    (scene, TreeShape { object_leaf, node_parent, ..Default::default() })
}

fn street_grid() -> ViewGrid {
    ViewGrid::new(Aabb::new(Vec3::new(0.0, 1.0, -2.0), Vec3::new(20.0, 2.0, 2.0)), [4, 1, 2])
}

#[test]
fn shared_corners_are_measured_once() {
    let (scene, shape) = street();
    let grid = street_grid();
    let mut backend = Counting { inner: CpuBackend::new(&scene, 16).unwrap(), points: Vec::new() };
    let calls = Calls::default();
    let bounds = scene.all_object_bounds();
    let out = precompute_shard(&mut backend, &grid, &bounds, &shape, &PrecomputeOptions::default(), Shard::ALL, &calls)
        .unwrap();
    let calls = calls.0.into_inner().unwrap();
    assert_eq!(grid.corner_count(), 5 * 2 * 3);
    assert_eq!(backend.points.len(), grid.corner_count(), "each corner measured exactly once");
    let mut distinct = backend.points.clone();
    distinct.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
    distinct.dedup();
    assert_eq!(distinct.len(), backend.points.len());
    assert_eq!(out.points_measured, grid.corner_count());
    assert_eq!(calls.last(), Some(&(30, 30)));
    assert_eq!(out.cells.len(), grid.cell_count());

    // With K interior points: K more per cell, corners still once.
    backend.points.clear();
    let options = PrecomputeOptions::sampled(hdov::Sampling::Interior(3));
    let out =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &options, Shard::ALL, &hdov::progress::Quiet).unwrap();
    assert_eq!(backend.points.len(), 30 + 3 * 8);
    assert_eq!(out.points_measured, 30 + 3 * 8);
}

#[test]
fn shards_cover_disjoint_cells_and_merge_to_the_whole() {
    let (scene, shape) = street();
    let grid = street_grid();
    let bounds = scene.all_object_bounds();
    let options = PrecomputeOptions::default();
    let mut backend = CpuBackend::new(&scene, 16).unwrap();
    let whole =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &options, Shard::ALL, &hdov::progress::Quiet).unwrap();
    let mut merged: Vec<(u32, CellDov)> = Vec::new();
    let mut measured = 0;
    for i in 0..3 {
        let shard = format!("{i}/3").parse::<Shard>().unwrap();
        let part =
            precompute_shard(&mut backend, &grid, &bounds, &shape, &options, shard, &hdov::progress::Quiet).unwrap();
        measured += part.points_measured;
        merged.extend(part.cells);
    }
    merged.sort_by_key(|c| c.0);
    assert_eq!(merged, whole.cells, "merged shards differ from the whole");
    // Shards recompute the corners on (and, for the neighbour floor test, one layer beyond)
    // their borders; each shard measures each of its corners once.
    assert!(measured > whole.points_measured && measured <= 3 * grid.corner_count());
    let corners_only = PrecomputeOptions { zero_dov_tests: vec![FloorTest::BoxWithin(0.0)], ..Default::default() };
    let mut measured = 0;
    for i in 0..3 {
        let shard = Shard { index: i, count: 3 };
        measured +=
            precompute_shard(&mut backend, &grid, &bounds, &shape, &corners_only, shard, &hdov::progress::Quiet)
                .unwrap()
                .points_measured;
    }
    assert!(measured < 8 * grid.cell_count(), "shards without the neighbour test measure {measured} corners");
    assert!("3/3".parse::<Shard>().is_err() && "1-3".parse::<Shard>().is_err() && "0/0".parse::<Shard>().is_err());
}

#[test]
fn node_dov_is_max_of_sums_not_sum_of_maxima() {
    // Two objects under leaf 1, under root 0. Point A sees object 0 a lot and object 1 a little;
    // point B the reverse. Max of sums = 0.35; sum of maxima would be 0.6.
    let shape =
        TreeShape { object_leaf: vec![1, 1, 2], node_parent: vec![None, Some(0), Some(0)], ..Default::default() };
    let point = |objects: Vec<(u32, f64)>| PointDov { resolution: 64, objects, back_face: 0.0, empty: 0.0 };
    let points = [point(vec![(0, 0.30), (1, 0.05)]), point(vec![(0, 0.05), (1, 0.30), (2, 0.01)])];
    let bounds = vec![Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0)); 3];
    let cell = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let points: Vec<&PointDov> = points.iter().collect();
    let c = cell_dov(&points, &[], &cell, &bounds, &shape, &PrecomputeOptions::default(), &CubeMap::new(64));
    assert_eq!(c.object(0), 0.30);
    assert_eq!(c.object(1), 0.30);
    let (leaf, leaf_nvo) = c.node(1);
    assert!((leaf - 0.35).abs() < 1e-6, "leaf DoV {leaf} is not the max of sums 0.35");
    assert_eq!(leaf_nvo, 2);
    let (root, root_nvo) = c.node(0);
    assert!((root - 0.36).abs() < 1e-6, "root DoV {root}");
    assert_eq!(root_nvo, 3);
    assert_eq!(c.node(2), (0.01, 1));
    assert_eq!(c.floored, 0);
}

#[test]
fn cell_dovs_from_a_real_scene_are_consistent() {
    let (scene, shape) = street();
    let grid = street_grid();
    let bounds = scene.all_object_bounds();
    let mut backend = CpuBackend::new(&scene, 32).unwrap();
    let out = precompute_shard(
        &mut backend,
        &grid,
        &bounds,
        &shape,
        &PrecomputeOptions::default(),
        Shard::ALL,
        &hdov::progress::Quiet,
    )
    .unwrap();
    for (id, cell) in &out.cells {
        let (root, nvo) = cell.node(0);
        assert!(root > 0.0 && root <= 1.0, "cell {id}: root DoV {root}");
        assert_eq!(nvo as usize, cell.objects.len(), "cell {id}: root NVO counts every visible object");
        let sum_of_maxima: f32 = cell.objects.iter().map(|o| o.1).sum();
        assert!(root <= sum_of_maxima + 1e-6);
        for &(object, dov) in &cell.objects {
            assert!(dov > 0.0);
            for node in shape.ancestors(object) {
                assert!(cell.node(node).0 >= dov, "cell {id}: node {node} below its object {object}");
            }
        }
    }
}

/// A small box inside a square tube along x: no corner of the cell around it sees it (the tube's
/// walls are in the way), a point on the tube's axis does. The floor test catches it.
fn tube_scene() -> (hdov::scene::Scene, u32) {
    let mut b = SceneBuilder::default();
    let target = b.aabox(Vec3::new(2.0, -0.1, -0.1), Vec3::new(2.2, 0.1, 0.1));
    // Tube walls (|y|, |z| ≤ 0.5 inside), x from -3 to 3.
    b.aabox(Vec3::new(-3.0, 0.5, -0.6), Vec3::new(3.0, 0.6, 0.6));
    b.aabox(Vec3::new(-3.0, -0.6, -0.6), Vec3::new(3.0, -0.5, 0.6));
    b.aabox(Vec3::new(-3.0, -0.5, 0.5), Vec3::new(3.0, 0.5, 0.6));
    b.aabox(Vec3::new(-3.0, -0.5, -0.6), Vec3::new(3.0, 0.5, -0.5));
    (b.build(), target)
}

#[test]
fn visible_zero_dov_object_gets_the_one_texel_floor() {
    let (scene, target) = tube_scene();
    let shape = TreeShape { object_leaf: vec![1; 5], node_parent: vec![None, Some(0)], ..Default::default() };
    // One cell straddling the tube: corners outside it, the centre on its axis.
    let grid = ViewGrid::new(Aabb::new(Vec3::new(-1.0, -1.0, -1.0), Vec3::new(1.0, 1.0, 1.0)), [1, 1, 1]);
    let bounds = scene.all_object_bounds();
    let mut backend = CpuBackend::new(&scene, 64).unwrap();
    assert!(backend.measure(Vec3::ZERO).unwrap().get(target) > 0.0, "the axis point sees the target");

    let no_floor = PrecomputeOptions { zero_dov_tests: vec![], ..Default::default() };
    let out =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &no_floor, Shard::ALL, &hdov::progress::Quiet).unwrap();
    assert_eq!(out.cells[0].1.object(target), 0.0, "a corner sees the target: the test scene is wrong");

    // The target's box is 1 unit from the cell: a margin of 1.5 reaches it.
    let floor = PrecomputeOptions { zero_dov_tests: vec![FloorTest::BoxWithin(1.5)], ..Default::default() };
    let out =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &floor, Shard::ALL, &hdov::progress::Quiet).unwrap();
    let cell = &out.cells[0].1;
    let want = backend.cube_map().texel_floor() as f32;
    assert_eq!(cell.object(target), want);
    assert_eq!(cell.floored, 1);
    assert_eq!(cell.node(1).1, 5, "the floored object counts in NVO");

    // The audit finds it with dense interior points (the cell centre is among them) and counts it
    // as caught by the floor.
    let audit = audit_zero_dov(
        &mut backend,
        &grid,
        &bounds,
        0..1,
        64,
        &[0],
        &[FloorTest::BoxWithin(0.5), FloorTest::BoxWithin(1.5)],
    )
    .unwrap();
    assert_eq!(audit[0].cells, 1);
    assert_eq!(audit[0].zero_dov, 1, "{audit:?}");
    assert_eq!(audit[0].caught, 0, "a margin of 0.5 does not reach the target: {audit:?}");
    assert_eq!(audit[1].caught, 1, "{audit:?}");
}

/// The neighbour-corner floor test: the upper cell's top corners lie inside the tube and see the
/// target; the lower cell's corners do not, and its box is far from the target, so only the
/// neighbour test floors it there.
#[test]
fn neighbour_corner_floor_test() {
    let (scene, target) = tube_scene();
    let shape = TreeShape { object_leaf: vec![1; 5], node_parent: vec![None, Some(0)], ..Default::default() };
    let grid = ViewGrid::new(Aabb::new(Vec3::new(-1.0, -1.8, -0.2), Vec3::new(1.0, 0.2, 0.2)), [1, 2, 1]);
    let bounds = scene.all_object_bounds();
    let mut backend = CpuBackend::new(&scene, 64).unwrap();
    let run = |tests: Vec<FloorTest>, backend: &mut CpuBackend| {
        let options = PrecomputeOptions { zero_dov_tests: tests, ..Default::default() };
        precompute_shard(backend, &grid, &bounds, &shape, &options, Shard::ALL, &hdov::progress::Quiet).unwrap()
    };
    let lower = grid.cell_id([0, 0, 0]);
    let upper = grid.cell_id([0, 1, 0]);
    let plain = run(vec![FloorTest::BoxWithin(0.0)], &mut backend);
    assert_eq!(plain.cells[lower].1.object(target), 0.0);
    assert!(plain.cells[upper].1.object(target) > backend.cube_map().texel_floor() as f32);
    let with_neighbours = run(vec![FloorTest::NeighbourCorners], &mut backend);
    assert_eq!(with_neighbours.cells[lower].1.object(target), backend.cube_map().texel_floor() as f32);
    assert_eq!(with_neighbours.cells[upper].1, plain.cells[upper].1, "a cell that sees it is unchanged");
}

/// The parts floor: a part next to one that the cell's points see gets the floor, a part further
/// on or of another object does not, and without the test nothing does. (What neighbouring
/// corners see counts with the neighbours test, which this cell has no corners for.)
#[test]
fn the_parts_floor_takes_the_parts_next_to_a_seen_part() {
    let point = PointDov { resolution: 64, objects: vec![(1, 0.01)], back_face: 0.0, empty: 0.0 };
    // Objects 0–3: parts of one object in a row; 4: another object.
    let shape = TreeShape {
        object_leaf: vec![1; 5],
        node_parent: vec![None, Some(0)],
        part_neighbours: vec![vec![1], vec![0, 2], vec![1, 3], vec![2], vec![]],
        part_planes: Vec::new(),
    };
    let far = Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0));
    let bounds = vec![far; 5];
    let cell = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let cube = CubeMap::new(64);
    let floor = cube.texel_floor() as f32;
    let with = |tests: Vec<FloorTest>| {
        let options = PrecomputeOptions { zero_dov_tests: tests, ..Default::default() };
        cell_dov(&[&point], &[], &cell, &bounds, &shape, &options, &cube)
    };
    let c = with(vec![FloorTest::PartNeighbours]);
    assert_eq!([c.object(0), c.object(1), c.object(2), c.object(3), c.object(4)], [floor, 0.01, floor, 0.0, 0.0]);
    assert_eq!(c.floored, 2);
    let c = with(vec![FloorTest::BoxWithin(0.0), FloorTest::NeighbourCorners]);
    assert_eq!([c.object(0), c.object(2)], [0.0, 0.0]);
    assert_eq!("parts".parse::<FloorTest>().unwrap(), FloorTest::PartNeighbours);
    assert_eq!(FloorTest::PartNeighbours.to_string(), "parts");

    // Part 0's face looks up from y = 0, at the cell (y from 0 to 1); part 2's looks up from
    // y = 5, the cell behind it: it shows the cell only its back, and gets no floor (decision
    // 137). A part listing no planes counts as facing every cell.
    let up = |y: f32| vec![glam::Vec4::new(0.0, 1.0, 0.0, y)];
    let facing = TreeShape { part_planes: vec![up(0.0), up(0.0), up(5.0), vec![], vec![]], ..shape.clone() };
    let options = PrecomputeOptions { zero_dov_tests: vec![FloorTest::PartNeighbours], ..Default::default() };
    let c = cell_dov(&[&point], &[], &cell, &bounds, &facing, &options, &cube);
    assert_eq!([c.object(0), c.object(1), c.object(2)], [floor, 0.01, 0.0]);
    assert_eq!(c.floored, 1);
}

#[test]
fn points_inside_geometry_are_skipped() {
    // A closed box around one corner of a 1-cell grid: that corner sees only back faces.
    let mut b = SceneBuilder::default();
    b.aabox(Vec3::splat(-0.5), Vec3::splat(0.5));
    b.aabox(Vec3::new(5.0, 0.0, 0.0), Vec3::new(6.0, 1.0, 1.0));
    let scene = b.build();
    let shape = TreeShape { object_leaf: vec![0, 0], node_parent: vec![None], ..Default::default() };
    let grid = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::splat(2.0)), [1, 1, 1]);
    let bounds = scene.all_object_bounds();
    let mut backend = CpuBackend::new(&scene, 32).unwrap();
    let options = PrecomputeOptions { zero_dov_tests: vec![], ..Default::default() };
    let out =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &options, Shard::ALL, &hdov::progress::Quiet).unwrap();
    let cell = &out.cells[0].1;
    assert_eq!(cell.skipped_points, 1);
    // From the other corners the small box covers far less than the near-1 it covers from inside.
    assert!(cell.object(0) < 0.3, "box DoV {} comes from the inside corner", cell.object(0));
    let keep = PrecomputeOptions { skip_inside_points: false, ..options };
    let out =
        precompute_shard(&mut backend, &grid, &bounds, &shape, &keep, Shard::ALL, &hdov::progress::Quiet).unwrap();
    assert!(out.cells[0].1.object(0) > 0.9);
}

/// Records every progress report, as `(done, total)`.
#[derive(Default)]
struct Calls(std::sync::Mutex<Vec<(usize, usize)>>);

impl hdov::progress::Report for Calls {
    fn advance(&self, _: u64) {}
    fn set(&self, done: u64, total: u64) {
        self.0.lock().unwrap().push((done as usize, total as usize));
    }
}

/// A part of a cell (a view cell refined from its lattice cell) answers what it sees at the
/// whole cell's DoVs, never a node above the whole's DoV, what the whole did not see at the
/// one-texel floor, and the box floor of its own box, not the whole cell's.
#[test]
fn a_part_of_a_cell_sees_no_more_than_the_whole() {
    // Objects 0–2 under leaf 1, object 3 under leaf 2; both leaves under the root 0.
    let shape =
        TreeShape { object_leaf: vec![1, 1, 1, 2], node_parent: vec![None, Some(0), Some(0)], ..Default::default() };
    let point = |objects: Vec<(u32, f64)>| PointDov { resolution: 64, objects, back_face: 0.0, empty: 0.0 };
    let points = [point(vec![(0, 0.30), (1, 0.05)]), point(vec![(0, 0.05), (1, 0.30)])];
    let points: Vec<&PointDov> = points.iter().collect();
    let far = Aabb::new(Vec3::splat(100.0), Vec3::splat(101.0));
    // Object 2 meets the whole cell's box but not the part's; object 3 meets the part's.
    let bounds =
        vec![far, far, Aabb::new(Vec3::new(0.8, 0.0, 0.8), Vec3::ONE), Aabb::new(Vec3::ZERO, Vec3::splat(0.2))];
    let (cell, part) = (Aabb::new(Vec3::ZERO, Vec3::ONE), Aabb::new(Vec3::ZERO, Vec3::new(0.5, 1.0, 0.5)));
    let cube = CubeMap::new(64);
    let no_floor = PrecomputeOptions { zero_dov_tests: vec![], ..Default::default() };
    let whole = cell_dov(&points, &[], &cell, &bounds, &shape, &no_floor, &cube);
    assert!((whole.node(1).0 - 0.35).abs() < 1e-6);
    let context =
        |options| CellContext { around: &[], object_bounds: &bounds, near: None, shape: &shape, options, cube: &cube };
    let seen = |objects: &[u32]| objects.iter().copied().collect::<std::collections::HashSet<u32>>();

    let one = part_dov(&seen(&[0]), &whole, &part, &context(&no_floor));
    assert_eq!(one.objects, vec![(0, 0.30)]);
    assert!((one.node(1).0 - 0.30).abs() < 1e-6 && one.node(1).1 == 1);
    // Both seen: their sum (0.60) is more than the whole saw of their leaf at any point.
    let both = part_dov(&seen(&[0, 1]), &whole, &part, &context(&no_floor));
    assert!((both.node(1).0 - 0.35).abs() < 1e-6 && both.node(1).1 == 2, "{:?}", both.node(1));
    // What the whole did not see (a ray from the part met it) is visible at the floor.
    let floor = cube.texel_floor() as f32;
    assert_eq!(part_dov(&seen(&[3]), &whole, &part, &context(&no_floor)).objects, vec![(3, floor)]);
    // The box floor takes what meets the part's box, not what meets the whole cell's only.
    let boxed = PrecomputeOptions { zero_dov_tests: vec![FloorTest::BoxWithin(0.0)], ..Default::default() };
    let floored = part_dov(&seen(&[0]), &whole, &part, &context(&boxed));
    assert_eq!(floored.objects, vec![(0, 0.30), (3, floor)]);
    assert_eq!(floored.floored, 1);
}
