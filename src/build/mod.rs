//! The writer: a database from a scene in stages — R-tree (bulk load), leaf and internal LODs,
//! DoV per cell, V-pages in every chosen layout — all into a temporary directory that becomes
//! the database only when every file is complete and synced ([`hdov_storage::DirTxn`]).
//!
//! - [`params`]: what a build takes, with its bounds, checked before any work;
//! - `lods`: leaf and internal LODs, streamed into the geometry file as they are built;
//! - [`vpages`]: from per-cell DoV to V-pages and back;
//! - [`merge`]: shard databases joined into one.

mod lods;
pub mod merge;
pub mod vpages;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::dov::gpu::GpuOptions;
use crate::dov::precompute::{PrecomputeOptions, TreeShape, precompute_shard};
use crate::dov::{WithRays, open_backend};
use crate::error::{Error, Param, Result};
use crate::format::catalog::{Catalog, LodRef, NodeShape, ObjectRecord};
pub use crate::format::params::{BuildParams, DEFAULT_FANOUT, ObjectParts, VisibilityParams, limits};
use crate::format::tree_page::{self, NodePage};
use crate::format::{
    CATALOG_FILE, CATALOG_KIND, Counts, FORMAT_VERSION, FileChecksum, FileEntry, GEOMETRY_FILE, GEOMETRY_KIND, LayoutInfo,
    LeftOutLayout, MANIFEST_FILE, Manifest, SCENE_FILES, TREE_FILE, TREE_KIND, VisibilityInfo, is_database,
};
use crate::grid::ViewGrid;
use crate::lod::LodLevel;
use crate::progress::Progress;
use crate::rtree::RTree;
use crate::scene::Scene;
use crate::overwrite::Overwrite;
use hdov_storage::{BlobWriter, DirTxn, LayoutOptions, PageFileWriter, VData, VShape, write_layout};

/// What a build did and how long each stage took.
#[derive(Clone, Debug, Serialize)]
pub struct BuildReport {
    /// The manifest written.
    pub manifest: Manifest,
    /// Seconds spent building the tree.
    pub tree_seconds: f64,
    /// Seconds spent building the leaf and internal LODs.
    pub lod_seconds: f64,
    /// Seconds spent writing the files (visibility included).
    pub write_seconds: f64,
    /// Leftovers of builds that died (temporary folders beside the target), removed.
    pub cleaned: Vec<PathBuf>,
    /// A database that a build which died mid-replace had moved aside, put back before this
    /// build began (only where directories cannot be swapped atomically).
    pub restored: Option<PathBuf>,
}

/// Claims `out` for writing: refuses an existing `out` unless `overwrite` allows ours and it is an hdov
/// database or an empty directory; removes leftovers of dead builds beside it.
pub(crate) fn begin_write(out: &Path, overwrite: Overwrite) -> Result<DirTxn> {
    let overwrite = match overwrite {
        Overwrite::Never => hdov_storage::Overwrite::Never,
        Overwrite::Ours => hdov_storage::Overwrite::IfOurs(is_database),
    };
    Ok(DirTxn::begin(out, overwrite)?)
}

