//! View geometry shared by the query engine, the renderer and REVIEW: a camera (what a renderer
//! would draw this frame), its view frustum, and the one rule for a view's basis. The query
//! culls answers to the frustum and takes screen-space errors from the camera; the renderer
//! projects with the same basis; REVIEW's frustum cell is built on it.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::geom::Aabb;

/// A pinhole camera at the query point looking along `look`, y up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// View direction (need not be unit length; not zero).
    pub look: Vec3,
    /// Vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f32,
    /// Width / height of the image.
    pub aspect: f32,
    /// Image height in pixels (screen-space errors are in these pixels).
    pub image_height: u32,
}

impl Default for Camera {
    fn default() -> Self {
        Self { look: Vec3::NEG_Z, fov_y_deg: 60.0, aspect: 16.0 / 9.0, image_height: 1080 }
    }
}

impl Camera {
    /// Checks the camera's numbers; returns the reason of the first bad one.
    pub fn check(&self) -> Result<(), String> {
        if !self.look.is_finite() || self.look.length_squared() == 0.0 {
            return Err(format!("look direction {:?} must be finite and not zero", self.look.to_array()));
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(format!("field of view {}° is not in (0, 180)", self.fov_y_deg));
        }
        if !(self.aspect.is_finite() && self.aspect > 0.0) || self.image_height == 0 {
            return Err("aspect and image height must be positive".into());
        }
        Ok(())
    }

    /// Pixels per unit of world length at distance 1 (the projection's scale).
    pub fn pixels_per_unit(&self) -> f64 {
        f64::from(self.image_height) / (2.0 * (f64::from(self.fov_y_deg).to_radians() / 2.0).tan())
    }

    /// The screen-space size in pixels of a world-space error `error` at the nearest point of
    /// `bounds` seen from `eye`; infinite when `eye` is inside `bounds`.
    pub fn screen_error(&self, eye: Vec3, bounds: &Aabb, error: f64) -> f64 {
        let d = f64::from(distance_to_box(eye, bounds));
        if d <= 0.0 { f64::INFINITY } else { error * self.pixels_per_unit() / d }
    }

    /// The view frustum from `eye` (no far plane: the camera sees to the horizon).
    pub fn frustum(&self, eye: Vec3) -> Frustum {
        let (forward, right, up) = basis(self.look);
        let half_v = (self.fov_y_deg.to_radians() / 2.0).tan();
        let half_h = half_v * self.aspect;
        // Inward normals of the four side planes through the eye.
        let normals = [
            up.cross(forward * half_h + right),   // right plane
            (forward * half_h - right).cross(up), // left plane
            (forward * half_v + up).cross(right), // top plane
            right.cross(forward * half_v - up),   // bottom plane
        ];
        Frustum { eye, planes: normals.map(|n| n.normalize()), forward }
    }
}

/// Unit forward, right and up vectors of a view along `look` (not zero): up is y unless the
/// view looks straight up or down, then z.
pub fn basis(look: Vec3) -> (Vec3, Vec3, Vec3) {
    let forward = look.normalize();
    let up_hint = if forward.cross(Vec3::Y).length_squared() < 1e-6 { Vec3::Z } else { Vec3::Y };
    let right = forward.cross(up_hint).normalize();
    (forward, right, right.cross(forward))
}

/// Distance from `p` to the nearest point of `b` (0 inside).
pub fn distance_to_box(p: Vec3, b: &Aabb) -> f32 {
    Aabb::new(p, p).distance(b)
}

/// A view frustum: four side planes through the eye, and the half-space in front of it.
#[derive(Clone, Copy, Debug)]
pub struct Frustum {
    eye: Vec3,
    planes: [Vec3; 4],
    forward: Vec3,
}

impl Frustum {
    /// Whether `b` may be seen: conservative (a box outside a plane is culled; one that
    /// straddles two planes' corner may be kept). A box holding the eye is always kept.
    pub fn meets(&self, b: &Aabb) -> bool {
        if b.contains_point(self.eye) {
            return true;
        }
        let outside = |n: Vec3| {
            // The box corner furthest along n: if even it is behind the plane, all are.
            let far = Vec3::select(n.cmpge(Vec3::ZERO), b.max, b.min);
            n.dot(far - self.eye) < 0.0
        };
        !outside(self.forward) && !self.planes.iter().any(|&n| outside(n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frustum_keeps_what_is_in_front_and_culls_behind_and_aside() {
        let cam = Camera { look: Vec3::NEG_Z, fov_y_deg: 60.0, aspect: 1.0, image_height: 100 };
        let f = cam.frustum(Vec3::ZERO);
        let unit = |c: Vec3| Aabb::new(c - 0.5, c + 0.5);
        assert!(f.meets(&unit(Vec3::new(0.0, 0.0, -10.0))));
        assert!(!f.meets(&unit(Vec3::new(0.0, 0.0, 10.0))), "behind");
        assert!(!f.meets(&unit(Vec3::new(20.0, 0.0, -10.0))), "right of a 60° view");
        assert!(!f.meets(&unit(Vec3::new(-20.0, 0.0, -10.0))), "left");
        assert!(!f.meets(&unit(Vec3::new(0.0, 20.0, -10.0))), "above");
        assert!(!f.meets(&unit(Vec3::new(0.0, -20.0, -10.0))), "below");
        assert!(f.meets(&unit(Vec3::new(5.0, 0.0, -10.0))), "inside the 30° half angle");
        assert!(f.meets(&unit(Vec3::ZERO)), "holding the eye");
        // Looking straight down works too.
        let down = Camera { look: Vec3::NEG_Y, ..cam }.frustum(Vec3::ZERO);
        assert!(down.meets(&unit(Vec3::new(0.0, -10.0, 0.0))) && !down.meets(&unit(Vec3::new(0.0, 10.0, 0.0))));
    }

    #[test]
    fn screen_error_falls_with_distance() {
        let cam = Camera { fov_y_deg: 90.0, image_height: 1000, ..Default::default() };
        let b = Aabb::new(Vec3::new(-1.0, -1.0, -11.0), Vec3::new(1.0, 1.0, -10.0));
        // tan(45°) = 1: 1000 px span 2 units at distance 1, so 0.1 units at 10 are 5 px.
        assert!((cam.screen_error(Vec3::ZERO, &b, 0.1) - 5.0).abs() < 1e-4);
        assert!(cam.screen_error(Vec3::new(0.0, 0.0, -10.5), &b, 0.1).is_infinite());
    }
}
