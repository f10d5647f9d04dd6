//! Walkthroughs (thesis §5.8.5): a session follows a path of viewpoints. While the viewpoint
//! stays in a cell nothing is read again; on leaving it the session flips to the new cell's
//! V-data and asks the tree again through its page cache. *Delta loading*: a LOD already
//! resident is not loaded again (instances share their base mesh's records, so one load serves
//! them all); LODs the new cell no longer needs are evicted, oldest first, while resident
//! geometry is over its byte budget.
//!
//! The same session runs REVIEW, the spatial baseline ([`Method::Review`], [`crate::review`]):
//! disk cells instead of viewing cells, CSearch instead of the HDoV-tree, the same delta
//! loading, resident geometry and [`Step`]s.

use std::collections::HashMap;
use std::time::Instant;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::access::Access;
use super::camera::distance_to_box;
use super::{Answer, Item, QueryParams, QueryStats};
use crate::db::Database;
use crate::error::{Error, Result};
use crate::render::fidelity::{self, Fidelity};
use crate::render::{ColorMode, Image, Renderer, View};
use crate::review::{self, ReviewParams, ReviewState};
use hdov_storage::{CacheLimits, PolicyKind};

/// Steps ahead along the current motion that prefetch looks (one step is one path point).
pub const PREFETCH_STEPS: f32 = 3.0;

/// How a session finds what to load: the HDoV-tree (VISUAL) or the spatial baseline (REVIEW).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Method {
    /// The HDoV-tree: on each cell flip, the query of `SessionParams::query` (thesis ch. 5).
    #[default]
    Visual,
    /// REVIEW (thesis ch. 4, [`crate::review`]): disk cells, CSearch, the R-tree alone; the
    /// query's mode, η and layout are not used, nor the viewing grid (steps report its cell
    /// where the viewpoint lies in it).
    Review(ReviewParams),
}

/// How a session runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SessionParams {
    /// VISUAL (the default) or REVIEW.
    pub method: Method,
    /// The query each cell flip runs (its camera's look is replaced per step when a step
    /// gives one).
    pub query: QueryParams,
    /// The tree-page and V-page cache's policy.
    pub cache: PolicyKind,
    /// Cache capacity in pages and in bytes (`None`: unbounded).
    pub cache_pages: Option<usize>,
    pub cache_bytes: Option<u64>,
    /// Most bytes of LOD geometry kept resident (`None`: unbounded).
    pub resident_bytes: Option<u64>,
    /// Query the cell [`PREFETCH_STEPS`] ahead along the motion, warming the cache.
    pub prefetch: bool,
}

impl Default for SessionParams {
    fn default() -> Self {
        Self {
            method: Method::Visual,
            query: QueryParams::default(),
            cache: PolicyKind::Lru,
            cache_pages: Some(256),
            cache_bytes: None,
            resident_bytes: None,
            prefetch: false,
        }
    }
}

/// What one step of a walk did and cost.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Step {
    pub step: u64,
    pub at: [f32; 3],
    pub cell: [u32; 3],
    /// The viewpoint entered another cell, and the tree was asked again.
    pub flipped: bool,
    /// LOD records loaded, and their bytes (heavy-weight I/O).
    pub loaded: u64,
    pub loaded_bytes: u64,
    /// LOD records evicted, and their bytes.
    pub evicted: u64,
    pub evicted_bytes: u64,
    /// Geometry resident after the step.
    pub resident: u64,
    pub resident_bytes: u64,
    /// Light-weight pages read (tree, V-index, V-pages) by this step's query.
    pub pages_read: u64,
    /// Page requests served without a read (the cache, or the reader's buffer of the page
    /// just read), and those read from the file.
    pub hits: u64,
    pub misses: u64,
    /// Of those, the requests that reached the page cache (past the read buffers), and those
    /// it served: the cache's own hit rate is `cache_hits / cache_requests`.
    pub cache_requests: u64,
    pub cache_hits: u64,
    /// Pages prefetch read for the cell ahead.
    pub prefetch_pages: u64,
    /// Items and faces drawn this step (culled to the step's view when it has a look).
    pub items: u64,
    pub faces: u64,
    /// The cell's answer needs more geometry than the resident budget holds.
    pub over_budget: bool,
    pub micros: u64,
    /// With `hdov walk --fidelity`: PSNR in dB of the drawn answer against full detail from
    /// the step's camera (`null` in JSON when the images are equal), and the share of pixels
    /// whose coverage differs ([`crate::render::fidelity`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage_diff: Option<f64>,
}

/// A resident LOD record.
struct Resident {
    bytes: Box<[u8]>,
    last_used: u64,
}

