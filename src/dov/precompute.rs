//! From-region DoV for every cell of a view grid (thesis §5.2, §5.5; docs/dov.md, "From-region DoV").
//!
//! Per cell, the sample points are its 8 corners (shared with the neighbouring cells and measured
//! once each) plus, optionally, K interior points. Then:
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

use glam::Vec3;

use super::adaptive::{AdaptiveSampling, sample_cell};
use super::probe::{Leads, RayProbing, probe_cell, region_finds};
use super::sampling::{RegionSequence, interior_points, is_inside, seen_by};
use super::{CubeMap, DovBackend, PointDov};
use crate::error::{Error, Param, Result};
pub use crate::format::params::{FloorTest, Shard};
use crate::format::params::VisibilityParams;
use crate::geom::Aabb;
use crate::grid::ViewGrid;
use crate::progress::Report;

/// The shape of the object tree, as far as DoV aggregation needs it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeShape {
    /// Leaf node id of each object.
    pub object_leaf: Vec<u32>,
    /// Parent of each node id (`None` for the root).
    pub node_parent: Vec<Option<u32>>,
}

impl TreeShape {
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

impl FloorTest {
    /// Whether this test finds `object` (with world box `bounds`) possibly visible from the cell
    /// `cell_box`; `seen_nearby` holds the objects that the neighbouring cells' corners see.
    pub fn finds(&self, object: u32, bounds: &Aabb, cell_box: &Aabb, seen_nearby: &HashSet<u32>) -> bool {
        match *self {
            FloorTest::BoxWithin(margin) => {
                let m = Vec3::splat(margin);
                !bounds.is_empty() && bounds.intersects(&Aabb::new(cell_box.min - m, cell_box.max + m))
            }
            FloorTest::NeighbourCorners => seen_nearby.contains(&object),
        }
    }
}

/// Options of a precomputation.
#[derive(Clone, Debug, PartialEq)]
pub struct PrecomputeOptions {
    /// Interior sample points per cell besides the 8 corners (Halton points in bases 2, 3, 5:
    /// well spread, the same relative positions in every cell). 0 = corners only (the thesis).
    pub interior_samples: u32,
    /// After the corners and the fixed interior points, measure more points where new objects
    /// appear ([`super::adaptive`]). `None`: no adaptive points.
    pub adaptive: Option<AdaptiveSampling>,
    /// After all measured points, aim rays at the objects the cell might see and no point saw
    /// ([`super::probe`]; needs a backend with [`DovBackend::ray_caster`]). `None`: no probing.
    pub probe: Option<RayProbing>,
    /// Objects that no sample point sees but any of these tests finds possibly visible get the
    /// one-texel floor. Empty: no floor.
    pub zero_dov_tests: Vec<FloorTest>,
    /// Leave out sample points whose view is mostly back faces (more than half the sphere): they
    /// lie inside a closed mesh and would give its walls a DoV near 1. When all points of a cell
    /// are inside, they are all kept.
    pub skip_inside_points: bool,
}

/// The corners alone, with both floors: the thesis's sampling (a build's default sampler is
/// [`crate::format::params::Sampling::default`]: [`PrecomputeOptions::of`]).
impl Default for PrecomputeOptions {
    fn default() -> Self {
        Self {
            interior_samples: 0,
            adaptive: None,
            probe: None,
            zero_dov_tests: vec![FloorTest::BoxWithin(0.0), FloorTest::NeighbourCorners],
            skip_inside_points: true,
        }
    }
}

impl PrecomputeOptions {
    /// What a build with `v` measures.
    pub fn of(v: &VisibilityParams) -> Self {
        PrecomputeOptions {
            interior_samples: v.sampling.interior_samples(),
            adaptive: v.sampling.adaptive(),
            probe: v.sampling.probe(),
            zero_dov_tests: v.zero_dov_floor.clone(),
            ..Default::default()
        }
    }

