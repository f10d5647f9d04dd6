//! Audits of the DoV measurement, for tests and experiment tools: per-object differences of two
//! measurements ([`DovDiff`], the backends' agreement tolerance), the dense from-region reference
//! ([`dense_cells`]), and how well sparse sampling and floor tests match it
//! ([`audit_zero_dov`]). They measure the library; the library does not need them.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};

use glam::Vec3;
use hdov::Result;
use hdov::dov::precompute::{CellDov, FloorContext, FloorTest, PrecomputeOptions, TreeShape, cell_dov};
use hdov::dov::sampling::{halton_point, interior_points, is_inside};
use hdov::dov::{DovBackend, PointDov};
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;

/// Per-object differences between two measurements of the same points (two backends, or one
/// backend with and without an approximation), for tests and experiment tools.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DovDiff {
    /// Objects compared: seen by either measurement.
    pub objects: usize,
    pub max_abs: f64,
    pub sum_abs: f64,
    /// Largest |Δ| / max(a, b).
    pub max_rel: f64,
    pub sum_rel: f64,
    /// Objects seen by one measurement only.
    pub flips: usize,
    /// Objects whose difference exceeds the backend-agreement tolerance: 0.5 % of the DoV plus
    /// two centre texels.
    pub over_tolerance: usize,
}

impl DovDiff {
    /// Adds one object's two values; `texel` is the centre-texel weight (`CubeMap::texel_floor`).
    /// Objects that neither measurement sees are not counted.
    pub fn add(&mut self, a: f64, b: f64, texel: f64) {
        if a == 0.0 && b == 0.0 {
            return;
        }
        let delta = (a - b).abs();
        self.objects += 1;
        self.max_abs = self.max_abs.max(delta);
        self.sum_abs += delta;
        self.max_rel = self.max_rel.max(delta / a.max(b));
        self.sum_rel += delta / a.max(b);
        self.flips += usize::from((a == 0.0) != (b == 0.0));
        self.over_tolerance += usize::from(delta > 0.005 * a.max(b) + 2.0 * texel);
    }

    /// Adds every object either point measurement sees.
    pub fn add_points(&mut self, a: &PointDov, b: &PointDov, texel: f64) {
        let mut ids: Vec<u32> = a.objects.iter().chain(&b.objects).map(|e| e.0).collect();
        ids.sort_unstable();
        ids.dedup();
        for id in ids {
            self.add(a.get(id), b.get(id), texel);
        }
    }

    pub fn mean_abs(&self) -> f64 {
        self.sum_abs / self.objects.max(1) as f64
    }

    pub fn mean_rel(&self) -> f64 {
        self.sum_rel / self.objects.max(1) as f64
    }
}

/// Where the reference points of [`dense_cells`] start in the Halton sequence: far from the
/// points 1, 2, … that the samplers take, so no sampler point is also a reference point.
pub const DENSE_HALTON_START: u32 = 1001;

/// The reference from-region DoV of each cell in `cells`: the max over its 8 corners and `dense`
/// Halton points ([`DENSE_HALTON_START`] on), without floors, points inside geometry left out as
/// in [`hdov::dov::precompute::precompute_shard`]. Node entries use `shape`. Costs one measurement per distinct corner
/// plus `dense` per cell.
pub fn dense_cells(
    backend: &mut dyn DovBackend,
    grid: &ViewGrid,
    object_bounds: &[Aabb],
    shape: &TreeShape,
    cells: impl IntoIterator<Item = usize>,
    dense: u32,
) -> Result<Vec<CellDov>> {
    let cube = backend.cube_map().clone();
    let options = PrecomputeOptions { zero_dov_tests: vec![], ..Default::default() };
    let mut corners: HashMap<usize, PointDov> = HashMap::new();
    let mut out = Vec::new();
    for id in cells {
        // Where the cell's viewers stand: its corners on their side, points among its places.
        let cell = grid.view_cell(id);
        let own = grid.view_corners(id);
        for &c in &own {
            if let Entry::Vacant(slot) = corners.entry(c) {
                slot.insert(backend.measure(grid.corner_position(grid.corner_coords(c)))?);
            }
        }
        let interior: Vec<PointDov> = (DENSE_HALTON_START..DENSE_HALTON_START + dense)
            .map(|k| backend.measure(halton_point(&cell, k)))
            .collect::<Result<_>>()?;
        let points: Vec<&PointDov> = own.iter().map(|c| &corners[c]).chain(&interior).collect();
        out.push(cell_dov(&points, &[], &cell.bounds, object_bounds, shape, &options, &cube));
    }
    Ok(out)
}

