//! The database directory: round trips of every file, and refusal of damaged ones.

use std::path::Path;

use glam::Mat4;
use hdov::scene::{BaseMesh, Object, Scene};

use hdov::Overwrite;
use hdov::format::{FORMAT_VERSION, TREE_FILE};
use hdov::progress::Progress;
use hdov::rtree::{RTree, TreeAlgorithm};
use hdov::{BuildParams, Database};
use hdov_storage::PageReader;

fn town(n: usize) -> Scene {
    hdov_testkit::scenes::town(n, 3)
}

fn build(dir: &Path, params: &BuildParams) -> hdov::BuildReport {
    let scene = town(8);
    hdov::build(&scene, dir, params, Overwrite::Never, &Progress::hidden()).unwrap()
}

#[test]
fn tree_pages_and_lods_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("db");
    let params = BuildParams { page_size: 256, ..Default::default() };
    build(&dir, &params);
    let scene = town(8);
    let boxes = scene.all_object_bounds();
    let tree = RTree::build(&boxes, hdov::format::tree_page::fanout(256), TreeAlgorithm::Str);
    let db = Database::open(&dir).unwrap();
    assert_eq!(db.node_count() as usize, tree.nodes.len());
    assert!(tree.height() >= 3, "a 256-byte page makes a deep enough tree to test");
    let mut pages = PageReader::uncached();
    for (id, node) in tree.nodes.iter().enumerate() {
        let page = db.read_node(id as u32, 0.0, &mut pages).unwrap();
        assert_eq!(&page.node, node);
        assert_eq!(page.subtree_objects as usize, tree.objects_under(id as u32).len());
        assert_eq!(db.node(id as u32).unwrap(), page, "a one-off read gives the same node");
    }
    let io = pages.io();
    assert_eq!(io.file(TREE_FILE), tree.nodes.len() as u64, "every node read is one counted page");
    assert_eq!(io.requested(), io.pages_read(), "one reader, no cache, no node read twice");
    // Instanced geometry is stored once: one chain per base mesh, not per object.
    assert_eq!(db.catalog().mesh_lods.len(), scene.meshes.len());
    assert!(db.catalog().objects.len() > scene.meshes.len());
    let ball = &db.catalog().mesh_lods[0];
    assert_eq!(ball[0].faces as usize, scene.meshes[0].mesh.triangle_count());
    for w in ball.windows(2) {
        assert!(w[1].faces < w[0].faces);
    }
    for lod in ball.iter().chain(db.catalog().node_lods.iter().flatten()) {
        assert_eq!(db.lod_mesh(lod).unwrap().triangle_count(), lod.faces as usize);
    }
    let m = db.manifest();
    assert_eq!(m.counts.objects as usize, scene.objects.len());
    assert_eq!(m.counts.triangles, scene.triangle_count());
}

#[test]
fn existing_database_is_kept_without_force_and_replaced_with_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("db");
    build(&dir, &BuildParams::default());
    let scene = town(3);
    let err = hdov::build(&scene, &dir, &BuildParams::default(), Overwrite::Never, &Progress::hidden()).unwrap_err();
    assert_eq!(err.to_string(), format!("{}: exists", dir.display()), "the library names no flag");
    assert_eq!(Database::open(&dir).unwrap().manifest().counts.objects as usize, town(8).objects.len());
    hdov::build(&scene, &dir, &BuildParams::default(), Overwrite::Ours, &Progress::hidden()).unwrap();
    assert_eq!(Database::open(&dir).unwrap().manifest().counts.objects as usize, scene.objects.len());
    // No temporary directory is left beside the target.
    let names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 1, "{names:?}");
}

/// A mesh with no triangles has no box: it is refused before any work, and nothing is written.
#[test]
fn empty_meshes_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("db");
    for empty in [hdov::scene::Mesh::default(), hdov::scene::Mesh { positions: vec![[0.0; 3]; 3], indices: vec![] }] {
        let mut scene = town(2);
        scene.meshes.push(BaseMesh { name: "hollow".into(), mesh: empty });
        scene.objects.push(Object {
            name: "ghost".into(),
            mesh: scene.meshes.len() as u32 - 1,
            transform: Mat4::IDENTITY,
            part: None,
        });
        let err =
            hdov::build(&scene, &out, &BuildParams::default(), Overwrite::Never, &Progress::hidden()).unwrap_err();
        assert!(err.to_string().starts_with("scene: mesh 'hollow': no triangles"), "{err}");
        assert!(std::fs::read_dir(tmp.path()).unwrap().next().is_none(), "nothing written");
    }
}

