//! REVIEW, the spatial baseline of thesis ch. 4: no visibility, an R-tree queried with a *disk
//! cell* around the viewer.
//!
//! - the *frustum cell* bounds what the viewer can see: the box of the view frustum from the
//!   eye to the far plane at the eyesight (default 1 km), fields of view of 45° horizontally
//!   and vertically ([`frustum_cell`]);
//! - the *disk cell* is that box scaled by SF (`review_box`) about its centre ([`disk_cell`]).
//!   While the frustum cell stays inside the disk cell nothing is read; when it leaves, a new
//!   disk cell is queried with **CSearch** against the history of cells whose objects are in
//!   the object buffer ([`search::csearch`]);
//! - the tree's pages are read through the session's page cache, whose priorities are DPLRU's
//!   `α·pp + β·pd` ([`dplru_priority`]);
//! - prefetch queries the cell around `F + k·velocity` ([`predicted_cell`]);
//! - what is drawn is the object buffer culled to the view frustum and the eyesight.
//!
//! A REVIEW walk is a [`Session`](crate::Session) started by [`Database::review_session`]
//! ([`session`]): it shares the visual session's delta loading, resident geometry and
//! [`Step`](crate::Step) reports, so walks compare 1:1. `docs/review.md` gives the formulas and
//! the decisions.

pub mod search;
mod session;

use glam::Vec3;

#[cfg(doc)]
use crate::db::Database;
use crate::error::Param;
use crate::geom::Aabb;

/// The thesis's eyesight: the depth of the view frustum, 1 km.
pub const DEFAULT_EYESIGHT: f32 = 1000.0;
/// The thesis's fields of view, horizontal and vertical, in degrees.
pub const DEFAULT_FOV_DEG: f32 = 45.0;
/// SF: the disk cell over the frustum cell, per axis (the thesis leaves it open; see
/// `docs/review.md`).
pub const DEFAULT_REVIEW_BOX: f32 = 2.0;
/// The prefetch factor k of `F + k·velocity` (thesis §4.4.1: best at 0.8).
pub const DEFAULT_PREFETCH_K: f32 = 0.8;
/// Most history cells kept (thesis: "fewer than twenty in most cases").
pub const HISTORY_MAX: usize = 20;
/// DPLRU's weights α = β (γ is the policy's, `hdov_storage::cache::DEFAULT_GAMMA`).
pub const DPLRU_WEIGHT: f64 = 1.0 / 3.0;

/// REVIEW's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReviewParams {
    /// SF: the disk cell is the frustum cell scaled by this about its centre (≥ 1).
    pub review_box: f32,
    /// The depth of the view frustum, in scene units (metres).
    pub eyesight: f32,
    /// The horizontal and vertical field of view, in degrees, in (0, 180).
    pub fov_deg: f32,
    /// The prefetch factor k.
    pub prefetch_k: f32,
}

impl Default for ReviewParams {
    fn default() -> Self {
        Self {
            review_box: DEFAULT_REVIEW_BOX,
            eyesight: DEFAULT_EYESIGHT,
            fov_deg: DEFAULT_FOV_DEG,
            prefetch_k: DEFAULT_PREFETCH_K,
        }
    }
}

impl ReviewParams {
    /// Checks the numbers; returns the parameter and the reason of the first bad one.
    pub fn check(&self) -> Result<(), (Param, String)> {
        if !(self.review_box.is_finite() && self.review_box >= 1.0) {
            return Err((Param::ReviewBox, format!("{} must be finite and >= 1", self.review_box)));
        }
        if !(self.eyesight.is_finite() && self.eyesight > 0.0) {
            return Err((Param::Eyesight, format!("{} must be finite and > 0", self.eyesight)));
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err((Param::Fov, format!("{}° is not in (0, 180)", self.fov_deg)));
        }
        if !(self.prefetch_k.is_finite() && self.prefetch_k >= 0.0) {
            return Err((Param::PrefetchK, format!("{} must be finite and >= 0", self.prefetch_k)));
        }
        Ok(())
    }

    /// The camera REVIEW culls with: square image, `fov_deg` both ways, looking along `look`.
    pub fn camera(&self, look: Vec3) -> crate::camera::Camera {
        crate::camera::Camera { look, fov_y_deg: self.fov_deg, aspect: 1.0, ..Default::default() }
    }
}

/// The frustum cell: the box of the view frustum from `eye` along `look` to the far plane at
/// `eyesight`, `fov_deg` wide both ways. Without a direction (the viewer may look anywhere),
/// the cube of half-side `eyesight` around the eye.
pub fn frustum_cell(eye: Vec3, look: Option<Vec3>, p: &ReviewParams) -> Aabb {
    let Some(dir) = look.and_then(|l| l.try_normalize()) else {
        return Aabb::new(eye - p.eyesight, eye + p.eyesight);
    };
    let (_, right, up) = crate::camera::basis(dir);
    let half = p.eyesight * (p.fov_deg.to_radians() / 2.0).tan();
    let far = eye + dir * p.eyesight;
    let corners =
        [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].map(|(a, b)| far + right * (a * half) + up * (b * half));
    Aabb::from_points(std::iter::once(eye).chain(corners))
}

/// `cell` scaled by `sf` about its centre.
pub fn disk_cell(cell: &Aabb, sf: f32) -> Aabb {
    let (c, h) = (cell.center(), cell.extent() * (sf / 2.0));
    Aabb::new(c - h, c + h)
}

/// The prefetch cell (thesis §4.2.5): a box of `size` centred at `F + k·velocity`, F the
/// centre of the far plane (the eye itself without a direction).
pub fn predicted_cell(eye: Vec3, look: Option<Vec3>, velocity: Vec3, size: Vec3, p: &ReviewParams) -> Aabb {
    let far = look.and_then(|l| l.try_normalize()).map_or(eye, |d| eye + d * p.eyesight);
    let c = far + velocity * p.prefetch_k;
    Aabb::new(c - size / 2.0, c + size / 2.0)
}

/// DPLRU's caller side, `α·pp + β·pd` (α = β = 1/3): `pp` = the node's level over the root's
/// (1 for the root, 0 for a leaf), `pd` = 1 − its block distance to the query cell over
/// `scale` (the scene's largest extent), at least 0. The policy adds `γ·pl`.
pub fn dplru_priority(level: u32, root_level: u32, block_distance: f32, scale: f32) -> f64 {
    let pp = if root_level == 0 { 1.0 } else { f64::from(level) / f64::from(root_level) };
    let pd = 1.0 - (f64::from(block_distance) / f64::from(scale.max(f32::MIN_POSITIVE))).min(1.0);
    DPLRU_WEIGHT * pp + DPLRU_WEIGHT * pd
}
