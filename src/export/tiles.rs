//! The HDoV-tree as an OGC 3D Tiles 1.1 tileset, with each view cell's visibility beside it as
//! small static files (docs/format.md, "3D Tiles"; decisions 120 and 131).
//!
//! - A node's internal levels are drawn in *slices*: each level's triangles grouped by the
//!   entries they stand for ([`super::slices`]). Each entry has a chain of its slices from the
//!   node's coarsest level to its finest, whose last tile holds the entry's own tiles; triangles
//!   that stand for several entries form chains of their own. A client that leaves out the
//!   entries a cell cannot see so leaves out their share of every coarse level, not only whole
//!   hidden nodes. An object's leaf levels are a chain too, ending in full detail (geometric
//!   error 0). `refine` is `REPLACE` throughout; a tile's geometric error is its level's recorded
//!   error, which the HLOD contract keeps at or above its children's, and in a chain each tile's
//!   error is strictly above the next one's (levels coarser than the tile above, or claiming no
//!   more error than a finer one, are left out).
//! - Every node below the root is a tileset of its own (`subtrees/n{node}.json`, an external
//!   tileset), named by a tile that clients refine through: a client fetches the tiles of a
//!   subtree only when it refines into it, so the subtrees a cell cannot see cost nothing.
//! - Content is written once (`content/n{node}-{level}-{slice}.glb`, `content/m{mesh}-{level}.glb`):
//!   every instance of a base mesh is a tile of its own that points at the mesh's files, under
//!   its model matrix as the tile's `transform`.
//! - Coordinates stay in the scene's frame, turned to 3D Tiles' z-up as glTF content is (glTF is
//!   y-up; a client turns content by +90° about x), under an optional root transform.
//! - `visibility/index.json` holds the grid and the matrix from the tileset's frame back to the
//!   scene's; `visibility/cells/{id}.bin` each cell's [`CellVisibility`]: what it may see with
//!   DoV, and where the threshold query stops refining.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use serde_json::{Value, json};

use std::sync::Arc;

use super::slices::{Slice, slice_mesh, slices};
use super::mesh_glb;
use crate::db::Database;
use crate::error::{Error, Param, Result};
use crate::format::catalog::LodRef;
use crate::format::tree_page::NodePage;
use crate::geom::{Aabb, max_scale};
use crate::grid::ViewGrid;
use crate::progress::Report;
use crate::query::{CellVisibility, QueryParams};
use crate::scene::Mesh;
use crate::progress::Progress;

/// The tileset, in the directory the export writes.
pub const TILESET_FILE: &str = "tileset.json";
/// The cells' visibility index, in the directory the export writes.
pub const VISIBILITY_INDEX: &str = "visibility/index.json";
/// The cell files, relative to the index (`{cell}` is the view cell's id).
pub const CELL_FILES: &str = "cells/{cell}.bin";

/// The path of cell `cell`'s visibility file in the export.
pub fn cell_file(cell: u32) -> String {
    format!("visibility/{}", CELL_FILES.replace("{cell}", &cell.to_string()))
}

/// glTF's y-up turned to 3D Tiles' z-up, as every 3D Tiles client turns glTF content:
/// (x, y, z) → (x, −z, y).
pub const Y_UP_TO_Z_UP: Mat4 = Mat4::from_cols(Vec4::X, Vec4::Z, Vec4::NEG_Y, Vec4::W);

/// A tileset of a database, ready to write or serve.
pub struct Tileset {
    /// `tileset.json`.
    pub json: Value,
    /// The subtrees' tilesets (external tilesets that `tileset.json` and each other name),
    /// serialised, by path in the export.
    pub subtrees: BTreeMap<String, Vec<u8>>,
    /// Each content file's path in the export and what it holds.
    pub contents: BTreeMap<String, TileContent>,
    /// `visibility/index.json`; `None` for a database without visibility.
    pub index: Option<Value>,
    /// Tiles in the tileset.
    pub tiles: usize,
}

