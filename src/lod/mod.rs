//! Levels of detail with meshoptimizer's simplifiers (`meshopt` crate).
//!
//! *Leaf LODs*: per base mesh, a chain from full detail down by a constant ratio (½ by default)
//! to a few dozen faces, built with the quadric-error simplifier; meshes are welded on position
//! first because flat-shaded exports repeat every corner and would otherwise not simplify.
//! *Internal LODs*, per tree node in world space: by geometric error ([`hlod`], the default:
//! levels whose errors double, each from the children's levels at the matching error), or the
//! thesis's §5.6 ([`InternalLods::Thesis`]): the aggregate of the children's coarsest LODs
//! simplified with the sloppy simplifier, which handles merged disjoint parts, so that a
//! parent's finest LOD has fewer faces than the sum of its children's coarsest.
//! Every level keeps its absolute error (mesh units for leaf levels, world units for internal
//! ones, which include the error of the simplified parts they merge).

pub mod hlod;

use std::borrow::Cow;

use meshopt::{SimplifyOptions, VertexDataAdapter};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::format::params::{InternalLods, LodParams};
use crate::error::Result;
use crate::geom::max_scale;
use crate::progress::Report;
use crate::rtree::RTree;
use crate::scene::{Mesh, Scene};

/// One level: the simplified mesh and its error bound (absolute; mesh units for leaf levels,
/// world units for internal ones, which include the error of the simplified parts they merge).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LodLevel {
    pub mesh: Mesh,
    pub error: f32,
}

impl LodLevel {
    pub fn faces(&self) -> usize {
        self.mesh.triangle_count()
    }
}

/// A level counts only if it drops at least this share of the faces of the level before;
/// below it the simplifier is stuck (e.g. a box cannot lose faces) and the chain ends.
pub(crate) const MIN_REDUCTION: f32 = 0.1;

/// The LODs of a whole scene.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneLods {
    /// Per base mesh, finest first; level 0 is the welded full mesh (error 0).
    pub leaf: Vec<Vec<LodLevel>>,
    /// Per tree node (by node id), finest first, in world space.
    pub internal: Vec<Vec<LodLevel>>,
}

/// Builds every leaf and internal LOD in memory. `progress` advances by one per base mesh and
/// per node. (A database build streams them to disk instead: `build::lods`.)
pub fn build_scene_lods(scene: &Scene, tree: &RTree, params: &LodParams, progress: &dyn Report) -> SceneLods {
    let leaf: Vec<Vec<LodLevel>> = scene
        .meshes
        .par_iter()
        .map(|m| {
            let chain = leaf_chain(&m.mesh, params);
            progress.advance(1);
            chain
        })
        .collect();
    let built = std::sync::Mutex::new(vec![Vec::new(); tree.nodes.len()]);
    let store = |id: usize, chain: Vec<LodLevel>| {
        built.lock().expect("no panics while held")[id] = chain;
        Ok(())
    };
    internal_lods(scene, tree, params, &leaf, progress, &store).expect("in-memory chains cannot fail");
    let mut internal = built.into_inner().expect("no panics while held");
    let sizes: Vec<Vec<hlod::LevelSize>> =
        internal.iter().map(|c| c.iter().map(hlod::LevelSize::of).collect()).collect();
    let leaf_bytes: usize = leaf.iter().flatten().map(hlod::mesh_bytes).sum();
    for (chain, drop) in internal.iter_mut().zip(budget_drops(params, &sizes, tree, leaf_bytes)) {
        chain.drain(..drop);
    }
    SceneLods { leaf, internal }
}

/// How many finest levels each internal chain (`sizes`, per node) loses to the byte budget:
/// by geometric error, the internal levels together weigh at most the leaf chains'
/// `leaf_bytes` ([`hlod::trim`]); the thesis's chains are kept whole.
pub fn budget_drops(params: &LodParams, sizes: &[Vec<hlod::LevelSize>], tree: &RTree, leaf_bytes: usize) -> Vec<usize> {
    match params.internal {
        InternalLods::Hlod => hlod::trim(sizes, tree, leaf_bytes),
        InternalLods::Thesis => vec![0; sizes.len()],
    }
}

