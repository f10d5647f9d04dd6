//! glTF 2.0 import: the node hierarchy flattened with its transforms, shared meshes stored once
//! with instances (and `EXT_mesh_gpu_instancing`), strips and fans unrolled, points skipped; and
//! bad files refused in one line without a panic: our own cases and assimp's test models.

use std::path::{Path, PathBuf};

use base64::Engine;
use glam::Vec3;
use hdov::Scene;
use serde_json::{Value, json};

/// A cube's 8 corners, its 12 triangles (u16), a strip of 4 indices and 3 instance offsets.
fn buffer() -> Vec<u8> {
    let mut b = Vec::new();
    for i in 0..8u32 {
        for bit in [1u32, 2, 4] {
            b.extend((if i & bit != 0 { 1.0f32 } else { 0.0 }).to_le_bytes());
        }
    }
    let tris: [u16; 36] =
        [0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1, 2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3];
    b.extend(tris.iter().flat_map(|i| i.to_le_bytes()));
    b.extend([0u16, 1, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
    for x in [0.0f32, 20.0, 40.0] {
        b.extend([x, 0.0, 30.0].iter().flat_map(|v| v.to_le_bytes()));
    }
    b
}

/// A document over [`buffer`]: a cube used by three nodes (one under a translated parent, one
/// scaled, one instanced three times) and a mesh of a strip and a point primitive.
fn document(buffer_len: usize, uri: Option<String>) -> Value {
    let mut buffer = json!({ "byteLength": buffer_len });
    if let Some(uri) = uri {
        buffer["uri"] = json!(uri);
    }
    json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["EXT_mesh_gpu_instancing"],
        "buffers": [buffer],
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": 96 },
            { "buffer": 0, "byteOffset": 96, "byteLength": 72 },
            { "buffer": 0, "byteOffset": 168, "byteLength": 8 },
            { "buffer": 0, "byteOffset": 176, "byteLength": 36 }
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1] },
            { "bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR" },
            { "bufferView": 2, "componentType": 5123, "count": 4, "type": "SCALAR" },
            { "bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3" }
        ],
        "meshes": [
            { "name": "cube", "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1 }] },
            { "name": "strip", "primitives": [
                { "attributes": { "POSITION": 0 }, "indices": 2, "mode": 5 },
                { "attributes": { "POSITION": 0 }, "mode": 0 }
            ] }
        ],
        "nodes": [
            { "name": "parent", "translation": [10, 0, 0], "children": [1] },
            { "name": "box", "mesh": 0, "translation": [0, 5, 0] },
            { "name": "box", "mesh": 0, "scale": [2, 2, 2] },
            { "name": "crowd", "mesh": 0, "extensions": { "EXT_mesh_gpu_instancing": { "attributes": { "TRANSLATION": 3 } } } },
            { "name": "ribbon", "mesh": 1 }
        ],
        "scenes": [{ "nodes": [0, 2, 3, 4] }],
        "scene": 0
    })
}

fn write_gltf(dir: &Path, name: &str, doc: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec_pretty(doc).unwrap()).unwrap();
    path
}

fn data_uri(bin: &[u8]) -> String {
    format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(bin))
}

fn check_scene(scene: &Scene, warnings: &[String]) {
    assert_eq!(scene.meshes.len(), 2, "the cube is stored once, beside the strip mesh");
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["box", "box#2", "crowd", "crowd#2", "crowd#3", "ribbon"]);
    let bounds = |name: &str| {
        let i = scene.objects.iter().position(|o| o.name == name).unwrap();
        scene.object_mesh(i).bounds().transformed(&scene.objects[i].transform)
    };
    // The child of the translated parent: both translations.
    assert_eq!(bounds("box").min, Vec3::new(10.0, 5.0, 0.0));
    assert_eq!(bounds("box#2").max, Vec3::splat(2.0));
    assert_eq!(bounds("crowd#3").min, Vec3::new(40.0, 0.0, 30.0));
    let cube = scene.objects.iter().filter(|o| o.mesh == scene.objects[0].mesh).count();
    assert_eq!(cube, 5, "five instances of one cube");
    // The strip of 4 indices is two triangles; the points are skipped and said so.
    let strip = scene.objects.iter().position(|o| o.name == "ribbon").unwrap();
    assert_eq!(scene.object_mesh(strip).triangle_count(), 2);
    assert!(warnings.iter().any(|w| w.contains("Points")), "{warnings:?}");
}

