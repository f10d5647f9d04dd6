//! The `hdov` command as users and scripts see it: outputs, exit codes, one-line errors.

use std::path::Path;
use std::process::{Command, Output};

fn hdov(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hdov")).args(args).output().expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Fails unless the command exited non-zero with one `error:` line naming `what`.
fn assert_refused(o: &Output, what: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.starts_with("error: ") && err.trim_end().lines().count() == 1, "not one line: {err}");
    assert!(err.contains(what), "'{what}' not in: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn generate_build_info_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let city = tmp.path().join("city");
    let o = hdov(&["generate", "city", "--scale", "tiny", "--seed", "7", "--out", city.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let scene = city.join("city.json");
    let db = tmp.path().join("db");
    let o = hdov(&["build", scene.to_str().unwrap(), "--out", db.to_str().unwrap(), "--page-size", "512", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("build --json prints one JSON document");
    assert!(report["manifest"]["counts"]["nodes"].as_u64().unwrap() > 1);
    // Without --layouts, the slot budget of decision 134 holds (the tiny city's slots pass
    // none of it); naming layouts writes them whatever their size.
    let visibility = &report["manifest"]["build"]["visibility"];
    assert_eq!(visibility["slot_budget"].as_u64(), Some(hdov::DEFAULT_SLOT_BUDGET));
    assert_eq!(visibility["layouts"], serde_json::json!(["horizontal", "vertical", "indexed-vertical"]));
    assert_eq!(report["manifest"]["visibility"]["layouts"].as_array().unwrap().len(), 3);
    let named = tmp.path().join("named");
    let layouts = "horizontal,vertical,indexed-vertical";
    let o = hdov(&["build", scene.to_str().unwrap(), "--out", named.to_str().unwrap(), "--layouts", layouts, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let named: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(named["manifest"]["build"]["visibility"].get("slot_budget").is_none(), "{named}");
    assert_eq!(named["manifest"]["visibility"]["layouts"].as_array().unwrap().len(), 3);
    let o = hdov(&["info", db.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (loaded, _) = hdov::scene::Scene::load(&scene).unwrap();
    assert_eq!(info["objects"].as_u64().unwrap() as usize, loaded.objects.len());
    assert_eq!(info["triangles"].as_u64().unwrap(), loaded.triangle_count());
    assert_eq!(info["base_meshes"].as_u64().unwrap() as usize, loaded.meshes.len());
    assert_eq!(info["grid"]["dims"].as_array().unwrap().len(), 3);
    assert_eq!(info["grid"]["region"].as_array().unwrap().len(), 6);
    // A second build to the same place is refused, and the first database still opens.
    let o = hdov(&["build", scene.to_str().unwrap(), "--out", db.to_str().unwrap()]);
    assert_refused(&o, "exists; pass --force to replace it");
    assert!(hdov(&["info", db.to_str().unwrap()]).status.success());
    // The 3D Tiles export, under a root transform (a move of 100 along x), never over itself.
    let tiles = tmp.path().join("tiles");
    let shift = "1,0,0,0,0,1,0,0,0,0,1,0,100,0,0,1";
    let o = hdov(&["export", db.to_str().unwrap(), "--3dtiles", tiles.to_str().unwrap(), "--root-transform", shift]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("tiles"), "{}", String::from_utf8_lossy(&o.stdout));
    let set: serde_json::Value = serde_json::from_slice(&std::fs::read(tiles.join("tileset.json")).unwrap()).unwrap();
    assert_eq!(set["root"]["transform"][12], 100.0);
    let o = hdov(&["export", db.to_str().unwrap(), "--3dtiles", tiles.to_str().unwrap()]);
    assert_refused(&o, "exists");
    let o = hdov(&[
        "export",
        db.to_str().unwrap(),
        "--3dtiles",
        tmp.path().join("t2").to_str().unwrap(),
        "--root-transform",
        "1,0,0",
    ]);
    assert!(!o.status.success() && !tmp.path().join("t2").exists(), "16 numbers or none");
}

/// `--samples probe` builds with both backends (the GPU backend's rays by a CPU backend of the
/// scene), records the sampler and its default floor (box alone) in the manifest, and, without
/// floors, answers with every object a corner-only build answers with (it only adds points).
#[test]
fn probed_builds_record_their_sampler_and_keep_what_corners_see() {
    let tmp = tempfile::tempdir().unwrap();
    let city = tmp.path().join("city");
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", city.to_str().unwrap()]).status.success());
    let scene = city.join("city.json");
    let db = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    let build = |name: &str, args: &[&str]| -> serde_json::Value {
        let o = hdov(&[&["build", scene.to_str().unwrap(), "--out", &db(name), "--resolution", "32"], args].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice(&std::fs::read(tmp.path().join(name).join("manifest.json")).unwrap()).unwrap()
    };
    let probed = build("probed", &["--backend", "cpu", "--samples", "probe:8:2"]);
    assert_eq!(probed["build"]["visibility"]["sampling"], "probe:8:2");
    assert_eq!(probed["build"]["visibility"]["zero_dov_floor"], serde_json::json!(["box"]));
    // The default is region rays (decision 98), with both floors.
    let default = build("default", &["--backend", "cpu"]);
    assert_eq!(default["build"]["visibility"]["sampling"], "probe:32:4:24576");
    assert_eq!(default["build"]["visibility"]["zero_dov_floor"], serde_json::json!(["box", "neighbours", "parts"]));
    let bare = ["--backend", "cpu", "--zero-dov-floor", "none"];
    let corners = build("corners", &[&bare[..], &["--samples", "corners"]].concat());
    assert_eq!(corners["build"]["visibility"]["sampling"], "corners");
    build("probed-bare", &[&bare[..], &["--samples", "probe:8:2"]].concat());
    let objects = |name: &str, at: &str| -> std::collections::BTreeSet<u64> {
        let o = hdov(&["query", &db(name), "--at", at, "--eta", "0", "--mode", "naive", "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let a: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        a["items"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|i| i["kind"] == "object")
            .map(|i| i["id"].as_u64().unwrap())
            .collect()
    };
    let r = &corners["grid"]["region"];
    let (lo, hi) = (&r["min"], &r["max"]);
    let mut more = 0;
    for k in 0..6 {
        let f = |a: usize| {
            let (l, h) = (lo[a].as_f64().unwrap(), hi[a].as_f64().unwrap());
            l + (h - l) * (k as f64 + 0.5) / 6.0
        };
        let at = format!("{},{},{}", f(0), f(1), f(2));
        let (c, p) = (objects("corners", &at), objects("probed-bare", &at));
        assert!(c.is_subset(&p), "at {at}: corners see {:?} that probing lost", c.difference(&p).collect::<Vec<_>>());
        more += p.len() - c.len();
    }
    eprintln!("probing added {more} objects over 6 cells");
    if hdov_testkit::gpu::adapter_or_skip() {
        let gpu = build("gpu", &["--backend", "gpu", "--samples", "probe:8:2"]);
        assert_eq!(gpu["build"]["visibility"]["sampling"], "probe:8:2");
    }
}

/// `--force` replaces an hdov database or an empty folder, and nothing else: a user's folder,
/// a file, or the scene's own folder is refused in one line and left as it was.
#[test]
fn force_never_replaces_what_is_not_ours() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let scene = s("city/city.json");
    let fast = ["--no-visibility", "--force"];
    std::fs::create_dir(s("mine")).unwrap();
    std::fs::write(s("mine/thesis.tex"), b"years of work").unwrap();
    std::fs::write(s("notes.txt"), b"notes").unwrap();
    for target in ["mine", "notes.txt", "city"] {
        let o = hdov(&[&["build", scene.as_str(), "--out", &s(target)][..], &fast[..]].concat());
        assert_refused(&o, "not an hdov database or an empty directory");
    }
    assert_eq!(std::fs::read(s("mine/thesis.tex")).unwrap(), b"years of work");
    assert_eq!(std::fs::read(s("notes.txt")).unwrap(), b"notes");
    assert!(hdov(&["info", &s("city")]).status.code() == Some(2), "the scene folder is not a database");
    assert!(hdov(&["build", &scene, "--out", &s("city2"), "--no-visibility"]).status.success());
    let o = hdov(&["merge", &s("city2"), "--out", &s("mine"), "--force"]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(std::fs::read(s("mine/thesis.tex")).unwrap(), b"years of work");
    // An empty folder and an earlier database are replaced.
    std::fs::create_dir(s("empty")).unwrap();
    for target in ["empty", "city2"] {
        let o = hdov(&[&["build", scene.as_str(), "--out", &s(target)][..], &fast[..]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
    }
    // generate --force replaces a generated scene only; demo refuses a folder it did not write.
    std::fs::write(s("mine/city.json"), b"{\"mine\": true}").unwrap();
    assert_refused(&hdov(&["generate", "city", "--scale", "tiny", "--out", &s("mine"), "--force"]), "city.json");
    assert_eq!(std::fs::read(s("mine/city.json")).unwrap(), b"{\"mine\": true}");
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city"), "--force"]).status.success());
    assert_refused(&hdov(&["demo", "--out", &s("mine")]), "thesis.tex");
    assert_eq!(std::fs::read(s("mine/thesis.tex")).unwrap(), b"years of work");
}

/// Coordinates below zero are values, not flags; argument errors are one line like all others.
#[test]
fn negative_coordinates_and_one_line_argument_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let obj = tmp.path().join("centred.obj");
    let mut text = String::new();
    for (i, x) in [-15.0f32, -5.0, 5.0].iter().enumerate() {
        text += &format!("g box{i}\nv {x} 0 -1\nv {} 0 -1\nv {x} 3 -1\nv {} 3 -1\nf -4 -3 -1 -2\n", x + 2.0, x + 2.0);
    }
    std::fs::write(&obj, text).unwrap();
    let (obj, db) = (obj.to_str().unwrap(), tmp.path().join("db"));
    let db = db.to_str().unwrap();
    let o =
        hdov(&["build", obj, "--out", db, "--region", "-20,1.5,-10,0,2,10", "--grid", "2x1x2", "--resolution", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&hdov(&["info", db, "--json"]).stdout).unwrap();
    assert_eq!(info["grid"]["region"], serde_json::json!([-20.0, 1.5, -10.0, 0.0, 2.0, 10.0]));
    let o = hdov(&["dov", obj, "--at", "-10,1.7,0", "--backend", "cpu", "--resolution", "32", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dov: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let at: Vec<f32> = dov["at"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
    assert_eq!(at, [-10.0, 1.7, 0.0]);
    assert_refused(&hdov(&["build"]), "SCENE");
    assert_refused(&hdov(&["build", obj, "--out", db, "--frobnicate"]), "--frobnicate");
    assert_refused(&hdov(&["build", obj, "--out", db, "--grid", "0x1x1"]), "--grid");
    assert_refused(&hdov(&["dov", obj, "--at", "-10,1.7"]), "--at");
    assert_refused(&hdov(&["nonsense"]), "nonsense");
    assert!(hdov(&["--help"]).status.success() && hdov(&["--version"]).status.success());
}

/// Every bound is checked before any work: a refused build leaves nothing behind.
#[test]
fn out_of_bounds_arguments_are_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let scene = s("city/city.json");
    let out = s("db");
    for (args, flag) in [
        (&["--grid", "100000x1x100000"][..], "--grid"),
        (&["--grid", "4294967295x4294967295x4294967295"], "--grid"),
        (&["--cell-size", "0.00001"], "--cell-size"),
        (&["--cell-size", "-3"], "--cell-size"),
        (&["--samples", "100000"], "--samples"),
        (&["--grid", "2000x1x2000", "--samples", "64"], "--samples"),
        (&["--samples", "adaptive:0:4"], "--samples"),
        (&["--samples", "adaptive:2:5000"], "--samples"),
        (&["--grid", "2000x1x2000", "--samples", "adaptive:2:64"], "--samples"),
        (&["--samples", "probe:0:4"], "--samples"),
        (&["--samples", "probe:4"], "--samples"),
        (&["--resolution", "0"], "--resolution"),
        (&["--resolution", "1000000"], "--resolution"),
        (&["--page-size", "50"], "--page-size"),
        (&["--page-size", "99999999"], "--page-size"),
        (&["--lod-draw-tolerance", "-1"], "--lod-draw-tolerance"),
        (&["--region-views", "17", "--backend", "gpu"], "--region-views"),
        (&["--region-views", "2", "--backend", "cpu"], "--region-views"),
        (&["--zero-dov-floor", "box:-2"], "--zero-dov-floor"),
        (&["--zero-dov-floor", "walls"], "--zero-dov-floor"),
        (&["--shard", "3/3"], "--shard"),
        (&["--layouts", "vertical,vertical"], "--layouts"),
    ] {
        let o = hdov(&[&["build", scene.as_str(), "--out", out.as_str()][..], args].concat());
        assert_refused(&o, flag);
    }
    assert_refused(&hdov(&["generate", "city", "--blocks", "1000x1000", "--out", &s("big")]), "--blocks");
    let names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, vec![std::ffi::OsString::from("city")], "nothing but the scene");
}

#[test]
fn obj_groups_become_objects() {
    let tmp = tempfile::tempdir().unwrap();
    let obj = tmp.path().join("parts.obj");
    let mut text = String::new();
    for part in 0..5 {
        let x = part as f32 * 3.0;
        text += &format!("g part{part}\nv {x} 0 0\nv {} 0 0\nv {x} 1 0\nv {} 1 0\nf -4 -3 -1 -2\n", x + 1.0, x + 1.0);
    }
    text += "g part1\nv 0 0 5\nv 1 0 5\nv 0 1 5\nf -3 -2 -1\ng empty\n";
    std::fs::write(&obj, text).unwrap();
    let db = tmp.path().join("db");
    let o = hdov(&["build", obj.to_str().unwrap(), "--out", db.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("warning:") && stderr(&o).contains("'empty'"), "{}", stderr(&o));
    let info: serde_json::Value =
        serde_json::from_slice(&hdov(&["info", db.to_str().unwrap(), "--json"]).stdout).unwrap();
    assert_eq!(info["objects"], 6);
    assert_eq!(info["triangles"], 11);
}

#[test]
fn a_building_gets_cells_on_both_storeys() {
    // Issue 31: `hdov build --cell-size 2` refused (5, 4.6, 5), upstairs, as outside the grid.
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("building.json");
    hdov_testkit::scenes::two_storey_building().write_manifest(&scene, hdov::Overwrite::Never).unwrap();
    let db = tmp.path().join("db");
    let (scene, db_s) = (scene.to_str().unwrap(), db.to_str().unwrap());
    let o = hdov(&["build", scene, "--out", db_s, "--cell-size", "2", "--resolution", "16", "--samples", "corners"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for at in ["5,4.6,5", "2,1.7,2"] {
        let o = hdov(&["query", db_s, "--at", at]);
        assert!(o.status.success(), "{at}: {}", stderr(&o));
    }
    assert_refused(&hdov(&["query", db_s, "--at", "7.5,1.6,7.5"]), "is in no view cell");
    let info: serde_json::Value = serde_json::from_slice(&hdov(&["info", db_s, "--json"]).stdout).unwrap();
    assert_eq!(info["grid"]["sparse"], true);
    let cells = hdov(&["info", db_s, "--cells", "--json"]);
    let lines: Vec<serde_json::Value> = stdout_of(&cells).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len() as u64, info["cells"].as_u64().unwrap());
    assert!(lines.iter().any(|c| c["min"][1].as_f64().unwrap() > 3.3), "no cell upstairs");
    // Lattice cells are answered in quarters, and the ground floor's partition cuts some of
    // them: the view cells of a lattice cell share it, their places do not meet, and each one's
    // box is at most a quarter of the 2 m cell's footprint.
    let places = |c: &serde_json::Value| u64::from_str_radix(c["places"].as_str().unwrap(), 16).unwrap();
    let shared: Vec<&serde_json::Value> =
        lines.iter().filter(|c| lines.iter().filter(|d| d["cell"] == c["cell"]).count() > 1).collect();
    assert!(!shared.is_empty(), "no lattice cell answered in parts");
    for c in &shared {
        let others = lines.iter().filter(|d| d["cell"] == c["cell"] && d["id"] != c["id"]);
        assert!(others.into_iter().all(|d| places(d) & places(c) == 0));
    }
    let width = |c: &serde_json::Value, a: usize| c["max"][a].as_f64().unwrap() - c["min"][a].as_f64().unwrap();
    assert!(
        lines.iter().all(|c| width(c, 0) <= 1.0 + 1e-4 && width(c, 2) <= 1.0 + 1e-4),
        "a view cell wider than a quarter"
    );
    let text = stdout_of(&hdov(&["info", db_s]));
    assert!(text.contains("where a viewer can stand"), "{text}");
    // Objects in parts on cells where viewers stand take the box and parts floors, a grid or
    // the file's objects the neighbours too (decision 127); a floor named is a floor taken.
    let floors = |db: &Path| -> Vec<String> {
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
        let floors = manifest.pointer("/build/visibility/zero_dov_floor").expect("the floors are recorded");
        floors.as_array().unwrap().iter().map(|f| f.as_str().unwrap().to_string()).collect()
    };
    assert_eq!(floors(&db), ["box", "parts"]);
    for (extra, expected) in [
        (&["--grid", "5x2x5"][..], &["box", "neighbours", "parts"][..]),
        (&["--cell-size", "2", "--objects", "file"], &["box", "neighbours", "parts"]),
        (&["--cell-size", "2", "--zero-dov-floor", "box,neighbours", "--objects", "file"], &["box", "neighbours"]),
    ] {
        let other = tmp.path().join(format!("db{}", extra.len()));
        let args = [
            &["build", scene, "--out", other.to_str().unwrap(), "--resolution", "16", "--samples", "region"][..],
            extra,
        ];
        let o = hdov(&args.concat());
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(floors(&other), expected, "{extra:?}");
    }
}

#[test]
fn bad_input_is_one_line_and_nonzero() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    std::fs::write(p("bad.obj"), "v 0 0 0\nv 1 0 x\nf 1 2 3\n").unwrap();
    std::fs::write(p("nan.obj"), "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(p("empty.obj"), "").unwrap();
    std::fs::write(p("scene.txt"), "").unwrap();
    let out = p("db");
    assert_refused(&hdov(&["build", &p("missing.obj"), "--out", &out]), "missing.obj");
    assert_refused(&hdov(&["build", &p("bad.obj"), "--out", &out]), "bad.obj");
    assert_refused(&hdov(&["build", &p("nan.obj"), "--out", &out]), "non-finite");
    assert_refused(&hdov(&["build", &p("empty.obj"), "--out", &out]), "empty.obj");
    assert_refused(&hdov(&["build", &p("scene.txt"), "--out", &out]), "unknown scene format");
    assert_refused(&hdov(&["info", &p("nowhere")]), "nowhere");
    assert!(!Path::new(&out).exists(), "a failed build leaves nothing behind");
    let names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(names.iter().all(|n| !n.to_string_lossy().contains("tmp")), "{names:?}");
}

/// A build killed at any moment leaves the old database intact (or the new one complete): never
/// a half-written database that opens.
#[test]
fn killed_build_leaves_the_old_database() {
    let tmp = tempfile::tempdir().unwrap();
    let city = tmp.path().join("city");
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", city.to_str().unwrap()]).status.success());
    let scene = city.join("city.json");
    let db = tmp.path().join("db");
    assert!(hdov(&["build", scene.to_str().unwrap(), "--out", db.to_str().unwrap()]).status.success());
    let before = std::fs::read(db.join("manifest.json")).unwrap();
    for delay_ms in [5, 50, 200] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_hdov"))
            .args(["build", scene.to_str().unwrap(), "--out", db.to_str().unwrap(), "--force", "--page-size", "1024"])
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        let status = child.wait().unwrap();
        let o = hdov(&["info", db.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "after a kill at {delay_ms} ms: {}", stderr(&o));
        let now = std::fs::read(db.join("manifest.json")).unwrap();
        if !status.success() {
            // Killed before its rename: the old database, byte for byte.
            assert!(now == before || now.windows(4).any(|w| w == b"1024"), "manifest changed without a complete build");
        }
    }
}

/// Real multi-part OBJ exports from Debian's `assimp-testmodels` (installed by `.ci/run`).
#[test]
fn real_multi_part_obj_files_import_one_object_per_group() {
    let Some(dir) = hdov_testkit::testdata::assimp_models("") else { return };
    let tmp = tempfile::tempdir().unwrap();
    for name in ["spider", "regr01"] {
        let obj = dir.join(format!("OBJ/{name}.obj"));
        // Independent count: one object per group that has faces, n − 2 fan triangles per
        // n-gon, less those of zero area (which import drops).
        let text = String::from_utf8_lossy(&std::fs::read(&obj).unwrap()).into_owned();
        let (mut groups, mut triangles, mut group_has_faces) = (0u64, 0u64, false);
        let mut v: Vec<glam::DVec3> = Vec::new();
        for line in text.lines() {
            let mut tok = line.split_whitespace();
            match tok.next() {
                Some("v") => {
                    v.push(glam::DVec3::from_slice(&tok.map(|x| x.parse().unwrap()).collect::<Vec<f64>>()[..3]))
                }
                Some("g" | "o") => group_has_faces = false,
                Some("f") => {
                    let idx: Vec<usize> = tok
                        .map(|t| t.split('/').next().unwrap().parse::<i64>().unwrap())
                        .map(|i| if i > 0 { i as usize - 1 } else { (v.len() as i64 + i) as usize })
                        .collect();
                    let area = |k: usize| (v[idx[k]] - v[idx[0]]).cross(v[idx[k + 1]] - v[idx[0]]).length();
                    triangles += (1..idx.len() - 1).filter(|&k| area(k) > 0.0).count() as u64;
                    if !group_has_faces {
                        groups += 1;
                        group_has_faces = true;
                    }
                }
                _ => {}
            }
        }
        let db = tmp.path().join(name);
        // The file's objects: what the import made of the groups (by default large ones are cut).
        let o = hdov(&["build", obj.to_str().unwrap(), "--out", db.to_str().unwrap(), "--objects", "file"]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let info: serde_json::Value =
            serde_json::from_slice(&hdov(&["info", db.to_str().unwrap(), "--json"]).stdout).unwrap();
        assert!(groups > 10, "{name} has many parts");
        assert_eq!(info["objects"], groups, "{name}");
        assert_eq!(info["triangles"], triangles, "{name}");
    }
    for bad in ["malformed.obj", "malformed2.obj", "empty.obj"] {
        let obj = dir.join("invalid").join(bad);
        assert_refused(&hdov(&["build", obj.to_str().unwrap(), "--out", tmp.path().join("x").to_str().unwrap()]), bad);
    }
}

/// Shards built separately keep only their V-data; merged with a base build they equal one
/// whole build, file for file; a wrong set of shards, or a wrong base, is refused.
#[test]
fn shards_merge_into_the_whole_database() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--seed", "4", "--out", &s("city")]).status.success());
    let scene = s("city/city.json");
    let common = ["--resolution", "16", "--backend", "cpu", "--page-size", "1024"];
    let build = |out: &str, extra: &[&str]| {
        let mut args = vec!["build", scene.as_str(), "--out", out];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        let o = hdov(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    build(&s("whole"), &[]);
    build(&s("base"), &["--no-visibility"]);
    for i in 0..3 {
        build(&s(&format!("shard{i}")), &["--shard", &format!("{i}/3")]);
    }
    // A shard holds its manifest and V-pages, not the scene: it names the files it was
    // measured against, and is no database to query.
    let bytes_of = |dir: &str| -> u64 {
        std::fs::read_dir(tmp.path().join(dir)).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum()
    };
    for f in ["tree.pages", "geometry.blob", "catalog.blob", "vpages.horizontal", "vpages.vertical"] {
        assert!(!tmp.path().join("shard1").join(f).exists(), "a shard keeps no {f}");
    }
    assert!(
        bytes_of("shard1") * 10 < bytes_of("base"),
        "{} bytes against the base's {}",
        bytes_of("shard1"),
        bytes_of("base")
    );
    assert_refused(&hdov(&["query", &s("shard1"), "--at", "1,1.7,1"]), "is a shard");
    let o = hdov(&["merge", &s("base"), &s("shard0"), &s("shard2"), &s("shard1"), "--out", &s("merged")]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Every file but the manifest is identical, byte for byte. The manifest differs in what
    // the shards measured, not what they stored: build seconds, and sample points (each shard
    // also measures the corners it shares with its neighbours' cells).
    let names = |dir: &str| {
        let mut v: Vec<String> = std::fs::read_dir(tmp.path().join(dir))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names("whole"), names("merged"));
    assert_eq!(names("whole").len(), 9, "{:?}", names("whole"));
    for f in names("whole").iter().filter(|f| *f != "manifest.json") {
        let (a, b) = (
            std::fs::read(tmp.path().join("whole").join(f)).unwrap(),
            std::fs::read(tmp.path().join("merged").join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs between the merged and the whole build");
    }
    let manifest = |dir: &str| -> serde_json::Value {
        let mut m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(tmp.path().join(dir).join("manifest.json")).unwrap()).unwrap();
        let v = m["visibility"].as_object_mut().unwrap();
        // Times (the seconds and where they went) and counts of measurements differ by design.
        let measured = (v.remove("seconds").unwrap(), v.remove("sample_points").unwrap(), v.remove("phases").unwrap());
        assert!(measured.0.as_f64().unwrap() > 0.0);
        assert!(measured.2["search"].as_f64().unwrap() > 0.0, "{}", measured.2);
        m
    };
    assert_eq!(manifest("whole"), manifest("merged"));
    // Damaged or forged shards are refused in one line, never a panic.
    let forge = |from: &str, to: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let (src, dst) = (tmp.path().join(from), tmp.path().join(to));
        std::fs::create_dir(&dst).unwrap();
        for e in std::fs::read_dir(&src).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
        }
        let path = dst.join("manifest.json");
        let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        edit(&mut m);
        std::fs::write(&path, serde_json::to_vec(&m).unwrap()).unwrap();
    };
    forge("shard1", "bad-index", &|m| m["build"]["visibility"]["shard"] = serde_json::json!([7, 3]));
    forge("shard1", "huge-count", &|m| m["build"]["visibility"]["shard"] = serde_json::json!([1, 4_000_000_000u32]));
    forge("shard1", "no-vis", &|m| m["visibility"] = serde_json::Value::Null);
    for (bad, why) in
        [("bad-index", "0 ≤ I < N"), ("huge-count", "more shards than"), ("no-vis", "no shard with visibility")]
    {
        assert_refused(&hdov(&["merge", &s("base"), &s("shard0"), &s(bad), &s("shard2"), "--out", &s("m6")]), why);
    }
    forge("shard2", "broken-file", &|_| {});
    std::fs::write(tmp.path().join("broken-file/vpages.indexed-vertical"), b"HDOVPAGE").unwrap();
    assert_refused(
        &hdov(&["merge", &s("base"), &s("shard0"), &s("shard1"), &s("broken-file"), "--out", &s("m7")]),
        "vpages.indexed-vertical",
    );
    assert!(!tmp.path().join("m6").exists() && !tmp.path().join("m7").exists());
    let merge = |base: &str, shards: [&str; 3], out: &str| {
        hdov(&["merge", &s(base), &s(shards[0]), &s(shards[1]), &s(shards[2]), "--out", &s(out)])
    };
    assert_refused(
        &hdov(&["merge", &s("base"), &s("shard0"), &s("shard1"), "--out", &s("m2")]),
        "shard 2/3 is missing",
    );
    assert_refused(&merge("base", ["shard0", "shard0", "shard1"], "m3"), "as is");
    assert_refused(&hdov(&["merge", &s("base"), &s("whole"), "--out", &s("m4")]), "not a shard");
    build(&s("other"), &["--shard", "1/3", "--zero-dov-floor", "none"]);
    assert_refused(&merge("base", ["shard0", "other", "shard2"], "m5"), "other parameters");
    // The base must be the shards' own: the same parameters, the same scene.
    let base_of = |scene: &str, out: &str, page_size: &str| {
        let o = hdov(&[
            "build",
            scene,
            "--out",
            out,
            "--no-visibility",
            "--resolution",
            "16",
            "--backend",
            "cpu",
            "--page-size",
            page_size,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    base_of(&scene, &s("base-512"), "512");
    assert_refused(&merge("base-512", ["shard0", "shard1", "shard2"], "m8"), "other parameters than");
    // The same city with one house moved by a metre: the same grid and parameters, other files.
    std::fs::create_dir(tmp.path().join("moved")).unwrap();
    std::fs::copy(tmp.path().join("city/city.meshes"), tmp.path().join("moved/city.meshes")).unwrap();
    let mut city: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("city/city.json")).unwrap()).unwrap();
    let x = city["objects"][0]["transform"][12].as_f64().unwrap();
    city["objects"][0]["transform"][12] = serde_json::json!(x + 1.0);
    std::fs::write(tmp.path().join("moved/city.json"), serde_json::to_vec(&city).unwrap()).unwrap();
    base_of(&s("moved/city.json"), &s("base5"), "1024");
    assert_refused(&merge("base5", ["shard0", "shard1", "shard2"], "m9"), "measured against another scene");
    // A shard built on the base (`--base`: no tree, LODs or catalog of its own) is the same
    // shard, file for file; a base of other parameters or of another scene is refused.
    build(&s("on-base1"), &["--shard", "1/3", "--base", &s("base")]);
    assert_eq!(names("shard1"), names("on-base1"));
    for f in names("shard1") {
        let (a, b) = (
            std::fs::read(tmp.path().join("shard1").join(&f)).unwrap(),
            std::fs::read(tmp.path().join("on-base1").join(&f)).unwrap(),
        );
        assert!(a == b || f == "manifest.json", "{f} differs between the shard and the shard built on the base");
    }
    assert_eq!(manifest("shard1"), manifest("on-base1"));
    let on_base = |base: &str, out: &str| {
        let mut args = vec!["build", scene.as_str(), "--out", out, "--shard", "1/3", "--base", base];
        args.extend_from_slice(&common);
        hdov(&args)
    };
    assert_refused(&on_base(&s("base5"), &s("m10")), "another scene");
    assert_refused(&on_base(&s("base-512"), &s("m11")), "other parameters");
    for m in ["m2", "m3", "m4", "m5", "m8", "m9", "m10", "m11"] {
        assert!(!tmp.path().join(m).exists(), "{m}");
    }
}

/// `--detail-model` instances a real mesh (here a two-group OBJ, merged into one model).
#[test]
fn detail_model_from_an_obj_file() {
    let tmp = tempfile::tempdir().unwrap();
    let obj = tmp.path().join("statue.obj");
    let mut text = String::from("o body\n");
    // An octahedron (8 faces) and a separate box-ish quad pair (2 faces) in a second group.
    for v in ["0 1 0", "1 0 0", "0 0 1", "-1 0 0", "0 0 -1", "0 -1 0"] {
        text += &format!("v {v}\n");
    }
    text += "f 1 2 3\nf 1 3 4\nf 1 4 5\nf 1 5 2\nf 6 3 2\nf 6 4 3\nf 6 5 4\nf 6 2 5\n";
    text += "o base\nv -1 -1 -1\nv 1 -1 -1\nv 1 -1 1\nv -1 -1 1\nf 7 8 9 10\n";
    std::fs::write(&obj, text).unwrap();
    let out = tmp.path().join("city");
    let o = hdov(&[
        "generate",
        "city",
        "--scale",
        "tiny",
        "--detail-model",
        obj.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (scene, _) = hdov::scene::Scene::load(&out.join("city.json")).unwrap();
    assert_eq!(scene.meshes[0].mesh.triangle_count(), 10, "both groups of the model, merged");
    let statues = scene.objects.iter().filter(|o| o.mesh == 0).count();
    assert!(statues > 1, "the model is instanced ({statues} instances)");
}

/// `hdov query` and `hdov walk` print the documented JSON, and refuse bad viewpoints and paths
/// in one line.
#[test]
fn query_and_walk_answer_in_json() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let o = hdov(&[
        "build",
        &s("city/city.json"),
        "--out",
        &s("db"),
        "--resolution",
        "16",
        "--backend",
        "cpu",
        "--fanout",
        "4",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&hdov(&["info", &s("db"), "--json"]).stdout).unwrap();
    let r = &info["grid"]["region"];
    let (x, z) = (r[0].as_f64().unwrap() + 5.0, r[2].as_f64().unwrap() + 8.0);
    let at = format!("{x},1.7,{z}");
    for mode in ["threshold", "naive", "budget", "vmsse", "frustum"] {
        let o = hdov(&["query", &s("db"), "--at", &at, "--mode", mode, "--json"]);
        assert!(o.status.success(), "{mode}: {}", stderr(&o));
        let a: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(a["cell"].as_array().unwrap().len(), 3);
        assert!(a["eta"].is_number() && a["mode"] == mode);
        let items = a["items"].as_array().unwrap();
        assert!(!items.is_empty(), "{mode} sees something");
        for i in items {
            for key in ["kind", "id", "name", "lod", "faces", "dov"] {
                assert!(!i[key].is_null(), "{mode}: item without {key}: {i}");
            }
        }
        for key in ["pages_read", "nodes_visited", "faces", "micros"] {
            assert!(a["stats"][key].is_u64(), "{mode}: stats without {key}");
        }
    }
    let far = format!("{},1.7,{z}", x + 1e5);
    assert_refused(&hdov(&["query", &s("db"), "--at", &far]), "--at: ");
    assert_refused(&hdov(&["query", &s("db"), "--at", &at, "--eta", "3"]), "--eta");
    // A walk: a CSV path, with comments, view directions, and a step back into a cell.
    let mut path = String::from("# x,y,z[,dx,dy,dz]\n");
    for k in 0..12 {
        path += &format!("{},1.7,{z},1,0,0\n", x + 6.0 * k as f64);
    }
    path += &format!("{x},1.7,{z}\n");
    std::fs::write(s("walk.csv"), path).unwrap();
    let o = hdov(&["walk", &s("db"), "--path", &s("walk.csv"), "--cache", "dov-time", "--cache-pages", "8", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let steps = w["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 13);
    for st in steps {
        for key in
            ["step", "at", "cell", "flipped", "loaded", "evicted", "pages_read", "hits", "misses", "faces", "micros"]
        {
            assert!(!st[key].is_null(), "step without {key}: {st}");
        }
    }
    assert!(steps[0]["flipped"] == true && w["summary"]["flips"].as_u64().unwrap() >= 2);
    // The same path by REVIEW: disk cells, CSearch, a DPLRU cache, prefetch.
    let review = |extra: &[&str]| {
        let (db, path) = (s("db"), s("walk.csv"));
        let mut args = vec!["walk", db.as_str(), "--path", path.as_str(), "--method", "review", "--cache", "dplru"];
        args.extend_from_slice(extra);
        hdov(&args)
    };
    let o = review(&["--review-box", "1.5", "--eyesight", "20", "--fov", "60", "--prefetch", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let steps = w["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 13);
    assert!(steps[0]["flipped"] == true && w["summary"]["flips"].as_u64().unwrap() >= 2, "{}", w["summary"]);
    assert!(w["summary"]["pages_read"].as_u64().unwrap() > 0 && w["summary"]["loaded_bytes"].as_u64().unwrap() > 0);
    assert_refused(&review(&["--eyesight", "0"]), "--eyesight");
    assert_refused(&review(&["--review-box", "0.5"]), "--review-box");
    assert_refused(&hdov(&["walk", &s("db"), "--path", &s("walk.csv"), "--method", "spatial"]), "spatial");
    std::fs::write(s("bad.csv"), format!("{x},1.7,{z}\n{x},oops,{z}\n")).unwrap();
    assert_refused(&hdov(&["walk", &s("db"), "--path", &s("bad.csv")]), "bad.csv: line 2");
    std::fs::write(s("out.csv"), format!("{x},1.7,{z}\n{},1.7,{z}\n", x + 1e5)).unwrap();
    assert_refused(&hdov(&["walk", &s("db"), "--path", &s("out.csv")]), "out.csv: line 2");
    // A recorded walk instead of a file; the turning walk's gaze leaves the avenue's axis.
    let o = hdov(&["walk", &s("db"), "--walk", "turning", "--steps", "9", "--lod-rule", "dov", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(w["steps"].as_array().unwrap().len(), 9);
    assert_refused(&hdov(&["walk", &s("db"), "--walk", "sideways"]), "sideways");
    assert_refused(&hdov(&["walk", &s("db"), "--walk", "straight", "--path", &s("walk.csv")]), "--path");
    assert_refused(&hdov(&["walk", &s("db")]), "--path");
    assert_refused(&hdov(&["query", &s("db"), "--at", &format!("{x},1.7,{z}"), "--lod-rule", "screen:-2"]), "≥ 0");
}

/// `hdov render` writes a PNG of the answer (or full detail), reports fidelity against full
/// detail in JSON, and refuses bad views in one line.
#[test]
fn render_writes_a_png_and_reports_fidelity() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let o = hdov(&["build", &s("city/city.json"), "--out", &s("db"), "--resolution", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let view = ["--at", "115,1.8,105", "--look", "1,0,0.3"];
    let db = s("db");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", db.as_str()];
        args.extend_from_slice(&view);
        args.extend_from_slice(extra);
        hdov(&args)
    };
    assert_refused(&render(&["--size", "0x10"]), "--size");
    assert_refused(&render(&["--color", "rainbow"]), "rainbow");
    assert_refused(&hdov(&["render", &db, "--at", "115,1.8,105", "--look", "0,0,0"]), "--look");
    if !hdov_testkit::gpu::adapter_or_skip() {
        return;
    }
    let out = s("answer.png");
    let o = render(&["--size", "64x40", "--color", "lod", "--out", &out, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON document");
    assert!(report["fidelity"]["coverage_diff"].as_f64().unwrap() <= 1.0);
    assert!(report["items"].as_u64().unwrap() > 0);
    let decoder = png::Decoder::new(std::fs::File::open(&out).unwrap());
    let reader = decoder.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (64, 40));
    let full = s("full.png");
    let o = render(&["--size", "64x40", "--full", "--out", &full]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("full detail"));
    let o = render(&["--size", "64x40", "--pair", "--out", &s("pair.png")]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("PSNR"), "{}", stderr(&o));
    let reader = png::Decoder::new(std::fs::File::open(s("pair.png")).unwrap()).read_info().unwrap();
    assert_eq!(reader.info().width, 64 * 2 + 4);
}

/// `hdov walk --fidelity` adds PSNR and coverage difference against full detail to each step
/// with a view direction, and none to a step without one.
#[test]
fn walk_reports_fidelity_per_step_with_a_look() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let o = hdov(&["build", &s("city/city.json"), "--out", &s("db"), "--resolution", "16", "--backend", "cpu"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&hdov(&["info", &s("db"), "--json"]).stdout).unwrap();
    let r = &info["grid"]["region"];
    let (x, z) = (r[0].as_f64().unwrap() + 5.0, r[2].as_f64().unwrap() + 8.0);
    let mut path: String = (0..4).map(|k| format!("{},1.7,{z},1,0,0\n", x + 8.0 * k as f64)).collect();
    path += &format!("{x},1.7,{z}\n");
    std::fs::write(s("walk.csv"), path).unwrap();
    assert_refused(&hdov(&["walk", &s("db"), "--path", &s("walk.csv"), "--fidelity", "--size", "0x9"]), "--size");
    if !hdov_testkit::gpu::adapter_or_skip() {
        return;
    }
    for method in ["visual", "review"] {
        let (db, walk) = (s("db"), s("walk.csv"));
        let args = ["walk", &db, "--path", &walk, "--method", method, "--fidelity", "--size", "64x40", "--json"];
        let o = hdov(&args);
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let steps = w["steps"].as_array().unwrap();
        assert_eq!(steps.len(), 5);
        for st in &steps[..4] {
            // PSNR is null in JSON where the images are equal (+∞).
            let psnr = st["psnr"].as_f64().unwrap_or(f64::INFINITY);
            assert!(psnr >= 0.0 && st.get("psnr").is_some(), "{method}: {st}");
            let c = st["coverage_diff"].as_f64().unwrap();
            assert!((0.0..=1.0).contains(&c), "{method}: {st}");
        }
        assert!(steps[4].get("psnr").is_none() && steps[4].get("coverage_diff").is_none(), "{}", steps[4]);
    }
}

/// Everything that draws works on a GL-only adapter (Mesa's llvmpipe through EGL, as on a
/// machine without `mesa-vulkan-drivers`): `render`, `walk --fidelity` and the GPU DoV backend.
/// None of them, nor a default build (`--backend auto` probes for an adapter), lets the graphics
/// drivers' Wayland probe print `XDG_RUNTIME_DIR` complaints when that variable is unset, as on
/// servers and CI.
#[test]
fn drawing_works_on_gl_alone_and_adapter_probes_stay_quiet() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    let run = |gl: bool, args: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_hdov"));
        c.args(args).env_remove("XDG_RUNTIME_DIR").env_remove("WGPU_BACKEND");
        if gl {
            c.env("WGPU_BACKEND", "gl");
        }
        c.output().expect("runs")
    };
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let o = run(false, &["build", &s("city/city.json"), "--out", &s("db"), "--resolution", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("XDG_RUNTIME_DIR"), "a default build printed: {}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&hdov(&["info", &s("db"), "--json"]).stdout).unwrap();
    let r = &info["grid"]["region"];
    let (x, z) = (r[0].as_f64().unwrap() + 5.0, r[2].as_f64().unwrap() + 8.0);
    let at = format!("{x},1.7,{z}");
    let render = ["render", &s("db"), "--at", &at, "--look", "1,0,0", "--size", "64x40", "--out", &s("gl.png")];
    let o = run(true, &render);
    if stderr(&o).contains("no graphics adapter") && std::env::var("HDOV_REQUIRE_ADAPTER").as_deref() != Ok("1") {
        hdov_testkit::skip("no GL adapter");
        return;
    }
    assert!(o.status.success(), "render on GL: {}", stderr(&o));
    assert!(stdout_of(&o).contains("on Gl"), "not drawn on GL: {}", stdout_of(&o));
    assert!(!stderr(&o).contains("XDG_RUNTIME_DIR"), "{}", stderr(&o));
    assert!(std::fs::metadata(s("gl.png")).unwrap().len() > 0);
    let walk = ["walk", &s("db"), "--walk", "turning", "--steps", "3", "--fidelity", "--size", "64x40", "--json"];
    let o = run(true, &walk);
    assert!(o.status.success(), "walk --fidelity on GL: {}", stderr(&o));
    let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(w["steps"].as_array().unwrap().iter().any(|st| st.get("coverage_diff").is_some()), "{w}");
    let o = run(true, &["dov", &s("city/city.json"), "--at", &at, "--backend", "gpu", "--resolution", "16"]);
    assert!(o.status.success(), "dov on GL: {}", stderr(&o));
    assert!(!stderr(&o).contains("XDG_RUNTIME_DIR"), "{}", stderr(&o));
}

fn stdout_of(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Output piped into a reader that stops early (`hdov info DB | head -1`) ends the command
/// quietly, without a panic.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_the_command_quietly() {
    use std::process::Stdio;
    let tmp = tempfile::tempdir().unwrap();
    let s = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    assert!(hdov(&["generate", "city", "--scale", "tiny", "--out", &s("city")]).status.success());
    let o = hdov(&["build", &s("city/city.json"), "--out", &s("db"), "--resolution", "8", "--backend", "cpu"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut child = Command::new(env!("CARGO_BIN_EXE_hdov"))
        .args(["info", &s("db")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // the reader goes away before the first line
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
}