/// Where a node's parts find the leaf chains of its objects' base meshes: in memory, or read
/// back from what a build has written.
pub trait LeafChains: Sync {
    /// The chain of base mesh `mesh`, finest first.
    fn chain(&self, mesh: u32) -> Result<Cow<'_, [LodLevel]>>;
}

impl LeafChains for Vec<Vec<LodLevel>> {
    fn chain(&self, mesh: u32) -> Result<Cow<'_, [LodLevel]>> {
        Ok(Cow::Borrowed(&self[mesh as usize]))
    }
}

/// Builds one node's chain from its children's (see [`depth_first`]).
pub(crate) type NodeChain<'a> = dyn Fn(usize, &[Vec<LodLevel>]) -> Result<Vec<LodLevel>> + Sync + 'a;

/// A store for finished internal chains: `store(node id, chain)`, called once per node.
pub type ChainStore<'a> = dyn Fn(usize, Vec<LodLevel>) -> Result<()> + Sync + 'a;

/// Every node's internal chain by `params.internal`, each handed to `store` (untrimmed) as
/// soon as its parent has been built from it, so only the chains along the open paths of a
/// depth-first walk are held ([`depth_first`]).
pub fn internal_lods(
    scene: &Scene,
    tree: &RTree,
    params: &LodParams,
    leaf: &dyn LeafChains,
    progress: &dyn Report,
    store: &ChainStore,
) -> Result<()> {
    match params.internal {
        InternalLods::Hlod => hlod::build(scene, tree, leaf, &hlod::ErrorLadder::of(scene), progress, store),
        InternalLods::Thesis => thesis_internal(scene, tree, leaf, params, progress, store),
    }
}

/// The thesis's internal LODs (§5.6): each node from its children's coarsest levels.
fn thesis_internal(
    scene: &Scene,
    tree: &RTree,
    leaf: &dyn LeafChains,
    params: &LodParams,
    progress: &dyn Report,
    store: &ChainStore,
) -> Result<()> {
    depth_first(tree, progress, store, &|id, children| {
        let node = &tree.nodes[id];
        // Each part with its error against full detail, in world units.
        let mut parts = Vec::with_capacity(node.entries.len());
        let mut errors = Vec::with_capacity(node.entries.len());
        for (i, e) in node.entries.iter().enumerate() {
            if node.is_leaf() {
                let o = &scene.objects[e.child as usize];
                let chain = leaf.chain(o.mesh)?;
                let coarsest = chain.last().expect("chains are never empty");
                parts.push(coarsest.mesh.transformed(&o.transform));
                errors.push(coarsest.error * max_scale(&o.transform));
            } else {
                let coarsest = children[i].last().expect("children are simplified before their parent");
                parts.push(coarsest.mesh.clone());
                errors.push(coarsest.error);
            }
        }
        let mut chain = aggregate_chain(&parts, params);
        // The simplifier measures against the parts, which are already simplified: a
        // level's error against full detail is at most its own plus the parts' worst.
        let inherited = errors.into_iter().fold(0.0, f32::max);
        for level in &mut chain {
            level.error += inherited;
        }
        Ok(chain)
    })
}

/// Every node's chain, built depth first from the root (a node's children in parallel, then
/// the node from their chains): `chain(node, children's chains in entry order)`, with none for
/// a leaf. Each chain goes to `store` once its parent is built, the root's last, so the chains
/// held at once are those of the children of the nodes being built — a few per tree level and
/// thread — whatever the tree's size.
pub(crate) fn depth_first(
    tree: &RTree,
    progress: &dyn Report,
    store: &ChainStore,
    chain: &NodeChain,
) -> Result<()> {
    fn visit(
        id: usize,
        tree: &RTree,
        progress: &dyn Report,
        store: &ChainStore,
        chain: &NodeChain,
    ) -> Result<Vec<LodLevel>> {
        let node = &tree.nodes[id];
        let children: Vec<Vec<LodLevel>> = match node.is_leaf() {
            true => Vec::new(),
            false => node
                .entries
                .par_iter()
                .map(|e| visit(e.child as usize, tree, progress, store, chain))
                .collect::<Result<_>>()?,
        };
        let own = chain(id, &children)?;
        progress.advance(1);
        for (e, c) in node.entries.iter().zip(children) {
            store(e.child as usize, c)?;
        }
        Ok(own)
    }
    if tree.nodes.is_empty() {
        return Ok(());
    }
    let root = visit(0, tree, progress, store, chain)?;
    store(0, root)
}