#[test]
fn gltf_and_glb_scenes_import_with_their_hierarchy_and_instances() {
    let dir = tempfile::tempdir().unwrap();
    let bin = buffer();
    let gltf = write_gltf(dir.path(), "scene.gltf", &document(bin.len(), Some(data_uri(&bin))));
    let (scene, warnings) = Scene::load(&gltf).unwrap();
    check_scene(&scene, &warnings);
    // The same as a .glb, and with the buffer in a file beside the .gltf.
    let glb_path = dir.path().join("scene.glb");
    std::fs::write(&glb_path, hdov::export::glb(&document(bin.len(), None), &bin)).unwrap();
    let (scene, warnings) = Scene::load(&glb_path).unwrap();
    check_scene(&scene, &warnings);
    std::fs::write(dir.path().join("scene.bin"), &bin).unwrap();
    let beside = write_gltf(dir.path(), "beside.gltf", &document(bin.len(), Some("scene.bin".into())));
    check_scene(&Scene::load(&beside).unwrap().0, &Scene::load(&beside).unwrap().1);
}

#[test]
fn bad_gltf_files_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let bin = buffer();
    let good = document(bin.len(), Some(data_uri(&bin)));
    let mut nan = bin.clone();
    nan[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut far_index = bin.clone();
    far_index[96..98].copy_from_slice(&99u16.to_le_bytes());
    type Edit = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        ("view past its buffer", Box::new(|d| d["bufferViews"][0]["byteLength"] = json!(4096)), "past its buffer"),
        ("2^31 elements", Box::new(|d| d["accessors"][0]["count"] = json!(1u64 << 31)), "do not fit"),
        ("non-finite position", Box::new(move |d| d["buffers"][0]["uri"] = json!(data_uri(&nan))), "non-finite"),
        (
            "index past the vertices",
            Box::new(move |d| d["buffers"][0]["uri"] = json!(data_uri(&far_index))),
            "past its",
        ),
        ("a node cycle", Box::new(|d| d["nodes"][1]["children"] = json!([0])), "reached twice"),
        (
            "draco",
            Box::new(|d| {
                d["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
                d["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
            }),
            "KHR_draco_mesh_compression",
        ),
        ("an index to no mesh", Box::new(|d| d["nodes"][1]["mesh"] = json!(7)), "invalid glTF"),
        (
            "a bad data URI",
            Box::new(|d| d["buffers"][0]["uri"] = json!("data:application/octet-stream;base64,@@@")),
            "base64",
        ),
        ("a URL", Box::new(|d| d["buffers"][0]["uri"] = json!("http://example.com/a.bin")), "not a file beside"),
        (
            // gltf-json's own check panicked on this (found by the scene_gltf fuzz target).
            "an attribute past the accessors",
            Box::new(|d| d["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(9)),
            "past the accessors",
        ),
    ];
    for (what, edit, expect) in cases {
        let mut doc = good.clone();
        edit(&mut doc);
        let path = write_gltf(dir.path(), "bad.gltf", &doc);
        let err = Scene::load(&path).expect_err(what).to_string();
        assert!(err.contains(expect), "{what}: expected '{expect}' in: {err}");
        assert!(err.contains("bad.gltf") && !err.contains('\n'), "{what}: {err}");
    }
    // Issue 32's audit: small files that would copy their buffers without end. A second buffer
    // without a URI (the gltf crate lets every such buffer be the GLB chunk, copied each time):
    let mut two = document(bin.len(), None);
    two["buffers"] = json!([{ "byteLength": bin.len() }, { "byteLength": bin.len() }]);
    let glb = dir.path().join("two.glb");
    std::fs::write(&glb, hdov::export::glb(&two, &bin)).unwrap();
    assert!(Scene::load(&glb).unwrap_err().to_string().contains("only buffer 0 is the binary chunk"));
    // A mesh of 20,000 primitives on one accessor: 4.8 MB of vertices and indices from a
    // 300-byte buffer.
    let mut many = good.clone();
    many["meshes"][0]["primitives"] = json!(vec![json!({ "attributes": { "POSITION": 0 }, "indices": 1 }); 20_000]);
    let path = write_gltf(dir.path(), "many.gltf", &many);
    let err = Scene::load(&path).unwrap_err().to_string();
    assert!(err.contains("times over are read") && !err.contains('\n'), "{err}");
    // A few primitives sharing an accessor are fine.
    many["meshes"][0]["primitives"] = json!(vec![json!({ "attributes": { "POSITION": 0 }, "indices": 1 }); 3]);
    let path = write_gltf(dir.path(), "few.gltf", &many);
    assert_eq!(Scene::load(&path).unwrap().0.meshes[0].mesh.triangle_count(), 36);
    // Buffers declaring more than a file may hold, in all.
    let mut huge = good.clone();
    huge["buffers"] = json!(vec![json!({ "byteLength": 1u64 << 33, "uri": "a.bin" }); 3]);
    let path = write_gltf(dir.path(), "huge.gltf", &huge);
    assert!(Scene::load(&path).unwrap_err().to_string().contains("in all"));

    // A GLB header declaring fewer bytes than itself (the gltf crate's unchecked subtraction,
    // found by the scene_gltf fuzz target).
    let mut short = hdov::export::glb(&document(bin.len(), None), &bin);
    short[8..12].copy_from_slice(&3u32.to_le_bytes());
    let path = dir.path().join("short.glb");
    std::fs::write(&path, &short).unwrap();
    assert!(Scene::load(&path).unwrap_err().to_string().contains("declares 3 bytes"));
    // A .glb cut short anywhere is refused, never a panic.
    let whole = hdov::export::glb(&document(bin.len(), None), &bin);
    for cut in [0, 4, 11, 12, 19, 40, whole.len() / 2, whole.len() - 1] {
        let path = dir.path().join("cut.glb");
        std::fs::write(&path, &whole[..cut]).unwrap();
        assert!(Scene::load(&path).is_err(), "a .glb cut at {cut} of {} bytes", whole.len());
    }
}

/// Issue 32's attacks: a buffer URI that leaves the scene's folder (by `..`, by a link, to a
/// device) is refused in one line naming the scene, before a byte of it is read; a buffer file
/// longer than its declared `byteLength` is refused too; one beside the scene loads.
#[test]
fn buffers_outside_the_scene_folder_are_refused_unread() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("scene");
    std::fs::create_dir(&folder).unwrap();
    let bin = buffer();
    std::fs::write(folder.join("a.bin"), &bin).unwrap();
    std::fs::write(dir.path().join("secret.bin"), &bin).unwrap();
    let with_uri = |uri: &str| {
        let path = write_gltf(&folder, "s.gltf", &document(bin.len(), Some(uri.to_string())));
        Scene::load(&path)
    };
    with_uri("a.bin").unwrap();
    for (uri, expect) in [
        ("../secret.bin", "outside the scene's folder"),
        ("../../../../../../../../etc/passwd", "outside the scene's folder"),
        ("/etc/passwd", "not a file beside"),
    ] {
        let err = with_uri(uri).expect_err(uri).to_string();
        assert!(err.contains(expect) && err.contains("s.gltf") && !err.contains('\n'), "{uri}: {err}");
    }
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/zero", folder.join("zero.bin")).unwrap();
        std::os::unix::fs::symlink(dir.path().join("secret.bin"), folder.join("link.bin")).unwrap();
        for uri in ["zero.bin", "link.bin"] {
            let err = with_uri(uri).expect_err(uri).to_string();
            assert!(err.contains("outside the scene's folder"), "{uri}: {err}");
        }
    }
    let mut longer = bin.clone();
    longer.extend([0u8; 64]);
    std::fs::write(folder.join("long.bin"), &longer).unwrap();
    let err = with_uri("long.bin").unwrap_err().to_string();
    assert!(err.contains(&format!("the scene declares {}", bin.len())), "{err}");
}

/// assimp's glTF 2.0 test models: the broken ones are refused in one line, the sound ones load,
/// and none panics (`assimp-testmodels`, which CI installs).
#[test]
fn assimp_gltf_models_load_or_are_refused() {
    let Some(root) = hdov_testkit::testdata::assimp_models("glTF2") else { return };
    let refused = [
        "IncorrectVertexArrays/Cube.gltf",
        "IndexOutOfRange/IndexOutOfRange.gltf",
        "IndexOutOfRange/AllIndicesOutOfRange.gltf",
        "MissingBin/BoxTextured.gltf",
        "RecursiveNodes/RecursiveNodes.gltf",
        "SchemaFailures/sceneWrongType.gltf",
        "TestNoRootNode/SceneWithoutNodes.gltf",
        "TestNoRootNode/NoScene.gltf",
        "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
        "wrongTypes/badNumber.gltf",
        "wrongTypes/badObject.gltf",
        "wrongTypes/badUint.gltf",
        "wrongTypes/badArray.gltf",
        "wrongTypes/badString.gltf",
    ];
    for f in refused {
        let err = Scene::load(&root.join(f)).expect_err(f).to_string();
        assert!(!err.contains('\n'), "{f}: {err}");
    }
    // Compressed geometry is refused by the extension's name.
    let draco = Scene::load(&root.join("draco/2CylinderEngine.gltf")).unwrap_err().to_string();
    assert!(draco.contains("KHR_draco_mesh_compression"), "{draco}");
    for f in [
        "BoxTextured-glTF/BoxTextured.gltf",
        "BoxTextured-glTF-Binary/BoxTextured.glb",
        "2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
    ] {
        let (scene, _) = Scene::load(&root.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(scene.triangle_count() > 0, "{f}");
    }
    // The glTF Asset Generator's cases: each loads or is refused; none panics.
    let mut files = Vec::new();
    let mut dirs = vec![root.join("glTF-Asset-Generator")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "gltf" || x == "glb") {
                files.push(p);
            }
        }
    }
    assert!(!files.is_empty());
    for f in files {
        let _ = Scene::load(&f);
    }
}

