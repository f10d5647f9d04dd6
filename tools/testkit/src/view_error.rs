//! From-region error as a user sees it (issue 22): from a viewpoint inside a cell, the share of
//! what the whole scene shows that the cell's answer lacks. The truth is a full view of the whole
//! scene at that viewpoint, so it is exact there and nothing needs to converge, unlike a count of
//! missed (cell, object) pairs against a sampled reference.
//!
//! - [`wrong_share`]: over a cube map, by solid angle;
//! - [`frame_error`]: over one rendered frame, by pixels (GVS++'s erroneous-pixel measure);
//! - [`random_viewpoint`]: a uniformly random point strictly inside a cell, from a seeded [`Rng`];
//! - [`dov_excess`]: how often a point's DoV exceeds the cell's stored DoV.

use std::collections::HashMap;

use glam::Vec3;
use hdov::dov::{CubeMap, IdCube, PointDov};
use hdov::geom::Aabb;

use crate::scenes::Rng;

/// What a viewpoint sees that an answer lacks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WrongShare {
    /// Solid angle (steradians) of texels showing an object the answer lacks.
    pub wrong: f64,
    /// Solid angle of all texels that show an object.
    pub seen: f64,
    /// The lacking objects and the solid angle each shows, largest first.
    pub missing: Vec<(u32, f64)>,
}

impl WrongShare {
    /// `wrong / seen`, 0 where nothing is seen.
    pub fn share(&self) -> f64 {
        if self.seen > 0.0 { self.wrong / self.seen } else { 0.0 }
    }
}

/// The texels of `ids` (measured with `cube`'s weights) whose object `answer_has` is false for,
/// weighed by their solid angle, against all texels that show an object. A texel whose nearest
/// surface is a back face counts for that object, as the DoV measurement counts it.
pub fn wrong_share(ids: &IdCube, cube: &CubeMap, answer_has: impl Fn(u32) -> bool) -> WrongShare {
    assert_eq!(ids.resolution, cube.resolution(), "the id cube and the weights are of one resolution");
    let r = ids.resolution as usize;
    let weights = cube.face_weights();
    let mut out = WrongShare::default();
    let mut missing: HashMap<u32, f64> = HashMap::new();
    for face in 0..6 {
        for (k, &w) in weights.iter().enumerate() {
            let Some(object) = ids.object_at(face * r * r + k) else { continue };
            out.seen += w;
            if !answer_has(object) {
                out.wrong += w;
                *missing.entry(object).or_default() += w;
            }
        }
    }
    out.missing = missing.into_iter().collect();
    out.missing.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    out
}

/// GVS++'s measure: of the pixels of one frame that show an object (`pixels`: object id and its
/// pixel count), the share showing one that `answer_has` is false for.
pub fn frame_error(pixels: impl IntoIterator<Item = (u32, usize)>, answer_has: impl Fn(u32) -> bool) -> f64 {
    let (mut seen, mut wrong) = (0usize, 0usize);
    for (id, n) in pixels {
        seen += n;
        if !answer_has(id) {
            wrong += n;
        }
    }
    if seen == 0 { 0.0 } else { wrong as f64 / seen as f64 }
}

/// Uniformly random points strictly inside `cell` (kept 0.1 % of each edge from its faces, so
/// never on a corner, a face or a neighbour's border), from `rng`. Unlike the build's sample
/// points (corners and Halton points), they follow no pattern a sampler could have matched.
pub fn random_viewpoint(cell: &Aabb, rng: &mut Rng) -> Vec3 {
    let margin = cell.extent() * 1e-3;
    let (lo, hi) = (cell.min + margin, cell.max - margin);
    Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z))
}

/// Whether `at` lies within `distance` of a surface of `scene` (its objects' world boxes `bounds`,
/// [`hdov::Scene::all_object_bounds`]). A truth whose cube faces clip at forward depth `near`
/// cuts a hole into a surface nearer than `√3 · near` (a texel's direction is up to √3 times
/// longer than its forward depth) and shows what lies behind it (the inside of a wall 1 cm
/// away), which a viewer there would not see: such viewpoints are redrawn, as those inside
/// geometry are. O(objects + the triangles of those whose boxes lie within `distance`).
pub fn nearer_than(scene: &hdov::Scene, bounds: &[Aabb], at: Vec3, distance: f32) -> bool {
    let around = Aabb::new(at - Vec3::splat(distance), at + Vec3::splat(distance));
    (0..scene.objects.len()).filter(|&o| bounds[o].intersects(&around)).any(|o| {
        scene.object_triangles(o).any(|t| closest_on_triangle(at, t).distance_squared(at) < distance * distance)
    })
}

/// The point of triangle `[a, b, c]` nearest `p` (Ericson, *Real-Time Collision Detection*,
/// 5.1.5).
pub fn closest_on_triangle(p: Vec3, [a, b, c]: [Vec3; 3]) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let sum = va + vb + vc;
    if sum <= 0.0 {
        // A triangle of no area (collinear corners): the nearest of its corners.
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p)))
            .unwrap_or(a);
    }
    a + ab * (vb / sum) + ac * (vc / sum)
}

/// Of the objects `point` sees, how many it sees with more DoV than `stored` (the cell's DoV of
/// an object, 0 where the answer lacks it) plus `texels` centre texels plus `relative` of its
/// own DoV: `(exceeding, seen)`.
pub fn dov_excess(
    point: &PointDov,
    stored: impl Fn(u32) -> f64,
    texel: f64,
    texels: f64,
    relative: f64,
) -> (usize, usize) {
    let exceeding = point.objects.iter().filter(|&&(o, d)| d > stored(o) + texels * texel + relative * d).count();
    (exceeding, point.objects.len())
}
