//! Walkthroughs (thesis §5.8.5): a session follows a path of viewpoints. While the viewpoint
//! stays in a cell nothing is read again; on leaving it the session flips to the new cell's
//! V-data and asks the tree again through its page cache. *Delta loading*: a LOD already
//! resident is not loaded again (instances share their base mesh's records, so one load serves
//! them all); LODs the new cell no longer needs are evicted, oldest first, while resident
//! geometry is over its byte budget.
//!
//! What a session asks on each step is its [`CellMethod`]: VISUAL ([`Database::session`]) asks
//! the HDoV-tree on each cell flip; REVIEW, the spatial baseline ([`crate::review`],
//! `Database::review_session`), searches the R-tree with disk cells. Both share the delta
//! loading, resident geometry and [`Step`]s, so walks compare 1:1.

use std::time::Instant;

use glam::Vec3;
use lru::LruCache;
use serde::{Deserialize, Serialize};

use super::{Answer, Camera, Item, QueryParams};
use crate::db::Database;
use crate::db::access::Access;
use crate::error::{Error, Param, Result};
use crate::format::catalog::LodRef;
use hdov_storage::PolicyKind;

/// Steps ahead along the current motion that prefetch looks (one step is one path point).
pub const PREFETCH_STEPS: f32 = 3.0;

/// How a session runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SessionParams {
    /// The query each cell flip runs (its camera's look is replaced per step when a step
    /// gives one).
    pub query: QueryParams,
    /// The tree-page and V-page cache's policy.
    pub cache: PolicyKind,
    /// Cache capacity in pages and in bytes (`None`: unbounded).
    pub cache_pages: Option<usize>,
    /// Cache capacity in bytes (`None`: unbounded).
    pub cache_bytes: Option<u64>,
    /// Most bytes of LOD geometry kept resident (`None`: unbounded).
    pub resident_bytes: Option<u64>,
    /// Query the cell [`PREFETCH_STEPS`] ahead along the motion, warming the cache.
    pub prefetch: bool,
}

impl Default for SessionParams {
    fn default() -> Self {
        Self {
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
    /// The step's index along the walk.
    pub step: u64,
    /// The viewpoint.
    pub at: [f32; 3],
    /// The viewing cell `[i, j, k]` holding it (REVIEW: `[0, 0, 0]` outside the grid).
    pub cell: [u32; 3],
    /// The viewpoint entered another cell, and the tree was asked again.
    pub flipped: bool,
    /// LOD records loaded, and their bytes (heavy-weight I/O).
    pub loaded: u64,
    /// Bytes of the records loaded.
    pub loaded_bytes: u64,
    /// LOD records evicted, and their bytes.
    pub evicted: u64,
    /// Bytes of the records evicted.
    pub evicted_bytes: u64,
    /// Geometry resident after the step.
    pub resident: u64,
    /// Bytes of the geometry resident after the step.
    pub resident_bytes: u64,
    /// Light-weight pages read (tree, V-index, V-pages) by this step's query.
    pub pages_read: u64,
    /// Page requests served without a read (the cache, or the reader's buffer of the page
    /// just read), and those read from the file.
    pub hits: u64,
    /// Page requests read from the file.
    pub misses: u64,
    /// Of those, the requests that reached the page cache (past the read buffers), and those
    /// it served: the cache's own hit rate is `cache_hits / cache_requests`.
    pub cache_requests: u64,
    /// Of those, the requests the cache served.
    pub cache_hits: u64,
    /// Pages prefetch read for the cell ahead.
    pub prefetch_pages: u64,
    /// Items and faces drawn this step (culled to the step's view when it has a look).
    pub items: u64,
    /// Faces drawn this step.
    pub faces: u64,
    /// The cell's answer needs more geometry than the resident budget holds.
    pub over_budget: bool,
    /// Time the step took, in microseconds.
    pub micros: u64,
    /// With `hdov walk --fidelity`: PSNR in dB of the drawn answer against full detail from
    /// the step's camera (`null` in JSON when the images are equal), and the share of pixels
    /// whose coverage differs (`render::fidelity`; a session measures none itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psnr: Option<f64>,
    /// With `hdov walk --fidelity`: the share of pixels whose coverage differs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage_diff: Option<f64>,
}

/// How a session finds what to draw as the viewer moves: VISUAL's HDoV-tree query per viewing
/// cell ([`Visual`]) or REVIEW's disk-cell search (`crate::review`). The session owns the page
/// reader, the current answer and the resident geometry; the method decides when to ask again,
/// what to ask, and what of the answer one frame draws.
pub(crate) trait CellMethod {
    /// Whether the viewer at `at` (looking along `look`, `None`: any direction) has left what
    /// `current` covers; if so, the new answer to keep resident, read through `access` (which
    /// knows its database), and the
    /// step's `cell` set. Errors (a viewpoint outside the grid, ...) leave the session as it was.
    fn flip(
        &mut self,
        access: &mut Access,
        at: Vec3,
        look: Option<Vec3>,
        current: Option<&Answer>,
        step: &mut Step,
    ) -> Result<Option<Answer>>;

    /// After a flip's delta loading: `resident(offset)` tells whether a LOD record stayed resident.
    fn loaded(&mut self, _resident: &dyn Fn(u64) -> bool) {}

    /// Reads ahead for where the viewer moving from `last` to `at` goes next, warming the page
    /// cache; `current` is the answer of where it is. Returns pages read.
    fn prefetch(
        &mut self,
        access: &mut Access,
        at: Vec3,
        last: Vec3,
        look: Option<Vec3>,
        current: &Answer,
    ) -> Result<u64>;

    /// What of `answer` one frame from `at`, looking along `look`, draws.
    fn frame<'a>(&self, answer: &'a Answer, at: Vec3, look: Option<Vec3>) -> Vec<&'a Item>;
}

/// VISUAL: on each cell flip, the HDoV-tree query of the session's [`QueryParams`] for the
/// whole cell; a frame draws the answer culled to its camera.
pub(super) struct Visual {
    pub query: QueryParams,
}

impl CellMethod for Visual {
    fn flip(
        &mut self,
        access: &mut Access,
        at: Vec3,
        _look: Option<Vec3>,
        current: Option<&Answer>,
        step: &mut Step,
    ) -> Result<Option<Answer>> {
        let db = access.db();
        let (cell, cell_id) = db.locate(at)?;
        step.cell = cell;
        if current.is_some_and(|a| a.cell_id == cell_id) {
            return Ok(None);
        }
        // The cell's whole answer (not culled): what a walkthrough keeps resident.
        db.query_with(access, at, &self.query, false).map(Some)
    }

