//! Assembling closed, outward-facing triangle meshes from parts.
//!
//! A building is a union of *parts*, each a closed surface of its own (a facade box, a ledge, a
//! roof). Parts may touch or interpenetrate; that is invisible to a renderer and to the DoV
//! measure, and it keeps every part watertight without cutting one part's faces against
//! another's. Within a part, vertices are welded by exact position, so every edge is shared by
//! exactly two triangles, traversed in opposite directions.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use crate::scene::Mesh;

/// An axis-aligned box footprint on the ground plane: x in `min.x..max.x`, z in `min.y..max.y`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub min: Vec2,
    pub max: Vec2,
}

impl Rect {
    pub fn new(min: Vec2, max: Vec2) -> Self {
        Self { min, max }
    }

    /// A rectangle of the given size centred on the origin.
    pub fn centered(size: Vec2) -> Self {
        Self { min: -size * 0.5, max: size * 0.5 }
    }

    pub fn size(&self) -> Vec2 {
        self.max - self.min
    }

    pub fn center(&self) -> Vec2 {
        (self.min + self.max) * 0.5
    }

    /// Grown by `d` on every side (shrunk where `d < 0`).
    pub fn grown(&self, d: f32) -> Rect {
        Rect { min: self.min - Vec2::splat(d), max: self.max + Vec2::splat(d) }
    }
}

/// Window recesses on the four facades of a [`Tier`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Windows {
    /// Window columns on the facades facing ±z (running along x) and on those facing ±x.
    pub cols: [u32; 2],
    /// Window rows, the same on every facade so that the facades meet corner to corner.
    pub rows: u32,
    /// Fraction of a column's width that is window (the rest is pier), in (0, 1).
    pub width_frac: f32,
    /// Fraction of a row's height that is window (the rest is spandrel), in (0, 1).
    pub height_frac: f32,
    /// How far the window pane sits behind the facade, in metres.
    pub depth: f32,
}

/// A box-shaped storey group whose facades carry recessed windows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tier {
    pub footprint: Rect,
    pub y0: f32,
    pub y1: f32,
    pub windows: Windows,
}

/// Collects parts into one [`Mesh`].
#[derive(Default)]
pub struct MeshBuilder {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
    weld: HashMap<[u32; 3], u32>,
}

