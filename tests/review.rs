//! REVIEW, the spatial baseline: CSearch and the box query against brute force over every
//! object box, REVIEW walks whose loads and evictions add up, and prefetch.

use std::collections::BTreeSet;
use std::path::Path;

use glam::Vec3;
use hdov::Overwrite;
use hdov::dov::BackendKind;
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;
use hdov::progress::Progress;
use hdov::review::{self, ReviewParams, search};
use hdov::rtree::{RTree, TreeAlgorithm};
use hdov::{BuildParams, Database, ObjectParts, SessionParams, VisibilityParams};
use hdov_storage::PolicyKind;
use proptest::prelude::*;

// ---- the searches on random trees ----

fn aabb() -> impl Strategy<Value = Aabb> {
    (0.0f32..100.0, 0.0f32..100.0, 0.0f32..20.0, 0.0f32..15.0, 0.0f32..15.0, 0.0f32..15.0)
        .prop_map(|(x, y, z, w, h, d)| Aabb::new(Vec3::new(x, y, z), Vec3::new(x + w, y + h, z + d)))
}

fn cell() -> impl Strategy<Value = Aabb> {
    (0.0f32..100.0, 0.0f32..100.0, 0.0f32..20.0, 1.0f32..50.0, 1.0f32..50.0, 1.0f32..30.0)
        .prop_map(|(x, y, z, w, h, d)| Aabb::new(Vec3::new(x, y, z), Vec3::new(x + w, y + h, z + d)))
}

/// The search through an in-memory tree; returns the object ids found (sorted, checked
/// unique) and the nodes read.
fn run(tree: &RTree, cell: &Aabb, history: &[Aabb]) -> (Vec<u32>, u64) {
    let mut reads = 0;
    let found = search::csearch(cell, history, &mut |id| {
        reads += 1;
        Ok(tree.node(id).clone())
    })
    .unwrap();
    let mut ids: Vec<u32> = found.iter().map(|e| e.child).collect();
    ids.sort_unstable();
    let n = ids.len();
    ids.dedup();
    assert_eq!(ids.len(), n, "an object is returned once");
    (ids, reads)
}