    /// The query of the cell [`PREFETCH_STEPS`] ahead along the motion (if that is another
    /// cell inside the grid), so that its pages are in the cache on arrival.
    fn prefetch(
        &mut self,
        access: &mut Access,
        at: Vec3,
        last: Vec3,
        _look: Option<Vec3>,
        current: &Answer,
    ) -> Result<u64> {
        let db = access.db();
        let ahead = at + (at - last) * PREFETCH_STEPS;
        let Ok((_, ahead_id)) = db.locate(ahead) else { return Ok(0) };
        if ahead_id == current.cell_id {
            return Ok(0);
        }
        let pages = db.query_with(access, ahead, &self.query, false)?.stats.pages_read;
        // Back to the current cell (free where the layout keeps no per-cell state).
        access.flip(current.cell_id)?;
        Ok(pages)
    }

    fn frame<'a>(&self, answer: &'a Answer, at: Vec3, look: Option<Vec3>) -> Vec<&'a Item> {
        let camera = look.map(|look| Camera { look, ..self.query.camera.unwrap_or_default() });
        match camera.filter(|c| c.check().is_ok()) {
            Some(cam) => {
                let f = cam.frustum(at);
                answer.items.iter().filter(|i| f.meets(&i.mbr)).collect()
            }
            None => answer.items.iter().collect(),
        }
    }
}

/// A walkthrough over one database. See the module documentation.
pub struct Session<'db> {
    db: &'db Database,
    params: SessionParams,
    access: Access<'db>,
    method: Box<dyn CellMethod + 'db>,
    /// The current cell's answer, unculled: what stays resident while the viewer is in it.
    answer: Option<Answer>,
    last_at: Option<Vec3>,
    /// LOD records by offset in `geometry.blob`, least recently needed first.
    resident: LruCache<u64, Box<[u8]>>,
    resident_bytes: u64,
    steps: u64,
}

/// Refuses a session camera that cannot be used.
pub(crate) fn check_camera(params: &SessionParams) -> Result<()> {
    match &params.query.camera {
        Some(cam) => cam.check().map_err(|r| Error::bad_param(Param::Camera, r)),
        None => Ok(()),
    }
}