/// Builds the database for `scene` at `out`.
///
/// Every parameter, the scene and the grid are checked first, then the target is claimed: an
/// existing `out` is refused unless `overwrite` is [`Overwrite::Ours`] and `out` is an hdov database or an empty
/// directory (a folder of anything else is never touched). On any error, and if the process
/// dies, `out` is left as it was. Costs the tree (O(n log n)), the LODs (meshopt, linear in the
/// faces) and, with visibility, one cube map per distinct sample point.
pub fn build(
    scene: &Scene,
    out: &Path,
    params: &BuildParams,
    overwrite: Overwrite,
    progress: &Progress,
) -> Result<BuildReport> {
    check_inputs(scene, params)?;
    let scene = &*objects_of(scene, params);
    let fanout = params.max_entries();
    // Claim the target first: a refusal must come before minutes of work, not after.
    let txn = begin_write(out, overwrite)?;
    let (cleaned, restored) = (txn.cleaned().to_vec(), txn.restored().map(Path::to_path_buf));

    let t = Instant::now();
    let boxes = scene.all_object_bounds();
    let tree = RTree::build(&boxes, fanout, params.tree);
    let tree_seconds = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let dir = txn.path().to_path_buf();
    let geometry_path = dir.join(GEOMETRY_FILE);
    let mut geometry = BlobWriter::create(&geometry_path, GEOMETRY_KIND)?;
    let bar = progress.bar("LODs", (scene.meshes.len() + tree.nodes.len()) as u64);
    let stored = lods::build_and_store(scene, &tree, &params.lod, &dir, &mut geometry, &geometry_path, &bar)?;
    bar.finish_and_clear();
    geometry.finish()?;
    let lod_seconds = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let ladder = crate::lod::hlod::ErrorLadder::of(scene);
    // Drawing by LOD on the GPU needs the leaf chains in memory; nothing else does.
    let draws_lods = params.visibility.as_ref().is_some_and(VisibilityParams::draws_lods);
    let leaf_lods = if draws_lods { Some(stored.leaf_chains(&geometry_path)?) } else { None };
    let lods::StoredLods { mesh_lods, node_lods, .. } = stored;

    write_tree(&dir, &tree, params.page_size)?;

    let catalog = Catalog {
        objects: scene
            .objects
            .iter()
            .map(|o| ObjectRecord {
                name: o.name.as_str().into(),
                mesh: o.mesh,
                transform: o.transform.to_cols_array(),
                part: o.part,
            })
            .collect(),
        mesh_names: scene.meshes.iter().map(|m| m.name.clone()).collect(),
        node_shapes: node_shapes(&tree, scene, &mesh_lods, &node_lods),
        descent_faces: descent_faces(&tree, scene, &mesh_lods, &ladder.0),
        error_ladder: ladder.0,
        mesh_lods,
        node_lods,
    };
    let mut cat = BlobWriter::create(&dir.join(CATALOG_FILE), CATALOG_KIND)?;
    let bytes = crate::record::encode(&catalog, &dir.join(CATALOG_FILE))?;
    cat.append(&bytes)?;
    cat.finish()?;

    let visibility = match (&params.visibility, &scene.grid) {
        (Some(v), Some(grid)) => {
            Some(build_visibility(scene, &tree, leaf_lods.as_deref(), grid, v, params.page_size, &dir, progress)?)
        }
        _ => None,
    };

    let lod_triangles = catalog.mesh_lods.iter().chain(&catalog.node_lods).flatten().map(|l| l.faces as u64).sum();
    let mut manifest = Manifest {
        hdov: Manifest::MAGIC.into(),
        format_version: FORMAT_VERSION,
        created_by: format!("hdov {}", env!("CARGO_PKG_VERSION")),
        // What was built: without a grid there is no visibility to have parameters for.
        build: BuildParams { visibility: visibility.as_ref().and(params.visibility.clone()), ..params.clone() },
        counts: Counts {
            objects: scene.objects.len() as u64,
            base_meshes: scene.meshes.len() as u64,
            triangles: scene.triangle_count(),
            stored_triangles: scene.stored_triangle_count(),
            nodes: tree.nodes.len() as u64,
            cells: scene.grid.as_ref().map_or(0, |g| g.cell_count() as u64),
            lod_triangles,
        },
        tree: tree.stats(),
        grid: scene.grid.clone(),
        files: Vec::new(),
        visibility,
        measured_against: None,
    };
    let is_shard = manifest.build.visibility.as_ref().is_some_and(|v| v.shard.is_some());
    let mut against = Vec::new();
    for name in SCENE_FILES {
        let path = dir.join(name);
        if is_shard {
            // A shard keeps its V-data only: the scene's files are named, not stored, and the
            // merge takes them from a base build (docs/sharding.md).
            against.push(FileChecksum::of(&dir, name)?);
            std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
        } else {
            let bytes = std::fs::metadata(&path).map_err(|e| Error::io(&path, e))?.len();
            manifest.files.push(FileEntry { name: name.into(), bytes });
        }
    }
    manifest.measured_against = is_shard.then_some(against);
    write_manifest(&dir, &manifest)?;
    txn.commit()?;
    Ok(BuildReport { manifest, tree_seconds, lod_seconds, write_seconds: t.elapsed().as_secs_f64(), cleaned, restored })
}

/// The scene, the parameters and the grid, checked before any work.
fn check_inputs(scene: &Scene, params: &BuildParams) -> Result<()> {
    scene.check().map_err(|r| Error::bad_param(Param::Scene, r))?;
    params.check(scene.grid.as_ref())
}

