//! Joining shards (`hdov build --shard I/N`) into one database.
//!
//! A shard keeps only the V-pages of its own cells and names, by size and SHA-256, the tree,
//! catalog and geometry it was measured against (a build is deterministic, so every shard of
//! one build names the same files). The merge takes those files from a base build of the same
//! scene and parameters (`hdov build --no-visibility`), checks that every shard was measured
//! against exactly them and that the shards cover every cell once, reads each shard's cells from
//! one of its layouts, cell by cell, into every layout written anew.

use std::path::{Path, PathBuf};

use hdov_storage::{Layout, LayoutKind, LayoutWriter, ReadMode, VShape};

use super::vpages::for_each_cell;
use super::{VisibilityParams, begin_write, layout_info, layout_options, layouts_for, write_manifest};
use crate::db::Database;
use crate::dov::precompute::Shard;
use crate::error::{Error, Param, Result};
use crate::format::{BakePhases, FileChecksum, Manifest, SCENE_FILES, VisibilityInfo};
use crate::grid::ViewGrid;
use crate::overwrite::Overwrite;

/// One shard, checked to be one: its manifest, visibility parameters and results, grid, and the
/// layout its cells are read from (its kind, and whether it stores 4-byte NVOs; the layout is
/// opened again when its cells are read, so one shard's mapping is held at a time).
struct ShardDir {
    path: PathBuf,
    manifest: Manifest,
    params: VisibilityParams,
    info: VisibilityInfo,
    shard: Shard,
    grid: ViewGrid,
    against: Vec<FileChecksum>,
    layout: LayoutKind,
    wide_nvo: bool,
}

impl ShardDir {
    fn open(path: &Path) -> Result<ShardDir> {
        let manifest = Manifest::read(path)?;
        let (Some(params), Some(info), Some(grid)) =
            (manifest.build.visibility.clone(), manifest.visibility.clone(), manifest.grid.clone())
        else {
            return Err(Error::bad_file(path, "holds no visibility"));
        };
        let shard = params.shard.ok_or_else(|| Error::bad_file(path, "is not a shard (built without --shard)"))?;
        let against = manifest
            .measured_against
            .clone()
            .ok_or_else(|| Error::bad_file(path, "is a shard that keeps the whole scene: rebuild it with this hdov"))?;
        // The layout the shard wrote (indexed-vertical; earlier shards wrote every layout).
        let kind = info
            .layouts
            .first()
            .and_then(|l| l.name.parse::<LayoutKind>().ok())
            .ok_or_else(|| Error::bad_file(path, "holds no layout"))?;
        let layout = Layout::open(path, kind, ReadMode::Mmap)?;
        let file = path.join(kind.file_names()[0]);
        if u64::from(layout.node_count()) != manifest.counts.nodes || u64::from(layout.cell_count()) != manifest.counts.cells
        {
            return Err(Error::bad_file(file, format!("{kind} layout's node or cell count differs from the manifest's")));
        }
        let wide_nvo = layout.codec().nvo_bytes > 2;
        Ok(ShardDir { path: path.to_path_buf(), manifest, params, info, shard, grid, against, layout: kind, wide_nvo })
    }
}

