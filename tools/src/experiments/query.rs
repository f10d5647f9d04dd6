//! Item 3, thesis figs. 5.21–5.22: query time and I/O against η per layout and for the naive
//! method, light-weight (tree, V-index, V-page pages) and heavy-weight (LOD geometry bytes the
//! answer needs) apart, under the default LOD rule (issue 18: the figures with the default query;
//! item 7 has the thesis's eq. 5.6 levels beside it). Item 7: faces, pages and query time against
//! image fidelity (PSNR of the answer drawn against full detail) across η, for the η rule, the
//! visibility-modulated error rule and polygon budgets, on one chart.

use glam::Vec3;
use hdov::query::{Camera, LodRule};
use hdov::render::{ColorMode, Renderer, View, fidelity};
use hdov::{Answer, Database, Mode, QueryParams};
use hdov_storage::LayoutKind;

use super::charts::{Panel, Series};
use super::{Csv, Ctx, Result, err, mean, sequence_psnr};

/// η of the sweeps: 0 (the naive answer) to 8e-3, as the thesis's figs. 5.21–5.22, and on to
/// the default η (3e-2), where the default rule stops changing.
pub const ETAS: [f64; 11] = [0.0, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 2e-3, 4e-3, 8e-3, 1e-2, 3e-2];

/// Bytes of LOD geometry an answer draws: the heavy-weight I/O a viewer without a cache pays.
pub fn geometry_bytes(a: &Answer) -> u64 {
    a.items.iter().map(|i| u64::from(i.lod_ref.blob().len)).sum()
}

/// Means over `points` of a query's costs: faces, tree, V-index, V-page and all pages, µs,
/// geometry bytes.
pub fn mean_costs(db: &Database, points: &[Vec3], params: &QueryParams) -> Result<[f64; 7]> {
    let mut sum = [0f64; 7];
    for &at in points {
        let a = db.query(at, params).map_err(err)?;
        let s = a.stats;
        let v = [s.faces, s.tree_pages, s.vindex_pages, s.vpage_pages, s.pages_read, s.micros, geometry_bytes(&a)];
        for (acc, x) in sum.iter_mut().zip(v) {
            *acc += x as f64;
        }
    }
    Ok(sum.map(|v| v / points.len().max(1) as f64))
}

