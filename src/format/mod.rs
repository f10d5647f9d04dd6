//! The on-disk format that the writer ([`crate::build`]) and the reader ([`crate::db`]) share:
//! file names and kinds, the manifest, the catalog, the byte layout of a tree page, and the
//! plain-data record of how a database was built ([`params`]). It knows bytes, names and
//! bounds; it builds nothing and opens nothing (docs/architecture.md).
//!
//! ```text
//! DB/manifest.json    format version, build parameters, counts (JSON; first key "hdov")
//! DB/tree.pages       R-tree nodes, one per page, node id = page number (storage page file, kind TREE)
//! DB/geometry.blob    every LOD level as a bincode mesh record (storage blob file, kind GEOM)
//! DB/catalog.blob     objects and LOD references (storage blob file, kind CATL)
//! ```
//! `docs/format.md` gives every byte.

pub(crate) mod by_name;
pub mod catalog;
pub mod limits;
pub mod manifest;
pub mod params;
pub mod sampling;
pub mod tree_page;

pub use manifest::{BakePhases, Counts, FileChecksum, FileEntry, LayoutInfo, LeftOutLayout, Manifest, VisibilityInfo, is_database};

/// 2: the catalog holds node shapes (the stop rule's inputs). 3: internal LODs by geometric
/// error, and the catalog's error ladder and descent faces. 4: objects may be parts of the
/// file's objects (the catalog's `part`). 5: a grid may hold view cells only where a viewer can
/// stand (the manifest grid's `present` runs), and shards split the view cells, not the lattice.
/// 6: a lattice cell that a wall cuts is several view cells (the grid's `parts`, numbered after
/// the lattice), and a cell's sample points lie where its viewers stand.
pub const FORMAT_VERSION: u32 = 6;
pub const MANIFEST_FILE: &str = "manifest.json";
pub const TREE_FILE: &str = "tree.pages";
pub const GEOMETRY_FILE: &str = "geometry.blob";
pub const CATALOG_FILE: &str = "catalog.blob";
/// The view-invariant files: the scene as a database stores it, which a shard names and does
/// not keep, and a merge takes from the base build.
pub const SCENE_FILES: [&str; 3] = [TREE_FILE, GEOMETRY_FILE, CATALOG_FILE];
pub const TREE_KIND: [u8; 4] = *b"TREE";
pub const GEOMETRY_KIND: [u8; 4] = *b"GEOM";
pub const CATALOG_KIND: [u8; 4] = *b"CATL";