impl MeshBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    pub fn finish(self) -> Mesh {
        Mesh { positions: self.positions, indices: self.indices }
    }

    /// Starts a new part: welding never joins vertices of different parts, so touching parts
    /// keep their own (closed) surfaces.
    fn begin_part(&mut self) {
        self.weld.clear();
    }

    /// The index of the vertex at `p` in the current part, added if new.
    fn vertex(&mut self, p: Vec3) -> u32 {
        // Adding +0.0 turns -0.0 into +0.0, so equal positions have equal bits.
        let p = p + Vec3::ZERO;
        let key = p.to_array().map(f32::to_bits);
        let next = self.positions.len() as u32;
        *self.weld.entry(key).or_insert_with(|| {
            self.positions.push(p.to_array());
            next
        })
    }

    fn triangle(&mut self, a: u32, b: u32, c: u32) {
        self.indices.extend_from_slice(&[a, b, c]);
    }

    /// A planar convex quad given counter-clockwise as seen from its front.
    fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.triangle(a, b, c);
        self.triangle(a, c, d);
    }

    /// A closed convex solid from its faces (each a planar convex polygon without collinear
    /// corners, in either winding). Each face is turned to face away from the solid's centre,
    /// which is outward for a convex solid, then fanned from its first corner.
    pub fn convex_solid(&mut self, faces: &[&[Vec3]]) {
        self.begin_part();
        let corners: Vec<Vec3> = faces.iter().flat_map(|f| f.iter().copied()).collect();
        let centre = corners.iter().copied().sum::<Vec3>() / corners.len() as f32;
        for face in faces {
            let face_centre = face.iter().copied().sum::<Vec3>() / face.len() as f32;
            let normal = (face[1] - face[0]).cross(face[2] - face[0]);
            let ids: Vec<u32> = face.iter().map(|&p| self.vertex(p)).collect();
            let outward = normal.dot(face_centre - centre) > 0.0;
            for k in 1..ids.len() - 1 {
                if outward {
                    self.triangle(ids[0], ids[k], ids[k + 1]);
                } else {
                    self.triangle(ids[0], ids[k + 1], ids[k]);
                }
            }
        }
    }

    /// A closed axis-aligned box over `footprint` from `y0` to `y1` (12 triangles).
    pub fn cuboid(&mut self, footprint: Rect, y0: f32, y1: f32) {
        let c = box_corners(footprint, y0, y1);
        let f = |i: [usize; 4]| i.map(|k| c[k]);
        self.convex_solid(&[
            &f([0, 1, 2, 3]),
            &f([4, 5, 6, 7]),
            &f([0, 1, 5, 4]),
            &f([1, 2, 6, 5]),
            &f([2, 3, 7, 6]),
            &f([3, 0, 4, 7]),
        ]);
    }

    /// A gable roof (triangular prism, 8 triangles) over `footprint` from `y0`, its ridge
    /// `height` above, running along x when `along_x`, else along z.
    pub fn gable_roof(&mut self, footprint: Rect, y0: f32, height: f32, along_x: bool) {
        self.hip_roof(footprint, y0, height, along_x, 0.0);
    }

    /// A hip roof (8 triangles): like a gable whose ridge ends are pulled in by `hip` metres,
    /// sloping the gable ends. `hip` is clamped short of meeting in the middle.
    pub fn hip_roof(&mut self, footprint: Rect, y0: f32, height: f32, along_x: bool, hip: f32) {
        // Work in (length, width) axes so one code path serves both ridge directions.
        let to_world = |l: f32, w: f32, y: f32| if along_x { Vec3::new(l, y, w) } else { Vec3::new(w, y, l) };
        let (l0, l1, w0, w1) = if along_x {
            (footprint.min.x, footprint.max.x, footprint.min.y, footprint.max.y)
        } else {
            (footprint.min.y, footprint.max.y, footprint.min.x, footprint.max.x)
        };
        let hip = hip.clamp(0.0, (l1 - l0) * 0.45);
        let wc = (w0 + w1) * 0.5;
        let y1 = y0 + height;
        let (a, b, c, d) = (to_world(l0, w0, y0), to_world(l1, w0, y0), to_world(l1, w1, y0), to_world(l0, w1, y0));
        let (r0, r1) = (to_world(l0 + hip, wc, y1), to_world(l1 - hip, wc, y1));
        self.convex_solid(&[&[a, b, c, d], &[a, b, r1, r0], &[c, d, r0, r1], &[d, a, r0], &[b, c, r1]]);
    }

    /// A square-based pyramid (6 triangles): spires and finials.
    pub fn pyramid(&mut self, footprint: Rect, y0: f32, height: f32) {
        let c = box_corners(footprint, y0, y0);
        let centre = footprint.center();
        let apex = Vec3::new(centre.x, y0 + height, centre.y);
        self.convex_solid(&[
            &[c[0], c[1], c[2], c[3]],
            &[c[0], c[1], apex],
            &[c[1], c[2], apex],
            &[c[2], c[3], apex],
            &[c[3], c[0], apex],
        ]);
    }

    /// A low wall around the edge of a flat roof: four boxes of `thickness`, `height` tall.
    pub fn parapet(&mut self, footprint: Rect, y0: f32, height: f32, thickness: f32) {
        let (lo, hi) = (footprint.min, footprint.max);
        let t = thickness;
        let y1 = y0 + height;
        // Long walls span the full x extent; the short ones fit between them.
        self.cuboid(Rect::new(lo, Vec2::new(hi.x, lo.y + t)), y0, y1);
        self.cuboid(Rect::new(Vec2::new(lo.x, hi.y - t), hi), y0, y1);
        self.cuboid(Rect::new(Vec2::new(lo.x, lo.y + t), Vec2::new(lo.x + t, hi.y - t)), y0, y1);
        self.cuboid(Rect::new(Vec2::new(hi.x - t, lo.y + t), Vec2::new(hi.x, hi.y - t)), y0, y1);
    }

    /// A box whose four facades carry a grid of recessed windows (see [`tier_triangles`] for its
    /// size). Each facade is a grid of cells cut by the window edges; wall cells are flat quads,
    /// window cells are dents (four reveal quads and a pane set back by the window depth). The
    /// roof and floor are fans from their centres, since their edges hold every grid line of
    /// the facades below and above them.
    pub fn tier(&mut self, tier: &Tier) {
        self.begin_part();
        let Rect { min, max } = tier.footprint;
        let w = tier.windows;
        let heights = grid_lines(tier.y0, tier.y1, w.rows, w.height_frac, 0.35);
        // Facades in counter-clockwise order seen from above, each running from one corner to
        // the next: facing -z, -x, +z, +x.
        let facades = [
            (Vec2::new(max.x, min.y), Vec2::new(min.x, min.y), w.cols[0], Vec3::NEG_Z),
            (Vec2::new(min.x, min.y), Vec2::new(min.x, max.y), w.cols[1], Vec3::NEG_X),
            (Vec2::new(min.x, max.y), Vec2::new(max.x, max.y), w.cols[0], Vec3::Z),
            (Vec2::new(max.x, max.y), Vec2::new(max.x, min.y), w.cols[1], Vec3::X),
        ];
        let mut top_loop = Vec::new();
        let mut bottom_loop = Vec::new();
        for &(start, end, cols, normal) in &facades {
            let along = grid_lines(0.0, 1.0, cols, w.width_frac, 0.5);
            let point_at = |i: usize| -> Vec2 {
                // Exact corners, so that neighbouring facades weld at their shared edge.
                match i {
                    0 => start,
                    _ if i + 1 == along.len() => end,
                    _ => start.lerp(end, along[i]),
                }
            };
            let grid: Vec<Vec<u32>> = (0..along.len())
                .map(|i| {
                    let p = point_at(i);
                    heights.iter().map(|&y| self.vertex(Vec3::new(p.x, y, p.y))).collect()
                })
                .collect();
            for i in 0..along.len() - 1 {
                for j in 0..heights.len() - 1 {
                    let outer = [grid[i][j], grid[i + 1][j], grid[i + 1][j + 1], grid[i][j + 1]];
                    if i % 2 == 1 && j % 2 == 1 {
                        self.recess(outer, normal * -w.depth);
                    } else {
                        self.quad(outer[0], outer[1], outer[2], outer[3]);
                    }
                }
            }
            // Each facade contributes its corners but the last (the next facade's first).
            for column in &grid[..grid.len() - 1] {
                bottom_loop.push(column[0]);
                top_loop.push(*column.last().expect("a facade has at least two height lines"));
            }
        }
        let centre = tier.footprint.center();
        let top_centre = self.vertex(Vec3::new(centre.x, tier.y1, centre.y));
        let bottom_centre = self.vertex(Vec3::new(centre.x, tier.y0, centre.y));
        let n = top_loop.len();
        for k in 0..n {
            self.triangle(top_centre, top_loop[k], top_loop[(k + 1) % n]);
            self.triangle(bottom_centre, bottom_loop[(k + 1) % n], bottom_loop[k]);
        }
    }

    /// Dents the facade cell `outer` (counter-clockwise from outside) by `offset` (pointing into
    /// the building): four reveals joining the cell's edges to the pane, then the pane.
    fn recess(&mut self, outer: [u32; 4], offset: Vec3) {
        let inner = outer.map(|v| self.vertex(Vec3::from(self.positions[v as usize]) + offset));
        for k in 0..4 {
            let n = (k + 1) % 4;
            self.quad(outer[k], outer[n], inner[n], inner[k]);
        }
        self.quad(inner[0], inner[1], inner[2], inner[3]);
    }
}

