//! From-region error as users see it (issue 22): builds a scene's database with each sampler,
//! then, at random viewpoints inside its cells, measures how much of the whole scene's view the
//! cell's answer lacks.
//!
//! ```sh
//! cargo run --release -p hdov-tools --bin view-error -- SCENE [--samplers corners,probe] [--viewpoints 8]
//!     [--seed 1] [--resolution 128] [--truth 256] [--cells N] [--frames] [--out OUT.csv] [--chart OUT.svg]
//! ```
//!
//! SCENE: `street` (issue 22's street: 1 m gaps, yards, poles, a slatted fence; 18 cells of
//! 5 × 0.5 × 2 m), `audit` (the street block of tests/dov_audit.rs), `fence` (the picket fence of
//! `sampler-audit`) or `city` (the default city; `--cells N` takes N of its cells, seeded).
//!
//! - **Builds**: one per sampler (`--samples` syntax), with the CPU backend at `--resolution` and
//!   the command's default floors; the visibility stage's seconds come from the manifest.
//! - **Viewpoints**: `--viewpoints` per cell, uniformly random strictly inside it (seeded; never a
//!   corner or a Halton point), redrawn where the truth finds them inside geometry or nearer to a
//!   surface than its near plane (which cuts a hole in the surface and shows what lies behind).
//! - **Truth**: a full id cube map of the whole scene at `--truth` texels per edge, by the other
//!   tracer: the GPU backend (wgpu) where an adapter exists, else the CPU backend, flagged as the
//!   same tracer.
//! - **Wrong share**: the solid angle of texels whose object the cell's naive answer lacks, over
//!   the solid angle of all texels that show an object. With `--frames`, also GVS++'s per-frame
//!   error: a 1024 × 1024 frame at 45°, looking in a random direction, drawn by hdov's renderer
//!   (pixels of absent objects over pixels that show one).
//! - **Stored DoV error**: the share of (viewpoint, object) pairs whose point DoV exceeds the
//!   cell's stored DoV by more than 2 texels (of the build's R) plus 1 %. Reported only.
//!
//! Prints a table per sampler (mean, p99, max, viewpoints with any wrong texel, the objects
//! behind the worst ones); writes a CSV row per (sampler, viewpoint) and a chart of mean error
//! against visibility time.

use std::collections::HashMap;
use std::path::PathBuf;

use clap::Parser;
use glam::Vec3;
use hdov::dov::sampling::is_inside;
use hdov::dov::{DovBackend, IdCube};
use hdov::render::{ColorMode, NO_ITEM, Renderer, View};
use hdov::{
    BackendKind, BuildParams, Database, FloorTest, Mode, ObjectParts, Overwrite, Progress, QueryParams, Sampling,
};
use hdov::{ItemKind, VisibilityParams};
use hdov_testkit::scenes::Rng;
use hdov_testkit::view_error::{dov_excess, frame_error, nearer_than, random_viewpoint, wrong_share};
use hdov_tools::experiments::charts::{Panel, Series, write_svg};
use hdov_tools::experiments::quantile;

/// What the truth sees from one viewpoint.
struct Viewpoint {
    cell: usize,
    at: Vec3,
    /// Solid angle per object seen, and in all.
    solid: HashMap<u32, f64>,
    seen: f64,
    /// Point DoV per object (for the stored-DoV check).
    point: hdov::PointDov,
    /// Pixels per object of the random frame (with `--frames`).
    frame: Option<HashMap<u32, usize>>,
}

/// One sampler's results.
struct Row {
    sampler: String,
    seconds: f64,
    shares: Vec<f64>,
    frames: Vec<f64>,
    excess: (usize, usize),
    worst: Vec<Worst>,
}

/// A viewpoint's wrong share, its index, and the lacking objects behind it (name, share).
type Worst = (f64, usize, Vec<(String, f64)>);