/// Instances cost no geometry: sixty instances of the cube store the same leaf LODs as three, and
/// the internal LODs, world-space summaries that would grow with the instances, stay within the
/// leaf LODs' bytes (nodes whose summary outweighs the one stored cube keep none).
#[test]
fn geometry_grows_with_base_meshes_not_instances() {
    let dir = tempfile::tempdir().unwrap();
    let leaf_bytes = |instances: usize| {
        let mut bin = buffer();
        bin.truncate(176);
        for k in 0..instances {
            bin.extend([(k % 10) as f32 * 3.0, 0.0, (k / 10) as f32 * 3.0 + 30.0].iter().flat_map(|v| v.to_le_bytes()));
        }
        let mut doc = document(bin.len(), Some(data_uri(&bin)));
        doc["bufferViews"][3]["byteLength"] = json!(12 * instances);
        doc["accessors"][3]["count"] = json!(instances);
        let gltf = write_gltf(dir.path(), &format!("crowd{instances}.gltf"), &doc);
        let (mut scene, _) = Scene::load(&gltf).unwrap();
        assert_eq!(scene.objects.len(), 3 + instances);
        scene.grid = Some(hdov::ViewGrid::new(
            hdov::Aabb::new(Vec3::new(-5.0, 1.5, 20.0), Vec3::new(35.0, 2.0, 28.0)),
            [2, 1, 1],
        ));
        let out = dir.path().join(format!("crowd{instances}.hdov"));
        let visibility =
            hdov::VisibilityParams { resolution: 16, backend: hdov::BackendKind::Cpu, ..Default::default() };
        let params = hdov::BuildParams { fanout: Some(4), visibility: Some(visibility), ..Default::default() };
        hdov::build(&scene, &out, &params, hdov::Overwrite::Never, &hdov::Progress::hidden()).unwrap();
        let info = hdov::Database::open(&out).unwrap().info().unwrap();
        assert!(info.internal_lod_bytes <= info.leaf_lod_bytes, "{info:?}");
        // Every mode still answers, descending through nodes without internal LODs.
        let db = hdov::Database::open(&out).unwrap();
        let at = Vec3::new(15.0, 1.7, 24.0);
        for (mode, eta, lod_rule) in [
            (hdov::Mode::Threshold, 1.0, hdov::LodRule::default()),
            (hdov::Mode::Threshold, 1.0, hdov::LodRule::Dov),
            (hdov::Mode::Vmsse, 0.0, hdov::LodRule::default()),
            (hdov::Mode::Budget, 0.0, hdov::LodRule::default()),
        ] {
            let p = hdov::QueryParams { mode, eta, lod_rule, budget: 10, ..Default::default() };
            let a = db.query(at, &p).unwrap();
            assert!(!a.items.is_empty(), "{mode} {lod_rule}");
        }
        info.leaf_lod_bytes
    };
    assert_eq!(leaf_bytes(3), leaf_bytes(60));
}