pub fn run(ctx: &mut Ctx) -> Result<()> {
    let (_, db) = ctx.main_database()?;
    let centres = db.grid().ok_or("the database holds no grid")?.cell_centres();
    // One untimed pass: the OS file cache warm, as for every later query.
    mean_costs(&db, &centres, &QueryParams::default())?;
    let mut csv = Csv::new(&[
        "method",
        "layout",
        "eta",
        "faces",
        "tree_pages",
        "vindex_pages",
        "vpage_pages",
        "pages",
        "micros_mean",
        "geometry_bytes",
    ]);
    let layouts = db.layouts();
    let bar = ctx.bar("query vs η", layouts.len() * (ETAS.len() + 1));
    let (mut pages, mut micros, mut heavy, mut faces) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for &layout in &layouts {
        let naive =
            mean_costs(&db, &centres, &QueryParams { mode: Mode::Naive, layout: Some(layout), ..Default::default() })?;
        bar.inc(1);
        let mut rows = Vec::new();
        for eta in ETAS {
            let m = mean_costs(&db, &centres, &QueryParams { eta, layout: Some(layout), ..Default::default() })?;
            rows.push((eta, m));
            bar.inc(1);
        }
        for (method, eta, m) in std::iter::once(("naive", "-".to_string(), naive))
            .chain(rows.iter().map(|(e, m)| ("hdov", e.to_string(), *m)))
        {
            csv.push(&[
                &method,
                &layout,
                &eta,
                &format!("{:.1}", m[0]),
                &format!("{:.3}", m[1]),
                &format!("{:.3}", m[2]),
                &format!("{:.3}", m[3]),
                &format!("{:.3}", m[4]),
                &format!("{:.2}", m[5]),
                &format!("{:.0}", m[6]),
            ]);
        }
        let line = |i: usize, scale: f64| rows.iter().map(|(e, m)| (*e, m[i] * scale)).collect::<Vec<_>>();
        let flat = |i: usize, scale: f64| ETAS.iter().map(|&e| (e, naive[i] * scale)).collect::<Vec<_>>();
        pages.push(Series::new(format!("{layout}"), line(4, 1.0)));
        micros.push(Series::new(format!("{layout}"), line(5, 1.0)));
        if layout == LayoutKind::IndexedVertical || layouts.len() == 1 {
            pages.push(Series::new("naive (indexed-vertical)", flat(4, 1.0)));
            micros.push(Series::new("naive (indexed-vertical)", flat(5, 1.0)));
            heavy.push(Series::new("HDoV-tree", line(6, 1e-6)));
            heavy.push(Series::new("naive", flat(6, 1e-6)));
            faces.push(Series::new("HDoV-tree", line(0, 1e-3)));
            faces.push(Series::new("naive", flat(0, 1e-3)));
        }
    }
    bar.finish_and_clear();
    ctx.write_csv("query_eta", &csv)?;
    let panel = |title: &str, y: &str, s: Vec<Series>| {
        let mut p = Panel::new(title, "η", y);
        p.series = s;
        p
    };
    ctx.write_chart(
        "query_eta",
        "Point queries from every cell centre against η (thesis figs. 5.21, 5.22)",
        &[
            panel("Light-weight I/O: pages read", "pages / query", pages),
            panel("Query time (warm)", "µs / query", micros),
            panel("Heavy-weight I/O: LOD geometry", "MB / query", heavy),
            panel("Faces returned", "thousand faces", faces),
        ],
        2,
    )
}

/// Image size of the fidelity views.
const WIDTH: u32 = 320;
const HEIGHT: u32 = 200;
const FOV_Y_DEG: f32 = 45.0;