    fn uses_neighbours(&self) -> bool {
        self.zero_dov_tests.contains(&FloorTest::NeighbourCorners)
    }
}

/// The corner ids of the cells within `ring` cells of cell `c` (ring 1: the 4 × 4 × 4 block of
/// its own 8 corners and those of its 26 neighbours; ring 0: its own 8), clipped to the grid.
pub fn neighbourhood_corners(grid: &ViewGrid, c: [u32; 3], ring: u32) -> Vec<usize> {
    block(|a| c[a].saturating_sub(ring)..=(c[a] + 1 + ring).min(grid.dims[a]), |p| grid.corner_id(p))
}

/// The ids `id` gives the lattice points of the box whose range along each axis is `range(axis)`,
/// x fastest, then z, then y.
fn block(range: impl Fn(usize) -> std::ops::RangeInclusive<u32>, id: impl Fn([u32; 3]) -> usize) -> Vec<usize> {
    let mut out = Vec::new();
    for y in range(1) {
        for z in range(2) {
            for x in range(0) {
                out.push(id([x, y, z]));
            }
        }
    }
    out
}

/// How many rings of neighbouring cells' region finds are a cell's probe candidates.
pub const REGION_RING: u32 = 8;

/// The ids of the cells within `ring` cells of cell `c` (itself included), clipped to the grid.
pub fn neighbourhood_cells(grid: &ViewGrid, c: [u32; 3], ring: u32) -> Vec<usize> {
    block(|a| c[a].saturating_sub(ring)..=(c[a] + ring).min(grid.dims[a] - 1), |p| grid.cell_id(p))
}

/// How many rings of neighbouring cells' corners give [`PrecomputeOptions::probe`] its candidates:
/// on the audit scene two rings left 33 % fewer pairs unfound than one, three rings 16 % fewer
/// again at 30 % more rays (docs/dov.md, "Ray probing").
pub const PROBE_CANDIDATE_RING: u32 = 2;

/// The output of one shard.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShardDov {
    /// `(cell id, visibility)` for every cell of the shard, ascending id.
    pub cells: Vec<(u32, CellDov)>,
    /// Point measurements done (distinct corners + interior points of the shard).
    pub points_measured: usize,
    /// Cube-map resolution of the measurements.
    pub resolution: u32,
    /// Rays cast by [`PrecomputeOptions::probe`] towards targets, and to measure footprints.
    pub probe_rays: u64,
    pub footprint_rays: u64,
}