fn brute(boxes: &[Aabb], cell: &Aabb, history: &[Aabb]) -> Vec<u32> {
    (0..boxes.len() as u32)
        .filter(|&o| {
            let b = &boxes[o as usize];
            b.intersects(cell) && !history.iter().any(|h| h.intersects(b))
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// CSearch returns exactly the objects that meet the new cell and no history cell; the box
    /// query (no history) exactly those that meet the cell; CSearch reads no node the box
    /// query does not; and a walk's complement results never overlap and together are every
    /// object any of its cells met.
    #[test]
    fn csearch_and_the_box_query_match_brute_force(
        boxes in prop::collection::vec(aabb(), 1..120),
        fanout in 2usize..7,
        linear in any::<bool>(),
        cells in prop::collection::vec(cell(), 1..8),
    ) {
        let algorithm = if linear { TreeAlgorithm::Linear } else { TreeAlgorithm::Str };
        let tree = RTree::build(&boxes, fanout, algorithm);
        let mut seen = BTreeSet::new();
        for (i, c) in cells.iter().enumerate() {
            let history = &cells[..i];
            let (plain, box_reads) = run(&tree, c, &[]);
            prop_assert_eq!(&plain, &brute(&boxes, c, &[]), "box query, cell {}", i);
            let (fresh, reads) = run(&tree, c, history);
            prop_assert_eq!(&fresh, &brute(&boxes, c, history), "CSearch, cell {}", i);
            prop_assert!(reads <= box_reads, "CSearch read {} nodes, the box query {}", reads, box_reads);
            for o in fresh {
                prop_assert!(seen.insert(o), "object {} returned by two cells", o);
            }
        }
        let any: BTreeSet<u32> = (0..boxes.len() as u32)
            .filter(|&o| cells.iter().any(|c| c.intersects(&boxes[o as usize])))
            .collect();
        prop_assert_eq!(seen, any);
    }
}

#[test]
fn csearch_prunes_subtrees_inside_a_history_cell() {
    // 64 unit boxes on a line, fan-out 4: the history cell holds the first half whole.
    let boxes: Vec<Aabb> = (0..64)
        .map(|i| Aabb::new(Vec3::new(2.0 * i as f32, 0.0, 0.0), Vec3::new(2.0 * i as f32 + 1.0, 1.0, 1.0)))
        .collect();
    let tree = RTree::build(&boxes, 4, TreeAlgorithm::Str);
    let all = Aabb::new(Vec3::splat(-1.0), Vec3::new(200.0, 2.0, 2.0));
    let first_half = Aabb::new(Vec3::splat(-1.0), Vec3::new(63.5, 2.0, 2.0));
    let (plain, box_reads) = run(&tree, &all, &[]);
    let (fresh, reads) = run(&tree, &all, &[first_half]);
    assert_eq!(plain.len(), 64);
    assert_eq!(fresh, (32..64).collect::<Vec<u32>>());
    assert!(reads < box_reads, "{reads} nodes read, the box query {box_reads}");
}

#[test]
fn block_distance_is_the_largest_gap() {
    let a = Aabb::new(Vec3::ZERO, Vec3::ONE);
    assert_eq!(search::block_distance(&a, &Aabb::new(Vec3::new(0.5, 0.5, 0.5), Vec3::splat(3.0))), 0.0);
    let b = Aabb::new(Vec3::new(4.0, 1.5, -3.0), Vec3::new(5.0, 2.0, -2.5));
    assert_eq!(search::block_distance(&a, &b), 3.0);
    assert_eq!(search::block_distance(&b, &a), 3.0);
}

#[test]
fn cells_follow_the_formulas() {
    let p = ReviewParams { eyesight: 10.0, fov_deg: 90.0, ..Default::default() };
    // Looking +x, 90°: the far plane is 20 × 20 at x = 10.
    let f = review::frustum_cell(Vec3::ZERO, Some(Vec3::X), &p);
    assert!((f.min - Vec3::new(0.0, -10.0, -10.0)).abs().max_element() < 1e-4, "{f:?}");
    assert!((f.max - Vec3::new(10.0, 10.0, 10.0)).abs().max_element() < 1e-4, "{f:?}");
    let d = review::disk_cell(&f, 2.0);
    assert!((d.min - Vec3::new(-5.0, -20.0, -20.0)).abs().max_element() < 1e-4);
    assert!((d.max - Vec3::new(15.0, 20.0, 20.0)).abs().max_element() < 1e-4);
    // No direction: a cube of half-side eyesight.
    assert_eq!(review::frustum_cell(Vec3::ONE, None, &p), Aabb::new(Vec3::splat(-9.0), Vec3::splat(11.0)));
    // F = (10, 0, 0), velocity (1, 0, 0), k = 0.8: centred at (10.8, 0, 0).
    let next = review::predicted_cell(Vec3::ZERO, Some(Vec3::X), Vec3::X, Vec3::splat(2.0), &p);
    assert!((next.center() - Vec3::new(10.8, 0.0, 0.0)).abs().max_element() < 1e-5);
    // DPLRU's caller side: root at no distance ⅔, a leaf one scale away 0.
    assert!((review::dplru_priority(3, 3, 0.0, 100.0) - 2.0 / 3.0).abs() < 1e-12);
    assert_eq!(review::dplru_priority(0, 3, 150.0, 100.0), 0.0);
    assert!((review::dplru_priority(0, 3, 50.0, 100.0) - 1.0 / 6.0).abs() < 1e-12);
}

// ---- walks over a built database ----

/// The block of 5 × 5 buildings of tests/query.rs, fan-out 4.
fn city(dir: &Path) -> Database {
    let mut scene = hdov_testkit::scenes::city_block(5, true);
    scene.grid = Some(ViewGrid::new(Aabb::new(Vec3::new(-5.0, 1.5, -5.0), Vec3::new(95.0, 2.0, 95.0)), [4, 1, 4]));
    // The block's own objects (its ground slab whole): the cache figures below are sized to them.
    let params = BuildParams {
        objects: ObjectParts::File,
        fanout: Some(4),
        visibility: Some(VisibilityParams { resolution: 16, backend: BackendKind::Cpu, ..Default::default() }),
        ..Default::default()
    };
    hdov::build(&scene, dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
    Database::open(dir).unwrap()
}

/// Every object's box, from the tree's leaves.
fn object_boxes(db: &Database) -> Vec<Aabb> {
    let mut boxes = vec![Aabb::EMPTY; db.catalog().objects.len()];
    for id in 0..db.node_count() {
        let n = db.node(id).unwrap().node;
        if n.is_leaf() {
            for e in n.entries {
                boxes[e.child as usize] = e.mbr;
            }
        }
    }
    boxes
}

fn small() -> ReviewParams {
    ReviewParams { eyesight: 15.0, review_box: 1.5, ..Default::default() }
}

/// Along a street and back, looking along the motion.
fn street() -> Vec<(Vec3, Vec3)> {
    let mut path: Vec<(Vec3, Vec3)> = (0..40).map(|i| (Vec3::new(-2.0 + 2.4 * i as f32, 1.7, 17.0), Vec3::X)).collect();
    let back: Vec<_> = path.iter().rev().map(|&(at, _)| (at, Vec3::NEG_X)).collect();
    path.extend(back);
    path
}

#[test]
fn a_review_walk_loads_its_disk_cells_and_its_deltas_add_up() {
    let tmp = tempfile::tempdir().unwrap();
    let db = city(&tmp.path().join("db"));
    let boxes = object_boxes(&db);
    let p = small();
    for budget in [None, Some(40_000u64), Some(4_000)] {
        for cache in [PolicyKind::None, PolicyKind::Lru, PolicyKind::Dplru, PolicyKind::DOV_TIME] {
            let params = SessionParams { cache, resident_bytes: budget, ..Default::default() };
            let mut s = db.review_session(&params, p).unwrap();
            let (mut loaded, mut evicted, mut flips) = (0i64, 0i64, 0);
            for (k, &(at, look)) in street().iter().enumerate() {
                let step = s.step(at, Some(look)).unwrap();
                assert_eq!(step.pages_read, step.misses);
                loaded += step.loaded_bytes as i64;
                evicted += step.evicted_bytes as i64;
                assert_eq!(loaded - evicted, step.resident_bytes as i64, "deltas add up at step {k}");
                assert_eq!(step.resident_bytes, s.resident_bytes());
                if step.flipped {
                    flips += 1;
                    // The buffer's part in the disk cell is every object that meets it.
                    let disk = review::disk_cell(&review::frustum_cell(at, Some(look), &p), p.review_box);
                    let got: BTreeSet<u32> = s.answer().unwrap().items.iter().map(|i| i.id).collect();
                    let want: BTreeSet<u32> =
                        (0..boxes.len() as u32).filter(|&o| boxes[o as usize].intersects(&disk)).collect();
                    assert_eq!(got, want, "step {k}: {cache} budget {budget:?}");
                } else {
                    assert_eq!((step.loaded, step.pages_read), (0, 0), "nothing is read inside a disk cell");
                }
                if let Some(b) = budget.filter(|_| !step.over_budget) {
                    assert!(step.resident_bytes <= b);
                }
                // What is drawn is resident, in the frustum, within the eyesight.
                let resident: BTreeSet<u64> = s.resident().map(|(k, _)| k).collect();
                let drawn = s.frame_items(at, Some(look));
                assert!(drawn.iter().all(|i| resident.contains(&i.lod_ref.offset)));
                assert!(drawn.iter().all(|i| hdov::camera::distance_to_box(at, &i.mbr) <= p.eyesight));
                assert_eq!(step.items as usize, drawn.len());
            }
            assert!(flips >= 6, "the walk leaves its disk cells ({flips} flips)");
            let total: u64 = s.resident().map(|(_, n)| n as u64).sum();
            assert_eq!(total as i64, loaded - evicted);
            if budget.is_none() {
                assert_eq!(evicted, 0);
            }
        }
    }
}

#[test]
fn review_prefetch_reads_the_predicted_cell_before_arrival() {
    let tmp = tempfile::tempdir().unwrap();
    let db = city(&tmp.path().join("db"));
    let path: Vec<Vec3> = (0..40).map(|i| Vec3::new(-2.0 + 2.4 * i as f32, 1.7, 17.0)).collect();
    let walk = |prefetch: bool| {
        let params = SessionParams { cache: PolicyKind::Dplru, prefetch, ..Default::default() };
        let mut s = db.review_session(&params, small()).unwrap();
        let (mut arrival, mut ahead) = (0, 0);
        for &at in &path {
            let st = s.step(at, Some(Vec3::X)).unwrap();
            arrival += st.pages_read;
            ahead += st.prefetch_pages;
        }
        (arrival, ahead)
    };
    let (cold, none) = walk(false);
    let (warm, ahead) = walk(true);
    assert_eq!(none, 0);
    assert!(ahead > 0, "prefetch read pages");
    assert!(warm < cold, "pages read on arrival: {warm} with prefetch, {cold} without");
}

#[test]
fn bad_review_parameters_are_refused_and_a_visual_walk_takes_dplru() {
    let tmp = tempfile::tempdir().unwrap();
    let db = city(&tmp.path().join("db"));
    for (p, name) in [
        (ReviewParams { review_box: 0.5, ..Default::default() }, "review_box"),
        (ReviewParams { eyesight: 0.0, ..Default::default() }, "eyesight"),
        (ReviewParams { fov_deg: 180.0, ..Default::default() }, "fov"),
    ] {
        let err = db.review_session(&SessionParams::default(), p).err().unwrap();
        assert!(err.to_string().starts_with(name), "{err}");
    }
    let mut s = db.session(&SessionParams { cache: PolicyKind::Dplru, ..Default::default() }).unwrap();
    let mut reads = [0u64; 2];
    for (k, &(at, look)) in street().iter().enumerate() {
        reads[usize::from(k >= 40)] += s.step(at, Some(look)).unwrap().pages_read;
    }
    assert!(reads[0] > 0 && reads[1] == 0, "DPLRU of 256 pages holds the walk: {reads:?}");
}