/// The scene a database built from `scene` with `params` holds, object for object (its object
/// ids are the database's): the file's objects, or with [`ObjectParts::Geometry`] and a grid,
/// those far larger than a cell cut into parts of two cells
/// ([`crate::scene::parts::split_large_objects`]). What to measure a database against.
pub fn objects_of<'a>(scene: &'a Scene, params: &BuildParams) -> std::borrow::Cow<'a, Scene> {
    match (params.objects, &scene.grid) {
        (ObjectParts::Geometry, Some(grid)) => {
            let extent = crate::scene::parts::part_extent_for_cells(grid.cell_size().max_element());
            std::borrow::Cow::Owned(crate::scene::parts::split_large_objects(scene, extent))
        }
        _ => std::borrow::Cow::Borrowed(scene),
    }
}

/// Writes `tree.pages`: one node per page, in node-id order.
fn write_tree(dir: &Path, tree: &RTree, page_size: u32) -> Result<()> {
    let mut pages = PageFileWriter::create(&dir.join(TREE_FILE), TREE_KIND, page_size)?;
    let objects_under = tree.subtree_object_counts();
    let leaves_under = tree.subtree_leaf_counts();
    for (id, node) in tree.nodes.iter().enumerate() {
        let page =
            NodePage { node: node.clone(), subtree_objects: objects_under[id], subtree_leaves: leaves_under[id] };
        pages.push(&tree_page::encode(&page))?;
    }
    pages.finish()?;
    Ok(())
}

/// Builds shard `params.visibility.shard` of `scene` at `out` against the scene files of
/// `base`, a `--no-visibility` build of the same scene and parameters, instead of building the
/// tree, LODs and catalog again: the shard then costs its cells' visibility and the scene's
/// BVH, not the LODs. Its files are those [`build`] writes for the shard, byte for byte.
///
/// `base` is refused in one line unless it was built with the same parameters (visibility
/// aside), grid and counts, and its tree is the one `scene` gives (rebuilt here: milliseconds).
pub fn build_shard_on(
    scene: &Scene,
    base: &Path,
    out: &Path,
    params: &BuildParams,
    overwrite: Overwrite,
    progress: &Progress,
) -> Result<BuildReport> {
    check_inputs(scene, params)?;
    let scene = &*objects_of(scene, params);
    let (Some(v), Some(grid)) = (params.visibility.as_ref().filter(|v| v.shard.is_some()), &scene.grid) else {
        return Err(Error::bad_param(Param::Base, "a base is for shard builds: give --shard I/N"));
    };
    let db = crate::db::Database::open(base)?;
    let mut manifest = db.manifest().clone();
    let other = |what: &str| Error::bad_file(base, format!("was built from {what} than this shard's"));
    if manifest.build.without_visibility() != params.without_visibility() {
        return Err(other("other parameters"));
    }
    let counts = (scene.objects.len() as u64, scene.meshes.len() as u64, scene.triangle_count(), scene.stored_triangle_count());
    let c = &manifest.counts;
    if manifest.grid.as_ref() != Some(grid) || (c.objects, c.base_meshes, c.triangles, c.stored_triangles) != counts {
        return Err(other("another scene or grid"));
    }
    let txn = begin_write(out, overwrite)?;
    let (cleaned, restored) = (txn.cleaned().to_vec(), txn.restored().map(Path::to_path_buf));
    let dir = txn.path().to_path_buf();
    let t = Instant::now();
    let tree = RTree::build(&scene.all_object_bounds(), params.max_entries(), params.tree);
    let tree_seconds = t.elapsed().as_secs_f64();
    write_tree(&dir, &tree, params.page_size)?;
    let ours = FileChecksum::of(&dir, TREE_FILE)?;
    std::fs::remove_file(dir.join(TREE_FILE)).map_err(|e| Error::io(dir.join(TREE_FILE), e))?;
    let against = FileChecksum::of_scene_files(base)?;
    if against[0] != ours {
        return Err(Error::bad_file(base, "was built from another scene than this shard's: its tree differs"));
    }
    let t = Instant::now();
    let leaf_lods = match v.draws_lods() {
        true => Some(
            db.catalog()
                .mesh_lods
                .iter()
                .map(|chain| chain.iter().map(|l| Ok(LodLevel { mesh: db.lod_mesh(l)?, error: l.error })).collect())
                .collect::<Result<Vec<Vec<LodLevel>>>>()?,
        ),
        false => None,
    };
    let visibility = build_visibility(scene, &tree, leaf_lods.as_deref(), grid, v, params.page_size, &dir, progress)?;
    manifest.build = params.clone();
    manifest.visibility = Some(visibility);
    manifest.files = Vec::new();
    manifest.measured_against = Some(against);
    write_manifest(&dir, &manifest)?;
    txn.commit()?;
    Ok(BuildReport { manifest, tree_seconds, lod_seconds: 0.0, write_seconds: t.elapsed().as_secs_f64(), cleaned, restored })
}

