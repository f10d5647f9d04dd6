//! Vmsse mode (seeds 000/001): refine until the visibility-weighted screen-space error is at
//! most τ pixels; hidden entries are skipped.

use super::{Choice, Selection, within_cap};
use crate::geom::Aabb;
use crate::query::levels::Levels;

pub(in crate::query) struct Vmsse;

impl Selection for Vmsse {
    fn object(&self, l: &Levels, o: u32, d: f64, _leaf: f64, mbr: &Aabb) -> Option<usize> {
        (d > 0.0).then(|| l.coarsest_within_tau(l.object_chain(o), d, mbr, l.object_scale(o)).unwrap_or(0))
    }

    /// Stops at the coarsest internal level within τ, made coarser until it draws no more than
    /// the visible objects would at their coarsest.
    fn node(&self, l: &Levels, c: u32, d: f64, nvo: u32, mbr: &Aabb) -> Choice {
        if d <= 0.0 {
            return Choice::Skip;
        }
        let chain = l.node_chain(c);
        l.coarsest_within_tau(chain, d, mbr, 1.0)
            .and_then(|level| within_cap(chain, level, l.descent_cap(c, nvo)))
            .map_or(Choice::Descend, Choice::Stop)
    }
}
