//! How a query walks the tree. One walk ([`Traversal::walk`]) serves threshold, vmsse, naive and
//! frustum modes; what each keeps is its [`Selection`] (`select/`, one file per mode). Budget
//! mode shares the walk's reads and level rules but refines by sharing a face budget among
//! siblings, which no per-entry rule expresses ([`Traversal::budget`]).
//!
//! A node's page and its V-page are read only when the walk enters the node; the V-entry that
//! led there (its DoV) is the node's priority for the cache.

use glam::Vec3;

use super::levels::Levels;
use super::select::{Choice, InFrustum, Naive, Selection, Threshold, Vmsse};
use super::{Item, ItemKind, Mode, QueryParams};
use crate::db::Database;
use crate::db::access::Access;
use crate::error::Result;
use crate::format::catalog::LodRef;
use crate::format::tree_page::NodePage;
use crate::geom::Aabb;
use hdov_storage::VEntry;

/// What a traversal found.
pub(super) struct Found {
    pub items: Vec<Item>,
    pub nodes_visited: u64,
    pub over_budget: bool,
}

/// Runs `params.mode` from `at` in the cell `access` has selected, whose box is `cell_box`;
/// frustum mode culls to the camera only if `cull`.
pub(super) fn run(
    db: &Database,
    access: &mut Access,
    at: Vec3,
    cell_box: Aabb,
    params: &QueryParams,
    cull: bool,
) -> Result<Found> {
    let levels = Levels { db, at, cell_box, params };
    let mut t = Traversal { levels, access, items: Vec::new(), nodes_visited: 0, vpage: Vec::new() };
    let selection: Box<dyn Selection> = match params.mode {
        Mode::Threshold => Box::new(Threshold),
        Mode::Vmsse => Box::new(Vmsse),
        Mode::Naive => Box::new(Naive),
        Mode::Frustum => Box::new(InFrustum(params.camera.filter(|_| cull).map(|c| c.frustum(at)))),
        Mode::Budget => {
            let over_budget = t.budget_root()?;
            return Ok(Found { items: t.items, nodes_visited: t.nodes_visited, over_budget });
        }
    };
    for (root, dov) in selection.roots(&t.levels) {
        t.walk(root, dov, selection.as_ref())?;
    }
    Ok(Found { items: t.items, nodes_visited: t.nodes_visited, over_budget: false })
}

struct Traversal<'a, 'db> {
    levels: Levels<'a>,
    access: &'a mut Access<'db>,
    items: Vec<Item>,
    nodes_visited: u64,
    /// A reused buffer for V-pages.
    vpage: Vec<VEntry>,
}

impl Traversal<'_, '_> {
    /// Reads node `id`'s page and its V-page in the cell; `None` when the node is hidden there.
    fn enter(&mut self, id: u32, dov: f64) -> Result<Option<(NodePage, Vec<VEntry>)>> {
        let mut v = std::mem::take(&mut self.vpage);
        let Some(page) = self.access.enter(id, dov, &mut v)? else {
            self.vpage = v;
            return Ok(None);
        };
        self.nodes_visited += 1;
        Ok(Some((page, v)))
    }

    /// Enters node `id` (reached with DoV `dov`) and handles each of its entries as `sel` says,
    /// in entry order, depth first.
    fn walk(&mut self, id: u32, dov: f64, sel: &dyn Selection) -> Result<()> {
        let (page, v) = if sel.reads_visibility() {
            let Some(entered) = self.enter(id, dov)? else { return Ok(()) };
            entered
        } else {
            self.nodes_visited += 1;
            (self.access.node(id, 0.0)?, Vec::new())
        };
        for (k, e) in page.node.entries.iter().enumerate() {
            let (d, nvo) = v.get(k).map_or((0.0, 0), |ve| (f64::from(ve.dov), ve.nvo));
            if page.node.is_leaf() {
                if let Some(lod) = sel.object(&self.levels, e.child, d, dov, &e.mbr) {
                    self.push_object(e.child, lod, d, e.mbr);
                }
                continue;
            }
            match sel.node(&self.levels, e.child, d, nvo, &e.mbr) {
                Choice::Skip => {}
                Choice::Stop(lod) => self.push_node(e.child, lod, d, e.mbr),
                Choice::Descend => self.walk(e.child, d, sel)?,
            }
        }
        if sel.reads_visibility() {
            self.vpage = v;
        }
        Ok(())
    }

