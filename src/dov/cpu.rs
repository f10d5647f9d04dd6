//! The CPU backend: one ray per texel centre, cast through a two-level BVH (obvhs CWBVHs).
//!
//! - Bottom level: one BVH per base mesh that two or more objects instance, in the mesh's model
//!   space, built once and shared by its instances; plus one BVH over the world-space triangles of
//!   every other object (meshes used once, and transforms that are not invertible affine maps),
//!   which is exactly the flat BVH of a scene without instancing.
//! - Top level: a BVH over the instances' world boxes.
//!
//! Meshes used once are not given a BLAS each: they are stored once either way, and on the large
//! city without its instances a TLAS over 10 941 single-use meshes cost 22 % more CPU per sample
//! point than one world-space BLAS (docs/dov.md, speed).
//!
//! `render_ids` traces 8 × 8 tiles, each ray first bounded by the previous texel's winning
//! triangle, with an AVX2 copy of the tracer chosen at run time that takes each tile in packets of
//! 4 × 4 rays (`packet`: one AVX2 lane per ray); [`CpuBackend::render_ids_reference`]
//! is the plain per-ray tracer it must equal (docs/dov.md, "Per-ray speed against Embree").
//!
//! A ray entering an instance's box (nearer than the best hit so far) is carried into model space
//! by the inverse transform, direction not normalised, so the ray parameter `t` is the same in
//! every space and hits of different instances compare directly.

use std::time::Duration;