#[derive(Parser)]
#[command(
    name = "view-error",
    about = "From-region error as users see it: the share of the view that a cell's answer lacks, at random \
             viewpoints inside its cells, per sampler",
    long_about = "From-region error as users see it (issue 22): builds the scene's database with each sampler (CPU\n\
                  backend at --resolution, the command's default floors), then, at --viewpoints random viewpoints\n\
                  strictly inside each cell (seeded; redrawn where the truth finds them inside geometry or nearer a surface than its near plane), measures\n\
                  the wrong share: the solid angle of texels whose object the cell's naive answer lacks, over that of\n\
                  all texels that show an object. The truth is a full id cube map of the whole scene at --truth by the\n\
                  other tracer (the GPU backend where an adapter exists, else the CPU backend, flagged as the same\n\
                  tracer). With --frames, also the per-frame error of a 1024 × 1024 frame at 45° in a random\n\
                  direction. Also reports the share of (viewpoint, object) pairs whose point DoV exceeds the cell's\n\
                  stored DoV by more than 2 texels + 1 %. Prints a table per sampler (visibility seconds, mean, p99,\n\
                  max, viewpoints wrong) and the worst viewpoints; --out writes a CSV row per (sampler, viewpoint),\n\
                  --chart a chart of mean error against visibility time.\n\
                  \n\
                  Makes: docs/dov.md, \"Wrong pixels at random viewpoints\" (the full tables: docs/journal/dov-sampling.md, §4), and\n\
                  docs/results.md, \"Wrong pixels at random viewpoints\": docs/data/view_error_SCENE.csv and the\n\
                  charts docs/results/view_error_SCENE.svg (`view-error street --samplers corners,16,adaptive,probe,...\n\
                  --viewpoints 8 --frames --out docs/data/view_error_street.csv --chart\n\
                  docs/results/view_error_street.svg`; and audit, fence, city)."
)]
struct Args {
    /// The scene: `street` (issue 22's street: 1 m gaps, yards, poles, a slatted fence; 18 cells), `audit` (the
    /// street block of tests/dov_audit.rs), `fence` (the picket fence of `sampler-audit`) or `city` (the default
    /// city; --cells N takes N of its cells).
    #[arg(value_name = "SCENE", default_value = "street")]
    scene: String,
    /// Samplers to build with, comma-separated, in `hdov build --samples` syntax (e.g. corners, 16, adaptive,
    /// probe, probe:32:4:24576, region).
    #[arg(long, value_name = "S,S,..", value_delimiter = ',', default_value = "corners,probe")]
    samplers: Vec<String>,
    /// Random viewpoints per cell.
    #[arg(long, value_name = "N", default_value_t = 8)]
    viewpoints: usize,
    /// Seed of the viewpoints, the cell subset and the frames' directions.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// `hdov build --region-views` (with `--backend gpu`: region rays drawn as views of N² texels a face).
    #[arg(long, value_name = "N", default_value_t = 0)]
    region_views: u32,
    /// Backend of the builds, `hdov build --backend` (the GPU backend draws region views).
    #[arg(long, value_name = "B", default_value = "cpu")]
    backend: BackendKind,
    /// Cube-map resolution R of the builds.
    #[arg(long, value_name = "R", default_value_t = 128)]
    resolution: u32,
    /// Cube-map resolution of the truth.
    #[arg(long, value_name = "R", default_value_t = 256)]
    truth: u32,
    /// Only N of the scene's cells, drawn with the seed (default: all).
    #[arg(long, value_name = "N")]
    cells: Option<usize>,
    /// Also GVS++'s per-frame error: one 1024 × 1024 frame at 45° per viewpoint, drawn by hdov's renderer.
    #[arg(long)]
    frames: bool,
    /// Write a CSV row per (sampler, viewpoint) to this file.
    #[arg(long, value_name = "OUT.csv")]
    out: Option<PathBuf>,
    /// Write the chart of mean wrong share against visibility time (SVG) to this file.
    #[arg(long, value_name = "OUT.svg")]
    chart: Option<PathBuf>,
    /// Objects of the builds: file (the scene's, as they are) or geometry (each far larger than
    /// a cell cut into parts of two cells, `hdov build --objects`).
    #[arg(long, default_value = "file")]
    objects: ObjectParts,
    /// `hdov build --zero-dov-floor` of every build, comma-separated (`none`: no floor; default:
    /// each sampler's own, as `hdov build` takes it).
    #[arg(long, value_name = "F,F,..", value_delimiter = ',')]
    zero_dov_floor: Vec<String>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let scene_name = args.scene;
    let samplers: Vec<String> = args.samplers;
    let per_cell: usize = args.viewpoints;
    let seed: u64 = args.seed;
    let r: u32 = args.resolution;
    let truth_r: u32 = args.truth;
    let frames = args.frames;
    let (mut scene, grid) = hdov_testkit::scenes::audit_scene(&scene_name, r)?;
    scene.grid = Some(grid.clone());
    // The objects the databases hold (large ones cut into parts, `--objects geometry`), whose ids
    // their answers name: the truth is measured on them.
    let built = BuildParams { objects: args.objects, ..Default::default() };
    let measured = hdov::objects_of(&scene, &built).into_owned();
    println!("{}", hdov_tools::machine());

    // Cells: all, or a seeded subset.
    let mut rng = Rng(seed);
    let mut cells: Vec<usize> = (0..grid.cell_count()).collect();
    if let Some(n) = args.cells {
        for i in (1..cells.len()).rev() {
            cells.swap(i, ((rng.next_f32() * (i + 1) as f32) as usize).min(i));
        }
        cells.truncate(n);
        cells.sort_unstable();
    }

