//! View cells where a viewer can stand. A box of cells at one height serves a city street; in a
//! building or a game level it has no cells on the upper storeys, and cells inside walls, floors
//! and rock that cost time and answer nothing. [`Scene::view_grid`] finds, without a region or a
//! grid given, the places a person can be: eye height above an up-facing floor, in empty space,
//! on every storey, and keeps exactly the cells of a lattice that hold such places
//! ([`ViewGrid::present`]).
//!
//! Vertical lines through the scene, 8 × 8 per cell column, meet the triangles above and below;
//! a surface facing up within 45° of the vertical is a floor where nothing covers it (a box
//! standing on it), the next surface above faces down (a ceiling) or there is none (the sky), and
//! there is room for the lowest eye height between ([`floors`]). Each floor's band of eye heights
//! marks the cells it meets, and in each cell the eighth of its footprint (a *place*,
//! [`ViewGrid::places`]) around the line, and the places around it that are open air from the
//! floor up to the highest eye (a viewer at the edge of a hole or a drop leans over it; a wall
//! standing on the floor is not open). Layers of cells are at most the lowest eye height tall, so
//! that a cell marked from a floor never reaches below it into the storey underneath. A cell is
//! answered in quarters, and a quarter whose places fall in parts that no place joins (a wall
//! through it) is one view cell per part ([`ViewGrid::parts`]): no answer mixes two rooms.

use glam::Vec3;

use super::Scene;
use crate::error::{Error, Param, Result};
use crate::geom::Aabb;
use crate::grid::{CellPart, CellSet, ViewGrid, place_parts, quarter_parts};

/// Vertical lines per cell edge (8 × 8 per cell column): floors narrower than an eighth of a cell
/// (a ledge, a step's nose) may go unseen.
const LINES_PER_CELL: u32 = crate::grid::PLACES_PER_EDGE;

/// A floor faces up within 45° of the vertical (steeper is a wall or a ramp no one stands on).
const FLOOR_COS: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The heights above a floor where a viewer's eye may be, in scene units: from `low` (crouching,
/// a short viewer) up to, not including, `high` (standing tall).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeHeights {
    /// The lowest eye height; also the headroom a floor needs.
    pub low: f32,
    /// The highest eye height.
    pub high: f32,
}

impl Default for EyeHeights {
    /// 1 to 2 scene units: a person's eyes in metres (1.5–1.75 standing, about 1.1 crouching),
    /// and a game character's (Quake's 50 units of eye height are 1.27–1.56 m, as converted).
    fn default() -> Self {
        EyeHeights { low: 1.0, high: 2.0 }
    }
}

impl EyeHeights {
    /// Checks that `0 < low ≤ high`, both finite.
    pub fn check(&self) -> Result<()> {
        if !(self.low.is_finite() && self.high.is_finite() && 0.0 < self.low && self.low <= self.high) {
            return Err(Error::bad_param(
                Param::EyeHeights,
                format!("{},{} must be two finite heights with 0 < LOW ≤ HIGH", self.low, self.high),
            ));
        }
        Ok(())
    }
}

/// What [`Scene::floors`] finds.
#[derive(Clone, Debug)]
pub struct Floors {
    /// The lattice's corner (the scene's lowest x and z; y is the scene's lowest).
    pub origin: Vec3,
    /// Columns of cells along x and z.
    pub columns: [u32; 2],
    /// Each floor a line crosses, lines in order (x fastest), bottom up.
    pub found: Vec<Floor>,
}

/// A floor where a vertical line crosses it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// The line (x, z) among all the scene's lines.
    pub line: [u32; 2],
    /// The point on the floor.
    pub at: Vec3,
    /// The height of the next surface above (+∞: none).
    pub ceiling: f32,
    /// Bit `b` set: the neighbouring line [`NEIGHBOURS`]`[b]` is open air from this floor up
    /// to its highest eye, so a viewer standing at the floor's edge may have their eyes there.
    pub reach: u8,
}

