//! Where a walk's geometry bytes go (issue 18's walk target): each recorded walk walked by the
//! naive query and by the default query in fresh sessions, and the bytes each loaded split into
//!
//! - *first loads*: the first record loaded of a base mesh (objects; instances share records) or
//!   of a node's chain;
//! - *refinements*: a finer record of a mesh or node that already had one loaded;
//! - the *floor*: per base mesh and node, the largest record any of the walk's answers drew, summed.
//!   A loader that knew the walk in advance and fetched each thing once, at the finest level the
//!   walk will need, would load exactly this; no loader can draw the same answers with less.
//!
//! `cargo run --release -p hdov-tools --bin walk-loads -- DB [--steps N]` (150 steps, as
//! `hdov walk`). Prints one Markdown table.

use std::collections::HashMap;
use std::path::PathBuf;

use hdov::city::WalkKind;
use hdov::{Database, ItemKind, Mode, QueryParams, SessionParams};

/// What one walk loaded.
#[derive(Default)]
struct Loads {
    /// Bytes loaded, as the session's steps report them.
    loaded: u64,
    /// `[objects, nodes]`: bytes of first loads, of refinements, and the floor.
    first: [u64; 2],
    refine: [u64; 2],
    floor: [u64; 2],
}

fn walk(db: &Database, kind: WalkKind, steps: usize, query: QueryParams) -> hdov::Result<Loads> {
    let grid = db.grid().expect("checked by main");
    let mut session = db.session(&SessionParams { query, ..Default::default() })?;
    let mut loads = Loads::default();
    // Per (is node, mesh or node id): the largest record drawn so far; per record: seen.
    let mut largest: HashMap<(usize, u32), u64> = HashMap::new();
    let mut seen = std::collections::HashSet::new();
    for (at, look) in hdov::city::walk(grid, kind, steps) {
        let step = session.step(at, Some(look))?;
        loads.loaded += step.loaded_bytes;
        if !step.flipped {
            continue;
        }
        for item in &session.answer().expect("a flip sets the answer").items {
            let (k, id) = match item.kind {
                ItemKind::Object => (0, db.catalog().objects[item.id as usize].mesh),
                ItemKind::Node => (1, item.id),
            };
            let len = u64::from(item.lod_ref.len);
            let before = largest.insert((k, id), len);
            if let Some(b) = before {
                largest.insert((k, id), b.max(len));
            }
            if seen.insert(item.lod_ref.offset) {
                let split = if before.is_none() { &mut loads.first } else { &mut loads.refine };
                split[k] += len;
            }
        }
    }
    for ((k, _), len) in largest {
        loads.floor[k] += len;
    }
    Ok(loads)
}

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
        let naive = walk(&db, kind, steps, QueryParams { mode: Mode::Naive, eta: 0.0, ..default })?;
        let threshold = walk(&db, kind, steps, default)?;
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