    fn push_object(&mut self, o: u32, lod: usize, d: f64, mbr: Aabb) {
        let cat = self.levels.db.catalog();
        let lod_ref = cat.object_lods(o)[lod];
        let record = &cat.objects[o as usize];
        self.items.push(item(ItemKind::Object, o, (record.name.clone(), record.part), lod, lod_ref, d, mbr));
    }

    fn push_node(&mut self, n: u32, lod: usize, d: f64, mbr: Aabb) {
        let lod_ref = self.levels.db.catalog().node_lods[n as usize][lod];
        self.items.push(item(ItemKind::Node, n, (format!("node {n}").into(), None), lod, lod_ref, d, mbr));
    }

    /// Budget mode from the root: refine within `params.budget` faces; if even that does not
    /// fit, the root's own LOD. Returns whether the budget was overrun.
    fn budget_root(&mut self) -> Result<bool> {
        let budget = self.levels.params.budget;
        let used = self.budget(0, 1.0, budget)?;
        if used <= budget {
            return Ok(false);
        }
        // The refinement overran even after every child fell back to its own LOD: the root's
        // LOD that fits (fig. 6.2's fallback to the parent, at the top).
        let chain = &self.levels.db.catalog().node_lods[0];
        if chain.is_empty() {
            return Ok(true); // no root LOD to fall back to: the refinement stands, over budget
        }
        let mbr = self.items.iter().fold(Aabb::EMPTY, |b, i| b.union(i.mbr));
        self.items.clear();
        let (lod, over) = fit(chain, budget, 0);
        self.push_node(0, lod, 1.0, mbr);
        Ok(over)
    }

    /// Thesis fig. 6.2: children in descending DoV, child i gets `remaining · d_i / D_rest`;
    /// a leaf's level is the LOD rule's, or coarser to fit B_i (the thesis: eq. 5.6's, λ = min(DoV/MAXDOV, 1)); an internal
    /// child is refined and falls back to its own LOD if the refinement overruns. Returns the
    /// faces used (more than `budget` only where coarsest LODs alone exceed it).
    fn budget(&mut self, id: u32, dov: f64, budget: u64) -> Result<u64> {
        let Some((page, v)) = self.enter(id, dov)? else { return Ok(0) };
        let mut visible: Vec<(usize, f64)> =
            v.iter().enumerate().filter(|(_, ve)| ve.dov > 0.0).map(|(i, ve)| (i, f64::from(ve.dov))).collect();
        visible.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let mut rest: f64 = visible.iter().map(|v| v.1).sum();
        let (mut remaining, mut used) = (budget, 0u64);
        for (i, d) in visible {
            let e = page.node.entries[i];
            let share = if rest > 0.0 { (remaining as f64 * d / rest) as u64 } else { remaining };
            rest -= d;
            let spent = if page.node.is_leaf() {
                let chain = self.levels.db.catalog().object_lods(e.child);
                let (lod, _) = fit(chain, share, self.levels.object_level(e.child, d, &e.mbr));
                self.push_object(e.child, lod, d, e.mbr);
                u64::from(chain[lod].faces)
            } else {
                let mark = self.items.len();
                let refined = self.budget(e.child, d, share)?;
                if refined <= share || self.levels.db.catalog().node_lods[e.child as usize].is_empty() {
                    refined
                } else {
                    // The refinement overran: the child's own LOD instead.
                    self.items.truncate(mark);
                    let chain = &self.levels.db.catalog().node_lods[e.child as usize];
                    let (lod, _) = fit(chain, share, 0);
                    self.push_node(e.child, lod, d, e.mbr);
                    u64::from(chain[lod].faces)
                }
            };
            used += spent;
            remaining = remaining.saturating_sub(spent);
        }
        self.vpage = v;
        Ok(used)
    }
}

/// The finest level at or below `preferred`'s detail with at most `budget` faces; the coarsest
/// (and `true`, an overrun) when none fits.
fn fit(chain: &[LodRef], budget: u64, preferred: usize) -> (usize, bool) {
    match (preferred..chain.len()).find(|&l| u64::from(chain[l].faces) <= budget) {
        Some(l) => (l, false),
        None => (chain.len() - 1, true),
    }
}

/// An answer item; `name` is its name and part.
fn item(kind: ItemKind, id: u32, name: (std::sync::Arc<str>, Option<u32>), lod: usize, lod_ref: LodRef, d: f64, mbr: Aabb) -> Item {
    Item { kind, id, name: name.0, part: name.1, lod: lod as u32, faces: lod_ref.faces, dov: d as f32, mbr, lod_ref }
}