/// The 8 neighbouring lines of a line, `[dx, dz]`.
pub const NEIGHBOURS: [[i64; 2]; 8] = [[-1, -1], [0, -1], [1, -1], [-1, 0], [1, 0], [-1, 1], [0, 1], [1, 1]];

impl Floor {
    /// The lines where a viewer standing on this floor may have their eyes: its own and the
    /// open neighbours ([`Floor::reach`]).
    pub fn eye_lines(&self) -> impl Iterator<Item = [u32; 2]> + '_ {
        let own = std::iter::once(self.line);
        let [i, k] = self.line.map(i64::from);
        own.chain(
            NEIGHBOURS
                .iter()
                .enumerate()
                .filter(move |(b, _)| self.reach >> b & 1 == 1)
                .map(move |(_, [di, dk])| [(i + di) as u32, (k + dk) as u32]),
        )
    }
}

impl Scene {
    /// The grid of view cells a build uses: `region` and `dims`/`cell_size` as given
    /// ([`ViewGrid::resolve`]), else the scene's own grid (recut to `cell_size` if given), else
    /// the cells where a viewer can stand, `cell_size` wide (default: a sixteenth of the scene's
    /// longer horizontal side) and at most `eyes.low` tall ([`Scene::standable_grid`]). A scene
    /// with no floor at all (objects in the air, a façade, a scan without its ground) gets one
    /// layer of cells over its footprint at eye height above its lowest point, as before.
    pub fn view_grid(
        &self,
        region: Option<Aabb>,
        dims: Option<[u32; 3]>,
        cell_size: Option<f32>,
        eyes: EyeHeights,
    ) -> Result<ViewGrid> {
        let bounds = self.bounds();
        if region.is_some() || dims.is_some() || self.grid.is_some() {
            return ViewGrid::resolve(bounds, self.grid.clone(), region, dims, cell_size);
        }
        let e = bounds.extent();
        let size = cell_size.unwrap_or(e.x.max(e.z) / 16.0);
        match self.standable_grid(size, eyes) {
            Err(Error::BadParam { param: Param::Region, .. }) if !bounds.is_empty() => {
                ViewGrid::resolve(bounds, None, None, None, cell_size)
            }
            other => other,
        }
    }

