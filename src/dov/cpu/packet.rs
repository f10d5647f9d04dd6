//! Packet tracing for the AVX2 build of `render_ids`: the 32 rays of one block of 4 × 8 texels,
//! which share their origin, go through each BVH together, one AVX2 lane per ray (four registers
//! of eight) (docs/dov.md, "Per-ray speed against Embree"; docs/decisions.md, 60–63, 100). Rays
//! may also start each from its own point ([`LaneOrigins`]: region rays of nearby directions
//! from all over a cell).
//!
//! A node is fetched and its children's quantised bounds converted once for all the rays, and
//! the stack holds one entry per node for all of them. One test of the eight children for the
//! whole packet first rules out those no lane can enter (exactly: see [`enter_children`]); on
//! the others each lane does obvhs's own box test, and on each triangle
//! [`RayTriangle::intersect`]'s arithmetic, operation for operation (the same products, sums,
//! min/max operand order and comparisons), with its own `tmax`, so a ray enters exactly the boxes
//! and hits exactly the triangles its own traversal would (tested lane against single ray): only
//! the order of visits changes, which the tie window's id does not depend on.

use std::arch::x86_64::*;

use glam::{Affine3A, Vec3A};
use obvhs::cwbvh::{CwBvh, node::CwBvhNode};

use super::bvh::{NODE_TMIN, RayTriangle, cross};
use crate::dov::cubemap::FaceBasis;

/// A packet's texels: `PACKET_COLS` columns of `PACKET_ROWS` rows, lane `row · COLS + col`
/// ([`super::PACKET_TEXELS`]).
pub(super) const PACKET_COLS: usize = super::PACKET_TEXELS.0;
pub(super) const PACKET_ROWS: usize = super::PACKET_TEXELS.1;
/// Rays per packet (at most 32: lane sets are `u32` masks).
pub(super) const LANES: usize = PACKET_COLS * PACKET_ROWS;
/// Every lane of a packet.
pub(super) const ALL_LANES: u32 = (u64::MAX >> (64 - LANES)) as u32;
/// AVX2 registers of `f32` per lane vector (called halves from when there were two).
const HALVES: usize = LANES / 8;
/// One `f32` per lane.
pub(super) type Lanes = [__m256; HALVES];
const _: () = assert!(LANES.is_multiple_of(8) && LANES <= 32 && (PACKET_COLS == 4 || PACKET_COLS == 8));

/// Where a packet's rays start: one point for every lane ([`Vec3A`]: a cube map's texels, a
/// probe point's rays) or a point per lane ([`LaneOrigins`]: region rays of nearby directions
/// from all over a cell). The tests branch on [`Origins::PER_LANE`], a constant, so a shared
/// origin costs about what it did before packets could have several (0.85 % more instructions
/// on the engine's cube maps: docs/decisions.md, 125).
pub(super) trait Origins: Copy {
    const PER_LANE: bool;
    /// The one origin (only called where `!PER_LANE`).
    fn shared(&self) -> Vec3A;
    /// Each lane's origin by axis (only called where `PER_LANE`).
    fn lanes(&self) -> &[Lanes; 3];
    /// The origins of these lanes (only called where `PER_LANE`).
    fn of_lanes(o: [Lanes; 3]) -> Self;
    /// This one origin (only called where `!PER_LANE`).
    fn of_shared(o: Vec3A) -> Self;
    /// The least and the greatest origin of a group of lanes, by axis: nothing for one origin.
    type Range: Copy;
    /// The range from its ends (only called where `PER_LANE`).
    fn range(lo: [f32; 3], hi: [f32; 3]) -> Self::Range;
    /// The ends of a range (only called where `PER_LANE`).
    fn ends(range: &Self::Range) -> ([f32; 3], [f32; 3]);
}

impl Origins for Vec3A {
    const PER_LANE: bool = false;
    #[inline(always)]
    fn shared(&self) -> Vec3A {
        *self
    }
    fn lanes(&self) -> &[Lanes; 3] {
        unreachable!("a shared origin has no lanes")
    }
    fn of_lanes(_: [Lanes; 3]) -> Self {
        unreachable!("a shared origin has no lanes")
    }
    #[inline(always)]
    fn of_shared(o: Vec3A) -> Self {
        o
    }
    type Range = ();
    fn range(_: [f32; 3], _: [f32; 3]) {}
    fn ends(_: &()) -> ([f32; 3], [f32; 3]) {
        unreachable!("a shared origin has no range")
    }
}

