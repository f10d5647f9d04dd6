//! REVIEW as a session's cell-finding method: when the frustum cell leaves the disk cell,
//! CSearch the new disk cell against the history and delta-load the object buffer's part in it;
//! prefetch the predicted cell when the next step's frustum cell would leave the disk cell.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Instant;

use glam::Vec3;

use super::{HISTORY_MAX, ReviewParams, disk_cell, dplru_priority, frustum_cell, predicted_cell, search};
use crate::camera::distance_to_box;
use crate::db::Database;
use crate::db::access::Access;
use crate::error::{Error, Param, Result};
use crate::geom::Aabb;
use crate::query::{Answer, CellMethod, Item, ItemKind, QueryParams, QueryStats, Session, SessionParams, Step};
use crate::rtree::Entry;
use hdov_storage::CacheLimits;

impl Database {
    /// Starts a REVIEW walkthrough session (thesis ch. 4): disk cells, CSearch, the R-tree
    /// alone, read through the session's page cache. The query's mode, η and layout are not
    /// used, nor the viewing grid (steps report its cell where the viewpoint lies in it).
    /// Checks the parameters; reads nothing yet.
    pub fn review_session(&self, params: &SessionParams, review: ReviewParams) -> Result<Session<'_>> {
        crate::query::session::check_camera(params)?;
        review.check().map_err(|(param, reason)| Error::bad_param(param, reason))?;
        let limits = CacheLimits { pages: params.cache_pages, bytes: params.cache_bytes };
        let access = Access::spatial(self, limits, params.cache);
        Ok(Session::new(self, params, access, Box::new(Review::new(self, review, params.query))))
    }
}

/// A REVIEW session's state beside the shared [`Session`] one.
#[derive(Debug)]
struct Review {
    params: ReviewParams,
    /// What answers report as their mode and η (REVIEW uses neither).
    query: QueryParams,
    /// The disk cell queried last.
    cell: Option<Aabb>,
    /// The disk cell of a flip whose delta loading is under way.
    flipping: Option<Aabb>,
    /// Cells every object of which is in the buffer (CSearch's H), the current one included.
    history: Vec<Aabb>,
    /// The object buffer: what the searches returned and is still resident, by object.
    buffer: BTreeMap<u32, Item>,
    /// Boxes of the tree nodes met so far (children of nodes read), for DPLRU's distances.
    boxes: HashMap<u32, Aabb>,
    /// Nodes read, whose cached pages' priorities follow the query cell.
    read: HashSet<u32>,
    /// The cell prefetched last.
    prefetched: Option<Aabb>,
    /// DPLRU's distance scale: the scene's largest extent.
    scale: f32,
}

impl Review {
    fn new(db: &Database, params: ReviewParams, query: QueryParams) -> Review {
        let scale = db.node(0).map(|n| n.node.mbr().extent().max_element()).unwrap_or(1.0);
        Review {
            params,
            query,
            cell: None,
            flipping: None,
            history: Vec::new(),
            buffer: BTreeMap::new(),
            boxes: HashMap::new(),
            read: HashSet::new(),
            prefetched: None,
            scale,
        }
    }

    /// The cache priority of node `id` while `cell` is queried.
    fn priority(&self, db: &Database, id: u32, cell: &Aabb) -> f64 {
        let shapes = &db.catalog().node_shapes;
        let d = self.boxes.get(&id).map_or(0.0, |b| search::block_distance(b, cell));
        dplru_priority(shapes[id as usize].level, shapes[0].level, d, self.scale)
    }

    /// CSearch of `cell` against the history, reading the tree through `access` at DPLRU
    /// priorities for `cell`; records the boxes met and the nodes read. Returns the qualifying
    /// object entries and the nodes read.
    fn search_through(&mut self, db: &Database, access: &mut Access, cell: &Aabb) -> Result<(Vec<Entry>, u64)> {
        let history = self.history.clone();
        let mut nodes = 0u64;
        let found = search::csearch(cell, &history, &mut |id| {
            let page = access.node(id, self.priority(db, id, cell))?;
            nodes += 1;
            if !page.node.is_leaf() {
                self.boxes.extend(page.node.entries.iter().map(|e| (e.child, e.mbr)));
            }
            self.read.insert(id);
            Ok(page.node)
        })?;
        Ok((found, nodes))
    }
}

