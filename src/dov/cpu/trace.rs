//! The CPU backend's tracers: the reference per-ray traversal, the fast path (each ray first
//! bounded by the previous texel's winning triangle, tile by tile) and its AVX2 build with
//! packets of 4 × 8 rays ([`super::packet`]), and the tie window that makes every route give
//! the same id.

use glam::{UVec2, Vec3, Vec3A};
use obvhs::{
    cwbvh::node::{CwBvhNode, extract_byte64},
    ray::{Ray, RayHit},
};

use super::bvh::{Hit, Instance, NODE_TMIN};
#[cfg(target_arch = "x86_64")]
use super::packet;
use super::{AMBIGUOUS_DEPTH, CpuBackend, TIE_EPSILON, TILE, check_cube, check_point};
use crate::dov::{IdCube, NO_OBJECT, cubemap};
use crate::error::Result;

/// What the fast path carries from one texel to the next on one thread.
#[derive(Default)]
pub(super) struct TexelState {
    pub(super) window: TieWindow,
    /// The previous texel's winning hit: instance and triangle.
    pub(super) last: Option<(u32, u32)>,
    #[cfg(target_arch = "x86_64")]
    pub(super) packet: PacketState,
}

/// What the packet tracer carries from one packet to the next on one thread.
#[cfg(target_arch = "x86_64")]
#[derive(Default)]
pub(super) struct PacketState {
    windows: LaneWindows,
    /// The previous packet's winning hits (instance, triangle), each once: tested first.
    last: Vec<(u32, u32)>,
    /// This packet's, while it is traced.
    winners: Vec<(u32, u32)>,
    tlas_stack: Vec<(u32, u32)>,
    blas_stack: Vec<(u32, u32)>,
}

/// The cosine of the widest angle between a packet's first ray and any other for
/// [`CpuBackend::first_hits_from_packets`] to trace them as a packet: about 8°, what a cube
/// map's block of 4 × 8 texels spans at R = 64 (aimed rays at many objects from one point span
/// far more, a footprint's texels less). On the default city, aimed rays took 1.2× as long as
/// packets as one by one, footprints 0.6×.
#[cfg(target_arch = "x86_64")]
const PACKET_CONE_COS: f32 = 0.99;

/// The cosine of the widest angle between the first ray of a run that
/// [`CpuBackend::first_hits_packets`] traces as one packet and any other: about 16°, so that a
/// run takes region rays from neighbouring direction bins (5.6° texels) too. Region rays on the
/// audit block, one thread (`cargo bench --bench dov -- "region rays"`): 8.3, 8.9, 9.3 and 9.2 M
/// rays a second at 8°, 11.5°, 16° and 21.6°; 4.9 M one by one.
#[cfg(target_arch = "x86_64")]
const RUN_CONE_COS: f32 = 0.96;

/// The fewest rays [`CpuBackend::first_hits_packets`] traces as a packet: a ray alone goes by the
/// single-ray path (runs of at least 2, 4 and 8 as packets: 9.4, 9.3 and 9.1 M rays a second, as
/// above).
#[cfg(target_arch = "x86_64")]
const PACKET_MIN_LANES: usize = 2;

/// One tie window per lane of a packet, and their bounds side by side (the lanes' `tmax`). A
/// window is emptied when its lane's first hit arrives, not for every packet: most lanes of most
/// packets hit nothing.
#[cfg(target_arch = "x86_64")]
pub(super) struct LaneWindows {
    windows: [TieWindow; packet::LANES],
    /// Each lane's window bound, `t_near·(1 + ε)` (the hint's bound before its first hit).
    bounds: packet::Lanes,
    /// Each lane's nearest hit (infinity before its first).
    t_near: packet::Lanes,
    /// The lanes whose windows hold this packet's hits (the others' are stale).
    filled: u32,
}

#[cfg(target_arch = "x86_64")]
impl Default for LaneWindows {
    fn default() -> Self {
        // SAFETY: a zeroed `__m256` is eight 0.0 (the bounds are set by `reset` before use).
        let zero = unsafe { std::mem::zeroed() };
        Self { windows: Default::default(), bounds: zero, t_near: zero, filled: 0 }
    }
}

