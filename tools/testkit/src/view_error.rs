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