/// The view-invariant inputs of the query's stop rule, per node (see [`NodeShape`]).
fn node_shapes(tree: &RTree, scene: &Scene, mesh_lods: &[Vec<LodRef>], node_lods: &[Vec<LodRef>]) -> Vec<NodeShape> {
    let leaves = tree.subtree_leaf_counts();
    let objects = tree.subtree_object_counts();
    let finest = |chain: &[LodRef]| chain.first().map_or(0, |l| u64::from(l.faces));
    let coarsest = |o: u32| mesh_lods[scene.objects[o as usize].mesh as usize].last().map_or(0, |l| u64::from(l.faces));
    // Children have larger ids than their parents: one reverse sweep sums bottom-up.
    let mut coarse = vec![0u64; tree.nodes.len()];
    for (id, node) in tree.nodes.iter().enumerate().rev() {
        coarse[id] = match node.is_leaf() {
            true => node.entries.iter().map(|e| coarsest(e.child)).sum(),
            false => node.entries.iter().map(|e| coarse[e.child as usize]).sum(),
        };
    }
    tree.nodes
        .iter()
        .enumerate()
        .map(|(id, node)| {
            let children: u64 = node
                .entries
                .iter()
                .map(|e| match node.is_leaf() {
                    true => finest(&mesh_lods[scene.objects[e.child as usize].mesh as usize]),
                    false => finest(&node_lods[e.child as usize]),
                })
                .sum();
            NodeShape {
                level: node.level,
                leaves: leaves[id],
                objects: objects[id],
                face_ratio: (finest(&node_lods[id]) as f64 / children.max(1) as f64) as f32,
                coarsest_object_faces: coarse[id],
            }
        })
        .collect()
}

/// Per node and rung of `ladder`: the faces of the objects under the node, each at its coarsest
/// leaf level within the rung's world error (see [`Catalog::descent_faces`]).
fn descent_faces(tree: &RTree, scene: &Scene, mesh_lods: &[Vec<LodRef>], ladder: &[f32]) -> Vec<Vec<u64>> {
    let object = |o: u32| -> Vec<u64> {
        let obj = &scene.objects[o as usize];
        let (chain, scale) = (&mesh_lods[obj.mesh as usize], crate::geom::max_scale(&obj.transform));
        ladder
            .iter()
            .map(|&e| {
                let l = chain.iter().rposition(|l| l.error * scale <= e).unwrap_or(0);
                u64::from(chain[l].faces)
            })
            .collect()
    };
    let add = |a: &mut Vec<u64>, b: &[u64]| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
    // Children have larger ids than their parents: one reverse sweep sums bottom-up.
    let mut out = vec![vec![0u64; ladder.len()]; tree.nodes.len()];
    for (id, node) in tree.nodes.iter().enumerate().rev() {
        let mut sum = vec![0u64; ladder.len()];
        for e in &node.entries {
            match node.is_leaf() {
                true => add(&mut sum, &object(e.child)),
                false => add(&mut sum, &out[e.child as usize]),
            }
        }
        out[id] = sum;
    }
    out
}