#[cfg(target_arch = "x86_64")]
impl LaneWindows {
    /// Empties every window, with the bound `bounds` (by lane).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn reset(&mut self, bounds: packet::Lanes) {
        self.bounds = bounds;
        self.t_near = packet::splat(f32::INFINITY);
        self.filled = 0;
    }

    /// Adds the hits of one triangle: the lanes `hits` at `t`, each lane's hit by `hit`. Each
    /// window's bound is `TieWindow::add`'s, `t_near·(1 + ε)` with the same product, worked out in
    /// registers for all the lanes at once.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn add(&mut self, hits: u32, t: packet::Lanes, hit: impl Fn(usize, f32) -> Hit) {
        let mask = packet::lane_mask(hits);
        self.t_near = packet::min_where(self.t_near, t, mask);
        self.bounds = packet::select(self.bounds, packet::scaled(self.t_near, 1.0 + TIE_EPSILON), mask);
        let t = packet::store(t);
        let mut left = hits;
        while left != 0 {
            let lane = left.trailing_zeros() as usize;
            left &= left - 1;
            let window = &mut self.windows[lane];
            if self.filled & (1 << lane) == 0 {
                self.filled |= 1 << lane;
                window.clear();
            }
            window.add(hit(lane, t[lane]));
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl packet::LaneBounds for LaneWindows {
    #[inline(always)]
    fn tmax(&self) -> packet::Lanes {
        self.bounds
    }
}


/// The hits of one ray inside the tie window of the nearest so far, `t ≤ t_near·(1 + ε)`. The
/// ray's id is a function of the set of its hits alone, whatever order a traversal finds them in:
/// a front face before a back face, then the lowest object id, its nearest triangle there
/// (docs/decisions.md, 41 and 136). So any traversal order, BVH or early bound gives the id the
/// reference tracer gives. Front first because a ray through the edge of a solid meets the face it
/// sees and, at the same `t`, the face behind the edge: the watertight test hits both.
#[derive(Default)]
pub(super) struct TieWindow {
    pub(super) hits: Vec<Hit>,
    /// `t_near·(1 + ε)`: hits beyond it can no longer change the id (infinity while empty).
    pub(super) bound: f32,
    pub(super) t_near: f32,
}

impl TieWindow {
    pub(super) fn clear(&mut self) {
        self.hits.clear();
        self.bound = f32::INFINITY;
        self.t_near = f32::INFINITY;
    }

    /// Adds a hit with `t ≤ self.bound`.
    #[inline(always)]
    pub(super) fn add(&mut self, hit: Hit) {
        if hit.t < self.t_near {
            self.t_near = hit.t;
            self.bound = hit.t * (1.0 + TIE_EPSILON);
            let bound = self.bound;
            self.hits.retain(|h| h.t <= bound);
        }
        self.hits.push(hit);
    }

    /// The winning hit, if any.
    pub(super) fn winner(&self) -> Option<&Hit> {
        self.hits.iter().min_by(|a, b| a.back.cmp(&b.back).then(a.obj.cmp(&b.obj)).then(a.t.total_cmp(&b.t)))
    }

    pub(super) fn id(&self) -> u32 {
        self.winner().map_or(NO_OBJECT, Hit::id)
    }
}

impl CpuBackend {
    /// The id seen from `origin` along `dir` (a texel direction whose forward component is 1):
    /// among the hits with `t ≥ near`, those within [`TIE_EPSILON`] of the nearest are ties, where a
    /// front face wins, then the lower object id, with [`BACK_FACE_BIT`] when its triangle faces
    /// away ([`TieWindow`]). The reference
    /// tracer: one plain obvhs traversal of the TLAS, and of the BLAS of each instance box the ray
    /// enters before its nearest hit's tie window.
    pub fn trace(&self, origin: Vec3, dir: Vec3) -> u32 {
        let mut window = TieWindow::default();
        window.clear();
        // Boxes beyond the tie window of the nearest hit cannot change the result.
        self.traverse_plainly(origin, dir, |hit| {
            window.add(hit);
            window.bound
        });
        window.id()
    }

    /// One plain obvhs traversal of the TLAS, and of the BLAS of each instance box the ray enters
    /// before the bound: `on_hit` takes each hit and returns the new bound.
    fn traverse_plainly(&self, origin: Vec3, dir: Vec3, mut on_hit: impl FnMut(Hit) -> f32) {
        let Some(tlas) = &self.tlas else { return };
        let (o, d) = (Vec3A::from(origin), Vec3A::from(dir));
        let mut bound = f32::INFINITY;
        tlas.ray_traverse(Ray::new(o, d, self.near, f32::INFINITY), &mut RayHit::none(), |_, ii| {
            let inst = &self.instances[ii];
            let blas = &self.blases[inst.blas as usize];
            let ray = self.instance_ray(inst, o, d, bound);
            blas.bvh.ray_traverse(ray, &mut RayHit::none(), |ray, i| {
                let t = blas.triangles[i].intersect(ray);
                if t.is_finite() {
                    bound = on_hit(blas.ray_hit(inst, ii, i, t, ray));
                }
                bound
            });
            bound
        });
    }

    /// The ids (with [`BACK_FACE_BIT`]) of the surfaces the ray from `origin` along `dir` meets
    /// within [`AMBIGUOUS_DEPTH`] of its nearest hit, each once. Where there are two or more, the
    /// ray's id depends on `f32` rounding of rays that start within about `near` of a tie, and
    /// the fast path's early culling may pick another of them than the reference tracer (tests).
    pub fn surfaces_at_nearest(&self, origin: Vec3, dir: Vec3) -> Vec<u32> {
        let mut hits: Vec<Hit> = Vec::new();
        self.traverse_plainly(origin, dir, |hit| {
            hits.push(hit);
            f32::INFINITY
        });
        let nearest = hits.iter().map(|h| h.t).fold(f32::INFINITY, f32::min);
        let mut ids: Vec<u32> = hits.iter().filter(|h| h.t <= nearest * (1.0 + AMBIGUOUS_DEPTH)).map(Hit::id).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// The ray of `inst`'s BLAS: the world ray, or carried into model space by the inverse
    /// transform (direction not normalised, so `t` is the same in both spaces).
    #[inline(always)]
    fn instance_ray(&self, inst: &Instance, o: Vec3A, d: Vec3A, tmax: f32) -> Ray {
        match &inst.to_model {
            None => Ray::new(o, d, self.near, tmax),
            Some(m) => Ray::new(m.transform_point3a(o), m.transform_vector3a(d), self.near, tmax),
        }
    }

    /// [`CpuBackend::trace`]'s id by a faster route. The previous texel's winning triangle is
    /// tested first, and its tie window bounds the traversal from the start, which then skips
    /// every box behind it; a scene whose TLAS holds one instance (no instancing) goes straight to
    /// its BLAS; triangles carry their precomputed normals. The id depends only on the set of hits
    /// the BVH lets through inside the tie window, which every route finds whole, so it equals
    /// `trace`'s. The bound is only trusted once the traversal itself reaches a hit at least as
    /// near: a ray grazing a box edge can hit a triangle whose box test it fails (rounding), and
    /// the reference would not see that hit; then the ray is traced again without the bound.
    #[inline(always)]
    fn trace_fast<const WIDE: bool>(&self, o: Vec3A, d: Vec3A, state: &mut TexelState) -> u32 {
        self.trace_fast_within::<WIDE>(o, d, f32::INFINITY, state)
    }

    /// [`CpuBackend::trace_fast`] among the hits up to `bound` along `d`.
    #[inline(always)]
    fn trace_fast_within<const WIDE: bool>(&self, o: Vec3A, d: Vec3A, bound: f32, state: &mut TexelState) -> u32 {
        let window = &mut state.window;
        window.clear();
        window.bound = bound;
        let mut hint_t = f32::INFINITY;
        if let Some((ii, i)) = state.last {
            let inst = &self.instances[ii as usize];
            let ray = self.instance_ray(inst, o, d, f32::INFINITY);
            let t = self.blases[inst.blas as usize].triangles[i as usize].intersect(&ray);
            // A hint beyond the bound bounds nothing.
            if t * (1.0 + TIE_EPSILON) < bound {
                hint_t = t;
                window.bound = t * (1.0 + TIE_EPSILON);
            }
        }
        self.traverse_all::<WIDE>(o, d, window);
        if window.t_near > hint_t {
            window.clear();
            window.bound = bound;
            self.traverse_all::<WIDE>(o, d, window);
        }
        // A miss keeps the last hit: the next ray may well hit it.
        if let Some(h) = window.winner() {
            state.last = Some((h.instance, h.tri));
        }
        window.id()
    }

    /// The first hit of each ray (origin, direction with its largest component ±1, the hits up
    /// to its bound along it) in turn, by the fast path: each ray first bounded by the previous
    /// one's winning triangle, so rays in a coherent order skip most of the boxes behind it.
    /// Equals a plain traversal's ids within each bound.
    #[inline(always)]
    pub(super) fn first_hits_fast<const WIDE: bool>(&self, rays: &[(Vec3A, Vec3A, f32)]) -> Vec<u32> {
        let mut state = TexelState::default();
        let mut ids = Vec::with_capacity(rays.len());
        // A loop, not a closure: a closure would not inherit the caller's target features, and
        // the AVX2 node test inlined into it would become calls.
        for &(o, d, bound) in rays {
            ids.push(self.trace_fast_within::<WIDE>(o, d, bound, &mut state));
        }
        ids
    }

    /// [`CpuBackend::first_hits_fast`] compiled as in [`CpuBackend::trace_band_wide`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn first_hits_wide(&self, rays: &[(Vec3A, Vec3A, f32)]) -> Vec<u32> {
        self.first_hits_fast::<true>(rays)
    }

    /// Adds to `window` the hits of every instance nearer than its bound.
    #[inline(always)]
    pub(super) fn traverse_all<const WIDE: bool>(&self, o: Vec3A, d: Vec3A, window: &mut TieWindow) {
        match &self.tlas {
            None => {}
            Some(_) if self.instances.len() == 1 => self.traverse_blas::<WIDE>(0, o, d, window),
            Some(tlas) => {
                let mut ray = Ray::new(o, d, self.near, window.bound);
                let mut traversal = tlas.new_traversal(ray.direction);
                let mut node;
                obvhs::traverse!(tlas, node, traversal, intersect_node::<WIDE>(node, &ray, traversal.oct_inv4), {
                    self.traverse_blas::<WIDE>(traversal.primitive_id as usize, o, d, window);
                    ray.tmax = window.bound;
                });
            }
        }
    }

    /// Adds to `window` the hits of instance `ii`'s BLAS nearer than its bound.
    #[inline(always)]
    fn traverse_blas<const WIDE: bool>(&self, ii: usize, o: Vec3A, d: Vec3A, window: &mut TieWindow) {
        let inst = &self.instances[ii];
        let blas = &self.blases[inst.blas as usize];
        let mut ray = self.instance_ray(inst, o, d, window.bound);
        let mut traversal = blas.bvh.new_traversal(ray.direction);
        let mut node;
        obvhs::traverse!(blas.bvh, node, traversal, intersect_node::<WIDE>(node, &ray, traversal.oct_inv4), {
            let i = traversal.primitive_id as usize;
            let t = blas.triangles[i].intersect(&ray);
            if t.is_finite() {
                window.add(blas.ray_hit(inst, ii, i, t, &ray));
                ray.tmax = window.bound;
            }
        });
    }

    /// The id cube from `p` by [`CpuBackend::trace`], one ray after another on the calling thread:
    /// the straightforward tracer that [`DovBackend::render_ids`] must equal texel for texel
    /// (tests), and the "before" of the per-ray speed figures (tools/src/bin/ray-speed.rs).
    pub fn render_ids_reference(&self, p: Vec3, out: &mut IdCube) -> Result<()> {
        check_point(p)?;
        check_cube(out, self.cube.resolution())?;
        let r = self.cube.resolution();
        let mut ids = out.ids.iter_mut();
        for face in 0..cubemap::FACE_COUNT {
            for row in 0..r {
                for col in 0..r {
                    *ids.next().expect("checked length") = self.trace(p, self.cube.texel_direction(face, row, col));
                }
            }
        }
        Ok(())
    }
}

/// The children of `node` that `ray` enters (obvhs's hit mask). `WIDE` (only inside
/// [`CpuBackend::trace_band_wide`]) tests all eight children in one AVX2 pass, with the operations
/// of obvhs's four-wide `intersect_ray_simd` lane by lane (the same products, sums, min/max and
/// `≤`), so the same children are entered; obvhs converts the quantised bounds one byte at a
/// time, the costliest part of its test, which AVX2 does in one instruction.
#[inline(always)]
fn intersect_node<const WIDE: bool>(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if WIDE {
        // SAFETY: WIDE is only instantiated under `trace_band_wide`, whose CPU has AVX2.
        return unsafe { intersect_node_avx2(node, ray, oct_inv4) };
    }
    node.intersect_ray(ray, oct_inv4)
}


#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn intersect_node_avx2(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    use std::arch::x86_64::*;
    let adj_dir = node.compute_extent() * ray.inv_direction;
    let adj_origin = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    // SAFETY (all intrinsics): AVX2 is present (see `intersect_node`); each load reads 8 bytes.
    unsafe {
        let q = |b: &[u8; 8]| _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(b.as_ptr().cast())));
        let slab = |lo: &[u8; 8], hi: &[u8; 8], negative: bool, dir: f32, origin: f32| {
            let (lo, hi) = (q(lo), q(hi));
            let (near, far) = if negative { (hi, lo) } else { (lo, hi) };
            let (dir, origin) = (_mm256_set1_ps(dir), _mm256_set1_ps(origin));
            (_mm256_add_ps(_mm256_mul_ps(near, dir), origin), _mm256_add_ps(_mm256_mul_ps(far, dir), origin))
        };
        let d = ray.direction;
        let (tmin_x, tmax_x) = slab(&node.child_min_x, &node.child_max_x, d.x < 0.0, adj_dir.x, adj_origin.x);
        let (tmin_y, tmax_y) = slab(&node.child_min_y, &node.child_max_y, d.y < 0.0, adj_dir.y, adj_origin.y);
        let (tmin_z, tmax_z) = slab(&node.child_min_z, &node.child_max_z, d.z < 0.0, adj_dir.z, adj_origin.z);
        let tmin = _mm256_max_ps(tmin_x, _mm256_max_ps(tmin_y, tmin_z));
        let tmax = _mm256_min_ps(tmax_x, _mm256_min_ps(tmax_y, tmax_z));
        let tmin = _mm256_max_ps(tmin, _mm256_set1_ps(NODE_TMIN));
        let tmax = _mm256_min_ps(tmax, _mm256_set1_ps(ray.tmax));
        let mut entered = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(tmin, tmax)) as u32;
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        while entered != 0 {
            let slot = entered.trailing_zeros() as usize;
            entered &= entered - 1;
            hit_mask |= extract_byte64(child_bits8, slot) << extract_byte64(bit_index8, slot);
        }
        hit_mask
    }
}

