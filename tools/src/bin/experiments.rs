//! The experiments harness: builds what it needs (cached), runs every experiment of issue 10
//! with a progress bar, and writes CSV data, SVG charts and `summary.md` (see
//! `hdov_tools::experiments` and docs/results.md).
//!
//! `cargo run --release -p hdov-tools --bin experiments -- [--scale small|default|large]
//! [--cache DIR]... [--out DIR] [--only NAME,..] [--resolution R]`
//!
//! `--cache` may be given more than once: every folder is searched for a database built with
//! the same parameters from the same scene; new builds go into the first (default
//! `target/experiments`). `--out` defaults to `docs/results`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use hdov_tools::experiments::{Config, EXPERIMENTS, Scale, run};

#[derive(Parser)]
#[command(
    name = "experiments",
    about = "The experiments harness: runs the thesis's measurements (storage, caching, query, scalability, \
             walkthrough, precompute, accuracy, stability) and writes their CSVs and charts",
    long_about = "The experiments harness (issue 10): builds the databases it needs (cached, reused only when built with\n\
                  the same parameters from the same scene), runs every experiment with a progress bar, and writes\n\
                  NAME.csv and NAME.svg per experiment and summary.md (machine, command, wall time per experiment)\n\
                  into --out. Prints the summary.\n\
                  \n\
                  Makes: docs/results.md, \"The experiments harness\", items 1–8 and docs/results/: storage against\n\
                  fan-out (table 5.2; storage), page-cache hit rate against cache size (figs. 5.15–5.20; caching), query\n\
                  time and I/O against η (figs. 5.21, 5.22; query), scalability (fig. 5.23), VISUAL against REVIEW\n\
                  and frustum culling (figs. 5.24–5.27, tables 5.3, 6.1; walkthrough), the DoV precompute's speed\n\
                  against accuracy (precompute), queries' speed against accuracy (accuracy), and where the DoV\n\
                  measurement fails (stability); also docs/query.md's \"Pages and time against η\" and \"Cache hit\n\
                  rate against cache size\". The docs' run: `experiments --scale default --cache /work/experiments`."
)]
struct Args {
    /// The city most experiments run on, and how long the sweeps are: small, default or large.
    #[arg(long, default_value = "default", value_parser = |s: &str| s.parse::<Scale>())]
    scale: Scale,
    /// A folder searched for cached databases built with the same parameters from the same scene; may be given
    /// more than once. New builds go into the first (default: target/experiments).
    #[arg(long, value_name = "DIR")]
    cache: Vec<PathBuf>,
    /// Where the CSVs, charts and summary.md go (default: docs/results).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Only these experiments, comma-separated (default: all).
    #[arg(long, value_name = "NAME,..", value_delimiter = ',', value_parser = PossibleValuesParser::new(EXPERIMENTS))]
    only: Vec<String>,
    /// Cube-map resolution R of every database built (default: 64).
    #[arg(long, value_name = "R", value_parser = clap::value_parser!(u32).range(1..=i64::from(hdov::format::limits::MAX_RESOLUTION)))]
    resolution: Option<u32>,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
}

fn parse() -> Config {
    let args = Args::parse();
    let mut cfg = Config::new(args.scale);
    if !args.cache.is_empty() {
        cfg.caches = args.cache;
    }
    if let Some(out) = args.out {
        cfg.out = out;
    }
    cfg.only = args.only;
    if let Some(r) = args.resolution {
        cfg.resolution = r;
    }
    cfg.progress = !args.quiet;
    cfg
}

fn main() -> ExitCode {
    match run(parse()) {
        Ok(summary) => {
            print!("{summary}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
