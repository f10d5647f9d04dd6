//! Where a cell is sampled: the one Halton sequence that every sampler draws interior points
//! from (fixed interior points, adaptive seeds, probe points, the dense reference), and the one
//! rule that leaves out a measured point lying inside geometry. The samplers themselves are
//! [`super::precompute`] and the samplers ([`super::sampler`]).

use std::collections::HashSet;

use glam::{Mat3, Quat, Vec3};

use super::PointDov;
use crate::grid::ViewCell;
use crate::rng::Rng;

/// `k` written in `base` and mirrored about the point: the Halton sequence's coordinate in
/// that base, in [0, 1).
fn radical_inverse(mut k: u32, base: u32) -> f32 {
    let (mut inv, mut f) = (0.0f64, 1.0f64 / base as f64);
    while k > 0 {
        inv += f * (k % base) as f64;
        k /= base;
        f /= base as f64;
    }
    inv as f32
}

/// The `k`-th (k ≥ 1) point of the Halton sequence in bases 2, 3, 5, in [0, 1)³.
pub fn halton3(k: u32) -> Vec3 {
    Vec3::new(radical_inverse(k, 2), radical_inverse(k, 3), radical_inverse(k, 5))
}

/// A cell's region rays: points of the Halton sequence in bases 2, 3, 5, 7, 11, the first three
/// coordinates a ray's origin in the cell and the last two its direction, uniform on the sphere,
/// so that origins and directions together spread evenly over the cell's rays. Each cell shifts
/// the sequence by its own offset (a Cranley–Patterson rotation, seeded by the cell box's bits):
/// neighbouring cells then cast different rays, not the same pattern moved by a cell, and what
/// one misses another may meet.
pub struct RegionRays {
    cell: ViewCell,
    shift: [f32; 5],
}

/// The seed of a cell's own samples, from its box's bits (and its places: the parts of one
/// lattice cell draw different samples).
fn cell_seed(cell: &ViewCell) -> u64 {
    let b = cell.bounds;
    let seed = b.min.to_array().iter().chain(&b.max.to_array()).fold(0x9e37_79b9_7f4a_7c15u64, |h, c| {
        (h ^ u64::from(c.to_bits())).wrapping_mul(0xbf58_476d_1ce4_e5b9)
    });
    if cell.places == crate::grid::ALL_PLACES { seed } else { (seed ^ cell.places).wrapping_mul(0xbf58_476d_1ce4_e5b9) }
}

impl RegionRays {
    /// The rays of `cell`, their origins where its viewers stand ([`ViewCell::point`]).
    pub fn new(cell: &ViewCell) -> Self {
        let mut rng = Rng::new(cell_seed(cell));
        Self { cell: *cell, shift: std::array::from_fn(|_| rng.unit()) }
    }

    /// The ray of one point of a [`RegionSequence`]: its origin and unit direction.
    pub fn ray(&self, h: &[f32; 5]) -> (Vec3, Vec3) {
        let u = |i: usize| (h[i] + self.shift[i]).fract();
        let origin = self.cell.point(Vec3::new(u(0), u(1), u(2)));
        let z = 1.0 - 2.0 * u(3);
        let phi = std::f32::consts::TAU * u(4);
        let r = (1.0 - z * z).max(0.0).sqrt();
        (origin, Vec3::new(r * phi.cos(), z, r * phi.sin()))
    }
}

/// A cell's region views: the GPU backend's form of its region rays
/// ([`super::DovBackend::region_views`]). As many small cube maps of N² texels a face as it
/// takes to hold the region rays' count, each from its own origin where the cell's viewers
/// stand (Halton points 1, 2, … shifted by the cell's own offset, as [`RegionRays`] shifts its
/// origins) and turned by its own random rotation, so that the views' texels together point
/// every way from all over the cell rather than along one cube's N² directions. A rasteriser
/// draws a whole view at once where a ray caster traces its texels one by one; what a cell
/// sees through a gap depends on where in the cell a ray starts, which small views (many
/// origins) sample best (docs/dov.md, "Region views on the GPU").
pub struct RegionViews {
    /// Per view, its origin and its turn (world direction = turn · the cube map's direction).
    views: Vec<(Vec3, Mat3)>,
    cube: super::CubeMap,
}

impl RegionViews {
    /// The views of `cell`, `resolution` texels a face edge each, that hold at least `rays`
    /// texels.
    pub fn new(cell: &ViewCell, rays: u32, resolution: u32) -> Self {
        let cube = super::CubeMap::new(resolution);
        let count = (rays as usize).div_ceil(cube.texel_count());
        let mut rng = Rng::new(cell_seed(cell) ^ 0x005e_ed0f_7ea1_u64);
        let shift = Vec3::new(rng.unit(), rng.unit(), rng.unit());
        let views = (1..=count as u32)
            .map(|k| {
                let h = halton3(k) + shift;
                let origin = cell.point(h - h.floor());
                (origin, Mat3::from_quat(random_rotation(&mut rng)))
            })
            .collect();
        Self { views, cube }
    }

    /// The views' origins and turns, in view order.
    pub fn views(&self) -> &[(Vec3, Mat3)] {
        &self.views
    }

    /// The cube map of one view.
    pub fn cube(&self) -> &super::CubeMap {
        &self.cube
    }

    /// Texels over all views: what [`super::DovBackend::region_views`] returns ids for.
    pub fn texel_count(&self) -> usize {
        self.views.len() * self.cube.texel_count()
    }

    /// The ray through the centre of texel `index` of all views' texels (view after view, each
    /// in [`super::IdCube`]'s order): its view's origin and unit direction.
    pub fn ray(&self, index: usize) -> (Vec3, Vec3) {
        let per_view = self.cube.texel_count();
        let (origin, turn) = self.views[index / per_view];
        let r = self.cube.resolution() as usize;
        let t = index % per_view;
        let (face, row, col) = (t / (r * r), (t / r % r) as u32, (t % r) as u32);
        (origin, (turn * self.cube.texel_direction(face, row, col)).normalize())
    }
}

/// A rotation drawn uniformly (Shoemake's method).
fn random_rotation(rng: &mut Rng) -> Quat {
    let (u1, u2, u3) = (rng.unit(), std::f32::consts::TAU * rng.unit(), std::f32::consts::TAU * rng.unit());
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    Quat::from_xyzw(a * u2.sin(), a * u2.cos(), b * u3.sin(), b * u3.cos()).normalize()
}

/// The region rays' Halton points 1 to `count` in bases 2, 3, 5, 7, 11, before any cell's shift:
/// the same for every cell, so a build computes them once, not once per cell.
pub struct RegionSequence(Vec<[f32; 5]>);

impl RegionSequence {
    pub fn new(count: u32) -> Self {
        Self((1..=count).map(|k| [2, 3, 5, 7, 11].map(|base| radical_inverse(k, base))).collect())
    }

    /// Point `k` (from 0) is the sequence's point `k + 1`.
    pub fn points(&self) -> &[[f32; 5]] {
        &self.0
    }
}

/// The `k`-th Halton point of `cell` (k ≥ 1): the same relative position in every whole cell,
/// and among the places of one that is not ([`ViewCell::point`]).
pub fn halton_point(cell: &ViewCell, k: u32) -> Vec3 {
    cell.point(halton3(k))
}

/// The `count` interior sample points of a cell, Halton points 1 to `count` (the `interior`
/// sampler).
pub fn interior_points(cell: &ViewCell, count: u32) -> Vec<Vec3> {
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
