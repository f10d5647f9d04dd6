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
//! 4 × 8 rays (`packet`: one AVX2 lane per ray, [`PACKET_TEXELS`]);
//! [`CpuBackend::render_ids_reference`] is the plain per-ray tracer it must equal (docs/dov.md,
//! "Per-ray speed against Embree").
//!
//! A ray entering an instance's box (nearer than the best hit so far) is carried into model space
//! by the inverse transform, direction not normalised, so the ray parameter `t` is the same in
//! every space and hits of different instances compare directly.

use std::time::Duration;

use glam::{Affine3A, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh},
};
use rayon::prelude::*;

use super::rays::{RayCaster, SurfaceTargets};
use super::{CubeMap, DovBackend, IdCube, NO_OBJECT, check_object_count, cubemap};
use crate::error::{Error, Param, Result};
use crate::scene::Scene;

mod bvh;
#[cfg(target_arch = "x86_64")]
mod packet;
mod trace;

pub use bvh::world_triangles;
use bvh::{Blas, BlasSource, Instance, build_blas, inverse_affine, padded};
use trace::{TexelState, TieWindow};

/// Two hits whose ray parameters differ by less than this fraction are a tie; a front face wins,
/// then the lower object id. Coplanar faces of two objects otherwise flicker between them with rounding.
pub const TIE_EPSILON: f32 = 1e-5;
/// Relative depth within which two surfaces are a tie up to `f32` rounding of rays that start
/// within about `near` of them (tests of the fast path, [`CpuBackend::surfaces_at_nearest`]).
pub const AMBIGUOUS_DEPTH: f32 = 1e-3;

/// Columns and rows of texels the packet tracer takes together: 4 × 8 took 762 M instructions
/// and 5.0 ms per point on the engine against 786 M and 5.4 ms for 8 × 4 and 885 M and 6.6 ms for
/// 4 × 4 (docs/journal/packet-tracer.md, §5; a tile holds two).
pub const PACKET_TEXELS: (usize, usize) = (4, 8);

/// Texels per side of the square tiles the fast path traces one after another.
const TILE: usize = 8;

