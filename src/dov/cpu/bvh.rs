//! The CPU backend's two-level BVH: one bottom level per base mesh that two or more objects
//! instance, one over the world-space triangles of every other object, and the triangles with
//! their normals precomputed for the (watertight) ray test.

use glam::{Affine3A, Vec3, Vec3A, Vec3Swizzles};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb as BvhAabb,
    bvh2::reinsertion::ReinsertionOptimizer,
    cwbvh::{CwBvh, bvh2_to_cwbvh::bvh2_to_cwbvh},
    ploc::PlocBuilder,
    splits::split_aabbs_preset,
    ray::Ray,
    triangle::Triangle,
};

use crate::dov::{BACK_FACE_BIT, NO_OBJECT, check_object_count};
use crate::error::Result;
use crate::scene::Scene;

/// obvhs's lower bound on a child's entry distance (its private `EPSILON`).
pub(super) const NODE_TMIN: f32 = 0.0001;

/// One ray-triangle hit.
#[derive(Clone, Copy, Debug)]
pub(super) struct Hit {
    pub(super) t: f32,
    pub(super) obj: u32,
    pub(super) back: bool,
    /// Instance and triangle (in its BLAS's order): where the next texel's ray looks first.
    pub(super) instance: u32,
    pub(super) tri: u32,
}

impl Hit {
    /// The texel id this hit gives: its object, with [`BACK_FACE_BIT`] when seen from behind.
    pub(super) fn id(&self) -> u32 {
        if self.back { self.obj | BACK_FACE_BIT } else { self.obj }
    }
}

/// The largest BLAS built with obvhs's very slow preset; bigger ones get the slow preset.
const VERY_SLOW_BUILD_MAX_TRIANGLES: usize = 1 << 20;

/// What one BLAS is built from.
pub(super) enum BlasSource {
    /// World-space triangles of these objects.
    World(Vec<usize>),
    /// A base mesh in model space.
    Mesh(usize),
}

/// One bottom-level BVH and its triangles in the BVH's primitive order (no indirection while
/// tracing).
pub(super) struct Blas {
    pub(super) bvh: CwBvh,
    pub(super) triangles: Vec<RayTriangle>,
    /// Object index of each triangle: filled for the world-space BLAS, empty for a base mesh's
    /// (its instance carries the object).
    pub(super) objects: Vec<u32>,
}

/// One primitive of the top level.
pub(super) struct Instance {
    pub(super) blas: u32,
    /// The object, or [`NO_OBJECT`] for the world-space BLAS (objects per triangle).
    pub(super) object: u32,
    /// World → model space; `None` for the world-space BLAS.
    pub(super) to_model: Option<Affine3A>,
}

impl Blas {
    /// The hit on triangle `i` at `t` through instance `inst` (number `ii`), seen from behind
    /// (`back`) or not. The back-face test is done in the triangle's own space: with n the
    /// model-space normal and M the linear part of the transform, the world normal of the
    /// (winding-corrected) world triangle is |det M|·M⁻ᵀn, so its sign against M·d is the sign of
    /// n·d.
    #[inline(always)]
    pub(super) fn hit(&self, inst: &Instance, ii: usize, i: usize, t: f32, back: bool) -> Hit {
        let obj = if inst.object == NO_OBJECT { self.objects[i] } else { inst.object };
        Hit { t, obj, back, instance: ii as u32, tri: i as u32 }
    }

    /// The hit of `ray` (in this BLAS's space) on triangle `i` at `t`.
    #[inline(always)]
    pub(super) fn ray_hit(&self, inst: &Instance, ii: usize, i: usize, t: f32, ray: &Ray) -> Hit {
        self.hit(inst, ii, i, t, self.triangles[i].seen_from_behind(ray.direction))
    }
}

/// A triangle as the ray test reads it: its corners and its normal. The test is watertight: a
/// ray cannot pass between two triangles that share an edge (docs/dov.md, "Watertight
/// triangles"). Aligned to a cache line, so that a triangle test touches one line, not two (its
/// 64 bytes at `Vec3A`'s alignment of 16 straddled two lines three times in four).
#[derive(Clone, Copy, Debug)]
#[repr(align(64))]
pub(super) struct RayTriangle {
    pub(super) v0: Vec3A,
    pub(super) v1: Vec3A,
    pub(super) v2: Vec3A,
    /// `(v0 − v1) × (v2 − v0)`: minus the counter-clockwise normal `(v1 − v0) × (v2 − v0)`,
    /// exactly (negation is exact in floating point).
    pub(super) n: Vec3A,
}

