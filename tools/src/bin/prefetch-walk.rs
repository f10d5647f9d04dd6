//! Prefetch on a walkthrough (docs/query.md, "Prefetch"): the continuous street walks of the
//! caching experiment with and without prefetching, DoV-Time cache of 64 pages. The thesis's
//! query figures (pages and time against η, cache hit rate against cache size) are drawn by
//! the experiments harness (`--bin experiments`, docs/results.md).
//!
//! `cargo run --release -p hdov-tools --bin prefetch-walk -- DB`

use std::path::PathBuf;

use clap::Parser;
use hdov::{Database, SessionParams};
use hdov_storage::PolicyKind;
use hdov_tools::experiments::caching::street_walks;

#[derive(Parser)]
#[command(
    name = "prefetch-walk",
    about = "Prefetch on a walkthrough: the continuous street walks with and without prefetching, DoV-Time cache of \
             64 pages",
    long_about = "Prefetch on a walkthrough: the continuous street walks of the caching experiment, walked with and\n\
                  without prefetching (the cell three steps ahead queried after each step), DoV-Time cache of 64\n\
                  pages. Prints a Markdown table: pages read on arrival, pages prefetched, cache hit rate, and the\n\
                  99th percentile of a step's time. (The thesis's query figures are drawn by the experiments harness.)\n\
                  \n\
                  Makes: docs/query.md, \"Prefetch\" (`prefetch-walk /work/experiments/default-r64-m16.hdov`)."
)]
struct Args {
    /// The database (a directory `hdov build` or the experiments harness wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { db: db_path } = Args::parse();
    let db = Database::open(&db_path)?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let continuous = street_walks(&grid);
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
    Ok(())
}
