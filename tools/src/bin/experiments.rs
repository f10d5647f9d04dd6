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

use std::process::ExitCode;

use hdov_tools::experiments::{Config, EXPERIMENTS, Scale, run};

fn parse() -> Result<Config, String> {
    let mut cfg = Config::new(Scale::Default);
    let mut caches = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--scale" => cfg.scale = value()?.parse()?,
            "--cache" => caches.push(value()?.into()),
            "--out" => cfg.out = value()?.into(),
            "--only" => cfg.only = value()?.split(',').map(str::to_string).collect(),
            "--resolution" => {
                let v = value()?;
                cfg.resolution = v
                    .parse()
                    .ok()
                    .filter(|r| (1..=4096).contains(r))
                    .ok_or(format!("--resolution: '{v}' is not a whole number in 1..=4096"))?
            }
            "--quiet" => cfg.progress = false,
            "-h" | "--help" => {
                return Err(format!(
                    "usage: experiments [--scale small|default|large] [--cache DIR]... [--out DIR] [--only {}] [--resolution R] [--quiet]",
                    EXPERIMENTS.join(",")
                ));
            }
            _ => return Err(format!("unknown argument '{a}' (--help lists them)")),
        }
    }
    if !caches.is_empty() {
        cfg.caches = caches;
    }
    Ok(cfg)
}

fn main() -> ExitCode {
    match parse().and_then(run) {
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
