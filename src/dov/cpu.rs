//! The CPU backend: one ray per texel centre, cast through a BVH (obvhs CWBVH) over every
//! world-space triangle of the scene.

use std::time::Duration;

use glam::{Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris},
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

/// Ray casting through a BVH over all triangles. Building costs O(T log T) for T triangles;
/// each [`DovBackend::render_ids`] casts 6·R² rays, in parallel on rayon's pool.
pub struct CpuBackend {
    cube: CubeMap,
    near: f32,
    bvh: Option<CwBvh>,
    /// Triangles in the BVH's primitive order (no indirection while tracing).
    triangles: Vec<Triangle>,
    /// Object index of each entry of `triangles`.
    triangle_object: Vec<u32>,
}

impl CpuBackend {
    /// Builds the BVH over `scene` at `resolution` texels per face edge, with the near plane of
    /// [`super::default_near`].
    pub fn new(scene: &Scene, resolution: u32) -> Result<Self> {
        Self::with_near(scene, resolution, super::default_near(&scene.bounds()))
    }

    /// As [`CpuBackend::new`] with an explicit near distance (surfaces nearer than `near` along a
    /// face's forward axis are ignored, exactly as the GPU backend's near plane clips them).
    pub fn with_near(scene: &Scene, resolution: u32, near: f32) -> Result<Self> {
        check_resolution_and_near(resolution, near)?;
        let (triangles, objects) = world_triangles(scene)?;
        let tris: Vec<Triangle> =
            triangles.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
        let (bvh, triangles, triangle_object) = if tris.is_empty() {
            (None, Vec::new(), Vec::new())
        } else {
            let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
            let ordered: Vec<Triangle> = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
            let ordered_obj: Vec<u32> = bvh.primitive_indices.iter().map(|&i| objects[i as usize]).collect();
            (Some(bvh), ordered, ordered_obj)
        };
        Ok(Self { cube: CubeMap::new(resolution), near, bvh, triangles, triangle_object })
    }

    pub fn near(&self) -> f32 {
        self.near
    }

    /// The id seen from `origin` along `dir` (a texel direction whose forward component is 1):
    /// the nearest hit with `t ≥ near`, ties within [`TIE_EPSILON`] to the lower object id, with
    /// [`BACK_FACE_BIT`] when that triangle faces away. Costs one BVH traversal.
    pub fn trace(&self, origin: Vec3, dir: Vec3) -> u32 {
        let Some(bvh) = &self.bvh else { return NO_OBJECT };
        let ray = Ray::new(Vec3A::from(origin), Vec3A::from(dir), self.near, f32::INFINITY);
        let mut best_t = f32::INFINITY;
        let mut best_obj = NO_OBJECT;
        let mut best_tri = usize::MAX;
        let mut hit = RayHit::none();
        bvh.ray_traverse(ray, &mut hit, |ray, i| {
            let t = self.triangles[i].intersect(ray);
            if !t.is_finite() {
                return f32::INFINITY;
            }
            let obj = self.triangle_object[i];
            if t < best_t * (1.0 - TIE_EPSILON) {
                // Clearly nearer than everything so far.
                (best_t, best_obj, best_tri) = (t, obj, i);
            } else if obj < best_obj || (obj == best_obj && t < best_t) {
                // A tie with the best (t was accepted, so t ≤ best_t·(1+ε)): lower id wins.
                (best_t, best_obj, best_tri) = (t.min(best_t), obj, i);
            }
            // Keep accepting hits inside the tie window behind this one.
            t * (1.0 + TIE_EPSILON)
        });
        if best_obj == NO_OBJECT {
            return NO_OBJECT;
        }
        let tri = &self.triangles[best_tri];
        let normal = (tri.v1 - tri.v0).cross(tri.v2 - tri.v0);
        if normal.dot(Vec3A::from(dir)) > 0.0 { best_obj | BACK_FACE_BIT } else { best_obj }
    }
}

impl DovBackend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu (obvhs CWBVH, {} triangles, {} threads)", self.triangles.len(), rayon::current_num_threads())
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

/// Every triangle of every object in world space, objects in index order, with its object index.
/// Mirroring transforms (negative determinant) get their winding flipped so that counter-clockwise
/// still means "seen from outside". Fails when there are more objects than ids can carry.
pub fn world_triangles(scene: &Scene) -> Result<(Vec<[Vec3; 3]>, Vec<u32>)> {
    if scene.objects.len() > MAX_OBJECT_ID as usize {
        return Err(Error::bad_arg(
            "scene",
            format!("{} objects exceed the DoV id limit {MAX_OBJECT_ID}", scene.objects.len()),
        ));
    }
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
    if resolution == 0 || resolution > 16384 {
        return Err(Error::bad_arg("resolution", format!("{resolution} is not in 1..=16384")));
    }
    if !(near.is_finite() && near > 0.0) {
        return Err(Error::bad_arg("near", format!("{near} must be finite and > 0")));
    }
    Ok(())
}

pub(crate) fn check_point(p: Vec3) -> Result<()> {
    if p.is_finite() { Ok(()) } else { Err(Error::bad_arg("point", format!("{p} is not finite"))) }
}

pub(crate) fn check_cube(out: &IdCube, resolution: u32) -> Result<()> {
    let r = resolution as usize;
    if out.resolution != resolution || out.ids.len() != cubemap::FACE_COUNT * r * r {
        return Err(Error::bad_arg(
            "id cube",
            format!("resolution {} does not match the backend's {resolution}", out.resolution),
        ));
    }
    Ok(())
}
