//! Internal LOD chains by geometric error (HLOD), as 3D Tiles' geometric error and cluster-DAG
//! LOD systems keep them.
//!
//! Every node shares one error ladder, `e_k = e_0·2^k` ([`ErrorLadder`]). Level k of a node is
//! the union of its children's coarsest levels with error ≤ `e_k/2` (an object's leaf level
//! under its transform, a child node's internal level), welded and simplified with a target
//! error of `e_k/2`: the quadric simplifier first (pruning parts smaller than the error), the
//! sloppy one where that cuts too little. Its recorded error is the simplifier's plus the worst
//! of the parts it merges, so it bounds the level's distance to full detail and a parent's error
//! is never below its children's (decision 29). A level is kept only if it cuts a quarter of the
//! faces it replaces at that error; [`trim`] then keeps the internal LODs from outweighing the
//! leaf LODs they summarise.

use std::borrow::Cow;

use super::{ChainStore, LeafChains, LodLevel, MIN_REDUCTION, simplify_to_error, weld};
use crate::error::Result;
use crate::geom::max_scale;
use crate::rtree::RTree;
use crate::scene::{Mesh, Scene};

/// A level must cut at least this share of the faces of the parts it replaces.
pub const MIN_CUT: f32 = 0.25;

/// Rungs of the ladder, finest first.
pub const LADDER_RUNGS: usize = 20;

/// The errors internal levels are built for: `e_k = e_0·2^k`, `e_0 = diagonal·2^−19`, so the
/// rungs span a 2^19 range up to the scene's size (about 4 mm to 1 km for a 2 km city).
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorLadder(pub Vec<f32>);

impl ErrorLadder {
    /// The ladder of `scene`: the one its internal LODs and its catalog's descent table share.
    pub fn of(scene: &Scene) -> ErrorLadder {
        Self::for_diagonal(scene.bounds().extent().length())
    }

    /// The ladder of a scene whose bounding box has diagonal `diagonal` (world units).
    pub fn for_diagonal(diagonal: f32) -> ErrorLadder {
        let e0 = (diagonal.max(f32::MIN_POSITIVE) * (-19f32).exp2()).max(f32::MIN_POSITIVE);
        ErrorLadder((0..LADDER_RUNGS).map(|k| e0 * (k as f32).exp2()).collect())
    }
}

/// One part of a node: an object's leaf chain under its transform, or a child node's chain;
/// finest first, errors in world units.
enum Part<'a> {
    Object { chain: Cow<'a, [LodLevel]>, transform: glam::Mat4, scale: f32 },
    Node(&'a [LodLevel]),
}

impl Part<'_> {
    /// The coarsest level with world error ≤ `error`: its index, faces and world error. An
    /// object always has one (level 0 has error 0); a child node may not.
    fn level(&self, error: f32) -> Option<(usize, usize, f32)> {
        let (chain, scale, l) = match self {
            Part::Object { chain, scale, .. } => {
                (&chain[..], *scale, chain.iter().rposition(|l| l.error * scale <= error).unwrap_or(0))
            }
            Part::Node(chain) => (*chain, 1.0, chain.iter().rposition(|l| l.error <= error)?),
        };
        Some((l, chain[l].faces(), chain[l].error * scale))
    }

    /// [`Part::level`]'s mesh in world space, faces and error.
    fn at(&self, error: f32) -> Option<(Mesh, usize, f32)> {
        let (l, faces, error) = self.level(error)?;
        let mesh = match self {
            Part::Object { chain, transform, .. } => chain[l].mesh.transformed(transform),
            Part::Node(chain) => chain[l].mesh.clone(),
        };
        Some((mesh, faces, error))
    }
}

/// Every node's chain, finest first, each handed to `store` (see [`super::depth_first`]).
/// `leaf` gives the base meshes' leaf chains. A node without a level that cuts faces (a single
/// box, say) gets one: its children's coarsest parts merged, simplified as far as the coarsest
/// rung allows.
pub fn build(
    scene: &Scene,
    tree: &RTree,
    leaf: &dyn LeafChains,
    ladder: &ErrorLadder,
    progress: &dyn crate::progress::Report,
    store: &ChainStore,
) -> Result<()> {
    super::depth_first(tree, progress, store, &|id, children| {
        let node = &tree.nodes[id];
        let parts: Vec<Part> = match node.is_leaf() {
            true => node
                .entries
                .iter()
                .map(|e| {
                    let o = &scene.objects[e.child as usize];
                    Ok(Part::Object { chain: leaf.chain(o.mesh)?, transform: o.transform, scale: max_scale(&o.transform) })
                })
                .collect::<Result<_>>()?,
            false => children.iter().map(|c| Part::Node(c)).collect(),
        };
        Ok(node_chain(&parts, ladder))
    })
}

