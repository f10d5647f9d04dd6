//! [`Info`]: what `hdov info --json` prints, as a library type that the command and the
//! experiment tools share.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::Database;
use crate::error::Result;
use crate::format::params::BuildParams;
use crate::format::{FileEntry, VisibilityInfo};
use crate::rtree::TreeStats;
use hdov_storage::{DovCodec, LayoutKind};

/// A database described: counts, grid, build parameters, files and every layout's costs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// The database's format version.
    pub format_version: u32,
    /// The hdov version that wrote it.
    pub created_by: String,
    /// Objects (instances) in the scene.
    pub objects: u64,
    /// Full-detail faces of every instance.
    pub triangles: u64,
    /// Full-detail faces of the base meshes (instances stored once).
    pub stored_triangles: u64,
    /// Distinct base meshes (each stored once).
    pub base_meshes: u64,
    /// Nodes of the R-tree.
    pub nodes: u64,
    /// View cells (0 without a grid): every cell of a regular grid, the places a viewer can
    /// stand of one found from the geometry.
    pub cells: u64,
    /// Faces over all stored LOD levels (leaf and internal).
    pub lod_triangles: u64,
    /// Bytes of `geometry.blob` holding the base meshes' leaf LOD chains (instances stored once).
    pub leaf_lod_bytes: u64,
    /// Bytes of `geometry.blob` holding the tree nodes' internal LOD chains.
    pub internal_lod_bytes: u64,
    /// The viewing grid, if the database has one.
    pub grid: Option<GridInfo>,
    /// Cube-face resolution R of the DoV measurement.
    pub resolution: Option<u32>,
    /// Shape and fill of the tree.
    pub tree: TreeStats,
    /// How the database was built.
    pub build: BuildParams,
    /// The database's files and their sizes.
    pub files: Vec<FileEntry>,
    /// What the visibility stage measured and wrote (`None`: built without visibility).
    pub visibility: Option<VisibilityInfo>,
    /// Per layout (keyed by its name in JSON).
    #[serde(with = "crate::format::by_name::keys")]
    pub layouts: BTreeMap<LayoutKind, LayoutCosts>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridInfo {
    /// `[x0, y0, z0, x1, y1, z1]`.
    pub region: [f32; 6],
    /// Cells along x, y (height layers) and z.
    pub dims: [u32; 3],
    /// Whether only some of the cells are view cells (`hdov info --cells` lists them).
    pub sparse: bool,
}

/// What one layout costs on disk and per cell flip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayoutCosts {
    /// Bytes of all the layout's files.
    pub bytes: u64,
    pub vpage_bytes: u64,
    pub index_bytes: u64,
    #[serde(with = "crate::format::by_name::one")]
    pub dov_codec: DovCodec,
    pub visible_nodes_per_cell: MeanMax,
    /// Storage per visible (node, cell) pair: what the layout pays for visibility.
    pub bytes_per_visible_vpage: f64,
    /// Pages a cell flip reads.
    pub flip_pages: MeanMax,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeanMax {
    pub mean: f64,
    pub max: u32,
}

impl Database {
    /// Describes the database (from the manifest and each layout's metadata; no page read).
    pub fn info(&self) -> Result<Info> {
        let m = self.manifest();
        let c = &m.counts;
        let mut layouts = BTreeMap::new();
        for kind in self.layouts() {
            let s = self.layout(kind)?.summary();
            let written = m.visibility.iter().flat_map(|v| &v.layouts).find(|l| l.name == kind.name());
            let visible_pages = (s.visible_nodes_mean * f64::from(s.cell_count)).max(1.0);
            layouts.insert(
                kind,
                LayoutCosts {
                    bytes: s.bytes,
                    vpage_bytes: written.map_or(0, |l| l.vpage_bytes),
                    index_bytes: written.map_or(0, |l| l.index_bytes),
                    dov_codec: s.dov,
                    visible_nodes_per_cell: MeanMax { mean: s.visible_nodes_mean, max: s.visible_nodes_max },
                    bytes_per_visible_vpage: s.bytes as f64 / visible_pages,
                    flip_pages: MeanMax { mean: s.flip_pages_mean, max: s.flip_pages_max },
                },
            );
        }
        Ok(Info {
            format_version: m.format_version,
            created_by: m.created_by.clone(),
            objects: c.objects,
            triangles: c.triangles,
            stored_triangles: c.stored_triangles,
            base_meshes: c.base_meshes,
            nodes: c.nodes,
            cells: m.grid.as_ref().map_or(0, |g| g.present_count() as u64),
            lod_triangles: c.lod_triangles,
            leaf_lod_bytes: self.catalog().mesh_lods.iter().flatten().map(|l| u64::from(l.len)).sum(),
            internal_lod_bytes: self.catalog().node_lods.iter().flatten().map(|l| u64::from(l.len)).sum(),
            grid: m.grid.as_ref().map(|g| GridInfo { region: g.region.to_array(), dims: g.dims, sparse: g.present.is_some() }),
            resolution: m.build.visibility.as_ref().map(|v| v.resolution),
            tree: m.tree.clone(),
            build: m.build.clone(),
            files: m.files.clone(),
            visibility: m.visibility.clone(),
            layouts,
        })
    }
}