    /// The floors that vertical lines, 8 × 8 per column of cells `cell_size` wide, find
    /// (module documentation), line by line and bottom up. Refused when `cell_size` is not a
    /// positive length or cuts the footprint into more than [`ViewGrid::MAX_CELLS`] columns, and
    /// when no floor is found. Costs O(triangles × lines each covers) time, and memory for the
    /// lines' crossings.
    pub fn floors(&self, cell_size: f32, eyes: EyeHeights) -> Result<Floors> {
        eyes.check()?;
        if !(cell_size.is_finite() && cell_size > 0.0) {
            return Err(Error::bad_param(Param::CellSize, format!("{cell_size} must be a positive length")));
        }
        let bounds = self.bounds();
        if bounds.is_empty() {
            return Err(Error::bad_param(Param::Region, "the scene is empty: no floor to stand on"));
        }
        let e = bounds.extent();
        let columns = |x: f32| (f64::from(x) / f64::from(cell_size)).ceil().max(1.0);
        let (cx, cz) = (columns(e.x), columns(e.z));
        let lines = cx * cz * f64::from(LINES_PER_CELL * LINES_PER_CELL);
        if cx * cz > ViewGrid::MAX_CELLS as f64 {
            let reason = format!("{cell_size} cuts the scene's footprint into {:.0} columns of cells, more than {}", cx * cz, ViewGrid::MAX_CELLS);
            return Err(Error::bad_param(Param::CellSize, reason));
        }
        let (cx, cz) = (cx as u32, cz as u32);
        let lines_x = cx * LINES_PER_CELL;
        let spacing = cell_size / LINES_PER_CELL as f32;
        let origin = bounds.min;
        let crossings = self.crossings(origin, spacing, [lines_x, cz * LINES_PER_CELL]);
        let lines_z = cz * LINES_PER_CELL;
        // The crossings of line `l`.
        let of_line = |l: u32| {
            let start = crossings.partition_point(|c| c.0 < l);
            &crossings[start..start + crossings[start..].partition_point(|c| c.0 == l)]
        };
        let found: Vec<Floor> = floors(&crossings, eyes)
            .into_iter()
            .map(|(line, y, ceiling)| {
                let (i, k) = (line % lines_x, line / lines_x);
                let at = Vec3::new(origin.x + (i as f32 + 0.5) * spacing, y, origin.z + (k as f32 + 0.5) * spacing);
                // The neighbouring lines with nothing from this floor up to the highest eye:
                // open air (the edge of a hole, a drop) that a viewer at the edge leans over.
                // A wall standing on the floor has its underside there and is not reached.
                let (bottom, top) = (y - hair(y, eyes), y + eyes.high.min(ceiling - y));
                let mut reach = 0u8;
                for (bit, [di, dk]) in NEIGHBOURS.iter().enumerate() {
                    let (ni, nk) = (i as i64 + di, k as i64 + dk);
                    if ni < 0 || nk < 0 || ni >= i64::from(lines_x) || nk >= i64::from(lines_z) {
                        continue;
                    }
                    if !of_line(nk as u32 * lines_x + ni as u32).iter().any(|c| c.1 > bottom && c.1 < top) {
                        reach |= 1 << bit;
                    }
                }
                Floor { line: [i, k], at, ceiling, reach }
            })
            .collect();
        if found.is_empty() {
            let reason = format!(
                "no floor found in {lines:.0} vertical lines: nowhere in this scene has an up-facing surface with {} of room above it; give --region and --grid",
                eyes.low
            );
            return Err(Error::bad_param(Param::Region, reason));
        }
        Ok(Floors { origin, columns: [cx, cz], found })
    }

    /// The cells, `cell_size` wide and `min(cell_size, eyes.low)` tall, that hold a place where a
    /// viewer can stand (module documentation): those [`Scene::floors`] finds. Refused as it is,
    /// and when the lattice would pass [`ViewGrid::MAX_CELLS`].
    pub fn standable_grid(&self, cell_size: f32, eyes: EyeHeights) -> Result<ViewGrid> {
        let Floors { origin, columns: [cx, cz], found: floors } = self.floors(cell_size, eyes)?;
        let layers @ Layers { y0, height: layer, count: ny } = Layers::of(&floors, cell_size, eyes);
        let dims = [cx, ny, cz];
        let region = Aabb::new(
            Vec3::new(origin.x, y0, origin.z),
            Vec3::new(origin.x + cx as f32 * cell_size, y0 + ny as f32 * layer, origin.z + cz as f32 * cell_size),
        );
        let lattice = u64::from(cx) * u64::from(ny) * u64::from(cz);
        if lattice > ViewGrid::MAX_CELLS {
            let reason = format!(
                "{cell_size} cuts the storeys into a lattice of {cx}x{ny}x{cz} cells, more than {}; use larger cells",
                ViewGrid::MAX_CELLS
            );
            return Err(Error::bad_param(Param::CellSize, reason));
        }
        let mut grid = ViewGrid::new(region, dims);
        // Per cell its squares where a floor's eyes reach it, one line each.
        let mut places: std::collections::BTreeMap<usize, u64> = Default::default();
        for f in &floors {
            for [i, k] in f.eye_lines() {
                let bit = 1u64 << ((k % LINES_PER_CELL) * LINES_PER_CELL + i % LINES_PER_CELL);
                for id in eye_cells(&grid, layers, f, [i / LINES_PER_CELL, k / LINES_PER_CELL], eyes) {
                    *places.entry(id).or_default() |= bit;
                }
            }
        }
        // Each cell's quarters (decision 130), and of a quarter whose places fall in parts that
        // no line between them joins (a wall, a pillar or a drop through it) each part, are view
        // cells, so that no answer mixes two rooms.
        let mut own = Vec::with_capacity(places.len());
        for (&id, &mask) in &places {
            let mut parts = quarter_parts(mask).into_iter();
            own.push(parts.next().expect("a cell in the map has a place"));
            grid.parts.extend(parts.map(|places| CellPart { cell: id as u32, places }));
        }
        grid.present = Some(CellSet::from_ids(places.keys().map(|&id| id as u32).collect()));
        grid.places = Some(own);
        if grid.cell_count() as u64 > ViewGrid::MAX_CELLS {
            let reason = format!("{cell_size} makes more than {} view cells; use larger cells", ViewGrid::MAX_CELLS);
            return Err(Error::bad_param(Param::CellSize, reason));
        }
        Ok(grid)
    }

