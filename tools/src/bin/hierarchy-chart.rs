//! The chart the HDoV-tree exists for: PSNR against faces drawn and against pages read, along the
//! default city's three recorded walks, for the default query across η, naive, vmsse across τ,
//! polygon budgets, the thesis's levels (`--lod-rule dov`) across η, and REVIEW (issue 18,
//! item 4).
//!
//! `cargo run --release -p hdov-tools --bin hierarchy-chart -- DB OUT.svg [STEPS]`
//!
//! Each method walks each walk in a fresh session (VISUAL: a 256-page LRU cache; REVIEW: DPLRU,
//! SF 2, 1 km eyesight); per walk it reports the mean faces drawn per step, the pages read over the
//! walk, and the PSNR of the walk's mean squared error against full detail from every step's
//! camera (640 × 360, 60°). Prints a CSV on stdout and writes the chart. Needs a wgpu adapter
//! (Mesa's CPU drivers do).

use std::path::PathBuf;

use clap::Parser;
use hdov::city::WalkKind;
use hdov::render::{ColorMode, Renderer, View, fidelity};
use hdov::review::ReviewParams;
use hdov::{Database, LodRule, Mode, PolicyKind, QueryParams, SessionParams};
use hdov_tools::experiments::charts::{Panel, Series, write_svg};
use hdov_tools::experiments::{mean, sequence_psnr};

/// One point of a curve: a walk's mean faces per step, pages read, PSNR.
type Point = (f64, f64, f64);

#[derive(Parser)]
#[command(
    name = "hierarchy-chart",
    about = "PSNR against faces drawn and against pages read along the database's three recorded walks, per query \
             method and parameter",
    long_about = "The chart the HDoV-tree exists for (issue 18): PSNR against faces drawn and against pages read along\n\
                  the database's three recorded walks, for the default query across η, naive, vmsse across τ,\n\
                  polygon budgets, the thesis's levels (`--lod-rule dov`) across η, and REVIEW. Each method walks each\n\
                  walk in a fresh session (VISUAL: a 256-page LRU cache; REVIEW: DPLRU, SF 2, 1 km eyesight); per walk\n\
                  it reports the mean faces drawn per step, the pages read over the walk, and the PSNR of the walk's\n\
                  mean squared error against full detail from every step's camera (640 × 360, 60°). Prints a CSV on\n\
                  stdout and writes the chart. Needs a wgpu adapter (Mesa's CPU drivers will do).\n\
                  \n\
                  Makes: docs/results.md, item 10 \"The hierarchy's speed against fidelity along the walks\":\n\
                  docs/results/hierarchy_walks.svg and (stdout) docs/results/hierarchy_walks.csv\n\
                  (`hierarchy-chart DB docs/results/hierarchy_walks.svg 60` on the demo's database)."
)]
struct Args {
    /// The database (a directory `hdov build` or `hdov demo` wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// The chart written (SVG).
    #[arg(value_name = "OUT.svg")]
    out: PathBuf,
    /// Steps per walk.
    #[arg(default_value_t = 60, value_parser = clap::value_parser!(u64).range(1..))]
    steps: u64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { db: db_path, out, steps } = Args::parse();
    let steps = steps as usize;
    let db = Database::open(&db_path)?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let renderer = Renderer::new()?;
    let (w, h, fov) = (640, 360, 60.0);
    let camera = View::new(glam::Vec3::ZERO, glam::Vec3::X, fov, w, h).camera();
    let visual = |query: QueryParams| SessionParams {
        query: QueryParams { camera: Some(camera), ..query },
        cache: PolicyKind::Lru,
        cache_pages: Some(256),
        ..Default::default()
    };
    // (curve, its parameter, session, REVIEW's parameters)
    let mut methods: Vec<(&str, f64, SessionParams, Option<ReviewParams>)> = Vec::new();
    for eta in hdov_tools::HIERARCHY_ETAS {
        methods.push(("default (η)", eta, visual(QueryParams { eta, ..Default::default() }), None));
        let dov = QueryParams { eta, lod_rule: LodRule::Dov, ..Default::default() };
        methods.push(("--lod-rule dov (η)", eta, visual(dov), None));
    }
    methods.push(("naive", 0.0, visual(QueryParams { mode: Mode::Naive, ..Default::default() }), None));
    for tau in [0.25, 1.0, 4.0, 16.0] {
        methods.push(("vmsse (τ)", tau, visual(QueryParams { mode: Mode::Vmsse, tau, ..Default::default() }), None));
    }
    for budget in [5_000u64, 20_000, 80_000, 320_000] {
        let p = QueryParams { mode: Mode::Budget, budget, ..Default::default() };
        methods.push(("budget (faces)", budget as f64, visual(p), None));
    }
    let review = SessionParams {
        query: QueryParams { camera: Some(camera), ..Default::default() },
        cache: PolicyKind::Dplru,
        ..Default::default()
    };
    methods.push(("REVIEW", 0.0, review, Some(ReviewParams::default())));

    println!("walk,method,parameter,faces_mean,pages,psnr_db");
    let mut curves: Vec<(WalkKind, &str, Vec<Point>)> = Vec::new();
    for kind in WalkKind::ALL {
        let path = hdov::city::walk(&grid, kind, steps);
        let views: Vec<View> = path.iter().map(|&(at, look)| View::new(at, look, fov, w, h)).collect();
        let full: Vec<_> =
            views.iter().map(|v| renderer.render_full(&db, v, ColorMode::Shaded)).collect::<hdov::Result<_>>()?;
        for (name, param, params, review) in &methods {
            let mut session = match review {
                None => db.session(params)?,
                Some(r) => db.review_session(params, *r)?,
            };
            let (mut faces, mut pages, mut psnrs) = (Vec::new(), 0u64, Vec::new());
            for (i, &(at, look)) in path.iter().enumerate() {
                let step = session.step(at, Some(look))?;
                faces.push(step.faces as f64);
                pages += step.pages_read;
                psnrs.push(fidelity::compare(&renderer.render_session(&session, &views[i])?, &full[i]).psnr);
            }
            let point = (mean(&faces), pages as f64, sequence_psnr(&psnrs));
            println!("{},{name},{param},{:.0},{},{:.2}", kind.name(), point.0, point.1, point.2);
            match curves.iter_mut().find(|c| c.0 == kind && c.1 == *name) {
                Some(c) => c.2.push(point),
                None => curves.push((kind, name, vec![point])),
            }
        }
    }
    let capped = |p: f64| p.min(60.0);
    let mut panels = Vec::new();
    for kind in WalkKind::ALL {
        let of = |x: fn(&Point) -> f64| {
            curves
                .iter()
                .filter(|c| c.0 == kind)
                .map(|c| Series::new(c.1, c.2.iter().map(|p| (x(p), capped(p.2))).collect()))
                .collect::<Vec<_>>()
        };
        let mut faces = Panel::new(format!("{} walk", kind.name()), "faces drawn per step (mean)", "PSNR dB").log_x();
        for s in of(|p| p.0.max(1.0)) {
            faces = faces.with(s);
        }
        let mut pages = Panel::new(format!("{} walk", kind.name()), "pages read over the walk", "PSNR dB").log_x();
        for s in of(|p| p.1.max(1.0)) {
            pages = pages.with(s);
        }
        panels.push(faces);
        panels.push(pages);
    }
    write_svg(&out, "Speed against fidelity along the default city's walks (PSNR capped at 60 dB)", &panels, 2)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
