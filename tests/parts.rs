//! Objects from the geometry (issue 31): a floor slab that spans four walled rooms is cut into
//! parts, and a cell in one room answers with that room's floor alone; `--objects file` keeps the
//! file's object whole.

use glam::{Mat4, Vec3};
use hdov::progress::Progress;
use hdov::{
    BackendKind, BuildParams, Database, ItemKind, Mode, ObjectParts, Overwrite, QueryParams, Sampling, Scene, ViewGrid,
    VisibilityParams,
};

/// A 40 × 40 m floor of 40 × 40 quads (one object, as an exporter writes one material), walled
/// into four 20 × 20 m rooms 3 m high; cells of 2 m at eye height.
fn four_rooms() -> Scene {
    let mut s = Scene::default();
    let n = 40u32;
    let mut floor = hdov::Mesh::default();
    for j in 0..=n {
        for i in 0..=n {
            floor.positions.push([i as f32, 0.0, j as f32]);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            floor.indices.extend([a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]);
        }
    }
    let mesh = s.add_mesh("floor", floor);
    s.add_object("floor", mesh, Mat4::IDENTITY);
    let (t, h) = (0.2, 3.0);
    for (name, min, max) in [
        ("wall x=0", Vec3::new(-t, 0.0, 0.0), Vec3::new(0.0, h, 40.0)),
        ("wall x=40", Vec3::new(40.0, 0.0, 0.0), Vec3::new(40.0 + t, h, 40.0)),
        ("wall z=0", Vec3::new(0.0, 0.0, -t), Vec3::new(40.0, h, 0.0)),
        ("wall z=40", Vec3::new(0.0, 0.0, 40.0), Vec3::new(40.0, h, 40.0 + t)),
        ("wall x=20", Vec3::new(20.0 - t / 2.0, 0.0, 0.0), Vec3::new(20.0 + t / 2.0, h, 40.0)),
        ("wall z=20", Vec3::new(0.0, 0.0, 20.0 - t / 2.0), Vec3::new(40.0, h, 20.0 + t / 2.0)),
        ("ceiling", Vec3::new(0.0, h, 0.0), Vec3::new(40.0, h + t, 40.0)),
    ] {
        s.add_box(name, min, max);
    }
    s.grid = Some(ViewGrid::new(hdov::Aabb::new(Vec3::new(0.0, 1.5, 0.0), Vec3::new(40.0, 1.7, 40.0)), [20, 1, 20]));
    s
}

fn build(scene: &Scene, objects: ObjectParts) -> (tempfile::TempDir, Database) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("db");
    let params = BuildParams {
        objects,
        visibility: Some(VisibilityParams {
            resolution: 64,
            backend: BackendKind::Cpu,
            sampling: Sampling::CORNERS,
            ..Default::default()
        }),
        ..Default::default()
    };
    hdov::build(scene, &out, &params, Overwrite::Never, &Progress::hidden()).unwrap();
    let db = Database::open(&out).unwrap();
    (dir, db)
}

#[test]
fn a_cell_sees_its_rooms_floor_parts_only() {
    let scene = four_rooms();
    let (_dir, db) = build(&scene, ObjectParts::Geometry);
    let parts = db.catalog().objects.iter().filter(|o| &*o.name == "floor").count();
    // 40 m halved until ≤ 4 m (two 2 m cells): 16 × 16 parts of 2.5 m.
    assert_eq!(parts, 256);
    assert_eq!(db.manifest().build.objects, ObjectParts::Geometry);
    let naive = QueryParams { mode: Mode::Naive, ..Default::default() };
    let answer = db.query(Vec3::new(9.0, 1.6, 9.0), &naive).unwrap();
    let floor: Vec<_> = answer.items.iter().filter(|i| i.kind == ItemKind::Object && &*i.name == "floor").collect();
    assert!(!floor.is_empty());
    // What the room's points see is the room's floor; the parts floor (decision 123) adds, at the
    // one-texel floor, the parts that touch a seen one: the slab goes on under the wall, one
    // part (2.5 m) into the next room and no further.
    let texel_floor = hdov::dov::CubeMap::new(64).texel_floor() as f32;
    for item in &floor {
        assert!(item.part.is_some());
        let c = item.mbr.center();
        if item.dov > texel_floor {
            assert!(c.x < 20.0 && c.z < 20.0, "part {:?} of another room seen, centre {c}", item.part);
        } else {
            assert!(c.x < 22.5 && c.z < 22.5, "part {:?} two parts into another room, centre {c}", item.part);
        }
    }
    // The room's 8 × 8 parts and the ring of 17 past its walls at most (of 256).
    assert!(floor.len() <= 64 + 17, "{} floor parts", floor.len());
    eprintln!("{} of {parts} floor parts seen from the room", floor.len());
    // The answer names the file's object and its part, in JSON too.
    let json = serde_json::to_value(floor[0]).unwrap();
    assert_eq!(json["name"], "floor");
    assert!(json["part"].is_u64());
}

#[test]
fn objects_file_keeps_the_files_objects_whole() {
    let scene = four_rooms();
    let (_dir, db) = build(&scene, ObjectParts::File);
    assert_eq!(db.catalog().objects.len(), scene.objects.len());
    assert!(db.catalog().objects.iter().all(|o| o.part.is_none()));
    let naive = QueryParams { mode: Mode::Naive, ..Default::default() };
    let answer = db.query(Vec3::new(9.0, 1.6, 9.0), &naive).unwrap();
    let floor: Vec<_> = answer.items.iter().filter(|i| &*i.name == "floor").collect();
    assert_eq!(floor.len(), 1);
    assert_eq!(floor[0].part, None);
    assert!(serde_json::to_value(floor[0]).unwrap().get("part").is_none());
}
