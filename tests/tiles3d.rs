//! The database as a 3D Tiles 1.1 tileset (`hdov::tiles`): every object's full-detail
//! triangles come back from its tiles, each tile's box holds its content and its geometric error
//! is at least its children's, instances share their content files, every content file passes
//! the Khronos glTF-Validator, and each cell's visibility file says what `Database::query`
//! answers there.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use glam::{Mat4, Vec3};
use hdov::tiles::{self, Y_UP_TO_Z_UP};
use hdov::{Database, ItemKind, QueryParams, Scene};
use serde_json::Value;

/// The export's `tileset.json` with its subtree tilesets in place (content URIs relative to `out`).
fn tileset(out: &Path) -> Value {
    let read = |p: &str| -> Value { serde_json::from_slice(&std::fs::read(out.join(p)).unwrap()).unwrap() };
    hdov_testkit::tiles::resolved(&read("tileset.json"), &mut |p| read(p))
}

fn export(dir: &Path) -> (Scene, Database, std::path::PathBuf) {
    let (scene, db) = hdov_testkit::scenes::tiny_city_database(dir);
    let db = Database::open(&db).unwrap();
    let out = dir.join("tiles");
    hdov::tiles::write_tileset(&db, &out, None, &hdov::Progress::hidden()).unwrap();
    (scene, db, out)
}

/// Every tile with the transform it is drawn under (its own and its ancestors').
fn tiles(tile: &Value, above: Mat4, out: &mut Vec<(Value, Mat4)>) {
    let m = match tile.get("transform") {
        Some(t) => above * Mat4::from_cols_slice(&serde_json::from_value::<Vec<f32>>(t.clone()).unwrap()),
        None => above,
    };
    out.push((tile.clone(), m));
    for c in tile["children"].as_array().into_iter().flatten() {
        tiles(c, m, out);
    }
}

/// A content file's triangles in the tile's frame (glTF y-up turned to z-up, as clients do).
fn content_triangles(file: &Path) -> Vec<[Vec3; 3]> {
    let (scene, _) = Scene::load(file).unwrap();
    assert_eq!(scene.objects.len(), 1, "{}: one node", file.display());
    scene.object_mesh(0).triangles().map(|t| t.map(|p| Y_UP_TO_Z_UP.transform_point3(p))).collect()
}

fn in_box(p: Vec3, b: &[f32]) -> bool {
    (0..3).all(|a| (p[a] - b[a]).abs() <= b[3 + 4 * a])
}

