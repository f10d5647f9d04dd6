//! The three V-page layouts written by `hdov build` for a generated city hold the same
//! V-entries, and those are exactly what the DoV precompute produced.

use hdov::Overwrite;
use hdov::city::{CityParams, CityScale};
use hdov::dov::BackendKind;
use hdov::dov::precompute::{PrecomputeOptions, Shard, TreeShape, precompute_shard};
use hdov::progress::Progress;
use hdov::rtree::RTree;
use hdov::{BuildParams, Database, VisibilityParams};
use hdov_storage::{LayoutKind, PageReader};
use proptest::prelude::*;

const RESOLUTION: u32 = 24;

struct Fixture {
    _tmp: tempfile::TempDir,
    db: Database,
    expected: hdov_storage::VData,
}

fn fixture() -> Fixture {
    let scene = hdov::city::generate(&CityParams { seed: 3, scale: CityScale::Tiny, ..Default::default() }).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("db");
    let params = BuildParams {
        page_size: 512,
        visibility: Some(VisibilityParams { resolution: RESOLUTION, backend: BackendKind::Cpu, ..Default::default() }),
        ..Default::default()
    };
    hdov::build(&scene, &dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
    // The same measurement, independently: the tree is deterministic, so are its V-pages.
    let tree = RTree::build(&scene.all_object_bounds(), hdov::format::tree_page::fanout(512), params.tree);
    let shape = TreeShape::of(&tree);
    let mut backend = hdov::dov::CpuBackend::new(&scene, RESOLUTION).unwrap();
    let grid = scene.grid.clone().unwrap();
    let dov = precompute_shard(
        &mut backend,
        &grid,
        &scene.all_object_bounds(),
        &shape,
        &PrecomputeOptions::of(params.visibility.as_ref().unwrap()),
        Shard::ALL,
        &hdov::progress::Quiet,
    )
    .unwrap();
    let expected = hdov::build::vpages::vdata_from_cells(&tree, grid.cell_count() as u32, &dov.cells);
    Fixture { _tmp: tmp, db: Database::open(&dir).unwrap(), expected }
}

#[test]
fn layouts_agree_with_each_other_and_with_the_precompute() {
    let f = fixture();
    assert_eq!(f.db.layouts(), LayoutKind::ALL.to_vec());
    // One cursor per layout, all reading through one page reader (one read buffer per file).
    let readers = std::cell::RefCell::new((
        LayoutKind::ALL.iter().map(|&k| f.db.layout(k).unwrap().cursor()).collect::<Vec<_>>(),
        PageReader::uncached(),
    ));
    let cells = f.expected.cell_count;
    let nodes = f.db.node_count();
    assert!(nodes > 3, "a 512-byte page gives a tree with several nodes");
    let visible: usize = f.expected.cells.iter().map(|c| c.len()).sum();
    assert!(visible > cells as usize, "the city is visible from its streets");
    let config = ProptestConfig { cases: 200, ..Default::default() };
    proptest!(config, |(cell in 0..cells, node in 0..nodes)| {
        let want = f.expected.cells[cell as usize].iter().find(|(n, _)| *n == node).map(|(_, v)| v.clone());
        let (cursors, pages) = &mut *readers.borrow_mut();
        for r in cursors.iter_mut() {
            r.flip_to_cell(cell, pages).unwrap();
            let kind = r.layout().kind();
            prop_assert_eq!(r.vpage(node, 0.0, pages).unwrap(), want.clone(), "{} cell {} node {}", kind, cell, node);
        }
    });
    // And exhaustively, every (cell, node); a horizontal flip reads nothing.
    let (cursors, pages) = &mut *readers.borrow_mut();
    for cell in 0..cells {
        for r in cursors.iter_mut() {
            let flip = r.flip_to_cell(cell, pages).unwrap();
            let kind = r.layout().kind();
            if kind == LayoutKind::Horizontal {
                assert_eq!(flip.pages_read, 0);
            }
            let got: Vec<_> = (0..nodes).filter_map(|n| r.vpage(n, 0.0, pages).unwrap().map(|v| (n, v))).collect();
            assert_eq!(got, f.expected.cells[cell as usize], "{} cell {cell}", kind);
        }
    }
    for io in pages.io().files {
        assert_eq!(io.requested, io.hits + io.pages_read, "{io:?}");
    }
}

/// The slot budget (decision 134) leaves out the layouts whose slots for every (node, cell)
/// would pass it, says so in the manifest and in the error of a query that asks for one, and
/// changes no answer; the merge of shards leaves out the same layouts as the whole build.
#[test]
fn a_slot_budget_leaves_out_the_layouts_that_would_pass_it() {
    let scene = hdov::city::generate(&CityParams { seed: 3, scale: CityScale::Tiny, ..Default::default() }).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let v = |slot_budget, layouts: &[LayoutKind], shard| VisibilityParams {
        resolution: RESOLUTION,
        backend: BackendKind::Cpu,
        slot_budget,
        layouts: layouts.to_vec(),
        shard,
        ..Default::default()
    };
    let build = |name: &str, visibility: Option<VisibilityParams>| {
        let dir = tmp.path().join(name);
        let params = BuildParams { page_size: 512, visibility, ..Default::default() };
        hdov::build(&scene, &dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
        dir
    };
    let open = |dir: std::path::PathBuf| Database::open(&dir).unwrap();
    let left_out = |db: &Database| -> Vec<(LayoutKind, u64)> {
        db.manifest().visibility.as_ref().unwrap().left_out.iter().map(|l| (l.kind, l.slot_bytes)).collect()
    };
    let all = open(build("all", Some(v(None, &LayoutKind::ALL, None))));
    assert_eq!(all.layouts(), LayoutKind::ALL.to_vec());
    assert!(left_out(&all).is_empty());

    let none = open(build("none", Some(v(Some(1), &LayoutKind::ALL, None))));
    assert_eq!(none.layouts(), vec![LayoutKind::IndexedVertical]);
    let out = left_out(&none);
    assert_eq!(out.iter().map(|l| l.0).collect::<Vec<_>>(), [LayoutKind::Horizontal, LayoutKind::Vertical]);
    // What the left-out layouts would have taken is what the whole build wrote of them: the
    // horizontal layout's V-pages are all slots; vertical's segments are part of its index.
    let written = all.info().unwrap().layouts;
    assert_eq!(out[0].1, written[&LayoutKind::Horizontal].vpage_bytes);
    assert!(out[1].1 > 0 && out[1].1 < written[&LayoutKind::Vertical].bytes, "{out:?}");
    let horizontal = |q: hdov::QueryParams| hdov::QueryParams { layout: Some(LayoutKind::Horizontal), ..q };
    let at = scene.grid.as_ref().unwrap().cell_centres()[0];
    let err = none.query(at, &horizontal(Default::default())).err().unwrap().to_string();
    assert!(err.contains("holds no horizontal layout") && err.contains(&out[0].1.to_string()), "{err}");
    let naive = hdov::QueryParams { mode: hdov::Mode::Naive, ..Default::default() };
    for at in scene.grid.as_ref().unwrap().cell_centres() {
        for q in [naive, hdov::QueryParams::default()] {
            let (got, want) = (none.query(at, &q).unwrap(), all.query(at, &horizontal(q)).unwrap());
            assert!(!want.items.is_empty() && got.items == want.items, "{at}");
        }
    }

    // A budget between the two: vertical's slots fit, horizontal's do not.
    let between = open(build("between", Some(v(Some(out[1].1), &LayoutKind::ALL, None))));
    assert_eq!(between.layouts(), vec![LayoutKind::Vertical, LayoutKind::IndexedVertical]);
    assert_eq!(left_out(&between), out[..1]);
    // Without indexed-vertical asked for, the budget leaves nothing out.
    let alone = open(build("alone", Some(v(Some(1), &[LayoutKind::Horizontal], None))));
    assert_eq!(alone.layouts(), vec![LayoutKind::Horizontal]);

    // Shards merge into what the whole build wrote: under the budget, and without one (shards
    // of a build before decision 134 record none) every layout.
    let base = build("base", None);
    for (budget, want) in [(Some(1), &out[..]), (None, &[][..])] {
        let shards: Vec<_> = (0..2)
            .map(|i| {
                let shard = Some(hdov::Shard::new(i, 2).unwrap());
                build(&format!("shard{i}-{budget:?}"), Some(v(budget, &LayoutKind::ALL, shard)))
            })
            .collect();
        let merged = tmp.path().join(format!("merged-{budget:?}"));
        hdov::merge(&base, &shards, &merged, Overwrite::Never).unwrap();
        let merged = open(merged);
        assert_eq!(left_out(&merged), want);
        assert_eq!(merged.layouts().len() + want.len(), 3);
    }

    // A manifest whose written and left-out layouts are not those asked for, under a budget they
    // pass, is refused: a written layout also listed as left out, one left out that was not asked
    // for, one left out without a budget, indexed-vertical left out.
    let tamper = |db: &str, change: &dyn Fn(&mut serde_json::Value)| {
        let path = tmp.path().join(db).join("manifest.json");
        let good = std::fs::read(&path).unwrap();
        let mut json: serde_json::Value = serde_json::from_slice(&good).unwrap();
        change(&mut json);
        std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
        let err = Database::open(&tmp.path().join(db)).err().map(|e| e.to_string());
        std::fs::write(&path, good).unwrap();
        assert!(err.as_deref().is_some_and(|e| e.contains("left out")), "{err:?}");
    };
    let left_out_json = |kind: &str| serde_json::json!([{ "name": kind, "slot_bytes": 1u64 << 40 }]);
    tamper("between", &|j| j["visibility"]["left_out"][0]["name"] = "vertical".into());
    tamper("alone", &|j| j["visibility"]["left_out"] = left_out_json("vertical"));
    tamper("none", &|j| {
        j["build"]["visibility"].as_object_mut().unwrap().remove("slot_budget");
    });
    tamper("none", &|j| j["build"]["visibility"]["slot_budget"] = (1u64 << 50).into());
    tamper("none", &|j| {
        j["visibility"]["left_out"]
            .as_array_mut()
            .unwrap()
            .extend(left_out_json("indexed-vertical").as_array().unwrap().clone());
        j["visibility"]["layouts"] = serde_json::json!([]);
    });
    assert_eq!(open(tmp.path().join("none")).layouts(), vec![LayoutKind::IndexedVertical]);
}
