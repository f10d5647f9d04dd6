//! The viewing-cell grid: a box region cut into nx × ny × nz cells (y is height), every one of
//! them a view cell, or only those of a [`CellSet`] (the places a viewer can stand, found from
//! the geometry by `scene::standable`): the lattice then only numbers the cells. Such a lattice
//! cell is several view cells, its quarters, each cut at walls ([`ViewGrid::parts`],
//! [`quarter_parts`]): the first keeps the lattice id, the others are numbered after the
//! lattice.
//!
//! Sample points are the cell corners, shared between neighbouring cells: a grid of nx × ny × nz
//! cells has (nx+1)(ny+1)(nz+1) corners, each measured once.

use glam::{UVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::geom::Aabb;

/// A regular grid of viewing cells over a region: the cells whose visibility a database stores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewGrid {
    /// The box the cells tile.
    pub region: Aabb,
    /// Cells along x, y (height layers) and z.
    pub dims: [u32; 3],
    /// The cells that are view cells; `None`: all of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub present: Option<CellSet>,
    /// With `present`, per view cell in ascending id order, where in it a viewer can stand: bit
    /// `z · 8 + x` of the 8 × 8 squares of its footprint (`LINES_PER_CELL` of `scene::standable`)
    /// is set where a floor's eyes reach the cell there. `None`: anywhere in the cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub places: Option<Vec<u64>>,
    /// The further view cells of lattice cells that walls cut, by lattice cell ascending: entry
    /// `k` is view cell `lattice_count() + k`, the squares of its lattice cell's footprint on one
    /// side (the lattice cell's own id keeps the squares of [`ViewGrid::places`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<CellPart>,
}

/// A further view cell of a lattice cell that a wall cuts ([`ViewGrid::parts`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellPart {
    /// The lattice cell's id.
    pub cell: u32,
    /// Its squares, as [`ViewGrid::places`].
    pub places: u64,
}

/// Every square of a footprint: a view cell where a viewer may be anywhere.
pub const ALL_PLACES: u64 = u64::MAX;

/// One view cell as its samplers see it: the box of its lattice cell and the squares of the
/// footprint where viewers stand (bit `z · 8 + x`, [`ALL_PLACES`] for anywhere).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCell {
    pub bounds: Aabb,
    pub places: u64,
}

impl ViewCell {
    /// A view cell where a viewer may be anywhere in `bounds`.
    pub fn whole(bounds: Aabb) -> Self {
        ViewCell { bounds, places: ALL_PLACES }
    }

    /// The point of the cell at `u` ∈ [0, 1)³: the box's own point for a whole cell; otherwise
    /// `u.x` picks a square (the squares in bit order, each an equal share) and places the
    /// point within it with what is left of `u.x` and with `u.z`, `u.y` the height. Evenly
    /// spread points of the cube stay evenly spread over the squares.
    pub fn point(&self, u: Vec3) -> Vec3 {
        if self.places == ALL_PLACES || self.places == 0 {
            return self.bounds.min + u * self.bounds.extent();
        }
        let n = self.places.count_ones();
        let t = u.x.clamp(0.0, 1.0) * n as f32;
        let k = (t.floor() as u32).min(n - 1);
        let mut left = self.places;
        for _ in 0..k {
            left &= left - 1;
        }
        let bit = left.trailing_zeros();
        let edge = PLACES_PER_EDGE as f32;
        let (sx, sz) = ((bit % PLACES_PER_EDGE) as f32, (bit / PLACES_PER_EDGE) as f32);
        let rel = Vec3::new((sx + (t - k as f32).clamp(0.0, 1.0)) / edge, u.y, (sz + u.z) / edge);
        self.bounds.min + rel * self.bounds.extent()
    }

    /// The box of the squares where viewers stand (the whole box for a whole cell), full height.
    pub fn places_box(&self) -> Aabb {
        if self.places == ALL_PLACES || self.places == 0 {
            return self.bounds;
        }
        let (mut lo, mut hi) = ([PLACES_PER_EDGE; 2], [0u32; 2]);
        let mut left = self.places;
        while left != 0 {
            let bit = left.trailing_zeros();
            left &= left - 1;
            let (x, z) = (bit % PLACES_PER_EDGE, bit / PLACES_PER_EDGE);
            (lo[0], lo[1], hi[0], hi[1]) = (lo[0].min(x), lo[1].min(z), hi[0].max(x + 1), hi[1].max(z + 1));
        }
        let (b, e, edge) = (self.bounds, self.bounds.extent(), PLACES_PER_EDGE as f32);
        Aabb::new(
            Vec3::new(b.min.x + e.x * lo[0] as f32 / edge, b.min.y, b.min.z + e.z * lo[1] as f32 / edge),
            Vec3::new(b.min.x + e.x * hi[0] as f32 / edge, b.max.y, b.min.z + e.z * hi[1] as f32 / edge),
        )
    }

    /// The square of the footprint holding `p` (clamped to the footprint): its bit.
    pub fn square_of(&self, p: Vec3) -> u32 {
        let b = self.bounds;
        let square = |a: usize| {
            let f = ((p[a] - b.min[a]) / b.extent()[a] * PLACES_PER_EDGE as f32).floor();
            if f.is_finite() { (f.max(0.0) as u32).min(PLACES_PER_EDGE - 1) } else { 0 }
        };
        square(2) * PLACES_PER_EDGE + square(0)
    }
}

/// Squares per cell edge of [`ViewGrid::places`].
pub const PLACES_PER_EDGE: u32 = 8;

/// A set of cell ids, as sorted runs `[first, end)`: the view cells of a sparse grid (a storey
/// is a few runs per row of cells).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct CellSet {
    runs: Vec<[u32; 2]>,
}

