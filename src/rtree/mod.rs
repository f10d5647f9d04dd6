//! The R-tree of the HDoV-tree: one node per fixed-size page, over object bounding boxes.
//!
//! Algorithms are apart from the node structure: [`str`] bulk-loads (the default), [`linear`] is
//! Guttman's insertion with linear split, the thesis's baseline. Both end in [`RTree::from_parts`],
//! which renumbers nodes in depth-first order, so a node's id *is* its depth-first number: the
//! page it is stored in and the index the vertical V-page layouts use.

pub mod linear;
pub mod str;

use serde::{Deserialize, Serialize};

use crate::geom::Aabb;

pub type NodeId = u32;

/// One entry of a node: the bounds of a child node (internal nodes) or of an object (leaves).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    pub mbr: Aabb,
    /// Child node id in an internal node, object index in a leaf.
    pub child: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Node {
    /// 0 for leaves; a parent is one level above its children.
    pub level: u32,
    pub parent: Option<NodeId>,
    pub entries: Vec<Entry>,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.level == 0
    }

    pub fn mbr(&self) -> Aabb {
        self.entries.iter().fold(Aabb::EMPTY, |b, e| b.union(e.mbr))
    }
}

/// Which algorithm builds the tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum TreeAlgorithm {
    /// Sort-Tile-Recursive bulk load with slab counts following the scene's extent per axis.
    #[default]
    Str,
    /// One-by-one insertion with Guttman's linear split (the thesis's R-tree).
    Linear,
}

impl TreeAlgorithm {
    /// Both algorithms.
    pub const ALL: [TreeAlgorithm; 2] = [TreeAlgorithm::Str, TreeAlgorithm::Linear];

    /// The name `--tree` takes. Manifests record the variant instead (`"Str"`, serde's derive)
    /// since format 1.
    pub fn name(self) -> &'static str {
        match self {
            Self::Str => "str",
            Self::Linear => "linear",
        }
    }
}

hdov_storage::named!(TreeAlgorithm, "tree algorithm");
hdov_storage::by_names!(TreeAlgorithm);

/// An R-tree whose node ids are depth-first numbers (root = 0).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RTree {
    pub nodes: Vec<Node>,
    /// Most entries a node may hold (follows from the page size).
    pub max_entries: usize,
}

/// Shape and fill of a tree, for `hdov info` and for comparing the builders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TreeStats {
    pub nodes: usize,
    pub leaves: usize,
    pub height: u32,
    pub max_entries: usize,
    /// Mean entries per node / max_entries.
    pub fill_factor: f64,
    /// Sum over nodes of MBR volume, a measure of how tight the grouping is (lower is better).
    pub total_volume: f64,
    /// Sum over levels of the pairwise overlap volume between sibling nodes' MBRs.
    pub sibling_overlap: f64,
}

impl RTree {
    /// Builds a tree over `boxes` (object i has box i).
    pub fn build(boxes: &[Aabb], max_entries: usize, algorithm: TreeAlgorithm) -> RTree {
        assert!(max_entries >= 2, "a node must hold at least two entries");
        match algorithm {
            TreeAlgorithm::Str => str::bulk_load(boxes, max_entries),
            TreeAlgorithm::Linear => linear::insert_all(boxes, max_entries),
        }
    }

