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
//! A ray entering an instance's box (nearer than the best hit so far) is carried into model space
//! by the inverse transform, direction not normalised, so the ray parameter `t` is the same in
//! every space and hits of different instances compare directly.

use std::time::Duration;

use glam::{Affine3A, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb as BvhAabb,
    cwbvh::{
        CwBvh,
        builder::{build_cwbvh, build_cwbvh_from_tris},
    },
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use rayon::prelude::*;

use super::{BACK_FACE_BIT, CubeMap, DovBackend, IdCube, MAX_OBJECT_ID, NO_OBJECT, cubemap};
use crate::error::{Error, Result};
use crate::scene::Scene;

/// Two hits whose ray parameters differ by less than this fraction are a tie; the lower object id
/// wins. Coplanar faces of two objects otherwise flicker between them with rounding.
pub const TIE_EPSILON: f32 = 1e-5;

/// One bottom-level BVH and its triangles in the BVH's primitive order (no indirection while
/// tracing).
struct Blas {
    bvh: CwBvh,
    triangles: Vec<Triangle>,
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

/// The best hit of one ray so far, shared by every BLAS the ray visits.
struct Best {
    t: f32,
    obj: u32,
    /// Instance and triangle (in its BLAS's order) of the hit.
    instance: usize,
    tri: usize,
    /// The smallest bound handed back to a traversal: hits beyond it cannot change the result.
    tmax: f32,
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
        })
    }

    pub fn near(&self) -> f32 {
        self.near
    }

    /// The id seen from `origin` along `dir` (a texel direction whose forward component is 1):
    /// the nearest hit with `t ≥ near`, ties within [`TIE_EPSILON`] to the lower object id, with
    /// [`BACK_FACE_BIT`] when that triangle faces away. Costs one TLAS traversal plus one BLAS
    /// traversal per instance box the ray enters before its nearest hit.
    pub fn trace(&self, origin: Vec3, dir: Vec3) -> u32 {
        let Some(tlas) = &self.tlas else { return NO_OBJECT };
        let (o, d) = (Vec3A::from(origin), Vec3A::from(dir));
        let world_ray = Ray::new(o, d, self.near, f32::INFINITY);
        let mut best =
            Best { t: f32::INFINITY, obj: NO_OBJECT, instance: usize::MAX, tri: usize::MAX, tmax: f32::INFINITY };
        let mut hit = RayHit::none();
        tlas.ray_traverse(world_ray, &mut hit, |_, ii| {
            let inst = &self.instances[ii];
            let blas = &self.blases[inst.blas as usize];
            let ray = match &inst.to_model {
                None => Ray { tmax: best.tmax, ..world_ray },
                Some(m) => Ray::new(m.transform_point3a(o), m.transform_vector3a(d), self.near, best.tmax),
            };
            let mut blas_hit = RayHit::none();
            blas.bvh.ray_traverse(ray, &mut blas_hit, |ray, i| {
                let t = blas.triangles[i].intersect(ray);
                if !t.is_finite() {
                    return f32::INFINITY;
                }
                let obj = if inst.object == NO_OBJECT { blas.objects[i] } else { inst.object };
                if t < best.t * (1.0 - TIE_EPSILON) {
                    // Clearly nearer than everything so far.
                    (best.t, best.obj, best.instance, best.tri) = (t, obj, ii, i);
                } else if obj < best.obj || (obj == best.obj && t < best.t) {
                    // A tie with the best (t was accepted, so t ≤ best.t·(1+ε)): lower id wins.
                    (best.t, best.obj, best.instance, best.tri) = (t.min(best.t), obj, ii, i);
                }
                // Keep accepting hits inside the tie window behind this one.
                let bound = t * (1.0 + TIE_EPSILON);
                best.tmax = best.tmax.min(bound);
                bound
            });
            // Instance boxes beyond the tie window of the best hit cannot change the result.
            best.tmax
        });
        if best.obj == NO_OBJECT {
            return NO_OBJECT;
        }
        // The back-face test in the hit triangle's own space: with n = e1×e2 in model space and
        // M the linear part of the transform, the world normal of the (winding-corrected) world
        // triangle is |det M|·M⁻ᵀn, so its sign against M·d is the sign of n·d.
        let inst = &self.instances[best.instance];
        let dir = inst.to_model.map_or(d, |m| m.transform_vector3a(d));
        let tri = &self.blases[inst.blas as usize].triangles[best.tri];
        let normal = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0);
        if normal.dot(dir) > 0.0 { best.obj | BACK_FACE_BIT } else { best.obj }
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

    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()> {
        check_point(p)?;
        check_cube(out, self.cube.resolution())?;
        let r = self.cube.resolution() as usize;
        let this = &*self;
        // One rayon task per texel row: rows are long enough to amortise scheduling.
        out.ids.par_chunks_mut(r).enumerate().for_each(|(face_row, ids)| {
            let face = face_row / r;
            let row = (face_row % r) as u32;
            for (col, id) in ids.iter_mut().enumerate() {
                *id = this.trace(p, this.cube.texel_direction(face, row, col as u32));
            }
        });
        Ok(())
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
    let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
    let triangles = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
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

fn check_object_count(scene: &Scene) -> Result<()> {
    if scene.objects.len() > MAX_OBJECT_ID as usize {
        return Err(Error::bad_param(
            "scene",
            format!("{} objects exceed the DoV id limit {MAX_OBJECT_ID}", scene.objects.len()),
        ));
    }
    Ok(())
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