impl CellMethod for Review {
    fn flip(
        &mut self,
        access: &mut Access,
        at: Vec3,
        look: Option<Vec3>,
        _current: Option<&Answer>,
        step: &mut Step,
    ) -> Result<Option<Answer>> {
        if !at.is_finite() {
            return Err(Error::bad_param(Param::At, format!("{:?} is not a finite point", at.to_array())));
        }
        let db = access.db();
        let start = Instant::now();
        let grid_cell = db.grid().and_then(|g| g.cell_of(at).map(|c| (c, g.cell_id(c) as u32)));
        let cell = grid_cell.unwrap_or_default();
        step.cell = cell.0;
        let view = frustum_cell(at, look, &self.params);
        if self.cell.is_some_and(|c| c.contains(&view)) {
            return Ok(None);
        }
        let disk = disk_cell(&view, self.params.review_box);
        self.history.retain(|h| h.intersects(&disk));
        access.reset_io();
        // DPLRU: the cached tree pages' priorities follow the new cell.
        let read: Vec<u32> = self.read.iter().copied().collect();
        for id in read {
            if !access.set_node_priority(id, self.priority(db, id, &disk)) {
                self.read.remove(&id);
            }
        }
        let (found, nodes) = self.search_through(db, access, &disk)?;
        for e in found {
            self.buffer.entry(e.child).or_insert_with(|| object_item(db, e.child, e.mbr));
        }
        let items: Vec<Item> = self.buffer.values().filter(|i| i.mbr.intersects(&disk)).cloned().collect();
        let stats = QueryStats::new(access.io(), nodes, &items, false, start);
        self.flipping = Some(disk);
        Ok(Some(Answer::new(at, cell, &self.query, None, items, stats, Vec::new())))
    }

    /// What delta loading evicted leaves the buffer; then only the new cell's objects are known
    /// to be all there, so the history restarts from it.
    fn loaded(&mut self, resident: &dyn Fn(u64) -> bool) {
        let Some(disk) = self.flipping.take() else { return };
        let before = self.buffer.len();
        self.buffer.retain(|_, i| resident(i.lod_ref.offset));
        if self.buffer.len() < before {
            self.history.clear();
        }
        self.history.push(disk);
        if self.history.len() > HISTORY_MAX {
            self.history.remove(0);
        }
        self.cell = Some(disk);
        self.prefetched = None;
    }

    /// REVIEW's prefetch (thesis §4.2.5): once per disk cell, when the next step at the
    /// current velocity would take the frustum cell out of it, CSearch the cell around
    /// `F + k·velocity` against the history, reading its tree pages into the cache (no
    /// geometry).
    fn prefetch(
        &mut self,
        access: &mut Access,
        at: Vec3,
        last: Vec3,
        look: Option<Vec3>,
        _current: &Answer,
    ) -> Result<u64> {
        let Some(cell) = self.cell else { return Ok(0) };
        let velocity = at - last;
        if self.prefetched.is_some() || velocity == Vec3::ZERO {
            return Ok(0);
        }
        if cell.contains(&frustum_cell(at + velocity, look, &self.params)) {
            return Ok(0);
        }
        let db = access.db();
        let next = predicted_cell(at, look, velocity, cell.extent(), &self.params);
        let before = access.io().tree;
        self.search_through(db, access, &next)?;
        self.prefetched = Some(next);
        Ok(access.io().tree - before)
    }

    /// The object buffer's part in the disk cell culled to REVIEW's own frustum (`fov_deg`
    /// both ways) and to the eyesight.
    fn frame<'a>(&self, answer: &'a Answer, at: Vec3, look: Option<Vec3>) -> Vec<&'a Item> {
        let eyesight = self.params.eyesight;
        let near = |i: &&Item| distance_to_box(at, &i.mbr) <= eyesight;
        match look.map(|l| self.params.camera(l)).filter(|c| c.check().is_ok()) {
            Some(cam) => {
                let f = cam.frustum(at);
                answer.items.iter().filter(|i| f.meets(&i.mbr)).filter(near).collect()
            }
            None => answer.items.iter().filter(near).collect(),
        }
    }
}

/// The buffer item of object `o` (box `mbr`): full detail, no DoV (REVIEW measures none).
fn object_item(db: &Database, o: u32, mbr: Aabb) -> Item {
    let cat = db.catalog();
    let lod_ref = cat.object_lods(o)[0];
    Item {
        kind: ItemKind::Object,
        id: o,
        name: cat.objects[o as usize].name.clone(),
        part: cat.objects[o as usize].part,
        lod: 0,
        faces: lod_ref.faces,
        dov: 0.0,
        mbr,
        lod_ref,
    }
}
