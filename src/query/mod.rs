//! The query engine: what is visible from a point, at which detail, and what it cost to find out.
//!
//! - [`Database::query`]: one point query in one of five [`Mode`]s — the HDoV-tree's threshold
//!   traversal (thesis fig. 5.4), the naive cell → visible-objects list (§5.8.4), a polygon
//!   budget (§6.1.2), a visibility-modulated screen-space error (seeds 000/001), and plain
//!   frustum culling;
//! - [`Session`]: a walkthrough, cell flips, delta loading of LODs and a page cache;
//! - [`Camera`] ([`crate::camera`]): the view frustum that every mode culls its answer to when
//!   given a camera.
//!
//! Every tree page and V-page is read through the database's page access (`db::access`),
//! which counts what each query reads per file.

mod cell;
mod levels;
mod select;
pub mod session;
mod traverse;

pub use cell::CellVisibility;
pub use levels::visibility_bias;

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use glam::Vec3;
use serde::{Deserialize, Serialize};

pub use crate::camera::Camera;
use crate::db::Database;
use crate::db::access::{Access, PageIo};
use crate::error::{Error, Param, Result};
use crate::format::by_name::serde_by_name;
use crate::format::catalog::LodRef;
use crate::geom::Aabb;
use hdov_storage::LayoutKind;
use hdov_storage::names::quoted;
pub(crate) use session::CellMethod;
pub use session::{Session, SessionParams, Step};

/// DoV above which an object is drawn at full detail (thesis eq. 5.6): an object whose box does
/// not hold the viewpoint covers at most half the sphere.
pub const MAX_DOV: f64 = 0.5;

/// The DoV threshold η a query uses unless told otherwise, chosen from the speed/fidelity
/// chart (docs/query.md, "The η rule"): on the default city's street views it reads 41 % of
/// naive's pages and draws 55 % of its faces at 40.8 dB PSNR against full detail, where larger
/// values change nothing more.
pub const DEFAULT_ETA: f64 = 3e-2;

/// How a query chooses what to return.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// The HDoV-tree traversal: hidden subtrees skipped, subtrees with DoV ≤ η returned as one
    /// internal LOD where that draws fewer faces than their visible objects (eq. 5.3–5.6), the
    /// objects of leaves with DoV ≤ η drawn within the bound relaxed by visibility.
    #[default]
    Threshold,
    /// Every object visible from the cell at its leaf LOD, from the leaves' V-pages alone.
    Naive,
    /// Refine by descending DoV within a budget of faces (thesis fig. 6.2).
    Budget,
    /// Stop refining where the visibility-weighted screen-space error is at most τ pixels.
    Vmsse,
    /// Every object in the view frustum at full detail, no visibility (the CONV baseline).
    Frustum,
}

impl Mode {
    /// Every mode.
    pub const ALL: [Mode; 5] = [Mode::Threshold, Mode::Naive, Mode::Budget, Mode::Vmsse, Mode::Frustum];

    /// The mode's name, as `--mode` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Threshold => "threshold",
            Mode::Naive => "naive",
            Mode::Budget => "budget",
            Mode::Vmsse => "vmsse",
            Mode::Frustum => "frustum",
        }
    }
}

hdov_storage::named!(Mode, "mode");
hdov_storage::by_names!(Mode);
serde_by_name!(Mode);

/// How a query picks the level of detail of each object it returns and of each subtree it
/// stops at (docs/query.md, "Levels of detail").
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LodRule {
    /// Thesis eq. 5.5 and 5.6: interpolate in faces by DoV (an object's DoV / [`MAX_DOV`], a
    /// stopped subtree's DoV / η). Cheap, but a building filling a quarter of the view still
    /// comes back at a middle level.
    Dov,
    /// The coarsest level whose simplification error, seen from the nearest point of the
    /// query's cell, is at most `pixels` pixels of the camera's image (of [`Camera::default`]
    /// without one). The answer then holds for every viewpoint of the cell.
    ScreenError {
        /// Most pixels of screen error.
        pixels: f64,
    },
}

impl Default for LodRule {
    fn default() -> Self {
        LodRule::ScreenError { pixels: 0.5 }
    }
}

impl fmt::Display for LodRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LodRule::Dov => f.write_str("dov"),
            LodRule::ScreenError { pixels } => write!(f, "screen:{pixels}"),
        }
    }
}

