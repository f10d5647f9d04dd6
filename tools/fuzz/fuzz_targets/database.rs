//! A whole database. A small database is built once; each input replaces one of its files and
//! the database is opened and read in full (every node, LOD mesh and layout, and the info): any
//! bytes give Ok or a one-line error, never a panic.
//!
//! Input: byte 0 picks the file (bits 0-3, modulo the file count), bit 6 records the input's
//! length as the file's size in `manifest.json` (so that the file's own checks are reached) and
//! bit 7 recomputes the page or blob checksums (so that the decoders behind them are reached);
//! the rest is the file.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::Vec3;
use hdov::dov::BackendKind;
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;
use hdov::progress::Progress;
use hdov::{BuildParams, Database, Scene, VisibilityParams};
use hdov_storage::blob::reseal_checksums as reseal_blob_checksums;
use hdov_storage::pagefile::reseal_checksums as reseal_page_checksums;
use libfuzzer_sys::fuzz_target;

const FILES: [&str; 9] = [
    "tree.pages",
    "geometry.blob",
    "catalog.blob",
    "manifest.json",
    "vpages.horizontal",
    "vindex.vertical",
    "vpages.vertical",
    "vindex.indexed-vertical",
    "vpages.indexed-vertical",
];

struct Db {
    /// Where inputs are tried: a copy of the clean database, restored after each input.
    dir: PathBuf,
    clean: Vec<(&'static str, Vec<u8>)>,
}

fn db() -> &'static Db {
    static DB: OnceLock<Db> = OnceLock::new();
    DB.get_or_init(|| {
        let mut scene = Scene::default();
        for i in 0..4 {
            for j in 0..4 {
                let min = Vec3::new(i as f32 * 10.0, 0.0, j as f32 * 10.0);
                scene.add_box(&format!("b{i}_{j}"), min, min + Vec3::new(6.0, 3.0 + (i + j) as f32, 6.0));
            }
        }
        scene.grid = Some(ViewGrid::new(Aabb::new(Vec3::new(-1.0, 1.5, -1.0), Vec3::new(39.0, 2.0, 39.0)), [2, 1, 2]));
        let params = BuildParams {
            page_size: 128,
            visibility: Some(VisibilityParams { resolution: 8, backend: BackendKind::Cpu, ..Default::default() }),
            ..Default::default()
        };
        // Kept for the life of the fuzzer (statics are never dropped): one small directory.
        let root = tempfile::tempdir().unwrap().keep();
        let dir = root.join("db");
        hdov::build(&scene, &dir, &params, hdov::Overwrite::Never, &Progress::hidden()).unwrap();
        let clean = FILES.iter().map(|&f| (f, std::fs::read(dir.join(f)).unwrap())).collect();
        read_all(&dir).expect("the clean database reads");
        Db { dir, clean }
    })
}

fn read_all(dir: &Path) -> hdov::Result<()> {
    let db = Database::open(dir)?;
    for id in 0..db.node_count() {
        db.node(id)?;
    }
    let catalog = db.catalog();
    for lod in catalog.mesh_lods.iter().chain(&catalog.node_lods).flatten() {
        db.lod_mesh(lod)?;
    }
    db.info()?;
    for kind in db.layouts() {
        db.layout(kind)?.verify()?;
    }
    Ok(())
}

/// `manifest.json` with the size of `name` recorded as `bytes`.
fn manifest_with_size(manifest: &[u8], name: &str, bytes: usize) -> Vec<u8> {
    let set = |list: &mut serde_json::Value| {
        for f in list.as_array_mut().into_iter().flatten().filter(|f| f["name"] == name) {
            f["bytes"] = bytes.into();
        }
    };
    let mut m: serde_json::Value = serde_json::from_slice(manifest).unwrap();
    set(&mut m["files"]);
    for layout in m["visibility"]["layouts"].as_array_mut().into_iter().flatten() {
        set(&mut layout["files"]);
    }
    serde_json::to_vec_pretty(&m).unwrap()
}

fuzz_target!(|data: &[u8]| {
    let Some((&head, file)) = data.split_first() else { return };
    let db = db();
    let name = FILES[usize::from(head & 0x0f) % FILES.len()];
    let mut bytes = file.to_vec();
    if head & 0x80 != 0 {
        if name.ends_with(".blob") {
            reseal_blob_checksums(&mut bytes);
        } else if name != "manifest.json" {
            reseal_page_checksums(&mut bytes);
        }
    }
    std::fs::write(db.dir.join(name), &bytes).unwrap();
    let manifest = &db.clean.iter().find(|(f, _)| *f == "manifest.json").unwrap().1;
    if head & 0x40 != 0 && name != "manifest.json" {
        std::fs::write(db.dir.join("manifest.json"), manifest_with_size(manifest, name, bytes.len())).unwrap();
    }
    if let Err(e) = read_all(&db.dir) {
        let msg = e.to_string();
        assert!(!msg.contains('\n'), "{msg}");
    }
    for (f, clean) in &db.clean {
        if *f == name || *f == "manifest.json" {
            std::fs::write(db.dir.join(f), clean).unwrap();
        }
    }
});