/// What a content file holds.
#[derive(Clone, Debug, PartialEq)]
pub enum TileContent {
    /// A stored level whole (an object's).
    Level(LodRef),
    /// The triangles of a node's stored level that stand for some of its entries
    /// ([`super::slices`]).
    Slice {
        /// The node's level.
        level: LodRef,
        /// Which of its triangles.
        triangles: Arc<[u32]>,
    },
}

impl TileContent {
    /// The stored level it is made from.
    pub fn level(&self) -> &LodRef {
        match self {
            TileContent::Level(lod) | TileContent::Slice { level: lod, .. } => lod,
        }
    }

    /// Its `.glb`, from its level's mesh `mesh`.
    fn glb(&self, mesh: &Mesh) -> Vec<u8> {
        match self {
            TileContent::Level(_) => mesh_glb(mesh),
            TileContent::Slice { triangles, .. } => mesh_glb(&slice_mesh(mesh, triangles)),
        }
    }
}

/// A content file's bytes: its level, or its slice of one, as a `.glb`.
pub fn content_glb(db: &Database, content: &TileContent) -> Result<Vec<u8>> {
    Ok(content.glb(&db.lod_mesh(content.level())?))
}

/// What [`write_tileset`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct TilesReport {
    /// Tiles in the tileset.
    pub tiles: usize,
    /// Content files (one per stored object level that a tile draws, one per slice of a node's).
    pub contents: usize,
    /// The content files' bytes.
    pub content_bytes: u64,
    /// `tileset.json`'s bytes and its subtrees'.
    pub tileset_bytes: u64,
    /// Subtree tilesets (one per node below the root).
    pub subtrees: usize,
    /// View cells (a visibility file each).
    pub cells: usize,
    /// The bytes of the cells' visibility files and their index together.
    pub visibility_bytes: u64,
}

/// The tileset of `db`, its root tile under `root_transform` (a column-major matrix applied
/// after the turn to z-up; `None`: the identity). Reads every node page and each base mesh's
/// full-detail level (for its box).
pub fn tileset(db: &Database, root_transform: Option<Mat4>) -> Result<Tileset> {
    let root = root_transform.unwrap_or(Mat4::IDENTITY);
    if !root.is_finite() || root.determinant().abs() <= f32::MIN_POSITIVE {
        return Err(Error::bad_param(Param::RootTransform, "must be finite and invertible"));
    }
    let pages = (0..db.node_count()).map(|n| db.node(n)).collect::<Result<Vec<NodePage>>>()?;
    let root_box = pages[0].node.entries.iter().fold(Aabb::EMPTY, |b, e| b.union(e.mbr));
    let diagonal = if root_box.is_empty() { 1.0 } else { root_box.extent().length().max(f32::MIN_POSITIVE) };
    let catalog = db.catalog();
    let levels: Vec<(u32, usize)> =
        (0..db.node_count()).flat_map(|n| (0..catalog.node_lods[n as usize].len()).map(move |l| (n, l))).collect();
    let slices = slices(db, &pages, &levels)?;
    let mut w = TileWriter {
        db,
        pages: &pages,
        slices,
        mesh_boxes: HashMap::new(),
        contents: BTreeMap::new(),
        subtrees: BTreeMap::new(),
        tiles: 0,
    };
    // Above every level's error: the root is an empty tile that a client refines through.
    let top_error = 2.0 * catalog.node_lods[0].iter().map(|l| l.error).fold(diagonal, f32::max);
    let children = w.node_below(0, top_error)?;
    let mut root_tile = w.tile(box_json(&z_up(&root_box)), top_error, None, json!({ "node": 0 }), children);
    root_tile["refine"] = json!("REPLACE");
    if root != Mat4::IDENTITY {
        root_tile["transform"] = json!(root.to_cols_array().map(num));
    }
    let mut json = json!({
        "asset": asset(),
        "geometricError": num(top_error),
        "root": root_tile,
        "extras": { "hdov": { "nodes": db.node_count(), "objects": db.catalog().objects.len() } },
    });
    // A database built without visibility is a tileset alone.
    let Some(grid) = db.grid().filter(|_| !db.layouts().is_empty()) else {
        return Ok(Tileset { json, subtrees: w.subtrees, contents: w.contents, index: None, tiles: w.tiles });
    };
    json["extras"]["hdov"]["visibility"] = json!(VISIBILITY_INDEX);
    let scene_from_tileset = (root * Y_UP_TO_Z_UP).inverse();
    let index = json!({
        "format": "hdov-cell-visibility",
        "version": CELL_FILE_VERSION,
        "cells": CELL_FILES,
        "cellCount": grid.cell_count(),
        "nodeCount": db.node_count(),
        "objectCount": db.catalog().objects.len(),
        "eta": QueryParams::default().eta,
        "sceneFromTileset": scene_from_tileset.to_cols_array(),
        "grid": client_grid(grid),
    });
    Ok(Tileset { json, subtrees: w.subtrees, contents: w.contents, index: Some(index), tiles: w.tiles })
}

