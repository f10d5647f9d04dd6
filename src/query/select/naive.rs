//! Naive mode (thesis §5.8.4): every object visible from the cell at its leaf LOD, reading the
//! leaves' V-pages alone (and each leaf's page for its objects), in depth-first order.

use super::{Choice, Selection};
use crate::geom::Aabb;
use crate::query::levels::Levels;

pub(in crate::query) struct Naive;

impl Selection for Naive {
    /// Every leaf, in node order.
    fn roots(&self, l: &Levels) -> Vec<(u32, f64)> {
        let shapes = &l.db.catalog().node_shapes;
        (0..l.db.node_count()).filter(|&n| shapes[n as usize].level == 0).map(|n| (n, 0.0)).collect()
    }

    fn object(&self, l: &Levels, o: u32, d: f64, _leaf: f64, mbr: &Aabb) -> Option<usize> {
        (d > 0.0).then(|| l.object_level(o, d, mbr))
    }

    /// Never reached from a leaf; a visible node is descended, never stopped at.
    fn node(&self, _: &Levels, _: u32, d: f64, _: u32, _: &Aabb) -> Choice {
        if d > 0.0 { Choice::Descend } else { Choice::Skip }
    }
}