    /// Of the lattice cells [`Scene::standable_grid`] finds places in, how many a wall cuts into
    /// parts that no line between them joins. Returns (such cells, view cells).
    pub fn cells_across_walls(&self, cell_size: f32, eyes: EyeHeights) -> Result<(usize, usize)> {
        let grid = self.standable_grid(cell_size, eyes)?;
        let lattice = grid.present_ids().filter(|&id| id < grid.lattice_count());
        let cut = lattice.filter(|&id| place_parts(grid.lattice_places(id)).len() > 1).count();
        Ok((cut, grid.present_count()))
    }

    /// Where each vertical line of the lattice `origin + (i + ½, ·, k + ½) · spacing`,
    /// `i < lines[0]`, `k < lines[1]`, crosses a triangle: `(line, height, facing)` with line
    /// `k · lines[0] + i` and facing the triangle normal's vertical part (1 straight up, −1
    /// straight down), sorted by line and height.
    fn crossings(&self, origin: Vec3, spacing: f32, lines: [u32; 2]) -> Vec<(u32, f32, f32)> {
        let mut out = Vec::new();
        for object in 0..self.objects.len() {
            for [a, b, c] in self.object_faces(object) {
                let n = (b - a).cross(c - a);
                let length = n.length();
                // Vertical and degenerate triangles: no line crosses them.
                if !length.is_finite() || length <= 0.0 || n.y.abs() <= length * 1e-6 {
                    continue;
                }
                let facing = n.y / length;
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                // The lines whose x and z fall within the triangle's footprint box.
                let span = |lo: f32, hi: f32, o: f32, n: u32| {
                    let first = ((lo - o) / spacing - 0.5).ceil().max(0.0) as i64;
                    let last = (((hi - o) / spacing - 0.5).floor() as i64).min(i64::from(n) - 1);
                    first as u32..(last + 1).max(first) as u32
                };
                for k in span(lo.z, hi.z, origin.z, lines[1]) {
                    let z = origin.z + (k as f32 + 0.5) * spacing;
                    for i in span(lo.x, hi.x, origin.x, lines[0]) {
                        let x = origin.x + (i as f32 + 0.5) * spacing;
                        if let Some(y) = height_at([a, b, c], x, z) {
                            out.push((k * lines[0] + i, y, facing));
                        }
                    }
                }
            }
        }
        out.sort_unstable_by(|p, q| p.0.cmp(&q.0).then(p.1.total_cmp(&q.1)));
        out
    }
}

/// The layers of a standable grid: from the lowest eye up, at most the lowest eye height tall
/// (so that a cell marked from a floor never reaches below it), to the highest eye.
#[derive(Clone, Copy)]
struct Layers {
    y0: f32,
    height: f32,
    count: u32,
}