    // The truth, by the tracer the builds do not use.
    let (mut truth, same): (Box<dyn DovBackend>, bool) =
        match hdov::open_backend(&measured, truth_r, BackendKind::Gpu, &Default::default()) {
            Ok(b) => (b, false),
            Err(e) => {
                println!("truth: no GPU backend ({e}); the CPU backend, the builds' own tracer");
                (hdov::open_backend(&measured, truth_r, BackendKind::Cpu, &Default::default())?, true)
            }
        };
    println!("truth: {} at R = {truth_r}{}", truth.name(), if same { " (same tracer as the builds)" } else { "" });
    let cube = truth.cube_map().clone();
    let mut ids = IdCube::new(truth_r);
    let mut views = Vec::new();
    // The truth clips at forward depth `near` (it was opened with the scene's default): a texel's
    // direction is up to √3 times its forward depth.
    let bounds = measured.all_object_bounds();
    let clipped_within = 3f32.sqrt() * hdov::dov::default_near(&measured.bounds());
    for &cell in &cells {
        let cell_box = grid.cell_box(grid.cell_coords(cell));
        let mut kept = 0;
        for _ in 0..per_cell * 20 {
            if kept == per_cell {
                break;
            }
            let at = random_viewpoint(&cell_box, &mut rng);
            if nearer_than(&measured, &bounds, at, clipped_within) {
                continue;
            }
            truth.render_ids(at, &mut ids)?;
            let point = ids.dov(&cube);
            if is_inside(&point) {
                continue;
            }
            let all = wrong_share(&ids, &cube, |_| false);
            views.push(Viewpoint {
                cell,
                at,
                solid: all.missing.into_iter().collect(),
                seen: all.seen,
                point,
                frame: None,
            });
            kept += 1;
        }
    }
    println!(
        "{scene_name}: {} objects, {} of {} cells, {} viewpoints",
        measured.objects.len(),
        cells.len(),
        grid.cell_count(),
        views.len()
    );

    let tmp = tempfile::tempdir()?;
    let mut rows: Vec<Row> = Vec::new();
    for (k, name) in samplers.iter().enumerate() {
        let sampling: Sampling = name.parse()?;
        let floors = FloorTest::chosen(&args.zero_dov_floor, &sampling, args.objects, Some(&grid))?;
        let visibility = VisibilityParams {
            resolution: r,
            backend: args.backend,
            region_views: args.region_views,
            sampling,
            zero_dov_floor: floors,
            ..Default::default()
        };
        let dir = tmp.path().join(format!("db{k}"));
        let report = hdov::build(
            &scene,
            &dir,
            &BuildParams { visibility: Some(visibility), ..built.clone() },
            Overwrite::Never,
            &Progress::hidden(),
        )?;
        let seconds = report.manifest.visibility.as_ref().map_or(f64::NAN, |v| v.seconds);
        let db = Database::open(&dir)?;
        if frames && k == 0 {
            draw_frames(&db, &mut views, seed)?;
        }
        let texel = hdov::dov::CubeMap::new(r).texel_floor();
        let naive = QueryParams { mode: Mode::Naive, ..Default::default() };
        let mut row =
            Row { sampler: name.clone(), seconds, shares: vec![], frames: vec![], excess: (0, 0), worst: vec![] };
        for (i, v) in views.iter().enumerate() {
            let answer = db.query(v.at, &naive)?;
            let stored: HashMap<u32, f64> = answer
                .items
                .iter()
                .filter(|it| it.kind == ItemKind::Object)
                .map(|it| (it.id, f64::from(it.dov)))
                .collect();
            let wrong: Vec<(u32, f64)> =
                v.solid.iter().filter(|(o, _)| !stored.contains_key(o)).map(|(&o, &w)| (o, w)).collect();
            let share = wrong.iter().fold(0.0, |a, w| a + w.1) / v.seen.max(f64::MIN_POSITIVE);
            row.shares.push(share);
            if let Some(pixels) = &v.frame {
                row.frames.push(frame_error(pixels.iter().map(|(&o, &n)| (o, n)), |o| stored.contains_key(&o)));
            }
            let (e, n) = dov_excess(&v.point, |o| stored.get(&o).copied().unwrap_or(0.0), texel, 2.0, 0.01);
            row.excess = (row.excess.0 + e, row.excess.1 + n);
            let name = |o: u32| {
                let object = &measured.objects[o as usize];
                hdov::scene::parts::display_name(&object.name, object.part)
            };
            let mut named: Vec<(String, f64)> = wrong.iter().map(|&(o, w)| (name(o), w / v.seen)).collect();
            named.sort_by(|a, b| b.1.total_cmp(&a.1));
            named.truncate(3);
            row.worst.push((share, i, named));
        }
        rows.push(row);
    }

