//! The level-of-detail rules that the query modes pick levels by: screen error from the cell
//! (relaxed by visibility under the η rule), visibility-weighted screen error (vmsse), and the
//! thesis's interpolation by DoV (eq. 5.5, 5.6).

use glam::{Mat4, Vec3};

use super::{LodRule, MAX_DOV, QueryParams};
use crate::db::Database;
use crate::format::catalog::LodRef;
use crate::geom::{Aabb, max_scale};
use crate::lod::pick_level;

/// A query's place and parameters, and the level rules over them.
pub(super) struct Levels<'a> {
    pub db: &'a Database,
    pub at: Vec3,
    pub cell_box: Aabb,
    pub params: &'a QueryParams,
}

impl Levels<'_> {
    /// The leaf LOD chain of object `o`.
    pub fn object_chain(&self, o: u32) -> &[LodRef] {
        self.db.catalog().object_lods(o)
    }

    /// The internal LOD chain of node `c`.
    pub fn node_chain(&self, c: u32) -> &[LodRef] {
        &self.db.catalog().node_lods[c as usize]
    }

    /// How much object `o`'s transform scales its mesh (and so its LOD errors).
    pub fn object_scale(&self, o: u32) -> f64 {
        f64::from(max_scale(&Mat4::from_cols_array(&self.db.catalog().objects[o as usize].transform)))
    }

    /// The query's LOD rule for object `o` seen with DoV `d`, unrelaxed: the coarsest level
    /// within the screen-error bound, or eq. 5.6's `k = min(DoV / MAXDOV, 1)`.
    pub fn object_level(&self, o: u32, d: f64, mbr: &Aabb) -> usize {
        let chain = self.object_chain(o);
        match self.params.lod_rule {
            LodRule::ScreenError { pixels } => {
                self.coarsest_within_pixels(chain, mbr, self.object_scale(o), pixels).unwrap_or(0)
            }
            LodRule::Dov => pick(chain, d / MAX_DOV),
        }
    }

    /// The screen-error bound `pixels` relaxed by visibility as vmsse relaxes it, B(μ)·error ≤
    /// pixels, for something of DoV `d` in box `mbr`: μ is taken from the cell's point farthest
    /// from the box's centre, where the box covers least of the sphere, so that the bound is the
    /// least relaxed one over the cell (docs/query.md, "The η rule").
    pub fn relaxed_pixels(&self, pixels: f64, d: f64, mbr: &Aabb) -> f64 {
        let far = farthest_point_distance(&self.cell_box, &mbr.center());
        pixels / bias_at_distance(d, far, mbr).max(f64::MIN_POSITIVE)
    }

    /// The faces node `c`'s `nvo` visible objects would draw at their coarsest leaf LODs. The
    /// counts come from files: the product saturates instead of wrapping, and `nvo` counts at
    /// most the node's objects.
    pub fn descent_cap(&self, c: u32, nvo: u32) -> u64 {
        let shape = &self.db.catalog().node_shapes[c as usize];
        u64::from(nvo.min(shape.objects)).saturating_mul(shape.coarsest_object_faces) / u64::from(shape.objects.max(1))
    }

    /// The faces node `c`'s `nvo` visible objects would draw at the levels the screen-error
    /// bound `pixels` gives them from the far side of the node: an estimate from the catalog's
    /// descent table, no page read.
    pub fn descent_faces(&self, c: u32, nvo: u32, mbr: &Aabb, pixels: f64) -> u64 {
        let shape = &self.db.catalog().node_shapes[c as usize];
        let per_unit = self.params.camera.unwrap_or_default().pixels_per_unit();
        let far_error = pixels * f64::from(farthest(&self.cell_box, mbr)) / per_unit;
        let faces = self.db.catalog().descent_faces_at(c, far_error);
        u64::from(nvo.min(shape.objects)).saturating_mul(faces) / u64::from(shape.objects.max(1))
    }

    /// `h·(1 + log_M s) < log_M(NVO)` (thesis eq. 5.4), with h = log_M m, m the node's leaf
    /// descendants, s its face ratio and M the tree's fan-out.
    pub fn internal_is_cheaper(&self, c: u32, nvo: u32) -> bool {
        let shape = &self.db.catalog().node_shapes[c as usize];
        let m_fan = (self.db.manifest().tree.max_entries.max(2)) as f64;
        let log_m = |x: f64| x.ln() / m_fan.ln();
        let h = log_m(f64::from(shape.leaves.max(1)));
        let lhs = if h == 0.0 { 0.0 } else { h * (1.0 + log_m(f64::from(shape.face_ratio))) };
        lhs < log_m(f64::from(nvo.max(1)))
    }

    /// Vmsse: the coarsest level whose visibility-weighted screen error is at most τ.
    pub fn coarsest_within_tau(&self, chain: &[LodRef], d: f64, mbr: &Aabb, scale: f64) -> Option<usize> {
        let cam = self.params.camera.unwrap_or_default();
        let bias = visibility_bias(d, self.at, mbr);
        (0..chain.len())
            .rev()
            .find(|&l| bias * cam.screen_error(self.at, mbr, f64::from(chain[l].error) * scale) <= self.params.tau)
    }

    /// The screen-error rule: the coarsest level whose error (times `scale`, for an object's
    /// transform) is at most `pixels` from the nearest point of the cell (only an error-free
    /// level where the cell meets the box); `None` when no level is.
    pub fn coarsest_within_pixels(&self, chain: &[LodRef], mbr: &Aabb, scale: f64, pixels: f64) -> Option<usize> {
        let per_unit = self.params.camera.unwrap_or_default().pixels_per_unit();
        let distance = f64::from(self.cell_box.distance(mbr));
        (0..chain.len()).rev().find(|&l| f64::from(chain[l].error) * scale * per_unit <= pixels * distance)
    }
}

/// The largest distance between a point of `a` and a point of `b`.
fn farthest(a: &Aabb, b: &Aabb) -> f32 {
    (a.max - b.min).abs().max((b.max - a.min).abs()).length()
}

/// The largest distance from a point of `a` to `p`.
fn farthest_point_distance(a: &Aabb, p: &Vec3) -> f32 {
    (a.max - *p).abs().max((*p - a.min).abs()).length()
}

/// The level picked by eq. 5.5/5.6 for interpolation weight `k`.
pub(super) fn pick(chain: &[LodRef], k: f64) -> usize {
    pick_level(chain.len(), |i| u64::from(chain[i].faces), k)
}

/// B(μ) = √μ, μ = DoV over the share of the sphere the box's bounding sphere covers from `at`
/// (1 inside it): the visible fraction of what could be seen. Monotone, B(0) = 0, B(1) = 1;
/// concave, so a half-hidden node keeps 71 % of its error weight (seed 000 §4 compares curves).
pub fn visibility_bias(dov: f64, at: Vec3, mbr: &Aabb) -> f64 {
    bias_at_distance(dov, at.distance(mbr.center()), mbr)
}

/// [`visibility_bias`] with the box's centre `distance` away.
fn bias_at_distance(dov: f64, distance: f32, mbr: &Aabb) -> f64 {
    let r = f64::from(mbr.extent().length()) / 2.0;
    let dist = f64::from(distance);
    let cover = if dist <= r { 1.0 } else { (1.0 - (1.0 - (r / dist).powi(2)).sqrt()) / 2.0 };
    (dov / cover.max(f64::MIN_POSITIVE)).clamp(0.0, 1.0).sqrt()
}
