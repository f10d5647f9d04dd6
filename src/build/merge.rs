//! Joining shard databases (`hdov build --shard I/N`) into one.
//!
//! Every shard holds the same tree, LODs and catalog (a build is deterministic) and the V-pages
//! of its own cells. The merge checks that the shards belong together and cover every cell once,
//! copies the view-invariant files, reads each shard's cells from one of its layouts and writes
//! all layouts anew.

use std::path::{Path, PathBuf};

use hdov_storage::VData;

use super::vpages::read_cells;
use super::{VisibilityParams, begin_write, write_layouts, write_manifest};
use crate::db::Database;
use crate::dov::precompute::Shard;
use crate::error::{Error, Param, Result};
use crate::format::{CATALOG_FILE, GEOMETRY_FILE, Manifest, TREE_FILE, VisibilityInfo};
use crate::grid::ViewGrid;
use crate::overwrite::Overwrite;

/// One shard database, checked to be a shard: its visibility parameters, results and grid.
struct ShardDb {
    db: Database,
    params: VisibilityParams,
    info: VisibilityInfo,
    shard: Shard,
    grid: ViewGrid,
}

impl ShardDb {
    fn open(path: &Path) -> Result<ShardDb> {
        let db = Database::open(path)?;
        let m = db.manifest();
        let (Some(params), Some(info), Some(grid)) = (m.build.visibility.clone(), m.visibility.clone(), m.grid) else {
            return Err(Error::bad_file(path, "holds no visibility"));
        };
        let shard = params.shard.ok_or_else(|| Error::bad_file(path, "is not a shard (built without a shard)"))?;
        if db.layouts().is_empty() {
            return Err(Error::bad_file(path, "holds no layout"));
        }
        Ok(ShardDb { db, params, info, shard, grid })
    }

    fn path(&self) -> &Path {
        self.db.dir()
    }
}

/// Merges `shards` into a new database at `out`. An existing `out` is refused unless `replace`
/// and it is an hdov database or an empty directory. Every shard is opened and validated, and
/// the set is refused in one line unless the shards share one build (parameters, grid and
/// byte-identical tree, geometry and catalog) and cover every part exactly once.
pub fn merge(shards: &[PathBuf], out: &Path, overwrite: Overwrite) -> Result<Manifest> {
    let first_path = shards.first().ok_or_else(|| Error::bad_param(Param::Shards, "no shard databases given"))?;
    let dbs = shards.iter().map(|p| ShardDb::open(p)).collect::<Result<Vec<_>>>()?;
    let first = &dbs[0];
    let count = first.shard.count;
    let mut seen = vec![None::<&Path>; count as usize];
    let invariant_files = [TREE_FILE, GEOMETRY_FILE, CATALOG_FILE];
    let checksums = |db: &Database| -> Result<Vec<u32>> {
        invariant_files
            .iter()
            .map(|f| {
                let p = db.dir().join(f);
                std::fs::read(&p).map(|b| crc32fast::hash(&b)).map_err(|e| Error::io(&p, e))
            })
            .collect()
    };
    let reference = checksums(&first.db)?;
    // Two builds belong together if they differ in nothing but the shard.
    let same_build = |s: &ShardDb| {
        let mut build = s.db.manifest().build.clone();
        if let Some(v) = build.visibility.as_mut() {
            v.shard = first.params.shard;
        }
        build == first.db.manifest().build && s.grid == first.grid
    };
    for s in &dbs {
        if s.shard.count != count || !same_build(s) {
            return Err(Error::bad_file(
                s.path(),
                format!("was built with other parameters than {}", first_path.display()),
            ));
        }
        if checksums(&s.db)? != reference {
            return Err(Error::bad_file(
                s.path(),
                format!("holds another scene or tree than {}", first_path.display()),
            ));
        }
        // `index < count` holds for every shard read (checked on open), and count is shared.
        if let Some(other) = seen[s.shard.index as usize].replace(s.db.dir()) {
            return Err(Error::bad_file(s.path(), format!("is shard {}, as is {}", s.shard, other.display())));
        }
    }
    if let Some(missing) = seen.iter().position(Option::is_none) {
        return Err(Error::bad_param(Param::Shards, format!("shard {missing}/{count} is missing")));
    }

    let txn = begin_write(out, overwrite)?;
    for f in invariant_files {
        let (from, to) = (first.db.dir().join(f), txn.path().join(f));
        let bytes = std::fs::read(&from).map_err(|e| Error::io(&from, e))?;
        hdov_storage::write_file_synced(&to, &bytes)?;
    }
    let grid = first.grid;
    let mut data = VData {
        cell_count: grid.cell_count() as u32,
        node_fanout: (0..first.db.node_count())
            .map(|id| first.db.node(id).map(|p| p.node.entries.len() as u16))
            .collect::<Result<_>>()?,
        cells: vec![Vec::new(); grid.cell_count()],
    };
    let mut info = VisibilityInfo {
        cells_computed: 0,
        sample_points: 0,
        floored_objects: 0,
        skipped_points: 0,
        seconds: 0.0,
        ..first.info.clone()
    };
    for s in &dbs {
        let range = s.shard.cells(&grid);
        let layout = s.db.layout(s.db.layouts()[0])?;
        for (cell, pages) in read_cells(layout, range.start as u32..range.end as u32)? {
            data.cells[cell as usize] = pages;
        }
        info.cells_computed += s.info.cells_computed;
        info.sample_points += s.info.sample_points;
        info.floored_objects += s.info.floored_objects;
        info.skipped_points += s.info.skipped_points;
        info.seconds += s.info.seconds;
    }
    let page_size = first.db.manifest().build.page_size;
    info.layouts = write_layouts(txn.path(), &first.params.layouts, &data, page_size, first.params.dov_codec)?;
    let mut manifest = first.db.manifest().clone();
    manifest.visibility = Some(info);
    if let Some(v) = manifest.build.visibility.as_mut() {
        v.shard = None;
    }
    write_manifest(txn.path(), &manifest)?;
    txn.commit()?;
    Ok(manifest)
}