#[test]
fn the_tileset_gives_back_every_object_and_keeps_the_error_contract() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, db, out) = export(tmp.path());
    let set = tileset(&out);
    assert_eq!(set["asset"]["version"], "1.1");
    assert_eq!(set["root"]["refine"], "REPLACE");
    let mut all = Vec::new();
    tiles(&set["root"], Mat4::IDENTITY, &mut all);
    assert!(set["geometricError"].as_f64().unwrap() >= set["root"]["geometricError"].as_f64().unwrap());
    let mut uri_of_mesh_level: HashMap<(u32, u64), String> = HashMap::new();
    let mut full_detail: HashMap<u32, Vec<[Vec3; 3]>> = HashMap::new();
    let mut uris = HashSet::new();
    for (tile, m) in &all {
        let error = tile["geometricError"].as_f64().unwrap();
        for c in tile["children"].as_array().into_iter().flatten() {
            // Errors fall strictly from a drawn tile to a drawn child: 3D Tiles clients refine a
            // tile of its parent's error without drawing it, so a stop there would not hold.
            // Nor is a first level drawn under another node's.
            if c["content"].is_object() && tile["content"].is_object() && c["geometricError"].as_f64() != Some(0.0) {
                assert!(c["geometricError"].as_f64().unwrap() < error, "{}: no finer than its parent", c["extras"]);
            }
            assert!(
                c["geometricError"].as_f64().unwrap() <= error,
                "a child's error above its parent's: {} {} under {} {}",
                c["extras"],
                c["geometricError"],
                tile["extras"],
                error
            );
        }
        let b: Vec<f32> = serde_json::from_value(tile["boundingVolume"]["box"].clone()).unwrap();
        let key = &tile["extras"]["hdov"];
        let Some(uri) = tile["content"]["uri"].as_str() else { continue };
        uris.insert(uri.to_string());
        let tris = content_triangles(&out.join(uri));
        assert!(!tris.is_empty());
        for t in &tris {
            for p in t {
                assert!(in_box(*p, &b), "{key}: {p} outside its box {b:?}");
            }
        }
        if let Some(o) = key["object"].as_u64() {
            let level = key["level"].as_u64().unwrap();
            let mesh = scene.objects[o as usize].mesh;
            // Instances of one base mesh share its files.
            let shared = uri_of_mesh_level.entry((mesh, level)).or_insert_with(|| uri.to_string());
            assert_eq!(shared, uri, "object {o}");
            if level == 0 {
                assert_eq!(error, 0.0, "full detail is exact");
                assert!(
                    full_detail
                        .insert(o as u32, tris.iter().map(|t| t.map(|p| m.transform_point3(p))).collect())
                        .is_none()
                );
            }
        }
    }
    // Each stored level is written once and every written file is a tile's.
    let written = std::fs::read_dir(out.join("content")).unwrap().count();
    assert_eq!(written, uris.len());
    let meshes: HashSet<u32> = scene.objects.iter().map(|o| o.mesh).collect();
    assert!(meshes.len() < scene.objects.len(), "the tiny city instances its meshes");
    assert_eq!(
        uri_of_mesh_level.keys().filter(|k| k.1 == 0).count(),
        meshes.len(),
        "one full-detail file per base mesh"
    );
    // Full detail of every object, back in the scene's frame, is the scene's.
    assert_eq!(full_detail.len(), scene.objects.len(), "every object has a full-detail tile");
    let back = Y_UP_TO_Z_UP.inverse();
    let key = |t: [Vec3; 3]| -> [[i64; 3]; 3] {
        let mut k = t.map(|p| p.to_array().map(|c| (c * 1000.0).round() as i64));
        k.sort_unstable();
        k
    };
    for (o, tris) in full_detail {
        let model = scene.objects[o as usize].transform;
        let mut want: Vec<_> =
            scene.object_mesh(o as usize).triangles().map(|t| key(t.map(|p| model.transform_point3(p)))).collect();
        let mut got: Vec<_> = tris.iter().map(|t| key(t.map(|p| back.transform_point3(p)))).collect();
        want.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, want, "object {o}: its triangles at full detail");
    }
    // Every content file passes the validator with no errors and no warnings.
    let files: Vec<_> = uris.iter().map(|u| out.join(u)).collect();
    match hdov_testkit::testdata::gltf_validator(&files) {
        Some(reports) => {
            for (f, (errors, warnings, messages)) in files.iter().zip(reports) {
                assert_eq!((errors, warnings), (0, 0), "{}: {messages}", f.display());
            }
        }
        None => hdov_testkit::testdata::skip_for_want_of("glTF-Validator (node, npm gltf-validator)"),
    }
    let _ = db;
}

/// A node's level comes in slices, one per set of entries its triangles stand for
/// (decision 131): together they hold the level's triangles once each, and a slice's vertices lie
/// in the boxes of the entries it names, so a client that draws the slices of the entries a cell
/// sees leaves out only what stands for hidden ones.
#[test]
fn node_levels_come_in_slices_by_the_entries_they_stand_for() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, db, out) = export(tmp.path());
    let mut all = Vec::new();
    tiles(&tileset(&out)["root"], Mat4::IDENTITY, &mut all);
    let nodes = u64::from(db.node_count());
    let back = Y_UP_TO_Z_UP.inverse();
    let mut faces: HashMap<(u64, u64), usize> = HashMap::new();
    let mut single = 0;
    for (tile, _) in &all {
        let h = &tile["extras"]["hdov"];
        let (Some(entries), Some(uri)) = (h["entries"].as_array(), tile["content"]["uri"].as_str()) else { continue };
        let (n, level) = (h["node"].as_u64().unwrap(), h["level"].as_u64().unwrap());
        let page = db.node(n as u32).unwrap();
        let key = |child: u32| if page.node.is_leaf() { nodes + u64::from(child) } else { u64::from(child) };
        let boxes: Vec<hdov::Aabb> = entries
            .iter()
            .map(|k| {
                page.node
                    .entries
                    .iter()
                    .find(|e| key(e.child) == k.as_u64().unwrap())
                    .expect("an entry of the node")
                    .mbr
            })
            .collect();
        single += usize::from(boxes.len() == 1);
        let tris = content_triangles(&out.join(uri));
        // Triangles as written (a scene load drops degenerate ones): the index accessor's count.
        let glb = std::fs::read(out.join(uri)).unwrap();
        let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
        *faces.entry((n, level)).or_default() += doc["accessors"][1]["count"].as_u64().unwrap() as usize / 3;
        for p in tris.iter().flatten().map(|&p| back.transform_point3(p)) {
            let pad = 1e-4 * (1.0 + p.abs().max_element());
            assert!(
                boxes.iter().any(|b| (p - b.min).min_element() >= -pad && (b.max - p).min_element() >= -pad),
                "node {n} level {level}: {p} in none of its entries' boxes {entries:?}"
            );
        }
    }
    assert!(single > 0 && !faces.is_empty());
    for ((n, level), count) in faces {
        assert_eq!(count, db.catalog().node_lods[n as usize][level as usize].faces as usize, "node {n} level {level}");
    }
}

