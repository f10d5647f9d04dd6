//! One view cell's whole visibility at once: every node and object it may see, with its DoV, and
//! where the threshold query stops refining there. What a client that picks its own levels (a
//! 3D Tiles renderer, `export::tiles`) needs in order to skip what is hidden and keep the η rule.

use std::collections::HashMap;

use glam::Vec3;

use super::{ItemKind, Mode, QueryParams, traverse};
use crate::db::Database;
use crate::db::access::Access;
use crate::error::{Error, Param, Result};
use hdov_storage::VEntry;

/// What one view cell sees, by tree entry.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellVisibility {
    /// The view cell.
    pub cell: u32,
    /// Every node the cell may see (its V-entry is not zero) with its DoV, in id order; the root
    /// (seen when anything is) with DoV 1, as the query enters it.
    pub nodes: Vec<(u32, f32)>,
    /// Every object the cell may see with its DoV, in id order.
    pub objects: Vec<(u32, f32)>,
    /// Nodes where the threshold query stops (DoV ≤ η) and the internal level it draws there:
    /// nothing below them is refined further, in id order.
    pub node_stops: Vec<(u32, u32)>,
    /// Objects of barely visible leaves (the leaf's DoV ≤ η) and the level the query draws them
    /// at (their bound relaxed by visibility), in id order.
    pub object_stops: Vec<(u32, u32)>,
}

impl Database {
    /// The whole visibility of view cell `cell` ([`CellVisibility`]): every V-page of a node the
    /// cell sees, and the threshold query of `params` (which depends on the cell, not the point
    /// in it) for its stops. Refused without a grid, past the last cell, or in another mode.
    pub fn cell_visibility(&self, cell: u32, params: &QueryParams) -> Result<CellVisibility> {
        let grid = self
            .grid()
            .ok_or_else(|| Error::bad_param(Param::Cell, format!("{} holds no grid", self.dir().display())))?;
        if cell as usize >= grid.cell_count() {
            return Err(Error::bad_param(Param::Cell, format!("{cell} is past the last view cell ({})", grid.cell_count())));
        }
        if params.mode != Mode::Threshold {
            return Err(Error::bad_param(Param::Mode, "a cell's visibility keeps the threshold query's stops"));
        }
        self.check_query(params)?;
        let mut access = Access::open(self, params.layout)?;
        access.flip(cell)?;
        let mut out = CellVisibility { cell, ..Default::default() };
        // The DoV of each seen leaf, for its objects' stops.
        let mut leaf_of_object: HashMap<u32, f32> = HashMap::new();
        let mut stack = vec![(0u32, 1.0f32)];
        let mut v: Vec<VEntry> = Vec::new();
        while let Some((id, dov)) = stack.pop() {
            let Some(page) = access.enter(id, f64::from(dov), &mut v)? else { continue };
            out.nodes.push((id, dov));
            for (e, ve) in page.node.entries.iter().zip(&v) {
                if ve.is_zero() {
                    continue;
                }
                if page.node.is_leaf() {
                    out.objects.push((e.child, ve.dov));
                    leaf_of_object.insert(e.child, dov);
                } else {
                    stack.push((e.child, ve.dov));
                }
            }
        }
        out.nodes.sort_unstable_by_key(|n| n.0);
        out.objects.sort_unstable_by_key(|o| o.0);
        let view = grid.view_cell(cell as usize);
        let at = view.point(Vec3::splat(0.5));
        let found = traverse::run(self, &mut access, at, view.bounds, params, false)?;
        for item in found.items {
            match item.kind {
                ItemKind::Node => out.node_stops.push((item.id, item.lod)),
                ItemKind::Object if leaf_of_object.get(&item.id).is_some_and(|&d| f64::from(d) <= params.eta) => {
                    out.object_stops.push((item.id, item.lod))
                }
                ItemKind::Object => {}
            }
        }
        out.node_stops.sort_unstable();
        out.object_stops.sort_unstable();
        Ok(out)
    }
}
