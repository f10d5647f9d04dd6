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

use glam::{Vec3, Vec4};

use super::sampler::{CellSampler, CellSite, Tally};
use super::sampling::{is_inside, seen_by};
use super::{CubeMap, DovBackend, PointDov};
use crate::error::{Error, Param, Result};
pub use crate::format::params::{FloorTest, Shard};
use crate::format::BakePhases;
use crate::format::params::{Sampling, VisibilityParams};
use crate::geom::Aabb;
use crate::grid::ViewGrid;
use crate::scene::parts::turns_a_face_to;
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
    /// Each part's face planes ([`crate::scene::parts::part_planes`]), for the parts floor's
    /// test that a part turns a face to the cell; empty where nothing was cut, and a part that
    /// lists none counts as facing every cell.
    pub part_planes: Vec<Vec<Vec4>>,
}

impl TreeShape {
    /// The shape of `tree`: its objects' leaves and its nodes' parents, no parts' neighbours.
    pub fn of(tree: &crate::rtree::RTree) -> Self {
        let node_parent = tree.nodes.iter().map(|n| n.parent).collect();
        Self { object_leaf: tree.object_leaves(), node_parent, part_neighbours: Vec::new(), part_planes: Vec::new() }
    }

    /// Checks that every id is in range, every node reaches a root (no cycles) and neighbouring
    /// parts list each other. O(nodes·depth + Σ neighbours²).
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
        if !self.part_planes.is_empty() && self.part_planes.len() != objects {
            return Err(Error::bad_param(
                Param::TreeShape,
                format!("face planes for {} of {objects} objects", self.part_planes.len()),
            ));
        }
        // The floors find a part through the parts that list it ([`CellContext::near`]).
        for (object, parts) in self.part_neighbours.iter().enumerate() {
            let listed_back = |&p: &u32| self.part_neighbours.get(p as usize).is_some_and(|back| back.contains(&(object as u32)));
            if let Some(p) = parts.iter().find(|p| !listed_back(p)) {
                return Err(Error::bad_param(Param::TreeShape, format!("part {p} does not list its neighbour {object}")));
            }
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
    /// Each part's face planes ([`TreeShape::part_planes`]).
    pub part_planes: &'a [Vec<Vec4>],
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
            FloorTest::PartNeighbours => {
                let seen = |p: &u32| cell.seen_here.contains(p) || cell.seen_nearby.contains(p);
                let planes = cell.part_planes.get(object as usize).map_or(&[][..], Vec::as_slice);
                cell.part_neighbours.get(object as usize).is_some_and(|parts| parts.iter().any(seen))
                    && turns_a_face_to(planes, cell.cell_box)
            }
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
/// backend measurements plus, per cell, O(visible objects × tree depth × points) and, for the
/// floor tests, the objects near the cell and the neighbouring parts of what it sees.
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
    let near_boxes = NearBoxes::new(grid, object_bounds, options, sites.iter().map(|(id, _)| grid.cell_id(grid.cell_coords(*id))));
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
        let near = near_boxes.near(grid.cell_id(coords));
        let context = CellContext { around: &around, object_bounds, near: Some(&near), shape, options, cube: &cube };
        let whole = combine(&points, &cell_box, &context);
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
                // too thin for its rays. What it took from across its lattice cell's border does
                // not count towards that share.
                let confirmed = seen.iter().filter(|o| seen_whole.contains(o)).count();
                if confirmed as f64 >= REFINED_TAKES_WHOLE * seen_whole.len() as f64 {
                    seen.extend(&seen_whole);
                }
                let part = crate::grid::ViewCell { bounds: cell_box, places: child_places }.places_box();
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

/// For each lattice cell a shard samples, the objects whose boxes may meet its box grown by the
/// widest [`FloorTest::BoxWithin`] margin: the box floor's candidates ([`CellContext::near`]),
/// found once per shard. Testing every object in every cell cost cells × objects, serially: 3 s
/// of a 57 s build of a 2,000-part level (dm4ish), and it grows as the square of a scene's size.
struct NearBoxes {
    /// By lattice cell id, for the cells sampled (none without a box test).
    by_cell: HashMap<usize, Vec<u32>>,
    /// Objects that span more than [`NearBoxes::WIDE`] lattice cells: near every cell.
    wide: Vec<u32>,
}

impl NearBoxes {
    /// The most lattice cells an object is listed in before it counts as near every cell: the
    /// lists hold at most this many entries an object.
    const WIDE: u64 = 4096;

    fn new(grid: &ViewGrid, object_bounds: &[Aabb], options: &PrecomputeOptions, cells: impl Iterator<Item = usize>) -> Self {
        let margins = options.zero_dov_tests.iter().filter_map(|t| match *t {
            FloorTest::BoxWithin(m) => Some(m),
            _ => None,
        });
        let Some(margin) = margins.reduce(f32::max) else {
            return NearBoxes { by_cell: HashMap::new(), wide: Vec::new() };
        };
        let mut near = NearBoxes { by_cell: cells.map(|id| (id, Vec::new())).collect(), wide: Vec::new() };
        let m = Vec3::splat(margin);
        for (object, bounds) in object_bounds.iter().enumerate() {
            // An empty box meets nothing ([`FloorTest::finds`]).
            let span = if bounds.is_empty() { None } else { grid.lattice_span(&Aabb::new(bounds.min - m, bounds.max + m)) };
            let Some(span @ [lo, hi]) = span else { continue };
            let count: u64 = (0..3).map(|a| u64::from(hi[a] - lo[a] + 1)).product();
            if count > Self::WIDE {
                near.wide.push(object as u32);
                continue;
            }
            for id in grid.lattice_cells(span) {
                if let Some(list) = near.by_cell.get_mut(&id) {
                    list.push(object as u32);
                }
            }
        }
        near
    }

    /// The objects near lattice cell `cell`.
    fn near(&self, cell: usize) -> Vec<u32> {
        self.by_cell.get(&cell).into_iter().flatten().chain(&self.wide).copied().collect()
    }
}

/// What combining a cell's views takes besides the views ([`cell_dov`], [`part_dov`]).
pub struct CellContext<'a> {
    /// The neighbouring cells' corners and finds, for [`FloorTest::NeighbourCorners`].
    pub around: &'a [&'a PointDov],
    pub object_bounds: &'a [Aabb],
    /// The objects whose boxes may meet the cell's, grown by the widest
    /// [`FloorTest::BoxWithin`] margin (any superset; empty without that test), so that the
    /// floors test those and the neighbours of what is seen instead of every object. `None`:
    /// every object is tested.
    pub near: Option<&'a [u32]>,
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
    let mut dov = combine(&[&view], part, c);
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
/// [`FloorTest::NeighbourCorners`]. Pure; O(Σ visible objects per point × tree depth + objects).
pub fn cell_dov(
    points: &[&PointDov],
    around: &[&PointDov],
    cell_box: &Aabb,
    object_bounds: &[Aabb],
    shape: &TreeShape,
    options: &PrecomputeOptions,
    cube: &CubeMap,
) -> CellDov {
    combine(points, cell_box, &CellContext { around, object_bounds, near: None, shape, options, cube })
}

/// [`cell_dov`] in `c`: with [`CellContext::near`], the floors cost O(near + the neighbouring
/// parts of what is seen) instead of O(objects), with the same result.
fn combine(points: &[&PointDov], cell_box: &Aabb, c: &CellContext) -> CellDov {
    let CellContext { around, object_bounds, shape, options, cube, .. } = *c;
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
            part_planes: &shape.part_planes,
        };
        // Every object a test can find: near the cell's box, seen nearby, or a neighbouring part
        // of what is seen (part neighbours list each other, [`TreeShape::check`]).
        let tested: Box<dyn Iterator<Item = u32>> = match c.near {
            None => Box::new(0..object_bounds.len() as u32),
            Some(near) => {
                let parts = |seen: &HashSet<u32>| -> Vec<u32> {
                    seen.iter().filter_map(|&o| shape.part_neighbours.get(o as usize)).flatten().copied().collect()
                };
                let mut tested: Vec<u32> = near.to_vec();
                tested.extend(&seen_around);
                tested.extend(parts(&seen_here));
                tested.extend(parts(&seen_around));
                Box::new(tested.into_iter())
            }
        };
        for object in tested {
            if object_max.contains_key(&object) {
                continue;
            }
            let bounds = &object_bounds[object as usize];
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

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The floors from the objects near each cell and the neighbouring parts of what it sees
        /// are the floors from every object: the same [`CellDov`], for the whole lattice cell and
        /// for a part of it, whatever the boxes (empty, outside the grid, spanning it), the
        /// margins and the tests.
        #[test]
        fn floors_from_the_objects_near_a_cell_are_the_floors_from_all(
            dims in proptest::array::uniform3(1u32..10),
            boxes in proptest::collection::vec((proptest::array::uniform3(-0.3f32..1.3), proptest::array::uniform3(-0.05f32..0.6)), 1..40),
            seen in proptest::collection::vec(any::<u16>(), 0..12),
            around in proptest::collection::vec(any::<u16>(), 0..12),
            pairs in proptest::collection::vec((any::<u16>(), any::<u16>()), 0..30),
            planes in proptest::collection::vec((proptest::array::uniform3(-1.0f32..1.0), -20.0f32..20.0), 0..40),
            margin in 0.0f32..3.0,
            tests in 1u8..16,
        ) {
            let region = Aabb::new(Vec3::new(-5.0, 0.0, 2.0), Vec3::new(15.0, 6.0, 12.0));
            let grid = ViewGrid::new(region, dims);
            let n = boxes.len();
            // Boxes relative to the region; a negative extent makes an empty box.
            let object_bounds: Vec<Aabb> = boxes
                .iter()
                .map(|&(at, extent)| {
                    let min = region.min + Vec3::from(at) * region.extent();
                    Aabb::new(min, min + Vec3::from(extent) * region.extent())
                })
                .collect();
            let mut part_neighbours = vec![Vec::new(); n];
            for &(a, b) in &pairs {
                let (a, b) = (u32::from(a) % n as u32, u32::from(b) % n as u32);
                if a != b && !part_neighbours[a as usize].contains(&b) {
                    part_neighbours[a as usize].push(b);
                    part_neighbours[b as usize].push(a);
                }
            }
            // One face plane for the first objects (some turned away from a cell), none for the rest.
            let part_planes = (0..n)
                .map(|k| planes.get(k).map(|&(normal, offset)| Vec3::from(normal).normalize_or_zero().extend(offset)).into_iter().collect())
                .collect();
            let shape = TreeShape { object_leaf: vec![0; n], node_parent: vec![None], part_neighbours, part_planes };
            shape.check(n).unwrap();
            let chosen = [FloorTest::BoxWithin(0.0), FloorTest::BoxWithin(margin), FloorTest::NeighbourCorners, FloorTest::PartNeighbours];
            let options = PrecomputeOptions {
                zero_dov_tests: chosen.into_iter().enumerate().filter(|(k, _)| tests & (1 << k) != 0).map(|(_, t)| t).collect(),
                ..Default::default()
            };
            let view = |ids: &[u16]| {
                let mut objects: Vec<(u32, f64)> = ids.iter().map(|&o| (u32::from(o) % n as u32, 0.01)).collect();
                objects.sort_unstable_by_key(|e| e.0);
                objects.dedup_by_key(|e| e.0);
                PointDov { resolution: 64, objects, back_face: 0.0, empty: 0.0 }
            };
            let (here, nearby) = (view(&seen), view(&around));
            let around_views = [&nearby];
            let cube = CubeMap::new(64);
            let near_boxes = NearBoxes::new(&grid, &object_bounds, &options, 0..grid.lattice_count());
            for id in 0..grid.lattice_count() {
                let cell_box = grid.cell_box(grid.cell_coords(id));
                let near = near_boxes.near(id);
                let context = |near| CellContext { around: &around_views, object_bounds: &object_bounds, near, shape: &shape, options: &options, cube: &cube };
                let part = Aabb::new(cell_box.min + 0.25 * cell_box.extent(), cell_box.max);
                for b in [cell_box, part] {
                    prop_assert_eq!(combine(&[&here], &b, &context(Some(&near))), combine(&[&here], &b, &context(None)));
                }
            }
        }
    }

