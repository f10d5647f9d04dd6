//! Packet tracing for the AVX2 build of `render_ids`: the sixteen rays of one 4 × 4 block of
//! texels, which share their origin, go through each BVH together, one AVX2 lane per ray (two
//! registers of eight) (docs/dov.md, "Per-ray speed against Embree"; docs/decisions.md, 60–63).
//!
//! A node is fetched and its children's quantised bounds converted once for the sixteen rays, and
//! the stack holds one entry per node for all of them. Each lane does obvhs's own box test and
//! [`RayTriangle::intersect`]'s arithmetic, operation for operation (the same products, sums,
//! min/max operand order and comparisons), with its own `tmax`, so a ray enters exactly the boxes
//! and hits exactly the triangles its own traversal would (tested lane against single ray): only
//! the order of visits changes, which the tie window's id does not depend on.

use std::arch::x86_64::*;

use glam::{Affine3A, Vec3A};
use obvhs::cwbvh::{CwBvh, node::CwBvhNode};

use super::bvh::RayTriangle;
use crate::dov::cubemap::FaceBasis;
use super::trace::NODE_TMIN;

/// AVX2 registers of `f32` per lane vector.
const HALVES: usize = 2;
/// Rays per packet.
pub(super) const LANES: usize = 8 * HALVES;
/// One `f32` per lane.
pub(super) type Lanes = [__m256; HALVES];
/// A packet's texels: `PACKET_COLS` columns of `LANES / PACKET_COLS` rows, lane `row · COLS + col`.
pub(super) const PACKET_COLS: usize = 4;

/// [`LANES`] rays from one origin in one BVH's space, lane by lane.
#[derive(Clone, Copy)]
pub(super) struct Packet {
    pub origin: Vec3A,
    /// Each lane's direction by axis.
    dir: [Lanes; 3],
    /// obvhs's `Ray::inv_direction` of each lane.
    inv: [Lanes; 3],
    /// The lanes in use.
    pub lanes: u32,
    /// Bit `l` of `negative[axis]`: lane `l`'s direction is `< 0` on that axis (obvhs's octant).
    negative: [u32; 3],
}

impl Packet {
    /// The packet of the rays from `origin` along `dirs` (lanes outside `lanes` are ignored).
    #[cfg(test)]
    #[target_feature(enable = "avx2")]
    pub fn new(origin: Vec3A, dirs: &[Vec3A; LANES], lanes: u32) -> Self {
        let mut d = [[0f32; LANES]; 3];
        for (l, dir) in dirs.iter().enumerate() {
            for axis in 0..3 {
                d[axis][l] = dir[axis];
            }
        }
        Self::along([load(&d[0]), load(&d[1]), load(&d[2])], origin, lanes)
    }