/// The folder of the subtrees' tilesets, beside `content/`.
const SUBTREES: &str = "subtrees";

/// `tile`'s content URIs and its descendants', written relative to the export's root, made
/// relative to [`SUBTREES`].
fn from_subtrees(tile: &mut Value) {
    if let Some(uri) = tile["content"]["uri"].as_str() {
        tile["content"]["uri"] = json!(format!("../{uri}"));
    }
    for c in tile.get_mut("children").and_then(Value::as_array_mut).into_iter().flatten() {
        from_subtrees(c);
    }
}

/// A tileset's `asset`.
fn asset() -> Value {
    json!({ "version": "1.1", "generator": concat!("hdov ", env!("CARGO_PKG_VERSION")) })
}

/// The grid as a client finds cells in it (docs/format.md, "3D Tiles out"): the region as six
/// numbers, and every 64-bit place mask as 16 hex digits, which JSON numbers (doubles in
/// JavaScript) cannot hold exactly.
fn client_grid(g: &ViewGrid) -> Value {
    let hex = |m: u64| format!("{m:016x}");
    json!({
        "region": g.region.to_array(),
        "dims": g.dims,
        "present": g.present.as_ref().map(|s| s.runs()),
        "places": g.places.as_ref().map(|p| p.iter().map(|&m| hex(m)).collect::<Vec<_>>()),
        "parts": g.parts.iter().map(|p| json!([p.cell, hex(p.places)])).collect::<Vec<_>>(),
    })
}

impl Tileset {
    /// `tileset.json`'s bytes.
    pub fn tileset_bytes(&self) -> Vec<u8> {
        serde_json::to_vec(&self.json).expect("serialisable")
    }

    /// `visibility/index.json`'s bytes; `None` without visibility.
    pub fn index_bytes(&self) -> Option<Vec<u8>> {
        self.index.as_ref().map(|i| serde_json::to_vec(i).expect("serialisable"))
    }
}

/// Builds the tiles depth first, naming each content once.
struct TileWriter<'a> {
    db: &'a Database,
    pages: &'a [NodePage],
    /// Every node level's slices by the entries they stand for.
    slices: HashMap<(u32, usize), Vec<Slice>>,
    /// Each base mesh's box over all its levels, in mesh space.
    mesh_boxes: HashMap<u32, Aabb>,
    contents: BTreeMap<String, TileContent>,
    subtrees: BTreeMap<String, Vec<u8>>,
    tiles: usize,
}

