//! The catalog (`catalog.blob`, storage kind `CATL`, one bincode record): objects and where each
//! LOD level lives in `geometry.blob`. Small enough to keep in memory while a database is open.

use hdov_storage::blob::{BLOB_HEADER_LEN, RECORD_HEADER_LEN};
use serde::{Deserialize, Serialize};

/// Where one LOD level lives and what it costs to draw.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LodRef {
    /// Triangles of the level.
    pub faces: u32,
    /// The simplifier's error bound, in world units for internal LODs and mesh units for leaves.
    pub error: f32,
    /// Byte offset of its record in `geometry.blob`: unique per stored level.
    pub offset: u64,
    /// Bytes of the record's data.
    pub len: u32,
}

impl LodRef {
    /// The record in `geometry.blob`.
    pub fn blob(&self) -> hdov_storage::BlobRef {
        hdov_storage::BlobRef { offset: self.offset, len: self.len }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectRecord {
    /// Shared with every answer that returns the object (a query copies no names).
    pub name: std::sync::Arc<str>,
    pub mesh: u32,
    /// Column-major 4×4.
    pub transform: [f32; 16],
    /// Which part of the file's object `name` this is, where the build cut it.
    pub part: Option<u32>,
}

/// What the query engine needs to know of a node before reading its page: the inputs of the
/// thesis's stop rule (eq. 5.3–5.4), view-invariant, so kept in memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeShape {
    /// 0 for leaves.
    pub level: u32,
    /// Leaf nodes under the node (a leaf counts itself): m of eq. 5.3.
    pub leaves: u32,
    /// Objects under the node.
    pub objects: u32,
    /// Faces of the node's finest internal LOD over the faces of its children's finest LODs
    /// (full-detail objects for a leaf): s of eq. 5.3.
    pub face_ratio: f32,
    /// Faces of the coarsest leaf LODs of all objects under the node: with `objects`, what a
    /// barely visible object under it costs on average.
    pub coarsest_object_faces: u64,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Catalog {
    pub objects: Vec<ObjectRecord>,
    pub mesh_names: Vec<String>,
    /// Per base mesh, finest first (level 0 = full detail).
    pub mesh_lods: Vec<Vec<LodRef>>,
    /// Per node id, finest first; empty where the node has no internal LOD (a query descends).
    pub node_lods: Vec<Vec<LodRef>>,
    /// Per node id.
    pub node_shapes: Vec<NodeShape>,
    /// The errors (world units) at which [`Catalog::descent_faces`] counts faces, finest first.
    pub error_ladder: Vec<f32>,
    /// Per node id and rung of [`Catalog::error_ladder`]: the faces of all objects under the
    /// node, each at its coarsest leaf level whose world error is within the rung's. What
    /// descending would draw if every object under the node were visible, at that error.
    pub descent_faces: Vec<Vec<u64>>,
}

impl Catalog {
    /// The faces descending into node `node` would draw at world error `error`, if every object
    /// under it were visible: the table's rung at or below `error` (the finest rung's count below
    /// it, which overstates).
    pub fn descent_faces_at(&self, node: u32, error: f64) -> u64 {
        let rung = self.error_ladder.iter().rposition(|&e| f64::from(e) <= error).unwrap_or(0);
        self.descent_faces[node as usize].get(rung).copied().unwrap_or(0)
    }

    /// The leaf LOD chain of an object.
    pub fn object_lods(&self, object: u32) -> &[LodRef] {
        &self.mesh_lods[self.objects[object as usize].mesh as usize]
    }

    /// Checks internal consistency, and that the LOD references lie inside a geometry file of
    /// `geometry_len` bytes and tile its records; returns the first violation.
    pub fn check(&self, nodes: usize, geometry_len: u64) -> Result<(), String> {
        if self.node_lods.len() != nodes || self.node_shapes.len() != nodes {
            return Err(format!(
                "{} node LOD chains and {} node shapes for {nodes} nodes",
                self.node_lods.len(),
                self.node_shapes.len()
            ));
        }
        if let Some(s) = self.node_shapes.iter().find(|s| {
            s.leaves == 0
                || s.objects == 0
                || s.objects as usize > self.objects.len()
                || s.face_ratio.is_nan()
                || s.face_ratio < 0.0
        }) {
            return Err(format!("a node shape that cannot be: {s:?}"));
        }
        if self.descent_faces.len() != nodes
            || self.descent_faces.iter().any(|d| d.len() != self.error_ladder.len())
            || self.error_ladder.windows(2).any(|w| w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less))
            || self.error_ladder.iter().any(|e| !(e.is_finite() && *e > 0.0))
        {
            return Err("an error ladder or descent table that does not fit the nodes".into());
        }
        if self.mesh_lods.len() != self.mesh_names.len() {
            return Err("mesh LOD chains and mesh names differ in number".into());
        }
        if let Some(o) = self.objects.iter().find(|o| o.mesh as usize >= self.mesh_lods.len()) {
            return Err(format!("object '{}' refers to mesh {} of {}", o.name, o.mesh, self.mesh_lods.len()));
        }
        if let Some(o) = self.objects.iter().find(|o| o.transform.iter().any(|x| !x.is_finite())) {
            return Err(format!("object '{}' has a non-finite transform", o.name));
        }
        if self.mesh_lods.iter().any(Vec::is_empty) {
            return Err("a base mesh without LODs".into());
        }
        // A node may have no internal LOD (its summary would outweigh what it summarises).
        for chain in self.mesh_lods.iter().chain(self.node_lods.iter().filter(|c| !c.is_empty())) {
            if let Some(l) =
                chain.iter().find(|l| l.offset.checked_add(u64::from(l.len)).is_none_or(|e| e > geometry_len))
            {
                return Err(format!(
                    "LOD at byte {} (+{}) lies outside geometry.blob ({geometry_len} bytes)",
                    l.offset, l.len
                ));
            }
            if chain.windows(2).any(|w| w[1].faces > w[0].faces) || chain[0].faces == 0 {
                return Err("a LOD chain that is not finest first or has an empty level".into());
            }
        }
        // The records of geometry.blob are the LOD levels, back to back: sorted by offset, the
        // references (a record may be referred to more than once) tile the data exactly. A
        // damaged offset or length is refused here, naming the catalog, not on a later read.
        let mut refs: Vec<(u64, u32)> =
            self.mesh_lods.iter().chain(&self.node_lods).flatten().map(|l| (l.offset, l.len)).collect();
        refs.sort_unstable();
        refs.dedup();
        let mut end = BLOB_HEADER_LEN as u64;
        for (offset, len) in refs {
            if offset != end {
                return Err(format!("LOD at byte {offset} (+{len}) is not where a geometry.blob record starts"));
            }
            end = offset.saturating_add((RECORD_HEADER_LEN as u64) + u64::from(len));
        }
        if end != geometry_len {
            return Err(format!("LOD records end at byte {end}, geometry.blob at byte {geometry_len}"));
        }
        Ok(())
    }
}
