//! The database directory, format v1.
//!
//! ```text
//! DB/manifest.json    format version, build parameters, counts (JSON; first key "hdov")
//! DB/tree.pages       R-tree nodes, one per page, node id = page number (storage page file, kind TREE)
//! DB/geometry.blob    every LOD level as a bincode mesh record (storage blob file, kind GEOM)
//! DB/catalog.blob     objects and LOD references (storage blob file, kind CATL)
//! ```
//! A database is written by [`crate::build()`] into a temporary directory and renamed into place
//! (see `hdov_storage::DirTxn`); it is immutable afterwards. `docs/format.md` gives every byte.

pub mod catalog;
pub mod info;
pub mod manifest;
pub mod tree_page;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::grid::ViewGrid;
use crate::scene::Mesh;
use catalog::{Catalog, LodRef};
use hdov_storage::{BlobFile, LayoutKind, LayoutReader, PageFile, ReadMode};
pub use manifest::{Counts, FileEntry, LayoutInfo, Manifest, VisibilityInfo, is_database};
use tree_page::NodePage;

/// 2: the catalog holds node shapes (the stop rule's inputs).
pub const FORMAT_VERSION: u32 = 2;
pub const MANIFEST_FILE: &str = "manifest.json";
pub const TREE_FILE: &str = "tree.pages";
pub const GEOMETRY_FILE: &str = "geometry.blob";
pub const CATALOG_FILE: &str = "catalog.blob";
pub const TREE_KIND: [u8; 4] = *b"TREE";
pub const GEOMETRY_KIND: [u8; 4] = *b"GEOM";
pub const CATALOG_KIND: [u8; 4] = *b"CATL";

/// An open, read-only database. Tree pages are read through memory maps and counted.
///
/// Opening validates every file (the manifest's fields and recorded sizes, the page and blob
/// headers, the catalog's references into the tree and the geometry); pages and records are
/// checked against their checksums when read. A damaged database gives a one-line error that
/// names the file, never a panic.
pub struct Database {
    dir: PathBuf,
    manifest: Manifest,
    catalog: Catalog,
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
        let mut records = catalog_file.iter();
        let record = records.next().ok_or_else(|| Error::bad_file(&catalog_path, "holds no catalog record"))??;
        if records.next().is_some() {
            return Err(Error::bad_file(&catalog_path, "holds more than one catalog record"));
        }
        let catalog: Catalog = crate::record::decode(record.1, &catalog_path, "catalog")?;
        let nodes = manifest.counts.nodes;
        if tree.page_count() != nodes {
            return Err(Error::bad_file(
                dir.join(TREE_FILE),
                format!("{} node pages, {MANIFEST_FILE} says {nodes}", tree.page_count()),
            ));
        }
        if tree.page_size() != manifest.build.page_size {
            return Err(Error::bad_file(
                dir.join(TREE_FILE),
                format!("pages of {} bytes, {MANIFEST_FILE} says {}", tree.page_size(), manifest.build.page_size),
            ));
        }
        let counts = &manifest.counts;
        if catalog.objects.len() as u64 != counts.objects || catalog.mesh_lods.len() as u64 != counts.base_meshes {
            return Err(Error::bad_file(
                &catalog_path,
                format!("object or base mesh count differs from {MANIFEST_FILE}'s"),
            ));
        }
        catalog.check(nodes as usize, geometry.file_len()).map_err(|r| Error::bad_file(&catalog_path, r))?;
        Ok(Database { dir: dir.to_path_buf(), manifest, catalog, tree, geometry })
    }

    /// The database directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// What the database holds and how it was built (`manifest.json`).
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Objects, base meshes and where every LOD level lives.
    pub fn catalog(&self) -> &Catalog {
        &self.catalog
    }

    /// The viewing-cell grid, if the database holds visibility.
    pub fn grid(&self) -> Option<&ViewGrid> {
        self.manifest.grid.as_ref()
    }

    pub fn node_count(&self) -> u32 {
        self.manifest.counts.nodes as u32
    }

    /// Reads and validates one node page (counted as one page read), its pointers against the
    /// depth-first numbering too (see [`tree_page::check_position`]).
    pub fn node(&self, id: u32) -> Result<NodePage> {
        let bytes = self.tree.page(id as u64)?;
        tree_page::decode(&bytes, self.node_count(), self.catalog.objects.len() as u32)
            .and_then(|page| tree_page::check_position(&page, id).map(|()| page))
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
        // Checked on open to be the parsed names of the layouts written.
        self.manifest.build.visibility.iter().flat_map(|v| v.layouts.iter().copied()).collect()
    }

    /// Opens the V-page reader of one layout.
    pub fn layout(&self, kind: LayoutKind, mode: ReadMode) -> Result<LayoutReader> {
        if !self.layouts().contains(&kind) {
            return Err(Error::bad_param("layout", format!("{} holds no {kind} layout", self.dir.display())));
        }
        let reader = LayoutReader::open(&self.dir, kind, mode)?;
        // Named by its first file (the index, where it has one), which records the counts.
        let file = self.dir.join(kind.file_names()[0]);
        if reader.node_count() != self.node_count() {
            return Err(Error::bad_file(
                file,
                format!("{kind} layout has {} nodes, the tree {}", reader.node_count(), self.node_count()),
            ));
        }
        if u64::from(reader.cell_count()) != self.manifest.counts.cells {
            return Err(Error::bad_file(
                file,
                format!("{kind} layout has {} cells, the grid {}", reader.cell_count(), self.manifest.counts.cells),
            ));
        }
        Ok(reader)
    }

    /// The encoded bytes of one LOD level in `geometry.blob` (checksum verified): what a
    /// walkthrough loads and keeps resident. Decode with [`Database::lod_mesh`].
    pub fn lod_bytes(&self, lod: &LodRef) -> Result<&[u8]> {
        Ok(self.geometry.get(lod.blob())?)
    }

    /// Loads one LOD mesh from `geometry.blob` (checksum verified).
    pub fn lod_mesh(&self, lod: &LodRef) -> Result<Mesh> {
        let bytes = self.geometry.get(lod.blob())?;
        let mesh: Mesh = crate::record::decode(bytes, &self.dir.join(GEOMETRY_FILE), "mesh record")?;
        mesh.check().map_err(|r| Error::bad_file(self.dir.join(GEOMETRY_FILE), r))?;
        Ok(mesh)
    }
}
