//! What the hierarchy buys at street level: the default query (and others) against the naive
//! answer at the same LOD rule and cameras, over 24 views of a database's grid (12 viewpoints
//! along the first avenue, each looking along the walk and to its left), with PSNR of the mean
//! squared error over the views against full detail (issue 18's protocol).
//!
//! `cargo run --release -p hdov-tools --bin hierarchy-table -- DB [WIDTHxHEIGHT]`
//!
//! Prints one Markdown table: pages, faces and items (draw calls) as shares of naive's, the
//! internal LODs returned, and PSNR. Needs a wgpu adapter for the PSNR column (Mesa's CPU
//! drivers do).

use std::path::PathBuf;

use clap::Parser;
use glam::Vec3;
use hdov::render::{ColorMode, Renderer, View, fidelity};
use hdov::{Database, ItemKind, LodRule, Mode, QueryParams};
use hdov_tools::HIERARCHY_ETAS as ETAS;
use hdov_tools::experiments::sequence_psnr;

#[derive(Parser)]
#[command(
    name = "hierarchy-table",
    about = "What the hierarchy buys at street level: pages, faces, items and PSNR of the default query (and others) \
             against naive's, over 24 street views",
    long_about = "What the hierarchy buys at street level (issue 18's protocol): the default query at each η (and the\n\
                  thesis's levels, vmsse, a screen-error rule) against the naive answer at the same LOD rule and\n\
                  cameras, over 24 views of the database's grid (12 viewpoints along the first avenue, each looking\n\
                  along the walk and to its left). Prints one Markdown table: pages, faces and items (draw calls) as\n\
                  shares of naive's, the internal LODs returned, and the PSNR of the mean squared error over the views\n\
                  against full detail; then, over every cell, how often a query reads more pages than naive and whether\n\
                  faces or pages ever grow from one η to the next. The PSNR column needs a wgpu adapter (Mesa's CPU\n\
                  drivers will do); without one it is left empty.\n\
                  \n\
                  Makes: docs/query.md, \"The η rule\" (the table the default η was chosen from, and the large\n\
                  city's), and the 24-street-view table of docs/query.md, \"Fan-out\" (`hierarchy-table DB` on the\n\
                  demo's database; `hierarchy-table /work/experiments/default-r128-mM.hdov` per fan-out)."
)]
struct Args {
    /// The database (a directory `hdov build` or `hdov demo` wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// Size of each view in pixels.
    #[arg(value_name = "WIDTHxHEIGHT", default_value = "640x360", value_parser = hdov_tools::args::size)]
    size: [u32; 2],
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { db: db_path, size: [w, h] } = Args::parse();
    let db = Database::open(&db_path)?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let views: Vec<View> = hdov::city::avenue_walk(&grid, 12)
        .into_iter()
        .flat_map(|(at, look)| {
            let left = Vec3::Y.cross(look).normalize_or(look);
            [View::new(at, look, 60.0, w, h), View::new(at, left, 60.0, w, h)]
        })
        .collect();
    let renderer = Renderer::new().ok();
    let full: Vec<_> = match &renderer {
        Some(r) => views.iter().map(|v| r.render_full(&db, v, ColorMode::Shaded)).collect::<hdov::Result<_>>()?,
        None => Vec::new(),
    };
    let configs: Vec<(String, QueryParams)> = {
        let mut c = Vec::new();
        for eta in ETAS {
            c.push((format!("default, η = {eta:e}"), QueryParams { eta, ..Default::default() }));
        }
        for eta in [1e-3, 8e-3] {
            let p = QueryParams { eta, lod_rule: LodRule::Dov, ..Default::default() };
            c.push((format!("`--lod-rule dov`, η = {eta:e}"), p));
        }
        c.push(("`--mode vmsse --tau 1`".into(), QueryParams { mode: Mode::Vmsse, tau: 1.0, ..Default::default() }));
        c.push((
            "`--lod-rule screen:2`, η = 8e-3".into(),
            QueryParams { eta: 8e-3, lod_rule: LodRule::ScreenError { pixels: 2.0 }, ..Default::default() },
        ));
        c
    };
    println!("{} views of {w}×{h}, 60° vertical field of view; {}", views.len(), db_path.display());
    println!();
    println!("| query | pages / naive | faces / naive | items / naive | internal LODs | PSNR |");
    println!("|---|---|---|---|---|---|");
    for (name, base) in &configs {
        let (mut sums, mut naive_sums, mut nodes, mut psnrs) = ([0u64; 3], [0u64; 3], 0usize, Vec::new());
        for (i, v) in views.iter().enumerate() {
            let p = QueryParams { camera: Some(v.camera()), ..*base };
            let a = db.query(v.eye, &p)?;
            let naive = db.query(v.eye, &QueryParams { mode: Mode::Naive, eta: 0.0, ..p })?;
            for (s, q) in [(&mut sums, &a), (&mut naive_sums, &naive)] {
                s[0] += q.stats.pages_read;
                s[1] += q.stats.faces;
                s[2] += q.items.len() as u64;
            }
            nodes += a.items.iter().filter(|i| i.kind == ItemKind::Node).count();
            if let Some(r) = &renderer {
                let image = r.render_answer(&db, &a, v, ColorMode::Shaded)?;
                psnrs.push(fidelity::psnr(&image, &full[i]));
            }
        }
        let share = |k: usize| 100.0 * sums[k] as f64 / naive_sums[k].max(1) as f64;
        let psnr = if psnrs.is_empty() { "—".to_string() } else { format!("{:.1} dB", sequence_psnr(&psnrs)) };
        println!("| {name} | {:.1} % | {:.1} % | {:.1} % | {nodes} | {psnr} |", share(0), share(1), share(2));
    }
    // Every cell, every η ≥ 1e-4: no query reads more pages than naive's; and whether faces or
    // pages ever grow from one η to the next in a cell.
    let centres = grid.cell_centres();
    let naive_pages: Vec<u64> = centres
        .iter()
        .map(|&at| db.query(at, &QueryParams { mode: Mode::Naive, ..Default::default() }).map(|a| a.stats.pages_read))
        .collect::<hdov::Result<_>>()?;
    let per_eta: Vec<Vec<(u64, u64)>> = ETAS
        .iter()
        .map(|&eta| {
            centres
                .iter()
                .map(|&at| {
                    db.query(at, &QueryParams { eta, ..Default::default() })
                        .map(|a| (a.stats.pages_read, a.stats.faces))
                })
                .collect::<hdov::Result<Vec<_>>>()
        })
        .collect::<hdov::Result<_>>()?;
    for (eta, answers) in ETAS.iter().zip(&per_eta).skip(1) {
        let over = answers.iter().zip(&naive_pages).filter(|((pages, _), naive)| pages > naive).count();
        let sum: u64 = answers.iter().map(|a| a.0).sum();
        let share = 100.0 * sum as f64 / naive_pages.iter().sum::<u64>().max(1) as f64;
        println!(
            "η = {eta:e}: {over} of {} cells read more pages than naive; all cells {share:.0} % of naive's pages",
            centres.len()
        );
    }
    let (mut pages_grew, mut faces_grew, mut worst) = (0, 0, 1.0f64);
    for pair in per_eta.windows(2) {
        for (&(p0, f0), &(p1, f1)) in pair[0].iter().zip(&pair[1]) {
            pages_grew += usize::from(p1 > p0);
            if f1 > f0 {
                faces_grew += 1;
                worst = worst.max(f1 as f64 / f0 as f64);
            }
        }
    }
    println!(
        "from one η of {ETAS:?} to the next, in {} (cell, η step) pairs: pages grew in {pages_grew}, faces in {faces_grew} (by at most {:.1} %)",
        centres.len() * (ETAS.len() - 1),
        100.0 * (worst - 1.0)
    );
    Ok(())
}