impl RayTriangle {
    pub(super) fn new(t: &Triangle) -> Self {
        Self { v0: t.v0, v1: t.v1, v2: t.v2, n: cross(t.v0 - t.v1, t.v2 - t.v0) }
    }

    /// `t` of the hit with `tmin ≤ t ≤ tmax`, or infinity.
    ///
    /// The ray meets the triangle where it lies on the same side of the three planes through its
    /// origin and an edge: the signs of `d · (a × b)` for the corners `a`, `b` of each edge taken
    /// from the origin (zero, a ray through an edge, counts as either side). Each of those
    /// numbers is computed from its edge's two corners alone, so a neighbour sharing the edge
    /// computes the same number, or its exact negation where it runs the other way (products
    /// commute, and `x − y = −(y − x)` exactly): the two triangles can never both reject the ray
    /// by rounding. Möller–Trumbore's barycentrics, computed from each triangle's own first corner,
    /// can, and rays through seams are common where a scene and its viewpoints lie on a grid.
    #[inline(always)]
    pub(super) fn intersect(&self, ray: &Ray) -> f32 {
        let d = ray.direction;
        let (a, b, c) = (self.v0 - ray.origin, self.v1 - ray.origin, self.v2 - ray.origin);
        let (u, v, w) = (d.dot(cross(b, c)), d.dot(cross(c, a)), d.dot(cross(a, b)));
        let inv_det = 1.0 / self.n.dot(d);
        if (u >= 0.0 && v >= 0.0 && w >= 0.0) || (u <= 0.0 && v <= 0.0 && w <= 0.0) {
            // A ray along the plane (n · d = 0) gets t = ±∞ or NaN, out of every range.
            let t = self.n.dot(a) * inv_det;
            if t >= ray.tmin && t <= ray.tmax.min(f32::MAX) {
                return t;
            }
        }
        f32::INFINITY
    }

    /// Whether a ray along `dir` (in this triangle's space) sees its back: the counter-clockwise
    /// normal points along the ray.
    #[inline(always)]
    pub(super) fn seen_from_behind(&self, dir: Vec3A) -> bool {
        self.n.dot(dir) < 0.0
    }
}

/// `a × b` as the packet test computes it lane by lane (x = a.y·b.z − a.z·b.y, …), by plain
/// products and differences. glam's own `cross` fuses them into FMAs where glam is compiled with
/// FMA (`-C target-cpu=native`, say), and then `a × b` is no longer exactly `−(b × a)`, which the
/// watertight test rests on.
#[inline(always)]
pub(super) fn cross(a: Vec3A, b: Vec3A) -> Vec3A {
    a.yzx() * b.zxy() - a.zxy() * b.yzx()
}

/// Builds one BLAS; `None` when it has no triangles.
pub(super) fn build_blas(scene: &Scene, source: &BlasSource) -> Option<Blas> {
    let (tris, objects): (Vec<Triangle>, Vec<u32>) = match source {
        BlasSource::World(objects) => {
            let mut tris = Vec::new();
            let mut objs = Vec::new();
            for &i in objects {
                let mirrored = scene.objects[i].transform.determinant() < 0.0;
                for t in scene.object_triangles(i) {
                    let t = if mirrored { [t[0], t[2], t[1]] } else { t };
                    tris.push(triangle(t));
                    objs.push(i as u32);
                }
            }
            (tris, objs)
        }
        BlasSource::Mesh(m) => (scene.meshes[*m].mesh.triangles().map(triangle).collect(), Vec::new()),
    };
    if tris.is_empty() {
        return None;
    }
    // Pre-split builds: per ray, the slow preset took 33 % less time than the medium one on the
    // default city and the very slow one 19 % less on the 110 k-triangle engine (the slow one
    // 15 %), but the very slow build took 6.5× the medium one on the city's 2.2 M triangles
    // (the slow 2.5×): the very slow one only where it stays cheap (docs/decisions.md, 42).
    let params = if tris.len() <= VERY_SLOW_BUILD_MAX_TRIANGLES {
        BvhBuildParams::very_slow_build()
    } else {
        BvhBuildParams::slow_build()
    };
    let bvh = build_cwbvh_padded(&tris, params);
    let triangles = bvh.primitive_indices.iter().map(|&i| RayTriangle::new(&tris[i as usize])).collect();
    let objects =
        if objects.is_empty() { objects } else { bvh.primitive_indices.iter().map(|&i| objects[i as usize]).collect() };
    Some(Blas { bvh, triangles, objects })
}