/// Each lane's own origin, by axis.
#[derive(Clone, Copy)]
pub(super) struct LaneOrigins([Lanes; 3]);

impl LaneOrigins {
    /// The origins `o[l]` of lanes `l`.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn new(o: &[Vec3A; LANES]) -> Self {
        let axis = |a: usize| load(&std::array::from_fn(|l| o[l][a]));
        Self([axis(0), axis(1), axis(2)])
    }
}

impl Origins for LaneOrigins {
    const PER_LANE: bool = true;
    fn shared(&self) -> Vec3A {
        unreachable!("lanes have their own origins")
    }
    #[inline(always)]
    fn lanes(&self) -> &[Lanes; 3] {
        &self.0
    }
    #[inline(always)]
    fn of_lanes(o: [Lanes; 3]) -> Self {
        Self(o)
    }
    fn of_shared(_: Vec3A) -> Self {
        unreachable!("lanes have their own origins")
    }
    type Range = ([f32; 3], [f32; 3]);
    #[inline(always)]
    fn range(lo: [f32; 3], hi: [f32; 3]) -> Self::Range {
        (lo, hi)
    }
    #[inline(always)]
    fn ends(range: &Self::Range) -> ([f32; 3], [f32; 3]) {
        *range
    }
}

/// [`LANES`] rays in one BVH's space, lane by lane, from one origin or each from its own
/// ([`Origins`]).
#[derive(Clone, Copy)]
pub(super) struct Packet<O: Origins = Vec3A> {
    pub origin: O,
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

    /// The packet of the texel rays from `origin` through `(u, v)` of face `b`, lane by lane:
    /// `forward + u·right + v·up`, in [`crate::dov::cubemap::uv_direction`]'s order of operations,
    /// so each lane's direction is that function's, bit for bit.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn through_face(b: &FaceBasis, u: Lanes, v: Lanes, origin: Vec3A, lanes: u32) -> Self {
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

    /// The texel coordinates of a whole block: `u` of its [`PACKET_COLS`] columns, `v` of its
    /// [`PACKET_ROWS`] rows, lane `row · PACKET_COLS + col`; made in registers, as stores of four
    /// bytes read back as thirty-two would stall.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn block_uv(u: &[f32; PACKET_COLS], v: &[f32; PACKET_ROWS]) -> (Lanes, Lanes) {
        let mut lanes_u = [_mm256_setzero_ps(); HALVES];
        let mut lanes_v = [_mm256_setzero_ps(); HALVES];
        for h in 0..HALVES {
            if PACKET_COLS == 8 {
                // SAFETY: reads the eight f32 of `u`.
                lanes_u[h] = unsafe { _mm256_loadu_ps(u.as_ptr()) };
                lanes_v[h] = _mm256_set1_ps(v[h]);
            } else {
                // SAFETY: reads the first four f32 of `u`.
                let u4 = unsafe { _mm_loadu_ps(u.as_ptr()) };
                lanes_u[h] = _mm256_set_m128(u4, u4);
                lanes_v[h] = _mm256_set_m128(_mm_set1_ps(v[2 * h + 1]), _mm_set1_ps(v[2 * h]));
            }
        }
        (lanes_u, lanes_v)
    }
}

