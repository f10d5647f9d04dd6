//! REVIEW's searches over the R-tree (thesis §4.2.2): the plain box query, and **CSearch**, the
//! complement search that returns the objects of a new disk cell that no cell of the history
//! returned already.
//!
//! Both read nodes through a caller's function (a session reads pages through its
//! [`PageReader`](hdov_storage::PageReader); tests read an in-memory tree), so they know
//! nothing of pages, caches or counts.

use crate::error::Result;
use crate::geom::Aabb;
use crate::rtree::{Entry, Node};

/// The block distance of thesis §4.2.4: 0 when the boxes meet, else the largest of the gaps
/// between them along x, y and z.
pub fn block_distance(a: &Aabb, b: &Aabb) -> f32 {
    let gap = (a.min - b.max).max(b.min - a.max).max(glam::Vec3::ZERO);
    gap.max_element()
}

/// Every object entry (object index and box) whose box meets `cell` (boundaries included),
/// in depth-first order: the BOX baseline's query. `read(id)` gives node `id`; node 0 is the
/// root.
pub fn box_query(cell: &Aabb, read: &mut dyn FnMut(u32) -> Result<Node>) -> Result<Vec<Entry>> {
    csearch(cell, &[], read)
}

/// CSearch (thesis fig. 4.5): the object entries whose boxes meet `cell` and none of the cells
/// of `history`, in depth-first order. An internal entry is followed only if its box meets
/// `cell` and lies inside none of the history cells (it "complement-overlaps" them all: a
/// subtree inside a history cell holds only objects that meet that cell, so none qualify).
/// With an empty history it is [`box_query`]. Reads no node that the box query would not.
pub fn csearch(cell: &Aabb, history: &[Aabb], read: &mut dyn FnMut(u32) -> Result<Node>) -> Result<Vec<Entry>> {
    let mut out = Vec::new();
    let mut stack = vec![0u32];
    while let Some(id) = stack.pop() {
        let node = read(id)?;
        if node.is_leaf() {
            let fresh = |e: &&Entry| e.mbr.intersects(cell) && !history.iter().any(|h| h.intersects(&e.mbr));
            out.extend(node.entries.iter().filter(fresh));
        } else {
            // Pushed in reverse, so children are visited in entry order (depth-first).
            let follow = |e: &&Entry| e.mbr.intersects(cell) && !history.iter().any(|h| h.contains(&e.mbr));
            stack.extend(node.entries.iter().rev().filter(follow).map(|e| e.child));
        }
    }
    Ok(out)
}
