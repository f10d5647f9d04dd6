//! The byte layout of one R-tree node inside a page of `tree.pages` (storage kind `TREE`).
//!
//! Page payload (little-endian), node id = page number:
//! ```text
//! 0   u32 level (0 = leaf)
//! 4   u32 parent node id (u32::MAX for the root)
//! 8   u32 entry count n
//! 12  u32 objects under the node
//! 16  u32 leaves under the node
//! 20  12 bytes reserved, zero
//! 32  n × 32-byte entries: f32 min x,y,z, f32 max x,y,z, u32 child (node id or object index), u32 reserved (zero)
//! ```

use crate::geom::Aabb;
use crate::rtree::{Entry, Node};

pub const NODE_HEADER_LEN: usize = 32;
pub const ENTRY_LEN: usize = 32;
/// Bytes a page spends on its own crc32 (the storage page trailer).
const PAGE_TRAILER_LEN: usize = hdov_storage::pagefile::PAGE_CRC_LEN;

/// Entries a node can hold in a page of `page_size` bytes: the tree's fan-out.
pub fn fanout(page_size: u32) -> usize {
    (page_size as usize).saturating_sub(PAGE_TRAILER_LEN + NODE_HEADER_LEN) / ENTRY_LEN
}

/// Node plus the subtree counts the query engine needs without visiting the subtree.
#[derive(Clone, Debug, PartialEq)]
pub struct NodePage {
    pub node: Node,
    pub subtree_objects: u32,
    pub subtree_leaves: u32,
}

pub fn encode(page: &NodePage) -> Vec<u8> {
    let n = &page.node;
    let mut out = Vec::with_capacity(NODE_HEADER_LEN + ENTRY_LEN * n.entries.len());
    for v in [n.level, n.parent.unwrap_or(u32::MAX), n.entries.len() as u32, page.subtree_objects, page.subtree_leaves]
    {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.resize(NODE_HEADER_LEN, 0);
    for e in &n.entries {
        for c in e.mbr.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out.extend_from_slice(&e.child.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
    }
    out
}

/// Decodes and validates one node page; `nodes` and `objects` bound the child pointers.
/// Returns the reason of the first inconsistency.
pub fn decode(bytes: &[u8], nodes: u32, objects: u32) -> Result<NodePage, String> {
    let u32_at = |off: usize| -> Result<u32, String> {
        bytes
            .get(off..off + 4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
            .ok_or_else(|| format!("node page cut short at byte {off}"))
    };
    let level = u32_at(0)?;
    let parent = u32_at(4)?;
    let count = u32_at(8)? as usize;
    if count == 0 || NODE_HEADER_LEN + count * ENTRY_LEN > bytes.len() {
        return Err(format!("node page claims {count} entries, which do not fit"));
    }
    if parent != u32::MAX && parent >= nodes {
        return Err(format!("parent {parent} out of range ({nodes} nodes)"));
    }
    let bound = if level == 0 { objects } else { nodes };
    let mut entries = Vec::with_capacity(count);
    for i in 0..count {
        let off = NODE_HEADER_LEN + i * ENTRY_LEN;
        let f = |k: usize| f32::from_le_bytes(bytes[off + 4 * k..off + 4 * k + 4].try_into().unwrap());
        let mbr = Aabb::from_array([f(0), f(1), f(2), f(3), f(4), f(5)]);
        let child = u32_at(off + 24)?;
        if child >= bound {
            return Err(format!("entry {i} points to {child}, out of range ({bound})"));
        }
        if !(mbr.min.is_finite() && mbr.max.is_finite()) {
            return Err(format!("entry {i} has a non-finite box"));
        }
        entries.push(Entry { mbr, child });
    }
    Ok(NodePage {
        node: Node { level, parent: (parent != u32::MAX).then_some(parent), entries },
        subtree_objects: u32_at(12)?,
        subtree_leaves: u32_at(16)?,
    })
}

/// Checks that a decoded page fits its place `id` in the depth-first numbering: the root is node
/// 0, a parent precedes its children and children follow their parent, so no walk down or up
/// the tree can loop. Returns the reason of the first violation.
pub fn check_position(page: &NodePage, id: u32) -> Result<(), String> {
    let n = &page.node;
    match n.parent {
        None if id != 0 => return Err("no parent, yet not the root (node 0)".into()),
        Some(p) if p >= id => return Err(format!("parent {p} does not precede the node")),
        _ => {}
    }
    if n.level > 0
        && let Some((i, e)) = n.entries.iter().enumerate().find(|(_, e)| e.child <= id)
    {
        return Err(format!("entry {i} points to node {}, which does not follow the node", e.child));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn fanout_follows_page_size() {
        assert_eq!(fanout(4096), 126);
        assert_eq!(fanout(1024), 30);
    }

    #[test]
    fn round_trip_and_bad_pointers() {
        let page = NodePage {
            node: Node {
                level: 1,
                parent: Some(0),
                entries: vec![Entry { mbr: Aabb::new(Vec3::ZERO, Vec3::ONE), child: 3 }; 5],
            },
            subtree_objects: 40,
            subtree_leaves: 5,
        };
        let bytes = encode(&page);
        assert_eq!(decode(&bytes, 10, 100).as_ref(), Ok(&page));
        assert!(decode(&bytes, 3, 100).unwrap_err().contains("out of range"));
        assert!(decode(&bytes[..40], 10, 100).unwrap_err().contains("do not fit"));
        // Node 2 under node 0, pointing down to node 3: in place. Elsewhere, a loop.
        assert_eq!(check_position(&page, 2), Ok(()));
        assert!(check_position(&page, 0).unwrap_err().contains("parent 0"));
        assert!(check_position(&page, 3).unwrap_err().contains("entry 0 points to node 3"));
    }
}