    /// The packet of the rays from `origin` along `dir` (by axis; lanes outside `lanes` are
    /// ignored).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn along(dir: [Lanes; 3], origin: Vec3A, lanes: u32) -> Self {
        // Loops, not `array::map`: the closure `map` calls cannot be inlined into it (it lacks
        // the caller's AVX2), and the call per element cost the packet tracer about a tenth.
        let (mut inverse, mut negative) = ([splat(0.0); 3], [0u32; 3]);
        for axis in 0..3 {
            for h in 0..HALVES {
                // obvhs's `Ray::inv_direction`, eight lanes at a time (was a scalar division each).
                inverse[axis][h] = safe_inverse(dir[axis][h]);
                // `d < 0.0`, ordered: false for −0.0 (and NaN), as obvhs's octant.
                let below = _mm256_cmp_ps::<_CMP_LT_OQ>(dir[axis][h], _mm256_setzero_ps());
                negative[axis] |= (_mm256_movemask_ps(below) as u32) << (8 * h);
            }
        }
        Self { origin, dir, inv: inverse, lanes, negative }
    }

    /// The packet of the texel rays from `origin` through `(u, v)` of face `b`, lane by lane:
    /// `forward + u·right + v·up`, in [`crate::dov::cubemap::uv_direction`]'s order of operations,
    /// so each lane's direction is that function's, bit for bit.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn through_face(b: &FaceBasis, u: &[f32; LANES], v: &[f32; LANES], origin: Vec3A, lanes: u32) -> Self {
        let (u, v) = (load(u), load(v));
        let mut dir = [splat(0.0); 3];
        for (axis, d) in dir.iter_mut().enumerate() {
            let (f, r, up) = (_mm256_set1_ps(b.forward[axis]), _mm256_set1_ps(b.right[axis]), _mm256_set1_ps(b.up[axis]));
            for h in 0..HALVES {
                let along_u = _mm256_add_ps(f, _mm256_mul_ps(r, u[h]));
                d[h] = _mm256_add_ps(along_u, _mm256_mul_ps(up, v[h]));
            }
        }
        Self::along(dir, origin, lanes)
    }

    /// This packet carried by `m` (world → model space), lane by lane as glam's
    /// `Affine3A::transform_vector3a` carries one direction (`(x·d.x + y·d.y) + z·d.z`).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn transformed(&self, m: &Affine3A) -> Self {
        let cols = [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis];
        let mut dir = [splat(0.0); 3];
        for (axis, d) in dir.iter_mut().enumerate() {
            for (h, d) in d.iter_mut().enumerate() {
                let term = |k: usize| _mm256_mul_ps(_mm256_set1_ps(cols[k][axis]), self.dir[k][h]);
                *d = _mm256_add_ps(_mm256_add_ps(term(0), term(1)), term(2));
            }
        }
        Self::along(dir, m.transform_point3a(self.origin), self.lanes)
    }

    /// Lane `l`'s direction.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn direction(&self, l: usize) -> Vec3A {
        let axis = |a: usize| store(self.dir[a])[l];
        Vec3A::new(axis(0), axis(1), axis(2))
    }

    /// obvhs's octant of lane `l` (bit 2: x < 0, bit 1: y < 0, bit 0: z < 0).
    #[inline(always)]
    fn octant(&self, l: u32) -> u32 {
        ((self.negative[0] >> l) & 1) << 2 | ((self.negative[1] >> l) & 1) << 1 | ((self.negative[2] >> l) & 1)
    }

    /// The octant of the lowest lane of `lanes` (not empty) and the lanes of `lanes` in it:
    /// traversals take a packet one octant at a time (one, mostly).
    #[inline(always)]
    fn octant_group(&self, lanes: u32) -> (u32, u32) {
        let oct = self.octant(lanes.trailing_zeros());
        let side = |axis: usize| if oct & (4 >> axis) != 0 { self.negative[axis] } else { !self.negative[axis] };
        (oct, lanes & side(0) & side(1) & side(2))
    }
}

/// obvhs's `safe_inverse` lane by lane: `1 / x`, or `±1 / ε` with `x`'s sign where
/// `|x| ≤ ε` (ε = `f32::EPSILON`). Division is exact in every lane as in scalar code, so the bits
/// are obvhs's (tested through the box test against obvhs's).
#[target_feature(enable = "avx2")]
#[inline]
fn safe_inverse(x: __m256) -> __m256 {
    let sign = _mm256_and_ps(x, _mm256_set1_ps(-0.0));
    let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), x);
    let tiny = _mm256_cmp_ps::<_CMP_LE_OQ>(abs, _mm256_set1_ps(f32::EPSILON));
    let clamped = _mm256_or_ps(sign, _mm256_set1_ps(1.0 / f32::EPSILON));
    _mm256_blendv_ps(_mm256_div_ps(_mm256_set1_ps(1.0), x), clamped, tiny)
}

/// The `f32` of `a` in registers.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn load(a: &[f32; LANES]) -> Lanes {
    let mut v = [_mm256_setzero_ps(); HALVES];
    for (h, v) in v.iter_mut().enumerate() {
        // SAFETY: each load reads 8 f32 inside the array.
        *v = unsafe { _mm256_loadu_ps(a.as_ptr().add(8 * h)) };
    }
    v
}

/// The lanes of `v`.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn store(v: Lanes) -> [f32; LANES] {
    let mut a = [0f32; LANES];
    for (h, v) in v.iter().enumerate() {
        // SAFETY: writes 8 f32 inside the array.
        unsafe { _mm256_storeu_ps(a.as_mut_ptr().add(8 * h), *v) };
    }
    a
}

/// `v` in every lane.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn splat(v: f32) -> Lanes {
    [_mm256_set1_ps(v); HALVES]
}

