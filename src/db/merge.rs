//! Joining shard databases (`hdov build --shard I/N`) into one.
//!
//! Every shard holds the same tree, LODs and catalog (a build is deterministic) and the V-pages
//! of its own cells. The merge checks that the shards belong together and cover every cell once,
//! copies the view-invariant files, reads each shard's cells from one of its layouts and writes
//! all layouts anew.

use std::path::{Path, PathBuf};

use hdov_storage::{DirTxn, ReadMode, VData};

use super::build::write_layouts;
use super::visibility::read_cells;
use super::*;

/// Merges `shards` into a new database at `out` (refused if it exists, unless `force`).
pub fn merge(shards: &[PathBuf], out: &Path, force: bool) -> Result<Manifest> {
    let first_path = shards.first().ok_or_else(|| Error::bad_arg("SHARD_DB", "no shard databases given"))?;
    let dbs = shards.iter().map(|p| Database::open(p)).collect::<Result<Vec<_>>>()?;
    let first = &dbs[0];
    let params = |db: &Database| -> Result<VisibilityParams> {
        db.manifest
            .build
            .visibility
            .clone()
            .ok_or_else(|| Error::bad_arg(db.dir().display().to_string(), "holds no visibility"))
    };
    let v0 = params(first)?;
    let count = v0.shard.map_or(1, |[_, n]| n);
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
    let reference = checksums(first)?;
    for db in &dbs {
        let name = db.dir().display().to_string();
        let v = params(db)?;
        let [index, n] = v.shard.ok_or_else(|| Error::bad_arg(&name, "is not a shard (built without --shard)"))?;
        let same_build =
            BuildParams { visibility: Some(VisibilityParams { shard: v0.shard, ..v }), ..db.manifest.build.clone() };
        if n != count || same_build != first.manifest.build || db.manifest.grid != first.manifest.grid {
            return Err(Error::bad_arg(
                &name,
                format!("was built with other parameters than {}", first_path.display()),
            ));
        }
        if checksums(db)? != reference {
            return Err(Error::bad_arg(&name, format!("holds another scene or tree than {}", first_path.display())));
        }
        if let Some(other) = seen[index as usize].replace(db.dir()) {
            return Err(Error::bad_arg(&name, format!("is shard {index}/{n}, as is {}", other.display())));
        }
    }
    if let Some(missing) = seen.iter().position(Option::is_none) {
        return Err(Error::bad_arg("SHARD_DB", format!("shard {missing}/{count} is missing")));
    }
    let grid = first.manifest.grid.ok_or_else(|| Error::bad_arg(first_path.display().to_string(), "has no grid"))?;

    let txn = DirTxn::begin(out, force)?;
    for f in invariant_files {
        let (from, to) = (first.dir().join(f), txn.path().join(f));
        let bytes = std::fs::read(&from).map_err(|e| Error::io(&from, e))?;
        hdov_storage::write_file_synced(&to, &bytes)?;
    }
    let mut data = VData {
        cell_count: grid.cell_count() as u32,
        node_fanout: (0..first.node_count())
            .map(|id| first.node(id).map(|p| p.node.entries.len() as u16))
            .collect::<Result<_>>()?,
        cells: vec![Vec::new(); grid.cell_count()],
    };
    let mut info = first.manifest.visibility.clone().expect("checked above");
    info.cells_computed = 0;
    info.sample_points = 0;
    info.floored_objects = 0;
    info.skipped_points = 0;
    info.seconds = 0.0;
    for db in &dbs {
        let v = db.manifest.visibility.as_ref().expect("checked above");
        let kind =
            *db.layouts().first().ok_or_else(|| Error::bad_arg(db.dir().display().to_string(), "holds no layout"))?;
        let [index, n] = params(db)?.shard.expect("checked above");
        let range = crate::dov::precompute::Shard { index, count: n }.cells(&grid);
        let mut reader = db.layout(kind, ReadMode::Mmap)?;
        for (cell, pages) in read_cells(&mut reader, range.start as u32..range.end as u32)? {
            data.cells[cell as usize] = pages;
        }
        info.cells_computed += v.cells_computed;
        info.sample_points += v.sample_points;
        info.floored_objects += v.floored_objects;
        info.skipped_points += v.skipped_points;
        info.seconds += v.seconds;
    }
    info.layouts = write_layouts(txn.path(), &v0.layout_kinds()?, &data, first.manifest.build.page_size, v0.codec()?)?;
    let mut manifest = first.manifest.clone();
    manifest.visibility = Some(info);
    if let Some(v) = manifest.build.visibility.as_mut() {
        v.shard = None;
    }
    let json = serde_json::to_vec_pretty(&manifest).map_err(|e| Error::bad_arg("manifest", e.to_string()))?;
    hdov_storage::write_file_synced(&txn.path().join(MANIFEST_FILE), &json)?;
    txn.commit()?;
    Ok(manifest)
}