/// Merges `shards` with the scene files of `base` into a new database at `out`. An existing `out`
/// is refused unless `overwrite` allows ours and it is an hdov database or an empty directory.
/// The set is refused in one line unless every shard was built with the base's parameters (the
/// shard aside) and grid, was measured against the base's very tree, catalog and geometry, and
/// the shards cover every part exactly once. Memory: one cell's V-pages and the layout
/// writers' buffers (one page per node for horizontal); the scene files are copied, not read.
pub fn merge(base: &Path, shards: &[PathBuf], out: &Path, overwrite: Overwrite) -> Result<Manifest> {
    let base_db = Database::open(base)?;
    let files = FileChecksum::of_scene_files(base)?;
    let base_manifest = base_db.manifest();
    let grid = base_manifest.grid.clone().ok_or_else(|| Error::bad_file(base, "holds no viewing grid"))?;
    let first_path = shards.first().ok_or_else(|| Error::bad_param(Param::Shards, "no shards given"))?;
    let dirs = shards.iter().map(|p| ShardDir::open(p)).collect::<Result<Vec<_>>>()?;
    let first = &dirs[0];
    let count = first.shard.count;
    let mut seen = vec![None::<&Path>; count as usize];
    // A shard belongs to the base if their builds differ in nothing but visibility.
    for s in &dirs {
        let mut params = s.params.clone();
        params.shard = first.params.shard;
        if s.shard.count != count || params != first.params {
            return Err(Error::bad_file(&s.path, format!("was built with other parameters than {}", first_path.display())));
        }
        if s.manifest.build.without_visibility() != base_manifest.build.without_visibility() || s.grid != grid {
            return Err(Error::bad_file(&s.path, format!("was built with other parameters than {}", base.display())));
        }
        if s.against != files {
            return Err(Error::bad_file(
                &s.path,
                format!("was measured against another scene or tree than {} holds", base.display()),
            ));
        }
        // `index < count` holds for every shard read (checked on open), and count is shared.
        if let Some(other) = seen[s.shard.index as usize].replace(&s.path) {
            return Err(Error::bad_file(&s.path, format!("is shard {}, as is {}", s.shard, other.display())));
        }
    }
    if let Some(missing) = seen.iter().position(Option::is_none) {
        return Err(Error::bad_param(Param::Shards, format!("shard {missing}/{count} is missing")));
    }

    let txn = begin_write(out, overwrite)?;
    for f in SCENE_FILES {
        hdov_storage::copy_file_synced(&base.join(f), &txn.path().join(f))?;
    }
    // Every cell, in order, goes straight from its shard's layout into every new layout: the
    // merge holds one cell's V-pages and the writers' buffers, whatever the grid. The V-entry
    // width is fixed before the first cell: 4-byte NVOs where any shard needed them, as a
    // whole build would have chosen from the same NVOs.
    let wide = dirs.iter().any(|s| s.wide_nvo);
    let shape = VShape {
        cell_count: grid.cell_count() as u32,
        node_fanout: (0..base_db.node_count())
            .map(|id| base_db.node(id).map(|p| p.node.entries.len() as u16))
            .collect::<Result<_>>()?,
        nvo_max: if wide { u32::MAX } else { u32::from(u16::MAX) },
    };
    let opts = layout_options(base_manifest.build.page_size, first.params.dov_codec);
    let params = VisibilityParams { shard: None, ..first.params.clone() };
    let (kinds, left_out) = layouts_for(&params, &shape, &opts);
    let mut writers =
        kinds.iter().map(|&k| LayoutWriter::create(txn.path(), k, &shape, &opts)).collect::<Result<Vec<_>, _>>()?;
    let mut info = VisibilityInfo {
        cells_computed: 0,
        sample_points: 0,
        floored_objects: 0,
        skipped_points: 0,
        seconds: 0.0,
        phases: Some(BakePhases::default()),
        left_out,
        ..first.info.clone()
    };
    let mut in_order: Vec<&ShardDir> = dirs.iter().collect();
    in_order.sort_by_key(|s| s.shard.index);
    // The lattice's cells shard by shard, then the further view cells of walls and quarters
    // (`ViewGrid::parts`), which follow their lattice cells' order.
    let mut next = 0;
    for (s, range) in in_order.iter().map(|s| (s, s.shard.cells(&grid))).chain(in_order.iter().map(|s| (s, s.shard.parts(&grid)))) {
        if range.start != next {
            return Err(Error::bad_file(&s.path, format!("starts at cell {}, not {next}", range.start)));
        }
        next = range.end;
        if range.is_empty() {
            continue;
        }
        let layout = Layout::open(&s.path, s.layout, ReadMode::Mmap)?;
        for_each_cell(&layout, range.start as u32..range.end as u32, |_, pages| {
            writers.iter_mut().try_for_each(|w| w.push_cell(&pages)).map_err(Error::from)
        })?;
    }
    for s in &in_order {
        // Counts read from the shards' manifests: summed without wrapping.
        info.cells_computed = info.cells_computed.saturating_add(s.info.cells_computed);
        info.sample_points = info.sample_points.saturating_add(s.info.sample_points);
        info.floored_objects = info.floored_objects.saturating_add(s.info.floored_objects);
        info.skipped_points = info.skipped_points.saturating_add(s.info.skipped_points);
        info.seconds += s.info.seconds;
        // A shard written before phases were recorded leaves the whole unknown.
        info.phases = match (info.phases.take(), &s.info.phases) {
            (Some(mut sum), Some(p)) => {
                sum.add(p);
                Some(sum)
            }
            _ => None,
        };
    }
    info.layouts = kinds
        .iter()
        .zip(writers)
        .map(|(&kind, w)| Ok(layout_info(kind, w.finish()?)))
        .collect::<Result<_>>()?;
    let mut manifest = base_manifest.clone();
    manifest.build.visibility = Some(params);
    manifest.visibility = Some(info);
    write_manifest(txn.path(), &manifest)?;
    txn.commit()?;
    Ok(manifest)
}