    #[test]
    fn a_shape_with_planes_for_some_objects_only_is_refused() {
        let shape = |planes: usize| TreeShape {
            object_leaf: vec![0; 3],
            node_parent: vec![None],
            part_planes: vec![Vec::new(); planes],
            ..Default::default()
        };
        assert!(shape(0).check(3).is_ok());
        assert!(shape(3).check(3).is_ok());
        assert!(shape(2).check(3).is_err());
    }

    #[test]
    fn an_object_over_most_of_a_large_lattice_is_near_every_cell() {
        let grid = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(40.0, 4.0, 40.0)), [40, 4, 40]);
        let bounds = [grid.region, Aabb::new(Vec3::splat(0.5), Vec3::splat(0.6))];
        let near = NearBoxes::new(&grid, &bounds, &PrecomputeOptions::default(), 0..grid.lattice_count());
        assert_eq!(near.wide, vec![0]);
        assert_eq!(near.near(0), vec![1, 0]);
        assert_eq!(near.near(grid.lattice_count() - 1), vec![0]);
        let none = PrecomputeOptions { zero_dov_tests: vec![FloorTest::PartNeighbours], ..Default::default() };
        assert!(NearBoxes::new(&grid, &bounds, &none, 0..grid.lattice_count()).near(0).is_empty());
    }
}