impl FromStr for LodRule {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<LodRule, String> {
        let bad = || format!("unknown LOD rule {} (dov, screen or screen:PIXELS)", quoted(s));
        match s.split_once(':') {
            None if s == "dov" => Ok(LodRule::Dov),
            None if s == "screen" => Ok(LodRule::default()),
            Some(("screen", px)) => match px.parse::<f64>() {
                Ok(pixels) if pixels.is_finite() && pixels >= 0.0 => Ok(LodRule::ScreenError { pixels }),
                _ => Err(format!("LOD rule {}: pixels must be a number ≥ 0", quoted(s))),
            },
            _ => Err(bad()),
        }
    }
}

/// What a query asks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QueryParams {
    /// How the query chooses what to return.
    pub mode: Mode,
    /// The DoV threshold η of threshold mode, in [0, 1]; 0 returns the naive answer.
    pub eta: f64,
    /// Faces the budget mode may return.
    pub budget: u64,
    /// Screen-space error bound of vmsse mode, in pixels of the camera's image.
    pub tau: f64,
    /// How threshold, naive and budget modes pick levels (vmsse has its own; budget coarsens to fit).
    pub lod_rule: LodRule,
    /// With a camera, the answer is culled to its view frustum (what is drawn this frame);
    /// without, it is everything the cell may see in every direction. Vmsse mode and the
    /// screen-error LOD rule take its image size and field of view (or [`Camera::default`]'s).
    pub camera: Option<Camera>,
    /// The V-page layout to read (default: indexed-vertical if the database has it).
    pub layout: Option<LayoutKind>,
}

impl Default for QueryParams {
    fn default() -> Self {
        Self {
            mode: Mode::Threshold,
            eta: DEFAULT_ETA,
            budget: 100_000,
            tau: 1.0,
            lod_rule: LodRule::default(),
            camera: None,
            layout: None,
        }
    }
}

/// An object or a tree node (drawn as its internal LOD).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ItemKind {
    /// An object of the scene at one of its leaf LODs.
    Object,
    /// A tree node drawn as one of its internal LODs.
    Node,
}

impl ItemKind {
    /// Both kinds.
    pub const ALL: [ItemKind; 2] = [ItemKind::Object, ItemKind::Node];

    /// The kind's name in answers.
    pub fn name(self) -> &'static str {
        match self {
            ItemKind::Object => "object",
            ItemKind::Node => "node",
        }
    }
}

hdov_storage::named!(ItemKind, "item kind");
hdov_storage::by_names!(ItemKind);
serde_by_name!(ItemKind);

/// One thing to draw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Item {
    /// Object or node.
    pub kind: ItemKind,
    /// Object index or node id.
    pub id: u32,
    /// The object's name (of the scene file's object), or `node N`.
    pub name: std::sync::Arc<str>,
    /// Which part of the file's object `name` this is, where the build cut it
    /// (`--objects geometry`); absent for a whole object and a node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<u32>,
    /// LOD level, 0 = finest.
    pub lod: u32,
    /// Faces at the chosen level.
    pub faces: u32,
    /// DoV from the query's cell (0 in frustum mode, which measures none).
    pub dov: f32,
    /// World-space bounds.
    pub mbr: Aabb,
    /// Where the LOD's geometry lives in `geometry.blob` ([`Database::lod_mesh`] loads it).
    pub lod_ref: LodRef,
}

impl Item {
    /// The identity of the geometry this item draws: (kind, id, level).
    pub fn key(&self) -> (ItemKind, u32, u32) {
        (self.kind, self.id, self.lod)
    }
}

/// Pages a query read, per file, and its other costs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct QueryStats {
    /// Pages read from `tree.pages`.
    pub tree_pages: u64,
    /// Pages read from the layout's index file (vertical layouts; 0 for horizontal).
    pub vindex_pages: u64,
    /// Pages read from the layout's V-page file.
    pub vpage_pages: u64,
    /// All light-weight pages read: tree + index + V-pages.
    pub pages_read: u64,
    /// Page requests, and those served without a read (the reader's buffer or a session's
    /// cache held the page): `pages_read = pages_requested − page_hits`.
    pub pages_requested: u64,
    /// Requests served without a read.
    pub page_hits: u64,
    /// Tree nodes whose page the query read.
    pub nodes_visited: u64,
    /// Faces of all items.
    pub faces: u64,
    /// Heavy-weight I/O: bytes of geometry loaded (a point query loads none; a session does).
    pub geometry_bytes: u64,
    /// Budget mode: the budget could not be kept (the coarsest LOD alone exceeds it).
    pub over_budget: bool,
    /// Time the query took, in microseconds.
    pub micros: u64,
}

