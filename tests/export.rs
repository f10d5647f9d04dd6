//! Answers and whole scenes out as glTF binaries: they import back with the same objects,
//! instances and triangles, pass the Khronos glTF-Validator with no errors (when `node` and the
//! `gltf-validator` package are there, as `.ci/run` makes them), and never overwrite a file.

use std::path::Path;

use hdov::city::CityParams;
use hdov::{BackendKind, BuildParams, Database, Overwrite, Progress, QueryParams, Scene, VisibilityParams};

fn tiny_city(dir: &Path) -> (Scene, Database) {
    let (scene, db) = hdov_testkit::scenes::tiny_city_database(dir);
    (scene, Database::open(&db).unwrap())
}

/// The validator's error and warning counts for `file`; `None` without node or the package.
fn validate(file: &Path) -> Option<(u64, u64, String)> {
    hdov_testkit::testdata::gltf_validator(&[file.to_path_buf()])?.pop()
}

#[test]
fn answers_and_scenes_come_out_as_gltf_and_back() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, db) = tiny_city(tmp.path());
    // The whole scene at full detail: the same objects, base meshes and triangles come back.
    let whole = tmp.path().join("scene.glb");
    hdov::write_scene_glb(&db, 0, &whole).unwrap();
    let (back, _) = Scene::load(&whole).unwrap();
    assert_eq!(back.objects.len(), scene.objects.len());
    assert_eq!(back.meshes.len(), scene.meshes.len(), "instances stay instances");
    assert_eq!(back.triangle_count(), scene.triangle_count());
    for (a, b) in back.objects.iter().zip(&scene.objects) {
        assert_eq!(a.name, b.name);
    }
    // A coarser level draws fewer triangles.
    let coarse = tmp.path().join("coarse.glb");
    hdov::write_scene_glb(&db, 2, &coarse).unwrap();
    assert!(Scene::load(&coarse).unwrap().0.triangle_count() < scene.triangle_count());
    // An answer: one node per item, at its level.
    let at = db.grid().unwrap().cell_centres()[5];
    let answer = db.query(at, &QueryParams::default()).unwrap();
    let file = tmp.path().join("answer.glb");
    hdov::write_answer_glb(&db, &answer, &file).unwrap();
    let (drawn, _) = Scene::load(&file).unwrap();
    assert_eq!(drawn.objects.len(), answer.items.len());
    assert_eq!(drawn.triangle_count(), answer.stats.faces);
    // Nothing is overwritten.
    let before = std::fs::read(&file).unwrap();
    let err = hdov::write_answer_glb(&db, &answer, &file).unwrap_err().to_string();
    assert!(err.contains("exists"), "{err}");
    assert_eq!(std::fs::read(&file).unwrap(), before);
    for f in [&whole, &coarse, &file] {
        match validate(f) {
            Some((errors, _, messages)) => assert_eq!(errors, 0, "{}: {messages}", f.display()),
            None => return hdov_testkit::testdata::skip_for_want_of("glTF-Validator (node, npm gltf-validator)"),
        }
    }
}

/// A mesh's triangles to the bit, each starting at its least corner (winding kept), sorted.
fn triangle_set(mesh: &hdov::Mesh) -> Vec<[[u32; 3]; 3]> {
    let mut set: Vec<[[u32; 3]; 3]> = mesh
        .triangles()
        .map(|t| {
            let t = t.map(|p| p.to_array().map(f32::to_bits));
            let first = (0..3).min_by_key(|&i| t[i]).unwrap();
            [t[first], t[(first + 1) % 3], t[(first + 2) % 3]]
        })
        .collect();
    set.sort_unstable();
    set
}

/// The default city, exported as glTF and built again, gives the same database content as the
/// build from its manifest: the same objects in the same order with the same names and base
/// meshes, the same triangles to the bit, and the same DoV per cell on a 2 × 1 × 2 block of its
/// street cells (the CPU backend, R = 16).
#[test]
fn the_default_city_built_from_its_gltf_export_equals_the_original() {
    let tmp = tempfile::tempdir().unwrap();
    let mut scene = hdov::city::generate(&CityParams::default()).unwrap();
    let grid = scene.grid.clone().unwrap();
    let (min, size) = (grid.cell_box([grid.dims[0] / 2, 0, grid.dims[2] / 2]).min, grid.cell_size());
    let block = hdov::ViewGrid::new(hdov::Aabb::new(min, min + size * glam::Vec3::new(2.0, 1.0, 2.0)), [2, 1, 2]);
    scene.grid = Some(block.clone());
    let params = BuildParams {
        visibility: Some(VisibilityParams { resolution: 16, backend: BackendKind::Cpu, ..Default::default() }),
        ..Default::default()
    };
    hdov::build(&scene, &tmp.path().join("db"), &params, Overwrite::Never, &Progress::hidden()).unwrap();
    let db = Database::open(&tmp.path().join("db")).unwrap();
    let glb = tmp.path().join("city.glb");
    hdov::write_scene_glb(&db, 0, &glb).unwrap();
    let (mut back, warnings) = Scene::load(&glb).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back.objects.len(), scene.objects.len());
    assert_eq!(back.meshes.len(), scene.meshes.len(), "instances stay instances");
    for (k, (a, b)) in back.objects.iter().zip(&scene.objects).enumerate() {
        assert_eq!(a.name, b.name);
        // The stored LOD 0 is the mesh with its vertices welded and reordered for the vertex
        // cache: the same triangles, winding kept, in another order.
        assert_eq!(triangle_set(back.object_mesh(k)), triangle_set(scene.object_mesh(k)), "{}", a.name);
        assert!(a.transform.abs_diff_eq(b.transform, 1e-4), "{}", a.name);
    }
    back.grid = Some(block.clone()); // glTF carries no viewing grid
    hdov::build(&back, &tmp.path().join("again"), &params, Overwrite::Never, &Progress::hidden()).unwrap();
    let again = Database::open(&tmp.path().join("again")).unwrap();
    let (a, b) = (db.info().unwrap(), again.info().unwrap());
    assert_eq!((a.objects, a.base_meshes, a.triangles), (b.objects, b.base_meshes, b.triangles));
    let naive = QueryParams { mode: hdov::Mode::Naive, ..Default::default() };
    for at in block.cell_centres() {
        let dov = |d: &Database| -> Vec<(String, f32)> {
            d.query(at, &naive).unwrap().items.iter().map(|i| (i.name.to_string(), i.dov)).collect()
        };
        let (x, y) = (dov(&db), dov(&again));
        assert!(x.len() > 20, "{at}: a street cell sees a good part of the city");
        assert_eq!(x.len(), y.len(), "{at}: the same objects are visible");
        for ((n, d), (m, e)) in x.iter().zip(&y) {
            assert_eq!(n, m);
            let texel = (2.0f32 / 16.0).powi(2) / (4.0 * std::f32::consts::PI);
            assert!((d - e).abs() <= 0.005 * d.max(*e) + 2.0 * texel, "{at} {n}: {d} against {e}");
        }
    }
}