impl<O: Origins> Packet<O> {
    /// The packet of the rays from `origin` (one, or one per lane) along `dir` (by axis; lanes
    /// outside `lanes` are ignored).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn along(dir: [Lanes; 3], origin: O, lanes: u32) -> Self {
        // Loops, not `array::map`: the closure `map` calls cannot be inlined into it (it lacks
        // the caller's AVX2), and the call per element cost the packet tracer about a tenth.
        // Each field made whole in registers and written once: a `u32` built up by four-byte
        // read-modify-writes stalled the copy of the packet that read it back.
        let mut p = Self { origin, dir, inv: [splat(0.0); 3], lanes, negative: [0; 3] };
        for (axis, d) in dir.iter().enumerate() {
            let mut negative = 0;
            for (h, &d) in d.iter().enumerate() {
                // obvhs's `Ray::inv_direction`, eight lanes at a time (was a scalar division each).
                p.inv[axis][h] = safe_inverse(d);
                // `d < 0.0`, ordered: false for −0.0 (and NaN), as obvhs's octant.
                let below = _mm256_cmp_ps::<_CMP_LT_OQ>(d, _mm256_setzero_ps());
                negative |= (_mm256_movemask_ps(below) as u32) << (8 * h);
            }
            p.negative[axis] = negative;
        }
        p
    }

    /// This packet carried by `m` (world → model space), lane by lane as glam's
    /// `Affine3A::transform_vector3a` carries one direction (`(x·d.x + y·d.y) + z·d.z`) and
    /// `transform_point3a` one origin.
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
        let origin = if O::PER_LANE {
            // `Affine3A::transform_point3a` lane by lane: `((x·o.x + y·o.y) + z·o.z) + t`.
            let o = self.origin.lanes();
            let mut moved = [splat(0.0); 3];
            for (axis, moved) in moved.iter_mut().enumerate() {
                for (h, moved) in moved.iter_mut().enumerate() {
                    let term = |k: usize| _mm256_mul_ps(_mm256_set1_ps(cols[k][axis]), o[k][h]);
                    let sum = _mm256_add_ps(_mm256_add_ps(term(0), term(1)), term(2));
                    *moved = _mm256_add_ps(sum, _mm256_set1_ps(m.translation[axis]));
                }
            }
            O::of_lanes(moved)
        } else {
            O::of_shared(m.transform_point3a(self.origin.shared()))
        };
        Self::along(dir, origin, self.lanes)
    }

    /// Lane `l`'s origin.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub fn origin_of(&self, l: usize) -> Vec3A {
        if O::PER_LANE {
            let axis = |a: usize| store(self.origin.lanes()[a])[l];
            Vec3A::new(axis(0), axis(1), axis(2))
        } else {
            self.origin.shared()
        }
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

/// All bits set in the lanes of `lanes`, clear in the others (a blend mask).
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn lane_mask(lanes: u32) -> Lanes {
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let mut m = [_mm256_setzero_ps(); HALVES];
    for (h, m) in m.iter_mut().enumerate() {
        let word = _mm256_set1_epi32(((lanes >> (8 * h)) & 0xff) as i32);
        *m = _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(word, bits), bits));
    }
    m
}

/// In the lanes of `mask`, the lesser of `a` and `b`; `a` in the others.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn min_where(a: Lanes, b: Lanes, mask: Lanes) -> Lanes {
    let mut v = a;
    for h in 0..HALVES {
        v[h] = _mm256_blendv_ps(a[h], _mm256_min_ps(a[h], b[h]), mask[h]);
    }
    v
}

/// The lanes where `a < b` (ordered: false where either is NaN), as a lane set.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn less_than(a: Lanes, b: Lanes) -> u32 {
    let mut bits = 0u32;
    for h in 0..HALVES {
        bits |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(a[h], b[h])) as u32) << (8 * h);
    }
    bits
}

/// In the lanes of `mask`, `b`; `a` in the others.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn select(a: Lanes, b: Lanes, mask: Lanes) -> Lanes {
    let mut v = a;
    for h in 0..HALVES {
        v[h] = _mm256_blendv_ps(a[h], b[h], mask[h]);
    }
    v
}

