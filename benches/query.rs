//! Query engine speed: warm point queries per mode and layout, walkthrough steps with and without
//! a cell flip, and cold point queries (OS page cache dropped before each one when running as
//! root), on the default city built at R = 64 with fan-out 16 (`hdov_testkit::bench`). The
//! large city is measured too when `HDOV_BENCH_LARGE=1`.
//!
//! `cargo bench --bench query` (about a minute per city once the database is cached; building
//! the default city's takes 1–2 minutes on two cores, the first time). Criterion gives means;
//! `cargo run --release -p hdov-tools --bin query-latency` gives p50/p99. Figures:
//! `docs/query-speed.md`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, Criterion, SamplingMode, criterion_group, criterion_main};
use glam::Vec3;
use hdov::city::CityScale;
use hdov::{Database, Mode, QueryParams, SessionParams};
use hdov_storage::{LayoutKind, PolicyKind, ReadMode};

use hdov_testkit::bench as common;

/// Benchmark group names: `query/...` for the default city, `query-large/...` for the large.
fn prefix(scale: CityScale) -> String {
    match scale {
        CityScale::Default => "query".to_string(),
        other => format!("query-{other}"),
    }
}

fn point(c: &mut Criterion, db: &Database, scale: CityScale) {
    let points = common::walk(db);
    let mut group = c.benchmark_group(format!("{}/point", prefix(scale)));
    group.sample_size(50).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    for (name, params) in common::point_configs() {
        let mut k = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                k = (k + 1) % points.len();
                black_box(db.query(points[k], &params).unwrap())
            })
        });
    }
    group.finish();
}

fn walk(c: &mut Criterion, db: &Database, scale: CityScale) {
    let params = SessionParams {
        query: QueryParams { layout: Some(LayoutKind::IndexedVertical), ..Default::default() },
        cache: PolicyKind::Lru,
        cache_pages: Some(256),
        ..Default::default()
    };
    let mut group = c.benchmark_group(format!("{}/walk", prefix(scale)));
    group.sample_size(50).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    // With a resident budget of one byte every flip evicts all the geometry the new cell does
    // not need (least recently used first) before loading what it does.
    let evicting = SessionParams { resident_bytes: Some(1), ..params };
    for (name, pair, flips, params) in [
        ("step-no-flip", common::same_cell_pair(db), false, params),
        ("step-flip", common::neighbour_pair(db), true, params),
        ("step-flip-evicting", common::neighbour_pair(db), true, evicting),
    ] {
        let mut session = db.session(&params).unwrap();
        // The first steps load the cells' geometry; afterwards only the step itself is measured.
        session.step(pair[0], Some(Vec3::X)).unwrap();
        session.step(pair[1], Some(Vec3::X)).unwrap();
        let mut k = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                k ^= 1;
                let step = session.step(pair[k], Some(Vec3::X)).unwrap();
                assert_eq!(step.flipped, flips);
                black_box(step)
            })
        });
    }
    group.finish();
}

/// Drops the OS page cache (root only); the reason when it cannot.
fn drop_page_cache() -> Result<(), String> {
    // Dirty pages are not dropped: write them first (`sync`; the database's own files are clean).
    let _ = std::process::Command::new("sync").status();
    std::fs::write("/proc/sys/vm/drop_caches", "3\n").map_err(|e| format!("/proc/sys/vm/drop_caches: {e}"))
}

fn cold(c: &mut Criterion, scale: CityScale) {
    let dir = common::fixture_dir(scale);
    let db = Database::open_with(&dir, ReadMode::Pread).unwrap();
    let points = common::walk(&db);
    let params = QueryParams { mode: Mode::Threshold, eta: 1e-3, ..Default::default() };
    let dropping = match drop_page_cache() {
        Ok(()) => {
            println!("cold queries: the OS page cache is dropped before each query");
            true
        }
        Err(e) => {
            println!("cold queries: cannot drop the OS page cache ({e}); measuring pread with a warm OS cache");
            false
        }
    };
    let mut group = c.benchmark_group(format!("{}/point-cold", prefix(scale)));
    // One query per sample, ten samples: each drop costs a sync and re-reads evicted files.
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_millis(10));
    let mut k = 0;
    group.bench_function("threshold-1e-3", |b| {
        b.iter_batched(
            || {
                if dropping {
                    drop_page_cache().unwrap();
                }
                k = (k + 7) % points.len();
                points[k]
            },
            |at| black_box(db.query(at, &params).unwrap()),
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

fn query_benches(c: &mut Criterion) {
    for scale in common::scales() {
        let db = common::open_or_build(scale).unwrap();
        point(c, &db, scale);
        walk(c, &db, scale);
        cold(c, scale);
    }
}

criterion_group!(benches, query_benches);
criterion_main!(benches);
