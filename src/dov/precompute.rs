//! From-region DoV for every cell of a view grid (thesis §5.2, §5.5; docs/dov.md, "From-region DoV").
//!
//! Per cell, the sample points are its 8 corners (shared with the neighbouring cells and measured
//! once each) plus those of the build's samplers ([`super::sampler`]). Then:
//! - object DoV = max over the sample points of the point DoV;
//! - node DoV = max over the sample points of the *sum* of the point DoVs of the objects under the
//!   node (the max of sums, which stays ≤ 1; not the sum of maxima);
//! - NVO = number of objects under the node whose cell DoV is > 0;
//! - *visible zero-DoV* objects (§5.5.2): objects no sample point sees but that one of the
//!   [`PrecomputeOptions::zero_dov_tests`] finds possibly visible get the one-texel floor
//!   [`CubeMap::texel_floor`], so that a query still fetches them (at a coarse LOD).
//!
//! Work can be split into shards of disjoint cells ([`Shard`]); their outputs merge by
//! concatenation.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};
use std::time::Instant;

use glam::Vec3;

use super::sampler::{CellSampler, CellSite, Tally};
use super::sampling::{is_inside, seen_by};
use super::{CubeMap, DovBackend, PointDov};
use crate::error::{Error, Param, Result};
pub use crate::format::params::{FloorTest, Shard};
use crate::format::BakePhases;
use crate::format::params::{Sampling, VisibilityParams};
use crate::geom::Aabb;
use crate::grid::ViewGrid;
use crate::progress::Report;

/// The shape of the object tree, as far as DoV aggregation needs it, and which objects are
/// neighbouring parts of one file object, as far as the parts floor needs it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeShape {
    /// Leaf node id of each object.
    pub object_leaf: Vec<u32>,
    /// Parent of each node id (`None` for the root).
    pub node_parent: Vec<Option<u32>>,
    /// Each object's neighbouring parts ([`crate::scene::parts::part_neighbours`]); empty (for
    /// all objects, or for one) where nothing was cut.
    pub part_neighbours: Vec<Vec<u32>>,
}

impl TreeShape {
    /// The shape of `tree`: its objects' leaves and its nodes' parents, no parts' neighbours.
    pub fn of(tree: &crate::rtree::RTree) -> Self {
        let node_parent = tree.nodes.iter().map(|n| n.parent).collect();
        Self { object_leaf: tree.object_leaves(), node_parent, part_neighbours: Vec::new() }
    }

