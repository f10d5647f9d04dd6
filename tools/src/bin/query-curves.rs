//! The thesis's query figures on our data, as CSV and Markdown tables:
//!
//! - figs. 5.21–5.22: pages read (light-weight, per file) and query time against η, per layout,
//!   beside the naive method, from every cell's centre;
//! - figs. 5.15–5.20: page-cache hit rate against cache size per policy (none, LRU, DoV,
//!   DoV-Time) on a continuous sequence (walks along the streets) and a random one (cell centres
//!   in a shuffled order), for η ∈ {1e-5, 1e-4, 5e-4}.
//!
//! `cargo run --release -p hdov-tools --bin query-curves -- DB [--out DIR]`
//! (e.g. a database built by `fanout-table`; writes DIR/query_eta.csv and DIR/cache_hits.csv).

use std::path::PathBuf;

use glam::Vec3;
use hdov::{Database, Mode, QueryParams, SessionParams};
use hdov_storage::{LayoutKind, PolicyKind};

const ETAS: [f64; 9] = [0.0, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 2e-3, 4e-3, 8e-3];
const CACHE_PAGES: [usize; 8] = [2, 4, 8, 16, 32, 64, 128, 256];
const CACHE_ETAS: [f64; 3] = [1e-5, 1e-4, 5e-4];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let db_path: PathBuf = args.next().ok_or("usage: query-curves DB [--out DIR]")?.into();
    let mut out = PathBuf::from("docs/results");
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next().ok_or("--out needs a directory")?.into(),
            _ => return Err(format!("unknown argument {a}").into()),
        }
    }
    std::fs::create_dir_all(&out)?;
    let db = Database::open(&db_path)?;
    let grid = *db.grid().ok_or("the database holds no grid")?;
    let centres = grid.cell_centres();
    println!(
        "{} ({} nodes, {} cells, fan-out {})\n",
        db_path.display(),
        db.node_count(),
        centres.len(),
        db.manifest().tree.max_entries
    );

    // Pages and time against η.
    let mut csv = vec!["method,layout,eta,faces,tree_pages,vindex_pages,vpage_pages,pages,micros_mean".to_string()];
    println!(
        "| method | layout | η | faces | tree | V-index | V-pages | pages | µs |\n|---|---|---|---|---|---|---|---|---|"
    );
    for layout in LayoutKind::ALL {
        let mut runs: Vec<(String, QueryParams)> =
            vec![("naive".into(), QueryParams { mode: Mode::Naive, layout: Some(layout), ..Default::default() })];
        runs.extend(ETAS.map(|eta| ("hdov".into(), QueryParams { eta, layout: Some(layout), ..Default::default() })));
        for (method, p) in runs {
            let mut sum = [0f64; 6];
            for &at in &centres {
                let a = db.query(at, &p)?;
                let s = a.stats;
                for (acc, v) in
                    sum.iter_mut().zip([s.faces, s.tree_pages, s.vindex_pages, s.vpage_pages, s.pages_read, s.micros])
                {
                    *acc += v as f64;
                }
            }
            let m = sum.map(|v| v / centres.len() as f64);
            let eta = if p.mode == Mode::Naive { "-".to_string() } else { p.eta.to_string() };
            println!(
                "| {method} | {layout} | {eta} | {:.0} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1} |",
                m[0], m[1], m[2], m[3], m[4], m[5]
            );
            csv.push(format!(
                "{method},{layout},{eta},{:.1},{:.3},{:.3},{:.3},{:.3},{:.2}",
                m[0], m[1], m[2], m[3], m[4], m[5]
            ));
        }
    }
    std::fs::write(out.join("query_eta.csv"), csv.join("\n") + "\n")?;

    // Cache hit rate against cache size.
    let continuous = street_walks(&grid);
    let mut random = centres.clone();
    shuffle(&mut random, 7);
    let mut csv = vec!["sequence,eta,policy,cache_pages,cache_requests,cache_hits,hit_rate,pages_read".to_string()];
    println!("\n| sequence | η | policy | {} |", CACHE_PAGES.map(|p| format!("{p} pages")).join(" | "));
    println!("|---|---|---|{}", "---|".repeat(CACHE_PAGES.len()));
    for (name, seq) in [("continuous", &continuous), ("random", &random)] {
        for eta in CACHE_ETAS {
            for policy in [PolicyKind::None, PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME] {
                let mut row = Vec::new();
                for pages in CACHE_PAGES {
                    let params = SessionParams {
                        query: QueryParams { eta, ..Default::default() },
                        cache: policy,
                        cache_pages: Some(pages),
                        ..Default::default()
                    };
                    let mut s = db.session(&params)?;
                    // The cache's own hit rate: requests that got past the reader's one-page read
                    // buffer (which serves consecutive V-pages on one disk page under any policy).
                    let (mut hits, mut requests, mut read) = (0u64, 0u64, 0u64);
                    for &at in seq.iter() {
                        let step = s.step(at, None)?;
                        hits += step.cache_hits;
                        requests += step.cache_requests;
                        read += step.pages_read;
                    }
                    let rate = hits as f64 / requests.max(1) as f64;
                    row.push(format!("{:.3}", rate));
                    csv.push(format!("{name},{eta},{policy},{pages},{requests},{hits},{rate:.4},{read}"));
                }
                println!("| {name} | {eta} | {policy} | {} |", row.join(" | "));
            }
        }
    }
    std::fs::write(out.join("cache_hits.csv"), csv.join("\n") + "\n")?;

    // Prefetch: the continuous walks with and without it, DoV-Time cache of 64 pages.
    println!(
        "\n| prefetch | pages read on arrival | pages prefetched | cache hit rate | step µs p99 |\n|---|---|---|---|---|"
    );
    for prefetch in [false, true] {
        let params =
            SessionParams { cache: PolicyKind::DOV_TIME, cache_pages: Some(64), prefetch, ..Default::default() };
        let mut s = db.session(&params)?;
        let (mut read, mut ahead, mut hits, mut requests, mut micros) = (0, 0, 0, 0, Vec::new());
        for &at in &continuous {
            let step = s.step(at, None)?;
            (read, ahead) = (read + step.pages_read, ahead + step.prefetch_pages);
            (hits, requests) = (hits + step.cache_hits, requests + step.cache_requests);
            micros.push(step.micros);
        }
        micros.sort_unstable();
        let p99 = micros[(micros.len() * 99).div_ceil(100).saturating_sub(1)];
        println!("| {prefetch} | {read} | {ahead} | {:.3} | {p99} |", hits as f64 / requests.max(1) as f64);
    }
    eprintln!("wrote {}/query_eta.csv and cache_hits.csv", out.display());
    Ok(())
}

/// Walks along the first avenue and back, then across the grid diagonally: viewpoints a few
/// metres apart, so cells are entered and left as a walker does.
fn street_walks(grid: &hdov::grid::ViewGrid) -> Vec<Vec3> {
    let mut path: Vec<Vec3> = hdov::city::avenue_walk(grid, 200).into_iter().map(|(p, _)| p).collect();
    path.extend(path.clone().into_iter().rev());
    let r = grid.region;
    let y = (r.min.y + r.max.y) / 2.0;
    path.extend((0..200).map(|i| {
        let t = i as f32 / 199.0;
        Vec3::new(r.min.x + (r.max.x - r.min.x) * t, y, r.min.z + (r.max.z - r.min.z) * t).min(r.max).max(r.min)
    }));
    path
}

/// A deterministic Fisher–Yates shuffle (SplitMix64).
fn shuffle<T>(v: &mut [T], seed: u64) {
    let mut s = seed;
    for i in (1..v.len()).rev() {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        v.swap(i, ((z ^ (z >> 31)) % (i as u64 + 1)) as usize);
    }
}