/// `glb` written as OBJ, one `o` group per node that draws a mesh, in world space: through the
/// `gltf` crate's own validation, accessor reader and transforms, not hdov's importer (the same
/// conversion as `tools/embree/glb_to_obj.py`, which needs Python's trimesh).
fn glb_as_obj(glb: &Path) -> String {
    use std::fmt::Write;
    let bytes = std::fs::read(glb).unwrap();
    let file = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = file.blob.clone().unwrap();
    let mut obj = String::new();
    let mut base = 1usize;
    let scene = file.document.default_scene().unwrap();
    // Pre-order, children in document order.
    let mut stack: Vec<(gltf::Node, glam::Mat4)> = scene.nodes().map(|n| (n, glam::Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * glam::Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            writeln!(obj, "o node{}", node.index()).unwrap();
            let mirrored = world.determinant() < 0.0;
            for prim in mesh.primitives() {
                assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles, "the sample holds triangle lists only");
                let reader = prim.reader(|_| Some(&blob[..]));
                let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
                for p in &positions {
                    let [x, y, z] = world.transform_point3(Vec3::from(*p)).to_array();
                    writeln!(obj, "v {x} {y} {z}").unwrap();
                }
                let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
                for t in indices.chunks_exact(3) {
                    let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize + base);
                    // A mirroring node keeps its outward winding.
                    let (b, c) = if mirrored { (c, b) } else { (b, c) };
                    writeln!(obj, "f {a} {b} {c}").unwrap();
                }
                base += positions.len();
            }
        }
        stack.extend(node.children().map(|c| (c, world)).collect::<Vec<_>>().into_iter().rev());
    }
    obj
}

