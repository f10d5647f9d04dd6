//! Objects from the geometry (issue 31): a floor slab that spans four walled rooms is cut into
//! parts, and a cell in one room answers with that room's floor alone; `--objects file` keeps the
//! file's object whole.

use glam::{Mat4, Vec3};
use hdov::progress::Progress;
use hdov::{
    BackendKind, BuildParams, Database, FloorTest, ItemKind, Mode, ObjectParts, Overwrite, QueryParams, Sampling,
    Scene, ViewGrid, VisibilityParams,
};

/// A 40 × 40 m floor of 40 × 40 quads (one object, as an exporter writes one material), walled
/// into four 20 × 20 m rooms 3 m high; cells of 2 m at eye height.
fn four_rooms() -> Scene {
    let mut s = Scene::default();
    let mut floor = hdov::Mesh::default();
    sheet(&mut floor, Vec3::ZERO, Vec3::Z * 40.0, Vec3::X * 40.0, 40, 40);
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

/// Adds to `mesh` a sheet of `n` × `m` quads from `origin` along `u` and `v`, its front towards
/// `u × v` (counter-clockwise).
fn sheet(mesh: &mut hdov::Mesh, origin: Vec3, u: Vec3, v: Vec3, n: u32, m: u32) {
    let first = mesh.positions.len() as u32;
    for j in 0..=m {
        for i in 0..=n {
            mesh.positions.push((origin + u * (i as f32 / n as f32) + v * (j as f32 / m as f32)).to_array());
        }
    }
    for j in 0..m {
        for i in 0..n {
            let a = first + j * (n + 1) + i;
            mesh.indices.extend([a, a + 1, a + n + 1, a + 1, a + n + 2, a + n + 1]);
        }
    }
}

#[test]
fn the_parts_floor_adds_only_parts_that_turn_a_face_to_the_cell() {
    // Two rooms on one floor, split by a wall 6 m thick and 3 m high: one object (one material)
    // of its face to room A (x = 17), its top and its face to room B (x = 23). Cut into parts,
    // the parts on room B's side (x > 20: the top's far half and room B's face) touch the parts
    // room A sees, but turn only their backs to room A's cells (below the top, behind B's face).
    let mut s = Scene::default();
    let mut floor = hdov::Mesh::default();
    sheet(&mut floor, Vec3::ZERO, Vec3::Z * 20.0, Vec3::X * 40.0, 20, 40);
    let mesh = s.add_mesh("floor", floor);
    s.add_object("floor", mesh, Mat4::IDENTITY);
    let (y, z) = (Vec3::Y * 3.0, Vec3::Z * 20.0);
    let mut wall = hdov::Mesh::default();
    sheet(&mut wall, Vec3::new(17.0, 0.0, 0.0), z, y, 20, 3);
    sheet(&mut wall, Vec3::new(17.0, 3.0, 0.0), z, Vec3::X * 6.0, 20, 6);
    sheet(&mut wall, Vec3::new(23.0, 0.0, 0.0), y, z, 3, 20);
    let mesh = s.add_mesh("wall", wall);
    s.add_object("wall", mesh, Mat4::IDENTITY);
    s.grid = Some(ViewGrid::new(hdov::Aabb::new(Vec3::new(0.0, 1.5, 0.0), Vec3::new(40.0, 1.7, 20.0)), [20, 1, 10]));

    let dir = tempfile::tempdir().unwrap();
    let params = BuildParams {
        objects: ObjectParts::Geometry,
        visibility: Some(VisibilityParams {
            resolution: 64,
            backend: BackendKind::Cpu,
            sampling: Sampling::CORNERS,
            zero_dov_floor: vec![FloorTest::BoxWithin(0.0), FloorTest::PartNeighbours],
            ..Default::default()
        }),
        ..Default::default()
    };
    hdov::build(&s, &dir.path().join("db"), &params, Overwrite::Never, &Progress::hidden()).unwrap();
    let db = Database::open(&dir.path().join("db")).unwrap();
    let wall_parts: Vec<_> = db.catalog().objects.iter().filter(|o| &*o.name == "wall").collect();
    assert!(wall_parts.len() >= 16, "{} wall parts", wall_parts.len());
    let naive = QueryParams { mode: Mode::Naive, ..Default::default() };
    let answer = db.query(Vec3::new(9.0, 1.6, 9.0), &naive).unwrap();
    let wall: Vec<_> = answer.items.iter().filter(|i| &*i.name == "wall").collect();
    // Room A sees its face of the wall ...
    assert!(wall.iter().any(|i| i.mbr.min.x < 17.5), "room A sees no part of its face of the wall");
    // ... and the parts floor adds none of the parts behind it, though they touch what it sees.
    for item in &wall {
        assert!(
            item.mbr.min.x < 20.0,
            "part {:?} of room B's side of the wall ({:?}) in room A's answer",
            item.part,
            item.mbr
        );
    }
}