impl CellSet {
    /// The set of `ids`, in any order, repeats allowed.
    pub fn from_ids(mut ids: Vec<u32>) -> CellSet {
        ids.sort_unstable();
        ids.dedup();
        let mut runs: Vec<[u32; 2]> = Vec::new();
        for id in ids {
            match runs.last_mut() {
                Some(run) if run[1] == id => run[1] += 1,
                _ => runs.push([id, id + 1]),
            }
        }
        CellSet { runs }
    }

    /// The set as sorted runs `[first, end)`.
    pub fn runs(&self) -> &[[u32; 2]] {
        &self.runs
    }

    /// Whether `id` is in the set.
    pub fn contains(&self, id: usize) -> bool {
        let i = self.runs.partition_point(|r| (r[1] as usize) <= id);
        self.runs.get(i).is_some_and(|r| r[0] as usize <= id)
    }

    /// The ids, ascending.
    pub fn ids(&self) -> impl Iterator<Item = usize> + '_ {
        self.runs.iter().flat_map(|r| r[0] as usize..r[1] as usize)
    }

    /// How many ids of the set are below `id`: `id`'s place among them when it is one.
    pub fn rank(&self, id: usize) -> usize {
        let i = self.runs.partition_point(|r| (r[1] as usize) <= id);
        let before: usize = self.runs[..i].iter().map(|r| (r[1] - r[0]) as usize).sum();
        before + self.runs.get(i).map_or(0, |r| id.saturating_sub(r[0] as usize))
    }

    /// How many ids.
    pub fn len(&self) -> usize {
        self.runs.iter().map(|r| (r[1] - r[0]) as usize).sum()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.runs.is_empty()
    }

    /// Checks that the runs are ascending, apart, non-empty and below `end`.
    pub fn check(&self, end: usize) -> Result<(), String> {
        let mut last = None;
        for r in &self.runs {
            if r[0] >= r[1] || last.is_some_and(|l| r[0] <= l) || r[1] as usize > end {
                return Err(format!("cell run {r:?} is empty, out of order, touches the one before or ends past {end}"));
            }
            last = Some(r[1]);
        }
        Ok(())
    }
}

/// The parts of a mask of places ([`ViewGrid::places`]) that 4-neighbouring squares join, by
/// their lowest square: the sides of a wall through a cell.
pub fn place_parts(mask: u64) -> Vec<u64> {
    let (mut left, mut parts) = (mask, Vec::new());
    while left != 0 {
        let mut part = left & left.wrapping_neg();
        loop {
            let grown = step_x(part) | (part << 8) | (part >> 8);
            let grown = grown & mask;
            if grown == part {
                break;
            }
            part = grown;
        }
        left &= !part;
        parts.push(part);
    }
    parts
}

/// Squares one step along x from `mask`'s, and its own (not across a row's end).
fn step_x(mask: u64) -> u64 {
    mask | ((mask << 1) & !0x0101_0101_0101_0101) | ((mask >> 1) & !0x8080_8080_8080_8080)
}

/// The squares of `within` (a lattice cell's places, [`ViewGrid::lattice_places`]) that are
/// `places` (one of its view cells) or touch one of them, edge or corner, on their side of any
/// wall (in the part of `within` that 4-neighbouring squares join, [`place_parts`]). A viewer
/// on a view cell's border, where a query takes the view cell whose square holds the point,
/// sees what is seen from just across it.
pub fn places_around(places: u64, within: u64) -> u64 {
    let row = step_x(places);
    let grown = row | (row << 8) | (row >> 8);
    let side = place_parts(within).into_iter().filter(|p| p & places != 0).fold(0, |m, p| m | p);
    (grown & side) | places
}

/// The four quarters of a footprint's squares (4 × 4 squares each), as masks of places.
pub const QUARTERS: [u64; 4] = [0x0f0f_0f0f, 0xf0f0_f0f0, 0x0f0f_0f0f << 32, 0xf0f0_f0f0 << 32];

/// A mask of places cut into quarters ([`QUARTERS`]): each quarter's squares that 4-neighbouring
/// squares join ([`place_parts`]), quarter by quarter.
pub fn quarter_parts(mask: u64) -> Vec<u64> {
    QUARTERS.iter().flat_map(|q| place_parts(mask & q)).collect()
}

