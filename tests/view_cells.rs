//! View cells where a viewer can stand (issue 31): a scene without a grid of its own gets cells
//! at eye height above every storey's floor and none inside solids, queries from where a person
//! stands are answered on every storey, and a point inside a solid is refused in one line.

use glam::Vec3;
use hdov::dov::BackendKind;
use hdov::progress::Progress;
use hdov::{
    BuildParams, Database, EyeHeights, ItemKind, Mode, Overwrite, QueryParams, Sampling, Scene, VisibilityParams,
};

/// Where people stand in [`hdov_testkit::scenes::two_storey_building`], eyes 1.1–1.9 m up: both
/// rooms of the ground floor (by the door, in a corner, beside the core), the upper floor (above
/// the core too) and the roof.
const STANDING: [[f32; 3]; 9] = [
    [2.0, 1.7, 2.0],
    [4.6, 1.1, 4.5],
    [5.4, 1.9, 4.5],
    [0.4, 1.5, 9.6],
    [5.6, 1.6, 8.0],
    [2.0, 5.0, 2.0],
    [8.0, 4.6, 8.0],
    [9.6, 5.2, 0.4],
    [5.0, 8.3, 5.0],
];

/// Inside the core, inside the upper floor's slab, under the ground slab, and above the roof's
/// eye heights.
const SOLID_OR_AIR: [[f32; 3]; 4] = [[7.5, 1.6, 7.5], [2.0, 3.15, 2.0], [5.0, -0.15, 5.0], [5.0, 9.5, 5.0]];

/// Inside walls 0.3 m thick, in cells where people stand beside them: the outer walls on both
/// storeys and the partition.
const IN_WALLS: [[f32; 3]; 4] = [[0.15, 1.5, 5.0], [5.0, 1.5, 2.0], [9.85, 4.8, 3.0], [3.0, 4.8, 0.12]];