/// The one rule that picks a level of a LOD chain (thesis eq. 5.5 and 5.6): interpolate in
/// face count, `k·faces(finest) + (1 − k)·faces(coarsest)` with `k` clamped to [0, 1], and
/// take the stored level nearest to it (the finer one on a tie). `faces(i)` gives level i's
/// faces, finest first; `levels` ≥ 1. O(levels).
pub fn pick_level(levels: usize, faces: impl Fn(usize) -> u64, k: f64) -> usize {
    let last = levels.saturating_sub(1);
    let k = if k.is_nan() { 0.0 } else { k.clamp(0.0, 1.0) };
    let target = k * faces(0) as f64 + (1.0 - k) * faces(last) as f64;
    (0..=last)
        .min_by(|&a, &b| (faces(a) as f64 - target).abs().total_cmp(&(faces(b) as f64 - target).abs()))
        .unwrap_or(0)
}

/// The error-budget rule that picks a level for drawing from one viewpoint: the coarsest level
/// whose error (`errors`, finest first, in the units of `budget`) is below `budget`; level 0
/// (full detail) when none is. O(levels).
pub fn coarsest_below(errors: impl DoubleEndedIterator<Item = f32> + ExactSizeIterator, budget: f32) -> usize {
    let last = errors.len().saturating_sub(1);
    errors.rev().position(|e| e < budget).map_or(0, |from_end| last - from_end)
}

/// The leaf chain of one mesh: full detail, then each level ≈ `ratio` of the one before.
pub fn leaf_chain(mesh: &Mesh, params: &LodParams) -> Vec<LodLevel> {
    let full = weld(mesh);
    let mut chain = vec![LodLevel { mesh: full.clone(), error: 0.0 }];
    while chain.last().unwrap().faces() > params.min_faces {
        let prev = chain.last().unwrap();
        let target = ((prev.faces() as f32 * params.ratio) as usize).max(1);
        let enough = |l: &LodLevel| l.faces() as f32 <= prev.faces() as f32 * (1.0 - MIN_REDUCTION);
        // Simplify from the full mesh each time, so errors do not compound across levels. Where
        // topology stops the quadric simplifier (seams, borders), the sloppy one goes on.
        let level =
            simplify(&full, target, false).filter(enough).or_else(|| simplify(&full, target, true).filter(enough));
        let Some(level) = level else { break };
        chain.push(level);
    }
    chain
}

/// The internal chain of a node from its children's coarsest meshes (world space). The finest
/// level has fewer faces than all parts together (when they have more than one face).
pub fn aggregate_chain(parts: &[Mesh], params: &LodParams) -> Vec<LodLevel> {
    let merged = weld(&Mesh::merged(parts));
    let total = merged.triangle_count();
    let mut chain: Vec<LodLevel> = Vec::new();
    let mut target = ((total as f32 * params.ratio) as usize).clamp(1, total.saturating_sub(1).max(1));
    while let Some(level) = simplify(&merged, target, true) {
        let prev = chain.last().map_or(total, |l| l.faces());
        if !chain.is_empty() && level.faces() as f32 > prev as f32 * (1.0 - MIN_REDUCTION) {
            break;
        }
        let faces = level.faces();
        chain.push(level);
        if faces <= params.min_faces {
            break;
        }
        target = ((faces as f32 * params.ratio) as usize).max(1);
    }
    if chain.is_empty() {
        // Nothing simplifies (a single triangle): the node's LOD is its geometry as it is.
        chain.push(LodLevel { mesh: merged, error: 0.0 });
    }
    chain
}