impl CpuBackend {
    /// Traces the texels of `rows` rows (`ids.len() / R`) of `face` from `row0`, tile by tile.
    #[inline(always)]
    pub(super) fn trace_band<const WIDE: bool>(
        &self,
        o: Vec3A,
        face: usize,
        row0: usize,
        ids: &mut [u32],
        state: &mut TexelState,
    ) {
        let r = self.cube.resolution() as usize;
        state.last = None;
        let rows = ids.len() / r;
        for col0 in (0..r).step_by(TILE) {
            let col1 = (col0 + TILE).min(r);
            for dr in 0..rows {
                for col in col0..col1 {
                    let d = self.cube.texel_direction(face, (row0 + dr) as u32, col as u32);
                    ids[dr * r + col] = self.trace_fast::<WIDE>(o, Vec3A::from(d), state);
                }
            }
        }
    }

    /// [`CpuBackend::traverse_all`] compiled as in [`CpuBackend::trace_band_wide`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn traverse_all_wide(&self, o: Vec3A, d: Vec3A, window: &mut TieWindow) {
        self.traverse_all::<true>(o, d, window)
    }

    /// [`CpuBackend::trace_band`] compiled for newer x86-64 CPUs, as Embree picks its kernels at
    /// run time. The traversal counts and finds bits per node (one instruction each with POPCNT and
    /// LZCNT, a dozen without); the arithmetic is the same operations (Rust never fuses a
    /// multiply-add by itself), so the ids are bit-identical (tests/dov_fast_path.rs).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn trace_band_wide(
        &self,
        o: Vec3A,
        face: usize,
        row0: usize,
        ids: &mut [u32],
        state: &mut TexelState,
    ) {
        if self.packets {
            self.trace_band_packets(o, face, row0, ids, state)
        } else {
            self.trace_band::<true>(o, face, row0, ids, state)
        }
    }

    /// [`CpuBackend::trace_band`] by packets: each tile in blocks of [`packet::PACKET_COLS`]
    /// columns of `LANES / PACKET_COLS` rows, one [`CpuBackend::trace_packet`] each (partial
    /// blocks at the image's edges).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn trace_band_packets(&self, o: Vec3A, face: usize, row0: usize, ids: &mut [u32], state: &mut TexelState) {
        use packet::{LANES, PACKET_COLS, PACKET_ROWS};
        let r = self.cube.resolution() as usize;
        let rows = ids.len() / r;
        let basis = cubemap::face_basis(face);
        state.packet.last.clear();
        for col0 in (0..r).step_by(TILE) {
            let col1 = (col0 + TILE).min(r);
            for pr in (0..rows).step_by(PACKET_ROWS) {
                for pc in (col0..col1).step_by(PACKET_COLS) {
                    let texel = |l: usize| (pr + l / PACKET_COLS, pc + l % PACKET_COLS);
                    // Whole blocks (all but the image's edges) row by row, the rest texel by texel.
                    let whole = pr + PACKET_ROWS <= rows && pc + PACKET_COLS <= col1;
                    let (lanes, (u, v)) = if whole {
                        let u = self.texel_u[pc..][..PACKET_COLS].try_into().expect("PACKET_COLS long");
                        let v = self.texel_v[row0 + pr..][..PACKET_ROWS].try_into().expect("PACKET_ROWS long");
                        (packet::ALL_LANES, packet::Packet::block_uv(u, v))
                    } else {
                        let (mut u, mut v, mut lanes) = ([0f32; LANES], [0f32; LANES], 0u32);
                        for l in 0..LANES {
                            let (row, col) = texel(l);
                            if row < rows && col < col1 {
                                (u[l], v[l]) = (self.texel_u[col], self.texel_v[row0 + row]);
                                lanes |= 1 << l;
                            }
                        }
                        (lanes, (packet::load(&u), packet::load(&v)))
                    };
                    let p = packet::Packet::through_face(&basis, u, v, o, lanes);
                    let lane_ids = self.trace_packet(&p, packet::splat(f32::INFINITY), state);
                    if whole {
                        for (i, row_ids) in lane_ids.chunks_exact(PACKET_COLS).enumerate() {
                            ids[(pr + i) * r + pc..][..PACKET_COLS].copy_from_slice(row_ids);
                        }
                    } else {
                        for (l, id) in lane_ids.iter().enumerate().filter(|&(l, _)| lanes & (1 << l) != 0) {
                            let (row, col) = texel(l);
                            ids[row * r + col] = *id;
                        }
                    }
                }
            }
        }
    }

    /// The first hit of each ray from `o` (direction with its largest component ±1, the hits up
    /// to its bound along it), [`packet::LANES`] rays after another in one packet where they
    /// point within [`PACKET_CONE_COS`] of the first, else one by one: callers give them in a
    /// coherent order. Equals a plain traversal's ids within each bound.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn first_hits_from_packets(&self, o: Vec3A, rays: &[(Vec3A, f32)]) -> Vec<u32> {
        use packet::LANES;
        let mut state = TexelState::default();
        let mut ids = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(LANES) {
            // Rays that go apart share few boxes: a packet of them visits the boxes of all, which
            // costs more than each ray alone with the previous one's hit as its first bound.
            let first = chunk[0].0.normalize();
            if chunk.iter().any(|(d, _)| d.normalize().dot(first) < PACKET_CONE_COS) {
                for &(d, bound) in chunk {
                    ids.push(self.trace_fast_within::<true>(o, d, bound, &mut state));
                }
                continue;
            }
            self.push_packet(o, chunk, &mut state, &mut ids);
        }
        ids
    }

    /// The first hit of each ray (origin, direction with its largest component ±1, the hits up
    /// to its bound along it): each run of rays that point within [`RUN_CONE_COS`] of the run's
    /// first, up to [`packet::LANES`], in one packet, each lane from its own origin (region rays
    /// of nearby directions from all over a cell); a run shorter than [`PACKET_MIN_LANES`] one
    /// ray after another. Callers give rays in a coherent order. Equals a plain traversal's ids
    /// within each bound.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn first_hits_packets(&self, rays: &[(Vec3A, Vec3A, f32)]) -> Vec<u32> {
        use packet::LANES;
        let mut state = TexelState::default();
        let mut ids = Vec::with_capacity(rays.len());
        let mut i = 0;
        while i < rays.len() {
            let first = rays[i].1.normalize();
            let mut n = 1;
            while n < LANES && i + n < rays.len() && rays[i + n].1.normalize().dot(first) >= RUN_CONE_COS {
                n += 1;
            }
            let run = &rays[i..i + n];
            i += n;
            if n < PACKET_MIN_LANES {
                for &(o, d, bound) in run {
                    ids.push(self.trace_fast_within::<true>(o, d, bound, &mut state));
                }
                continue;
            }
            let (mut origins, mut lane_rays) = ([Vec3A::ZERO; LANES], [(Vec3A::ZERO, 0.0); LANES]);
            for (l, &(o, d, bound)) in run.iter().enumerate() {
                (origins[l], lane_rays[l]) = (o, (d, bound));
            }
            self.push_packet(packet::LaneOrigins::new(&origins), &lane_rays[..n], &mut state, &mut ids);
        }
        ids
    }

    /// The rays of `run` (at most [`packet::LANES`]: direction with its largest component ±1,
    /// and bound) from `origin` (one, or one per lane) as one packet: their first hits, in
    /// order, onto `ids`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn push_packet<O: packet::Origins>(&self, origin: O, run: &[(Vec3A, f32)], state: &mut TexelState, ids: &mut Vec<u32>) {
        use packet::LANES;
        let (mut dir, mut reach) = ([[0f32; LANES]; 3], [f32::INFINITY; LANES]);
        for (l, &(d, bound)) in run.iter().enumerate() {
            (dir[0][l], dir[1][l], dir[2][l], reach[l]) = (d.x, d.y, d.z, bound);
        }
        let lanes = packet::ALL_LANES >> (LANES - run.len());
        let p = packet::Packet::along([packet::load(&dir[0]), packet::load(&dir[1]), packet::load(&dir[2])], origin, lanes);
        ids.extend_from_slice(&self.trace_packet(&p, packet::load(&reach), state)[..run.len()]);
    }

    /// [`CpuBackend::trace_fast`] for the lanes of a packet together, each lane among the hits
    /// up to its `reach`: the previous packet's winning triangles bound each lane from the start,
    /// one packet traversal finds every lane's hits inside its bound, and a lane whose bound the
    /// traversal did not confirm (a hit it cannot reach, see `trace_fast`) is traced again alone
    /// without it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn trace_packet<O: packet::Origins>(
        &self,
        p: &packet::Packet<O>,
        reach: packet::Lanes,
        state: &mut TexelState,
    ) -> [u32; packet::LANES] {
        use packet::LANES;
        let ps = &mut state.packet;
        let mut hint = packet::splat(f32::INFINITY);
        // The lanes some hint triangle bounds.
        let mut hinted = 0u32;
        for &(ii, i) in &ps.last {
            let inst = &self.instances[ii as usize];
            let moved = self.instance_packet(inst, p);
            let q = moved.as_ref().unwrap_or(p);
            let tri = &self.blases[inst.blas as usize].triangles[i as usize];
            let (hits, t, _) = packet::intersect_triangle(tri, q, self.near, packet::splat(f32::INFINITY), p.lanes);
            hinted |= hits;
            hint = packet::min_where(hint, t, packet::lane_mask(hits));
        }
        // A hint at or beyond a lane's reach bounds nothing, as in `trace_fast_within`.
        let hint_bound = packet::scaled(hint, 1.0 + TIE_EPSILON);
        hinted &= packet::less_than(hint_bound, reach);
        let hint = packet::select(packet::splat(f32::INFINITY), hint, packet::lane_mask(hinted));
        ps.windows.reset(packet::select(reach, hint_bound, packet::lane_mask(hinted)));
        let (hint_t, reach) = (packet::store(hint), packet::store(reach));
        let PacketState { windows, last, winners, tlas_stack, blas_stack } = ps;
        match &self.tlas {
            None => {}
            Some(_) if self.instances.len() == 1 => self.traverse_blas_packet(0, p, p.lanes, blas_stack, windows),
            Some(tlas) => packet::traverse(tlas, p, p.lanes, tlas_stack, windows, |w, ii, lanes| {
                self.traverse_blas_packet(ii, p, lanes, blas_stack, w)
            }),
        }
        let mut ids = [NO_OBJECT; LANES];
        winners.clear();
        // Lanes with neither a hit nor a hint saw nothing.
        let mut left = (windows.filled | hinted) & p.lanes;
        while left != 0 {
            let l = left.trailing_zeros() as usize;
            left &= left - 1;
            let window = &mut windows.windows[l];
            // A hinted lane without a hit of its own (its window is stale) is traced again too.
            if windows.filled & (1 << l) == 0 || window.t_near > hint_t[l] {
                window.clear();
                window.bound = reach[l];
                // SAFETY: AVX2 and the rest of `wide_instructions` are present (the callers are
                // `trace_band_wide`, `first_hits_from_packets` and `first_hits_packets`, compiled
                // with them).
                unsafe { self.traverse_all_wide(p.origin_of(l), p.direction(l), window) };
            }
            let Some(h) = window.winner() else { continue };
            if !winners.contains(&(h.instance, h.tri)) {
                winners.push((h.instance, h.tri));
            }
            ids[l] = h.id();
        }
        // A packet of misses keeps the last hits: the next packet may well hit them.
        if !winners.is_empty() {
            std::mem::swap(last, winners);
        }
        ids
    }

    /// Adds to each lane's window the hits of instance `ii`'s BLAS nearer than its bound.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn traverse_blas_packet<O: packet::Origins>(
        &self,
        ii: usize,
        p: &packet::Packet<O>,
        lanes: u32,
        stack: &mut Vec<(u32, u32)>,
        windows: &mut LaneWindows,
    ) {
        use packet::LaneBounds;
        let inst = &self.instances[ii];
        let blas = &self.blases[inst.blas as usize];
        let moved = self.instance_packet(inst, p);
        let q = moved.as_ref().unwrap_or(p);
        packet::traverse(&blas.bvh, q, lanes, stack, windows, |w, i, m| {
            let (hits, t, back) = packet::intersect_triangle(&blas.triangles[i], q, self.near, w.tmax(), m);
            if hits != 0 {
                w.add(hits, t, |l, t| blas.hit(inst, ii, i, t, back & (1 << l) != 0));
            }
        });
    }

    /// The packet of `inst`'s BLAS carried into model space lane by lane, as
    /// [`CpuBackend::instance_ray`] carries one ray; `None` where the BLAS is in world space (the
    /// packet itself serves: copying its 700 bytes per BLAS and per hint cost more than a node
    /// test).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn instance_packet<O: packet::Origins>(&self, inst: &Instance, p: &packet::Packet<O>) -> Option<packet::Packet<O>> {
        Some(p.transformed(inst.to_model.as_ref()?))
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// After any hits, each lane's bound in registers is its tie window's own bound (the
        /// hint's bound before its first hit), and its nearest hit the window's.
        #[test]
        fn lane_bounds_are_the_tie_windows_bounds(
            hint in prop::collection::vec(prop_oneof![Just(f32::INFINITY), 0.1f32..10.0], packet::LANES),
            hits in prop::collection::vec((0u32..=packet::ALL_LANES, prop::collection::vec(0.1f32..10.0, packet::LANES)), 0..12),
        ) {
            if !super::super::wide_instructions() {
                eprintln!("skipped: no AVX2");
                return Ok(());
            }
            let hint: [f32; packet::LANES] = hint.try_into().expect("LANES long");
            let mut w = LaneWindows::default();
            // SAFETY: AVX2 is present (checked above).
            let (bounds, t_near) = unsafe {
                w.reset(packet::load(&hint));
                for (lanes, t) in &hits {
                    let t: [f32; packet::LANES] = t.clone().try_into().expect("LANES long");
                    // Only hits inside the bound reach a window (the triangle test's `tmax`).
                    let inside = (0..packet::LANES)
                        .filter(|&l| lanes & (1 << l) != 0 && t[l] <= packet::store(w.bounds)[l])
                        .fold(0, |m, l| m | 1 << l);
                    let hit = |l: usize, t: f32| Hit { t, obj: l as u32, back: false, instance: 0, tri: 0 };
                    w.add(inside, packet::load(&t), hit);
                }
                (packet::store(w.bounds), packet::store(w.t_near))
            };
            for l in 0..packet::LANES {
                if w.filled & (1 << l) != 0 {
                    prop_assert_eq!(bounds[l].to_bits(), w.windows[l].bound.to_bits(), "lane {}", l);
                    prop_assert_eq!(t_near[l].to_bits(), w.windows[l].t_near.to_bits(), "lane {}", l);
                } else {
                    prop_assert_eq!(bounds[l].to_bits(), hint[l].to_bits(), "lane {}", l);
                }
            }
        }
    }
}