/// Each lane of `v` times `k`.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn scaled(v: Lanes, k: f32) -> Lanes {
    let mut out = v;
    for h in 0..HALVES {
        out[h] = _mm256_mul_ps(v[h], _mm256_set1_ps(k));
    }
    out
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
pub(super) fn intersect_triangle<O: Origins>(
    tri: &RayTriangle,
    p: &Packet<O>,
    tmin: f32,
    tmax: Lanes,
    lanes: u32,
) -> (u32, Lanes, u32) {
    // The corners from the origin, the edges' normals a × b and n · a: once for a shared origin,
    // lane by lane for lanes' own.
    let shared = if O::PER_LANE {
        None
    } else {
        let o = p.origin.shared();
        let (a, b, c) = (tri.v0 - o, tri.v1 - o, tri.v2 - o);
        Some(([cross(b, c), cross(c, a), cross(a, b)], tri.n.dot(a)))
    };
    let (mut hits, mut back, mut ts) = (0, 0, [_mm256_setzero_ps(); HALVES]);
    let (mul, add, sub) = (|a, b| _mm256_mul_ps(a, b), |a, b| _mm256_add_ps(a, b), |a, b| _mm256_sub_ps(a, b));
    // (x·v.x + y·v.y) + z·v.z, glam's order.
    let dot_with = |[x, y, z]: [__m256; 3], v: Vec3A| {
        add(add(mul(x, _mm256_set1_ps(v.x)), mul(y, _mm256_set1_ps(v.y))), mul(z, _mm256_set1_ps(v.z)))
    };
    let dot_lanes = |[x, y, z]: [__m256; 3], [vx, vy, vz]: [__m256; 3]| add(add(mul(x, vx), mul(y, vy)), mul(z, vz));
    // `bvh::cross`, lane by lane: x = a.y·b.z − a.z·b.y, …
    let cross_lanes = |[ax, ay, az]: [__m256; 3], [bx, by, bz]: [__m256; 3]| {
        [sub(mul(ay, bz), mul(az, by)), sub(mul(az, bx), mul(ax, bz)), sub(mul(ax, by), mul(ay, bx))]
    };
    let zero = _mm256_setzero_ps();
    for h in 0..HALVES {
        let d = [p.dir[0][h], p.dir[1][h], p.dir[2][h]];
        let ([u, v, w], n_dot_a) = match shared {
            Some((edges, n_dot_a)) => (edges.map(|e| dot_with(d, e)), _mm256_set1_ps(n_dot_a)),
            None => {
                let o = p.origin.lanes();
                let from = |v: Vec3A| std::array::from_fn::<_, 3, _>(|k| sub(_mm256_set1_ps(v[k]), o[k][h]));
                let (a, b, c) = (from(tri.v0), from(tri.v1), from(tri.v2));
                let edges = [cross_lanes(b, c), cross_lanes(c, a), cross_lanes(a, b)];
                (edges.map(|e| dot_lanes(d, e)), dot_with(a, tri.n))
            }
        };
        // All three ≥ 0 or all three ≤ 0.
        let (ge, le) = (|x| _mm256_cmp_ps::<_CMP_GE_OQ>(x, zero), |x| _mm256_cmp_ps::<_CMP_LE_OQ>(x, zero));
        let and3 = |a, b, c| _mm256_and_ps(_mm256_and_ps(a, b), c);
        let inside = _mm256_or_ps(and3(ge(u), ge(v), ge(w)), and3(le(u), le(v), le(w)));
        let n_dot_d = dot_with(d, tri.n);
        let inv_det = _mm256_div_ps(_mm256_set1_ps(1.0), n_dot_d);
        let t = mul(n_dot_a, inv_det);
        let in_range = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(t, _mm256_set1_ps(tmin)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(t, _mm256_min_ps(tmax[h], _mm256_set1_ps(f32::MAX))),
        );
        hits |= (_mm256_movemask_ps(_mm256_and_ps(inside, in_range)) as u32) << (8 * h);
        // `RayTriangle::seen_from_behind`: n · d < 0.
        back |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(n_dot_d, zero)) as u32) << (8 * h);
        ts[h] = t;
    }
    (hits & lanes, ts, back)
}

/// The range of one octant group's inverse directions on each axis, and of its origins where
/// each lane has its own: the least and the greatest over its lanes.
#[derive(Clone, Copy)]
struct GroupRange<O: Origins> {
    lo: [f32; 3],
    hi: [f32; 3],
    origins: O::Range,
}

impl<O: Origins> GroupRange<O> {
    /// The range over the lanes `lanes` of `p` (not empty).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn of(p: &Packet<O>, lanes: u32) -> Self {
        let used = lane_mask(lanes);
        let (inf, neg_inf) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
        let range = |v: &Lanes| {
            let (mut min, mut max) = (inf, neg_inf);
            for (v, used) in v.iter().zip(&used) {
                min = _mm256_min_ps(min, _mm256_blendv_ps(inf, *v, *used));
                max = _mm256_max_ps(max, _mm256_blendv_ps(neg_inf, *v, *used));
            }
            (horizontal_min(min), horizontal_max(max))
        };
        let (mut lo, mut hi, mut origin_lo, mut origin_hi) = ([0f32; 3], [0f32; 3], [0f32; 3], [0f32; 3]);
        for axis in 0..3 {
            (lo[axis], hi[axis]) = range(&p.inv[axis]);
            if O::PER_LANE {
                (origin_lo[axis], origin_hi[axis]) = range(&p.origin.lanes()[axis]);
            }
        }
        Self { lo, hi, origins: O::range(origin_lo, origin_hi) }
    }
}

/// The least of the eight lanes of `v`.
#[target_feature(enable = "avx2")]
#[inline]
fn horizontal_min(v: __m256) -> f32 {
    let m = _mm256_min_ps(v, _mm256_permute2f128_ps::<1>(v, v));
    let m = _mm256_min_ps(m, _mm256_shuffle_ps::<0b01_00_11_10>(m, m));
    let m = _mm256_min_ps(m, _mm256_shuffle_ps::<0b10_11_00_01>(m, m));
    _mm256_cvtss_f32(m)
}