/// Item 7: one point per (rule, parameter): mean faces, pages and µs of the query with the
/// view's camera against the PSNR of its answer drawn beside full detail.
pub fn run_accuracy(ctx: &mut Ctx) -> Result<()> {
    let renderer = match Renderer::new() {
        Ok(r) => r,
        Err(e) if std::env::var(hdov_testkit::gpu::REQUIRE_ADAPTER_ENV).is_ok_and(|v| v == "1") => return Err(err(e)),
        Err(e) => {
            eprintln!("skipped: no adapter ({e})");
            ctx.note("- `accuracy`: skipped, no wgpu adapter");
            return Ok(());
        }
    };
    let (_, db) = ctx.main_database()?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let n_views = if ctx.cfg.scale == super::Scale::Small { 4 } else { 12 };
    let views: Vec<View> = hdov::city::avenue_walk(&grid, n_views)
        .into_iter()
        .map(|(at, look)| View::new(at, look, FOV_Y_DEG, WIDTH, HEIGHT))
        .collect();
    let full: Vec<_> = views
        .iter()
        .map(|v| renderer.render_full(&db, v, ColorMode::Shaded))
        .collect::<hdov::Result<_>>()
        .map_err(err)?;
    let camera = |v: &View| -> Camera { v.camera() };
    // Budgets from a thousandth of what frustum culling draws in view (full detail) to all of it.
    let full_faces = {
        let mut f = Vec::new();
        for v in &views {
            let p = QueryParams { mode: Mode::Frustum, camera: Some(camera(v)), ..Default::default() };
            f.push(db.query(v.eye, &p).map_err(err)?.stats.faces as f64);
        }
        mean(&f)
    };
    let mut configs: Vec<(&str, f64, QueryParams)> = Vec::new();
    for eta in ETAS {
        configs.push(("η, screen 0.5 px (default)", eta, QueryParams { eta, ..Default::default() }));
        configs.push(("η, eq. 5.6 (thesis)", eta, QueryParams { eta, lod_rule: LodRule::Dov, ..Default::default() }));
    }
    for pixels in [0.25, 1.0, 2.0, 4.0, 8.0, 16.0, 64.0] {
        let lod_rule = LodRule::ScreenError { pixels };
        configs.push(("screen px at the default η", pixels, QueryParams { lod_rule, ..Default::default() }));
    }
    for tau in [0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 64.0] {
        configs.push(("vmsse", tau, QueryParams { mode: Mode::Vmsse, tau, ..Default::default() }));
    }
    for share in [0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0] {
        let budget = (share * full_faces).max(1.0) as u64;
        configs.push(("budget", budget as f64, QueryParams { mode: Mode::Budget, budget, ..Default::default() }));
    }
    configs.push(("frustum", 0.0, QueryParams { mode: Mode::Frustum, ..Default::default() }));
    let mut csv = Csv::new(&[
        "rule",
        "parameter",
        "views",
        "faces",
        "pages",
        "micros_mean",
        "psnr_db",
        "coverage_diff",
        "silhouette_diff",
    ]);
    let bar = ctx.bar("accuracy", configs.len());
    let mut points: Vec<(&str, [f64; 4])> = Vec::new();
    for (rule, param, base) in &configs {
        let (mut faces, mut pages, mut micros, mut psnrs, mut cov, mut sil) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (v, reference) in views.iter().zip(&full) {
            let p = QueryParams { camera: Some(camera(v)), ..*base };
            let a = db.query(v.eye, &p).map_err(err)?;
            let image = renderer.render_answer(&db, &a, v, ColorMode::Shaded).map_err(err)?;
            let f = fidelity::compare(&image, reference);
            faces.push(a.stats.faces as f64);
            pages.push(a.stats.pages_read as f64);
            micros.push(a.stats.micros as f64);
            psnrs.push(f.psnr);
            cov.push(f.coverage_diff);
            sil.push(f.silhouette_diff);
        }
        let psnr = sequence_psnr(&psnrs);
        let row = [mean(&faces), mean(&pages), mean(&micros), psnr];
        csv.push(&[
            rule,
            param,
            &views.len(),
            &format!("{:.0}", row[0]),
            &format!("{:.2}", row[1]),
            &format!("{:.1}", row[2]),
            &format!("{psnr:.2}"),
            &format!("{:.5}", mean(&cov)),
            &format!("{:.5}", mean(&sil)),
        ]);
        points.push((rule, row));
        bar.inc(1);
    }
    bar.finish_and_clear();
    ctx.write_csv("accuracy", &csv)?;
    let rules = [
        "η, screen 0.5 px (default)",
        "η, eq. 5.6 (thesis)",
        "screen px at the default η",
        "vmsse",
        "budget",
        "frustum",
    ];
    let panel = |title: &str, y: &str, i: usize, scale: f64| {
        let mut p = Panel::new(title, "PSNR against full detail (dB)", y).log_y();
        for rule in rules {
            let pts: Vec<(f64, f64)> =
                points.iter().filter(|(r, _)| *r == rule).map(|(_, v)| (v[3].min(PSNR_CAP), v[i] * scale)).collect();
            p.series.push(Series::new(rule, pts));
        }
        p
    };
    ctx.write_chart(
        "accuracy",
        &format!(
            "Speed against image fidelity, {} views of {WIDTH}×{HEIGHT} (PSNR capped at {PSNR_CAP} dB)",
            views.len()
        ),
        &[
            panel("Faces drawn", "thousand faces", 0, 1e-3),
            panel("Pages read", "pages / query", 1, 1.0),
            panel("Query time", "µs / query", 2, 1.0),
        ],
        3,
    )
}

/// Where equal images are drawn on the chart (their PSNR is ∞).
const PSNR_CAP: f64 = 80.0;
