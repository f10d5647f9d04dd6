//! The cube map both backends measure on: 6 faces of 90°, R×R texels each, the texel centre
//! directions and the solid-angle weight of every texel.
//!
//! Conventions (shared by the CPU ray caster and the GPU rasteriser, so that texel `(face, row,
//! col)` means the same direction in both):
//! - face `f` has an orthonormal basis `(right, up, forward)` with `right = forward × up`;
//! - texel column `col` (left to right) has `u = 2(col + ½)/R − 1`, row `row` (top to bottom, the
//!   order of texture rows in memory) has `v = 1 − 2(row + ½)/R`;
//! - the texel's centre direction is `forward + u·right + v·up` (not normalised: its component
//!   along `forward` is 1, so a ray parameter `t` along it is the depth along `forward`, the same
//!   quantity the GPU's near plane clips).
//!
//! The weight of a texel is `w(u, v) = (2/R)² / (1 + u² + v²)^{3/2}` (thesis eq. 5.11). The sum
//! over all texels approaches 4π as R grows (midpoint rule, error O(1/R²)); DoVs are divided by
//! that exact sum ([`CubeMap::total_weight`]) rather than by 4π, so that a point surrounded by
//! geometry gets DoVs summing to exactly 1.

use glam::Vec3;

/// Largest R (the build parameters' bound).
pub const MAX_RESOLUTION: u32 = crate::format::params::limits::MAX_RESOLUTION;

/// The six cube faces, in the order used for texel indices: +X, −X, +Y, −Y, +Z, −Z.
pub const FACE_COUNT: usize = 6;

/// Orthonormal basis of one cube face: `dir(u, v) = forward + u·right + v·up`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceBasis {
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
}

impl FaceBasis {
    /// The basis turned by the rotation `turn`.
    pub fn turned(&self, turn: glam::Mat3) -> FaceBasis {
        FaceBasis { right: turn * self.right, up: turn * self.up, forward: turn * self.forward }
    }
}

/// The basis of face `face` (0..6). `right = forward × up`, i.e. the frame of a right-handed
/// camera looking along `forward` (glam's `look_to_rh`), so the GPU's view matrix is a rotation.
pub fn face_basis(face: usize) -> FaceBasis {
    let (forward, up) = match face {
        0 => (Vec3::X, Vec3::Y),
        1 => (Vec3::NEG_X, Vec3::Y),
        2 => (Vec3::Y, Vec3::NEG_Z),
        3 => (Vec3::NEG_Y, Vec3::Z),
        4 => (Vec3::Z, Vec3::Y),
        5 => (Vec3::NEG_Z, Vec3::Y),
        _ => panic!("cube face {face} out of range 0..6"),
    };
    FaceBasis { right: forward.cross(up), up, forward }
}

/// The direction through `(u, v)` of face `face`, `forward + u·right + v·up` (its `forward`
/// component is 1): texel centres, and any point inside a texel.
pub fn uv_direction(face: usize, u: f64, v: f64) -> Vec3 {
    let b = face_basis(face);
    b.forward + b.right * u as f32 + b.up * v as f32
}

/// The cube map of one resolution: texel coordinates and weights, computed once.
#[derive(Clone, Debug)]
pub struct CubeMap {
    resolution: u32,
    /// `u` (equivalently `v` mirrored) of each column centre.
    coords: Vec<f64>,
    /// Weight of texel (row, col), identical on every face: `weights[row * R + col]`.
    weights: Vec<f64>,
    total_weight: f64,
}