/// `scene` built at `dir` with the file's objects, R = 32 on the CPU and no floors, so that
/// nothing but the samples counts; opened.
fn build_without_floors(scene: &Scene, dir: &std::path::Path) -> Database {
    let params = BuildParams {
        objects: hdov::ObjectParts::File,
        visibility: Some(VisibilityParams {
            resolution: 32,
            backend: BackendKind::Cpu,
            zero_dov_floor: vec![],
            ..Default::default()
        }),
        ..Default::default()
    };
    hdov::build(scene, dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
    Database::open(dir).unwrap()
}

fn grid(scene: &Scene) -> hdov::ViewGrid {
    scene.view_grid(None, None, Some(2.0), EyeHeights::default()).unwrap()
}

#[test]
fn cells_are_where_people_stand_on_every_storey_and_not_in_solids() {
    let scene = hdov_testkit::scenes::two_storey_building();
    let g = grid(&scene);
    let present = |p: [f32; 3]| g.cell_of(Vec3::from(p)).is_some_and(|c| g.is_present(g.cell_id(c)));
    for p in STANDING {
        assert!(present(p), "{p:?} is where a person stands, but in no view cell");
    }
    for p in SOLID_OR_AIR {
        assert!(!present(p), "{p:?} is inside a solid or out of reach, but in a view cell");
    }
    let stands = |p: [f32; 3]| {
        let c = g.cell_of(Vec3::from(p)).unwrap();
        g.standing_cell(g.cell_id(c), c, Vec3::from(p)).is_some()
    };
    for p in STANDING {
        assert!(stands(p), "{p:?} is where a person stands, but refused within its cell");
    }
    for p in IN_WALLS {
        assert!(present(p) && !stands(p), "{p:?} is inside a wall");
    }
    // Cells are 2 m wide and one eye height (1 m) tall. On the ground floor (eyes 1–2 m: one
    // layer) the core and the walls around it fill 4 of the 25 columns; upstairs (eyes at
    // 4.3–5.3) and on the roof (7.6–8.6) two layers of all 25.
    assert_eq!(g.cell_size(), Vec3::new(2.0, 1.0, 2.0));
    let layer = |y: u32| g.present_ids().filter(|&id| id < g.lattice_count() && g.cell_coords(id)[1] == y).count();
    assert_eq!((0..g.dims[1]).map(layer).collect::<Vec<_>>(), vec![21, 0, 0, 25, 25, 0, 25, 25]);
    // The four ground-floor cells the partition runs through are cut into one view cell per
    // room (the fifth has the door, which joins them); every view cell is a quarter of its
    // lattice cell or less, and none spans a wall.
    assert_eq!(scene.cells_across_walls(2.0, EyeHeights::default()).unwrap(), (4, 484));
    for id in g.present_ids() {
        assert_eq!(hdov::grid::place_parts(g.places_of(id)).len(), 1, "view cell {id} spans a wall");
        assert!(hdov::grid::QUARTERS.iter().any(|q| g.places_of(id) & !q == 0), "view cell {id} spans quarters");
    }
    for z in [1.0, 3.0, 7.0, 9.0] {
        let (west, east) = (Vec3::new(4.6, 1.5, z), Vec3::new(5.4, 1.5, z));
        let c = g.cell_of(west).unwrap();
        assert_eq!(g.cell_of(east), Some(c));
        let side = |p| g.standing_cell(g.cell_id(c), c, p);
        assert!(side(west).is_some() && side(east).is_some() && side(west) != side(east), "z = {z}");
    }
    // A cell marked from a floor never reaches below it: every cell's bottom is at or above
    // the ground floor, and none spans the upper floor's slab (3.0–3.3).
    for id in g.present_ids() {
        let b = g.cell_box(g.cell_coords(id));
        assert!(b.min.y >= 0.0 && !(b.min.y < 3.0 && b.max.y > 3.3), "cell {id} spans {:?}", [b.min.y, b.max.y]);
    }
}

#[test]
fn nowhere_to_stand_falls_back_and_bad_eye_heights_are_refused() {
    // A vertical sheet has no surface facing up: no cells where a viewer stands, and the
    // default grid falls back to one layer over the footprint at eye height.
    let mut sheet = Scene::default();
    sheet.add_box("sheet", Vec3::ZERO, Vec3::new(0.0, 3.0, 4.0));
    let e = sheet.standable_grid(1.0, EyeHeights::default()).unwrap_err().to_string();
    assert!(e.contains("no floor found"), "{e}");
    let g = sheet.view_grid(None, None, Some(1.0), EyeHeights::default()).unwrap();
    assert_eq!((g.present, g.dims), (None, [1, 1, 4]));
    let scene = hdov_testkit::scenes::two_storey_building();
    for (low, high) in [(0.0, 1.0), (2.0, 1.0), (f32::NAN, 1.0)] {
        let e = scene.view_grid(None, None, Some(2.0), EyeHeights { low, high }).unwrap_err().to_string();
        assert!(e.starts_with("eye_heights: ") && !e.contains('\n'), "{e}");
    }
    let e = scene.view_grid(None, None, Some(0.0001), EyeHeights::default()).unwrap_err().to_string();
    assert!(e.starts_with("cell_size: ") && e.contains("more than"), "{e}");
}

#[test]
fn both_storeys_answer_and_a_solid_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let mut scene = hdov_testkit::scenes::two_storey_building();
    scene.grid = Some(grid(&scene));
    let params = BuildParams {
        objects: hdov::ObjectParts::File,
        visibility: Some(VisibilityParams {
            resolution: 32,
            backend: BackendKind::Cpu,
            sampling: Sampling::CORNERS,
            ..Default::default()
        }),
        ..Default::default()
    };
    let dir = tmp.path().join("db");
    let report = hdov::build(&scene, &dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
    let g = scene.grid.as_ref().unwrap();
    let db = Database::open(&dir).unwrap();
    assert_eq!(db.info().unwrap().cells, g.present_count() as u64);
    assert_eq!(report.manifest.visibility.as_ref().unwrap().cells_computed, g.present_count() as u64);
    assert_eq!(db.grid(), Some(g));

    let naive = QueryParams { mode: Mode::Naive, eta: 0.0, ..Default::default() };
    // The partition with the door (objects 11–13) is seen from the ground floor only.
    let partition = |p: [f32; 3]| {
        let a = db.query(Vec3::from(p), &naive).unwrap();
        a.items.iter().any(|i| i.kind == ItemKind::Object && (11..=13).contains(&i.id))
    };
    for p in STANDING {
        let a = db.query(Vec3::from(p), &naive).unwrap();
        assert!(!a.items.is_empty(), "{p:?}: nothing visible");
    }
    assert!(partition(STANDING[0]) && partition(STANDING[4]));
    assert!(!partition(STANDING[5]) && !partition(STANDING[6]), "the upper floor sees through its slab");
    for p in SOLID_OR_AIR {
        let e = db.query(Vec3::from(p), &naive).unwrap_err().to_string();
        assert!(e.starts_with("at: ") && !e.contains('\n'), "{e}");
    }
    let e = db.query(Vec3::new(7.5, 1.6, 7.5), &naive).unwrap_err().to_string();
    assert!(e.contains("is in no view cell"), "{e}");
    for p in IN_WALLS {
        let e = db.query(Vec3::from(p), &naive).unwrap_err().to_string();
        assert!(e.contains("inside a wall") && !e.contains('\n'), "{p:?}: {e}");
    }
}

/// Two rooms, a box in each, and a 0.3 m wall between them through the middle of a column of
/// 2 m cells: each side of the wall is a view cell of its own, sampled where its viewers
/// stand, and sees its own room's box only (no floors, so that nothing but the samples counts).
#[test]
fn a_wall_through_a_cell_parts_its_answers() {
    let mut b = hdov_testkit::scenes::SceneBuilder::default();
    let v = Vec3::new;
    b.aabox(v(0.0, -0.3, 0.0), v(10.0, 0.0, 4.0));
    b.aabox(v(4.9, 0.0, -1.0), v(5.2, 3.0, 5.0));
    let west = b.aabox(v(1.0, 0.0, 1.0), v(2.0, 1.0, 2.0));
    let east = b.aabox(v(8.0, 0.0, 1.0), v(8.5, 1.0, 2.0));
    let mut scene = b.build();
    let g = grid(&scene);
    let (w, e) = (v(4.6, 1.5, 2.0), v(5.5, 1.5, 2.0));
    let c = g.cell_of(w).unwrap();
    assert_eq!(g.cell_of(e), Some(c), "both sides in one lattice cell");
    scene.grid = Some(g);
    let tmp = tempfile::tempdir().unwrap();
    let db = build_without_floors(&scene, &tmp.path().join("db"));
    let (wc, ec) = (db.locate(w).unwrap(), db.locate(e).unwrap());
    assert!(wc.0 == ec.0 && wc.1 != ec.1, "{wc:?} {ec:?}");
    let naive = QueryParams { mode: Mode::Naive, eta: 0.0, ..Default::default() };
    let sees = |p: Vec3, object: u32| {
        db.query(p, &naive).unwrap().items.iter().any(|i| i.kind == ItemKind::Object && i.id == object)
    };
    assert!(sees(w, west) && !sees(w, east), "the west side sees the east room");
    assert!(sees(e, east) && !sees(e, west), "the east side sees the west room");
}

/// A view cell is a quarter of its lattice cell, and answers what is seen from it, not from the
/// rest of the lattice cell: a box 30 m away, seen past the end of a tall wall 0.5 m beyond
/// the cell from the part of the cell beyond x = 1.5 only, is in the answers of the two
/// quarters beyond x = 1 and not of the other two, nor from the squares around them, which
/// reach x = 1.25 (no floors, so that nothing but the samples counts).
#[test]
fn a_quarter_of_a_cell_answers_what_is_seen_from_it() {
    let mut b = hdov_testkit::scenes::SceneBuilder::default();
    let v = Vec3::new;
    b.aabox(v(0.0, -0.3, 0.0), v(2.0, 0.0, 2.0));
    b.aabox(v(-20.0, 0.0, 2.45), v(1.5, 10.0, 2.55));
    let far = b.aabox(v(-0.5, 0.0, 30.0), v(0.5, 3.0, 31.0));
    let mut scene = b.build();
    let g = grid(&scene);
    let quarters = [v(0.5, 1.5, 0.5), v(0.5, 1.5, 1.5), v(1.5, 1.5, 0.5), v(1.5, 1.5, 1.5)];
    let c = g.cell_of(quarters[0]).unwrap();
    assert!(quarters.iter().all(|&p| g.cell_of(p) == Some(c)), "one lattice cell");
    assert_eq!(g.view_cells_of(g.cell_id(c)).count(), 4, "four quarters");
    scene.grid = Some(g);
    let tmp = tempfile::tempdir().unwrap();
    let db = build_without_floors(&scene, &tmp.path().join("db"));
    let naive = QueryParams { mode: Mode::Naive, eta: 0.0, ..Default::default() };
    let sees = |p: Vec3| db.query(p, &naive).unwrap().items.iter().any(|i| i.kind == ItemKind::Object && i.id == far);
    let cells: Vec<_> = quarters.iter().map(|&p| db.locate(p).unwrap()).collect();
    assert!(cells.windows(2).all(|w| w[0] != w[1]), "{cells:?}");
    assert!(!sees(quarters[0]) && !sees(quarters[1]), "the wall hides the box from x < 1");
    assert!(sees(quarters[2]) && sees(quarters[3]), "the box is seen past the wall's end from x > 1");
}

/// A viewer on the border between two quarters, whom the query places in one of them, gets
/// what is seen from the border: a strip 30 m away, its right edge at x = 1, is seen past a tall
/// wall from x ≤ 1 and from at most 1 cm beyond. A viewer at x = 1 is answered by a quarter
/// beyond x = 1, which takes what was seen from the squares just across its border (no floors,
/// so that nothing but the samples counts; the sampler's unit test
/// `a_view_cell_takes_what_was_seen_from_the_squares_around_it` checks the rule itself).
#[test]
fn a_viewer_on_the_border_of_two_quarters_gets_what_is_seen_from_it() {
    let mut b = hdov_testkit::scenes::SceneBuilder::default();
    let v = Vec3::new;
    // From x = 0, the scene's least x, the lattice's cells are 2 m: x = 1 is a quarter's border.
    b.aabox(v(0.0, -0.3, 0.0), v(2.0, 0.0, 2.0));
    b.aabox(v(1.0, -100.0, 2.45), v(20.0, 100.0, 2.55));
    let far = b.aabox(v(0.9, -100.0, 30.0), v(1.0, 100.0, 30.5));
    let mut scene = b.build();
    scene.grid = Some(grid(&scene));
    let tmp = tempfile::tempdir().unwrap();
    let db = build_without_floors(&scene, &tmp.path().join("db"));
    let naive = QueryParams { mode: Mode::Naive, eta: 0.0, ..Default::default() };
    let sees = |p: Vec3| db.query(p, &naive).unwrap().items.iter().any(|i| i.kind == ItemKind::Object && i.id == far);
    for z in [0.5, 1.5] {
        let border = v(1.0, 1.5, z);
        let (here, before) = (db.locate(border).unwrap(), db.locate(v(0.5, 1.5, z)).unwrap());
        assert_eq!(here.0, before.0, "one lattice cell");
        assert_eq!(here, db.locate(v(1.5, 1.5, z)).unwrap(), "answered by the quarter beyond");
        assert!(sees(v(0.5, 1.5, z)) && sees(border), "z {z}");
    }
}

/// Cells where viewers stand (quarters, sides of walls) are sharded with their lattice cells:
/// shards of the two-storey building, merged, equal its whole build file for file. Each
/// manifest says where its bake's time went: the phases that ran, within the stage's seconds;
/// the merged one, the shards' sums; one written before a phase, or any, was recorded still
/// opens.
#[test]
fn shards_of_cells_where_viewers_stand_merge_into_the_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let mut scene = hdov_testkit::scenes::two_storey_building();
    scene.grid = Some(grid(&scene));
    assert!(!scene.grid.as_ref().unwrap().parts.is_empty());
    let build = |name: &str, visibility: Option<VisibilityParams>| {
        let params = BuildParams { objects: hdov::ObjectParts::File, visibility, ..Default::default() };
        let dir = tmp.path().join(name);
        hdov::build(&scene, &dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
        dir
    };
    let v = |shard| VisibilityParams { resolution: 16, backend: BackendKind::Cpu, shard, ..Default::default() };
    let whole = build("whole", Some(v(None)));
    let base = build("base", None);
    let shards: Vec<_> =
        (0..3).map(|i| build(&format!("shard{i}"), Some(v(Some(hdov::Shard::new(i, 3).unwrap()))))).collect();
    let merged = tmp.path().join("merged");
    hdov::merge(&base, &shards, &merged, Overwrite::Never).unwrap();
    let names = |dir: &std::path::Path| {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    };
    assert_eq!(names(&whole), names(&merged));
    let layouts = names(&whole).into_iter().filter(|f| f.starts_with("vpages.")).count();
    assert!(layouts >= 1, "{:?}", names(&whole));
    for f in names(&whole).iter().filter(|f| *f != "manifest.json") {
        assert!(std::fs::read(whole.join(f)).unwrap() == std::fs::read(merged.join(f)).unwrap(), "{f} differs");
    }
    assert_eq!(
        Database::open(&merged).unwrap().info().unwrap().cells,
        Database::open(&whole).unwrap().info().unwrap().cells
    );

    let info = |dir: &std::path::Path| hdov::Manifest::read(dir).unwrap().visibility.unwrap();
    let ran = info(&whole);
    let phases = ran.phases.clone().expect("a new build records its phases");
    // Region rays (the default sampler), refined into quarters: every phase but the samplers'
    // own cube maps ran.
    for (name, s) in phases.named() {
        assert_eq!(s > 0.0, name != "points", "{name}: {s} s");
    }
    let spent: f64 = phases.named().iter().map(|p| p.1).sum();
    assert!(spent <= ran.seconds, "{spent} s of phases in {} s", ran.seconds);
    let mut sum = hdov::BakePhases::default();
    for s in &shards {
        sum.add(&info(s).phases.unwrap());
    }
    // serde_json reads a float back to within an ulp, not always bit for bit.
    let close = |a: &hdov::BakePhases, b: &hdov::BakePhases| {
        for ((name, x), (_, y)) in a.named().into_iter().zip(b.named()) {
            assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-3), "{name}: {x} against {y}");
        }
    };
    close(&info(&merged).phases.unwrap(), &sum);
    // A manifest written before a phase was recorded, and before any were.
    let path = whole.join("manifest.json");
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    json["visibility"]["phases"].as_object_mut().unwrap().remove("border_rays");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    close(&info(&whole).phases.unwrap(), &hdov::BakePhases { border_rays: 0.0, ..phases });
    json["visibility"].as_object_mut().unwrap().remove("phases");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    assert_eq!(info(&whole).phases, None);
}