/// A walkthrough over one database. See the module documentation.
pub struct Session<'db> {
    db: &'db Database,
    params: SessionParams,
    access: Access<'db>,
    /// The current cell's answer, unculled: what stays resident while the viewer is in it.
    answer: Option<Answer>,
    last_at: Option<Vec3>,
    /// By LOD record offset in `geometry.blob`.
    resident: HashMap<u64, Resident>,
    resident_bytes: u64,
    steps: u64,
    /// REVIEW's disk cells, history and object buffer (`None` for VISUAL).
    review: Option<ReviewState>,
}

impl Database {
    /// Starts a walkthrough session. Checks the parameters; reads nothing yet.
    pub fn session(&self, params: &SessionParams) -> Result<Session<'_>> {
        if let Some(cam) = &params.query.camera {
            cam.check().map_err(|r| Error::bad_param("camera", r))?;
        }
        let limits = CacheLimits { pages: params.cache_pages, bytes: params.cache_bytes };
        let (access, review) = match params.method {
            Method::Visual => (Access::cached(self, params.query.layout, limits, params.cache)?, None),
            Method::Review(r) => {
                r.check().map_err(|(param, reason)| Error::bad_param(param, reason))?;
                (Access::spatial(self, limits, params.cache), Some(ReviewState::new(self, r)))
            }
        };
        Ok(Session {
            db: self,
            params: *params,
            access,
            review,
            answer: None,
            last_at: None,
            resident: HashMap::new(),
            resident_bytes: 0,
            steps: 0,
        })
    }
}

impl<'db> Session<'db> {
    /// Moves the viewer to `at`, looking along `look` (or the session camera's direction).
    /// Errors as [`Database::query`] does (a viewpoint outside the grid, ...), and leaves the
    /// session as it was.
    pub fn step(&mut self, at: Vec3, look: Option<Vec3>) -> Result<Step> {
        let start = Instant::now();
        let mut step = if self.review.is_some() { self.review_step(at, look)? } else { self.visual_step(at)? };
        let items = self.frame_items(at, look);
        step.items = items.len() as u64;
        step.faces = items.iter().map(|i| u64::from(i.faces)).sum();
        step.resident = self.resident.len() as u64;
        step.resident_bytes = self.resident_bytes;
        step.micros = start.elapsed().as_micros() as u64;
        self.last_at = Some(at);
        self.steps += 1;
        Ok(step)
    }

    /// VISUAL: a cell flip queries the HDoV-tree; prefetch queries the cell ahead.
    fn visual_step(&mut self, at: Vec3) -> Result<Step> {
        let (cell, cell_id) = self.db.locate(at)?;
        let flipped = self.answer.as_ref().is_none_or(|a| a.cell_id != cell_id);
        let mut step = Step { step: self.steps, at: at.to_array(), cell, flipped, ..Default::default() };
        if flipped {
            // The cell's whole answer (not culled): what a walkthrough keeps resident.
            let answer = self.db.query_with(&mut self.access, at, &self.params.query, false)?;
            step.pages_read = answer.stats.pages_read;
            step.hits = answer.stats.page_hits;
            step.misses = answer.stats.pages_requested - answer.stats.page_hits;
            let cache = self.access.cache_stats();
            (step.cache_requests, step.cache_hits) = (cache.requests, cache.hits);
            self.answer = Some(answer);
            self.delta_load(&mut step)?;
        }
        if self.params.prefetch {
            step.prefetch_pages = self.prefetch(at, cell_id)?;
        }
        Ok(step)
    }

    /// The direction the viewer looks: the step's, else the session camera's.
    fn look(&self, look: Option<Vec3>) -> Option<Vec3> {
        look.or(self.params.query.camera.map(|c| c.look))
    }