/// Copies a database and applies `damage` to one of its files.
/// The manifest's version field as written.
fn version(v: u32) -> String {
    format!("\"format_version\": {v}")
}

fn damaged(src: &Path, file: &str, damage: impl FnOnce(&mut Vec<u8>)) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), tmp.path().join(e.file_name())).unwrap();
    }
    let p = tmp.path().join(file);
    let mut bytes = std::fs::read(&p).unwrap();
    damage(&mut bytes);
    std::fs::write(&p, bytes).unwrap();
    tmp
}

/// Opens and reads everything; returns the first error.
fn open_and_read_all(dir: &Path) -> hdov::Result<()> {
    let db = Database::open(dir)?;
    for id in 0..db.node_count() {
        db.node(id)?;
    }
    for lod in db.catalog().mesh_lods.iter().chain(&db.catalog().node_lods).flatten() {
        db.lod_mesh(lod)?;
    }
    Ok(())
}

#[test]
fn damaged_files_are_refused_with_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("db");
    build(&dir, &BuildParams { page_size: 256, ..Default::default() });
    open_and_read_all(&dir).unwrap();
    type Damage = Box<dyn FnOnce(&mut Vec<u8>)>;
    let cases: Vec<(&str, Damage, &str)> = vec![
        ("tree.pages", Box::new(|b| b[700] ^= 1), "checksum"),
        ("tree.pages", Box::new(|b| b.truncate(b.len() - 100)), "truncated"),
        ("tree.pages", Box::new(|b| b[0] = b'X'), "magic"),
        (
            "geometry.blob",
            Box::new(|b| {
                let n = b.len();
                b[n - 5] ^= 0x10
            }),
            "checksum",
        ),
        ("geometry.blob", Box::new(|b| b.truncate(b.len() / 2)), "truncated"),
        (
            "catalog.blob",
            Box::new(|b| {
                let n = b.len();
                b[n / 2] ^= 0xff
            }),
            "checksum",
        ),
        (
            "manifest.json",
            Box::new(|b| {
                *b = String::from_utf8(b.clone()).unwrap().replace(&version(FORMAT_VERSION), &version(9)).into_bytes()
            }),
            "version 9",
        ),
        (
            // A database of the previous format (before view cells where a viewer can stand).
            "manifest.json",
            Box::new(|b| {
                *b = String::from_utf8(b.clone())
                    .unwrap()
                    .replace(&version(FORMAT_VERSION), &version(FORMAT_VERSION - 1))
                    .into_bytes()
            }),
            "rebuild it",
        ),
        ("manifest.json", Box::new(|b| b.truncate(b.len() / 2)), "manifest"),
        (
            "manifest.json",
            Box::new(|b| {
                *b = String::from_utf8(b.clone())
                    .unwrap()
                    .replace("\"hdov\": \"database\"", "\"hdov\": \"scene\"")
                    .into_bytes()
            }),
            "not a database",
        ),
    ];
    for (file, damage, expect) in cases {
        let bad = damaged(&dir, file, damage);
        let err = open_and_read_all(bad.path()).expect_err(file).to_string();
        assert!(err.contains(expect), "{file}: expected '{expect}' in: {err}");
        assert!(
            err.contains(file) || file == "manifest.json" && err.contains("manifest"),
            "{file}: error names no file: {err}"
        );
        assert!(!err.contains('\n'), "{err}");
    }
    let missing = damaged(&dir, "tree.pages", |_| {});
    std::fs::remove_file(missing.path().join("tree.pages")).unwrap();
    assert!(open_and_read_all(missing.path()).unwrap_err().to_string().contains("tree.pages"));
    assert!(Database::open(&tmp.path().join("nope")).err().unwrap().to_string().contains("no such database"));
}