    /// Checks that every id is in range and every node reaches a root (no cycles). O(nodes·depth).
    pub fn check(&self, objects: usize) -> Result<()> {
        let nodes = self.node_parent.len();
        if self.object_leaf.len() != objects {
            return Err(Error::bad_param(
                Param::TreeShape,
                format!("{} object leaves for {objects} objects", self.object_leaf.len()),
            ));
        }
        if let Some(&bad) = self.object_leaf.iter().find(|&&l| l as usize >= nodes) {
            return Err(Error::bad_param(Param::TreeShape, format!("leaf {bad} out of range ({nodes} nodes)")));
        }
        for start in 0..nodes {
            let mut node = start;
            for step in 0..=nodes {
                match self.node_parent[node] {
                    None => break,
                    Some(p) if (p as usize) < nodes && step < nodes => node = p as usize,
                    Some(p) => {
                        return Err(Error::bad_param(
                            Param::TreeShape,
                            format!("node {start}: parent {p} out of range or a cycle"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The node ids on the path from `object`'s leaf up to the root, leaf first.
    pub fn ancestors(&self, object: u32) -> impl Iterator<Item = u32> + '_ {
        std::iter::successors(Some(self.object_leaf[object as usize]), |&n| self.node_parent[n as usize])
    }
}

/// The precomputed visibility of one cell. Only entries > 0 are stored.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellDov {
    /// `(object index, DoV)`, ascending object index.
    pub objects: Vec<(u32, f32)>,
    /// `(node id, DoV, NVO)`, ascending node id.
    pub nodes: Vec<(u32, f32, u32)>,
    /// How many of `objects` got the visible-zero-DoV floor.
    pub floored: u32,
    /// Sample points left out because they lie inside geometry (see
    /// [`PrecomputeOptions::skip_inside_points`]).
    pub skipped_points: u32,
}

impl CellDov {
    /// The DoV of `object` (0 when absent). O(log n).
    pub fn object(&self, object: u32) -> f32 {
        self.objects.binary_search_by_key(&object, |e| e.0).map_or(0.0, |i| self.objects[i].1)
    }

    /// `(DoV, NVO)` of `node` ((0, 0) when absent). O(log n).
    pub fn node(&self, node: u32) -> (f32, u32) {
        self.nodes.binary_search_by_key(&node, |e| e.0).map_or((0.0, 0), |i| (self.nodes[i].1, self.nodes[i].2))
    }
}

/// What the floor tests know of a cell.
pub struct FloorContext<'a> {
    /// The cell's box.
    pub cell_box: &'a Aabb,
    /// The objects that the neighbouring cells' corners (and region rays) see; empty without
    /// the neighbours test.
    pub seen_nearby: &'a HashSet<u32>,
    /// The objects that the cell's own points see.
    pub seen_here: &'a HashSet<u32>,
    /// Each object's neighbouring parts ([`TreeShape::part_neighbours`]).
    pub part_neighbours: &'a [Vec<u32>],
}

impl FloorTest {
    /// Whether this test finds `object` (with world box `bounds`) possibly visible from the cell.
    pub fn finds(&self, object: u32, bounds: &Aabb, cell: &FloorContext) -> bool {
        match *self {
            FloorTest::BoxWithin(margin) => {
                let m = Vec3::splat(margin);
                !bounds.is_empty() && bounds.intersects(&Aabb::new(cell.cell_box.min - m, cell.cell_box.max + m))
            }
            FloorTest::NeighbourCorners => cell.seen_nearby.contains(&object),
            FloorTest::PartNeighbours => cell
                .part_neighbours
                .get(object as usize)
                .is_some_and(|parts| parts.iter().any(|p| cell.seen_here.contains(p) || cell.seen_nearby.contains(p))),
        }
    }
}

/// Options of a precomputation.
#[derive(Clone, Debug, PartialEq)]
pub struct PrecomputeOptions {
    /// The samplers that measure each cell besides its 8 corners, run in turn (each sees the
    /// points the ones before it measured). Empty: the corners alone (the thesis).
    pub samplers: Vec<Sampling>,
    /// Objects that no sample point sees but any of these tests finds possibly visible get the
    /// one-texel floor. Empty: no floor.
    pub zero_dov_tests: Vec<FloorTest>,
    /// Leave out sample points whose view is mostly back faces (more than half the sphere): they
    /// lie inside a closed mesh and would give its walls a DoV near 1. When all points of a cell
    /// are inside, they are all kept.
    pub skip_inside_points: bool,
}

/// The corners alone, with both floors: the thesis's sampling (a build's default sampler is
/// [`Sampling::default`]: [`PrecomputeOptions::of`]).
impl Default for PrecomputeOptions {
    fn default() -> Self {
        Self {
            samplers: Vec::new(),
            zero_dov_tests: FloorTest::DEFAULT.to_vec(),
            skip_inside_points: true,
        }
    }
}

impl PrecomputeOptions {
    /// What a build with `v` measures.
    pub fn of(v: &VisibilityParams) -> Self {
        PrecomputeOptions { samplers: vec![v.sampling], zero_dov_tests: v.zero_dov_floor.clone(), ..Default::default() }
    }

    /// The corners and `sampling`, with both floors.
    pub fn sampled(sampling: Sampling) -> Self {
        PrecomputeOptions { samplers: vec![sampling], ..Default::default() }
    }

    fn uses_neighbours(&self) -> bool {
        self.zero_dov_tests.contains(&FloorTest::NeighbourCorners)
    }
}

/// The output of one shard.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShardDov {
    /// `(cell id, visibility)` for every cell of the shard, ascending id.
    pub cells: Vec<(u32, CellDov)>,
    /// Point measurements done (distinct corners + interior points of the shard).
    pub points_measured: usize,
    /// Cube-map resolution of the measurements.
    pub resolution: u32,
    /// Rays cast by ray probing towards targets, and to measure footprints.
    pub probe_rays: u64,
    pub footprint_rays: u64,
    /// Region views drawn instead of region rays cast (the GPU backend).
    pub region_views: u64,
    /// Where the shard's time went.
    pub phases: BakePhases,
}

/// Computes the [`CellDov`] of every cell of `shard`.
///
/// Every corner that a shard cell uses — its own 8, plus its neighbours' within the widest ring
/// that a sampler ([`CellSampler::corner_ring`]) or [`FloorTest::NeighbourCorners`] reads — is
/// measured exactly once and kept until the last cell that uses it is done (memory: about two
/// layers of corners, four with the neighbour test); then each sampler adds the cell's points.
/// `progress` is set to `(points done, points total)` after each measurement (the total grows
/// where a sampler takes more than it planned). Costs (distinct corners + the samplers' points)
/// backend measurements plus, per cell, O(visible objects × tree depth × points + objects) for
/// the floor tests.
pub fn precompute_shard(
    backend: &mut dyn DovBackend,
    grid: &ViewGrid,
    object_bounds: &[Aabb],
    shape: &TreeShape,
    options: &PrecomputeOptions,
    shard: Shard,
    progress: &dyn Report,
) -> Result<ShardDov> {
    grid.check().map_err(|r| Error::bad_param(Param::Grid, r))?;
    shape.check(object_bounds.len())?;
    if shard.count == 0 || shard.index >= shard.count {
        return Err(Error::bad_param(Param::Shard, format!("{}/{} is not 0 ≤ I < N", shard.index, shard.count)));
    }
    let cells: Vec<usize> = shard.cells(grid).chain(shard.parts(grid)).filter(|&id| grid.is_present(id)).collect();
    let mut samplers: Vec<Box<dyn CellSampler>> = options.samplers.iter().map(Sampling::sampler).collect();
    let ring = samplers.iter().map(|s| s.corner_ring()).chain([u32::from(options.uses_neighbours())]).max().unwrap_or(0);
    let corners_of = |coords: [u32; 3]| grid.neighbourhood_view_corners(coords, ring);
    // What is sampled as one: each view cell, or where lattice cells are refined, each lattice
    // cell's view cells together (the lattice cell's own id), refined into them after.
    let split = grid.refines_lattice_cells();
    let sites: Vec<(usize, Vec<usize>)> = if split {
        cells.iter().filter(|&&id| id < grid.lattice_count()).map(|&id| (id, grid.view_cells_of(id).collect())).collect()
    } else {
        cells.iter().map(|&id| (id, vec![id])).collect()
    };
    // How many shard cells still need each corner: drop a corner's DoV after its last cell.
    let mut corner_uses: HashMap<usize, u32> = HashMap::new();
    for (id, _) in &sites {
        for c in corners_of(grid.cell_coords(*id)) {
            *corner_uses.entry(c).or_insert(0) += 1;
        }
    }
    let per_cell: u32 = samplers.iter().map(|s| s.planned_points()).sum();
    let mut tally = Tally::new(corner_uses.len() + cells.len() * per_cell as usize, progress);
    for sampler in &mut samplers {
        sampler.prepare(backend, grid, &cells, &mut tally)?;
    }
    let mut corner_dov: HashMap<usize, PointDov> = HashMap::new();
    let cube = backend.cube_map().clone();
    let mut out = ShardDov { cells: Vec::with_capacity(cells.len()), resolution: cube.resolution(), ..Default::default() };
    for (id, children) in sites {
        let coords = grid.cell_coords(id);
        let cell_box = grid.cell_box(coords);
        let places = if split { grid.lattice_places(id) } else { grid.places_of(id) };
        let needed = corners_of(coords);
        let start = Instant::now();
        for &corner in &needed {
            if let Entry::Vacant(slot) = corner_dov.entry(corner) {
                slot.insert(backend.measure(grid.corner_position(grid.corner_coords(corner)))?);
                tally.measured(false);
            }
        }
        tally.phases.corners += start.elapsed().as_secs_f64();
        let own = grid.corners_next_to(coords, places);
        let own_dov: Vec<&PointDov> = own.iter().map(|c| &corner_dov[c]).collect();
        let nearby_ids: Vec<usize> = needed.iter().copied().filter(|c| !own.contains(c)).collect();
        let nearby: Vec<&PointDov> = nearby_ids.iter().map(|c| &corner_dov[c]).collect();
        let nearby_at: Vec<Vec3> = nearby_ids.iter().map(|&c| grid.corner_position(grid.corner_coords(c))).collect();
        let site = CellSite {
            id,
            coords,
            bounds: cell_box,
            places,
            grid,
            corners: &own_dov,
            nearby: &nearby,
            nearby_at: &nearby_at,
            object_bounds,
            cube: &cube,
        };
        let mut sampled = Vec::new();
        for sampler in &mut samplers {
            sampler.sample(backend, &site, &mut sampled, &mut tally)?;
        }
        let points: Vec<&PointDov> = own_dov.iter().copied().chain(&sampled).collect();
        // What the samplers found from the neighbouring cells by themselves (region rays) counts
        // as seen nearby, as their corners' views do (the neighbours floor).
        let found_around: Vec<PointDov> = grid
            .neighbourhood_view_cells(coords, 1)
            .into_iter()
            .filter(|&n| n != id)
            .flat_map(|n| samplers.iter().filter_map(move |s| s.found_from(n)))
            .map(|objects| PointDov {
                resolution: cube.resolution(),
                objects: objects.into_iter().map(|o| (o, 0.0)).collect(),
                back_face: 0.0,
                empty: 0.0,
            })
            .collect();
        let around: Vec<&PointDov> = if ring > 0 {
            grid.neighbourhood_view_corners(coords, 1)
                .into_iter()
                .filter(|c| !own.contains(c))
                .map(|c| &corner_dov[&c])
                .chain(&found_around)
                .collect()
        } else {
            Vec::new()
        };
        let whole = cell_dov(&points, &around, &cell_box, object_bounds, shape, options, &cube);
        if !split {
            out.cells.push((id as u32, whole));
        } else {
            // Each view cell sees what the whole sees from its own squares: its corners' views,
            // the samplers' findings there, and what rays from its own points at the rest meet.
            let seen_whole = seen_by(points.iter().copied());
            let mut candidates: Vec<u32> = seen_whole.iter().copied().collect();
            candidates.sort_unstable();
            for child in children {
                let child_places = grid.places_of(child);
                let mut seen = seen_by(grid.view_corners(child).iter().map(|c| &corner_dov[c]));
                // A sampler that cannot place its findings, or none (the corners alone: a
                // quarter has 2 of them), leaves the view cell what the whole cell sees.
                let mut placed = !samplers.is_empty();
                for sampler in &mut samplers {
                    match sampler.refine(backend, &site, child_places, &seen, &candidates, &mut tally)? {
                        Some(refined) => seen = refined,
                        None => placed = false,
                    }
                }
                if !placed {
                    seen.extend(&seen_whole);
                }
                // A view cell that confirms most of what its lattice cell sees takes all of it:
                // what it would leave out is little, and most likely what it sees through gaps
                // too thin for its rays.
                if seen.len() as f64 >= REFINED_TAKES_WHOLE * seen_whole.len() as f64 {
                    seen.extend(&seen_whole);
                }
                let part = crate::grid::ViewCell { bounds: cell_box, places: child_places }.places_box();
                let context = CellContext { around: &around, object_bounds, shape, options, cube: &cube };
                out.cells.push((child as u32, part_dov(&seen, &whole, &part, &context)));
            }
        }
        for corner in needed {
            let uses = corner_uses.get_mut(&corner).expect("every needed corner is counted");
            *uses -= 1;
            if *uses == 0 {
                corner_dov.remove(&corner);
            }
        }
    }
    out.cells.sort_unstable_by_key(|c| c.0);
    out.points_measured = tally.done();
    out.probe_rays = tally.probe_rays;
    out.footprint_rays = tally.footprint_rays;
    out.region_views = tally.region_views;
    out.phases = tally.phases;
    Ok(out)
}

/// A view cell refined from its lattice cell ([`ViewGrid::refines_lattice_cells`]) that sees at
/// least this share of the objects its lattice cell's points see takes all of them. Measured on
/// four game levels and a house in parts (decision 130): refining every view cell answered
/// 0.47–0.55× the levels' PVS but the house's mean miss rose from 7.6e-7 to 4.5e-6 (thin
/// rafters that only the lattice cell's other corners saw); at 0.8 the levels answer 0.49–0.59×
/// at their unrefined misses and the house misses 1.2e-6; at 0.9, 0.55–0.57× and 2.6e-6.
const REFINED_TAKES_WHOLE: f64 = 0.8;

/// What combining a cell's views takes besides the views ([`cell_dov`], [`part_dov`]).
pub struct CellContext<'a> {
    /// The neighbouring cells' corners and finds, for [`FloorTest::NeighbourCorners`].
    pub around: &'a [&'a PointDov],
    pub object_bounds: &'a [Aabb],
    pub shape: &'a TreeShape,
    pub options: &'a PrecomputeOptions,
    pub cube: &'a CubeMap,
}

/// The [`CellDov`] of a part of a cell (a view cell refined from its lattice cell), box `part`,
/// that sees `seen`, from the whole cell's `whole`: each object seen at the whole's DoV (at
/// least the one-texel floor, for what the whole did not see), the floors of the part's own box
/// and sight, and no node above the whole's DoV (or the floor): a part of a cell sees no more
/// of an object or a node than the whole does.
pub fn part_dov(seen: &HashSet<u32>, whole: &CellDov, part: &Aabb, c: &CellContext) -> CellDov {
    let floor = c.cube.texel_floor();
    let mut objects: Vec<(u32, f64)> = seen.iter().map(|&o| (o, f64::from(whole.object(o)).max(floor))).collect();
    objects.sort_unstable_by_key(|e| e.0);
    let view = PointDov { resolution: c.cube.resolution(), objects, back_face: 0.0, empty: 0.0 };
    let mut dov = cell_dov(&[&view], c.around, part, c.object_bounds, c.shape, c.options, c.cube);
    for n in &mut dov.nodes {
        let (most, _) = whole.node(n.0);
        if most > 0.0 {
            n.1 = n.1.min(most.max(floor as f32));
        }
    }
    dov
}

/// Combines the point DoVs of one cell's sample points into its [`CellDov`] (see the module
/// documentation for the rules); `around` are the neighbouring cells' corners, used only by
/// [`FloorTest::NeighbourCorners`]. Pure; O(Σ visible objects per point × tree depth).
pub fn cell_dov(
    points: &[&PointDov],
    around: &[&PointDov],
    cell_box: &Aabb,
    object_bounds: &[Aabb],
    shape: &TreeShape,
    options: &PrecomputeOptions,
    cube: &CubeMap,
) -> CellDov {
    let inside = |p: &&&PointDov| options.skip_inside_points && is_inside(p);
    let skipped = points.iter().filter(inside).count();
    let keep_all = skipped == points.len();
    let used: Vec<&PointDov> = points.iter().filter(|p| keep_all || !inside(p)).copied().collect();

    let mut object_max: HashMap<u32, f64> = HashMap::new();
    let mut node_max: HashMap<u32, f64> = HashMap::new();
    let mut node_sum: HashMap<u32, f64> = HashMap::new();
    for p in &used {
        node_sum.clear();
        for &(object, dov) in &p.objects {
            let m = object_max.entry(object).or_insert(0.0);
            *m = m.max(dov);
            for node in shape.ancestors(object) {
                *node_sum.entry(node).or_insert(0.0) += dov;
            }
        }
        for (&node, &sum) in &node_sum {
            let m = node_max.entry(node).or_insert(0.0);
            *m = m.max(sum);
        }
    }

    let mut floored = 0;
    if !options.zero_dov_tests.is_empty() {
        let seen_around: HashSet<u32> =
            if options.uses_neighbours() { seen_by(around.iter().copied()) } else { Default::default() };
        let floor = cube.texel_floor();
        // What the points see, before any floor.
        let seen_here: HashSet<u32> = object_max.keys().copied().collect();
        let context = FloorContext {
            cell_box,
            seen_nearby: &seen_around,
            seen_here: &seen_here,
            part_neighbours: &shape.part_neighbours,
        };
        for (object, bounds) in object_bounds.iter().enumerate() {
            let object = object as u32;
            if object_max.contains_key(&object) {
                continue;
            }
            let possibly_visible =
                options.zero_dov_tests.iter().any(|t| t.finds(object, bounds, &context));
            if possibly_visible {
                object_max.insert(object, floor);
                floored += 1;
                // Keep node DoV ≥ every object DoV below it (queries prune by node DoV).
                for node in shape.ancestors(object) {
                    let m = node_max.entry(node).or_insert(0.0);
                    *m = m.max(floor);
                }
            }
        }
    }

    let mut nvo: HashMap<u32, u32> = HashMap::new();
    for &object in object_max.keys() {
        for node in shape.ancestors(object) {
            *nvo.entry(node).or_insert(0) += 1;
        }
    }
    let mut objects: Vec<(u32, f32)> = object_max.into_iter().map(|(o, d)| (o, positive_f32(d))).collect();
    objects.sort_unstable_by_key(|e| e.0);
    let mut nodes: Vec<(u32, f32, u32)> =
        node_max.into_iter().map(|(n, d)| (n, positive_f32(d), nvo.get(&n).copied().unwrap_or(0))).collect();
    nodes.sort_unstable_by_key(|e| e.0);
    CellDov { objects, nodes, floored, skipped_points: if keep_all { 0 } else { skipped as u32 } }
}

/// `d` as f32, never rounded down to 0 (an entry that exists means "visible") and never above 1.
fn positive_f32(d: f64) -> f32 {
    (d as f32).clamp(f32::MIN_POSITIVE, 1.0)
}
