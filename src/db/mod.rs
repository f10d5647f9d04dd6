//! The database directory, format v1.
//!
//! ```text
//! DB/manifest.json    format version, build parameters, counts (JSON; first key "hdov")
//! DB/tree.pages       R-tree nodes, one per page, node id = page number (storage page file, kind TREE)
//! DB/geometry.blob    every LOD level as a bincode mesh record (storage blob file, kind GEOM)
//! DB/catalog.blob     objects and LOD references (storage blob file, kind CATL)
//! ```
//! A database is written by [`build::build`] into a temporary directory and renamed into place
//! (see `hdov_storage::DirTxn`); it is immutable afterwards. `docs/format.md` gives every byte.

pub mod build;
pub mod catalog;
pub mod merge;
pub mod tree_page;
pub mod visibility;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::dov::BackendKind;
use crate::dov::precompute::{FloorTest, Shard};
use crate::error::{Error, Result};
use crate::grid::ViewGrid;
use crate::lod::LodParams;
use crate::rtree::{TreeAlgorithm, TreeStats};
use crate::scene::Mesh;
use catalog::{Catalog, LodRef};
use hdov_storage::{BlobFile, DovCodec, LayoutKind, LayoutReader, PageFile, ReadMode};
use tree_page::NodePage;

pub const FORMAT_VERSION: u32 = 1;
pub const MANIFEST_FILE: &str = "manifest.json";
pub const TREE_FILE: &str = "tree.pages";
pub const GEOMETRY_FILE: &str = "geometry.blob";
pub const CATALOG_FILE: &str = "catalog.blob";
pub const TREE_KIND: [u8; 4] = *b"TREE";
pub const GEOMETRY_KIND: [u8; 4] = *b"GEOM";
pub const CATALOG_KIND: [u8; 4] = *b"CATL";

/// How a database was built.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildParams {
    /// Bytes per page of the tree file and of the V-page layouts.
    pub page_size: u32,
    pub tree: TreeAlgorithm,
    pub lod: LodParams,
    /// `None` builds tree and LODs only.
    pub visibility: Option<VisibilityParams>,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            page_size: 4096,
            tree: TreeAlgorithm::Str,
            lod: LodParams::default(),
            visibility: Some(VisibilityParams::default()),
        }
    }
}

/// How DoV is measured and stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibilityParams {
    /// Texels per cube-face edge (R).
    pub resolution: u32,
    pub backend: BackendKind,
    /// Stratified interior sample points per cell, besides the 8 shared corners.
    pub interior_samples: u32,
    /// Layouts to write: `horizontal`, `vertical`, `indexed-vertical`.
    pub layouts: Vec<String>,
    /// How V-entries store DoV: `f32` or `log-u16`.
    pub dov_codec: String,
    /// `[I, N]`: this database holds part I of N of the grid's cells.
    pub shard: Option<[u32; 2]>,
    /// Visible-zero-DoV tests (thesis §5.5.2) that give unseen objects the one-texel floor:
    /// `box` (the object's box meets the cell), `neighbours` (a neighbouring cell's corner sees
    /// it). Empty: no floor.
    #[serde(default)]
    pub zero_dov_floor: Vec<String>,
    /// GPU backend: texels of LOD error below which an object is drawn coarser (0 = off).
    #[serde(default)]
    pub lod_draw_tolerance: f32,
}

impl Default for VisibilityParams {
    fn default() -> Self {
        Self {
            resolution: 128,
            backend: BackendKind::Auto,
            interior_samples: 0,
            layouts: LayoutKind::ALL.iter().map(|k| k.name().to_string()).collect(),
            dov_codec: DovCodec::F32.to_string(),
            shard: None,
            zero_dov_floor: vec!["box".into(), "neighbours".into()],
            lod_draw_tolerance: crate::dov::gpu::DEFAULT_LOD_TOLERANCE_TEXELS,
        }
    }
}