    /// REVIEW: when the frustum cell leaves the disk cell, CSearch the new disk cell against
    /// the history and delta-load the object buffer's part in it; prefetch the predicted cell
    /// when the next step's frustum cell would leave the disk cell.
    fn review_step(&mut self, at: Vec3, look: Option<Vec3>) -> Result<Step> {
        if !at.is_finite() {
            return Err(Error::bad_param("at", format!("{:?} is not a finite point", at.to_array())));
        }
        let grid_cell = self.db.grid().and_then(|g| g.cell_of(at).map(|c| (c, g.cell_id(c) as u32)));
        let (cell, cell_id) = grid_cell.unwrap_or_default();
        let mut step = Step { step: self.steps, at: at.to_array(), cell, ..Default::default() };
        let look = self.look(look);
        let db = self.db;
        let r = self.review.as_mut().expect("a review session");
        let view = review::frustum_cell(at, look, &r.params);
        if !r.cell.is_some_and(|c| c.contains(&view)) {
            let disk = review::disk_cell(&view, r.params.review_box);
            step.flipped = true;
            r.history.retain(|h| h.intersects(&disk));
            self.access.reset_io();
            // DPLRU: the cached tree pages' priorities follow the new cell.
            let read: Vec<u32> = r.read.iter().copied().collect();
            for id in read {
                if !self.access.set_node_priority(id, r.priority(db, id, &disk)) {
                    r.read.remove(&id);
                }
            }
            let (found, nodes) = review::search_through(db, &mut self.access, r, &disk)?;
            for e in found {
                r.buffer.entry(e.child).or_insert_with(|| review::object_item(db, e.child, e.mbr));
            }
            let items: Vec<Item> = r.buffer.values().filter(|i| i.mbr.intersects(&disk)).cloned().collect();
            let io = self.access.io();
            step.pages_read = io.tree;
            step.hits = io.hits;
            step.misses = io.requested - io.hits;
            let cache = self.access.cache_stats();
            (step.cache_requests, step.cache_hits) = (cache.requests, cache.hits);
            let stats = QueryStats {
                tree_pages: io.tree,
                pages_read: io.tree,
                pages_requested: io.requested,
                page_hits: io.hits,
                nodes_visited: nodes,
                faces: items.iter().map(|i| u64::from(i.faces)).sum(),
                ..QueryStats::default()
            };
            let q = &self.params.query;
            self.answer = Some(Answer {
                at: step.at,
                cell,
                cell_id,
                mode: q.mode,
                eta: q.eta,
                layout: "review".into(),
                items,
                stats,
                warnings: Vec::new(),
            });
            self.delta_load(&mut step)?;
            // What delta loading evicted leaves the buffer; then only the new cell's objects
            // are known to be all there, so the history restarts from it.
            let r = self.review.as_mut().expect("a review session");
            let before = r.buffer.len();
            let resident = &self.resident;
            r.buffer.retain(|_, i| resident.contains_key(&i.lod_ref.offset));
            if r.buffer.len() < before {
                r.history.clear();
            }
            r.history.push(disk);
            if r.history.len() > review::HISTORY_MAX {
                r.history.remove(0);
            }
            r.cell = Some(disk);
            r.prefetched = None;
        }
        if self.params.prefetch {
            step.prefetch_pages = self.review_prefetch(at, look)?;
        }
        Ok(step)
    }

    /// REVIEW's prefetch (thesis §4.2.5): once per disk cell, when the next step at the
    /// current velocity would take the frustum cell out of it, CSearch the cell around
    /// `F + k·velocity` against the history, reading its tree pages into the cache (no
    /// geometry). Returns pages read.
    fn review_prefetch(&mut self, at: Vec3, look: Option<Vec3>) -> Result<u64> {
        let Some(last) = self.last_at else { return Ok(0) };
        let db = self.db;
        let r = self.review.as_mut().expect("a review session");
        let Some(cell) = r.cell else { return Ok(0) };
        let velocity = at - last;
        if r.prefetched.is_some() || velocity == Vec3::ZERO {
            return Ok(0);
        }
        if cell.contains(&review::frustum_cell(at + velocity, look, &r.params)) {
            return Ok(0);
        }
        let next = review::predicted_cell(at, look, velocity, cell.extent(), &r.params);
        let before = self.access.io().tree;
        review::search_through(db, &mut self.access, r, &next)?;
        r.prefetched = Some(next);
        Ok(self.access.io().tree - before)
    }

    /// The items to draw from `at` looking along `look`: the cell's answer culled to the view.
    /// REVIEW culls the object buffer's part in the disk cell to its own frustum (`fov_deg`
    /// both ways) and to the eyesight.
    pub fn frame_items(&self, at: Vec3, look: Option<Vec3>) -> Vec<&Item> {
        let Some(answer) = &self.answer else { return Vec::new() };
        if let Some(r) = &self.review {
            let eyesight = r.params.eyesight;
            let near = |i: &&Item| distance_to_box(at, &i.mbr) <= eyesight;
            return match self.look(look).map(|l| r.params.camera(l)).filter(|c| c.check().is_ok()) {
                Some(cam) => {
                    let f = cam.frustum(at);
                    answer.items.iter().filter(|i| f.meets(&i.mbr)).filter(near).collect()
                }
                None => answer.items.iter().filter(near).collect(),
            };
        }
        let camera = match (look, self.params.query.camera) {
            (Some(look), cam) => Some(super::Camera { look, ..cam.unwrap_or_default() }),
            (None, cam) => cam,
        };
        match camera.filter(|c| c.check().is_ok()) {
            Some(cam) => {
                let f = cam.frustum(at);
                answer.items.iter().filter(|i| f.meets(&i.mbr)).collect()
            }
            None => answer.items.iter().collect(),
        }
    }