impl QueryStats {
    /// The costs of a query that read `io`, entered `nodes_visited` nodes and returned `items`,
    /// since `start`.
    pub(crate) fn new(io: PageIo, nodes_visited: u64, items: &[Item], over_budget: bool, start: Instant) -> Self {
        QueryStats {
            tree_pages: io.tree,
            vindex_pages: io.vindex,
            vpage_pages: io.vpages,
            pages_read: io.tree + io.vindex + io.vpages,
            pages_requested: io.requested,
            page_hits: io.hits,
            nodes_visited,
            faces: items.iter().map(|i| u64::from(i.faces)).sum(),
            geometry_bytes: 0,
            over_budget,
            micros: start.elapsed().as_micros() as u64,
        }
    }
}

/// What a query returned.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    /// The viewpoint.
    pub at: [f32; 3],
    /// The cell `[i, j, k]` holding the viewpoint, and its id.
    pub cell: [u32; 3],
    /// The id of the cell.
    pub cell_id: u32,
    /// The mode that answered.
    pub mode: Mode,
    /// The DoV threshold η asked with.
    pub eta: f64,
    /// The V-page layout read (`null` in JSON for REVIEW, which reads the tree alone).
    #[serde(with = "crate::format::by_name::optional")]
    pub layout: Option<LayoutKind>,
    /// What to draw.
    pub items: Vec<Item>,
    /// What finding it cost.
    pub stats: QueryStats,
    /// E.g. an η below the database's resolution floor.
    pub warnings: Vec<String>,
}

impl Answer {
    /// The answer from `at` in `cell` (`[i, j, k]` and id) to `params`, read through `layout`:
    /// the one place answers are made, by queries and by REVIEW's searches.
    pub(crate) fn new(
        at: Vec3,
        (cell, cell_id): ([u32; 3], u32),
        params: &QueryParams,
        layout: Option<LayoutKind>,
        items: Vec<Item>,
        stats: QueryStats,
        warnings: Vec<String>,
    ) -> Answer {
        Answer { at: at.to_array(), cell, cell_id, mode: params.mode, eta: params.eta, layout, items, stats, warnings }
    }
}