/// The simplest version of `mesh` within absolute error `error` (mesh units): the quadric
/// simplifier, pruning parts smaller than the error; where that leaves more than `enough`
/// faces, the sloppy simplifier too, and the one with fewer faces. The level's error is what
/// the simplifier reports. `None` when nothing is left.
pub(crate) fn simplify_to_error(mesh: &Mesh, error: f32, enough: usize) -> Option<LodLevel> {
    let adapter = VertexDataAdapter::new(bytemuck::cast_slice(&mesh.positions), 12, 0).ok()?;
    let opts = SimplifyOptions::ErrorAbsolute | SimplifyOptions::Prune;
    let mut reached = 0.0f32;
    let indices = meshopt::simplify(&mesh.indices, &adapter, 0, error, opts, Some(&mut reached));
    let mut best = (!indices.is_empty()).then_some((indices, reached));
    if best.as_ref().is_none_or(|(i, _)| i.len() / 3 > enough) {
        let scale = meshopt::simplify_scale(&adapter);
        if scale > 0.0 {
            let mut relative = 0.0f32;
            let sloppy = meshopt::simplify_sloppy(&mesh.indices, &adapter, 0, error / scale, Some(&mut relative));
            if !sloppy.is_empty() && best.as_ref().is_none_or(|(i, _)| sloppy.len() < i.len()) {
                best = Some((sloppy, relative * scale));
            }
        }
    }
    let (mut indices, error) = best?;
    let positions = meshopt::optimize_vertex_fetch(&mut indices, &mesh.positions);
    Some(LodLevel { mesh: Mesh { positions, indices }, error: error * ERROR_MARGIN })
}

/// The simplifiers' reported errors are estimates (the quadric one measures distance to the
/// planes of the faces it removed, the sloppy one a grid cell's size), not bounds: sampled
/// distances to the full detail reached 1.04× the estimate on tests/hlod.rs's scenes. Internal
/// levels record 1.5× it, so that their error bounds the distance (tested).
const ERROR_MARGIN: f32 = 1.5;

/// One simplification to about `target` faces; `sloppy` for merged disjoint parts. The result
/// is compacted to the vertices it uses. `None` when nothing is left.
fn simplify(mesh: &Mesh, target: usize, sloppy: bool) -> Option<LodLevel> {
    let adapter = VertexDataAdapter::new(bytemuck::cast_slice(&mesh.positions), 12, 0).ok()?;
    let mut error = 0.0f32;
    let target_indices = target * 3;
    let mut indices = if sloppy {
        meshopt::simplify_sloppy(&mesh.indices, &adapter, target_indices, f32::MAX, Some(&mut error))
    } else {
        let opts = SimplifyOptions::ErrorAbsolute | SimplifyOptions::Prune;
        meshopt::simplify(&mesh.indices, &adapter, target_indices, f32::MAX, opts, Some(&mut error))
    };
    if indices.is_empty() {
        return None;
    }
    if sloppy {
        // The sloppy simplifier reports relative error; scale it to mesh units.
        error *= meshopt::simplify_scale(&adapter);
    }
    let positions = meshopt::optimize_vertex_fetch(&mut indices, &mesh.positions);
    Some(LodLevel { mesh: Mesh { positions, indices }, error })
}

