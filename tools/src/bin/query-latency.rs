//! Query latency percentiles: p50/p99 of warm point queries per mode and layout, and of
//! walkthrough steps without and with a cell flip (and of the flipping steps of a walk along the
//! avenue: point queries through a reader kept open), on the query benchmarks' fixture (the default
//! city at R = 64, fan-out 16, cached under `<target>/bench-data`; built on first use; the large
//! city too with `HDOV_BENCH_LARGE=1`). Criterion (`cargo bench --bench query`) gives the means;
//! this gives the tails. Prints a Markdown table, with the machine.
//!
//! `cargo run --release -p hdov-tools --bin query-latency -- [--db DB] [N] [FILTER]` (`--db`:
//! that database instead of the fixtures, over its grid's avenue walk; N timed queries or
//! steps per row, default 2,000, after one untimed pass over the viewpoints; only the rows whose
//! name contains FILTER, e.g. `walk/` or `threshold-1e-3`, for profiling one of them).

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use glam::Vec3;
use hdov::{Database, QueryParams, SessionParams};
use hdov_storage::{LayoutKind, PolicyKind};

use hdov_testkit::bench as common;
use hdov_tools::experiments::quantile;

#[derive(Parser)]
#[command(
    name = "query-latency",
    about = "Query latency percentiles: p50/p99 of warm point queries per mode and layout, and of walkthrough steps",
    long_about = "Query latency percentiles: p50/p99 (and mean, max) of warm point queries per mode and layout, and of\n\
                  walkthrough steps without and with a cell flip (and of the flipping steps of a walk along the avenue:\n\
                  point queries through a reader kept open), with pages, nodes and items per query and the slowest\n\
                  viewpoint. Runs on the query benchmarks' fixture (the default city at R = 64, fan-out 16, cached\n\
                  under <target>/bench-data, built on first use; the large city too with HDOV_BENCH_LARGE=1), or on\n\
                  --db's database over its grid's avenue walk. Criterion (`cargo bench --bench query`) gives the\n\
                  means; this gives the tails. Prints a Markdown table, with the machine.\n\
                  \n\
                  Makes: docs/query-speed.md, \"Results\" (the p50/p99 columns of the default and large city's\n\
                  tables; `HDOV_BENCH_LARGE=1 query-latency 2000`), and the latency figures of docs/query.md, \"The η\n\
                  rule\", and docs/sharding.md (`query-latency --db DB 2000`)."
)]
struct Args {
    /// Measure this database instead of the fixtures, over its grid's avenue walk.
    #[arg(long, value_name = "DB")]
    db: Option<PathBuf>,
    /// Timed queries or steps per row, after one untimed pass over the viewpoints.
    #[arg(default_value_t = 2_000)]
    n: usize,
    /// Only the rows whose name contains FILTER, e.g. `walk/` or `point/threshold-1e-3` (for profiling one;
    /// default: every row).
    filter: Option<String>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { db: given, n, filter } = Args::parse();
    let (n, filter) = (n.max(1), filter.unwrap_or_default());
    println!("{}\n", hdov_tools::machine());
    println!(
        "| city | benchmark | p50 µs | p99 µs | mean µs | max µs | pages/query | nodes/query | items | slowest viewpoint: median µs (pages) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let dbs: Vec<(String, Database)> = match given {
        Some(path) => vec![(path.display().to_string(), Database::open(&path)?)],
        None => common::scales()
            .into_iter()
            .map(|s| Ok((s.to_string(), common::open_or_build(s)?)))
            .collect::<Result<_, Box<dyn std::error::Error>>>()?,
    };
    for (scale, db) in &dbs {
        let (scale, db) = (scale.as_str(), db);
        for (name, params) in common::point_configs() {
            let name = format!("point/{name}");
            // A database built with fewer layouts (the huge city's: indexed-vertical) skips the rest.
            if !name.contains(&filter) || params.layout.is_some_and(|l| !db.layouts().contains(&l)) {
                continue;
            }
            let row = point_latency(db, &params, n)?;
            print_row(scale, &name, &row);
        }
        for (name, flips) in [("walk/step-no-flip", false), ("walk/step-flip", true)] {
            if !name.contains(&filter) {
                continue;
            }
            let row = step_latency(db, flips, n)?;
            print_row(scale, name, &row);
        }
        if "walk/avenue-flips".contains(filter.as_str()) {
            print_row(scale, "walk/avenue-flips", &avenue_latency(db, n)?);
        }
    }
    Ok(())
}

/// One row: latencies in µs, the mean pages, nodes and items per query or step, and the
/// slowest viewpoint (point queries: the one with the highest median, and its pages).
struct Row {
    micros: Vec<f64>,
    pages: f64,
    nodes: f64,
    items: f64,
    slowest: Option<(f64, u64)>,
}

