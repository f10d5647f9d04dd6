//! The fan-out table (issue "query engine", re-checked for issue 18): for M ∈ {4, 8, 16, 32, 126},
//! the tree's nodes and height, each layout's bytes, and per η ∈ {0, 1e-4, 1e-3, 1e-2, 3e-2} the
//! faces, pages and items (draw calls) of the default query from every cell's centre
//! (indexed-vertical, no camera), beside the naive method's at the same LOD rule. Databases are
//! built once into `--cache DIR` and reused.
//!
//! `cargo run --release -p hdov-tools --bin fanout-table -- [--scale small|default|large] [--resolution R] [--lod-rule RULE] [--cache DIR] [--csv FILE]`

use std::path::PathBuf;

use clap::Parser;
use hdov::Overwrite;
use hdov::city::{CityParams, CityScale};
use hdov::dov::BackendKind;
use hdov::progress::Progress;
use hdov::{BuildParams, Database, LodRule, Mode, QueryParams, VisibilityParams};

const FANOUTS: [u32; 5] = [4, 8, 16, 32, 126];
const ETAS: [f64; 5] = [0.0, 1e-4, 1e-3, 1e-2, 3e-2];

#[derive(Parser)]
#[command(
    name = "fanout-table",
    about = "The fan-out table: per fan-out M, the tree's nodes, height and layout bytes, and the default query's \
             faces, pages and items per η beside naive's",
    long_about = "The fan-out table (re-checked for issue 18): for M in {4, 8, 16, 32, 126}, the tree's nodes and\n\
                  height, each storage layout's bytes, and per η in {0, 1e-4, 1e-3, 1e-2, 3e-2} the mean faces, pages\n\
                  and items (draw calls) of the default query from every cell's centre (indexed-vertical, no camera),\n\
                  beside the naive method's at the same LOD rule. Databases (CPU backend) are built once into --cache\n\
                  and reused. Prints a Markdown table; --csv also writes the numbers with internal LODs per η.\n\
                  \n\
                  Makes: docs/query.md, \"Fan-out\" (both tables) and docs/results/fanout_default.csv,\n\
                  docs/results/fanout_large.csv (`fanout-table --scale default --resolution 128 --cache\n\
                  /work/experiments --csv docs/results/fanout_default.csv`; `--scale large` for the large city)."
)]
struct Args {
    /// The generated city (seed 1): tiny, small, default, large or huge.
    #[arg(long, default_value = "default", value_parser = hdov_tools::args::city_scale)]
    scale: CityScale,
    /// Cube-map resolution R of the databases built.
    #[arg(long, value_name = "R", default_value_t = 64)]
    resolution: u32,
    /// The queries' LOD rule, as `hdov query --lod-rule` takes it (default: the query's default).
    #[arg(long, value_name = "RULE", value_parser = hdov_tools::args::lod_rule)]
    lod_rule: Option<LodRule>,
    /// Where the databases are built and looked for, one per M: SCALE-rR-mM.hdov.
    #[arg(long, value_name = "DIR", default_value = "target/experiments")]
    cache: PathBuf,
    /// Also write the table's numbers as CSV to this file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let (scale, resolution, cache, csv) = (args.scale, args.resolution, args.cache, args.csv);
    let lod_rule = args.lod_rule.unwrap_or_default();
    let scene = hdov::city::generate(&CityParams { seed: 1, scale, ..Default::default() })?;
    let mut rows = vec![format!(
        "M,nodes,height,horizontal_bytes,vertical_bytes,indexed_vertical_bytes,naive_faces,naive_pages,naive_items,{}",
        ETAS.iter()
            .map(|e| format!("faces_eta_{e},pages_eta_{e},items_eta_{e},internal_lods_eta_{e}"))
            .collect::<Vec<_>>()
            .join(",")
    )];
    println!(
        "| M | nodes | height | bytes h / v / iv | naive: faces, pages, items | {} |",
        ETAS.map(|e| format!("η = {e}: faces, pages, items")).join(" | ")
    );
    println!("|---|---|---|---|---|{}", "---|".repeat(ETAS.len()));
    for m in FANOUTS {
        let dir = cache.join(format!("{scale}-r{resolution}-m{m}.hdov"));
        let db = match Database::open(&dir) {
            Ok(db) if db.manifest().tree.max_entries == m as usize => db,
            _ => {
                eprintln!("building {}", dir.display());
                let params = BuildParams {
                    fanout: Some(m),
                    // Every layout, whatever its size: the table compares their bytes.
                    visibility: Some(VisibilityParams {
                        resolution,
                        backend: BackendKind::Cpu,
                        slot_budget: None,
                        ..Default::default()
                    }),
                    ..Default::default()
                };
                hdov::build(&scene, &dir, &params, Overwrite::Ours, &Progress::for_terminal(false))?;
                Database::open(&dir)?
            }
        };
        let info = db.info()?;
        let grid = db.grid().cloned().ok_or("no grid")?;
        let centres = grid.cell_centres();
        let n = centres.len() as f64;
        // Means of faces, pages, items and internal LODs over the cell centres.
        let mean = |p: &QueryParams| -> Result<[f64; 4], hdov::Error> {
            let mut sums = [0.0; 4];
            for &at in &centres {
                let a = db.query(at, p)?;
                sums[0] += a.stats.faces as f64;
                sums[1] += a.stats.pages_read as f64;
                sums[2] += a.items.len() as f64;
                sums[3] += a.items.iter().filter(|i| i.kind == hdov::ItemKind::Node).count() as f64;
            }
            Ok(sums.map(|s| s / n))
        };
        let naive = mean(&QueryParams { mode: Mode::Naive, lod_rule, ..Default::default() })?;
        let per_eta: Vec<_> = ETAS
            .iter()
            .map(|&eta| mean(&QueryParams { eta, lod_rule, ..Default::default() }))
            .collect::<Result<_, _>>()?;
        let bytes = hdov_storage::LayoutKind::ALL.map(|k| info.layouts.get(&k).map_or(0, |l| l.bytes));
        let (nodes, height) = (info.nodes, info.tree.height);
        println!(
            "| {m} | {nodes} | {height} | {} | {:.0}, {:.1}, {:.1} | {} |",
            bytes.map(|b| b.to_string()).join(" / "),
            naive[0],
            naive[1],
            naive[2],
            per_eta.iter().map(|[f, p, i, _]| format!("{f:.0}, {p:.1}, {i:.1}")).collect::<Vec<_>>().join(" | ")
        );
        rows.push(format!(
            "{m},{nodes},{height},{},{:.1},{:.2},{:.2},{}",
            bytes.map(|b| b.to_string()).join(","),
            naive[0],
            naive[1],
            naive[2],
            per_eta.iter().map(|[f, p, i, l]| format!("{f:.1},{p:.2},{i:.2},{l:.2}")).collect::<Vec<_>>().join(",")
        ));
    }
    if let Some(path) = csv {
        std::fs::write(&path, rows.join("\n") + "\n")?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