    // The table.
    let base = rows.first().map_or(1.0, |r| r.seconds);
    println!(
        "\n| sampler | visibility s | / {} | mean | p99 | max | viewpoints wrong | frame mean | stored DoV exceeded |",
        rows.first().map_or("", |r| r.sampler.as_str())
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for row in &mut rows {
        let mean = row.shares.iter().fold(0.0, |a, s| a + s) / row.shares.len().max(1) as f64;
        let wrong = row.shares.iter().filter(|&&s| s > 0.0).count();
        let max = row.shares.iter().copied().fold(0.0, f64::max);
        let frame = if row.frames.is_empty() {
            "–".to_string()
        } else {
            format!("{:.1e}", row.frames.iter().fold(0.0, |a, f| a + f) / row.frames.len() as f64)
        };
        println!(
            "| {} | {:.2} | {:.2}× | {:.1e} | {:.1e} | {:.1e} | {wrong} of {} | {frame} | {:.2} % |",
            row.sampler,
            row.seconds,
            row.seconds / base,
            mean,
            quantile(&row.shares, 0.99),
            max,
            row.shares.len(),
            100.0 * row.excess.0 as f64 / row.excess.1.max(1) as f64
        );
    }
    for row in &mut rows {
        row.worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        for (share, i, named) in row.worst.iter().take(3).filter(|w| w.0 > 0.0) {
            let v = &views[*i];
            let list: Vec<String> = named.iter().map(|(n, s)| format!("{n} {s:.1e}")).collect();
            println!(
                "  {}: {share:.1e} at cell {} ({:.2}, {:.2}, {:.2}): {}",
                row.sampler,
                v.cell,
                v.at.x,
                v.at.y,
                v.at.z,
                list.join(", ")
            );
        }
    }

    if let Some(out) = args.out {
        let mut csv = String::from("scene,sampler,visibility_seconds,cell,x,y,z,wrong_share,frame_error\n");
        for row in &rows {
            for (i, v) in views.iter().enumerate() {
                let frame = row.frames.get(i).map_or(String::new(), |f| format!("{f:.6e}"));
                csv += &format!(
                    "{scene_name},{},{:.3},{},{:.3},{:.3},{:.3},{:.6e},{frame}\n",
                    row.sampler, row.seconds, v.cell, v.at.x, v.at.y, v.at.z, row.shares[i]
                );
            }
        }
        std::fs::write(&out, csv)?;
        println!("wrote {}", out.display());
    }
    if let Some(chart) = args.chart {
        let mut panel = Panel::new(
            format!("{scene_name}: {} viewpoints", views.len()),
            "visibility time / the first sampler's",
            "mean wrong share",
        )
        .log_y();
        for row in &rows {
            let mean = row.shares.iter().fold(0.0, |a, s| a + s) / row.shares.len().max(1) as f64;
            panel = panel.with(Series::new(row.sampler.clone(), vec![(row.seconds / base, mean.max(1e-9))]));
        }
        write_svg(&chart, "Wrong share of the view against visibility build time", &[panel], 1)?;
        println!("wrote {}", chart.display());
    }
    Ok(())
}

/// One 1024 × 1024 frame at 45° per viewpoint, looking in a uniformly random direction, drawn by
/// hdov's renderer from the database's full-detail geometry: pixels per object.
fn draw_frames(db: &Database, views: &mut [Viewpoint], seed: u64) -> Result<(), Box<dyn std::error::Error>> {
    let renderer = match Renderer::new() {
        Ok(r) => r,
        Err(e) => {
            println!("frames: skipped ({e})");
            return Ok(());
        }
    };
    let mut rng = Rng(seed ^ 0xf4a3e);
    for v in views.iter_mut() {
        let z = rng.range(-1.0, 1.0);
        let phi = rng.range(0.0, std::f32::consts::TAU);
        let s = (1.0 - z * z).sqrt();
        let look = Vec3::new(s * phi.cos(), z, s * phi.sin());
        let image = renderer.render_full(db, &View::new(v.at, look, 45.0, 1024, 1024), ColorMode::Shaded)?;
        let mut pixels: HashMap<u32, usize> = HashMap::new();
        for &id in image.ids.iter().filter(|&&id| id != NO_ITEM) {
            *pixels.entry(id).or_default() += 1;
        }
        v.frame = Some(pixels);
    }
    Ok(())
}
