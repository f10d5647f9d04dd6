//! Where a walk's geometry bytes go (issue 18's walk target): each recorded walk walked by the
//! naive query and by the default query in fresh sessions, the bytes each loaded split into first
//! loads, refinements and the floor ([`hdov_tools::walk_loads`]).
//!
//! `cargo run --release -p hdov-tools --bin walk-loads -- DB [--steps N]` (150 steps, as
//! `hdov walk`). Prints one Markdown table.

use std::path::PathBuf;

use clap::Parser;
use hdov::city::WalkKind;
use hdov::{Database, Mode, QueryParams, SessionParams};
use hdov_tools::walk_loads::walk;

#[derive(Parser)]
#[command(
    name = "walk-loads",
    about = "Where a walk's geometry bytes go: each recorded walk by the naive and the default query, the bytes loaded \
             split into first loads, refinements and the floor",
    long_about = "Where a walk's geometry bytes go (issue 18's walk target): each recorded walk (straight, turning,\n\
                  back-and-forth) walked by the naive query and by the default query in fresh sessions, the bytes\n\
                  each loaded split into first loads and refinements of objects and of internal nodes, and the floor\n\
                  (what no loader could avoid), each against naive's loads. Prints one Markdown table.\n\
                  \n\
                  Makes: docs/query.md, \"The η rule\", the table of geometry loaded along the recorded walks\n\
                  (`walk-loads DB` on the demo's database)."
)]
struct Args {
    /// The database (a directory `hdov build` or `hdov demo` wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// Steps per walk (150, as `hdov walk`).
    #[arg(long, value_name = "N", default_value_t = 150)]
    steps: usize,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { db: db_path, steps } = Args::parse();
    let db = Database::open(&db_path)?;
    db.grid().ok_or("the database holds no grid to walk")?;
    let default = QueryParams::default();
    println!(
        "{steps} steps per walk, {}; default η = {:e}, LOD rule {}",
        db_path.display(),
        default.eta,
        default.lod_rule
    );
    println!();
    println!(
        "| walk | query | loaded | / naive | objects: first, refinements | nodes: first, refinements | floor: objects + nodes | floor / naive's loads |"
    );
    println!("|---|---|---:|---:|---|---|---|---:|");
    let mb = |b: u64| format!("{:.2} MB", b as f64 / 1e6);
    for kind in WalkKind::ALL {
        let path = hdov::city::walk(db.grid().expect("checked above"), kind, steps);
        let session = |query| SessionParams { query, ..Default::default() };
        let naive = walk(&db, &path, &session(QueryParams { mode: Mode::Naive, eta: 0.0, ..default }))?;
        let threshold = walk(&db, &path, &session(default))?;
        for (name, l) in [("naive", &naive), ("default", &threshold)] {
            let floor = l.floor[0] + l.floor[1];
            println!(
                "| {} | {name} | {} | {:.0} % | {}, {} | {}, {} | {} + {} | {:.0} % |",
                kind.name(),
                mb(l.loaded),
                100.0 * l.loaded as f64 / naive.loaded.max(1) as f64,
                mb(l.first[0]),
                mb(l.refine[0]),
                mb(l.first[1]),
                mb(l.refine[1]),
                mb(l.floor[0]),
                mb(l.floor[1]),
                100.0 * floor as f64 / naive.loaded.max(1) as f64,
            );
        }
    }
    Ok(())
}