impl TileWriter<'_> {
    /// The tiles that draw node `n`'s subtree below a tile of error `above` (decision 131): for
    /// each entry, the chain of its slices of the node's levels of less error, coarsest first,
    /// the finest holding the entry's own tiles (an object's chain, or a child node's subtree
    /// tileset); for triangles that stand for several entries, a chain of their slices. A client
    /// draws a node's level as the slices of the entries it may see.
    fn node_below(&mut self, n: u32, above: f32) -> Result<Vec<Value>> {
        let chain = self.db.catalog().node_lods[n as usize].clone();
        let errors = chain_errors(&chain, 1.0);
        let kept: Vec<usize> = distinct_levels(&errors).into_iter().filter(|&l| errors[l] < above).collect();
        let pages = self.pages;
        let node = &pages[n as usize].node;
        let key = |k: u32| {
            let child = node.entries[k as usize].child;
            if node.is_leaf() { object_key(self.db.node_count(), child) } else { u64::from(child) }
        };
        // Each set of entries' slices, finest first, as (level, slice).
        let mut chains: BTreeMap<Vec<u32>, Vec<(usize, usize)>> = BTreeMap::new();
        for &l in &kept {
            for (k, s) in self.slices[&(n, l)].iter().enumerate() {
                chains.entry(s.entries.clone()).or_default().push((l, k));
            }
        }
        let mut out = Vec::new();
        for (k, e) in node.entries.iter().enumerate() {
            let own = chains.remove(&vec![k as u32]).unwrap_or_default();
            let finest = own.first().map_or(above, |&(l, _)| errors[l]);
            let below =
                if node.is_leaf() { self.object_tile(e.child, finest)? } else { self.subtree(e.child, e.mbr, finest)? };
            if own.is_empty() {
                out.push(below);
                continue;
            }
            out.push(self.slice_chain(n, &chain, &errors, &own, e.mbr, &[key(k as u32)], vec![below]));
        }
        for (entries, own) in chains {
            let keys: Vec<u64> = entries.iter().map(|&k| key(k)).collect();
            // Past the node's finest level its entries draw themselves: the chain ends in an
            // empty tile, since a client draws a tile without children however close it is.
            let b = own.iter().fold(Aabb::EMPTY, |b, &(l, k)| b.union(self.slices[&(n, l)][k].bounds));
            let end = self.tile(box_json(&z_up(&b)), 0.0, None, json!({ "node": n, "entries": keys }), Vec::new());
            out.push(self.slice_chain(n, &chain, &errors, &own, Aabb::EMPTY, &keys, vec![end]));
        }
        Ok(out)
    }

    /// The chain of node `n`'s slices `own` (finest first, as (level, slice)) that stand for the
    /// entries `keys` (plugin keys), boxed by `mbr` and their triangles; the finest tile holds
    /// `children`.
    #[allow(clippy::too_many_arguments)]
    fn slice_chain(
        &mut self,
        n: u32,
        chain: &[LodRef],
        errors: &[f32],
        own: &[(usize, usize)],
        mbr: Aabb,
        keys: &[u64],
        children: Vec<Value>,
    ) -> Value {
        let b = own.iter().fold(mbr, |b, &(l, k)| b.union(self.slices[&(n, l)][k].bounds));
        // A set of entries has at most one slice of a level.
        let contents: HashMap<usize, (String, TileContent)> = own
            .iter()
            .map(|&(l, k)| {
                let triangles: Arc<[u32]> = self.slices[&(n, l)][k].triangles.clone().into();
                (l, (format!("n{n}-{l}-{k}"), TileContent::Slice { level: chain[l], triangles }))
            })
            .collect();
        let levels: Vec<usize> = own.iter().map(|&(l, _)| l).collect();
        let key = |l: usize| json!({ "node": n, "level": l, "entries": keys });
        self.chain(&box_json(&z_up(&b)), &levels, errors, |l| contents[&l].clone(), key, children)
    }

    /// Node `c` (box `mbr`) below a tile of error `above`, as a tile that names the tileset of
    /// its subtree (`subtrees/n{c}.json`): a client fetches it only when it refines into `c`, so
    /// the subtrees its cell cannot see cost nothing. Clients refine such a tile without drawing
    /// it.
    fn subtree(&mut self, c: u32, mbr: Aabb, above: f32) -> Result<Value> {
        let children = self.node_below(c, above)?;
        let bounds = box_json(&z_up(&mbr));
        let mut root = self.tile(bounds.clone(), above, None, json!({ "node": c }), children);
        root["refine"] = json!("REPLACE");
        let path = format!("{SUBTREES}/n{c}.json");
        // Its URIs are relative to its own folder.
        from_subtrees(&mut root);
        let set = json!({ "asset": asset(), "geometricError": num(above), "root": root });
        self.subtrees.insert(path.clone(), serde_json::to_vec(&set).expect("serialisable"));
        let mut tile = self.tile(bounds, above, None, json!({ "node": c }), Vec::new());
        tile["content"] = json!({ "uri": path });
        Ok(tile)
    }

    /// Object `o` below a tile of error `above`: its levels of less error (full detail always),
    /// coarsest first, under the object's model matrix.
    fn object_tile(&mut self, o: u32, above: f32) -> Result<Value> {
        let record = &self.db.catalog().objects[o as usize];
        let (mesh, model) = (record.mesh, Mat4::from_cols_array(&record.transform));
        let chain = self.db.catalog().object_lods(o).to_vec();
        let scale = max_scale(&model);
        let bounds = box_json(&z_up(&self.mesh_box(mesh, &chain)?));
        let errors = chain_errors(&chain, scale);
        let kept: Vec<usize> = distinct_levels(&errors).into_iter().filter(|&l| l == 0 || errors[l] < above).collect();
        let content = |l: usize| (format!("m{mesh}-{l}"), TileContent::Level(chain[l]));
        let mut tile = self.chain(&bounds, &kept, &errors, content, |l| json!({ "object": o, "level": l }), Vec::new());
        if model != Mat4::IDENTITY {
            tile["transform"] = json!((Y_UP_TO_Z_UP * model * Y_UP_TO_Z_UP.inverse()).to_cols_array().map(num));
        }
        Ok(tile)
    }

    /// The tiles of a chain's `levels` (finest first, each drawing `content(level)` with tile
    /// error `errors[level]`), the coarsest outermost and the finest holding `children`.
    fn chain(
        &mut self,
        bounds: &Value,
        levels: &[usize],
        errors: &[f32],
        content: impl Fn(usize) -> (String, TileContent),
        key: impl Fn(usize) -> Value,
        mut children: Vec<Value>,
    ) -> Value {
        for &l in levels {
            children = vec![self.tile(bounds.clone(), errors[l], Some(content(l)), key(l), children)];
        }
        children.pop().expect("a chain has a level")
    }

    /// One tile; `content` names what it draws (written once however many tiles share it).
    fn tile(&mut self, bounds: Value, error: f32, content: Option<(String, TileContent)>, key: Value, children: Vec<Value>) -> Value {
        self.tiles += 1;
        let mut tile = json!({ "boundingVolume": { "box": bounds }, "geometricError": num(error), "extras": { "hdov": key } });
        if let Some((name, lod)) = content {
            let uri = format!("content/{name}.glb");
            tile["content"] = json!({ "uri": &uri });
            self.contents.insert(uri, lod);
        }
        if !children.is_empty() {
            tile["children"] = Value::Array(children);
        }
        tile
    }

    /// The mesh-space box of every level of base mesh `mesh` (whose chain is `chain`).
    fn mesh_box(&mut self, mesh: u32, chain: &[LodRef]) -> Result<Aabb> {
        if let Some(b) = self.mesh_boxes.get(&mesh) {
            return Ok(*b);
        }
        let mut b = Aabb::EMPTY;
        for lod in chain {
            b = self.db.lod_mesh(lod)?.positions.iter().fold(b, |b, &p| b.grow(Vec3::from(p)));
        }
        self.mesh_boxes.insert(mesh, b);
        Ok(b)
    }
}