/// The triangles [`MeshBuilder::tier`] emits for `windows`: per facade with `c` columns and `r`
/// rows, `16cr + 4c + 4r + 2`; plus `2c + 1` per facade in each of the roof and floor fans.
#[cfg(test)]
fn tier_triangles(windows: &Windows) -> usize {
    let r = windows.rows as usize;
    windows
        .cols
        .iter()
        .map(|&c| {
            let c = c as usize;
            2 * (16 * c * r + 4 * c + 4 * r + 2) + 2 * 2 * (2 * c + 1)
        })
        .sum()
}

/// Positions from `lo` to `hi` that cut `count` equal bays, each holding an opening of
/// `frac` of its size placed at `offset` (0 bottom/left, 0.5 centred) of the remaining space:
/// `[lo, open₀, close₀, open₁, close₁, …, hi]`. Openings are the odd intervals.
fn grid_lines(lo: f32, hi: f32, count: u32, frac: f32, offset: f32) -> Vec<f32> {
    let bay = (hi - lo) / count.max(1) as f32;
    let opening = bay * frac;
    let before = (bay - opening) * offset;
    let mut lines = vec![lo];
    for k in 0..count {
        let start = lo + bay * k as f32 + before;
        lines.push(start);
        lines.push(start + opening);
    }
    lines.push(hi);
    lines
}