#[test]
fn each_cell_file_says_what_the_query_answers_there() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, db, out) = export(tmp.path());
    let index: Value = serde_json::from_slice(&std::fs::read(out.join(tiles::VISIBILITY_INDEX)).unwrap()).unwrap();
    let grid = db.grid().unwrap().clone();
    let g = &index["grid"];
    assert_eq!(g["dims"], serde_json::json!(grid.dims));
    let region: Vec<f32> = serde_json::from_value(g["region"].clone()).unwrap();
    assert_eq!(region, grid.region.to_array());
    let scene_from_tileset =
        Mat4::from_cols_slice(&serde_json::from_value::<Vec<f32>>(index["sceneFromTileset"].clone()).unwrap());
    let nodes = u64::from(db.node_count());
    let (default, all) = (QueryParams::default(), QueryParams { eta: 0.0, ..Default::default() });
    for cell in 0..grid.cell_count() as u32 {
        let file = tiles::decode_cell(&std::fs::read(out.join(tiles::cell_file(cell))).unwrap()).unwrap();
        assert_eq!(file.cell, cell);
        let at = grid.view_cell(cell as usize).point(Vec3::splat(0.5));
        // The index's matrix takes the point in the tileset's frame back to the scene's.
        assert!(scene_from_tileset.transform_point3(Y_UP_TO_Z_UP.transform_point3(at)).abs_diff_eq(at, 1e-3));
        let key = |i: &hdov::Item| match i.kind {
            ItemKind::Node => u64::from(i.id),
            ItemKind::Object => nodes + u64::from(i.id),
        };
        let entries: HashMap<u64, u16> = file.entries.iter().copied().collect();
        // At η = 0 the query draws every object the cell sees: the file's objects, no more.
        let answer = db.query(at, &all).unwrap();
        assert_eq!(answer.cell_id, cell);
        let drawn: HashSet<u64> = answer.items.iter().map(key).collect();
        let listed: HashSet<u64> = entries.keys().copied().filter(|&k| k >= nodes).collect();
        assert_eq!(drawn, listed, "cell {cell}: objects");
        for i in &answer.items {
            assert!(tiles::dov_of_code(entries[&key(i)]) >= f64::from(i.dov), "cell {cell}: a code below its DoV");
        }
        // At the default η, every node it stops at is a stop at the level it draws.
        let answer = db.query(at, &default).unwrap();
        let stops: HashMap<u64, u32> = file.stops.iter().copied().collect();
        for i in &answer.items {
            assert!(entries.contains_key(&key(i)), "cell {cell}: {:?} {} drawn, not listed", i.kind, i.id);
            if i.kind == ItemKind::Node {
                assert_eq!(stops.get(&key(i)), Some(&i.lod), "cell {cell}: node {} stops", i.id);
            }
            if let Some(&l) = stops.get(&key(i)) {
                assert_eq!(l, i.lod, "cell {cell}: {:?} {}", i.kind, i.id);
            }
        }
        let node_stops = file.stops.iter().filter(|s| s.0 < nodes).count();
        assert_eq!(node_stops, answer.items.iter().filter(|i| i.kind == ItemKind::Node).count(), "cell {cell}");
    }
}

