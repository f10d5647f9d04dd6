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
