//! Threshold mode, the HDoV-tree's traversal (thesis fig. 5.4): hidden entries are skipped,
//! visible objects returned at their leaf level, and a subtree with DoV ≤ η stops at one
//! internal LOD where that draws no more than descending would.

use super::{Choice, Selection, within_cap};
use crate::geom::Aabb;
use crate::query::LodRule;
use crate::query::levels::{Levels, pick};

pub(in crate::query) struct Threshold;

impl Selection for Threshold {
    /// The η rule: the objects of a barely visible leaf (DoV ≤ η) are drawn within the bound
    /// relaxed by their own visibility, as a stopped subtree is. Gated by the leaf, not the
    /// object, so that a subtree is open or closed at every η alike and its stop never draws more
    /// than its descent did at a smaller η (decision 95).
    fn object(&self, l: &Levels, o: u32, d: f64, leaf: f64, mbr: &Aabb) -> Option<usize> {
        if d <= 0.0 {
            return None;
        }
        Some(match l.params.lod_rule {
            LodRule::ScreenError { pixels } if leaf <= l.params.eta => {
                let relaxed = l.relaxed_pixels(pixels, d, mbr);
                l.coarsest_within_pixels(l.object_chain(o), mbr, l.object_scale(o), relaxed).unwrap_or(0)
            }
            _ => l.object_level(o, d, mbr),
        })
    }

    /// Under the screen-error rule (the default) a subtree with DoV ≤ η stops at the coarsest
    /// internal level whose error is within the bound (relaxed by visibility,
    /// [`Levels::relaxed_pixels`]) from the nearest point of the cell, where that level draws
    /// no more faces than descending would ([`Levels::descent_faces`]). Under eq. 5.5 the level
    /// is made coarser until it draws no more than the visible objects would at their coarsest
    /// (leaf LODs of barely visible objects are coarse, which eq. 5.4's estimate from
    /// full-detail faces does not see); where no level does, the query descends.
    fn node(&self, l: &Levels, c: u32, d: f64, nvo: u32, mbr: &Aabb) -> Choice {
        if d <= 0.0 {
            return Choice::Skip; // a hidden branch
        }
        let chain = l.node_chain(c);
        if chain.is_empty() || d > l.params.eta {
            return Choice::Descend;
        }
        let stop = match l.params.lod_rule {
            LodRule::ScreenError { pixels } => l
                .coarsest_within_pixels(chain, mbr, 1.0, l.relaxed_pixels(pixels, d, mbr))
                .filter(|&level| u64::from(chain[level].faces) <= l.descent_faces(c, nvo, mbr, pixels)),
            // Eq. 5.4: stop where the internal LOD draws fewer faces than the visible leaves;
            // eq. 5.5 picks its level.
            LodRule::Dov if l.internal_is_cheaper(c, nvo) => {
                within_cap(chain, pick(chain, d / l.params.eta), l.descent_cap(c, nvo))
            }
            LodRule::Dov => None,
        };
        stop.map_or(Choice::Descend, Choice::Stop)
    }
}