/// Each level's geometric error as a tile: its recorded error times `scale`, or a finer level's
/// where that is larger. A level's recorded error adds the worst of the parts it merges, so a
/// coarser level can record less than a finer one; a tile must not claim less than the tiles
/// below it.
fn chain_errors(chain: &[LodRef], scale: f32) -> Vec<f32> {
    chain
        .iter()
        .scan(0.0f32, |worst, l| {
            *worst = worst.max(l.error * scale);
            Some(*worst)
        })
        .collect()
}

/// The levels of a chain whose tile errors (`errors`, finest first, never falling) exceed every
/// finer level's: a coarser level that claims a finer one's error would be refined exactly when
/// that one is, and 3D Tiles clients refine a tile whose error equals its parent's without
/// drawing it.
fn distinct_levels(errors: &[f32]) -> Vec<usize> {
    let mut kept: Vec<usize> = Vec::with_capacity(errors.len());
    for (l, &e) in errors.iter().enumerate() {
        if kept.last().is_none_or(|&k| e > errors[k]) {
            kept.push(l);
        }
    }
    kept
}

/// A scene-frame box as a box of the z-up frame.
fn z_up(b: &Aabb) -> Aabb {
    if b.is_empty() {
        return Aabb::new(Vec3::ZERO, Vec3::ZERO);
    }
    b.transformed(&Y_UP_TO_Z_UP)
}