/// Corners of a box: the bottom four counter-clockwise from above, then the top four.
fn box_corners(r: Rect, y0: f32, y1: f32) -> [Vec3; 8] {
    let xz = [r.min, Vec2::new(r.max.x, r.min.y), r.max, Vec2::new(r.min.x, r.max.y)];
    std::array::from_fn(|i| {
        let p = xz[i % 4];
        Vec3::new(p.x, if i < 4 { y0 } else { y1 }, p.y)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every directed edge of a closed, consistently wound surface has exactly one reverse twin.
    fn assert_closed(mesh: &Mesh) {
        let mut edges = HashMap::new();
        for t in mesh.indices.chunks_exact(3) {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "edge {a}->{b} used {n} times");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}->{b} has no twin");
        }
    }

    fn signed_volume(mesh: &Mesh) -> f32 {
        mesh.triangles().map(|[a, b, c]| a.dot(b.cross(c)) / 6.0).sum()
    }

    #[test]
    fn parts_are_closed_outward_and_sized_as_documented() {
        let windows = Windows { cols: [3, 2], rows: 4, width_frac: 0.5, height_frac: 0.6, depth: 0.3 };
        let tier = Tier { footprint: Rect::centered(Vec2::new(12.0, 9.0)), y0: 0.0, y1: 12.0, windows };
        let mut b = MeshBuilder::new();
        b.tier(&tier);
        assert_eq!(b.triangle_count(), tier_triangles(&windows));
        let mesh = b.finish();
        assert_closed(&mesh);
        // The box less the window dents: 12 windows of 2 x 1.8 m on each ±z facade, 8 of
        // 2.25 x 1.8 m on each ±x facade, all 0.3 m deep.
        let expected = 12.0 * 9.0 * 12.0 - 0.3 * 1.8 * (2.0 * 12.0 * 2.0 + 2.0 * 8.0 * 2.25);
        let v = signed_volume(&mesh);
        assert!((v - expected).abs() < 0.05, "tier volume {v}, expected {expected}");

        let mut b = MeshBuilder::new();
        let r = Rect::centered(Vec2::new(4.0, 6.0));
        b.cuboid(r, 0.0, 2.0);
        b.hip_roof(r, 2.0, 1.5, false, 1.0);
        b.gable_roof(r, 2.0, 1.5, true);
        b.pyramid(r, 0.0, 3.0);
        b.parapet(r, 0.0, 1.0, 0.3);
        assert_eq!(b.triangle_count(), 12 + 8 + 8 + 6 + 48);
        let mesh = b.finish();
        assert_closed(&mesh);
        // Box 48, hip roof 12 + 2 end pyramids of 2, gable 18, pyramid 24, parapet 2.4 + 3.24.
        let expected = 48.0 + 16.0 + 18.0 + 24.0 + 5.64;
        let v = signed_volume(&mesh);
        assert!((v - expected).abs() < 0.01, "parts volume {v}, expected {expected}");
    }
}
