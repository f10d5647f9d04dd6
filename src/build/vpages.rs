//! From per-cell DoV to V-pages and back.
//!
//! The V-page of node N for cell c holds one V-entry per entry of N: for an internal node the
//! child node's (DoV, NVO), for a leaf the object's (DoV, 1 if visible else 0). A node gets a
//! V-page in a cell only if some entry is visible there: hidden subtrees cost no storage.

use hdov_storage::{Layout, PageReader, VData, VEntry};

use crate::dov::precompute::CellDov;
use crate::error::Result;
use crate::rtree::RTree;

/// V-data of the whole grid from the cells a build (or shard) computed; other cells stay empty.
pub fn vdata_from_cells(tree: &RTree, cell_count: u32, cells: &[(u32, CellDov)]) -> VData {
    let mut data = VData {
        cell_count,
        node_fanout: tree.nodes.iter().map(|n| n.entries.len() as u16).collect(),
        cells: vec![Vec::new(); cell_count as usize],
    };
    for (cell, dov) in cells {
        // Visible nodes are exactly those whose V-page has a visible entry; `dov.nodes` lists
        // the visible nodes, so their parents are the nodes needing a V-page.
        let mut pages: Vec<u32> = Vec::new();
        for &(node, _, _) in &dov.nodes {
            if let Some(p) = tree.nodes[node as usize].parent {
                pages.push(p);
            }
            if tree.nodes[node as usize].is_leaf() {
                pages.push(node);
            }
        }
        pages.sort_unstable();
        pages.dedup();
        data.cells[*cell as usize] = pages
            .into_iter()
            .map(|id| {
                let node = &tree.nodes[id as usize];
                let entries = node
                    .entries
                    .iter()
                    .map(|e| {
                        if node.is_leaf() {
                            let d = dov.object(e.child);
                            VEntry { dov: d, nvo: u32::from(d > 0.0) }
                        } else {
                            let (d, nvo) = dov.node(e.child);
                            VEntry { dov: d, nvo }
                        }
                    })
                    .collect();
                (id, entries)
            })
            .filter(|(_, e): &(u32, Vec<VEntry>)| e.iter().any(|v| !v.is_zero()))
            .collect();
    }
    data
}

/// The visible V-pages of one cell: (node id, V-entries), ascending node id.
pub type CellVPages = Vec<(u32, Vec<VEntry>)>;

/// Reads the V-pages of `cells` back from a layout, one cell at a time into `each(cell, its
/// V-pages)` (for merging shard databases), through a cursor and an uncached page reader of
/// its own.
pub fn for_each_cell(
    layout: &Layout,
    cells: std::ops::Range<u32>,
    mut each: impl FnMut(u32, CellVPages) -> Result<()>,
) -> Result<()> {
    let mut reader = PageReader::uncached();
    let mut cursor = layout.cursor();
    for cell in cells {
        cursor.flip_to_cell(cell, &mut reader)?;
        // Vertical layouts name the nodes they store; horizontal is asked node by node.
        let nodes = cursor.visible_nodes().unwrap_or_else(|| (0..layout.node_count()).collect());
        let mut pages = Vec::new();
        for node in nodes {
            if let Some(v) = cursor.vpage(node, 0.0, &mut reader)? {
                pages.push((node, v));
            }
        }
        each(cell, pages)?;
    }
    Ok(())
}