impl VisibilityParams {
    pub fn layout_kinds(&self) -> Result<Vec<LayoutKind>> {
        self.layouts.iter().map(|l| l.parse().map_err(|e: String| Error::bad_arg("--layouts", e))).collect()
    }

    pub fn codec(&self) -> Result<DovCodec> {
        self.dov_codec.parse().map_err(|e: String| Error::bad_arg("--dov-codec", e))
    }

    pub fn floor_tests(&self) -> Result<Vec<FloorTest>> {
        self.zero_dov_floor
            .iter()
            .map(|t| match t.as_str() {
                "box" => Ok(FloorTest::BoxWithin(0.0)),
                "neighbours" => Ok(FloorTest::NeighbourCorners),
                _ => Err(Error::bad_arg("--zero-dov-floor", format!("unknown test '{t}' (box, neighbours)"))),
            })
            .collect()
    }

    pub fn shard(&self) -> Shard {
        self.shard.map_or(Shard::ALL, |[index, count]| Shard { index, count })
    }
}

/// What the visibility stage measured and wrote.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibilityInfo {
    /// The backend that measured, with its adapter.
    pub backend: String,
    /// Cells of the grid this database holds visibility for.
    pub cells_computed: u64,
    pub sample_points: u64,
    /// Objects given the one-texel floor (visible from the cell, seen from no sample point).
    pub floored_objects: u64,
    /// Sample points left out because they lie inside geometry.
    pub skipped_points: u64,
    pub seconds: f64,
    pub layouts: Vec<LayoutInfo>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayoutInfo {
    pub name: String,
    pub vpage_bytes: u64,
    pub index_bytes: u64,
    pub files: Vec<FileEntry>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    pub objects: u64,
    pub base_meshes: u64,
    /// Full-detail faces of every instance.
    pub triangles: u64,
    /// Full-detail faces of the base meshes (instances stored once).
    pub stored_triangles: u64,
    pub nodes: u64,
    pub cells: u64,
    /// Faces over all stored LOD levels (leaf and internal).
    pub lod_triangles: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    pub name: String,
    pub bytes: u64,
}

/// `manifest.json`. Its first key, `"hdov": "database"`, is the file's magic.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub hdov: String,
    pub format_version: u32,
    pub created_by: String,
    pub build: BuildParams,
    pub counts: Counts,
    pub tree: TreeStats,
    pub grid: Option<ViewGrid>,
    pub files: Vec<FileEntry>,
    pub visibility: Option<VisibilityInfo>,
}

impl Manifest {
    pub const MAGIC: &'static str = "database";

    fn read(dir: &Path) -> Result<Manifest> {
        let path = dir.join(MANIFEST_FILE);
        let bytes = std::fs::read(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::bad_file(dir, "not an hdov database (no manifest.json)"),
            _ => Error::io(&path, e),
        })?;
        #[derive(Deserialize)]
        struct Head {
            hdov: String,
            format_version: u32,
        }
        let head: Head =
            serde_json::from_slice(&bytes).map_err(|e| Error::bad_file(&path, format!("not an hdov manifest: {e}")))?;
        if head.hdov != Self::MAGIC {
            return Err(Error::bad_file(&path, format!("an hdov '{}' file, not a database manifest", head.hdov)));
        }
        if head.format_version != FORMAT_VERSION {
            return Err(Error::bad_file(
                &path,
                format!("database format version {}, this hdov reads version {FORMAT_VERSION}", head.format_version),
            ));
        }
        serde_json::from_slice(&bytes).map_err(|e| Error::bad_file(&path, format!("malformed manifest: {e}")))
    }
}

/// An open, read-only database. Tree pages are read through memory maps and counted.
pub struct Database {
    dir: PathBuf,
    pub manifest: Manifest,
    pub catalog: Catalog,
    tree: PageFile,
    geometry: BlobFile,
}

impl Database {
    pub fn open(dir: &Path) -> Result<Database> {
        Self::open_with(dir, ReadMode::Mmap)
    }