use glam::{Affine3A, UVec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb as BvhAabb,
    cwbvh::{
        CwBvh,
        builder::{build_cwbvh, build_cwbvh_from_tris},
        node::{CwBvhNode, extract_byte64},
    },
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use rayon::prelude::*;

use super::probe::{RayCaster, SurfaceTargets};
use super::{BACK_FACE_BIT, CubeMap, DovBackend, IdCube, NO_OBJECT, check_object_count, cubemap};
use crate::error::{Error, Result};
use crate::scene::Scene;

#[cfg(target_arch = "x86_64")]
mod packet;

/// Two hits whose ray parameters differ by less than this fraction are a tie; the lower object id
/// wins. Coplanar faces of two objects otherwise flicker between them with rounding.
pub const TIE_EPSILON: f32 = 1e-5;
/// Relative depth within which two surfaces are a tie up to `f32` rounding of rays that start
/// within about `near` of them (tests of the fast path, [`CpuBackend::surfaces_at_nearest`]).
pub const AMBIGUOUS_DEPTH: f32 = 1e-3;

/// The largest BLAS built with obvhs's very slow preset; bigger ones get the slow preset.
const VERY_SLOW_BUILD_MAX_TRIANGLES: usize = 1 << 20;

/// Texels per side of the square tiles the fast path traces one after another.
const TILE: usize = 8;

/// What the fast path carries from one texel to the next on one thread.
#[derive(Default)]
struct TexelState {
    window: TieWindow,
    /// The previous texel's winning hit: instance and triangle.
    last: Option<(u32, u32)>,
    #[cfg(target_arch = "x86_64")]
    packet: PacketState,
}

/// What the packet tracer carries from one packet to the next on one thread.
#[cfg(target_arch = "x86_64")]
#[derive(Default)]
struct PacketState {
    windows: LaneWindows,
    /// The previous packet's winning hits (instance, triangle), each once: tested first.
    last: Vec<(u32, u32)>,
    /// This packet's, while it is traced.
    winners: Vec<(u32, u32)>,
    tlas_stack: Vec<(u32, u32)>,
    blas_stack: Vec<(u32, u32)>,
}

/// One tie window per lane of a packet, and their bounds side by side (the lanes' `tmax`).
#[cfg(target_arch = "x86_64")]
#[derive(Default)]
struct LaneWindows {
    windows: [TieWindow; packet::LANES],
    bounds: [f32; packet::LANES],
}

#[cfg(target_arch = "x86_64")]
impl LaneWindows {
    /// Empties every window, with the bound `bounds[l]` on lane `l`.
    fn reset(&mut self, bounds: [f32; packet::LANES]) {
        for (w, &b) in self.windows.iter_mut().zip(&bounds) {
            w.clear();
            w.bound = b;
        }
        self.bounds = bounds;
    }

    #[inline(always)]
    fn add(&mut self, lane: usize, hit: Hit) {
        self.windows[lane].add(hit);
        self.bounds[lane] = self.windows[lane].bound;
    }
}

#[cfg(target_arch = "x86_64")]
impl packet::LaneBounds for LaneWindows {
    #[inline(always)]
    fn tmax(&self) -> &[f32; packet::LANES] {
        &self.bounds
    }
}

/// One bottom-level BVH and its triangles in the BVH's primitive order (no indirection while
/// tracing).
struct Blas {
    bvh: CwBvh,
    triangles: Vec<RayTriangle>,
    /// Object index of each triangle: filled for the world-space BLAS, empty for a base mesh's
    /// (its instance carries the object).
    objects: Vec<u32>,
}

/// One primitive of the top level.
struct Instance {
    blas: u32,
    /// The object, or [`NO_OBJECT`] for the world-space BLAS (objects per triangle).
    object: u32,
    /// World → model space; `None` for the world-space BLAS.
    to_model: Option<Affine3A>,
}

impl Blas {
    /// The hit on triangle `i` at `t` through instance `inst` (number `ii`), seen from behind
    /// (`back`) or not. The back-face test is done in the triangle's own space: with n the
    /// model-space normal and M the linear part of the transform, the world normal of the
    /// (winding-corrected) world triangle is |det M|·M⁻ᵀn, so its sign against M·d is the sign of
    /// n·d.
    #[inline(always)]
    fn hit(&self, inst: &Instance, ii: usize, i: usize, t: f32, back: bool) -> Hit {
        let obj = if inst.object == NO_OBJECT { self.objects[i] } else { inst.object };
        Hit { t, obj, back, instance: ii as u32, tri: i as u32 }
    }

    /// The hit of `ray` (in this BLAS's space) on triangle `i` at `t`.
    #[inline(always)]
    fn ray_hit(&self, inst: &Instance, ii: usize, i: usize, t: f32, ray: &Ray) -> Hit {
        self.hit(inst, ii, i, t, self.triangles[i].seen_from_behind(ray.direction))
    }
}

/// A triangle with the edges and normal of obvhs's Möller–Trumbore test precomputed: the test
/// below is [`Triangle::intersect`]'s arithmetic operation for operation (so hits and `t` are
/// bit-identical, tested), less the two edge differences and the cross product per test.
#[derive(Clone, Copy, Debug)]
struct RayTriangle {
    v0: Vec3A,
    /// `v0 − v1` and `v2 − v0`, the order obvhs uses.
    e1: Vec3A,
    e2: Vec3A,
    /// `e1 × e2`: minus the counter-clockwise normal `(v1 − v0) × (v2 − v0)`, exactly (negation
    /// is exact in floating point).
    n: Vec3A,
}

impl RayTriangle {
    fn new(t: &Triangle) -> Self {
        let (e1, e2) = (t.v0 - t.v1, t.v2 - t.v0);
        Self { v0: t.v0, e1, e2, n: e1.cross(e2) }
    }

    /// `t` of the hit with `tmin ≤ t ≤ tmax`, or infinity.
    #[inline(always)]
    fn intersect(&self, ray: &Ray) -> f32 {
        let c = self.v0 - ray.origin;
        let r = ray.direction.cross(c);
        let inv_det = 1.0 / self.n.dot(ray.direction);
        let u = r.dot(self.e2) * inv_det;
        let v = r.dot(self.e1) * inv_det;
        let w = 1.0 - u - v;
        // A sign bit in u, v or w (−0.0 included, as obvhs) is a miss.
        let signs = u.to_bits() | v.to_bits() | w.to_bits();
        if inv_det != 0.0 && signs & 0x8000_0000 == 0 {
            let t = self.n.dot(c) * inv_det;
            if t >= ray.tmin && t <= ray.tmax {
                return t;
            }
        }
        f32::INFINITY
    }

    /// Whether a ray along `dir` (in this triangle's space) sees its back: the counter-clockwise
    /// normal points along the ray.
    #[inline(always)]
    fn seen_from_behind(&self, dir: Vec3A) -> bool {
        self.n.dot(dir) < 0.0
    }
}

/// One ray-triangle hit.
#[derive(Clone, Copy, Debug)]
struct Hit {
    t: f32,
    obj: u32,
    back: bool,
    /// Instance and triangle (in its BLAS's order): where the next texel's ray looks first.
    instance: u32,
    tri: u32,
}

impl Hit {
    /// The texel id this hit gives: its object, with [`BACK_FACE_BIT`] when seen from behind.
    fn id(&self) -> u32 {
        if self.back { self.obj | BACK_FACE_BIT } else { self.obj }
    }
}

/// The hits of one ray inside the tie window of the nearest so far, `t ≤ t_near·(1 + ε)`. The
/// ray's id is a function of the set of its hits alone, whatever order a traversal finds them in:
/// the lowest object id in the window, its nearest triangle there, a front face before a back face
/// at equal `t` (docs/decisions.md, 41). So any traversal order, BVH or early bound gives the id
/// the reference tracer gives.
#[derive(Default)]
struct TieWindow {
    hits: Vec<Hit>,
    /// `t_near·(1 + ε)`: hits beyond it can no longer change the id (infinity while empty).
    bound: f32,
    t_near: f32,
}

impl TieWindow {
    fn clear(&mut self) {
        self.hits.clear();
        self.bound = f32::INFINITY;
        self.t_near = f32::INFINITY;
    }

    /// Adds a hit with `t ≤ self.bound`.
    #[inline(always)]
    fn add(&mut self, hit: Hit) {
        if hit.t < self.t_near {
            self.t_near = hit.t;
            self.bound = hit.t * (1.0 + TIE_EPSILON);
            let bound = self.bound;
            self.hits.retain(|h| h.t <= bound);
        }
        self.hits.push(hit);
    }

    /// The winning hit, if any.
    fn winner(&self) -> Option<&Hit> {
        self.hits.iter().min_by(|a, b| a.obj.cmp(&b.obj).then(a.t.total_cmp(&b.t)).then(a.back.cmp(&b.back)))
    }

    fn id(&self) -> u32 {
        self.winner().map_or(NO_OBJECT, Hit::id)
    }
}

/// Ray casting through a two-level BVH. Building costs O(T log T) for the T stored triangles
/// (each instanced base mesh once, BLASes built in parallel) plus O(I log I) for I instances;
/// each [`DovBackend::render_ids`] casts 6·R² rays, in parallel on rayon's pool.
pub struct CpuBackend {
    cube: CubeMap,
    near: f32,
    tlas: Option<CwBvh>,
    /// In the TLAS's primitive order.
    instances: Vec<Instance>,
    blases: Vec<Blas>,
    /// Triangles of the scene with instances counted each time (for [`DovBackend::name`]).
    triangle_count: u64,
    /// Whether `render_ids` runs [`CpuBackend::trace_band_wide`].
    wide: bool,
    /// Whether [`CpuBackend::trace_band_wide`] traces packets of rays (else one ray at a time).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    packets: bool,
    /// Where probe rays aim ([`super::probe`]).
    targets: SurfaceTargets,
}

/// What one BLAS is built from.
enum BlasSource {
    /// World-space triangles of these objects.
    World(Vec<usize>),
    /// A base mesh in model space.
    Mesh(usize),
}

impl CpuBackend {
    /// Builds the BVHs over `scene` at `resolution` texels per face edge, with the near plane of
    /// [`super::default_near`].
    pub fn new(scene: &Scene, resolution: u32) -> Result<Self> {
        Self::with_near(scene, resolution, super::default_near(&scene.bounds()))
    }

    /// As [`CpuBackend::new`] with an explicit near distance (surfaces nearer than `near` along a
    /// face's forward axis are ignored, exactly as the GPU backend's near plane clips them).
    pub fn with_near(scene: &Scene, resolution: u32, near: f32) -> Result<Self> {
        check_resolution_and_near(resolution, near)?;
        check_object_count(scene)?;
        // Which objects are instanced: an invertible affine transform of a mesh two or more such
        // objects share. Every other object goes into the world-space BLAS.
        let to_model: Vec<Option<Affine3A>> = scene.objects.iter().map(|o| inverse_affine(&o.transform)).collect();
        let mut uses = vec![0u32; scene.meshes.len()];
        for (o, inv) in scene.objects.iter().zip(&to_model) {
            if inv.is_some() && scene.meshes[o.mesh as usize].mesh.triangle_count() > 0 {
                uses[o.mesh as usize] += 1;
            }
        }
        let instanced = |i: usize| to_model[i].is_some() && uses[scene.objects[i].mesh as usize] >= 2;
        let world: Vec<usize> = (0..scene.objects.len()).filter(|&i| !instanced(i)).collect();
        let mut sources = Vec::new();
        let mut mesh_blas = vec![u32::MAX; scene.meshes.len()];
        if !world.is_empty() {
            sources.push(BlasSource::World(world));
        }
        for (m, &n) in uses.iter().enumerate() {
            if n >= 2 {
                mesh_blas[m] = sources.len() as u32;
                sources.push(BlasSource::Mesh(m));
            }
        }
        // The world-space BLAS (the biggest, usually) starts first; the obvhs builds are parallel
        // inside too.
        let blases: Vec<Option<Blas>> = sources.par_iter().map(|s| build_blas(scene, s)).collect();

        let mut instances = Vec::new();
        let mut boxes = Vec::new();
        let mut blas_index = vec![u32::MAX; blases.len()];
        let mut kept = Vec::new();
        for (i, b) in blases.into_iter().enumerate() {
            if let Some(b) = b {
                blas_index[i] = kept.len() as u32;
                kept.push(b);
            }
        }
        if let Some(BlasSource::World(_)) = sources.first()
            && blas_index[0] != u32::MAX
        {
            instances.push(Instance { blas: blas_index[0], object: NO_OBJECT, to_model: None });
            boxes.push(kept[blas_index[0] as usize].bvh.total_aabb);
        }
        let mesh_boxes: Vec<crate::geom::Aabb> = scene.meshes.iter().map(|m| m.mesh.bounds()).collect();
        for (i, o) in scene.objects.iter().enumerate() {
            if !instanced(i) {
                continue;
            }
            let b = blas_index[mesh_blas[o.mesh as usize] as usize];
            instances.push(Instance { blas: b, object: i as u32, to_model: to_model[i] });
            boxes.push(padded(mesh_boxes[o.mesh as usize].transformed(&o.transform)));
        }
        let tlas = if instances.is_empty() {
            None
        } else {
            let tlas = build_cwbvh(&boxes, BvhBuildParams::medium_build(), &mut Duration::default());
            let mut slots: Vec<Option<Instance>> = instances.into_iter().map(Some).collect();
            instances =
                tlas.primitive_indices.iter().map(|&i| slots[i as usize].take().expect("one leaf each")).collect();
            Some(tlas)
        };
        Ok(Self {
            cube: CubeMap::new(resolution),
            near,
            tlas,
            instances,
            blases: kept,
            triangle_count: scene.triangle_count(),
            wide: wide_instructions(),
            packets: true,
            targets: SurfaceTargets::new(scene),
        })
    }

    pub fn near(&self) -> f32 {
        self.near
    }

    /// Lets `render_ids` use the AVX2 build of its tracer where the CPU has one (the default), or
    /// keeps it to the portable build (tests compare both; the ids are the same).
    pub fn set_wide_instructions(&mut self, on: bool) {
        self.wide = on && wide_instructions();
    }

    /// Lets the AVX2 build trace packets of 4 × 4 rays (the default), or one ray at a time (the
    /// previous fast path, kept for comparison: tests and `ray-speed`; the ids are the same).
    pub fn set_packets(&mut self, on: bool) {
        self.packets = on;
    }

    /// The id seen from `origin` along `dir` (a texel direction whose forward component is 1):
    /// among the hits with `t ≥ near`, those within [`TIE_EPSILON`] of the nearest are ties and the
    /// lower object id wins, with [`BACK_FACE_BIT`] when its triangle faces away. The reference
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
    /// its BLAS; triangles carry their precomputed edges. The id depends only on the set of hits
    /// the BVH lets through inside the tie window, which every route finds whole, so it equals
    /// `trace`'s. The bound is only trusted once the traversal itself reaches a hit at least as
    /// near: a ray grazing a box edge can hit a triangle whose box test it fails (rounding), and
    /// the reference would not see that hit; then the ray is traced again without the bound.
    #[inline(always)]
    fn trace_fast<const WIDE: bool>(&self, o: Vec3A, d: Vec3A, state: &mut TexelState) -> u32 {
        let window = &mut state.window;
        window.clear();
        let mut hint_t = f32::INFINITY;
        if let Some((ii, i)) = state.last {
            let inst = &self.instances[ii as usize];
            let ray = self.instance_ray(inst, o, d, f32::INFINITY);
            hint_t = self.blases[inst.blas as usize].triangles[i as usize].intersect(&ray);
            window.bound = hint_t * (1.0 + TIE_EPSILON);
        }
        self.traverse_all::<WIDE>(o, d, window);
        if window.t_near > hint_t {
            window.clear();
            self.traverse_all::<WIDE>(o, d, window);
        }
        // A miss keeps the last hit: the next ray may well hit it.
        if let Some(h) = window.winner() {
            state.last = Some((h.instance, h.tri));
        }
        window.id()
    }

    /// Adds to `window` the hits of every instance nearer than its bound.
    #[inline(always)]
    fn traverse_all<const WIDE: bool>(&self, o: Vec3A, d: Vec3A, window: &mut TieWindow) {
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

impl DovBackend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu (obvhs CWBVH, {} triangles, {} threads)", self.triangle_count, rayon::current_num_threads())
    }

    fn resolution(&self) -> u32 {
        self.cube.resolution()
    }

    fn cube_map(&self) -> &CubeMap {
        &self.cube
    }

    fn ray_caster(&self) -> Option<&dyn RayCaster> {
        Some(self)
    }

    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()> {
        check_point(p)?;
        check_cube(out, self.cube.resolution())?;
        let r = self.cube.resolution() as usize;
        let this = &*self;
        let o = Vec3A::from(p);
        // One rayon task per band of TILE rows of a face, traced tile by tile: neighbouring rays
        // share BVH nodes (in cache) and, mostly, their nearest triangle (tested first).
        let bands = out.ids.par_chunks_mut(r * r).enumerate().flat_map(|(face, ids)| {
            ids.par_chunks_mut(r * TILE).enumerate().map(move |(band, ids)| (face, band * TILE, ids))
        });
        let wide = self.wide;
        bands.for_each_init(TexelState::default, |state, (face, row0, ids)| {
            #[cfg(target_arch = "x86_64")]
            if wide {
                // SAFETY: the CPU has the features (checked at run time by `wide_instructions`).
                return unsafe { this.trace_band_wide(o, face, row0, ids, state) };
            }
            this.trace_band::<false>(o, face, row0, ids, state);
        });
        Ok(())
    }
}

impl RayCaster for CpuBackend {
    /// [`CpuBackend::trace`]'s id among the hits within `reach`, by the fast path's traversal
    /// (the AVX2 build where the CPU has it), `dir` scaled so that its largest component is ±1,
    /// the texel directions' convention, so that the near plane means the same distance.
    fn first_hit(&self, origin: Vec3, dir: Vec3, reach: f32) -> u32 {
        thread_local! {
            static WINDOW: std::cell::RefCell<TieWindow> = std::cell::RefCell::new(TieWindow::default());
        }
        let scale = dir.abs().max_element();
        let (o, d) = (Vec3A::from(origin), Vec3A::from(dir / scale));
        WINDOW.with_borrow_mut(|window| {
            window.clear();
            window.bound = reach * scale;
            #[cfg(target_arch = "x86_64")]
            if self.wide {
                // SAFETY: the CPU has the features (checked at run time by `wide_instructions`).
                unsafe { self.traverse_all_wide(o, d, window) };
                return window.id();
            }
            self.traverse_all::<false>(o, d, window);
            window.id()
        })
    }

    fn targets(&self) -> &SurfaceTargets {
        &self.targets
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

/// obvhs's lower bound on a child's entry distance (its private `EPSILON`).
const NODE_TMIN: f32 = 0.0001;

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

/// Whether this CPU runs [`CpuBackend::trace_band_wide`] (x86-64 with AVX2, FMA, BMI1/2, LZCNT and
/// POPCNT: every x86-64 since 2013).
fn wide_instructions() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

impl CpuBackend {
    /// Traces the texels of `rows` rows (`ids.len() / R`) of `face` from `row0`, tile by tile.
    #[inline(always)]
    fn trace_band<const WIDE: bool>(
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
    unsafe fn traverse_all_wide(&self, o: Vec3A, d: Vec3A, window: &mut TieWindow) {
        self.traverse_all::<true>(o, d, window)
    }

    /// [`CpuBackend::trace_band`] compiled for newer x86-64 CPUs, as Embree picks its kernels at
    /// run time. The traversal counts and finds bits per node (one instruction each with POPCNT and
    /// LZCNT, a dozen without); the arithmetic is the same operations (Rust never fuses a
    /// multiply-add by itself), so the ids are bit-identical (tests/dov_fast_path.rs).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn trace_band_wide(&self, o: Vec3A, face: usize, row0: usize, ids: &mut [u32], state: &mut TexelState) {
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
        use packet::{LANES, PACKET_COLS};
        let r = self.cube.resolution() as usize;
        let rows = ids.len() / r;
        state.packet.last.clear();
        for col0 in (0..r).step_by(TILE) {
            let col1 = (col0 + TILE).min(r);
            for pr in (0..rows).step_by(LANES / PACKET_COLS) {
                for pc in (col0..col1).step_by(PACKET_COLS) {
                    let texel = |l: usize| (pr + l / PACKET_COLS, pc + l % PACKET_COLS);
                    let mut dirs = [Vec3A::ZERO; LANES];
                    let mut lanes = 0u32;
                    for (l, dir) in dirs.iter_mut().enumerate() {
                        let (row, col) = texel(l);
                        if row < rows && col < col1 {
                            *dir = self.cube.texel_direction(face, (row0 + row) as u32, col as u32).into();
                            lanes |= 1 << l;
                        }
                    }
                    let lane_ids = self.trace_packet(&packet::Packet::new(o, &dirs, lanes), state);
                    for (l, id) in lane_ids.iter().enumerate().filter(|&(l, _)| lanes & (1 << l) != 0) {
                        let (row, col) = texel(l);
                        ids[row * r + col] = *id;
                    }
                }
            }
        }
    }

    /// [`CpuBackend::trace_fast`] for the lanes of a packet together: the previous packet's
    /// winning triangles bound each lane from the start, one packet traversal finds every lane's
    /// hits inside its bound, and a lane whose bound the traversal did not confirm (a hit it
    /// cannot reach, see `trace_fast`) is traced again alone without it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn trace_packet(&self, p: &packet::Packet, state: &mut TexelState) -> [u32; packet::LANES] {
        use packet::LANES;
        let ps = &mut state.packet;
        let mut hint_t = [f32::INFINITY; LANES];
        for &(ii, i) in &ps.last {
            let inst = &self.instances[ii as usize];
            let q = self.instance_packet(inst, p);
            let tri = &self.blases[inst.blas as usize].triangles[i as usize];
            let (hits, t, _) = packet::intersect_triangle(tri, &q, self.near, packet::splat(f32::INFINITY), p.lanes);
            let t = packet::store(t);
            for l in (0..LANES).filter(|l| hits & (1 << l) != 0) {
                hint_t[l] = hint_t[l].min(t[l]);
            }
        }
        ps.windows.reset(hint_t.map(|t| t * (1.0 + TIE_EPSILON)));
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
        for l in (0..LANES).filter(|l| p.lanes & (1 << l) != 0) {
            let window = &mut windows.windows[l];
            if window.t_near > hint_t[l] {
                window.clear();
                // SAFETY: AVX2 and the rest of `wide_instructions` are present (the only caller
                // is `trace_band_wide`).
                unsafe { self.traverse_all_wide(p.origin, p.dirs[l], window) };
            }
            if let Some(h) = window.winner()
                && !winners.contains(&(h.instance, h.tri))
            {
                winners.push((h.instance, h.tri));
            }
            ids[l] = window.id();
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
    fn traverse_blas_packet(
        &self,
        ii: usize,
        p: &packet::Packet,
        lanes: u32,
        stack: &mut Vec<(u32, u32)>,
        windows: &mut LaneWindows,
    ) {
        use packet::{LANES, LaneBounds};
        let inst = &self.instances[ii];
        let blas = &self.blases[inst.blas as usize];
        let q = self.instance_packet(inst, p);
        packet::traverse(&blas.bvh, &q, lanes, stack, windows, |w, i, m| {
            let tmax = packet::load(w.tmax());
            let (hits, t, back) = packet::intersect_triangle(&blas.triangles[i], &q, self.near, tmax, m);
            if hits != 0 {
                let t = packet::store(t);
                for l in (0..LANES).filter(|l| hits & (1 << l) != 0) {
                    w.add(l, blas.hit(inst, ii, i, t[l], back & (1 << l) != 0));
                }
            }
        });
    }

    /// The packet of `inst`'s BLAS: `p`, or carried into model space lane by lane as
    /// [`CpuBackend::instance_ray`] carries one ray.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn instance_packet(&self, inst: &Instance, p: &packet::Packet) -> packet::Packet {
        match &inst.to_model {
            None => *p,
            Some(m) => {
                let dirs = p.dirs.map(|d| m.transform_vector3a(d));
                packet::Packet::new(m.transform_point3a(p.origin), &dirs, p.lanes)
            }
        }
    }
}

/// Builds one BLAS; `None` when it has no triangles.
fn build_blas(scene: &Scene, source: &BlasSource) -> Option<Blas> {
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
    let bvh = build_cwbvh_from_tris(&tris, params, &mut Duration::default());
    let triangles = bvh.primitive_indices.iter().map(|&i| RayTriangle::new(&tris[i as usize])).collect();
    let objects =
        if objects.is_empty() { objects } else { bvh.primitive_indices.iter().map(|&i| objects[i as usize]).collect() };
    Some(Blas { bvh, triangles, objects })
}

fn triangle(t: [Vec3; 3]) -> Triangle {
    Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }
}

/// World → model space of an affine, invertible transform whose inverse is finite; `None` for
/// any other (such objects are traced in world space, as the flat BVH did).
fn inverse_affine(m: &glam::Mat4) -> Option<Affine3A> {
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
fn padded(b: crate::geom::Aabb) -> BvhAabb {
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
    for (i, o) in scene.objects.iter().enumerate() {
        let mirrored = o.transform.determinant() < 0.0;
        for t in scene.object_triangles(i) {
            triangles.push(if mirrored { [t[0], t[2], t[1]] } else { t });
            objects.push(i as u32);
        }
    }
    Ok((triangles, objects))
}

pub(crate) fn check_resolution_and_near(resolution: u32, near: f32) -> Result<()> {
    let max = super::cubemap::MAX_RESOLUTION;
    if resolution == 0 || resolution > max {
        return Err(Error::bad_param("resolution", format!("{resolution} is not in 1..={max}")));
    }
    if !(near.is_finite() && near > 0.0) {
        return Err(Error::bad_param("near", format!("{near} must be finite and > 0")));
    }
    Ok(())
}

pub(crate) fn check_point(p: Vec3) -> Result<()> {
    if p.is_finite() { Ok(()) } else { Err(Error::bad_param("point", format!("{p} is not finite"))) }
}

pub(crate) fn check_cube(out: &IdCube, resolution: u32) -> Result<()> {
    let r = resolution as usize;
    if out.resolution != resolution || out.ids.len() != cubemap::FACE_COUNT * r * r {
        return Err(Error::bad_param(
            "id cube",
            format!("resolution {} does not match the backend's {resolution}", out.resolution),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn vec3a() -> impl Strategy<Value = Vec3A> {
        // Small integers make degenerate, edge-on and exactly-on-edge cases common.
        prop_oneof![
            [-4.0f32..4.0, -4.0..4.0, -4.0..4.0].prop_map(Vec3A::from),
            [-2i8..3, -2..3, -2..3].prop_map(|v| Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32)),
        ]
    }

    /// Boxes of many sizes around the origin.
    fn boxes() -> Scene {
        use crate::dov::precompute::halton3;
        let mut s = Scene::default();
        for k in 1..=30 {
            let p = (halton3(k) - Vec3::splat(0.5)) * Vec3::new(12.0, 6.0, 12.0);
            let size = Vec3::splat(0.05) + halton3(k + 100) * 2.0;
            s.add_box(&format!("box {k}"), p, p + size);
        }
        s
    }

    proptest! {
        /// A probe ray's id (the AVX2 traversal where the CPU has it, its direction rescaled) is
        /// the id of a plain traversal within its reach.
        #[test]
        fn first_hit_is_a_plain_traversal_within_reach(
            rays in prop::collection::vec((vec3a(), vec3a(), prop_oneof![Just(f32::INFINITY), 0.1f32..10.0]), 1..40),
        ) {
            let scene = boxes();
            let cpu = CpuBackend::new(&scene, 8).unwrap();
            for (o, d, reach) in rays {
                let scale = d.abs().max_element();
                prop_assume!(scale > 0.0);
                // The reach in lengths of `d`, and the bound it makes along `d / scale` (the same
                // rounding as `first_hit`'s).
                let reach = reach / scale;
                let mut plain = TieWindow::default();
                plain.clear();
                plain.bound = reach * scale;
                cpu.traverse_all::<false>(o, d / scale, &mut plain);
                prop_assert_eq!(cpu.first_hit(o.into(), d.into(), reach), plain.id());
            }
        }

        /// The precomputed test is obvhs's, bit for bit: the fast path and the reference tracer may
        /// then differ in nothing but the order in which they meet triangles.
        #[test]
        fn ray_triangle_is_obvhs_triangle_bit_for_bit(
            v in [vec3a(), vec3a(), vec3a()], o in vec3a(), d in vec3a(), tmin in 0.0f32..0.5, tmax in 0.5f32..20.0,
        ) {
            let tri = Triangle { v0: v[0], v1: v[1], v2: v[2] };
            let ray = Ray { origin: o, direction: d, inv_direction: d.recip(), tmin, tmax };
            prop_assert_eq!(RayTriangle::new(&tri).intersect(&ray).to_bits(), tri.intersect(&ray).to_bits());
            // The back-face sign: e1 × e2 is minus (v1 − v0) × (v2 − v0), exactly.
            let ccw = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0);
            prop_assert_eq!(RayTriangle::new(&tri).seen_from_behind(d), ccw.dot(d) > 0.0);
        }

        /// The tie window's id does not depend on the order hits arrive in (as long as each is
        /// within the bound at its arrival, as a traversal guarantees).
        #[test]
        fn tie_window_id_ignores_hit_order(
            hits in prop::collection::vec((0u32..4, 0u32..6, any::<bool>()), 1..12), seed in any::<u64>(),
        ) {
            // t values 1 + k·4e-6: neighbours tie, the far ones chain beyond one window.
            let hits: Vec<Hit> = hits
                .iter()
                .enumerate()
                .map(|(i, &(k, obj, back))| Hit { t: 1.0 + k as f32 * 4e-6, obj, back, instance: 0, tri: i as u32 })
                .collect();
            let id = |order: &[Hit]| {
                let mut w = TieWindow::default();
                w.clear();
                for h in order {
                    if h.t <= w.bound {
                        w.add(*h);
                    }
                }
                w.id()
            };
            let mut shuffled = hits.clone();
            let mut s = seed;
            for i in (1..shuffled.len()).rev() {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                shuffled.swap(i, (s >> 33) as usize % (i + 1));
            }
            prop_assert_eq!(id(&hits), id(&shuffled));
        }
    }
}
