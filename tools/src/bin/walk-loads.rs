//! Where a walk's geometry bytes go (issue 18's walk target): each recorded walk walked by the
//! naive query and by the default query in fresh sessions, the bytes each loaded split into first
//! loads, refinements and the floor ([`hdov_tools::walk_loads`]).
//!
//! `cargo run --release -p hdov-tools --bin walk-loads -- DB [--steps N]` (150 steps, as
//! `hdov walk`). Prints one Markdown table.

use std::path::PathBuf;

use hdov::city::WalkKind;
use hdov::{Database, Mode, QueryParams, SessionParams};
use hdov_tools::walk_loads::walk;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let usage = "usage: walk-loads DB [--steps N]";
    let mut args = std::env::args().skip(1);
    let db_path = PathBuf::from(args.next().ok_or(usage)?);
    let mut steps = 150;
    while let Some(flag) = args.next() {
        match (flag.as_str(), args.next()) {
            ("--steps", Some(v)) => steps = v.parse()?,
            _ => return Err(format!("unknown or incomplete flag {flag}; {usage}").into()),
        }
    }
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