/// A box as 3D Tiles' `box` (centre, then three half-axes), widened by a few units in the last
/// place of its coordinates so that content rounded on its faces stays inside, and never flat.
fn box_json(b: &Aabb) -> Value {
    let c = b.center();
    let magnitude = b.min.abs().max(b.max.abs()).max_element();
    let pad = (magnitude * 4.0 * f32::EPSILON).max(b.extent().length() * 1e-6).max(f32::MIN_POSITIVE.sqrt());
    let h = b.extent() * 0.5 + Vec3::splat(pad);
    json!([c.x, c.y, c.z, h.x, 0.0, 0.0, 0.0, h.y, 0.0, 0.0, 0.0, h.z].map(num))
}

/// An `f32` as the shortest decimal that reads back as it (`694.801`, not the `f64`
/// `694.801025390625`): tilesets are mostly numbers, and a client downloads them. A reader
/// taking it as an `f64` is within half a unit in the last place of the `f32`, which box
/// padding covers, and distinct `f32`s stay distinct and in order.
fn num(x: f32) -> Value {
    json!(x.to_string().parse::<f64>().expect("an f32 prints as a number"))
}

/// The version of the cell file format ([`encode_cell`]).
pub const CELL_FILE_VERSION: u32 = 1;

/// What the cell files start with.
const CELL_MAGIC: &[u8; 4] = b"HDVC";

/// A DoV as a 16-bit code `c`, rounded up: the DoV is at most `2^(c/1024 − 32)`; 1 for any DoV
/// at or below `2^−32` (an entry that is seen with no measured share).
pub fn dov_code(dov: f32) -> u16 {
    if dov.is_nan() || dov <= 0.0 {
        return 1;
    }
    ((f64::from(dov).log2() + 32.0) * 1024.0).ceil().clamp(1.0, 32768.0) as u16
}

/// The DoV a code stands for (at least the DoV it was made from).
pub fn dov_of_code(code: u16) -> f64 {
    (f64::from(code) / 1024.0 - 32.0).exp2()
}

