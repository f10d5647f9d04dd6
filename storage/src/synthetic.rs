//! Synthetic V-data: a complete tree over objects laid out along a street, seen from cells
//! along the same street. Deterministic per seed; used by the tests, the benchmark and the
//! size table of `docs/storage-format.md`.

use crate::vpage::{VData, VEntry};

/// Shape of a synthetic data set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SyntheticSpec {
    pub cells: u32,
    /// Entries per node.
    pub fanout: u16,
    /// Levels of the complete tree; objects = fanout^levels.
    pub levels: u32,
    /// Objects are seen from cells within this fraction of the street's length.
    pub reach: f64,
    /// Of the objects within reach, the share that is not occluded.
    pub visible_share: f64,
    pub seed: u64,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self { cells: 64, fanout: 16, levels: 3, reach: 0.1, visible_share: 0.3, seed: 1 }
    }
}

/// splitmix64: a small, good-enough hash for reproducible pseudo-random choices.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Builds the data set: object DoVs fall off with distance, internal entries carry the sum
/// of their children's DoVs (capped at 1) and NVOs.
pub fn synthetic_vdata(spec: &SyntheticSpec) -> VData {
    let m = u64::from(spec.fanout.max(1));
    let levels = spec.levels.max(1);
    let objects = m.pow(levels);
    // Nodes of a complete tree in dfs order: record (level, first object) per node.
    let mut nodes: Vec<(u32, u64)> = Vec::new();
    fn dfs(level: u32, first: u64, m: u64, levels: u32, out: &mut Vec<(u32, u64)>) {
        out.push((level, first));
        if level + 1 < levels {
            let span = m.pow(levels - level - 1);
            for i in 0..m {
                dfs(level + 1, first + i * span, m, levels, out);
            }
        }
    }
    dfs(0, 0, m, levels, &mut nodes);
    let node_fanout = vec![m as u16; nodes.len()];

    let mut cells = Vec::with_capacity(spec.cells as usize);
    for c in 0..spec.cells {
        let at = (f64::from(c) + 0.5) / f64::from(spec.cells.max(1));
        // DoV of each object from this cell.
        let dov = |o: u64| -> f32 {
            let pos = (o as f64 + 0.5) / objects as f64;
            let d = (pos - at).abs();
            let h = mix(spec.seed ^ mix(u64::from(c) << 32 ^ o));
            if d > spec.reach || unit(h) >= spec.visible_share {
                return 0.0;
            }
            // Nearby objects cover more of the view; spread over decades like real DoVs.
            let near = 1.0 - d / spec.reach.max(1e-9);
            (1e-5_f64 * 1e3_f64.powf(near * unit(mix(h)))) as f32
        };
        let object_dov: Vec<f32> = (0..objects).map(dov).collect();
        let mut cell = Vec::new();
        for (dfs_no, &(level, first)) in nodes.iter().enumerate() {
            let span = m.pow(levels - level - 1);
            let mut entries = Vec::with_capacity(m as usize);
            for i in 0..m {
                let lo = (first + i * span) as usize;
                let seen = &object_dov[lo..lo + span as usize];
                let sum: f32 = seen.iter().sum();
                let nvo = seen.iter().filter(|&&d| d > 0.0).count() as u32;
                entries.push(VEntry { dov: sum.min(1.0), nvo });
            }
            if entries.iter().any(|e| e.dov > 0.0) {
                cell.push((dfs_no as u32, entries));
            }
        }
        cells.push(cell);
    }
    VData { cell_count: spec.cells, node_fanout, cells }
}

/// Sparse V-data: a complete tree of fan-out `fanout` and `levels` levels, seen from `cells`
/// cells; in each visible node each entry is visible with probability `entry_share` (at least
/// one entry per visible node), and a child node is visible exactly when its entry in the
/// parent is. The root is visible from every cell. Models the V-pages of real trees, whose
/// visible nodes see few of their entries (a city street sees a handful of a node's 126).
pub fn sparse_vdata(cells: u32, fanout: u16, levels: u32, entry_share: f64, seed: u64) -> VData {
    let m = usize::from(fanout.max(1));
    let levels = levels.max(1);
    // Nodes in dfs order: per node, its level and its children's dfs numbers.
    let mut children: Vec<Vec<u32>> = Vec::new();
    fn dfs(level: u32, m: usize, levels: u32, children: &mut Vec<Vec<u32>>) -> u32 {
        let me = children.len();
        children.push(Vec::new());
        if level + 1 < levels {
            let kids: Vec<u32> = (0..m).map(|_| dfs(level + 1, m, levels, children)).collect();
            children[me] = kids;
        }
        me as u32
    }
    dfs(0, m, levels, &mut children);
    let node_fanout = vec![m as u16; children.len()];
    let cells_data = (0..cells)
        .map(|c| {
            let mut visible = vec![false; children.len()];
            visible[0] = true;
            let mut cell = Vec::new();
            for n in 0..children.len() {
                if !visible[n] {
                    continue;
                }
                let h = |i: usize| mix(seed ^ mix((u64::from(c) << 40) ^ ((n as u64) << 12) ^ i as u64));
                let forced = (h(usize::MAX >> 1) % m as u64) as usize;
                let entries: Vec<VEntry> = (0..m)
                    .map(|i| {
                        if i != forced && unit(h(i)) >= entry_share {
                            return VEntry::default();
                        }
                        if let Some(&kid) = children[n].get(i) {
                            visible[kid as usize] = true;
                        }
                        let dov = (1e-5_f64 * 1e4_f64.powf(unit(mix(h(i))))) as f32;
                        VEntry { dov, nvo: 1 + (mix(h(i) ^ 1) % 50) as u32 }
                    })
                    .collect();
                cell.push((n as u32, entries));
            }
            cell
        })
        .collect();
    VData { cell_count: cells, node_fanout, cells: cells_data }
}