/// Computes the [`CellDov`] of every cell of `shard`.
///
/// Every corner that a shard cell uses — its own 8, plus its neighbours' with
/// [`FloorTest::NeighbourCorners`] — is measured exactly once and kept until the last cell that
/// uses it is done (memory: about two layers of corners, four with the neighbour test); interior
/// points are measured once per cell. `progress` is set to `(points done, points total)`
/// after each measurement (with [`PrecomputeOptions::adaptive`] the total grows as cells take
/// more than their seeds). Costs (distinct corners + K·cells + adaptive points) backend
/// measurements plus, per cell,
/// O(visible objects × tree depth × points + objects) for the floor tests.
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
    let cells = shard.cells(grid);
    // The adaptive sampler and the probes take their candidates from the neighbours' corners too;
    // the probes from two rings of them.
    let ring = if options.probe.is_some() {
        PROBE_CANDIDATE_RING
    } else {
        u32::from(options.uses_neighbours() || options.adaptive.is_some())
    };
    if let Some(p) = options.probe
        && backend.ray_caster().is_none()
    {
        return Err(Error::bad_param(
            Param::Samples,
            format!("{p} casts single rays: the {} backend has none (use the cpu backend)", backend.name()),
        ));
    }
    let corners_of = |coords: [u32; 3]| neighbourhood_corners(grid, coords, ring);
    // How many shard cells still need each corner: drop a corner's DoV after its last cell.
    let mut corner_uses: HashMap<usize, u32> = HashMap::new();
    for id in cells.clone() {
        for c in corners_of(grid.cell_coords(id)) {
            *corner_uses.entry(c).or_insert(0) += 1;
        }
    }
    // The adaptive sampler's count is known only when it stops: plan with its seeds.
    let per_cell = options.interior_samples + options.adaptive.map_or(0, |a| a.seeds);
    let mut total = corner_uses.len() + cells.len() * per_cell as usize;
    let mut done = 0;
    let mut corner_dov: HashMap<usize, PointDov> = HashMap::new();
    let cube = backend.cube_map().clone();
    let mut out = ShardDov {
        cells: Vec::with_capacity(cells.len()),
        points_measured: 0,
        resolution: cube.resolution(),
        probe_rays: 0,
        footprint_rays: 0,
    };
    // Region rays, for the shard's cells and their neighbours: what a cell's rays meet it sees,
    // and its neighbours probe for (an object seen from part of a cell is the likeliest to be
    // seen from part of the next, where that cell's own rays may have missed it).
    let mut region: HashMap<usize, Vec<(u32, Vec3)>> = HashMap::new();
    if let (Some(probing), Some(caster)) = (options.probe.filter(|p| p.region > 0), backend.ray_caster()) {
        let mut ids: Vec<usize> = cells.clone().flat_map(|id| neighbourhood_cells(grid, grid.cell_coords(id), REGION_RING)).collect();
        ids.sort_unstable();
        ids.dedup();
        let sequence = RegionSequence::new(probing.region);
        for id in ids {
            region.insert(id, region_finds(caster, &grid.cell_box(grid.cell_coords(id)), &sequence));
            out.probe_rays += u64::from(probing.region);
        }
    }
    for id in cells {
        let coords = grid.cell_coords(id);
        let cell_box = grid.cell_box(coords);
        let needed = corners_of(coords);
        for &corner in &needed {
            if let Entry::Vacant(slot) = corner_dov.entry(corner) {
                slot.insert(backend.measure(grid.corner_position(grid.corner_coords(corner)))?);
                done += 1;
                progress.set(done as u64, total as u64);
            }
        }
        let mut interior = Vec::with_capacity(options.interior_samples as usize);
        for p in interior_points(&cell_box, options.interior_samples) {
            interior.push(backend.measure(p)?);
            done += 1;
            progress.set(done as u64, total as u64);
        }
        let own = grid.cell_corners(coords);
        if let Some(sampling) = &options.adaptive {
            let known: Vec<&PointDov> = own.iter().map(|c| &corner_dov[c]).chain(&interior).collect();
            let candidates = seen_by(needed.iter().filter(|c| !own.contains(c)).map(|c| &corner_dov[c]));
            let planned = sampling.seeds as usize;
            let mut taken = 0;
            let extra = sample_cell(backend, &cell_box, &known, &candidates, sampling, &mut || {
                done += 1;
                taken += 1;
                total += usize::from(taken > planned);
                progress.set(done as u64, total as u64);
            })?;
            interior.extend(extra);
        }
        if let (Some(probing), Some(caster)) = (&options.probe, backend.ray_caster()) {
            let seen = seen_by(own.iter().map(|c| &corner_dov[c]).chain(&interior));
            let mut candidates = seen_by(needed.iter().filter(|c| !own.contains(c)).map(|c| &corner_dov[c]));
            candidates
                .extend((0..object_bounds.len() as u32).filter(|&o| object_bounds[o as usize].intersects(&cell_box)));
            if probing.region > 0 {
                // What the neighbours' region rays met, nearest cells first, as many as probing
                // them would cost the cell's own region rays at most.
                let cap = (probing.region / (probing.points * probing.rays).max(1)) as usize;
                let mut ring_of: Vec<(u32, u32)> = neighbourhood_cells(grid, coords, REGION_RING)
                    .into_iter()
                    .filter(|&n| n != id)
                    .flat_map(|n| {
                        let c = grid.cell_coords(n);
                        let ring = (0..3).map(|a| c[a].abs_diff(coords[a])).max().unwrap_or(0);
                        region.get(&n).into_iter().flatten().map(move |f| (ring, f.0))
                    })
                    .filter(|&(_, o)| !seen.contains(&o) && !candidates.contains(&o))
                    .collect();
                ring_of.sort_unstable();
                let mut taken = HashSet::new();
                for (_, o) in ring_of {
                    if taken.len() == cap {
                        break;
                    }
                    taken.insert(o);
                }
                candidates.extend(taken);
            }
            // probe_cell skips the seen ones.
            let mut candidates: Vec<u32> = candidates.into_iter().collect();
            candidates.sort_unstable();
            let own = region.get(&id).map_or(&[][..], Vec::as_slice);
            let leads = Leads { seen: &seen, candidates: &candidates, region: own };
            let probe = probe_cell(caster, &cube, &cell_box, &leads, object_bounds, probing);
            out.probe_rays += probe.rays;
            out.footprint_rays += probe.footprint_rays;
            interior.extend(probe.points);
        }
        let points: Vec<&PointDov> = own.iter().map(|c| &corner_dov[c]).chain(&interior).collect();
        // What the neighbouring cells' region rays met counts as seen nearby, as their corners'
        // views do (the neighbours floor).
        let region_around: Vec<PointDov> = neighbourhood_cells(grid, coords, 1)
            .into_iter()
            .filter(|&n| n != id)
            .filter_map(|n| region.get(&n))
            .map(|finds| PointDov {
                resolution: cube.resolution(),
                objects: finds.iter().map(|f| (f.0, 0.0)).collect(),
                back_face: 0.0,
                empty: 0.0,
            })
            .collect();
        let around: Vec<&PointDov> = if ring > 0 {
            neighbourhood_corners(grid, coords, 1)
                .into_iter()
                .filter(|c| !own.contains(c))
                .map(|c| &corner_dov[&c])
                .chain(&region_around)
                .collect()
        } else {
            Vec::new()
        };
        out.cells.push((id as u32, cell_dov(&points, &around, &cell_box, object_bounds, shape, options, &cube)));
        for corner in needed {
            let uses = corner_uses.get_mut(&corner).expect("every needed corner is counted");
            *uses -= 1;
            if *uses == 0 {
                corner_dov.remove(&corner);
            }
        }
    }
    out.points_measured = done;
    Ok(out)
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
        for (object, bounds) in object_bounds.iter().enumerate() {
            let object = object as u32;
            if object_max.contains_key(&object) {
                continue;
            }
            let possibly_visible =
                options.zero_dov_tests.iter().any(|t| t.finds(object, bounds, cell_box, &seen_around));
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