/// [`RayTriangle::intersect`] for every lane: the lanes that hit `tri` with `tmin ≤ t ≤ tmax`
/// (among `lanes`), each lane's `t`, and the lanes that see its back.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn intersect_triangle(
    tri: &RayTriangle,
    p: &Packet,
    tmin: f32,
    tmax: Lanes,
    lanes: u32,
) -> (u32, Lanes, u32) {
    let c = tri.v0 - p.origin;
    let n_dot_c = tri.n.dot(c);
    let (mut hits, mut back, mut ts) = (0, 0, [_mm256_setzero_ps(); HALVES]);
    for h in 0..HALVES {
        let [dx, dy, dz] = [p.dir[0][h], p.dir[1][h], p.dir[2][h]];
        let (cx, cy, cz) = (_mm256_set1_ps(c.x), _mm256_set1_ps(c.y), _mm256_set1_ps(c.z));
        let (mul, add, sub) = (|a, b| _mm256_mul_ps(a, b), |a, b| _mm256_add_ps(a, b), |a, b| _mm256_sub_ps(a, b));
        // r = d × c (glam's order: x = d.y·c.z − d.z·c.y, …).
        let rx = sub(mul(dy, cz), mul(dz, cy));
        let ry = sub(mul(dz, cx), mul(dx, cz));
        let rz = sub(mul(dx, cy), mul(dy, cx));
        // a · b = (a.x·b.x + a.y·b.y) + a.z·b.z, glam's order.
        let dot = |x, y, z, v: Vec3A| {
            add(add(mul(x, _mm256_set1_ps(v.x)), mul(y, _mm256_set1_ps(v.y))), mul(z, _mm256_set1_ps(v.z)))
        };
        let n_dot_d = dot(dx, dy, dz, tri.n);
        let inv_det = _mm256_div_ps(_mm256_set1_ps(1.0), n_dot_d);
        let u = mul(dot(rx, ry, rz, tri.e2), inv_det);
        let v = mul(dot(rx, ry, rz, tri.e1), inv_det);
        let w = sub(sub(_mm256_set1_ps(1.0), u), v);
        let signs = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(u, v), w)) as u32;
        let det_nonzero = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(inv_det, _mm256_setzero_ps())) as u32;
        let t = mul(_mm256_set1_ps(n_dot_c), inv_det);
        let in_range = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(t, _mm256_set1_ps(tmin)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(t, tmax[h]),
        );
        hits |= (det_nonzero & !signs & _mm256_movemask_ps(in_range) as u32) << (8 * h);
        // `RayTriangle::seen_from_behind`: n · d < 0.
        back |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(n_dot_d, _mm256_setzero_ps())) as u32) << (8 * h);
        ts[h] = t;
    }
    (hits & lanes, ts, back)
}

/// For each child slot of `node`, the lanes of `lanes` (all of octant `oct`) that enter it:
/// obvhs's `intersect_ray_simd` per lane, with each lane's `tmax`.
#[target_feature(enable = "avx2")]
#[inline]
fn enter_children(node: &CwBvhNode, p: &Packet, oct: u32, tmax: Lanes, lanes: u32) -> [u32; 8] {
    {
        let e = node.compute_extent();
        let o = Vec3A::from(node.p) - p.origin;
        // SAFETY: reads the 8 bytes of `b`.
        let q = |b: &[u8; 8]| _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(unsafe { _mm_loadl_epi64(b.as_ptr().cast()) }));
        let mut near = [[0f32; 8]; 3];
        let mut far = [[0f32; 8]; 3];
        let bounds = [
            (&node.child_min_x, &node.child_max_x),
            (&node.child_min_y, &node.child_max_y),
            (&node.child_min_z, &node.child_max_z),
        ];
        let mut adj_dir = [[_mm256_setzero_ps(); HALVES]; 3];
        let mut adj_origin = [[_mm256_setzero_ps(); HALVES]; 3];
        for axis in 0..3 {
            let (lo, hi) = (q(bounds[axis].0), q(bounds[axis].1));
            // One octant: the near plane is the same side for every lane.
            let (n, f) = if oct & (4 >> axis) != 0 { (hi, lo) } else { (lo, hi) };
            // SAFETY: each store writes 8 f32 into an array of 8.
            unsafe {
                _mm256_storeu_ps(near[axis].as_mut_ptr(), n);
                _mm256_storeu_ps(far[axis].as_mut_ptr(), f);
            }
            // obvhs: extent · inv_direction and (p − origin) · inv_direction.
            for h in 0..HALVES {
                adj_dir[axis][h] = _mm256_mul_ps(_mm256_set1_ps(e[axis]), p.inv[axis][h]);
                adj_origin[axis][h] = _mm256_mul_ps(_mm256_set1_ps(o[axis]), p.inv[axis][h]);
            }
        }
        let plane = |q: f32, axis: usize, h: usize| {
            _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(q), adj_dir[axis][h]), adj_origin[axis][h])
        };
        let mut entered = [0u32; 8];
        for (slot, lanes_in) in entered.iter_mut().enumerate() {
            if node.child_meta[slot] == 0 {
                continue;
            }
            for (h, tmax) in tmax.iter().enumerate() {
                let tmin_x = plane(near[0][slot], 0, h);
                let tmin_y = plane(near[1][slot], 1, h);
                let tmin_z = plane(near[2][slot], 2, h);
                let tmax_x = plane(far[0][slot], 0, h);
                let tmax_y = plane(far[1][slot], 1, h);
                let tmax_z = plane(far[2][slot], 2, h);
                let t0 = _mm256_max_ps(tmin_x, _mm256_max_ps(tmin_y, tmin_z));
                let t1 = _mm256_min_ps(tmax_x, _mm256_min_ps(tmax_y, tmax_z));
                let t0 = _mm256_max_ps(t0, _mm256_set1_ps(NODE_TMIN));
                let t1 = _mm256_min_ps(t1, *tmax);
                *lanes_in |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(t0, t1)) as u32) << (8 * h);
            }
            *lanes_in &= lanes;
        }
        entered
    }
}