impl Layers {
    fn of(floors: &[Floor], cell_size: f32, eyes: EyeHeights) -> Layers {
        let height = cell_size.min(eyes.low);
        let y0 = floors.iter().map(|f| f.at.y).fold(f32::INFINITY, f32::min) + eyes.low;
        let top = floors.iter().map(|f| f.at.y + (f.ceiling - f.at.y).min(eyes.high)).fold(f32::NEG_INFINITY, f32::max);
        let count = ((f64::from(top - y0) / f64::from(height)).ceil().max(1.0)).min(f64::from(u32::MAX)) as u32;
        Layers { y0, height, count }
    }
}

/// The cells of `grid` (a standable grid with `layers`) in `column` that the eye band of floor
/// `f` meets: eyes from `low` up to, not including, `high`, so that a band ending on a layer's
/// bottom does not reach into it (the layers' own numbers, not the grid's box divided again,
/// which would reach into it by a rounding).
fn eye_cells<'g>(
    grid: &'g ViewGrid,
    layers: Layers,
    f: &Floor,
    column: [u32; 2],
    eyes: EyeHeights,
) -> impl Iterator<Item = usize> + 'g {
    let Layers { y0, height: layer, count: ny } = layers;
    let low = f.at.y + eyes.low;
    let high = (f.at.y + eyes.high).min(f.ceiling);
    let first = (((low - y0) / layer).floor().max(0.0) as u32).min(ny - 1);
    let end = (((high - y0) / layer).ceil().max(1.0) as u32).min(ny);
    let [x, z] = column;
    (first..end.max(first + 1)).map(move |y| grid.cell_id([x, y, z]))
}

/// The height of triangle `t` over `(x, z)`, if its footprint holds the point, edges included
/// with a margin of [`EDGE`]: a line through the shared edge of two triangles (the diagonal of a
/// quad, met exactly by lines on a regular spacing) must not fall through the crack that rounding
/// opens between them. Both then report it; `floors` counts one surface.
pub fn height_at(t: [Vec3; 3], x: f32, z: f32) -> Option<f32> {
    let [a, b, c] = t;
    let d = (b.x - a.x) * (c.z - a.z) - (c.x - a.x) * (b.z - a.z);
    let u = ((b.x - x) * (c.z - z) - (c.x - x) * (b.z - z)) / d;
    let v = ((c.x - x) * (a.z - z) - (a.x - x) * (c.z - z)) / d;
    let w = 1.0 - u - v;
    (u >= -EDGE && v >= -EDGE && w >= -EDGE).then_some(u * a.y + v * b.y + w * c.y)
}

/// How far outside a triangle, in barycentric units, a line still meets it.
const EDGE: f32 = 1e-5;

/// Crossings of a line closer than this to height `y` are one surface: 1e-4 of the lowest eye
/// height, or 1e-7 of `y` where that is larger (far from the origin, where f32 steps grow).
fn hair(y: f32, eyes: EyeHeights) -> f32 {
    1e-4 * eyes.low.max(y.abs() * 1e-3)
}