impl CubeMap {
    /// Precomputes the texel centres and weights of an R×R-per-face cube map. Costs O(R²).
    ///
    /// # Panics
    /// If `resolution` is 0.
    pub fn new(resolution: u32) -> Self {
        assert!(resolution > 0, "cube map resolution must be at least 1");
        let r = resolution as usize;
        let coords: Vec<f64> = (0..r).map(|i| 2.0 * (i as f64 + 0.5) / r as f64 - 1.0).collect();
        let texel_area = (2.0 / r as f64).powi(2);
        let mut weights = Vec::with_capacity(r * r);
        for row in 0..r {
            // v runs from +1 at the top row down to −1, u from −1 at the left column.
            let v = -coords[row];
            for &u in &coords {
                weights.push(texel_area / (1.0 + u * u + v * v).powf(1.5));
            }
        }
        let total_weight = FACE_COUNT as f64 * weights.iter().sum::<f64>();
        Self { resolution, coords, weights, total_weight }
    }

    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Number of texels over all six faces: 6·R².
    pub fn texel_count(&self) -> usize {
        FACE_COUNT * self.weights.len()
    }

    /// `(u, v)` of the centre of texel (row, col), both in (−1, 1).
    pub fn texel_uv(&self, row: u32, col: u32) -> (f64, f64) {
        (self.coords[col as usize], -self.coords[row as usize])
    }

    /// Direction through the centre of texel (face, row, col); its `forward` component is 1.
    pub fn texel_direction(&self, face: usize, row: u32, col: u32) -> Vec3 {
        let (u, v) = self.texel_uv(row, col);
        uv_direction(face, u, v)
    }

    /// Solid angle (steradians) of texel (row, col) of any face: `(2/R)² / (1+u²+v²)^{3/2}`.
    pub fn weight(&self, row: u32, col: u32) -> f64 {
        self.weights[row as usize * self.resolution as usize + col as usize]
    }

    /// The weights of one face in row-major order (all faces share them).
    pub fn face_weights(&self) -> &[f64] {
        &self.weights
    }

    /// Sum of all 6·R² texel weights: 4π up to the midpoint rule's O(1/R²) error.
    pub fn total_weight(&self) -> f64 {
        self.total_weight
    }

    /// The smallest DoV one texel can carry, a texel at a face centre: ≈ (2/R)²/4π. The floor
    /// given to visible zero-DoV objects and the noise level below which a threshold means nothing.
    pub fn texel_floor(&self) -> f64 {
        (2.0 / self.resolution as f64).powi(2) / self.total_weight
    }

    /// The texel whose centre direction is nearest `dir` (tests, and the bins region rays are
    /// sorted into): `(face, row, col)`. Returns `None` for a zero or non-finite direction.
    pub fn texel_of_direction(&self, dir: Vec3) -> Option<(usize, u32, u32)> {
        if !dir.is_finite() || dir == Vec3::ZERO {
            return None;
        }
        let a = dir.abs();
        let face = if a.x >= a.y && a.x >= a.z {
            if dir.x > 0.0 { 0 } else { 1 }
        } else if a.y >= a.z {
            if dir.y > 0.0 { 2 } else { 3 }
        } else if dir.z > 0.0 {
            4
        } else {
            5
        };
        let b = face_basis(face);
        let f = dir.dot(b.forward) as f64;
        let u = dir.dot(b.right) as f64 / f;
        let v = dir.dot(b.up) as f64 / f;
        let r = self.resolution as f64;
        let col = (((u + 1.0) * 0.5 * r).floor()).clamp(0.0, r - 1.0) as u32;
        let row = (((1.0 - v) * 0.5 * r).floor()).clamp(0.0, r - 1.0) as u32;
        Some((face, row, col))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bases_are_right_handed_and_orthonormal() {
        for f in 0..FACE_COUNT {
            let b = face_basis(f);
            assert!((b.right.cross(b.up) - (-b.forward)).length() < 1e-6, "face {f}");
            assert!(b.right.dot(b.up).abs() < 1e-6);
            assert!((b.right.length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn texel_lookup_round_trips() {
        let cube = CubeMap::new(16);
        for face in 0..FACE_COUNT {
            for (row, col) in [(0, 0), (3, 9), (15, 15), (8, 7)] {
                let d = cube.texel_direction(face, row, col);
                assert_eq!(cube.texel_of_direction(d), Some((face, row, col)));
            }
        }
    }
}