impl<'db> Session<'db> {
    /// A session reading through `access` and finding what to load by `method`.
    pub(crate) fn new(
        db: &'db Database,
        params: &SessionParams,
        access: Access<'db>,
        method: Box<dyn CellMethod + 'db>,
    ) -> Session<'db> {
        Session {
            db,
            params: *params,
            access,
            method,
            answer: None,
            last_at: None,
            resident: LruCache::unbounded(),
            resident_bytes: 0,
            steps: 0,
        }
    }

    /// Moves the viewer to `at`, looking along `look` (or the session camera's direction).
    /// Errors as [`Database::query`] does (a viewpoint outside the grid, ...), and leaves the
    /// session as it was.
    pub fn step(&mut self, at: Vec3, look: Option<Vec3>) -> Result<Step> {
        let start = Instant::now();
        let look = self.look(look);
        let mut step = Step { step: self.steps, at: at.to_array(), ..Default::default() };
        if let Some(mut answer) = self.method.flip(&mut self.access, at, look, self.answer.as_ref(), &mut step)? {
            self.prefer_resident(&mut answer);
            step.flipped = true;
            step.pages_read = answer.stats.pages_read;
            step.hits = answer.stats.page_hits;
            step.misses = answer.stats.pages_requested - answer.stats.page_hits;
            let cache = self.access.cache_stats();
            (step.cache_requests, step.cache_hits) = (cache.requests, cache.hits);
            self.answer = Some(answer);
            self.delta_load(&mut step)?;
            let resident = &self.resident;
            self.method.loaded(&|offset| resident.contains(&offset));
        }
        if self.params.prefetch
            && let (Some(last), Some(answer)) = (self.last_at, &self.answer)
        {
            step.prefetch_pages = self.method.prefetch(&mut self.access, at, last, look, answer)?;
        }
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

    /// The direction the viewer looks: the step's, else the session camera's.
    fn look(&self, look: Option<Vec3>) -> Option<Vec3> {
        look.or(self.params.query.camera.map(|c| c.look))
    }

    /// The items to draw from `at` looking along `look` (else the session camera's direction):
    /// the current answer culled to the view as the session's method culls it. VISUAL culls to
    /// the session camera's frustum; REVIEW to its own frustum (`fov_deg` both ways) and to the
    /// eyesight.
    pub fn frame_items(&self, at: Vec3, look: Option<Vec3>) -> Vec<&Item> {
        match &self.answer {
            Some(answer) => self.method.frame(answer, at, self.look(look)),
            None => Vec::new(),
        }
    }

    /// The database the session walks.
    pub fn database(&self) -> &'db Database {
        self.db
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
        self.resident.iter().map(|(&k, bytes)| (k, bytes.len()))
    }

    /// Draws an item at a finer level that is resident already rather than load its own: a finer
    /// level's error is smaller, so the answer's bound still holds, and the walk saves the load
    /// (the coarsest such level; faces grow a little). A walk's answers change levels from cell to
    /// cell (a stopped subtree's, and what the η rule relaxes); without this each change is a
    /// load.
    fn prefer_resident(&self, answer: &mut Answer) {
        let catalog = self.db.catalog();
        for item in &mut answer.items {
            if self.resident.contains(&item.lod_ref.offset) {
                continue;
            }
            let chain = match item.kind {
                super::ItemKind::Object => catalog.object_lods(item.id),
                super::ItemKind::Node => &catalog.node_lods[item.id as usize],
            };
            if let Some(l) = (0..item.lod as usize).rev().find(|&l| self.resident.contains(&chain[l].offset)) {
                item.lod = l as u32;
                item.lod_ref = chain[l];
                item.faces = chain[l].faces;
            }
        }
        answer.stats.faces = answer.items.iter().map(|i| u64::from(i.faces)).sum();
    }

    /// Loads what the new cell's answer needs and is not resident; evicts what it does not
    /// need, least recently used first, while the budget would be exceeded. A cell's records
    /// count as used in offset order, so the eviction order is (last flip that needed the
    /// record, offset), whatever order the answer lists them in.
    fn delta_load(&mut self, step: &mut Step) -> Result<()> {
        let answer = self.answer.as_ref().expect("a flip sets the answer");
        let mut needed: Vec<(u64, LodRef)> = answer.items.iter().map(|i| (i.lod_ref.offset, i.lod_ref)).collect();
        needed.sort_unstable_by_key(|n| n.0);
        needed.dedup_by_key(|n| n.0);
        let is_needed = |k: &u64| needed.binary_search_by_key(k, |n| n.0).is_ok();
        // The needed records become the most recent, so the least recent ones are spare.
        for (k, _) in &needed {
            self.resident.promote(k);
        }
        let incoming: u64 =
            needed.iter().filter(|(k, _)| !self.resident.contains(k)).map(|(_, l)| u64::from(l.len)).sum();
        if let Some(budget) = self.params.resident_bytes {
            while self.resident_bytes + incoming > budget {
                match self.resident.peek_lru() {
                    Some((k, _)) if !is_needed(k) => {
                        let (_, bytes) = self.resident.pop_lru().expect("peeked");
                        self.resident_bytes -= bytes.len() as u64;
                        step.evicted += 1;
                        step.evicted_bytes += bytes.len() as u64;
                    }
                    _ => break, // only needed records are left
                }
            }
            step.over_budget = self.resident_bytes + incoming > budget;
        }
        for &(k, lod) in &needed {
            if self.resident.contains(&k) {
                continue;
            }
            let bytes: Box<[u8]> = self.db.lod_bytes(&lod)?.into();
            step.loaded += 1;
            step.loaded_bytes += bytes.len() as u64;
            self.resident_bytes += bytes.len() as u64;
            self.resident.put(k, bytes);
        }
        for (k, _) in &needed {
            self.resident.promote(k);
        }
        Ok(())
    }
}