/// The greatest of the eight lanes of `v` (negation is exact).
#[target_feature(enable = "avx2")]
#[inline]
fn horizontal_max(v: __m256) -> f32 {
    -horizontal_min(_mm256_sub_ps(_mm256_setzero_ps(), v))
}

/// For each child slot of `node`, the lanes of `lanes` (all of octant `oct`, their inverse
/// directions within `range`) that enter it: obvhs's `intersect_ray_simd` per lane, with each
/// lane's `tmax`.
///
/// First one test of all eight children for the whole group, which rules out only children no
/// lane can enter, and the per-lane test on the others (1.11 of the 7.94 children in use per
/// node on the engine, of which 0.91 are entered). The group test needs no widening: each plane
/// distance `q·(e·inv) + (p − origin)·inv` is a chain of rounded products and sums, and rounding
/// is monotone, so with `q ≥ 0` and `e ≥ 0` it lies between the same chain at the range's ends
/// (for `p − origin < 0` with the ends swapped); max and min are exact, so a lane's entry and
/// exit lie inside the group's, and a child the group test rules out no lane enters. Where each
/// lane has its own origin, `p − origin` lies between `p` less the group's greatest and least
/// origin, and its product with `inv` between the least and the greatest of the four products
/// of the two ranges' ends (a product is monotone in each factor, and so is its rounding).
#[target_feature(enable = "avx2")]
#[inline]
fn enter_children<O: Origins>(
    node: &CwBvhNode,
    p: &Packet<O>,
    oct: u32,
    range: &GroupRange<O>,
    tmax: Lanes,
    lanes: u32,
    entered: &mut [u32; 8],
) -> u32 {
    let e = node.compute_extent();
    // p − origin: the one origin's, or (per lane) the least and the greatest.
    let (o_least, o_most) = if O::PER_LANE {
        let (lo, hi) = O::ends(&range.origins);
        let p = Vec3A::from(node.p);
        (p - Vec3A::from(hi), p - Vec3A::from(lo))
    } else {
        let o = Vec3A::from(node.p) - p.origin.shared();
        (o, o)
    };
    // SAFETY: reads the 8 bytes of `b`.
    let q = |b: &[u8; 8]| _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(unsafe { _mm_loadl_epi64(b.as_ptr().cast()) }));
    let mut near = [[0f32; 8]; 3];
    let mut far = [[0f32; 8]; 3];
    let bounds = [
        (&node.child_min_x, &node.child_max_x),
        (&node.child_min_y, &node.child_max_y),
        (&node.child_min_z, &node.child_max_z),
    ];
    let widest_lanes = tmax.iter().fold(_mm256_set1_ps(f32::NEG_INFINITY), |m, t| _mm256_max_ps(m, *t));
    let widest = horizontal_max(widest_lanes);
    let (mut group_t0, mut group_t1) = (_mm256_set1_ps(NODE_TMIN), _mm256_set1_ps(widest));
    for axis in 0..3 {
        let (lo, hi) = (q(bounds[axis].0), q(bounds[axis].1));
        // One octant: the near plane is the same side for every lane.
        let (n, f) = if oct & (4 >> axis) != 0 { (hi, lo) } else { (lo, hi) };
        // SAFETY: each store writes 8 f32 into an array of 8.
        unsafe {
            _mm256_storeu_ps(near[axis].as_mut_ptr(), n);
            _mm256_storeu_ps(far[axis].as_mut_ptr(), f);
        }
        let (inv_lo, inv_hi) = (range.lo[axis], range.hi[axis]);
        let (o_lo, o_hi) = if O::PER_LANE {
            let ends = [o_least[axis] * inv_lo, o_least[axis] * inv_hi, o_most[axis] * inv_lo, o_most[axis] * inv_hi];
            (ends.into_iter().fold(f32::INFINITY, f32::min), ends.into_iter().fold(f32::NEG_INFINITY, f32::max))
        } else {
            let o = o_least[axis];
            if o >= 0.0 { (o * inv_lo, o * inv_hi) } else { (o * inv_hi, o * inv_lo) }
        };
        let plane = |q, inv: f32, o: f32| _mm256_add_ps(_mm256_mul_ps(q, _mm256_set1_ps(e[axis] * inv)), _mm256_set1_ps(o));
        group_t0 = _mm256_max_ps(group_t0, plane(n, inv_lo, o_lo));
        group_t1 = _mm256_min_ps(group_t1, plane(f, inv_hi, o_hi));
    }
    // The slots in use: those whose meta byte is not 0.
    // SAFETY: reads the 8 bytes of `child_meta`.
    let meta = unsafe { _mm_loadl_epi64(node.child_meta.as_ptr().cast()) };
    let used = !(_mm_movemask_epi8(_mm_cmpeq_epi8(meta, _mm_setzero_si128())) as u32) & 0xff;
    let maybe = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(group_t0, group_t1)) as u32 & used;
    *entered = [0; 8];
    if maybe == 0 {
        return 0;
    }
    // Eight lanes at a time, over the children the group may enter.
    for (h, tmax) in tmax.iter().enumerate() {
        // obvhs: extent · inv_direction and (p − origin) · inv_direction.
        let mut adj_dir = [_mm256_setzero_ps(); 3];
        let mut adj_origin = [_mm256_setzero_ps(); 3];
        for axis in 0..3 {
            adj_dir[axis] = _mm256_mul_ps(_mm256_set1_ps(e[axis]), p.inv[axis][h]);
            let o = if O::PER_LANE {
                _mm256_sub_ps(_mm256_set1_ps(node.p[axis]), p.origin.lanes()[axis][h])
            } else {
                _mm256_set1_ps(o_least[axis])
            };
            adj_origin[axis] = _mm256_mul_ps(o, p.inv[axis][h]);
        }
        let plane = |q: f32, axis: usize| _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(q), adj_dir[axis]), adj_origin[axis]);
        let mut left = maybe;
        while left != 0 {
            let slot = left.trailing_zeros() as usize;
            left &= left - 1;
            let tmin_x = plane(near[0][slot], 0);
            let tmin_y = plane(near[1][slot], 1);
            let tmin_z = plane(near[2][slot], 2);
            let tmax_x = plane(far[0][slot], 0);
            let tmax_y = plane(far[1][slot], 1);
            let tmax_z = plane(far[2][slot], 2);
            let t0 = _mm256_max_ps(tmin_x, _mm256_max_ps(tmin_y, tmin_z));
            let t1 = _mm256_min_ps(tmax_x, _mm256_min_ps(tmax_y, tmax_z));
            let t0 = _mm256_max_ps(t0, _mm256_set1_ps(NODE_TMIN));
            let t1 = _mm256_min_ps(t1, *tmax);
            entered[slot] |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(t0, t1)) as u32) << (8 * h);
        }
    }
    let mut slots = 0;
    let mut left = maybe;
    while left != 0 {
        let slot = left.trailing_zeros() as usize;
        left &= left - 1;
        entered[slot] &= lanes;
        slots |= u32::from(entered[slot] != 0) << slot;
    }
    slots
}

