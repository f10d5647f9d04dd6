//! Axis-aligned boxes and small geometric helpers shared by the scene, the tree and the DoV code.

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// An axis-aligned bounding box. An empty box has `min > max` on every axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// The lower corner.
    pub min: Vec3,
    /// The upper corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The box of nothing: unions leave the other box unchanged.
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    /// The box from `min` to `max`.
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The smallest box holding `points` ([`Aabb::EMPTY`] for none).
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, |b, p| b.grow(p))
    }

    /// Whether the box holds no point (some min above its max).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The box grown to hold `p`.
    #[must_use]
    pub fn grow(self, p: Vec3) -> Self {
        Self { min: self.min.min(p), max: self.max.max(p) }
    }

    /// The smallest box holding both.
    #[must_use]
    pub fn union(self, o: Aabb) -> Self {
        Self { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    /// The centre.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// The side lengths.
    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    /// Whether `o` lies inside `self` (boundaries included).
    pub fn contains(&self, o: &Aabb) -> bool {
        self.min.cmple(o.min).all() && self.max.cmpge(o.max).all()
    }

    /// Whether `p` lies in the box (boundary included).
    pub fn contains_point(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && self.max.cmpge(p).all()
    }

    /// Whether the boxes share a point (touching counts).
    pub fn intersects(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && self.max.cmpge(o.min).all()
    }

    /// The largest `n · p` over the box's points `p` (at its corner furthest along `n`); minus
    /// infinity for an empty box.
    pub fn max_along(&self, n: Vec3) -> f32 {
        if self.is_empty() {
            return f32::NEG_INFINITY;
        }
        n.dot(self.center()) + n.abs().dot(0.5 * self.extent())
    }

    /// The distance between the nearest points of the two boxes (0 where they meet).
    pub fn distance(&self, o: &Aabb) -> f32 {
        (o.min - self.max).max(self.min - o.max).max(Vec3::ZERO).length()
    }

    /// The box of the eight transformed corners: a conservative bound of the transformed content.
    pub fn transformed(&self, m: &Mat4) -> Aabb {
        if self.is_empty() {
            return *self;
        }
        let (a, b) = (self.min, self.max);
        Aabb::from_points((0..8).map(|i| {
            let c = Vec3::new(
                if i & 1 == 0 { a.x } else { b.x },
                if i & 2 == 0 { a.y } else { b.y },
                if i & 4 == 0 { a.z } else { b.z },
            );
            m.transform_point3(c)
        }))
    }

    /// `[x0, y0, z0, x1, y1, z1]`, the order the CLI and the JSON outputs use.
    pub fn to_array(&self) -> [f32; 6] {
        [self.min.x, self.min.y, self.min.z, self.max.x, self.max.y, self.max.z]
    }

    /// The box `[min x, min y, min z, max x, max y, max z]`.
    pub fn from_array(a: [f32; 6]) -> Self {
        Self { min: Vec3::new(a[0], a[1], a[2]), max: Vec3::new(a[3], a[4], a[5]) }
    }

    /// Surface area.
    pub fn surface_area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// Volume.
    pub fn volume(&self) -> f32 {
        let e = self.extent();
        e.x * e.y * e.z
    }
}

/// The largest factor by which `m` stretches a length: what turns an error in a mesh's units
/// into world units (mirroring does not count).
pub fn max_scale(m: &Mat4) -> f32 {
    [m.x_axis, m.y_axis, m.z_axis].into_iter().map(|a| a.truncate().length()).fold(0.0, f32::max)
}

/// The Morton (Z-order) code of a point of the unit cube (coordinates clamped to [0, 1]), 10
/// bits per axis: nearby points mostly get nearby codes, so sorting by it groups space.
pub fn morton3(p: Vec3) -> u32 {
    // Spreads the low 10 bits of `v` to every third bit.
    fn spread(v: u32) -> u32 {
        let mut v = v & 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    }
    let q = |x: f32| (x.clamp(0.0, 1.0) * 1023.0) as u32;
    spread(q(p.x)) | (spread(q(p.y)) << 1) | (spread(q(p.z)) << 2)
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    proptest! {
        /// The furthest point along a direction is the furthest of the eight corners.
        #[test]
        fn max_along_is_the_furthest_corner(
            min in proptest::array::uniform3(-100.0f32..100.0),
            extent in proptest::array::uniform3(0.0f32..50.0),
            n in proptest::array::uniform3(-1.0f32..1.0),
        ) {
            let b = Aabb::new(Vec3::from(min), Vec3::from(min) + Vec3::from(extent));
            let n = Vec3::from(n);
            let corners = (0..8).map(|i| {
                let pick = |bit: usize, lo: f32, hi: f32| if i & bit == 0 { lo } else { hi };
                n.dot(Vec3::new(pick(1, b.min.x, b.max.x), pick(2, b.min.y, b.max.y), pick(4, b.min.z, b.max.z)))
            });
            let furthest = corners.fold(f32::NEG_INFINITY, f32::max);
            prop_assert!((b.max_along(n) - furthest).abs() <= 1e-4 * (1.0 + furthest.abs()));
        }
    }

    #[test]
    fn an_empty_box_lies_along_no_direction() {
        assert_eq!(Aabb::EMPTY.max_along(Vec3::X), f32::NEG_INFINITY);
    }
}
