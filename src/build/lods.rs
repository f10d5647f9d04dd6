//! The LOD stage of a build, streamed to disk so that its memory does not grow with the scene:
//!
//! 1. leaf chains, a batch of base meshes at a time (in parallel), each level encoded and
//!    appended to `geometry.blob` in base-mesh order as soon as its batch is done;
//! 2. internal chains depth first ([`crate::lod::internal_lods`]), each node's leaf parts read
//!    back from `geometry.blob`, each finished chain spilled to a temporary blob file in the
//!    database's temporary directory;
//! 3. the byte budget's trim ([`crate::lod::budget_drops`]) on the chains' sizes alone, then the kept levels
//!    copied from the spill into `geometry.blob` in node order, and the spill removed.
//!
//! The geometry file is the same, byte for byte, as building every chain in memory and writing
//! it out (leaf chains in mesh order, then internal chains in node order); what is held at once
//! is one batch of leaf chains, or the parts of the nodes being built.

use std::borrow::Cow;
use std::path::Path;
use std::sync::Mutex;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::format::catalog::LodRef;
use crate::lod::hlod::LevelSize;
use crate::lod::{LeafChains, LodLevel, LodParams, budget_drops, internal_lods, leaf_chain};
use crate::progress::Report;
use crate::rtree::RTree;
use crate::scene::{Mesh, Scene};
use hdov_storage::{AppendedRecords, BlobRef, BlobWriter};

/// Base meshes simplified per batch: enough to keep every core busy, few enough that a
/// batch's encoded chains stay small beside the scene.
const LEAF_BATCH: usize = 256;

/// The spill file of internal chains, inside the build's temporary directory.
const SPILL_FILE: &str = "internal-lods.spill";
const SPILL_KIND: [u8; 4] = *b"SPIL";

/// Where every stored LOD level lies in `geometry.blob`.
pub(crate) struct StoredLods {
    /// Per base mesh, finest first.
    pub mesh_lods: Vec<Vec<LodRef>>,
    /// Per tree node, finest first (after the trim).
    pub node_lods: Vec<Vec<LodRef>>,
    /// Reads back what was appended to `geometry.blob`.
    pub geometry: AppendedRecords,
}

impl StoredLods {
    /// Every base mesh's leaf chain, decoded from `geometry.blob` (for drawing by LOD on the
    /// GPU, which holds them all).
    pub fn leaf_chains(&self, path: &Path) -> Result<Vec<Vec<LodLevel>>> {
        let reader = StoredLeafChains { refs: &self.mesh_lods, geometry: &self.geometry, path };
        (0..self.mesh_lods.len() as u32).map(|m| reader.chain(m).map(Cow::into_owned)).collect()
    }
}

/// One level encoded for the geometry file, with what the catalog and the trim need of it.
struct Encoded {
    bytes: Vec<u8>,
    faces: usize,
    error: f32,
    size: LevelSize,
}

fn encode(level: &LodLevel, path: &Path) -> Result<Encoded> {
    Ok(Encoded {
        bytes: crate::record::encode(&level.mesh, path)?,
        faces: level.faces(),
        error: level.error,
        size: LevelSize::of(level),
    })
}

fn lod_ref(level: &Encoded, r: BlobRef) -> LodRef {
    LodRef { faces: level.faces as u32, error: level.error, offset: r.offset, len: r.len }
}

/// Builds every leaf and internal LOD of `scene` and appends them to `geometry` (whose path is
/// `geometry_path`, in the build's temporary directory `dir`). `progress` advances by one per
/// base mesh and per node.
pub(crate) fn build_and_store(
    scene: &Scene,
    tree: &RTree,
    params: &LodParams,
    dir: &Path,
    geometry: &mut BlobWriter,
    geometry_path: &Path,
    progress: &dyn Report,
) -> Result<StoredLods> {
    let mut mesh_lods = Vec::with_capacity(scene.meshes.len());
    let mut leaf_bytes = 0usize;
    for batch in scene.meshes.chunks(LEAF_BATCH) {
        let chains: Vec<Vec<Encoded>> = batch
            .par_iter()
            .map(|m| {
                let chain = leaf_chain(&m.mesh, params).iter().map(|l| encode(l, geometry_path)).collect();
                progress.advance(1);
                chain
            })
            .collect::<Result<_>>()?;
        for chain in chains {
            leaf_bytes += chain.iter().map(|l| l.size.bytes).sum::<usize>();
            mesh_lods.push(chain.iter().map(|l| Ok(lod_ref(l, geometry.append(&l.bytes)?))).collect::<Result<_>>()?);
        }
    }
    let reader = geometry.reader()?;

    let spill_path = dir.join(SPILL_FILE);
    let spill = Mutex::new(BlobWriter::create(&spill_path, SPILL_KIND)?);
    let spilled: Mutex<Vec<Vec<(Encoded, BlobRef)>>> = Mutex::new((0..tree.nodes.len()).map(|_| Vec::new()).collect());
    let store = |id: usize, chain: Vec<LodLevel>| -> Result<()> {
        let mut levels = Vec::with_capacity(chain.len());
        for level in &chain {
            let mut e = encode(level, &spill_path)?;
            let r = spill.lock().expect("no panics while held").append(&e.bytes)?;
            e.bytes = Vec::new();
            levels.push((e, r));
        }
        spilled.lock().expect("no panics while held")[id] = levels;
        Ok(())
    };
    let leaf = StoredLeafChains { refs: &mesh_lods, geometry: &reader, path: geometry_path };
    internal_lods(scene, tree, params, &leaf, progress, &store)?;
    let spilled = spilled.into_inner().expect("no panics while held");
    let mut spill = spill.into_inner().expect("no panics while held");
    let sizes: Vec<Vec<LevelSize>> = spilled.iter().map(|c| c.iter().map(|(e, _)| e.size).collect()).collect();
    let drops = budget_drops(params, &sizes, tree, leaf_bytes);
    let from_spill = spill.reader()?;
    let mut node_lods = Vec::with_capacity(spilled.len());
    for (chain, drop) in spilled.iter().zip(drops) {
        let kept = chain[drop..].iter().map(|(e, r)| Ok(lod_ref(e, geometry.append(&from_spill.read(*r)?)?)));
        node_lods.push(kept.collect::<Result<Vec<_>>>()?);
    }
    drop((spill, from_spill));
    std::fs::remove_file(&spill_path).map_err(|e| Error::io(&spill_path, e))?;
    Ok(StoredLods { mesh_lods, node_lods, geometry: reader })
}

/// Leaf chains read back from `geometry.blob` by their references.
struct StoredLeafChains<'a> {
    refs: &'a [Vec<LodRef>],
    geometry: &'a AppendedRecords,
    path: &'a Path,
}

impl LeafChains for StoredLeafChains<'_> {
    fn chain(&self, mesh: u32) -> Result<Cow<'_, [LodLevel]>> {
        let levels = self.refs[mesh as usize].iter().map(|r| {
            let bytes = self.geometry.read(BlobRef { offset: r.offset, len: r.len })?;
            let mesh: Mesh = crate::record::decode(&bytes, self.path, "LOD mesh")?;
            Ok(LodLevel { mesh, error: r.error })
        });
        Ok(Cow::Owned(levels.collect::<Result<_>>()?))
    }
}