/// The eight bits of `slots` reordered so that bit `k` is bit `k ^ oct`: swapping neighbours,
/// pairs and nibbles for the octant's three bits.
#[inline(always)]
fn xor_permuted(mut slots: u32, oct: u32) -> u32 {
    if oct & 1 != 0 {
        slots = (slots & 0x55) << 1 | (slots & 0xaa) >> 1;
    }
    if oct & 2 != 0 {
        slots = (slots & 0x33) << 2 | (slots & 0xcc) >> 2;
    }
    if oct & 4 != 0 {
        slots = (slots & 0x0f) << 4 | (slots & 0xf0) >> 4;
    }
    slots
}

/// Where a packet traversal keeps its per-lane bounds: `tmax` of each lane, read at every node
/// (in registers: written lane by lane and read back whole, they would stall on every node, as
/// a store of four bytes cannot forward to a load of thirty-two).
pub(super) trait LaneBounds {
    fn tmax(&self) -> Lanes;
}

/// Traverses `bvh` with the lanes `lanes` of `p`, nearest children first: `leaf(bounds, primitive
/// index, lanes)` for each primitive of each leaf a lane enters (primitive indices are positions in
/// `bvh.primitive_indices`). `stack` is scratch space.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn traverse<O: Origins, B: LaneBounds>(
    bvh: &CwBvh,
    p: &Packet<O>,
    lanes: u32,
    stack: &mut Vec<(u32, u32)>,
    bounds: &mut B,
    mut leaf: impl FnMut(&mut B, usize, u32),
) {
    let mut left = lanes;
    while left != 0 {
        let (oct, group) = p.octant_group(left);
        left &= !group;
        let range = GroupRange::of(p, group);
        let mut entered = [0u32; 8];
        stack.clear();
        stack.push((0, group));
        while let Some((index, lanes)) = stack.pop() {
            let node = &bvh.nodes[index as usize];
            // The caller's array, not a returned one: returning it copied it out whole, which
            // stalled on the four-byte writes just made to it.
            let slots = enter_children(node, p, oct, &range, bounds.tmax(), lanes, &mut entered);
            // obvhs's build puts children in slots so that slot ^ octant runs near to far: bit k
            // of `order` is slot k ^ octant's.
            let order = |slots: u32| xor_permuted(slots, oct);
            let inner = slots & node.imask as u32;
            // Far to near onto the stack, so the nearest comes off first.
            let mut far_first = order(inner);
            while far_first != 0 {
                let k = 31 - far_first.leading_zeros();
                far_first &= !(1 << k);
                let slot = (k ^ oct) as usize;
                let before = node.imask as u32 & ((1u32 << slot) - 1);
                stack.push((node.child_base_idx + before.count_ones(), entered[slot]));
            }
            let mut near_first = order(slots & !inner);
            while near_first != 0 {
                let slot = (near_first.trailing_zeros() ^ oct) as usize;
                near_first &= near_first - 1;
                let (first, count) = node.child_primitives(slot);
                for i in first..first + count {
                    leaf(bounds, i as usize, entered[slot]);
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
        (std::array::from_fn(|_| vec3a()), std::array::from_fn(|_| tmax()), 1u32..=ALL_LANES)
    }

    /// Bit `k` of the reordered slots is bit `k ^ oct` of the slots, for every octant and set.
    #[test]
    fn xor_permuted_moves_bit_k_xor_oct_to_k() {
        for oct in 0..8 {
            for slots in 0..256u32 {
                let expected = (0..8).fold(0, |m, k| m | ((slots >> (k ^ oct)) & 1) << k);
                assert_eq!(xor_permuted(slots, oct), expected, "oct {oct}, slots {slots:#010b}");
            }
        }
    }

    /// A whole block's coordinates: lane `row · PACKET_COLS + col` has the column's `u` and the
    /// row's `v`.
    #[test]
    fn block_uv_lays_out_columns_and_rows() {
        if !super::super::wide_instructions() {
            eprintln!("skipped: no AVX2");
            return;
        }
        let u: [f32; PACKET_COLS] = std::array::from_fn(|c| c as f32 * 0.75 - 1.0);
        let v: [f32; PACKET_ROWS] = std::array::from_fn(|r| 2.0 - r as f32 * 0.375);
        // SAFETY: AVX2 is present (checked above).
        let (lu, lv) = unsafe {
            let (lu, lv) = Packet::block_uv(&u, &v);
            (store(lu), store(lv))
        };
        for l in 0..LANES {
            assert_eq!((lu[l], lv[l]), (u[l % PACKET_COLS], v[l / PACKET_COLS]), "lane {l}");
        }
    }

    /// `dirs` by axis in registers.
    #[target_feature(enable = "avx2")]
    fn direction_lanes(dirs: &[Vec3A; LANES]) -> [Lanes; 3] {
        let axis = |a: usize| load(&std::array::from_fn(|l| dirs[l][a]));
        [axis(0), axis(1), axis(2)]
    }

    /// At every node of `bvh`, each lane of `p` (from `origins`, along `dirs`, up to `tmax`)
    /// enters the children obvhs's own box test lets its ray enter.
    fn check_box_test<O: Origins>(
        bvh: &CwBvh,
        p: &Packet<O>,
        origins: &[Vec3A; LANES],
        dirs: &[Vec3A; LANES],
        tmax: &[f32; LANES],
    ) -> Result<(), TestCaseError> {
        for node in &bvh.nodes {
            let mut left = p.lanes;
            while left != 0 {
                let (oct, group) = p.octant_group(left);
                left &= !group;
                let mut entered = [0; 8];
                // SAFETY: the callers checked that AVX2 is present.
                let slots = unsafe {
                    let range = GroupRange::of(p, group);
                    enter_children(node, p, oct, &range, load(tmax), group, &mut entered)
                };
                let nonzero = (0..8).fold(0, |m, slot| m | u32::from(entered[slot] != 0) << slot);
                prop_assert_eq!(slots, nonzero, "entered slots");
                for l in (0..LANES).filter(|l| group & (1 << l) != 0) {
                    let ray = Ray::new(origins[l], dirs[l], 0.0, tmax[l]);
                    let oct_inv4 = bvh.new_traversal(dirs[l]).oct_inv4;
                    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
                    let lane_mask = (0..8)
                        .filter(|&slot| entered[slot] & (1 << l) != 0)
                        .fold(0, |m, slot| m | extract_byte64(child_bits8, slot) << extract_byte64(bit_index8, slot));
                    prop_assert_eq!(lane_mask, node.intersect_ray(&ray, oct_inv4), "lane {}", l);
                }
            }
        }
        Ok(())
    }

    proptest! {
        /// Every lane enters the children obvhs's own box test lets its ray enter, whatever the
        /// packet's other lanes, from one origin or each from its own: the hit mask rebuilt from the lanes' per-child masks is
        /// `CwBvhNode::intersect_ray`'s, at every node of a random BVH.
        #[test]
        fn lane_box_test_is_obvhs_box_test(
            tris in prop::collection::vec([vec3a(), vec3a(), vec3a()], 1..60),
            origin in vec3a(),
            (dirs, tmax, lanes) in lanes(),
            spread in prop::option::of(prop::array::uniform32(vec3a())),
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let tris: Vec<Triangle> = tris.iter().map(|v| Triangle { v0: v[0], v1: v[1], v2: v[2] }).collect();
            let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
            match spread {
                // SAFETY: AVX2 is present (checked above).
                None => check_box_test(&bvh, &unsafe { Packet::new(origin, &dirs, lanes) }, &[origin; LANES], &dirs, &tmax)?,
                Some(spread) => {
                    // Each lane from its own origin, about the first.
                    let origins: [Vec3A; LANES] = std::array::from_fn(|l| origin + spread[l]);
                    // SAFETY: as above.
                    let p = unsafe { Packet::along(direction_lanes(&dirs), LaneOrigins::new(&origins), lanes) };
                    check_box_test(&bvh, &p, &origins, &dirs, &tmax)?;
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
            lanes in 1u32..=ALL_LANES,
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
                let p = Packet::through_face(&basis, load(&u), load(&v), origin, lanes);
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
            v in [vec3a(), vec3a(), vec3a()],
            origin in vec3a(),
            (dirs, tmax, lanes) in lanes(),
            tmin in 0.0f32..0.5,
            spread in prop::option::of(prop::array::uniform32(vec3a())),
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let tri = RayTriangle::new(&Triangle { v0: v[0], v1: v[1], v2: v[2] });
            let origins: [Vec3A; LANES] = std::array::from_fn(|l| origin + spread.map_or(Vec3A::ZERO, |s| s[l]));
            // SAFETY: AVX2 is present (checked above).
            let (hits, t, back) = unsafe {
                let (hits, t, back) = match spread {
                    None => intersect_triangle(&tri, &Packet::new(origin, &dirs, lanes), tmin, load(&tmax), lanes),
                    Some(_) => {
                        let p = Packet::along(direction_lanes(&dirs), LaneOrigins::new(&origins), lanes);
                        intersect_triangle(&tri, &p, tmin, load(&tmax), lanes)
                    }
                };
                (hits, store(t), back)
            };
            for l in (0..LANES).filter(|l| lanes & (1 << l) != 0) {
                let ray = Ray::new(origins[l], dirs[l], tmin, tmax[l]);
                let expected = tri.intersect(&ray);
                prop_assert_eq!(hits & (1 << l) != 0, expected.is_finite(), "lane {}", l);
                if expected.is_finite() {
                    prop_assert_eq!(t[l].to_bits(), expected.to_bits(), "lane {}", l);
                }
                prop_assert_eq!(back & (1 << l) != 0, tri.seen_from_behind(dirs[l]), "lane {}", l);
            }
        }

        /// Carried by a transform, each lane's own origin is `Affine3A::transform_point3a`'s, bit
        /// for bit (the single-ray path's origin in an instance's space).
        #[test]
        fn carried_lane_origins_are_the_single_rays_origins(
            origins in prop::array::uniform32(vec3a()),
            (dirs, _, lanes) in lanes(),
            cols in [vec3a(), vec3a(), vec3a(), vec3a()],
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let m = Affine3A::from_cols(cols[0], cols[1], cols[2], cols[3]);
            for l in 0..LANES {
                // SAFETY: AVX2 is present (checked above).
                let (got, moved) = unsafe {
                    let p = Packet::along(direction_lanes(&dirs), LaneOrigins::new(&origins), lanes);
                    (p.origin_of(l), p.transformed(&m).origin_of(l))
                };
                prop_assert_eq!(got.to_array().map(f32::to_bits), origins[l].to_array().map(f32::to_bits), "lane {}", l);
                let expected = m.transform_point3a(origins[l]).to_array().map(f32::to_bits);
                prop_assert_eq!(moved.to_array().map(f32::to_bits), expected, "lane {}", l);
            }
        }
    }
}
