//! Where a cell is sampled: the one Halton sequence that every sampler draws interior points
//! from (fixed interior points, adaptive seeds, probe points, the dense reference), and the one
//! rule that leaves out a measured point lying inside geometry. The samplers themselves are
//! [`super::precompute`] (corners and interior points), [`super::adaptive`] and [`super::probe`].

use std::collections::HashSet;

use glam::Vec3;

use super::PointDov;
use crate::geom::Aabb;

/// The `k`-th (k ≥ 1) point of the Halton sequence in bases 2, 3, 5, in [0, 1)³.
pub fn halton3(k: u32) -> Vec3 {
    fn radical_inverse(mut k: u32, base: u32) -> f32 {
        let (mut inv, mut f) = (0.0f64, 1.0f64 / base as f64);
        while k > 0 {
            inv += f * (k % base) as f64;
            k /= base;
            f /= base as f64;
        }
        inv as f32
    }
    Vec3::new(radical_inverse(k, 2), radical_inverse(k, 3), radical_inverse(k, 5))
}

/// The `k`-th Halton point of `cell` (k ≥ 1): the same relative position in every cell.
pub fn halton_point(cell: &Aabb, k: u32) -> Vec3 {
    cell.min + halton3(k) * cell.extent()
}

/// The `count` interior sample points of a cell box, Halton points 1 to `count`
/// ([`super::precompute::PrecomputeOptions::interior_samples`]).
pub fn interior_points(cell: &Aabb, count: u32) -> Vec<Vec3> {
    (1..=count).map(|k| halton_point(cell, k)).collect()
}

/// Whether a measured point lies inside geometry: more than half its sphere of directions sees
/// back faces. Such a point's view does not count
/// ([`super::precompute::PrecomputeOptions::skip_inside_points`]); probing tells its own points
/// by the same majority over 26 rays (`probe`).
pub fn is_inside(p: &PointDov) -> bool {
    p.back_face > 0.5
}

/// The objects that the points outside geometry see.
pub fn seen_by<'a>(points: impl IntoIterator<Item = &'a PointDov>) -> HashSet<u32> {
    points.into_iter().filter(|p| !is_inside(p)).flat_map(|p| p.objects.iter().map(|e| e.0)).collect()
}
