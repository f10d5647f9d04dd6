//! Guttman's R-tree insertion with the linear split (1984), the thesis's tree: objects are
//! inserted one by one into the leaf whose box grows least, and an overflowing node is split
//! around the two entries farthest apart along some axis. Kept as the baseline that STR
//! bulk loading is compared against.

use super::{Entry, Node, RTree};
use crate::geom::Aabb;

/// Smallest share of `max_entries` a split leaves in either half (Guttman's m = 40 %).
const MIN_FILL: f64 = 0.4;

pub fn insert_all(boxes: &[Aabb], max_entries: usize) -> RTree {
    let mut t = Builder { nodes: vec![Node { level: 0, parent: None, entries: Vec::new() }], root: 0, max_entries };
    for (i, b) in boxes.iter().enumerate() {
        t.insert(Entry { mbr: *b, child: i as u32 });
    }
    RTree::from_parts(t.nodes, t.root, max_entries)
}

struct Builder {
    nodes: Vec<Node>,
    root: usize,
    max_entries: usize,
}

/// Volume with a small surface term, so that flat or degenerate boxes still compare.
fn cost(b: &Aabb) -> f64 {
    b.volume() as f64 + 1e-3 * b.surface_area() as f64
}

impl Builder {
    fn insert(&mut self, entry: Entry) {
        let leaf = self.choose_leaf(&entry.mbr);
        self.nodes[leaf].entries.push(entry);
        self.adjust(leaf);
    }

    /// Descends by least enlargement, ties broken by the smaller box.
    fn choose_leaf(&self, b: &Aabb) -> usize {
        let mut n = self.root;
        while !self.nodes[n].is_leaf() {
            let best = self.nodes[n]
                .entries
                .iter()
                .min_by(|x, y| {
                    let gx = cost(&x.mbr.union(*b)) - cost(&x.mbr);
                    let gy = cost(&y.mbr.union(*b)) - cost(&y.mbr);
                    gx.total_cmp(&gy).then(cost(&x.mbr).total_cmp(&cost(&y.mbr)))
                })
                .expect("internal nodes are never empty");
            n = best.child as usize;
        }
        n
    }

    /// Walks from `n` to the root, splitting overflowing nodes and refreshing parent entries.
    fn adjust(&mut self, mut n: usize) {
        loop {
            let sibling = (self.nodes[n].entries.len() > self.max_entries).then(|| self.split(n));
            match self.nodes[n].parent {
                None => {
                    if let Some(s) = sibling {
                        let level = self.nodes[n].level + 1;
                        let root = self.nodes.len();
                        let entries = [n, s].map(|c| Entry { mbr: self.nodes[c].mbr(), child: c as u32 }).to_vec();
                        self.nodes.push(Node { level, parent: None, entries });
                        self.nodes[n].parent = Some(root as u32);
                        self.nodes[s].parent = Some(root as u32);
                        self.root = root;
                    }
                    return;
                }
                Some(p) => {
                    let p = p as usize;
                    let mbr = self.nodes[n].mbr();
                    let slot =
                        self.nodes[p].entries.iter_mut().find(|e| e.child as usize == n).expect("child in parent");
                    slot.mbr = mbr;
                    if let Some(s) = sibling {
                        self.nodes[s].parent = Some(p as u32);
                        let mbr = self.nodes[s].mbr();
                        self.nodes[p].entries.push(Entry { mbr, child: s as u32 });
                    }
                    n = p;
                }
            }
        }
    }

    /// Linear split: seeds are the pair with the greatest normalised separation on any axis; the
    /// rest go, in order, to the group that grows least, unless the other needs them to reach
    /// the minimum fill. Returns the new sibling's id.
    fn split(&mut self, n: usize) -> usize {
        let entries = std::mem::take(&mut self.nodes[n].entries);
        let (s1, s2) = pick_seeds(&entries);
        let min = ((self.max_entries as f64 * MIN_FILL).floor() as usize).max(1);
        let mut groups = [vec![entries[s1]], vec![entries[s2]]];
        let mut boxes = [entries[s1].mbr, entries[s2].mbr];
        let rest: Vec<Entry> =
            entries.iter().enumerate().filter(|(i, _)| *i != s1 && *i != s2).map(|(_, e)| *e).collect();
        let total = rest.len();
        for (k, e) in rest.into_iter().enumerate() {
            let left = total - k;
            let g = if groups[0].len() + left <= min {
                0
            } else if groups[1].len() + left <= min {
                1
            } else {
                let grow = |i: usize| cost(&boxes[i].union(e.mbr)) - cost(&boxes[i]);
                if grow(0) < grow(1) || (grow(0) == grow(1) && groups[0].len() <= groups[1].len()) { 0 } else { 1 }
            };
            boxes[g] = boxes[g].union(e.mbr);
            groups[g].push(e);
        }
        let [a, b] = groups;
        let level = self.nodes[n].level;
        self.nodes[n].entries = a;
        let sibling = self.nodes.len();
        if level > 0 {
            for e in &b {
                self.nodes[e.child as usize].parent = Some(sibling as u32);
            }
        }
        self.nodes.push(Node { level, parent: None, entries: b });
        sibling
    }
}

fn pick_seeds(entries: &[Entry]) -> (usize, usize) {
    let mut best = (0, 1, f32::NEG_INFINITY);
    for axis in 0..3 {
        // The entry with the highest low side and the one with the lowest high side.
        let hi_low = (0..entries.len()).max_by(|&a, &b| entries[a].mbr.min[axis].total_cmp(&entries[b].mbr.min[axis]));
        let lo_high = (0..entries.len()).min_by(|&a, &b| entries[a].mbr.max[axis].total_cmp(&entries[b].mbr.max[axis]));
        let (Some(a), Some(b)) = (hi_low, lo_high) else { continue };
        if a == b {
            continue;
        }
        let lo = entries.iter().map(|e| e.mbr.min[axis]).fold(f32::INFINITY, f32::min);
        let hi = entries.iter().map(|e| e.mbr.max[axis]).fold(f32::NEG_INFINITY, f32::max);
        let width = (hi - lo).max(f32::MIN_POSITIVE);
        let sep = (entries[a].mbr.min[axis] - entries[b].mbr.max[axis]) / width;
        if sep > best.2 {
            best = (a, b, sep);
        }
    }
    (best.0, best.1)
}