    /// Makes a tree from nodes in any order with a known root: renumbers depth-first (root = 0,
    /// children in entry order), rewrites child pointers and parents.
    pub(crate) fn from_parts(nodes: Vec<Node>, root: usize, max_entries: usize) -> RTree {
        let mut order = Vec::with_capacity(nodes.len());
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            order.push(n);
            if !nodes[n].is_leaf() {
                stack.extend(nodes[n].entries.iter().rev().map(|e| e.child as usize));
            }
        }
        let mut new_id = vec![u32::MAX; nodes.len()];
        for (i, &old) in order.iter().enumerate() {
            new_id[old] = i as u32;
        }
        let mut out: Vec<Node> = order
            .iter()
            .map(|&old| {
                let mut n = nodes[old].clone();
                if !n.is_leaf() {
                    for e in &mut n.entries {
                        e.child = new_id[e.child as usize];
                    }
                }
                n.parent = None;
                n
            })
            .collect();
        for id in 0..out.len() {
            if !out[id].is_leaf() {
                for k in 0..out[id].entries.len() {
                    let c = out[id].entries[k].child as usize;
                    out[c].parent = Some(id as NodeId);
                }
            }
        }
        RTree { nodes: out, max_entries }
    }

    pub fn root(&self) -> &Node {
        &self.nodes[0]
    }

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id as usize]
    }

    pub fn height(&self) -> u32 {
        self.root().level + 1
    }

    pub fn object_count(&self) -> usize {
        self.nodes.iter().filter(|n| n.is_leaf()).map(|n| n.entries.len()).sum()
    }

    /// The leaf holding each object, indexed by object.
    pub fn object_leaves(&self) -> Vec<NodeId> {
        let mut leaf = vec![0; self.object_count()];
        for (id, n) in self.nodes.iter().enumerate().filter(|(_, n)| n.is_leaf()) {
            for e in &n.entries {
                leaf[e.child as usize] = id as NodeId;
            }
        }
        leaf
    }

    /// Objects under each node (in depth-first object order), computed bottom-up in one pass.
    pub fn subtree_object_counts(&self) -> Vec<u32> {
        let mut count = vec![0u32; self.nodes.len()];
        // Children have larger ids than their parent (depth-first numbering), so a reverse sweep
        // sees every child before its parent.
        for id in (0..self.nodes.len()).rev() {
            let n = &self.nodes[id];
            count[id] = if n.is_leaf() {
                n.entries.len() as u32
            } else {
                n.entries.iter().map(|e| count[e.child as usize]).sum()
            };
        }
        count
    }

    /// Leaf nodes under each node (a leaf counts itself).
    pub fn subtree_leaf_counts(&self) -> Vec<u32> {
        let mut count = vec![0u32; self.nodes.len()];
        for id in (0..self.nodes.len()).rev() {
            let n = &self.nodes[id];
            count[id] = if n.is_leaf() { 1 } else { n.entries.iter().map(|e| count[e.child as usize]).sum() };
        }
        count
    }

    /// The objects under `node`, in depth-first order.
    pub fn objects_under(&self, node: NodeId) -> Vec<u32> {
        let mut out = Vec::new();
        let mut stack = vec![node];
        while let Some(n) = stack.pop() {
            let n = self.node(n);
            if n.is_leaf() {
                out.extend(n.entries.iter().map(|e| e.child));
            } else {
                stack.extend(n.entries.iter().rev().map(|e| e.child));
            }
        }
        out
    }

    pub fn stats(&self) -> TreeStats {
        let entries: usize = self.nodes.iter().map(|n| n.entries.len()).sum();
        let mut overlap = 0.0;
        for n in self.nodes.iter().filter(|n| !n.is_leaf()) {
            for (i, a) in n.entries.iter().enumerate() {
                for b in &n.entries[i + 1..] {
                    let lo = a.mbr.min.max(b.mbr.min);
                    let hi = a.mbr.max.min(b.mbr.max);
                    overlap += Aabb::new(lo, hi).volume() as f64;
                }
            }
        }
        TreeStats {
            nodes: self.nodes.len(),
            leaves: self.nodes.iter().filter(|n| n.is_leaf()).count(),
            height: self.height(),
            max_entries: self.max_entries,
            fill_factor: entries as f64 / (self.nodes.len() * self.max_entries) as f64,
            total_volume: self.nodes.iter().map(|n| n.mbr().volume() as f64).sum(),
            sibling_overlap: overlap,
        }
    }

    /// Checks the R-tree invariants against the object boxes; returns the first violation.
    /// Every object reachable exactly once, every entry's MBR equal to its child's bounds (hence
    /// containing it), node sizes within bounds, leaves all at level 0, parents consistent and ids
    /// in depth-first order.
    pub fn check(&self, boxes: &[Aabb]) -> Result<(), String> {
        if self.nodes.is_empty() {
            return Err("tree has no nodes".into());
        }
        let mut seen = vec![false; boxes.len()];
        let mut next_dfs = 0u32;
        let mut stack = vec![0u32];
        while let Some(id) = stack.pop() {
            if id != next_dfs {
                return Err(format!("node {id} visited as depth-first number {next_dfs}"));
            }
            next_dfs += 1;
            let n = self.node(id);
            if n.entries.is_empty() || n.entries.len() > self.max_entries {
                return Err(format!("node {id} has {} entries (max {})", n.entries.len(), self.max_entries));
            }
            for e in &n.entries {
                if n.is_leaf() {
                    let o = e.child as usize;
                    if o >= boxes.len() || std::mem::replace(&mut seen[o], true) {
                        return Err(format!("object {o} is out of range or reachable twice"));
                    }
                    if e.mbr != boxes[o] {
                        return Err(format!("leaf {id}: entry of object {o} has a wrong box"));
                    }
                } else {
                    let c = self.node(e.child);
                    if c.parent != Some(id) || c.level + 1 != n.level {
                        return Err(format!("node {}: parent/level inconsistent with node {id}", e.child));
                    }
                    if e.mbr != c.mbr() {
                        return Err(format!("node {id}: entry MBR differs from child {}'s bounds", e.child));
                    }
                }
            }
            if !n.is_leaf() {
                stack.extend(n.entries.iter().rev().map(|e| e.child));
            }
        }
        if next_dfs as usize != self.nodes.len() {
            return Err(format!("{} of {} nodes reachable", next_dfs, self.nodes.len()));
        }
        if let Some(o) = seen.iter().position(|s| !s) {
            return Err(format!("object {o} is not reachable"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use proptest::prelude::*;

    fn boxes_strategy() -> impl Strategy<Value = Vec<Aabb>> {
        prop::collection::vec(
            (0.0f32..1000.0, 0.0f32..50.0, 0.0f32..1000.0, 0.1f32..40.0, 0.1f32..60.0, 0.1f32..40.0),
            1..600,
        )
        .prop_map(|v| {
            v.into_iter()
                .map(|(x, y, z, w, h, d)| Aabb::new(Vec3::new(x, y, z), Vec3::new(x + w, y + h, z + d)))
                .collect()
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn both_builders_keep_the_invariants(boxes in boxes_strategy(), m in 3usize..20) {
            for alg in [TreeAlgorithm::Str, TreeAlgorithm::Linear] {
                let t = RTree::build(&boxes, m, alg);
                prop_assert_eq!(t.check(&boxes), Ok(()), "{}", alg);
                prop_assert_eq!(t.object_count(), boxes.len());
                prop_assert_eq!(t.subtree_object_counts()[0] as usize, boxes.len());
                let s = t.stats();
                prop_assert!(s.fill_factor > 0.0 && s.fill_factor <= 1.0);
            }
        }
    }

    #[test]
    fn str_packs_leaves_full_and_follows_a_flat_extent() {
        // 40 × 40 flat city blocks: STR should cut x and z, never the thin y axis.
        let boxes: Vec<Aabb> = (0..1600)
            .map(|i| {
                let (x, z) = ((i % 40) as f32 * 10.0, (i / 40) as f32 * 10.0);
                Aabb::new(Vec3::new(x, 0.0, z), Vec3::new(x + 8.0, 20.0, z + 8.0))
            })
            .collect();
        let t = RTree::build(&boxes, 16, TreeAlgorithm::Str);
        t.check(&boxes).unwrap();
        let s = t.stats();
        assert!(s.fill_factor > 0.9, "{s:?}");
        // Leaves are square-ish tiles of 4 × 4 blocks, not strips.
        for n in t.nodes.iter().filter(|n| n.is_leaf()) {
            let e = n.mbr().extent();
            assert!(e.x < 80.0 && e.z < 80.0, "leaf extent {e}");
        }
        // STR groups better than insertion with linear splits on the same data.
        let lin = RTree::build(&boxes, 16, TreeAlgorithm::Linear);
        lin.check(&boxes).unwrap();
        assert!(lin.stats().total_volume > s.total_volume);
    }
}