impl Database {
    /// Starts a VISUAL walkthrough session. Checks the parameters; reads nothing yet.
    pub fn session(&self, params: &SessionParams) -> Result<Session<'_>> {
        session::check_camera(params)?;
        let limits = hdov_storage::CacheLimits { pages: params.cache_pages, bytes: params.cache_bytes };
        let access = Access::cached(self, params.query.layout, limits, params.cache)?;
        Ok(Session::new(self, params, access, Box::new(session::Visual { query: params.query })))
    }

    /// Answers a point query from `at`.
    ///
    /// Errors (one line, naming the parameter): `at` not finite or outside the grid, η outside
    /// [0, 1], a bad camera, a layout the database lacks, a database without visibility. An η
    /// below the resolution floor (one centre texel, docs/dov.md, "The measurement") is answered with a warning.
    /// Costs the pages it reads (counted in [`Answer::stats`]): a cell flip, then one tree page
    /// and one V-page per node the traversal enters.
    pub fn query(&self, at: Vec3, params: &QueryParams) -> Result<Answer> {
        let mut access = Access::open(self, params.layout)?;
        self.query_with(&mut access, at, params, true)
    }

    /// A query through an existing reader (a session's, with its cache). With `cull` false the
    /// camera only sets the screen-error scale: the answer is the whole cell's.
    pub(crate) fn query_with(&self, access: &mut Access, at: Vec3, params: &QueryParams, cull: bool) -> Result<Answer> {
        let start = Instant::now();
        let warnings = self.check_query(params)?;
        let (cell, cell_id) = self.locate(at)?;
        access.reset_io();
        access.flip(cell_id)?;
        // Where a viewer of this view cell can be: the box of its places (its lattice cell's box
        // where viewers stand anywhere in it).
        let cell_box = self.grid().map_or(Aabb::new(at, at), |g| g.view_cell(cell_id as usize).places_box());
        let mut out = traverse::run(self, access, at, cell_box, params, cull)?;
        if let Some(cam) = params.camera.as_ref().filter(|_| cull) {
            let frustum = cam.frustum(at);
            out.items.retain(|i| frustum.meets(&i.mbr));
        }
        let stats = QueryStats::new(access.io(), out.nodes_visited, &out.items, out.over_budget, start);
        Ok(Answer::new(at, (cell, cell_id), params, access.layout_kind(), out.items, stats, warnings))
    }

    /// The column-major matrix an item's level is drawn under: its object's model matrix, or the
    /// identity for a node's internal LOD (stored in world space).
    pub fn item_transform(&self, item: &Item) -> glam::Mat4 {
        self.transform_of(item.kind, item.id)
    }

    /// [`Database::item_transform`] by kind and id.
    pub(crate) fn transform_of(&self, kind: ItemKind, id: u32) -> glam::Mat4 {
        match kind {
            ItemKind::Object => self.object_transform(id).unwrap_or(glam::Mat4::IDENTITY),
            ItemKind::Node => glam::Mat4::IDENTITY,
        }
    }

    /// The view cell holding `at` (points on an inner cell border belong to the upper cell; in
    /// a cell that a wall cuts, the part on `at`'s side) and its lattice cell's coordinates;
    /// refused outside the grid, in a cell that is not a view cell, and where in its cell no
    /// viewer stands (an eighth of a cell's footprint at a time: inside a wall).
    pub fn locate(&self, at: Vec3) -> Result<([u32; 3], u32)> {
        let grid =
            self.grid().ok_or_else(|| Error::bad_param(Param::At, format!("{} holds no grid", self.dir().display())))?;
        if !at.is_finite() {
            return Err(Error::bad_param(Param::At, format!("{:?} is not a finite point", at.to_array())));
        }
        let cell = grid.cell_of(at).ok_or_else(|| {
            Error::bad_param(Param::At, format!("{:?} lies outside the grid {:?}", at.to_array(), grid.region.to_array()))
        })?;
        let id = grid.cell_id(cell);
        if !grid.is_present(id) {
            let reason = format!(
                "{:?} is in no view cell: this database has cells only where a viewer can stand (eye height above a floor, in empty space), and cell {cell:?} is not one",
                at.to_array()
            );
            return Err(Error::bad_param(Param::At, reason));
        }
        let Some(id) = grid.standing_cell(id, cell, at) else {
            let reason = format!(
                "{:?} is where no viewer stands in cell {cell:?}: inside a wall or a solid, or with no floor an eye height below",
                at.to_array()
            );
            return Err(Error::bad_param(Param::At, reason));
        };
        Ok((cell, id as u32))
    }

    /// Checks the query's parameters; returns its warnings.
    fn check_query(&self, p: &QueryParams) -> Result<Vec<String>> {
        let mut warnings = Vec::new();
        if !(0.0..=1.0).contains(&p.eta) {
            return Err(Error::bad_param(Param::Eta, format!("{} is not in [0, 1]", p.eta)));
        }
        if !(p.tau.is_finite() && p.tau > 0.0) {
            return Err(Error::bad_param(Param::Tau, format!("{} pixels must be finite and > 0", p.tau)));
        }
        if let Some(cam) = &p.camera {
            cam.check().map_err(|r| Error::bad_param(Param::Camera, r))?;
        }
        if let Some(r) = self.manifest().build.visibility.as_ref().map(|v| v.resolution) {
            // One face-centre texel's share of the sphere (CubeMap::texel_floor, without the map).
            let floor = (2.0 / f64::from(r)).powi(2) / (4.0 * std::f64::consts::PI);
            if p.mode == Mode::Threshold && p.eta > 0.0 && p.eta < floor {
                warnings.push(format!(
                    "eta {} is below the resolution floor {floor:.2e} of R = {r}: it acts as 0 (DoVs smaller than one texel are noise)",
                    p.eta
                ));
            }
        }
        Ok(warnings)
    }
}