/// The floors along the lines: `(line, floor height, height of the next surface above or +∞)`.
/// Crossings within a hair of each other are one surface (a line through the edge two
/// triangles share meets both). A floor is a surface that faces up within 45°, that
///
/// - is not covered: nothing at its height faces down (a box standing on it, a wall's
///   underside);
/// - is not inside a solid: the next surface above faces down (a ceiling, an underside) or there
///   is none (the sky); one that only faces up is the top of a solid this floor is inside;
/// - has at least `eyes.low` of room up to that surface.
///
/// Nothing else is assumed of the meshes: a BSP export keeps only the faces seen from inside the
/// level (no undersides where solids touch, several undersides under one top), a BIM export
/// closed solids that touch. A slab drawn as one plane from both sides counts as covered.
fn floors(crossings: &[(u32, f32, f32)], eyes: EyeHeights) -> Vec<(u32, f32, f32)> {
    let mut out = Vec::new();
    for line in crossings.chunk_by(|a, b| a.0 == b.0) {
        // The surfaces along the line, bottom up: (height, some of it faces down, a floor).
        let mut surfaces: Vec<(f32, bool, bool)> = Vec::new();
        let mut k = 0;
        while k < line.len() {
            let y = line[k].1;
            let group = &line[k..k + line[k..].iter().take_while(|c| c.1 <= y + hair(y, eyes)).count()];
            let down = group.iter().any(|c| c.2 < 0.0);
            surfaces.push((y, down, group.iter().any(|c| c.2 >= FLOOR_COS)));
            k += group.len();
        }
        for (n, &(y, down, floor)) in surfaces.iter().enumerate() {
            let above = surfaces.get(n + 1);
            let open = above.is_none_or(|a| a.1);
            let ceiling = above.map_or(f32::INFINITY, |a| a.0);
            if floor && !down && open && ceiling - y >= eyes.low {
                out.push((line[0].0, y, ceiling));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_over_a_triangle_and_off_it() {
        let t = [Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 2.0), Vec3::new(2.0, 3.0, 0.0)];
        assert_eq!(height_at(t, 0.0, 0.0), Some(1.0));
        assert!((height_at(t, 1.0, 0.5).unwrap() - 2.0).abs() < 1e-6);
        assert_eq!(height_at(t, 1.5, 1.5), None);
        // A quad's two triangles both meet a line through their shared diagonal.
        let (p, q, r, s) = (Vec3::new(0.1, 0.0, 0.3), Vec3::new(0.7, 0.0, 0.3), Vec3::new(0.7, 0.0, 0.9), Vec3::new(0.1, 0.0, 0.9));
        for k in 1..50 {
            let f = k as f32 / 50.0;
            let (x, z) = (0.1 + 0.6 * f, 0.3 + 0.6 * f);
            assert!(height_at([p, q, r], x, z).is_some() || height_at([p, r, s], x, z).is_some(), "a crack at {x}, {z}");
        }
    }

    #[test]
    fn floors_need_room_and_a_ceiling_that_faces_down() {
        let eyes = EyeHeights::default();
        let c = [
            // A floor (no underside, as a BSP export has it) under a ceiling 3 up, then a
            // closed slab from 3 to 3.3 under the sky.
            (0, 0.0, 1.0),
            (0, 3.0, -1.0),
            (0, 3.3, 1.0),
            // A closed slab whose top has a box standing on it up to a closed slab above: the
            // box's inside is no place to stand; the upper slab's top is, under the sky.
            (1, -0.3, -1.0),
            (1, 0.0, 1.0),
            (1, 0.0, -1.0),
            (1, 3.0, 1.0),
            (1, 3.0, -1.0),
            (1, 3.3, 1.0),
            // A floor under a ceiling half a unit up; a floor drawn twice, with sky; a slope
            // steeper than 45°.
            (2, 0.0, 1.0),
            (2, 0.5, -1.0),
            (3, 4.0, 0.9),
            (3, 4.0, 0.9),
            (4, 0.0, 0.6),
            // A block's underside met on the edge its two triangles share, then its top.
            (5, -0.5, -1.0),
            (5, -0.5, -1.0),
            (5, 0.0, 1.0),
            // A BSP floor over three undersides of the room below (a light, a sloped trim, a
            // panel) and under a ceiling: no solid's count may hide it.
            (6, -2.0, 1.0),
            (6, 2.5, -1.0),
            (6, 2.875, -0.7),
            (6, 3.0, -1.0),
            (6, 4.0, 1.0),
            (6, 8.0, -1.0),
        ];
        let found = floors(&c, eyes);
        let sky = f32::INFINITY;
        assert_eq!(
            found,
            vec![(0, 0.0, 3.0), (0, 3.3, sky), (1, 3.3, sky), (3, 4.0, sky), (5, 0.0, sky), (6, -2.0, 2.5), (6, 4.0, 8.0)]
        );
    }
}