/// The ids `id` gives the lattice points of the box whose range along each axis is
/// `range(axis)`, x fastest, then z, then y.
fn lattice_block(range: impl Fn(usize) -> std::ops::RangeInclusive<u32>, id: impl Fn([u32; 3]) -> usize) -> Vec<usize> {
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

impl ViewGrid {
    /// Most cells a grid may have (the thesis's city had about 4,000): every cell id fits a
    /// u32 with room to spare, and a mistyped grid is refused instead of allocated.
    pub const MAX_CELLS: u64 = 1 << 22;

    /// A grid of `dims` cells (x, y, z) over `region`, every cell a view cell.
    pub fn new(region: Aabb, dims: [u32; 3]) -> Self {
        Self { region, dims, present: None, places: None, parts: Vec::new() }
    }

    /// The grid a build uses. Region: `region`, else the scene's own grid's, else the footprint
    /// of `bounds` at eye height (1.5–2.0 above its lowest point). Cells: `dims`, else
    /// `cell_size` (one height layer), else the scene grid's dims, else 16 along the longer
    /// horizontal axis.
    pub fn resolve(
        bounds: Aabb,
        scene_grid: Option<ViewGrid>,
        region: Option<Aabb>,
        dims: Option<[u32; 3]>,
        cell_size: Option<f32>,
    ) -> crate::Result<ViewGrid> {
        use crate::error::{Error, Param};
        let region = region.or(scene_grid.as_ref().map(|g| g.region)).unwrap_or_else(|| {
            let y = bounds.min.y;
            Aabb::new(Vec3::new(bounds.min.x, y + 1.5, bounds.min.z), Vec3::new(bounds.max.x, y + 2.0, bounds.max.z))
        });
        let e = region.extent();
        let dims_given = dims.is_some();
        let dims = match (dims, cell_size) {
            (Some(d), _) => d,
            (None, Some(s)) if s > 0.0 && s.is_finite() => {
                let n = |x: f32| (f64::from(x) / f64::from(s)).ceil().max(1.0);
                let cells = n(e.x) * n(e.z);
                if cells > Self::MAX_CELLS as f64 {
                    let reason = format!("{s} cuts the region into {cells:.0} cells, more than {}", Self::MAX_CELLS);
                    return Err(Error::bad_param(Param::CellSize, reason));
                }
                [n(e.x) as u32, 1, n(e.z) as u32]
            }
            (None, Some(s)) => return Err(Error::bad_param(Param::CellSize, format!("{s} must be a positive length"))),
            (None, None) => match scene_grid {
                Some(g) if g.region == region => g.dims,
                _ => {
                    let s = e.x.max(e.z) / 16.0;
                    let n = |x: f32| if s > 0.0 { ((x / s).round() as u32).max(1) } else { 1 };
                    [n(e.x), 1, n(e.z)]
                }
            },
        };
        let g = ViewGrid::new(region, dims);
        g.check().map_err(|r| Error::bad_param(if dims_given { Param::Grid } else { Param::Region }, r))?;
        Ok(g)
    }

    /// Checks the region and the counts; returns the reason of the first bad one.
    pub fn check(&self) -> Result<(), String> {
        let r = self.region;
        if !(r.min.is_finite() && r.max.is_finite()) || r.min.cmpgt(r.max).any() {
            return Err(format!("grid region {:?} is not a finite box", r.to_array()));
        }
        if self.dims.contains(&0) {
            return Err(format!("grid dims {:?} must all be at least 1", self.dims));
        }
        if self.cell_count() as u64 > Self::MAX_CELLS {
            return Err(format!("grid dims {:?} make more than {} cells", self.dims, Self::MAX_CELLS));
        }
        if let Some(set) = &self.present {
            set.check(self.lattice_count())?;
            if set.is_empty() {
                return Err("the grid has no view cell".into());
            }
        }
        match (&self.places, &self.present) {
            (Some(p), Some(set)) if p.len() != set.len() => {
                Err(format!("{} places for {} view cells", p.len(), set.len()))
            }
            (Some(_), None) => Err("places to stand without view cells".into()),
            _ => self.check_parts(),
        }
    }

    /// Checks that each part is of a view cell with places, in ascending order, and shares no
    /// square with its cell or another part of it.
    fn check_parts(&self) -> Result<(), String> {
        let mut last: Option<(u32, u64)> = None;
        for p in &self.parts {
            let id = p.cell as usize;
            if self.places.is_none() || id >= self.lattice_count() || !self.is_present(id) {
                return Err(format!("a part of cell {id}, which is no view cell with places"));
            }
            let taken = self.places_of(id) | last.filter(|l| l.0 == p.cell).map_or(0, |l| l.1);
            if p.places == 0 || p.places & taken != 0 || last.is_some_and(|l| l.0 > p.cell) {
                return Err(format!("a part of cell {id} is empty, overlaps its cell's squares or is out of order"));
            }
            last = Some((p.cell, taken | p.places));
        }
        Ok(())
    }

    /// The view cell of lattice cell `id` (a view cell, `c` its coordinates) where a viewer at
    /// `p` stands: `id` itself or a further part of it ([`ViewGrid::parts`]); `None` where in
    /// the cell no viewer stands. Always `id` in a grid without [`ViewGrid::places`].
    pub fn standing_cell(&self, id: usize, c: [u32; 3], p: Vec3) -> Option<usize> {
        let (Some(places), Some(set)) = (&self.places, &self.present) else { return Some(id) };
        let bit = 1u64 << ViewCell::whole(self.cell_box(c)).square_of(p);
        if places.get(set.rank(id))? & bit != 0 {
            return Some(id);
        }
        self.parts_of_cell(id).find(|&k| self.parts[k].places & bit != 0).map(|k| self.lattice_count() + k)
    }

    /// The view cells of lattice cell `id`: itself where it is one, then its further parts.
    pub fn view_cells_of(&self, id: usize) -> impl Iterator<Item = usize> + '_ {
        let lattice = self.lattice_count();
        (id < lattice && self.is_present(id)).then_some(id).into_iter().chain(self.parts_of_cell(id).map(move |k| lattice + k))
    }

    /// The squares where viewers stand in the lattice cells beside lattice cell `c` on its layer
    /// (along x and z, edge or corner) that touch one of `places`, its own squares, across its
    /// border: per such neighbour, its id and each of those squares' bits with the bit of one
    /// of `places` it touches. Without [`ViewGrid::places`], none.
    pub fn squares_across(&self, c: [u32; 3], places: u64) -> Vec<(usize, Vec<(u32, u32)>)> {
        if self.places.is_none() {
            return Vec::new();
        }
        let edge = PLACES_PER_EDGE as i64;
        let mut out = Vec::new();
        // The lattice cells one step away along x and z on the layer, clipped to the grid.
        let range = |a: usize| match a {
            1 => c[1]..=c[1],
            _ => c[a].saturating_sub(1)..=(c[a] + 1).min(self.dims[a] - 1),
        };
        for n in lattice_block(range, |p| self.cell_id(p)) {
            let nc = self.cell_coords(n);
            if nc == c {
                continue;
            }
            let (dx, dz) = (i64::from(nc[0]) - i64::from(c[0]), i64::from(nc[2]) - i64::from(c[2]));
            let theirs = self.lattice_places(n);
            let mut pairs = Vec::new();
            let mut left = if theirs == 0 { 0 } else { places };
            while left != 0 {
                let bit = left.trailing_zeros();
                left &= left - 1;
                let (x, z) = (i64::from(bit) % edge, i64::from(bit) / edge);
                for (ox, oz) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                    // The square beside, in the neighbour's own footprint.
                    let (tx, tz) = (x + ox - dx * edge, z + oz - dz * edge);
                    if (0..edge).contains(&tx) && (0..edge).contains(&tz) {
                        let their = (tz * edge + tx) as u32;
                        if theirs >> their & 1 == 1 && !pairs.iter().any(|p: &(u32, u32)| p.0 == their) {
                            pairs.push((their, bit));
                        }
                    }
                }
            }
            if !pairs.is_empty() {
                out.push((n, pairs));
            }
        }
        out
    }

    /// The centre of square `bit` of lattice cell `c`'s footprint, half way up the cell.
    pub fn square_centre(&self, c: [u32; 3], bit: u32) -> Vec3 {
        ViewCell { bounds: self.cell_box(c), places: 1 << bit }.point(Vec3::splat(0.5))
    }

    /// The squares of lattice cell `id` where viewers stand, in any of its view cells.
    pub fn lattice_places(&self, id: usize) -> u64 {
        self.view_cells_of(id).fold(0, |m, v| m | self.places_of(v))
    }

    /// The indices in [`ViewGrid::parts`] of lattice cell `id`'s further parts.
    fn parts_of_cell(&self, id: usize) -> std::ops::Range<usize> {
        let first = self.parts.partition_point(|q| (q.cell as usize) < id);
        first..first + self.parts[first..].iter().take_while(|q| q.cell as usize == id).count()
    }

    /// View cell `id` as samplers see it.
    pub fn view_cell(&self, id: usize) -> ViewCell {
        ViewCell { bounds: self.cell_box(self.cell_coords(id)), places: self.places_of(id) }
    }

    /// The squares of view cell `id` where viewers stand ([`ALL_PLACES`] without places).
    pub fn places_of(&self, id: usize) -> u64 {
        if let Some(part) = id.checked_sub(self.lattice_count()).and_then(|k| self.parts.get(k)) {
            return part.places;
        }
        match (&self.places, &self.present) {
            (Some(places), Some(set)) if set.contains(id) => places[set.rank(id)],
            _ => ALL_PLACES,
        }
    }

    /// The corners of view cell `id` next to a square where viewers stand (a lattice corner is
    /// the outer corner of one square of each cell it bounds): those of its 8 that lie on its
    /// side of a wall. All 8 where none does (a part in the middle of its cell), so that every
    /// view cell has measured points.
    pub fn view_corners(&self, id: usize) -> Vec<usize> {
        self.corners_next_to(self.cell_coords(id), self.places_of(id))
    }

    /// The corners of lattice cell `c` next to its squares `places` ([`ViewGrid::view_corners`]).
    pub fn corners_next_to(&self, c: [u32; 3], places: u64) -> Vec<usize> {
        let all = self.cell_corners(c);
        let last = PLACES_PER_EDGE - 1;
        let kept: Vec<usize> = (0..8)
            .filter(|&i| places >> ((i >> 2 & 1) * last * PLACES_PER_EDGE + (i & 1) * last) & 1 == 1)
            .map(|i| all[i as usize])
            .collect();
        if kept.is_empty() { all.to_vec() } else { kept }
    }

    /// Whether the view cells were made where viewers stand (`Scene::view_grid` without a grid:
    /// eye height above floors, cut at walls), rather than a whole regular grid.
    pub fn where_viewers_stand(&self) -> bool {
        self.places.is_some()
    }

    /// Whether a precompute samples each lattice cell whole and refines what it sees into the
    /// lattice cell's view cells (its quarters, cut at walls): in grids made where viewers
    /// stand, whose view cells are quarters of lattice cells (decision 130).
    pub fn refines_lattice_cells(&self) -> bool {
        self.where_viewers_stand()
    }

    /// Whether cell `id` is a view cell.
    pub fn is_present(&self, id: usize) -> bool {
        match id.checked_sub(self.lattice_count()) {
            Some(k) => k < self.parts.len(),
            None => self.present.as_ref().is_none_or(|s| s.contains(id)),
        }
    }

    /// The ids of the view cells, ascending (a wall's further parts last).
    pub fn present_ids(&self) -> Box<dyn Iterator<Item = usize> + '_> {
        let parts = self.lattice_count()..self.cell_count();
        match &self.present {
            Some(set) => Box::new(set.ids().chain(parts)),
            None => Box::new(0..self.cell_count()),
        }
    }

    /// How many view cells.
    pub fn present_count(&self) -> usize {
        self.present.as_ref().map_or(self.lattice_count(), CellSet::len) + self.parts.len()
    }

    /// Cells in the lattice.
    pub fn lattice_count(&self) -> usize {
        // Saturating: an unchecked grid's count must not wrap into a small one ([`ViewGrid::check`]).
        self.dims.iter().fold(1usize, |n, &d| n.saturating_mul(d as usize))
    }

    /// The ids of cells: the lattice's, then the further parts of cells that walls cut; the
    /// ids run below it (view cells or not).
    pub fn cell_count(&self) -> usize {
        self.lattice_count().saturating_add(self.parts.len())
    }

    /// The side lengths of one cell.
    pub fn cell_size(&self) -> Vec3 {
        self.region.extent() / UVec3::from(self.dims).as_vec3()
    }

    /// Linear cell id: x fastest, then z, then y (height layers outermost).
    pub fn cell_id(&self, c: [u32; 3]) -> usize {
        let [nx, _, nz] = self.dims.map(|d| d as usize);
        (c[1] as usize * nz + c[2] as usize) * nx + c[0] as usize
    }

    /// The `[i, j, k]` of cell `id` (of its lattice cell, for a further part).
    pub fn cell_coords(&self, id: usize) -> [u32; 3] {
        let id = id.checked_sub(self.lattice_count()).and_then(|k| self.parts.get(k)).map_or(id, |p| p.cell as usize);
        let [nx, _, nz] = self.dims.map(|d| d as usize);
        [(id % nx) as u32, (id / (nx * nz)) as u32, ((id / nx) % nz) as u32]
    }

    /// The cell holding `p`; points on an inner boundary belong to the upper cell, points on the
    /// region's upper face to the last cell. `None` outside the region.
    pub fn cell_of(&self, p: Vec3) -> Option<[u32; 3]> {
        if !p.is_finite() || !self.region.contains_point(p) {
            return None;
        }
        let rel = (p - self.region.min) / self.cell_size();
        let mut c = [0u32; 3];
        for a in 0..3 {
            let f = if rel[a].is_finite() { rel[a].floor() as i64 } else { 0 };
            c[a] = f.clamp(0, self.dims[a] as i64 - 1) as u32;
        }
        Some(c)
    }

    /// The lattice cells whose boxes may meet `b`, as their lowest and highest coordinates: one
    /// cell more on every side than the division gives, so that rounding leaves none out (the
    /// whole span of an axis where `b` is NaN there); `None` where `b` lies beyond that.
    pub fn lattice_span(&self, b: &Aabb) -> Option<[[u32; 3]; 2]> {
        let s = self.cell_size();
        let (mut lo, mut hi) = ([0u32; 3], [0u32; 3]);
        for a in 0..3 {
            let last = self.dims[a].saturating_sub(1) as f32;
            let from = ((b.min[a] - self.region.min[a]) / s[a]).floor() - 1.0;
            let to = ((b.max[a] - self.region.min[a]) / s[a]).floor() + 1.0;
            if from.is_nan() || to.is_nan() {
                (lo[a], hi[a]) = (0, last as u32);
            } else if to < 0.0 || from > last {
                return None;
            } else {
                // Saturating casts: an infinite end is the lattice's edge.
                (lo[a], hi[a]) = (from.max(0.0) as u32, to.min(last) as u32);
            }
        }
        Some([lo, hi])
    }

    /// The ids of the lattice cells of a span ([`ViewGrid::lattice_span`]); x fastest, then z,
    /// then y.
    pub fn lattice_cells(&self, [lo, hi]: [[u32; 3]; 2]) -> Vec<usize> {
        lattice_block(|a| lo[a]..=hi[a], |p| self.cell_id(p))
    }

    /// The centre of every cell, by cell id.
    pub fn cell_centres(&self) -> Vec<Vec3> {
        (0..self.cell_count()).map(|id| self.cell_box(self.cell_coords(id)).center()).collect()
    }

    /// The box of cell `c`.
    pub fn cell_box(&self, c: [u32; 3]) -> Aabb {
        let s = self.cell_size();
        let min = self.region.min + UVec3::from(c).as_vec3() * s;
        Aabb::new(min, min + s)
    }

    /// Number of shared corner sample points.
    pub fn corner_count(&self) -> usize {
        self.dims.iter().fold(1usize, |n, &d| n.saturating_mul(d as usize + 1))
    }

    /// Linear id of corner (i, j, k), same axis order as cells.
    pub fn corner_id(&self, c: [u32; 3]) -> usize {
        let [nx, _, nz] = self.dims.map(|d| d as usize + 1);
        (c[1] as usize * nz + c[2] as usize) * nx + c[0] as usize
    }

    /// The `[i, j, k]` of corner `id` (corners are the cells' vertices).
    pub fn corner_coords(&self, id: usize) -> [u32; 3] {
        let [nx, _, nz] = self.dims.map(|d| d as usize + 1);
        [(id % nx) as u32, (id / (nx * nz)) as u32, ((id / nx) % nz) as u32]
    }

    /// Where corner `c` lies.
    pub fn corner_position(&self, c: [u32; 3]) -> Vec3 {
        self.region.min + UVec3::from(c).as_vec3() * self.cell_size()
    }

    /// The ids of the 8 corners of a cell.
    pub fn cell_corners(&self, c: [u32; 3]) -> [usize; 8] {
        std::array::from_fn(|i| {
            self.corner_id([c[0] + (i as u32 & 1), c[1] + ((i as u32 >> 1) & 1), c[2] + ((i as u32 >> 2) & 1)])
        })
    }

    /// The corner ids of the cells within `ring` cells of cell `c` (ring 1: the 4 × 4 × 4 block
    /// of its own 8 corners and those of its 26 neighbours; ring 0: its own 8), clipped to the
    /// grid; x fastest, then z, then y.
    pub fn neighbourhood_corners(&self, c: [u32; 3], ring: u32) -> Vec<usize> {
        lattice_block(|a| c[a].saturating_sub(ring)..=(c[a] + 1 + ring).min(self.dims[a]), |p| self.corner_id(p))
    }

    /// The corner ids of the view cells within `ring` cells of cell `c`, ascending: in a grid
    /// of view cells only, the corners where a viewer nearly is (not those of cells inside a
    /// solid or across a floor, nor those behind a wall, [`ViewGrid::view_corners`]);
    /// [`ViewGrid::neighbourhood_corners`] otherwise.
    pub fn neighbourhood_view_corners(&self, c: [u32; 3], ring: u32) -> Vec<usize> {
        if self.present.is_none() {
            return self.neighbourhood_corners(c, ring);
        }
        let mut out: Vec<usize> =
            self.neighbourhood_view_cells(c, ring).into_iter().flat_map(|id| self.view_corners(id)).collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The view cells within `ring` cells of cell `c` (its own included): the lattice's view
    /// cells, then the further parts of those that walls cut.
    pub fn neighbourhood_view_cells(&self, c: [u32; 3], ring: u32) -> Vec<usize> {
        let mut out: Vec<usize> = self.neighbourhood_cells(c, ring).into_iter().filter(|&id| self.is_present(id)).collect();
        if !self.parts.is_empty() {
            let lattice = self.lattice_count();
            let parts: Vec<usize> = out.iter().flat_map(|&id| self.parts_of_cell(id)).map(|k| lattice + k).collect();
            out.extend(parts);
        }
        out
    }

    /// The ids of the cells within `ring` cells of cell `c` (itself included), clipped to the
    /// grid; x fastest, then z, then y.
    pub fn neighbourhood_cells(&self, c: [u32; 3], ring: u32) -> Vec<usize> {
        lattice_block(|a| c[a].saturating_sub(ring)..=(c[a] + ring).min(self.dims[a] - 1), |p| self.cell_id(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_and_corners_are_shared() {
        let g = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(4.0, 2.0, 3.0)), [4, 2, 3]);
        for id in 0..g.cell_count() {
            assert_eq!(g.cell_id(g.cell_coords(id)), id);
        }
        for id in 0..g.corner_count() {
            assert_eq!(g.corner_id(g.corner_coords(id)), id);
        }
        // Neighbouring cells along x share 4 corners.
        let a = g.cell_corners([0, 0, 0]);
        let b = g.cell_corners([1, 0, 0]);
        assert_eq!(a.iter().filter(|x| b.contains(x)).count(), 4);
        assert_eq!(g.corner_count(), 5 * 3 * 4);
    }

    #[test]
    fn cell_sets_hold_their_ids_and_nothing_else() {
        let set = CellSet::from_ids(vec![7, 3, 4, 5, 9, 3]);
        assert_eq!(set.ids().collect::<Vec<_>>(), vec![3, 4, 5, 7, 9]);
        assert_eq!(set.len(), 5);
        assert!((0..12).all(|id| set.contains(id) == [3, 4, 5, 7, 9].contains(&id)));
        assert!(set.check(10).is_ok());
        assert!(set.check(9).is_err());
        let mut g = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(4.0, 2.0, 4.0)), [4, 1, 4]);
        g.present = Some(set);
        assert!(g.check().is_ok());
        assert_eq!(g.present_ids().collect::<Vec<_>>(), vec![3, 4, 5, 7, 9]);
        assert!(g.is_present(9) && !g.is_present(8) && !g.is_present(16));
        let set = g.present.clone().unwrap();
        assert_eq!([3, 5, 7, 9, 10].map(|id| set.rank(id)), [0, 2, 3, 4, 5]);
        // Places: cell 3 only in its x < ½ half, the others everywhere.
        let half = (0..8).fold(0u64, |m, z| m | 0x0f << (8 * z));
        g.places = Some(vec![half, !0, !0, !0, !0]);
        assert!(g.check().is_ok());
        let c = g.cell_coords(3);
        assert_eq!(g.standing_cell(3, c, Vec3::new(3.2, 1.0, 0.5)), Some(3));
        assert_eq!(g.standing_cell(3, c, Vec3::new(3.7, 1.0, 0.5)), None);
        g.places = Some(vec![!0; 4]);
        assert!(g.check().is_err());
        g.places = None;
        let json = serde_json::to_string(&g).unwrap();
        assert!(json.contains("\"present\":[[3,6],[7,8],[9,10]]"), "{json}");
        assert_eq!(serde_json::from_str::<ViewGrid>(&json).unwrap(), g);
        let bad: CellSet = serde_json::from_str("[[3,6],[5,8]]").unwrap();
        assert!(bad.check(16).is_err());
        g.present = Some(CellSet::default());
        assert!(g.check().is_err());
    }

    #[test]
    fn a_mask_of_places_falls_in_parts() {
        assert_eq!(place_parts(0).len(), 0);
        assert_eq!(place_parts(u64::MAX).len(), 1);
        // Columns 0–2 and 4–7 of every row: a wall at column 3.
        let row = 0b1111_0111u64;
        assert_eq!(place_parts((0..8).fold(0, |m, z| m | row << (8 * z))).len(), 2);
        // The same with a door in row 5.
        assert_eq!(place_parts((0..8).fold(0, |m, z| m | row << (8 * z)) | 1 << (5 * 8 + 3)).len(), 1);
        // Bit 7 of a row and bit 0 of the next are not neighbours.
        assert_eq!(place_parts(1 << 7 | 1 << 8).len(), 2);
        assert_eq!(place_parts(1 << 7 | 1 << 15).len(), 1);
    }

    #[test]
    fn the_squares_around_a_view_cell_stop_at_walls_and_at_the_cell() {
        let mask = |squares: &[(u32, u32)]| squares.iter().fold(0u64, |m, &(x, z)| m | 1 << (z * 8 + x));
        let all = |xs: std::ops::Range<u32>| (0..8).flat_map(move |z| xs.clone().map(move |x| (x, z))).collect::<Vec<_>>();
        // The north-east quarter of a whole cell takes the ring around it, corner included.
        let ring: Vec<(u32, u32)> = (3..8).flat_map(|z| (3..8).map(move |x| (x, z))).collect();
        assert_eq!(places_around(QUARTERS[3], u64::MAX), mask(&ring));
        // One square in the middle: its 3 × 3 block; in a corner, what of it the cell has.
        assert_eq!(places_around(mask(&[(4, 4)]), u64::MAX).count_ones(), 9);
        assert_eq!(places_around(mask(&[(0, 0)]), u64::MAX), mask(&[(0, 0), (1, 0), (0, 1), (1, 1)]));
        // Nothing wraps from one row's end to the next row's start.
        assert_eq!(places_around(mask(&[(7, 3)]), u64::MAX) & mask(&[(0, 4), (0, 3), (0, 2)]), 0);
        // A wall at column 3: the west side's squares never take the east side's.
        let (west, east) = (mask(&all(0..3)), mask(&all(4..8)));
        assert_eq!(places_around(west & QUARTERS[0], west | east), west & mask(&all(0..3)) & (QUARTERS[0] | QUARTERS[0] << 8));
        assert_eq!(places_around(east & QUARTERS[1], west | east) & west, 0);
        // Only squares where viewers stand.
        assert_eq!(places_around(QUARTERS[0], QUARTERS[0] | QUARTERS[1]) & (QUARTERS[2] | QUARTERS[3]), 0);
        // A square touching at a corner only, in another part (no 4-neighbour joins them).
        assert_eq!(places_around(mask(&[(0, 0)]), mask(&[(0, 0), (1, 1)])), mask(&[(0, 0)]));
        assert_eq!(places_around(mask(&[(0, 0)]), mask(&[(0, 0), (1, 0), (1, 1)])), mask(&[(0, 0), (1, 0), (1, 1)]));
    }

    #[test]
    fn the_squares_across_a_view_cells_border_touch_it() {
        // 3 × 1 × 3 cells of 2 m, viewers everywhere but in the cell at x 0, z 2.
        let mut g = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(6.0, 1.0, 6.0)), [3, 1, 3]);
        let ids: Vec<usize> = (0..9).filter(|&id| id != 6).collect();
        g.present = Some(CellSet::from_ids(ids.iter().map(|&id| id as u32).collect()));
        g.places = Some(vec![ALL_PLACES; ids.len()]);
        assert!(g.check().is_ok());
        let bits = |pairs: &[(u32, u32)]| pairs.iter().map(|p| p.0).collect::<std::collections::BTreeSet<u32>>();
        // The centre cell's north-east quarter touches the cells at +x, +z and both.
        let across = g.squares_across([1, 0, 1], QUARTERS[3]);
        let by_id: std::collections::BTreeMap<usize, Vec<(u32, u32)>> = across.into_iter().collect();
        assert_eq!(by_id.keys().copied().collect::<Vec<_>>(), vec![g.cell_id([2, 0, 1]), g.cell_id([1, 0, 2]), g.cell_id([2, 0, 2])]);
        assert_eq!(bits(&by_id[&g.cell_id([2, 0, 1])]), (3..8).map(|z| z * 8).collect());
        assert_eq!(bits(&by_id[&g.cell_id([1, 0, 2])]), (3..8).collect());
        assert_eq!(bits(&by_id[&g.cell_id([2, 0, 2])]), [0].into());
        // Each square across is paired with one of the quarter's that touches it.
        for (n, pairs) in &by_id {
            for &(their, own) in pairs {
                let (a, b) = (g.square_centre([1, 0, 1], own), g.square_centre(g.cell_coords(*n), their));
                assert!(QUARTERS[3] >> own & 1 == 1 && (a - b).abs().max_element() <= 0.25 + 1e-6, "{a} {b}");
                assert_eq!(a.y, 0.5);
            }
        }
        // The south-west quarter of the cell at x 1, z 2: nothing from the cell where no viewer
        // stands, nor past the grid's edge.
        let across = g.squares_across([1, 0, 2], QUARTERS[0]);
        assert_eq!(across.iter().map(|a| a.0).collect::<Vec<_>>(), vec![g.cell_id([0, 0, 1]), g.cell_id([1, 0, 1])]);
    }

    /// A wall along x = ½ through cell 5 of a 4 × 1 × 4 grid: its west squares keep id 5, its
    /// east squares are view cell 16, the first after the lattice.
    fn cut_grid() -> ViewGrid {
        let west = (0..8).fold(0u64, |m, z| m | 0x07 << (8 * z));
        let mut g = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(4.0, 1.0, 4.0)), [4, 1, 4]);
        g.present = Some(CellSet::from_ids(vec![4, 5, 6]));
        g.places = Some(vec![ALL_PLACES, west, ALL_PLACES]);
        g.parts = vec![CellPart { cell: 5, places: west << 4 | west << 5 }];
        g
    }

    #[test]
    fn a_cell_cut_by_a_wall_is_a_view_cell_per_side() {
        let g = cut_grid();
        assert!(g.check().is_ok());
        assert_eq!((g.lattice_count(), g.cell_count(), g.present_count()), (16, 17, 4));
        assert_eq!(g.present_ids().collect::<Vec<_>>(), vec![4, 5, 6, 16]);
        assert!(g.is_present(16) && !g.is_present(17) && !g.is_present(7));
        assert_eq!(g.cell_coords(16), g.cell_coords(5));
        let c = g.cell_coords(5);
        assert_eq!(g.standing_cell(5, c, Vec3::new(1.2, 0.5, 0.5)), Some(5));
        assert_eq!(g.standing_cell(5, c, Vec3::new(1.8, 0.5, 0.5)), Some(16));
        // The wall's own squares (x in [3/8, 4/8)) are nobody's.
        assert_eq!(g.standing_cell(5, c, Vec3::new(1.4, 0.5, 0.5)), None);
        // Each side keeps the corners next to its squares; a whole cell all 8.
        let x_of = |ids: Vec<usize>| ids.iter().map(|&k| g.corner_coords(k)[0]).collect::<Vec<_>>();
        assert_eq!(x_of(g.view_corners(5)), vec![1; 4]);
        assert_eq!(x_of(g.view_corners(16)), vec![2; 4]);
        assert_eq!(g.view_corners(4).len(), 8);
        // Points of a side lie in its squares, spread over all of them.
        for (id, x) in [(5, 1.0..1.375), (16, 1.5..2.0)] {
            let cell = g.view_cell(id);
            let u = |k: u32| Vec3::new((k as f32 + 0.5) / 64.0, 0.3, ((k * 37 % 64) as f32 + 0.5) / 64.0);
            let points: Vec<Vec3> = (0..64).map(|k| cell.point(u(k))).collect();
            assert!(points.iter().all(|p| x.contains(&p.x) && g.standing_cell(5, c, *p) == Some(id)), "{id}");
            let squares: std::collections::HashSet<u32> = points.iter().map(|&p| cell.square_of(p)).collect();
            assert_eq!(squares.len() as u32, cell.places.count_ones(), "{id}");
        }
        assert_eq!(g.neighbourhood_view_cells(g.cell_coords(4), 1), vec![4, 5, 16]);
        let json = serde_json::to_string(&g).unwrap();
        assert_eq!(serde_json::from_str::<ViewGrid>(&json).unwrap(), g);
    }

    #[test]
    fn parts_that_overlap_or_lack_a_view_cell_are_refused() {
        let mut g = cut_grid();
        g.parts[0].places |= 1;
        assert!(g.check().is_err());
        let mut g = cut_grid();
        g.parts[0].cell = 7;
        assert!(g.check().is_err());
        let mut g = cut_grid();
        g.parts.push(g.parts[0]);
        assert!(g.check().is_err());
        let mut g = cut_grid();
        g.parts[0].places = 0;
        assert!(g.check().is_err());
    }

    proptest::proptest! {
        /// A footprint's quarter parts tile its places: each lies in one quarter, is one piece
        /// that 4-neighbouring squares join, and none overlaps another; the box of a part holds
        /// its squares.
        #[test]
        fn quarter_parts_tile_the_places(mask in proptest::prelude::any::<u64>()) {
            let parts = quarter_parts(mask);
            proptest::prop_assert_eq!(parts.iter().fold(0, |m, p| m | p), mask);
            proptest::prop_assert_eq!(parts.iter().map(|p| p.count_ones()).sum::<u32>(), mask.count_ones());
            let bounds = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 2.0));
            for &p in &parts {
                proptest::prop_assert!(QUARTERS.iter().any(|q| p & !q == 0), "{:x} spans quarters", p);
                proptest::prop_assert_eq!(place_parts(p), vec![p]);
                let cell = ViewCell { bounds, places: p };
                let b = cell.places_box();
                for k in 0..64u32 {
                    let u = Vec3::new((k as f32 + 0.5) / 64.0, 0.5, ((k * 29 % 64) as f32 + 0.5) / 64.0);
                    proptest::prop_assert!(b.contains_point(cell.point(u)));
                }
            }
        }
    }

    proptest::proptest! {
        /// Every lattice cell whose box meets a box lies in the box's span, wherever the box
        /// lies against the region (inside, across its faces, outside, infinite on a side).
        #[test]
        fn a_span_holds_every_cell_a_box_meets(
            origin in proptest::array::uniform3(-1000.0f32..1000.0),
            size in proptest::array::uniform3(0.1f32..50.0),
            dims in proptest::array::uniform3(1u32..12),
            at in proptest::array::uniform3(-0.5f32..1.5),
            extent in proptest::array::uniform3(0.0f32..0.8),
            open_side in 0usize..8,
        ) {
            let (origin, size) = (Vec3::from(origin), Vec3::from(size));
            let g = ViewGrid::new(Aabb::new(origin, origin + size * UVec3::from(dims).as_vec3()), dims);
            let extent_of_region = g.region.extent();
            let min = origin + Vec3::from(at) * extent_of_region;
            let mut b = Aabb::new(min, min + Vec3::from(extent) * extent_of_region);
            if open_side < 3 {
                b.max[open_side] = f32::INFINITY;
            }
            let span = g.lattice_span(&b);
            for id in 0..g.lattice_count() {
                let c = g.cell_coords(id);
                if g.cell_box(c).intersects(&b) {
                    let [lo, hi] = span.expect("a box that meets a cell has a span");
                    proptest::prop_assert!((0..3).all(|a| lo[a] <= c[a] && c[a] <= hi[a]), "{:?} outside {:?}", c, [lo, hi]);
                }
            }
        }
    }

    #[test]
    fn cell_of_boundaries() {
        let g = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(4.0, 2.0, 4.0)), [4, 1, 4]);
        assert_eq!(g.cell_of(Vec3::new(1.0, 0.5, 0.0)), Some([1, 0, 0]));
        assert_eq!(g.cell_of(Vec3::new(4.0, 2.0, 4.0)), Some([3, 0, 3]));
        assert_eq!(g.cell_of(Vec3::new(4.01, 1.0, 1.0)), None);
        assert_eq!(g.cell_of(Vec3::new(f32::NAN, 1.0, 1.0)), None);
        let c = g.cell_of(Vec3::new(2.5, 1.0, 3.5)).unwrap();
        assert!(g.cell_box(c).contains_point(Vec3::new(2.5, 1.0, 3.5)));
    }
}