/// Measures DoV for the shard's cells and writes the chosen V-page layouts into `dir`.
#[allow(clippy::too_many_arguments)]
fn build_visibility(
    scene: &Scene,
    tree: &RTree,
    leaf_lods: Option<&[Vec<LodLevel>]>,
    grid: &ViewGrid,
    v: &VisibilityParams,
    page_size: u32,
    dir: &Path,
    progress: &Progress,
) -> Result<VisibilityInfo> {
    let t = Instant::now();
    let gpu = GpuOptions {
        lods: leaf_lods,
        lod_tolerance_texels: v.lod_draw_tolerance,
        region_views: v.region_views,
        ..Default::default()
    };
    let mut backend = open_backend(scene, v.resolution, v.backend, &gpu)?;
    if v.sampling.sampler().casts_rays() {
        backend = WithRays::wrap(backend, scene)?;
    }
    let bounds = scene.all_object_bounds();
    let part_neighbours = crate::scene::parts::part_neighbours(scene, &bounds);
    let part_planes = crate::scene::parts::part_planes(scene, &part_neighbours);
    let shape = TreeShape { part_neighbours, part_planes, ..TreeShape::of(tree) };
    let options = PrecomputeOptions::of(v);
    let bar = progress.bar("sample points", 0);
    let dov = precompute_shard(
        backend.as_mut(),
        grid,
        &bounds,
        &shape,
        &options,
        v.shard(),
        &bar,
    )?;
    bar.finish_and_clear();
    let data = vpages::vdata_from_cells(tree, grid.cell_count() as u32, &dov.cells);
    let opts = layout_options(page_size, v.dov_codec);
    let (kinds, left_out) = layouts_for(v, &VShape::of(&data), &opts);
    let layouts = write_layouts(dir, &kinds, &data, &opts)?;
    Ok(VisibilityInfo {
        backend: backend.name(),
        cells_computed: dov.cells.len() as u64,
        sample_points: dov.points_measured as u64,
        floored_objects: dov.cells.iter().map(|(_, c)| c.floored as u64).sum(),
        skipped_points: dov.cells.iter().map(|(_, c)| c.skipped_points as u64).sum(),
        seconds: t.elapsed().as_secs_f64(),
        phases: Some(dov.phases),
        layouts,
        left_out,
    })
}

/// Writes `manifest.json` into the directory being built (synced): the last file, whose
/// presence makes the directory a database.
pub(crate) fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<()> {
    let path = dir.join(MANIFEST_FILE);
    let json = serde_json::to_vec_pretty(manifest).map_err(|e| Error::bad_file(&path, e.to_string()))?;
    Ok(hdov_storage::write_file_synced(&path, &json)?)
}

/// How the layouts of a database with `page_size` and `codec` are written.
pub(crate) fn layout_options(page_size: u32, codec: hdov_storage::DovCodec) -> LayoutOptions {
    LayoutOptions { page_size: page_size.min(hdov_storage::layout::MAX_LAYOUT_PAGE_SIZE), dov: codec, ..Default::default() }
}

/// The manifest's entry for a written layout.
pub(crate) fn layout_info(kind: hdov_storage::LayoutKind, size: hdov_storage::LayoutSize) -> LayoutInfo {
    LayoutInfo {
        name: kind.name().to_string(),
        vpage_bytes: size.vpage_bytes,
        index_bytes: size.index_bytes,
        files: size.files.into_iter().map(|(name, bytes)| FileEntry { name, bytes }).collect(),
    }
}

/// Of the layouts `v` stores, those a build of `shape` written with `opts` writes, and those its
/// [slot budget](VisibilityParams::slot_budget) leaves out, with the bytes their slots would
/// have taken (decision 134).
pub(crate) fn layouts_for(
    v: &VisibilityParams,
    shape: &VShape,
    opts: &LayoutOptions,
) -> (Vec<hdov_storage::LayoutKind>, Vec<LeftOutLayout>) {
    let asked = v.stored_layouts();
    let budget = v.slot_budget.filter(|_| asked.contains(&hdov_storage::LayoutKind::IndexedVertical));
    let mut written = Vec::new();
    let mut left_out = Vec::new();
    for kind in asked {
        match budget.map(|b| (b, shape.slot_bytes(kind, opts))) {
            Some((b, slot_bytes)) if slot_bytes > b => {
                left_out.push(LeftOutLayout { kind, slot_bytes })
            }
            _ => written.push(kind),
        }
    }
    (written, left_out)
}

/// Writes every chosen layout of `data` into `dir`.
pub(crate) fn write_layouts(
    dir: &Path,
    kinds: &[hdov_storage::LayoutKind],
    data: &VData,
    opts: &LayoutOptions,
) -> Result<Vec<LayoutInfo>> {
    kinds.iter().map(|&kind| Ok(layout_info(kind, write_layout(dir, kind, data, opts)?))).collect()
}
