//! The reader: an open database directory (its files are [`crate::format`]'s).
//!
//! A database is written by [`crate::build()`] into a temporary directory and renamed into place
//! (see `hdov_storage::DirTxn`); it is immutable afterwards. `docs/format.md` gives every byte.

pub(crate) mod access;
pub mod info;

use std::path::{Path, PathBuf};

use crate::error::{Error, Param, Result};
use crate::format::catalog::{Catalog, LodRef};
use crate::format::tree_page::{self, NodePage};
use crate::format::{
    CATALOG_FILE, CATALOG_KIND, GEOMETRY_FILE, GEOMETRY_KIND, MANIFEST_FILE, Manifest, TREE_FILE, TREE_KIND,
};
use crate::grid::ViewGrid;
use crate::scene::Mesh;
use hdov_storage::{BlobFile, Layout, LayoutKind, PageFile, PageReader, ReadMode};

/// An open, read-only database: `Send + Sync`, so any number of threads may query it at once,
/// each reading pages through its own [`PageReader`] (which counts them) and its own
/// [`LayoutCursor`](hdov_storage::LayoutCursor)s.
///
/// Opening validates every file (the manifest's fields and recorded sizes, the page and blob
/// headers, the catalog's references into the tree and the geometry, every layout's metadata);
/// pages and records are checked against their checksums when read. A damaged database gives a
/// one-line error that names the file, never a panic.
pub struct Database {
    dir: PathBuf,
    manifest: Manifest,
    catalog: Catalog,
    tree: PageFile,
    geometry: BlobFile,
    /// The layouts the manifest lists, opened once, in its order.
    layouts: Vec<Layout>,
}

impl Database {
    /// Opens the database directory `dir` read-only, through memory maps, validating every file.
    pub fn open(dir: &Path) -> Result<Database> {
        Self::open_with(dir, ReadMode::Mmap)
    }

    /// Opens with a chosen read mode (`Pread` reads pages with `pread`, for cold-cache runs).
    pub fn open_with(dir: &Path, mode: ReadMode) -> Result<Database> {
        if !dir.is_dir() {
            return Err(Error::bad_file(dir, "no such database directory"));
        }
        let manifest = Manifest::read(dir)?;
        if manifest.measured_against.is_some() {
            return Err(Error::bad_file(
                dir,
                "is a shard, which keeps only its cells' visibility: join the shards with their base build (hdov merge BASE SHARD… --out DB)",
            ));
        }
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
        let layouts = manifest
            .written_layouts()
            .into_iter()
            .map(|kind| {
                let layout = Layout::open(dir, kind, mode)?;
                // Named by its first file (the index, where it has one), which records the counts.
                let file = dir.join(kind.file_names()[0]);
                if u64::from(layout.node_count()) != nodes {
                    return Err(Error::bad_file(
                        file,
                        format!("{kind} layout has {} nodes, the tree {nodes}", layout.node_count()),
                    ));
                }
                if u64::from(layout.cell_count()) != manifest.counts.cells {
                    return Err(Error::bad_file(
                        file,
                        format!("{kind} layout has {} cells, the grid {}", layout.cell_count(), manifest.counts.cells),
                    ));
                }
                Ok(layout)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Database { dir: dir.to_path_buf(), manifest, catalog, tree, geometry, layouts })
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

    /// Nodes of the R-tree (node ids are `0..node_count()`, the root is 0).
    pub fn node_count(&self) -> u32 {
        self.manifest.counts.nodes as u32
    }

    /// Reads and validates one node page through `pages` (which counts it: requested, and
    /// read unless its read buffer or cache held it). `priority` is the cache policy's number
    /// for the page: the node's DoV, 0 when unknown.
    pub fn read_node(&self, id: u32, priority: f64, pages: &mut PageReader) -> Result<NodePage> {
        let bytes = pages.page(&self.tree, u64::from(id), priority)?;
        tree_page::decode(&bytes, self.node_count(), self.catalog.objects.len() as u32)
            .and_then(|page| tree_page::check_position(&page, id).map(|()| page))
            .map_err(|r| Error::bad_file(self.dir.join(TREE_FILE), format!("node {id}: {r}")))
    }

    /// Reads and validates one node page, uncounted: a one-off read through a
    /// [`PageReader::uncached`] of its own. A query reads through its own reader
    /// ([`read_node`](Self::read_node)).
    pub fn node(&self, id: u32) -> Result<NodePage> {
        self.read_node(id, 0.0, &mut PageReader::uncached())
    }

    /// `tree.pages`: the page file the nodes are read from (for
    /// [`PageReader::set_priority`] and [`IoStats`](hdov_storage::IoStats) by its name).
    pub fn tree_file(&self) -> &PageFile {
        &self.tree
    }

    /// The layouts this database holds, in the order they were written.
    pub fn layouts(&self) -> Vec<LayoutKind> {
        self.layouts.iter().map(Layout::kind).collect()
    }

    /// One layout's V-pages, opened with the database (read them through a
    /// [`Layout::cursor`]).
    pub fn layout(&self, kind: LayoutKind) -> Result<&Layout> {
        self.layouts
            .iter()
            .find(|l| l.kind() == kind)
            .ok_or_else(|| {
                let why = self.manifest.visibility.as_ref().and_then(|v| v.left_out_of(kind));
                let why = why.map_or(String::new(), |l| format!(": {l}"));
                Error::bad_param(Param::Layout, format!("{} holds no {kind} layout{why}", self.dir.display()))
            })
    }

    /// The encoded bytes of one LOD level in `geometry.blob` (checksum verified): what a
    /// walkthrough loads and keeps resident. Decode with [`Database::lod_mesh`].
    pub fn lod_bytes(&self, lod: &LodRef) -> Result<&[u8]> {
        Ok(self.geometry.get(lod.blob())?)
    }

    /// The crc32 stored for one LOD level's record in `geometry.blob` (its bytes are checked when
    /// read): a content tag for the record, such as the server's ETag.
    pub fn lod_checksum(&self, lod: &LodRef) -> Result<u32> {
        Ok(self.geometry.checksum(lod.blob())?)
    }

    /// Every stored LOD level: the base meshes' chains, then the nodes'. A reference from outside
    /// (a URL) is valid only if it is one of these.
    pub fn lod_refs(&self) -> impl Iterator<Item = &LodRef> + '_ {
        self.catalog.mesh_lods.iter().chain(&self.catalog.node_lods).flatten()
    }

    /// An object's column-major model matrix (mesh space to world), `None` past the last object.
    pub fn object_transform(&self, object: u32) -> Option<glam::Mat4> {
        self.catalog.objects.get(object as usize).map(|o| glam::Mat4::from_cols_array(&o.transform))
    }

    /// Loads one LOD mesh from `geometry.blob` (checksum verified).
    pub fn lod_mesh(&self, lod: &LodRef) -> Result<Mesh> {
        let bytes = self.geometry.get(lod.blob())?;
        let mesh: Mesh = crate::record::decode(bytes, &self.dir.join(GEOMETRY_FILE), "mesh record")?;
        mesh.check().map_err(|r| Error::bad_file(self.dir.join(GEOMETRY_FILE), r))?;
        Ok(mesh)
    }
}

#[cfg(test)]
mod tests {
    use super::Database;

    #[test]
    fn database_is_send_and_sync() {
        // A static assertion: this compiles only if any number of threads may share one.
        const fn shared<T: Send + Sync>() {}
        const _: () = shared::<Database>();
    }
}