/// obvhs's `build_cwbvh_from_tris` with every leaf box grown by a little more than a box test's
/// rounding ([`padded_box`]). A ray through an edge that two triangles share lies on the faces of
/// both their boxes, where the slab test's rounding decides whether it enters either: a flat box
/// (a wall's triangles in a plane) can be missed by every ray along its rim, and the watertight
/// triangle test never sees them.
fn build_cwbvh_padded(tris: &[Triangle], config: BvhBuildParams) -> CwBvh {
    let mut aabbs: Vec<BvhAabb> = tris.iter().map(Triangle::aabb).collect();
    let mut indices: Vec<u32> = (0..tris.len() as u32).collect();
    if config.pre_split {
        let halves: Vec<f32> = aabbs.iter().map(BvhAabb::half_area).collect();
        let largest = halves.iter().copied().fold(0.0, f32::max);
        let mean = halves.iter().sum::<f32>() / halves.len() as f32;
        split_aabbs_preset(&mut aabbs, &mut indices, tris, mean, largest);
    }
    for b in &mut aabbs {
        *b = padded_box(*b);
    }
    let mut bvh2 = PlocBuilder::with_capacity(aabbs.len()).build(
        config.ploc_search_distance,
        &aabbs,
        indices,
        config.sort_precision,
        config.search_depth_threshold,
    );
    bvh2.uses_spatial_splits = config.pre_split;
    ReinsertionOptimizer::default().run(&mut bvh2, config.reinsertion_batch_ratio, None);
    bvh2_to_cwbvh(&bvh2, config.max_prims_per_leaf.clamp(1, 3), true, false)
}

/// `b` grown by 4e-6 of its largest coordinate and 1e-6 m: several times the rounding of a slab
/// test's `t` (a few ulps) at any distance up to the box's own coordinates.
fn padded_box(b: BvhAabb) -> BvhAabb {
    let pad = b.min.abs().max(b.max.abs()).max_element() * 4e-6 + 1e-6;
    BvhAabb::new(b.min - Vec3A::splat(pad), b.max + Vec3A::splat(pad))
}

pub(super) fn triangle(t: [Vec3; 3]) -> Triangle {
    Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }
}

/// World → model space of an affine, invertible transform whose inverse is finite; `None` for
/// any other (such objects are traced in world space, as the flat BVH did).
pub(super) fn inverse_affine(m: &glam::Mat4) -> Option<Affine3A> {
    if m.row(3) != glam::Vec4::W {
        return None;
    }
    let a = Affine3A::from_mat4(*m);
    let det = a.matrix3.determinant();
    if !(det.is_finite() && det.abs() > 1e-20) {
        return None;
    }
    let inv = a.inverse();
    inv.is_finite().then_some(inv)
}

/// An instance's world box grown by a little more than rounding, so that a ray whose model-space
/// hit lies on the mesh's boundary still enters the box in world space.
pub(super) fn padded(b: crate::geom::Aabb) -> BvhAabb {
    let pad = b.extent().max_element() * 1e-5 + b.min.abs().max(b.max.abs()).max_element() * 1e-6 + 1e-6;
    BvhAabb::new(Vec3A::from(b.min - Vec3::splat(pad)), Vec3A::from(b.max + Vec3::splat(pad)))
}

/// Every triangle of every object in world space, objects in index order, with its object index.
/// Mirroring transforms (negative determinant) get their winding flipped so that counter-clockwise
/// still means "seen from outside". Fails when there are more objects than ids can carry.
pub fn world_triangles(scene: &Scene) -> Result<(Vec<[Vec3; 3]>, Vec<u32>)> {
    check_object_count(scene)?;
    let mut triangles = Vec::with_capacity(scene.triangle_count() as usize);
    let mut objects = Vec::with_capacity(triangles.capacity());
    for i in 0..scene.objects.len() {
        for t in scene.object_faces(i) {
            triangles.push(t);
            objects.push(i as u32);
        }
    }
    Ok((triangles, objects))
}
