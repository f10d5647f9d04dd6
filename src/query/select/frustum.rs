//! Frustum mode (the CONV baseline): tree pages only; every object whose box meets the frustum
//! (all of them without one), at full detail.

use super::{Choice, Selection};
use crate::camera::Frustum;
use crate::geom::Aabb;
use crate::query::levels::Levels;

pub(in crate::query) struct InFrustum(pub Option<Frustum>);

impl Selection for InFrustum {
    fn roots(&self, _: &Levels) -> Vec<(u32, f64)> {
        vec![(0, 0.0)]
    }

    fn reads_visibility(&self) -> bool {
        false
    }

    fn object(&self, _: &Levels, _: u32, _: f64, _: f64, mbr: &Aabb) -> Option<usize> {
        self.0.is_none_or(|f| f.meets(mbr)).then_some(0)
    }

    fn node(&self, _: &Levels, _: u32, _: f64, _: u32, mbr: &Aabb) -> Choice {
        if self.0.is_none_or(|f| f.meets(mbr)) { Choice::Descend } else { Choice::Skip }
    }
}