/// Where a packet traversal keeps its per-lane bounds: `tmax` of each lane, read at every node.
pub(super) trait LaneBounds {
    fn tmax(&self) -> &[f32; LANES];
}

/// Traverses `bvh` with the lanes `lanes` of `p`, nearest children first: `leaf(bounds, primitive
/// index, lanes)` for each primitive of each leaf a lane enters (primitive indices are positions in
/// `bvh.primitive_indices`). `stack` is scratch space.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn traverse<B: LaneBounds>(
    bvh: &CwBvh,
    p: &Packet,
    lanes: u32,
    stack: &mut Vec<(u32, u32)>,
    bounds: &mut B,
    mut leaf: impl FnMut(&mut B, usize, u32),
) {
    let mut left = lanes;
    while left != 0 {
        let (oct, group) = p.octant_group(left);
        left &= !group;
        stack.clear();
        stack.push((0, group));
        while let Some((index, lanes)) = stack.pop() {
            let node = &bvh.nodes[index as usize];
            let entered = enter_children(node, p, oct, load(bounds.tmax()), lanes);
            // obvhs's build puts children in slots so that slot ^ octant runs near to far.
            for k in (0..8u32).rev() {
                let slot = (k ^ oct) as usize;
                let m = entered[slot];
                if m != 0 && !node.is_leaf(slot) {
                    let before = node.imask as u32 & ((1u32 << slot) - 1);
                    stack.push((node.child_base_idx + before.count_ones(), m));
                }
            }
            for k in 0..8u32 {
                let slot = (k ^ oct) as usize;
                let m = entered[slot];
                if m != 0 && node.is_leaf(slot) {
                    let (first, count) = node.child_primitives(slot);
                    for i in first..first + count {
                        leaf(bounds, i as usize, m);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::{
        BvhBuildParams,
        ray::Ray,
        cwbvh::{builder::build_cwbvh_from_tris, node::extract_byte64},
        triangle::Triangle,
    };
    use proptest::prelude::*;
    use std::time::Duration;

    fn vec3a() -> impl Strategy<Value = Vec3A> {
        // Small integers make zero direction components, edge-on and on-edge cases common.
        prop_oneof![
            [-4.0f32..4.0, -4.0..4.0, -4.0..4.0].prop_map(Vec3A::from),
            [-2i8..3, -2..3, -2..3].prop_map(|v| Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32)),
        ]
    }

    /// A direction and a `tmax` (some infinite) per lane, and the lanes in use.
    fn lanes() -> impl Strategy<Value = ([Vec3A; LANES], [f32; LANES], u32)> {
        let tmax = || prop_oneof![Just(f32::INFINITY), 0.0f32..20.0];
        (std::array::from_fn(|_| vec3a()), std::array::from_fn(|_| tmax()), 1u32..1 << LANES)
    }

    proptest! {
        /// Every lane enters the children obvhs's own box test lets its ray enter, whatever the
        /// packet's other lanes: the hit mask rebuilt from the lanes' per-child masks is
        /// `CwBvhNode::intersect_ray`'s, at every node of a random BVH.
        #[test]
        fn lane_box_test_is_obvhs_box_test(
            tris in prop::collection::vec([vec3a(), vec3a(), vec3a()], 1..60),
            origin in vec3a(),
            (dirs, tmax, lanes) in lanes(),
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let tris: Vec<Triangle> = tris.iter().map(|v| Triangle { v0: v[0], v1: v[1], v2: v[2] }).collect();
            let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
            // SAFETY: AVX2 is present (checked above).
            let p = unsafe { Packet::new(origin, &dirs, lanes) };
            for node in &bvh.nodes {
                let mut left = lanes;
                while left != 0 {
                    let (oct, group) = p.octant_group(left);
                    left &= !group;
                    // SAFETY: as above.
                    let entered = unsafe { enter_children(node, &p, oct, load(&tmax), group) };
                    for l in (0..LANES).filter(|l| group & (1 << l) != 0) {
                        let ray = Ray::new(origin, dirs[l], 0.0, tmax[l]);
                        let oct_inv4 = bvh.new_traversal(dirs[l]).oct_inv4;
                        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
                        let lane_mask = (0..8)
                            .filter(|&slot| entered[slot] & (1 << l) != 0)
                            .fold(0, |m, slot| m | extract_byte64(child_bits8, slot) << extract_byte64(bit_index8, slot));
                        prop_assert_eq!(lane_mask, node.intersect_ray(&ray, oct_inv4), "lane {}", l);
                    }
                }
            }
        }

        /// Each lane of a face's packet has `uv_direction`'s direction, and each lane of a carried
        /// packet `Affine3A::transform_vector3a`'s, bit for bit (the single-ray paths' rays).
        #[test]
        fn packet_directions_are_the_single_rays_directions(
            face in 0usize..6,
            uv in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0), LANES),
            cols in [vec3a(), vec3a(), vec3a(), vec3a()],
            origin in vec3a(),
            lanes in 1u32..1 << LANES,
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let u: [f32; LANES] = std::array::from_fn(|l| uv[l].0);
            let v: [f32; LANES] = std::array::from_fn(|l| uv[l].1);
            let m = Affine3A::from_cols(cols[0], cols[1], cols[2], cols[3]);
            let basis = crate::dov::cubemap::face_basis(face);
            // SAFETY: AVX2 is present (checked above).
            let (p, q) = unsafe {
                let p = Packet::through_face(&basis, &u, &v, origin, lanes);
                (p, p.transformed(&m))
            };
            prop_assert_eq!(q.origin.to_array().map(f32::to_bits), m.transform_point3a(origin).to_array().map(f32::to_bits));
            for l in 0..LANES {
                let d = Vec3A::from(crate::dov::cubemap::uv_direction(face, u[l] as f64, v[l] as f64));
                // SAFETY: as above.
                let (got, carried) = unsafe { (p.direction(l), q.direction(l)) };
                prop_assert_eq!(got.to_array().map(f32::to_bits), d.to_array().map(f32::to_bits), "lane {}", l);
                let expected = m.transform_vector3a(d).to_array().map(f32::to_bits);
                prop_assert_eq!(carried.to_array().map(f32::to_bits), expected, "lane {}", l);
            }
        }

        /// Every lane's triangle test is `RayTriangle::intersect` (hit, `t` bit for bit) and
        /// `seen_from_behind` for its ray.
        #[test]
        fn lane_triangle_test_is_ray_triangle_test(
            v in [vec3a(), vec3a(), vec3a()], origin in vec3a(), (dirs, tmax, lanes) in lanes(), tmin in 0.0f32..0.5,
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let tri = RayTriangle::new(&Triangle { v0: v[0], v1: v[1], v2: v[2] });
            // SAFETY: AVX2 is present (checked above).
            let (hits, t, back) = unsafe {
                let p = Packet::new(origin, &dirs, lanes);
                let (hits, t, back) = intersect_triangle(&tri, &p, tmin, load(&tmax), lanes);
                (hits, store(t), back)
            };
            for l in (0..LANES).filter(|l| lanes & (1 << l) != 0) {
                let ray = Ray::new(origin, dirs[l], tmin, tmax[l]);
                let expected = tri.intersect(&ray);
                prop_assert_eq!(hits & (1 << l) != 0, expected.is_finite(), "lane {}", l);
                if expected.is_finite() {
                    prop_assert_eq!(t[l].to_bits(), expected.to_bits(), "lane {}", l);
                }
                prop_assert_eq!(back & (1 << l) != 0, tri.seen_from_behind(dirs[l]), "lane {}", l);
            }
        }
    }
}
