//! Single rays through a scene: the capability a backend offers when it can cast them one by
//! one ([`super::DovBackend::ray_caster`]; the CPU backend does), and the points on every
//! object's surface that rays are aimed at. Ray probing and region rays use it.

use glam::{Affine3A, Vec3};

use super::sampling::halton3;
#[cfg(doc)]
use super::{BACK_FACE_BIT, NO_OBJECT};
use crate::geom::Aabb;
use crate::scene::Scene;

/// Single rays through a scene, with the id rule of [`super::DovBackend::render_ids`]. The CPU
/// backend is one ([`super::DovBackend::ray_caster`]).
pub trait RayCaster: Sync {
    /// The id seen from `origin` along `dir` (any length) among the surfaces within `reach`
    /// lengths of `dir` (infinity: all): object id, with [`BACK_FACE_BIT`] when its surface is
    /// seen from behind, or [`NO_OBJECT`].
    fn first_hit(&self, origin: Vec3, dir: Vec3, reach: f32) -> u32;

    /// [`RayCaster::first_hit`] of each ray (origin, direction) within `reach`, in turn. A
    /// caster may carry what one ray met to the next, or trace runs of nearly parallel rays
    /// together, so rays in a coherent order (nearby directions one after another) can be
    /// faster; the ids are the same.
    fn first_hits(&self, rays: &[(Vec3, Vec3)], reach: f32) -> Vec<u32> {
        rays.iter().map(|&(o, d)| self.first_hit(o, d, reach)).collect()
    }

    /// [`RayCaster::first_hit`] of each ray from `origin` (direction, reach in lengths of it):
    /// rays that share an origin, such as a probe point's rays at many targets or a footprint's
    /// texels, which a caster may sort by direction and trace together; the ids are the same,
    /// in the order of `rays`.
    fn first_hits_from(&self, origin: Vec3, rays: &[(Vec3, f32)]) -> Vec<u32> {
        rays.iter().map(|&(d, reach)| self.first_hit(origin, d, reach)).collect()
    }

    /// Points on every object's surface to aim at.
    fn targets(&self) -> &SurfaceTargets;
}

/// Points spread over each object's surface, by area: [`SurfaceTargets::PER_MESH`] per base mesh
/// in model space (instances share them), carried to the world by the object's transform.
pub struct SurfaceTargets {
    /// Model-space points of each base mesh.
    mesh_points: Vec<Vec<Vec3>>,
    /// Base mesh and model → world transform of each object.
    objects: Vec<(u32, Affine3A)>,
    /// Centre of each object's box: the target of an object without area.
    centres: Vec<Vec3>,
}

impl SurfaceTargets {
    /// Points per base mesh: enough that 64 probe points × 4 rays aim at 256 different places.
    pub const PER_MESH: usize = 256;

    /// Costs one pass over the scene's stored triangles.
    pub fn new(scene: &Scene) -> Self {
        let mesh_points = scene.meshes.iter().map(|m| spread_over(&m.mesh.triangles().collect::<Vec<_>>())).collect();
        let objects = scene.objects.iter().map(|o| (o.mesh, Affine3A::from_mat4(o.transform))).collect();
        let centres = scene.all_object_bounds().iter().map(Aabb::center).collect();
        Self { mesh_points, objects, centres }
    }

    /// The `k`-th target of `object` (cycling through its points).
    pub fn target(&self, object: u32, k: usize) -> Vec3 {
        let (mesh, to_world) = &self.objects[object as usize];
        let points = &self.mesh_points[*mesh as usize];
        if points.is_empty() {
            return self.centres[object as usize];
        }
        to_world.transform_point3(points[k % points.len()])
    }
}

/// [`SurfaceTargets::PER_MESH`] points over `triangles`, each triangle getting its share of the
/// area: stratified along the cumulative area, Halton-spread inside each triangle.
fn spread_over(triangles: &[[Vec3; 3]]) -> Vec<Vec3> {
    let mut cumulative = Vec::with_capacity(triangles.len());
    let mut total = 0.0f64;
    for t in triangles {
        total += 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64;
        cumulative.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    let n = SurfaceTargets::PER_MESH;
    (0..n)
        .map(|k| {
            let x = (k as f64 + 0.5) / n as f64 * total;
            let t = &triangles[cumulative.partition_point(|&c| c < x).min(triangles.len() - 1)];
            let h = halton3(k as u32 + 1);
            let (mut a, mut b) = (h.x, h.y);
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0])
        })
        .collect()
}