/// Merges vertices with equal positions, so that the simplifier sees connected surfaces.
pub fn weld(mesh: &Mesh) -> Mesh {
    let (count, remap) = meshopt::generate_vertex_remap(&mesh.positions, Some(&mesh.indices));
    Mesh {
        positions: meshopt::remap_vertex_buffer(&mesh.positions, count, &remap),
        indices: meshopt::remap_index_buffer(Some(&mesh.indices), count, &remap),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UV sphere of about `2·n²` triangles, flat-shaded (every triangle has its own corners).
    pub fn sphere(n: usize) -> Mesh {
        let mut m = Mesh::default();
        let p = |i: usize, j: usize| {
            let (t, f) = (std::f32::consts::PI * i as f32 / n as f32, std::f32::consts::TAU * j as f32 / n as f32);
            [t.sin() * f.cos(), t.cos(), t.sin() * f.sin()]
        };
        for i in 0..n {
            for j in 0..n {
                for tri in [[p(i, j), p(i + 1, j), p(i + 1, j + 1)], [p(i, j), p(i + 1, j + 1), p(i, j + 1)]] {
                    let b = m.positions.len() as u32;
                    m.positions.extend(tri);
                    m.indices.extend([b, b + 1, b + 2]);
                }
            }
        }
        m
    }

    #[test]
    fn coarsest_below_takes_the_coarsest_level_under_the_budget() {
        let errors = [0.0, 0.1, 0.4, 2.0];
        let pick = |budget| coarsest_below(errors.iter().copied(), budget);
        assert_eq!(pick(0.0), 0, "no level is below a zero budget: full detail");
        assert_eq!(pick(0.05), 0);
        assert_eq!(pick(0.1), 0, "the budget is exclusive");
        assert_eq!(pick(0.2), 1);
        assert_eq!(pick(1.0), 2);
        assert_eq!(pick(f32::INFINITY), 3);
        assert_eq!(coarsest_below(std::iter::empty(), 1.0), 0);
    }

    #[test]
    fn leaf_chain_is_monotone_and_ends_small() {
        let chain = leaf_chain(&sphere(60), &LodParams::default());
        assert!(chain.len() >= 5, "{} levels", chain.len());
        assert_eq!(chain[0].error, 0.0);
        for w in chain.windows(2) {
            assert!(w[1].faces() < w[0].faces(), "faces must fall: {} then {}", w[0].faces(), w[1].faces());
            assert!(w[1].error >= w[0].error, "error must not fall: {} then {}", w[0].error, w[1].error);
            w[1].mesh.check().unwrap();
        }
        let faces: Vec<usize> = chain.iter().map(|l| l.faces()).collect();
        assert!(chain.last().unwrap().faces() <= 64, "{faces:?}");
        // Errors are absolute: a coarse sphere of radius 1 deviates by a sizeable fraction of it.
        assert!(chain.last().unwrap().error > 0.01 && chain.last().unwrap().error < 1.0);
    }

    #[test]
    fn aggregate_finest_is_below_the_sum_of_parts() {
        let parts: Vec<Mesh> = (0..6)
            .map(|i| {
                leaf_chain(&sphere(12), &LodParams::default())
                    .pop()
                    .unwrap()
                    .mesh
                    .transformed(&glam::Mat4::from_translation(glam::Vec3::X * 3.0 * i as f32))
            })
            .collect();
        let sum: usize = parts.iter().map(|p| p.triangle_count()).sum();
        let chain = aggregate_chain(&parts, &LodParams::default());
        assert!(chain[0].faces() < sum, "{} !< {sum}", chain[0].faces());
        for w in chain.windows(2) {
            assert!(w[1].faces() < w[0].faces());
        }
    }

    #[test]
    fn scene_lods_respect_the_parent_rule() {
        use crate::scene::{BaseMesh, Object};
        let scene = Scene {
            meshes: vec![BaseMesh { name: "s".into(), mesh: sphere(16) }],
            objects: (0..40)
                .map(|i| Object {
                    name: format!("o{i}"),
                    mesh: 0,
                    transform: glam::Mat4::from_scale_rotation_translation(
                        glam::Vec3::splat(2.0),
                        glam::Quat::from_rotation_y(i as f32),
                        glam::Vec3::new((i % 8) as f32 * 6.0, 0.0, (i / 8) as f32 * 6.0),
                    ),
                    part: None,
                })
                .collect(),
            grid: None,
        };
        let tree = RTree::build(&scene.all_object_bounds(), 4, crate::rtree::TreeAlgorithm::Str);
        let thesis = LodParams { internal: InternalLods::Thesis, ..Default::default() };
        let lods = build_scene_lods(&scene, &tree, &thesis, &crate::progress::Quiet);
        assert_eq!(lods.leaf.len(), 1, "instanced geometry is simplified once");
        for (id, node) in tree.nodes.iter().enumerate() {
            let children: usize = node
                .entries
                .iter()
                .map(|e| {
                    if node.is_leaf() {
                        lods.leaf[0].last().unwrap().faces()
                    } else {
                        lods.internal[e.child as usize].last().unwrap().faces()
                    }
                })
                .sum();
            assert!(
                lods.internal[id][0].faces() < children,
                "node {id}: {} !< {children}",
                lods.internal[id][0].faces()
            );
            // Errors are against full detail: every level at least the worst part's, which
            // is already simplified (objects scaled ×2 below: their error doubles).
            let worst_part = node
                .entries
                .iter()
                .map(|e| {
                    if node.is_leaf() {
                        lods.leaf[0].last().unwrap().error * 2.0
                    } else {
                        lods.internal[e.child as usize].last().unwrap().error
                    }
                })
                .fold(0.0, f32::max);
            assert!(worst_part > 0.0);
            for level in &lods.internal[id] {
                assert!(level.error >= worst_part, "node {id}: {} < {worst_part}", level.error);
            }
        }
    }
}