/// Ray casting through a two-level BVH. Building costs O(T log T) for the T stored triangles
/// (each instanced base mesh once, BLASes built in parallel) plus O(I log I) for I instances;
/// each [`DovBackend::render_ids`] casts 6·R² rays, in parallel on rayon's pool.
pub struct CpuBackend {
    cube: CubeMap,
    /// `u` of each column and `v` of each row of a face as `f32`, as `uv_direction` rounds them
    /// (the packets' texel directions; converting the cube map's `f64` per lane instead made
    /// the packets 7 % slower: 11.0 against 10.3 ms per point, `ray-speed` on the engine).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    texel_u: Vec<f32>,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    texel_v: Vec<f32>,
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
    /// Where probe rays aim ([`super::rays::SurfaceTargets`]).
    targets: SurfaceTargets,
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
        Self::build(scene, resolution, near, WORLD_BLAS_MAX_TRIANGLES)
    }

    /// [`CpuBackend::with_near`] with world BLASes of at most `world_blas_max` triangles.
    fn build(scene: &Scene, resolution: u32, near: f32, world_blas_max: u64) -> Result<Self> {
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
        let world_chunks = world_chunks(scene, world, world_blas_max);
        let world_count = world_chunks.len();
        sources.extend(world_chunks.into_iter().map(BlasSource::World));
        for (m, &n) in uses.iter().enumerate() {
            if n >= 2 {
                mesh_blas[m] = sources.len() as u32;
                sources.push(BlasSource::Mesh(m));
            }
        }
        // The world-space BLASes one after another, each obvhs build parallel inside: two at once
        // would need both builds' working memory at once ([`WORLD_BLAS_MAX_TRIANGLES`]). The
        // instanced meshes' (small, many) in parallel.
        let mut blases: Vec<Option<Blas>> = sources[..world_count].iter().map(|s| build_blas(scene, s)).collect();
        blases.par_extend(sources[world_count..].par_iter().map(|s| build_blas(scene, s)));

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
        for &b in blas_index[..world_count].iter().filter(|&&b| b != u32::MAX) {
            instances.push(Instance { blas: b, object: NO_OBJECT, to_model: None });
            boxes.push(kept[b as usize].bvh.total_aabb);
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
        let cube = CubeMap::new(resolution);
        let texel_u = (0..resolution).map(|col| cube.texel_uv(0, col).0 as f32).collect();
        let texel_v = (0..resolution).map(|row| cube.texel_uv(row, 0).1 as f32).collect();
        Ok(Self {
            cube,
            texel_u,
            texel_v,
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

    /// Lets the AVX2 build trace packets of [`PACKET_TEXELS`] rays (the default), or one ray at a
    /// time (the previous fast path, kept for comparison: tests and `ray-speed`; the ids are the
    /// same).
    pub fn set_packets(&mut self, on: bool) {
        self.packets = on;
    }

    /// The first hit of each ray (origin, direction with its largest component ±1, bound) by
    /// the fast path, compiled for this CPU's instructions: each ray bounded first by the
    /// previous one's nearest triangle.
    fn first_hits_scaled(&self, rays: &[(Vec3A, Vec3A, f32)]) -> Vec<u32> {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: the CPU has the features (checked at run time by `wide_instructions`).
            return unsafe { self.first_hits_wide(rays) };
        }
        self.first_hits_fast::<false>(rays)
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
        let (o, d, bound) = texel_scaled(origin, dir, reach);
        WINDOW.with_borrow_mut(|window| {
            window.clear();
            window.bound = bound;
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

    /// Runs of nearly parallel rays in packets, each lane from its own origin, where the CPU has
    /// AVX2 ([`CpuBackend::set_packets`]); else by the fast path, each ray bounded first by the
    /// previous one's nearest triangle.
    fn first_hits(&self, rays: &[(Vec3, Vec3)], reach: f32) -> Vec<u32> {
        let rays: Vec<(Vec3A, Vec3A, f32)> = rays.iter().map(|&(o, d)| texel_scaled(o, d, reach)).collect();
        #[cfg(target_arch = "x86_64")]
        if self.wide && self.packets {
            // SAFETY: the CPU has the features (checked at run time by `wide_instructions`).
            return unsafe { self.first_hits_packets(&rays) };
        }
        self.first_hits_scaled(&rays)
    }

    /// Sorted by direction (cube face, then Morton order on it), so that rays side by side go
    /// the same way; in packets where the CPU has AVX2 ([`CpuBackend::set_packets`]), else one
    /// after another by the fast path.
    fn first_hits_from(&self, origin: Vec3, rays: &[(Vec3, f32)]) -> Vec<u32> {
        let scaled: Vec<(Vec3A, f32)> = rays
            .iter()
            .map(|&(d, reach)| {
                let (_, d, bound) = texel_scaled(origin, d, reach);
                (d, bound)
            })
            .collect();
        let mut order: Vec<u32> = (0..rays.len() as u32).collect();
        order.sort_by_cached_key(|&i| direction_order(scaled[i as usize].0));
        let sorted: Vec<(Vec3A, f32)> = order.iter().map(|&i| scaled[i as usize]).collect();
        let o = Vec3A::from(origin);
        let traced = match () {
            // SAFETY: the CPU has the features (checked at run time by `wide_instructions`).
            #[cfg(target_arch = "x86_64")]
            () if self.wide && self.packets => unsafe { self.first_hits_from_packets(o, &sorted) },
            () => self.first_hits_scaled(&sorted.iter().map(|&(d, bound)| (o, d, bound)).collect::<Vec<_>>()),
        };
        let mut ids = vec![NO_OBJECT; rays.len()];
        for (&i, id) in order.iter().zip(traced) {
            ids[i as usize] = id;
        }
        ids
    }

    fn targets(&self) -> &SurfaceTargets {
        &self.targets
    }
}

/// Where a direction (largest component ±1) sorts among a point's rays: its cube face, then the
/// Morton order of its place on the face, so that neighbours in the order point nearly the same
/// way.
fn direction_order(d: Vec3A) -> u64 {
    let a = d.abs();
    let (axis, u, v) = if a.x >= a.y && a.x >= a.z {
        (0, d.y, d.z)
    } else if a.y >= a.z {
        (1, d.x, d.z)
    } else {
        (2, d.x, d.y)
    };
    let face = 2 * axis as u64 + u64::from(d[axis] < 0.0);
    face << 30 | u64::from(crate::geom::morton3(Vec3::new(0.5 * (u + 1.0), 0.5 * (v + 1.0), 0.0)))
}

/// The most world-space triangles one BLAS takes. A bigger world goes into several BLASes of
/// spatially compact groups of objects, built one after another: an obvhs build holds about
/// 250 bytes a triangle of working memory beside what its BVH keeps (the large city's 10 M
/// world triangles in one build: 4.5 GB at its peak against 2.0 GB after), and the huge city's
/// 114 M in one build did not fit in 24 GB. Scenes up to 4 M triangles (the default city's
/// 2.2 M) keep one world BLAS; more BLASes cost the rays a little (docs/results.md, "The large
/// city's full grid").
const WORLD_BLAS_MAX_TRIANGLES: u64 = 4 << 20;

/// `world` (object indices) cut into groups of at most `max` triangles
/// (an object is never split), in Morton order of their boxes' centres so each group is compact;
/// one group, in index order, when the whole fits.
fn world_chunks(scene: &Scene, mut world: Vec<usize>, max: u64) -> Vec<Vec<usize>> {
    let tris = |i: usize| scene.meshes[scene.objects[i].mesh as usize].mesh.triangle_count() as u64;
    if world.iter().map(|&i| tris(i)).sum::<u64>() <= max {
        return if world.is_empty() { Vec::new() } else { vec![world] };
    }
    let boxes = scene.all_object_bounds();
    let bounds = boxes.iter().fold(crate::geom::Aabb::EMPTY, |a, &b| a.union(b));
    let key = |i: usize| {
        let c = (boxes[i].center() - bounds.min) / bounds.extent().max(Vec3::splat(f32::MIN_POSITIVE));
        crate::geom::morton3(c)
    };
    world.sort_by_cached_key(|&i| (key(i), i));
    let mut chunks: Vec<Vec<usize>> = Vec::new();
    let mut filled = u64::MAX;
    for i in world {
        if filled.saturating_add(tris(i)) > max {
            chunks.push(Vec::new());
            filled = 0;
        }
        filled += tris(i);
        chunks.last_mut().expect("pushed above").push(i);
    }
    chunks
}

/// A ray for the fast path's traversal: `dir` scaled so that its largest component is ±1, the
/// texel directions' convention (so that the near plane means the same distance), and `reach`
/// in units of the scaled direction.
fn texel_scaled(origin: Vec3, dir: Vec3, reach: f32) -> (Vec3A, Vec3A, f32) {
    let scale = dir.abs().max_element();
    (Vec3A::from(origin), Vec3A::from(dir / scale), reach * scale)
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

pub(crate) fn check_resolution_and_near(resolution: u32, near: f32) -> Result<()> {
    let max = super::cubemap::MAX_RESOLUTION;
    if resolution == 0 || resolution > max {
        return Err(Error::bad_param(Param::Resolution, format!("{resolution} is not in 1..={max}")));
    }
    if !(near.is_finite() && near > 0.0) {
        return Err(Error::bad_param(Param::Near, format!("{near} must be finite and > 0")));
    }
    Ok(())
}

pub(crate) fn check_point(p: Vec3) -> Result<()> {
    if p.is_finite() { Ok(()) } else { Err(Error::bad_param(Param::Point, format!("{p} is not finite"))) }
}

pub(crate) fn check_cube(out: &IdCube, resolution: u32) -> Result<()> {
    let r = resolution as usize;
    if out.resolution != resolution || out.ids.len() != cubemap::FACE_COUNT * r * r {
        return Err(Error::bad_param(
            Param::IdCube,
            format!("resolution {} does not match the backend's {resolution}", out.resolution),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::bvh::{Hit, RayTriangle};
    use super::*;
    use obvhs::{ray::Ray, triangle::Triangle};
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
        use crate::dov::sampling::halton3;
        let mut s = Scene::default();
        for k in 1..=30 {
            let p = (halton3(k) - Vec3::splat(0.5)) * Vec3::new(12.0, 6.0, 12.0);
            let size = Vec3::splat(0.05) + halton3(k + 100) * 2.0;
            s.add_box(&format!("box {k}"), p, p + size);
        }
        s
    }

    /// A world cut into many BLASes sees exactly what one BLAS sees.
    #[test]
    fn world_blases_in_groups_see_what_one_sees() {
        // Each box its own mesh, so that all go into world-space BLASes.
        let instanced = boxes();
        let mut scene = Scene::default();
        for (i, o) in instanced.objects.iter().enumerate() {
            let m = scene.add_mesh(&format!("m{i}"), instanced.object_mesh(i).transformed(&o.transform));
            scene.add_object(&o.name, m, glam::Mat4::IDENTITY);
        }
        let mut one = CpuBackend::new(&scene, 24).unwrap();
        assert_eq!(one.blases.len(), 1);
        let near = super::super::default_near(&scene.bounds());
        let mut groups = CpuBackend::build(&scene, 24, near, 40).unwrap();
        assert!(groups.blases.len() >= 9, "{} BLASes for 30 boxes of 12 triangles", groups.blases.len());
        let (mut a, mut b) = (IdCube::new(24), IdCube::new(24));
        for p in [Vec3::ZERO, Vec3::new(3.0, 1.0, -2.0), Vec3::new(-5.0, -2.0, 4.0)] {
            one.render_ids(p, &mut a).unwrap();
            groups.render_ids(p, &mut b).unwrap();
            assert!(a == b, "ids differ at {p}");
        }
    }

    #[test]
    fn morton_codes_order_space() {
        use crate::geom::morton3;
        assert_eq!(morton3(Vec3::ZERO), 0);
        assert_eq!(morton3(Vec3::ONE), (1 << 30) - 1);
        assert_eq!(morton3(Vec3::new(f32::NAN, 2.0, -1.0)), morton3(Vec3::new(0.0, 1.0, 0.0)));
        // The first bit interleaved is x's, then y's, then z's.
        let step = 1.0 / 1023.0;
        assert_eq!(morton3(Vec3::new(step, 0.0, 0.0)), 1);
        assert_eq!(morton3(Vec3::new(0.0, step, 0.0)), 2);
        assert_eq!(morton3(Vec3::new(0.0, 0.0, step)), 4);
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

        /// A batch of rays (region rays' route) gets each ray's own first hit within the reach,
        /// by packets and without, also where each ray is bounded by the previous one's nearest
        /// triangle: parallel rays from origins spread around (a region ray bundle), rays near
        /// each other in origin and direction, and a far one between.
        #[test]
        fn first_hits_are_first_hit_ray_by_ray(
            base in (vec3a(), vec3a()),
            offsets in prop::collection::vec((vec3a(), vec3a()), 1..80),
        ) {
            let scene = boxes();
            let mut cpu = CpuBackend::new(&scene, 8).unwrap();
            let rays: Vec<(Vec3, Vec3)> = offsets
                .iter()
                .enumerate()
                .map(|(k, (o, d))| match k % 40 {
                    0..=31 => (base.0 + *o, base.1 + 0.001 * *d),
                    32 => (*o, *d),
                    _ => (base.0 + 0.05 * *o, base.1 + 0.05 * *d),
                })
                .map(|(o, d)| (o.into(), d.into()))
                .filter(|(_, d): &(Vec3, Vec3)| d.abs().max_element() > 0.0)
                .collect();
            for reach in [f32::INFINITY, 1.0, 6.0] {
                let one_by_one: Vec<u32> = rays.iter().map(|&(o, d)| cpu.first_hit(o, d, reach)).collect();
                for packets in [true, false] {
                    cpu.set_packets(packets);
                    prop_assert_eq!(cpu.first_hits(&rays, reach), one_by_one.clone());
                }
            }
        }

        /// Rays from one origin (a probe point's aimed rays, a footprint's texels) get each ray's
        /// own first hit within its own reach, in the order given, by packets and without:
        /// directions spread over the sphere and bunched, so that packets are mixed.
        #[test]
        fn first_hits_from_one_origin_are_first_hit_ray_by_ray(
            origin in vec3a(),
            rays in prop::collection::vec((vec3a(), prop_oneof![Just(f32::INFINITY), 0.05f32..3.0]), 1..80),
            bunched in vec3a(),
        ) {
            let scene = boxes();
            let mut cpu = CpuBackend::new(&scene, 8).unwrap();
            let rays: Vec<(Vec3, f32)> = rays
                .iter()
                .enumerate()
                .map(|(k, &(d, reach))| if k % 3 == 0 { (d, reach) } else { (bunched + 0.05 * d, reach) })
                .map(|(d, reach)| (Vec3::from(d), reach))
                .filter(|(d, _)| d.abs().max_element() > 0.0)
                .collect();
            let one_by_one: Vec<u32> = rays.iter().map(|&(d, reach)| cpu.first_hit(origin.into(), d, reach)).collect();
            for packets in [true, false] {
                cpu.set_packets(packets);
                prop_assert_eq!(cpu.first_hits_from(origin.into(), &rays), one_by_one.clone());
            }
        }

        /// Away from its edges the test agrees with obvhs's Möller–Trumbore test (the same hit and
        /// `t` within rounding); the back-face sign is minus the counter-clockwise normal's.
        #[test]
        fn ray_triangle_agrees_with_obvhs_away_from_edges(
            v in [vec3a(), vec3a(), vec3a()], o in vec3a(), d in vec3a(), tmin in 0.0f32..0.5, tmax in 0.5f32..20.0,
        ) {
            let tri = Triangle { v0: v[0], v1: v[1], v2: v[2] };
            let ray = Ray { origin: o, direction: d, inv_direction: d.recip(), tmin, tmax };
            let (ours, theirs) = (RayTriangle::new(&tri).intersect(&ray), tri.intersect(&ray));
            // Barycentrics and t in f64: clear of every edge, of the plane and of the range.
            let [a, b, c, o, d] = [tri.v0, tri.v1, tri.v2, o, d].map(|p| p.as_dvec3());
            let n = (b - a).cross(c - a);
            let det = n.dot(d);
            let t = n.dot(a - o) / det;
            let edge = |p: glam::DVec3, q: glam::DVec3| d.dot((p - o).cross(q - o)) / det;
            let bary = [edge(b, c), edge(c, a), edge(a, b)];
            let scale = (b - a).length() * (c - a).length() + (a - o).length_squared() + 1.0;
            let clear = det.abs() > 1e-3 * n.length() * d.length()
                && bary.iter().all(|w| w.abs() > 1e-4 * scale)
                && (t - f64::from(tmin)).abs() > 1e-4 * (1.0 + t.abs())
                && (t - f64::from(tmax)).abs() > 1e-4 * (1.0 + t.abs());
            if clear {
                prop_assert_eq!(ours.is_finite(), theirs.is_finite(), "t {} against obvhs's {}", ours, theirs);
                if ours.is_finite() {
                    prop_assert!((ours - theirs).abs() <= 1e-4 * (1.0 + theirs.abs()), "t {} against obvhs's {}", ours, theirs);
                }
            }
            let ccw = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0);
            prop_assert_eq!(RayTriangle::new(&tri).seen_from_behind(d.as_vec3a()), ccw.dot(d.as_vec3a()) > 0.0);
        }

        /// Watertight: a ray towards a point of an edge two triangles share (either way round,
        /// in a plane or folded) hits at least one of them, whatever the rounding.
        #[test]
        fn a_ray_through_a_shared_edge_hits_one_of_its_triangles(
            p in vec3a(), q in vec3a(), r in vec3a(), fold in vec3a(), o in vec3a(),
            along in 0.05f32..0.95, flip in any::<bool>(),
        ) {
            // Triangles p q r and q p s (or p q s, wound the same way), s across the edge from r.
            let mid = 0.5 * (p + q);
            let s = mid - (r - mid) + 0.5 * fold;
            let a = Triangle { v0: p, v1: q, v2: r };
            let b = if flip { Triangle { v0: p, v1: q, v2: s } } else { Triangle { v0: q, v1: p, v2: s } };
            let target = p + (q - p) * along;
            let d = target - o;
            let normal_a = (q - p).cross(r - p);
            let normal_b = (q - p).cross(s - p);
            // Only where the two lie on two sides of the edge seen from the origin (else the edge
            // is a silhouette, and a ray just past it rightly misses both), clear of rays along a
            // triangle's plane (they may graze both).
            let edge_plane = (p - o).cross(q - o);
            let side = |x: Vec3A| edge_plane.dot(x - o) / (edge_plane.length() * (x - o).length());
            let grazing = |n: Vec3A| n.dot(d).abs() <= 1e-3 * n.length() * d.length();
            prop_assume!(normal_a.length() > 1e-3 && normal_b.length() > 1e-3 && d.length() > 1e-2);
            prop_assume!((q - p).length() > 1e-2 && !grazing(normal_a) && !grazing(normal_b));
            prop_assume!(side(r) * side(s) < -1e-6);
            let ray = Ray::new(o, d, 0.0, f32::INFINITY);
            let (ta, tb) = (RayTriangle::new(&a).intersect(&ray), RayTriangle::new(&b).intersect(&ray));
            prop_assert!(ta.is_finite() || tb.is_finite(), "the ray passes between the two triangles");
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
