//! Sort-Tile-Recursive bulk loading (Leutenegger et al. 1997), with slab counts per axis in
//! proportion to the data's extent: a flat city is cut into columns along x and z and never
//! along its thin height axis, so leaves are compact tiles rather than thin slices.

use super::{Entry, Node, RTree};
use crate::geom::Aabb;

/// Builds the tree bottom-up: pack objects into leaves, then leaves into parents, until one
/// node remains. Every node but the last of each slab run is full.
pub fn bulk_load(boxes: &[Aabb], max_entries: usize) -> RTree {
    let mut nodes: Vec<Node> = Vec::new();
    let mut level_entries: Vec<Entry> =
        boxes.iter().enumerate().map(|(i, b)| Entry { mbr: *b, child: i as u32 }).collect();
    let mut level = 0;
    loop {
        let groups = pack(&mut level_entries, max_entries);
        let first = nodes.len();
        for g in groups {
            nodes.push(Node { level, parent: None, entries: g });
        }
        if nodes.len() - first == 1 {
            let root = nodes.len() - 1;
            return RTree::from_parts(nodes, root, max_entries);
        }
        level_entries = (first..nodes.len()).map(|id| Entry { mbr: nodes[id].mbr(), child: id as u32 }).collect();
        level += 1;
    }
}

/// Slab counts per axis whose product is about `leaves` and whose ratios follow `extent`.
/// An axis whose share would fall below one slab gets exactly one and drops out.
pub fn slab_counts(extent: glam::Vec3, leaves: usize) -> [usize; 3] {
    let mut counts = [1usize; 3];
    let mut active: Vec<usize> = (0..3).filter(|&a| extent[a] > 0.0).collect();
    loop {
        if active.is_empty() {
            return counts;
        }
        // s_a = e_a · (P / Π e)^(1/k): equal slab widths on every active axis.
        let prod: f64 = active.iter().map(|&a| extent[a] as f64).product();
        let k = active.len() as f64;
        let unit = (leaves as f64 / prod).powf(1.0 / k);
        let shares: Vec<f64> = active.iter().map(|&a| extent[a] as f64 * unit).collect();
        if let Some(i) = shares.iter().position(|&s| s < 1.0) {
            active.remove(i);
            continue;
        }
        for (i, &a) in active.iter().enumerate() {
            counts[a] = shares[i].round().max(1.0) as usize;
        }
        return counts;
    }
}

/// Groups entries into runs of at most `max_entries`, tiling space by centre coordinates.
fn pack(entries: &mut [Entry], max_entries: usize) -> Vec<Vec<Entry>> {
    let leaves = entries.len().div_ceil(max_entries);
    let bounds = Aabb::from_points(entries.iter().map(|e| e.mbr.center()));
    let counts = slab_counts(bounds.extent(), leaves);
    // Cut the axes with most slabs first; the last axis only orders entries inside a run.
    let mut axes = [0usize, 1, 2];
    axes.sort_by_key(|&a| std::cmp::Reverse(counts[a]));
    let mut out = Vec::with_capacity(leaves);
    tile(entries, &axes, &counts, max_entries, &mut out);
    out
}

fn tile(entries: &mut [Entry], axes: &[usize], counts: &[usize; 3], max_entries: usize, out: &mut Vec<Vec<Entry>>) {
    let axis = axes[0];
    entries.sort_by(|a, b| a.mbr.center()[axis].total_cmp(&b.mbr.center()[axis]));
    if axes.len() == 1 {
        out.extend(entries.chunks(max_entries).map(|c| c.to_vec()));
        return;
    }
    // Slabs hold whole nodes' worth of entries so that only the last node of a slab is partial.
    let nodes = entries.len().div_ceil(max_entries);
    let per_slab = nodes.div_ceil(counts[axis].max(1)) * max_entries;
    for slab in entries.chunks_mut(per_slab.max(max_entries)) {
        tile(slab, &axes[1..], counts, max_entries, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn slab_counts_follow_extent() {
        // A flat square city: no cuts along y.
        let c = slab_counts(Vec3::new(1000.0, 10.0, 1000.0), 100);
        assert_eq!(c[1], 1);
        assert_eq!(c[0], 10);
        assert_eq!(c[2], 10);
        // A long street: almost all cuts along x.
        let c = slab_counts(Vec3::new(4000.0, 5.0, 250.0), 64);
        assert_eq!(c, [32, 1, 2]);
        // A cube: equal cuts.
        assert_eq!(slab_counts(Vec3::splat(1.0), 27), [3, 3, 3]);
        assert_eq!(slab_counts(Vec3::ZERO, 5), [1, 1, 1]);
    }
}