/// How well sparse sampling and a floor test match dense sampling, over some cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZeroDovAudit {
    /// Interior points used besides the corners (the first K of the dense Halton points).
    pub interior_samples: u32,
    /// The floor test evaluated.
    pub test: FloorTest,
    pub cells: usize,
    /// (cell, object) pairs seen by some sparse sample point (corners + K interior).
    pub sparse_visible: usize,
    /// Pairs seen by some dense interior point but by no sparse point: the visible zero-DoV
    /// objects.
    pub zero_dov: usize,
    /// Of those, how many the floor test catches.
    pub caught: usize,
    /// Pairs the floor test adds that no dense point sees either (harmless over-fetching).
    pub false_floors: usize,
}

/// Measures, for each cell in `cells`, which objects `dense` Halton interior points see that the
/// sparse sample points (corners + the first K Halton points, for each K in `interior_samples`)
/// do not, and how many of those each floor test in `tests` catches: one [`ZeroDovAudit`] per
/// (K, test), K-major. Points inside geometry (more than half back faces) are left out, as
/// [`hdov::dov::precompute::precompute_shard`] does by default. Costs one measurement per distinct corner of the cells'
/// neighbourhoods plus `dense` per cell.
pub fn audit_zero_dov(
    backend: &mut dyn DovBackend,
    grid: &ViewGrid,
    object_bounds: &[Aabb],
    cells: impl IntoIterator<Item = usize>,
    dense: u32,
    interior_samples: &[u32],
    tests: &[FloorTest],
) -> Result<Vec<ZeroDovAudit>> {
    let mut audits: Vec<ZeroDovAudit> = interior_samples
        .iter()
        .flat_map(|&k| tests.iter().map(move |&test| (k, test)))
        .map(|(interior_samples, test)| ZeroDovAudit {
            interior_samples,
            test,
            cells: 0,
            sparse_visible: 0,
            zero_dov: 0,
            caught: 0,
            false_floors: 0,
        })
        .collect();
    let mut seen_from = |p: Vec3| -> Result<HashSet<u32>> {
        let d = backend.measure(p)?;
        Ok(if is_inside(&d) { HashSet::new() } else { d.objects.iter().map(|e| e.0).collect() })
    };
    let mut corner_seen: HashMap<usize, HashSet<u32>> = HashMap::new();
    for id in cells {
        let coords = grid.cell_coords(id);
        let cell_box = grid.cell_box(coords);
        let hood = grid.neighbourhood_corners(coords, 1);
        for &c in &hood {
            if let Entry::Vacant(slot) = corner_seen.entry(c) {
                slot.insert(seen_from(grid.corner_position(grid.corner_coords(c)))?);
            }
        }
        let own = grid.view_corners(id);
        let by_corner: HashSet<u32> = own.iter().flat_map(|c| &corner_seen[c]).copied().collect();
        let around: HashSet<u32> = hood.iter().flat_map(|c| &corner_seen[c]).copied().collect();
        let interior: Vec<HashSet<u32>> =
            interior_points(&grid.view_cell(id), dense).into_iter().map(&mut seen_from).collect::<Result<_>>()?;
        let by_dense: HashSet<u32> = interior.iter().flatten().chain(&by_corner).copied().collect();
        for audit in &mut audits {
            let k = (audit.interior_samples as usize).min(interior.len());
            let sparse: HashSet<u32> = interior[..k].iter().flatten().chain(&by_corner).copied().collect();
            audit.cells += 1;
            audit.sparse_visible += sparse.len();
            for (object, bounds) in object_bounds.iter().enumerate() {
                let object = object as u32;
                if sparse.contains(&object) {
                    continue;
                }
                let cell = FloorContext {
                    cell_box: &cell_box,
                    seen_nearby: &around,
                    seen_here: &sparse,
                    part_neighbours: &[],
                    part_planes: &[],
                };
                let floored = audit.test.finds(object, bounds, &cell);
                let seen = by_dense.contains(&object);
                audit.zero_dov += seen as usize;
                audit.caught += (seen && floored) as usize;
                audit.false_floors += (floored && !seen) as usize;
            }
        }
    }
    Ok(audits)
}
