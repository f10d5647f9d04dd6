//! What each query mode keeps of the tree walk ([`super::traverse`]), as rstar's selection
//! functions are: for every entry of a node the walk entered, skip it, return it at a level (an
//! object, or an internal node as one LOD), or descend. One file per mode; budget mode shares a
//! face budget among siblings, which no per-entry rule expresses, and has a walk of its own.

mod frustum;
mod naive;
mod threshold;
mod vmsse;

pub(super) use frustum::InFrustum;
pub(super) use naive::Naive;
pub(super) use threshold::Threshold;
pub(super) use vmsse::Vmsse;

use super::levels::Levels;
use crate::geom::Aabb;

/// What the walk does with one entry of an internal node.
pub(super) enum Choice {
    Skip,
    /// Return the child node as its internal LOD at this level.
    Stop(usize),
    Descend,
}

/// A query mode's rule for the tree walk.
pub(super) trait Selection {
    /// Where the walk starts: `(node, DoV it is reached with)`, in order. The root by default.
    fn roots(&self, _levels: &Levels) -> Vec<(u32, f64)> {
        vec![(0, 1.0)]
    }

    /// Whether the walk reads V-pages: entries then carry their DoV and NVO in the query's cell,
    /// and a node hidden there is not entered. Without, every entry's DoV is 0.
    fn reads_visibility(&self) -> bool {
        true
    }

    /// The level at which to return object `o` (an entry of a leaf seen with DoV `leaf`; its own
    /// DoV `d`), or `None` to skip it.
    fn object(&self, levels: &Levels, o: u32, d: f64, leaf: f64, mbr: &Aabb) -> Option<usize>;

    /// What to do with child node `c` (DoV `d`, `nvo` visible objects).
    fn node(&self, levels: &Levels, c: u32, d: f64, nvo: u32, mbr: &Aabb) -> Choice;
}

/// The first level from `level` down `chain`'s detail that draws at most `cap` faces: a stopped
/// subtree never draws more than its visible objects would at their coarsest.
fn within_cap(chain: &[crate::format::catalog::LodRef], level: usize, cap: u64) -> Option<usize> {
    (level..chain.len()).find(|&l| u64::from(chain[l].faces) <= cap)
}