    /// The fidelity of what the session draws from `view` (the cell's answer culled as
    /// [`Session::frame_items`] culls it from `view.eye` looking along `view.look`) against
    /// full detail from the same view, both shaded. For a fair number the view should lie
    /// inside the session's own frustum (REVIEW: `fov_deg` both ways), else the objects it
    /// culled at the image's edges count as differences.
    pub fn fidelity(&self, renderer: &Renderer, view: &View) -> Result<Fidelity> {
        let image = self.draw(renderer, view)?;
        let full = renderer.render_full(self.db, view, ColorMode::Shaded)?;
        Ok(fidelity::compare(&image, &full))
    }

    /// What the session draws from `view`, shaded: the cell's answer culled as
    /// [`Session::frame_items`] culls it from `view.eye` looking along `view.look`. Errors
    /// before the first step.
    pub fn draw(&self, renderer: &Renderer, view: &View) -> Result<Image> {
        let Some(a) = &self.answer else {
            return Err(Error::bad_param("fidelity", "the session has taken no step yet"));
        };
        let items: Vec<Item> = self.frame_items(view.eye, Some(view.look)).into_iter().cloned().collect();
        let drawn = Answer {
            at: a.at,
            cell: a.cell,
            cell_id: a.cell_id,
            mode: a.mode,
            eta: a.eta,
            layout: a.layout.clone(),
            items,
            stats: a.stats,
            warnings: Vec::new(),
        };
        renderer.render_answer(self.db, &drawn, view, ColorMode::Shaded)
    }

    /// The current cell's answer.
    pub fn answer(&self) -> Option<&Answer> {
        self.answer.as_ref()
    }

    /// Bytes of LOD geometry resident now.
    pub fn resident_bytes(&self) -> u64 {
        self.resident_bytes
    }

    /// The LOD records resident now, by offset in `geometry.blob`, with their sizes.
    pub fn resident(&self) -> impl Iterator<Item = (u64, usize)> + '_ {
        self.resident.iter().map(|(&k, r)| (k, r.bytes.len()))
    }

    /// Loads what the new cell's answer needs and is not resident; evicts what it does not
    /// need, least recently used first, while the budget would be exceeded.
    fn delta_load(&mut self, step: &mut Step) -> Result<()> {
        let answer = self.answer.as_ref().expect("a flip sets the answer");
        let mut needed: Vec<(u64, crate::db::catalog::LodRef)> =
            answer.items.iter().map(|i| (i.lod_ref.offset, i.lod_ref)).collect();
        needed.sort_unstable_by_key(|n| n.0);
        needed.dedup_by_key(|n| n.0);
        let is_needed = |k: &u64| needed.binary_search_by_key(k, |n| n.0).is_ok();
        for (k, _) in &needed {
            if let Some(r) = self.resident.get_mut(k) {
                r.last_used = self.steps;
            }
        }
        let incoming: u64 =
            needed.iter().filter(|(k, _)| !self.resident.contains_key(k)).map(|(_, l)| u64::from(l.len)).sum();
        if let Some(budget) = self.params.resident_bytes {
            let mut spare: Vec<(u64, u64)> =
                self.resident.iter().filter(|(k, _)| !is_needed(k)).map(|(&k, r)| (r.last_used, k)).collect();
            spare.sort_unstable();
            for (_, k) in spare {
                if self.resident_bytes + incoming <= budget {
                    break;
                }
                let r = self.resident.remove(&k).expect("listed as resident");
                self.resident_bytes -= r.bytes.len() as u64;
                step.evicted += 1;
                step.evicted_bytes += r.bytes.len() as u64;
            }
            step.over_budget = self.resident_bytes + incoming > budget;
        }
        for (k, lod) in needed {
            if self.resident.contains_key(&k) {
                continue;
            }
            let bytes: Box<[u8]> = self.db.lod_bytes(&lod)?.into();
            step.loaded += 1;
            step.loaded_bytes += bytes.len() as u64;
            self.resident_bytes += bytes.len() as u64;
            self.resident.insert(k, Resident { bytes, last_used: self.steps });
        }
        Ok(())
    }

    /// Runs the query of the cell [`PREFETCH_STEPS`] ahead along the motion (if that is another
    /// cell inside the grid), so its pages are in the cache on arrival; returns pages read.
    fn prefetch(&mut self, at: Vec3, cell_id: u32) -> Result<u64> {
        let Some(last) = self.last_at else { return Ok(0) };
        let ahead = at + (at - last) * PREFETCH_STEPS;
        let Ok((_, ahead_id)) = self.db.locate(ahead) else { return Ok(0) };
        if ahead_id == cell_id {
            return Ok(0);
        }
        let pages = self.db.query_with(&mut self.access, ahead, &self.params.query, false)?.stats.pages_read;
        // Back to the current cell (free where the layout keeps no per-cell state).
        self.access.flip(cell_id)?;
        Ok(pages)
    }
}