/// A cell's visibility file: `HDVC`, version, cell, entry count, stop count (u32 LE each); the
/// entries' keys ascending as LEB128 deltas (a node's key is its id, an object's the node count
/// plus its id); their DoV codes ([`dov_code`], u16 LE); the stops as pairs of a key delta and
/// the level, LEB128 (docs/format.md, "3D Tiles").
pub fn encode_cell(v: &CellVisibility, nodes: u32) -> Vec<u8> {
    let entries = keyed(&v.nodes, &v.objects, nodes);
    let stops = keyed(&v.node_stops, &v.object_stops, nodes);
    let mut out = Vec::with_capacity(20 + entries.len() * 4 + stops.len() * 3);
    out.extend(CELL_MAGIC);
    for x in [CELL_FILE_VERSION, v.cell, entries.len() as u32, stops.len() as u32] {
        out.extend(x.to_le_bytes());
    }
    let mut last = 0;
    for &(k, _) in &entries {
        leb128(&mut out, k - last);
        last = k;
    }
    for &(_, d) in &entries {
        out.extend(dov_code(d).to_le_bytes());
    }
    last = 0;
    for &(k, l) in &stops {
        leb128(&mut out, k - last);
        leb128(&mut out, u64::from(l));
        last = k;
    }
    out
}

/// View cell `cell`'s visibility file: its [`CellVisibility`] under the default query,
/// encoded ([`encode_cell`]).
pub fn cell_file_bytes(db: &Database, cell: u32) -> Result<Vec<u8>> {
    Ok(encode_cell(&db.cell_visibility(cell, &QueryParams::default())?, db.node_count()))
}

/// Node pairs and object pairs as one list by key (an object's key is `nodes` plus its id).
fn keyed<T: Copy>(of_nodes: &[(u32, T)], of_objects: &[(u32, T)], nodes: u32) -> Vec<(u64, T)> {
    let node_keys = of_nodes.iter().map(|&(n, x)| (u64::from(n), x));
    node_keys.chain(of_objects.iter().map(|&(o, x)| (object_key(nodes, o), x))).collect()
}

/// Object `o`'s key in cell files and tile extras: the node count plus its id (a node's key is
/// its id).
fn object_key(nodes: u32, o: u32) -> u64 {
    u64::from(nodes) + u64::from(o)
}

fn leb128(out: &mut Vec<u8>, mut x: u64) {
    loop {
        let byte = (x & 0x7f) as u8;
        x >>= 7;
        if x == 0 {
            out.push(byte);
            return;
        }
        out.push(byte | 0x80);
    }
}

/// A cell file read back: entries (key, DoV code) and stops (key, level), keys as written.
#[derive(Clone, Debug, PartialEq)]
pub struct CellFile {
    /// The view cell.
    pub cell: u32,
    /// Key and DoV code of each entry the cell may see, keys ascending.
    pub entries: Vec<(u64, u16)>,
    /// Key and level of each stop, keys ascending.
    pub stops: Vec<(u64, u32)>,
}

/// Reads a cell file ([`encode_cell`]); the reason when it is not one.
pub fn decode_cell(bytes: &[u8]) -> std::result::Result<CellFile, String> {
    let mut at = 0usize;
    let take = |at: &mut usize, n: usize| -> std::result::Result<&[u8], String> {
        let s = bytes.get(*at..*at + n).ok_or("ends early")?;
        *at += n;
        Ok(s)
    };
    if take(&mut at, 4)? != CELL_MAGIC {
        return Err("is not a cell visibility file".into());
    }
    let mut word = || -> std::result::Result<u32, String> {
        Ok(u32::from_le_bytes(take(&mut at, 4)?.try_into().expect("four bytes")))
    };
    let (version, cell, n, s) = (word()?, word()?, word()?, word()?);
    if version != CELL_FILE_VERSION {
        return Err(format!("version {version}, this reader reads {CELL_FILE_VERSION}"));
    }
    let varint = |at: &mut usize| -> std::result::Result<u64, String> {
        let mut x = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *bytes.get(*at).ok_or("ends early")?;
            *at += 1;
            x |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(x);
            }
        }
        Err("holds a number of more than 64 bits".into())
    };
    let mut keys = Vec::with_capacity(n.min(1 << 20) as usize);
    let mut last = 0u64;
    for _ in 0..n {
        last = last.checked_add(varint(&mut at)?).ok_or("a key past 2^64")?;
        keys.push(last);
    }
    let mut entries = Vec::with_capacity(keys.len());
    for k in keys {
        entries.push((k, u16::from_le_bytes(take(&mut at, 2)?.try_into().expect("two bytes"))));
    }
    let mut stops = Vec::new();
    last = 0;
    for _ in 0..s {
        last = last.checked_add(varint(&mut at)?).ok_or("a key past 2^64")?;
        let level = u32::try_from(varint(&mut at)?).map_err(|_| "a level past 2^32")?;
        stops.push((last, level));
    }
    if at != bytes.len() {
        return Err(format!("{} bytes after its last stop", bytes.len() - at));
    }
    Ok(CellFile { cell, entries, stops })
}