/// A real model built from its `.glb` and from its OBJ conversion gives the same triangles and
/// the same DoV: 2CylinderEngine (67 parts sharing 29 meshes) at three points among its parts.
#[test]
fn the_engine_from_glb_and_from_obj_agree() {
    let Some(glb) = hdov_testkit::testdata::assimp_models("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb")
    else {
        return;
    };
    let glb = glb.as_path();
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("engine.obj");
    std::fs::write(&obj, glb_as_obj(glb)).unwrap();
    let (from_glb, _) = Scene::load(glb).unwrap();
    let (from_obj, _) = Scene::load(&obj).unwrap();
    assert_eq!(from_glb.objects.len(), from_obj.objects.len());
    assert_eq!((from_glb.meshes.len(), from_obj.meshes.len()), (29, 67), "shared meshes are stored once from glTF");
    assert_eq!(from_glb.triangle_count(), from_obj.triangle_count());
    assert_eq!(from_glb.triangle_count(), 110_336, "the sample less its zero-area triangles");
    let near = |a: hdov::Aabb, b: hdov::Aabb| {
        (a.min - b.min).abs().max_element() < 1e-3 && (a.max - b.max).abs().max_element() < 1e-3
    };
    // Object k is the same part in both: the tight box of its world-space triangles says so.
    let tight = |s: &Scene, k: usize| hdov::Aabb::from_points(s.object_triangles(k).flatten());
    for k in 0..from_glb.objects.len() {
        let (a, b) = (tight(&from_glb, k), tight(&from_obj, k));
        assert!(near(a, b), "object {k}: {a:?} against {b:?}");
    }
    let a = from_glb.bounds();
    // Three points among the engine's parts, each seeing nine or more of them: R = 64, the CPU backend.
    let (c, e) = (a.center(), a.extent());
    let points =
        [c + e * Vec3::new(-0.3, 0.55, -0.4), c + e * Vec3::new(0.05, -0.1, 0.6), c + e * Vec3::new(0.0, 0.6, 0.0)];
    let mut glb_backend = hdov::open_backend(&from_glb, 64, hdov::BackendKind::Cpu, &Default::default()).unwrap();
    let mut obj_backend = hdov::open_backend(&from_obj, 64, hdov::BackendKind::Cpu, &Default::default()).unwrap();
    for p in points {
        let (x, y) = (glb_backend.measure(p).unwrap(), obj_backend.measure(p).unwrap());
        // Objects come in the same order from both files; compare each object's DoV.
        assert_eq!(x.objects.len(), y.objects.len(), "{p}: the same objects are seen");
        let total = |d: &hdov::PointDov| d.objects.iter().map(|o| o.1).sum::<f64>();
        assert!(total(&x) > 0.15 && x.objects.len() >= 9, "{p}: the engine's parts fill some of the view");
        for (&(i, d), &(j, f)) in x.objects.iter().zip(&y.objects) {
            assert_eq!(i, j, "{p}");
            assert!((d - f).abs() <= 0.005 * d.max(f), "{p} object {i}: {d} against {f}");
        }
    }
}
