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
    let left_out = |db: &Database| -> Vec<(String, u64)> {
        db.manifest().visibility.as_ref().unwrap().left_out.iter().map(|l| (l.name.clone(), l.slot_bytes)).collect()
    };
    let all = open(build("all", Some(v(None, &LayoutKind::ALL, None))));
    assert_eq!(all.layouts(), LayoutKind::ALL.to_vec());
    assert!(left_out(&all).is_empty());

    let none = open(build("none", Some(v(Some(1), &LayoutKind::ALL, None))));
    assert_eq!(none.layouts(), vec![LayoutKind::IndexedVertical]);
    let out = left_out(&none);
    assert_eq!(out.iter().map(|l| l.0.as_str()).collect::<Vec<_>>(), ["horizontal", "vertical"]);
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

    let base = build("base", None);
    let shards: Vec<_> = (0..2)
        .map(|i| build(&format!("shard{i}"), Some(v(Some(1), &LayoutKind::ALL, Some(hdov::Shard::new(i, 2).unwrap())))))
        .collect();
    let merged = tmp.path().join("merged");
    hdov::merge(&base, &shards, &merged, Overwrite::Never).unwrap();
    let merged = open(merged);
    assert_eq!(merged.layouts(), vec![LayoutKind::IndexedVertical]);
    assert_eq!(left_out(&merged), out);

    // A manifest whose written and left-out layouts do not add up to those asked for is refused.
    let path = tmp.path().join("none/manifest.json");
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    json["visibility"]["left_out"][1]["name"] = "indexed-vertical".into();
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let err = Database::open(&tmp.path().join("none")).err().unwrap().to_string();
    assert!(err.contains("left out"), "{err}");
}