    /// Opens with a chosen read mode (`Pread` reads pages with `pread`, for cold-cache runs).
    pub fn open_with(dir: &Path, mode: ReadMode) -> Result<Database> {
        if !dir.is_dir() {
            return Err(Error::bad_file(dir, "no such database directory"));
        }
        let manifest = Manifest::read(dir)?;
        let tree = PageFile::open(&dir.join(TREE_FILE), TREE_KIND, mode)?;
        let geometry = BlobFile::open(&dir.join(GEOMETRY_FILE), GEOMETRY_KIND)?;
        let catalog_file = BlobFile::open(&dir.join(CATALOG_FILE), CATALOG_KIND)?;
        let catalog_path = dir.join(CATALOG_FILE);
        let record =
            catalog_file.iter().next().ok_or_else(|| Error::bad_file(&catalog_path, "holds no catalog record"))??;
        let (catalog, _): (Catalog, usize) =
            bincode::serde::decode_from_slice(record.1, bincode::config::standard())
                .map_err(|e| Error::bad_file(&catalog_path, format!("malformed catalog: {e}")))?;
        let nodes = manifest.counts.nodes;
        if tree.page_count() != nodes {
            return Err(Error::bad_file(
                dir.join(TREE_FILE),
                format!("{} node pages, the manifest says {nodes}", tree.page_count()),
            ));
        }
        if catalog.objects.len() as u64 != manifest.counts.objects {
            return Err(Error::bad_file(&catalog_path, "object count differs from the manifest"));
        }
        catalog.check(nodes as usize).map_err(|r| Error::bad_file(&catalog_path, r))?;
        Ok(Database { dir: dir.to_path_buf(), manifest, catalog, tree, geometry })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn node_count(&self) -> u32 {
        self.manifest.counts.nodes as u32
    }

    /// Reads and validates one node page (counted as one page read).
    pub fn node(&self, id: u32) -> Result<NodePage> {
        let bytes = self.tree.page(id as u64)?;
        tree_page::decode(&bytes, self.node_count(), self.catalog.objects.len() as u32)
            .map_err(|r| Error::bad_file(self.dir.join(TREE_FILE), format!("node {id}: {r}")))
    }

    /// Pages of `tree.pages` read since open or the last reset.
    pub fn tree_pages_read(&self) -> u64 {
        self.tree.reads()
    }

    pub fn reset_io(&self) {
        self.tree.reset_reads();
    }

    /// The layouts this database holds, in the order they were written.
    pub fn layouts(&self) -> Vec<LayoutKind> {
        let names = self.manifest.visibility.iter().flat_map(|v| &v.layouts);
        names.filter_map(|l| l.name.parse().ok()).collect()
    }

    /// Opens the V-page reader of one layout.
    pub fn layout(&self, kind: LayoutKind, mode: ReadMode) -> Result<LayoutReader> {
        if !self.layouts().contains(&kind) {
            return Err(Error::bad_arg("--layout", format!("{} holds no {kind} layout", self.dir.display())));
        }
        let reader = LayoutReader::open(&self.dir, kind, mode)?;
        if reader.node_count() != self.node_count() {
            return Err(Error::bad_file(
                &self.dir,
                format!("{kind} layout has {} nodes, the tree {}", reader.node_count(), self.node_count()),
            ));
        }
        Ok(reader)
    }

    /// Loads one LOD mesh from `geometry.blob` (checksum verified).
    pub fn lod_mesh(&self, lod: &LodRef) -> Result<Mesh> {
        let bytes = self.geometry.get(lod.blob())?;
        let (mesh, _): (Mesh, usize) = bincode::serde::decode_from_slice(bytes, bincode::config::standard())
            .map_err(|e| Error::bad_file(self.dir.join(GEOMETRY_FILE), format!("malformed mesh record: {e}")))?;
        mesh.check().map_err(|r| Error::bad_file(self.dir.join(GEOMETRY_FILE), r))?;
        Ok(mesh)
    }
}