/// One node's chain from its parts (see the module documentation).
fn node_chain(parts: &[Part], ladder: &ErrorLadder) -> Vec<LodLevel> {
    let mut coarse_first: Vec<LodLevel> = Vec::new();
    for &e in ladder.0.iter().rev() {
        let half = e / 2.0;
        let Some(replaced) = parts.iter().map(|p| p.level(half).map(|l| l.1)).sum::<Option<usize>>() else { continue };
        if replaced < 4 {
            continue;
        }
        if coarse_first.last().is_some_and(|l| replaced as f32 * (1.0 - MIN_CUT) <= l.faces() as f32) {
            // The parts at this error are no more than the coarser level already kept: a finer
            // level would not have fewer faces than it.
            continue;
        }
        let picked: Vec<(Mesh, usize, f32)> = parts.iter().filter_map(|p| p.at(half)).collect();
        let inherited = picked.iter().map(|p| p.2).fold(0.0, f32::max);
        let merged = weld(&Mesh::merged(&picked.into_iter().map(|p| p.0).collect::<Vec<_>>()));
        let Some(mut level) = simplify_to_error(&merged, half, (replaced as f32 * (1.0 - MIN_CUT)) as usize) else {
            continue;
        };
        if level.faces() as f32 > replaced as f32 * (1.0 - MIN_CUT) {
            continue;
        }
        level.error += inherited;
        // A finer level with no more faces than a coarser one makes the coarser one useless.
        while coarse_first.last().is_some_and(|l| l.faces() as f32 >= level.faces() as f32 * (1.0 - MIN_REDUCTION)) {
            coarse_first.pop();
        }
        coarse_first.push(level);
    }
    if coarse_first.is_empty() {
        coarse_first.push(fallback(parts, ladder));
    }
    coarse_first.reverse();
    coarse_first
}

/// What [`trim`] weighs of a level: its bytes ([`mesh_bytes`]) and faces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelSize {
    pub bytes: usize,
    pub faces: usize,
}

impl LevelSize {
    pub fn of(level: &LodLevel) -> LevelSize {
        LevelSize { bytes: mesh_bytes(level), faces: level.faces() }
    }
}

/// How many finest levels to drop from each chain (`sizes`, per node, finest first) so that all
/// together hold at most `bytes` bytes of mesh data: those of the highest nodes first (the
/// root's finest level is the one a query is least likely to stop at, since a node's DoV only
/// grows towards the root), the biggest first among equals. Nodes keep their coarsest level
/// while finer ones are left to drop; past that (many instances of tiny meshes, whose summaries
/// outweigh the one stored copy) nodes lose their last level too, the highest first, and a
/// query descends through them.
pub fn trim(sizes: &[Vec<LevelSize>], tree: &RTree, bytes: usize) -> Vec<usize> {
    let mut dropped = vec![0usize; sizes.len()];
    let left = |i: usize, dropped: &[usize]| sizes[i].len() - dropped[i];
    let mut total: usize = sizes.iter().flatten().map(|l| l.bytes).sum();
    for keep in [1, 0] {
        while total > bytes {
            let Some(id) = (0..sizes.len())
                .filter(|&i| left(i, &dropped) > keep)
                .max_by_key(|&i| (tree.nodes[i].level, sizes[i][dropped[i]].faces))
            else {
                break;
            };
            total -= sizes[id][dropped[id]].bytes;
            dropped[id] += 1;
        }
    }
    dropped
}

/// The bytes a level's mesh record takes in `geometry.blob`: 12 per position, and each index as
/// bincode's variable-length integer (1 byte below 251, 3 below 2^16, 5 above), which is what
/// makes a big merged mesh weigh more per face than a small one.
pub fn mesh_bytes(level: &LodLevel) -> usize {
    let index = |i: &u32| match *i {
        0..251 => 1,
        251..65_536 => 3,
        _ => 5,
    };
    level.mesh.positions.len() * 12 + level.mesh.indices.iter().map(index).sum::<usize>()
}

/// The one level of a node no rung could cut: its parts at their coarsest, merged as they are.
fn fallback(parts: &[Part], ladder: &ErrorLadder) -> LodLevel {
    let top = *ladder.0.last().expect("a ladder has rungs");
    let picked: Vec<(Mesh, usize, f32)> = parts
        .iter()
        .map(|p| match p {
            Part::Node(chain) => {
                let l = chain.last().expect("children are built first");
                (l.mesh.clone(), l.faces(), l.error)
            }
            object => object.at(top).expect("objects always have a level"),
        })
        .collect();
    let error = picked.iter().map(|p| p.2).fold(0.0, f32::max);
    LodLevel { mesh: weld(&Mesh::merged(&picked.into_iter().map(|p| p.0).collect::<Vec<_>>())), error }
}