/// Writes `db` as a 3D Tiles tileset into the new directory `dir` (refused if anything is
/// there; written aside and renamed into place, so a failed export leaves nothing): the
/// tileset, each stored level's content once, and every view cell's visibility (none for a
/// database built without it).
pub fn write_tileset(db: &Database, dir: &Path, root_transform: Option<Mat4>, progress: &Progress) -> Result<TilesReport> {
    let set = tileset(db, root_transform)?;
    let txn = hdov_storage::DirTxn::begin(dir, hdov_storage::Overwrite::Never)?;
    let at = |p: &str| -> PathBuf { txn.path().join(p) };
    let subs: &[&str] =
        if set.index.is_some() { &["content", SUBTREES, "visibility/cells"] } else { &["content", SUBTREES] };
    for sub in subs {
        std::fs::create_dir_all(at(sub)).map_err(|e| Error::io(at(sub), e))?;
    }
    let write = |path: PathBuf, bytes: &[u8]| std::fs::write(&path, bytes).map_err(|e| Error::io(path, e));
    let tileset_bytes = set.tileset_bytes();
    write(at(TILESET_FILE), &tileset_bytes)?;
    let mut subtree_bytes = 0;
    for (path, bytes) in &set.subtrees {
        subtree_bytes += bytes.len() as u64;
        write(at(path), bytes)?;
    }
    let bar = progress.bar("content", set.contents.len() as u64);
    // Each stored level is read once: a node level's slices are all cut from one read.
    let mut by_level: BTreeMap<u64, Vec<(&String, &TileContent)>> = BTreeMap::new();
    for (name, content) in &set.contents {
        by_level.entry(content.level().offset).or_default().push((name, content));
    }
    let content_bytes = by_level
        .into_par_iter()
        .map(|(_, files)| {
            let mesh = db.lod_mesh(files[0].1.level())?;
            let mut sum = 0;
            for (name, content) in files {
                let bytes = content.glb(&mesh);
                write(at(name), &bytes)?;
                bar.advance(1);
                sum += bytes.len() as u64;
            }
            Ok(sum)
        })
        .sum::<Result<u64>>()?;
    bar.finish_and_clear();
    let index_bytes = set.index_bytes().unwrap_or_default();
    let cells = if set.index.is_some() {
        write(at(VISIBILITY_INDEX), &index_bytes)?;
        db.grid().map_or(0, |g| g.cell_count()) as u32
    } else {
        0
    };
    let bar = progress.bar("visibility", u64::from(cells));
    let cell_bytes = (0..cells)
        .into_par_iter()
        .map(|c| {
            let bytes = cell_file_bytes(db, c)?;
            write(at(&cell_file(c)), &bytes)?;
            bar.advance(1);
            Ok(bytes.len() as u64)
        })
        .sum::<Result<u64>>()?;
    bar.finish_and_clear();
    txn.commit()?;
    Ok(TilesReport {
        tiles: set.tiles,
        contents: set.contents.len(),
        content_bytes,
        tileset_bytes: tileset_bytes.len() as u64 + subtree_bytes,
        subtrees: set.subtrees.len(),
        cells: cells as usize,
        visibility_bytes: cell_bytes + index_bytes.len() as u64,
    })
}