fn point_latency(db: &Database, params: &QueryParams, n: usize) -> hdov::Result<Row> {
    let points = common::walk(db);
    for &at in &points {
        db.query(at, params)?;
    }
    let (mut micros, mut pages, mut nodes, mut items) = (Vec::with_capacity(n), 0u64, 0u64, 0u64);
    // Per viewpoint: its latencies and its pages (the same every time).
    let mut by_point: Vec<(Vec<f64>, u64)> = vec![(Vec::new(), 0); points.len()];
    for i in 0..n {
        let at = points[i % points.len()];
        let t = Instant::now();
        let answer = db.query(at, params)?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        micros.push(us);
        by_point[i % points.len()].0.push(us);
        by_point[i % points.len()].1 = answer.stats.pages_read;
        pages += answer.stats.pages_read;
        nodes += answer.stats.nodes_visited;
        items += answer.items.len() as u64;
    }
    let slowest = by_point
        .iter_mut()
        .filter(|(v, _)| !v.is_empty())
        .map(|(v, pages)| {
            v.sort_by(f64::total_cmp);
            (quantile(v, 0.5), *pages)
        })
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let per = |x: u64| x as f64 / n as f64;
    Ok(Row { micros, pages: per(pages), nodes: per(nodes), items: per(items), slowest })
}

/// Steps alternating between two points of one cell (`flips` false) or of two neighbouring
/// cells (`flips` true), indexed-vertical layout, LRU cache of 256 pages, looking +x.
fn step_latency(db: &Database, flips: bool, n: usize) -> hdov::Result<Row> {
    let params = SessionParams {
        query: QueryParams { layout: Some(LayoutKind::IndexedVertical), ..Default::default() },
        cache: PolicyKind::Lru,
        cache_pages: Some(256),
        ..Default::default()
    };
    let pair = if flips { common::neighbour_pair(db) } else { common::same_cell_pair(db) };
    let mut session = db.session(&params)?;
    // Untimed: the first steps load the cells' geometry.
    for &at in pair.iter().chain(&pair) {
        session.step(at, Some(Vec3::X))?;
    }
    let (mut micros, mut pages, mut items) = (Vec::with_capacity(n), 0u64, 0u64);
    for i in 0..n {
        let t = Instant::now();
        let step = session.step(pair[i % 2], Some(Vec3::X))?;
        micros.push(t.elapsed().as_secs_f64() * 1e6);
        assert_eq!(step.flipped, flips, "step {i} at {:?}", step.at);
        pages += step.pages_read;
        items += step.items;
    }
    let per = |x: u64| x as f64 / n as f64;
    // A session's step reports no node count; its query's pages are tree + index + V-pages.
    Ok(Row { micros, pages: per(pages), nodes: f64::NAN, items: per(items), slowest: None })
}

/// Steps along the 64-point avenue walk, cycled (indexed-vertical, η = 1e-3, LRU 256 pages),
/// timing only the steps that flip: the point-query traversal of every cell on the walk, through
/// a reader that stays open, for comparison with `point/threshold-1e-3`.
fn avenue_latency(db: &Database, n: usize) -> hdov::Result<Row> {
    let params = SessionParams {
        query: QueryParams { layout: Some(LayoutKind::IndexedVertical), ..Default::default() },
        cache: PolicyKind::Lru,
        cache_pages: Some(256),
        ..Default::default()
    };
    let points = common::walk(db);
    let mut session = db.session(&params)?;
    for &at in &points {
        session.step(at, Some(Vec3::X))?;
    }
    let (mut micros, mut pages, mut items) = (Vec::with_capacity(n), 0u64, 0u64);
    let mut i = 0;
    while micros.len() < n {
        let t = Instant::now();
        let step = session.step(points[i % points.len()], Some(Vec3::X))?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        i += 1;
        if step.flipped {
            micros.push(us);
            pages += step.pages_read;
            items += step.items;
        }
    }
    let per = |x: u64| x as f64 / n as f64;
    Ok(Row { micros, pages: per(pages), nodes: f64::NAN, items: per(items), slowest: None })
}

fn print_row(scale: &str, name: &str, row: &Row) {
    let mut v = row.micros.clone();
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let nodes = if row.nodes.is_nan() { "–".to_string() } else { format!("{:.1}", row.nodes) };
    let slowest = row.slowest.map_or("–".to_string(), |(us, pages)| format!("{us:.1} ({pages})"));
    println!(
        "| {scale} | {name} | {:.1} | {:.1} | {mean:.1} | {:.1} | {:.1} | {nodes} | {:.1} | {slowest} |",
        quantile(&v, 0.5),
        quantile(&v, 0.99),
        v[v.len() - 1],
        row.pages,
        row.items
    );
}