#[test]
fn cell_files_refuse_damage_and_the_export_never_overwrites() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, db, out) = export(tmp.path());
    let bytes = std::fs::read(out.join(tiles::cell_file(0))).unwrap();
    assert!(tiles::decode_cell(&bytes[..bytes.len() - 1]).is_err(), "truncated");
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(tiles::decode_cell(&longer).is_err(), "trailing bytes");
    assert!(tiles::decode_cell(b"glTF\x02\0\0\0").is_err(), "another file");
    for d in [1e-12f32, 1e-7, 3e-2, 0.5, 1.0] {
        let c = tiles::dov_code(d);
        assert!(tiles::dov_of_code(c) >= f64::from(d) && tiles::dov_of_code(c) <= f64::from(d) * 1.001 + 3e-10, "{d}");
    }
    // An existing directory is refused and left as it was.
    let before = std::fs::read(out.join("tileset.json")).unwrap();
    let err = hdov::tiles::write_tileset(&db, &out, None, &hdov::Progress::hidden()).unwrap_err().to_string();
    assert!(err.contains("exists"), "{err}");
    assert_eq!(std::fs::read(out.join("tileset.json")).unwrap(), before);
    // A singular root transform is refused before anything is written.
    let other = tmp.path().join("other");
    assert!(hdov::tiles::write_tileset(&db, &other, Some(Mat4::ZERO), &hdov::Progress::hidden()).is_err());
    assert!(!other.exists());
}

/// A second client reads the tileset: loaders.gl (`tools/tiles/loadersgl-check.mjs`, run by
/// node) finds every tile's error at least its children's and every content vertex inside its
/// tile's box as loaders.gl places it.
#[test]
fn loaders_gl_reads_the_tileset_and_finds_each_box_holds_its_content() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, _, out) = export(tmp.path());
    let npm_root = std::process::Command::new("npm").args(["root", "-g"]).output().ok();
    let node_path = npm_root.map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string()).unwrap_or_default();
    if !Path::new(&node_path).join("@loaders.gl/tiles").exists() {
        return hdov_testkit::testdata::skip_for_want_of(
            "loaders.gl (node, npm @loaders.gl/core, 3d-tiles, tiles, gltf)",
        );
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/tiles/loadersgl-check.mjs");
    let run = std::process::Command::new("node").arg(&script).arg(&out).env("NODE_PATH", &node_path).output().unwrap();
    let report = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{report}{}", String::from_utf8_lossy(&run.stderr));
    let r: Value = serde_json::from_str(report.trim()).unwrap();
    let set = tileset(&out);
    let mut all = Vec::new();
    tiles(&set["root"], Mat4::IDENTITY, &mut all);
    assert_eq!(r["tiles"].as_u64().unwrap() as usize, all.len(), "loaders.gl reads every tile");
    assert!(r["vertices"].as_u64().unwrap() > 0);
}

/// A database built without visibility exports as a tileset alone: no visibility index for a
/// client to follow, every object's full detail still there.
#[test]
fn a_database_without_visibility_is_a_tileset_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let scene =
        hdov::city::generate(&hdov::city::CityParams { scale: hdov::city::CityScale::Tiny, ..Default::default() })
            .unwrap();
    let params = hdov::BuildParams { visibility: None, ..Default::default() };
    let dir = tmp.path().join("db");
    hdov::build(&scene, &dir, &params, hdov::Overwrite::Never, &hdov::Progress::hidden()).unwrap();
    let db = Database::open(&dir).unwrap();
    let out = tmp.path().join("tiles");
    let report = hdov::tiles::write_tileset(&db, &out, None, &hdov::Progress::hidden()).unwrap();
    assert_eq!((report.cells, report.visibility_bytes), (0, 0));
    assert!(!out.join("visibility").exists());
    let set = tileset(&out);
    assert!(set["extras"]["hdov"]["visibility"].is_null());
    let mut all = Vec::new();
    tiles(&set["root"], Mat4::IDENTITY, &mut all);
    let full: HashSet<u64> = all
        .iter()
        .filter(|(t, _)| t["extras"]["hdov"]["level"] == 0)
        .filter_map(|(t, _)| t["extras"]["hdov"]["object"].as_u64())
        .collect();
    assert_eq!(full.len(), scene.objects.len());
}
