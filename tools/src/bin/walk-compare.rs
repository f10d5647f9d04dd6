//! Recorded walks, several methods (thesis §5.8.5, table 5.3, fig. 5.26): the database's avenue
//! walks (`hdov::city::walk`: straight, turning, back-and-forth) walked by VISUAL (the
//! HDoV-tree) at several η and LOD rules, by REVIEW at two disk-cell sizes, and by frustum
//! culling alone (`Mode::Frustum` through the session: every object of the cell whose box meets
//! the view, at full detail). Per method: mean and variance of a step's time, pages read, faces
//! drawn, resident bytes, the time to draw the frame, and, with a graphics adapter, PSNR and
//! coverage difference of what is drawn against full detail from the step's camera. Prints a
//! Markdown table per walk, with the machine; `--pictures DIR` writes, per walk, the frame where
//! REVIEW at 200 m loses most against full detail: full | VISUAL η = 1e-3 | REVIEW, side by side.
//!
//! `cargo run --release -p hdov-tools --bin walk-compare -- DB [--size WxH] [--steps N]
//! [--walk straight|turning|back-and-forth|all] [--pictures DIR]` (default 320x200, 60 steps,
//! all walks). Each method walks once untimed (the OS file cache warm, its session cold), then
//! once timed in a fresh session; images are drawn after each timed step, outside its time.

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use glam::Vec3;
use hdov::city::WalkKind;
use hdov::query::LodRule;
use hdov::render::fidelity;
use hdov::render::{ColorMode, Image, Renderer, View};
use hdov::{Database, Step};
use hdov_tools::experiments::walkthrough::{self, FOV_H_DEG, REVIEW_PICTURED, VISUAL_PICTURED, WalkMethod};
use hdov_tools::experiments::{mean, sequence_psnr, variance};

struct Options {
    db: PathBuf,
    size: [u32; 2],
    steps: usize,
    walks: Vec<WalkKind>,
    pictures: Option<PathBuf>,
}

#[derive(Parser)]
#[command(
    name = "walk-compare",
    about = "Recorded walks, several methods: VISUAL (the HDoV-tree), REVIEW and frustum culling compared step by step \
             (time, pages, faces, memory, fidelity)",
    long_about = "Recorded walks, several methods (thesis §5.8.5, table 5.3, fig. 5.26): the database's avenue walks\n\
                  (straight, turning, back-and-forth) walked by VISUAL (the HDoV-tree) at several η and LOD rules, by\n\
                  REVIEW at two disk-cell sizes, and by frustum culling alone. Per method: mean and variance of a\n\
                  step's time, pages read, faces drawn, resident bytes, the time to draw the frame, and, with a\n\
                  graphics adapter, PSNR and coverage difference of what is drawn against full detail from the step's\n\
                  camera. Each method walks once untimed (the OS file cache warm, its session cold), then once timed\n\
                  in a fresh session; images are drawn after each timed step, outside its time. Prints a Markdown\n\
                  table per walk, with the machine.\n\
                  \n\
                  Makes: docs/review.md, \"Walkthrough comparison\" (the tables of sessions 1–3 and \"Frame cost\n\
                  beside the thesis's table 5.3\") and, with --pictures, the pictures of \"REVIEW's lost far objects\n\
                  (thesis fig. 5.26)\": docs/review-vs-visual-WALK.png (`walk-compare /work/cmp/default.hdov --steps 60\n\
                  --walk straight --pictures docs`)."
)]
struct Args {
    /// The database (a directory `hdov build` wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// Image size WxH in pixels (the cameras are 45° across).
    #[arg(long, value_name = "WxH", default_value = "320x200", value_parser = hdov_tools::args::size)]
    size: [u32; 2],
    /// Steps per walk.
    #[arg(long, value_name = "N", default_value_t = 60)]
    steps: usize,
    /// The walk: straight, turning, back-and-forth, or all three.
    #[arg(
        long,
        value_name = "KIND|all",
        default_value = "all",
        value_parser = PossibleValuesParser::new(WalkKind::ALL.map(WalkKind::name).into_iter().chain(["all"]))
    )]
    walk: String,
    /// Per walk, write the frame where REVIEW at 200 m loses most against full detail, as full | VISUAL η = 1e-3 |
    /// REVIEW side by side, into DIR/review-vs-visual-WALK.png (needs a graphics adapter).
    #[arg(long, value_name = "DIR")]
    pictures: Option<PathBuf>,
}

fn options() -> Result<Options, String> {
    let args = Args::parse();
    let walks = match args.walk.as_str() {
        "all" => WalkKind::ALL.to_vec(),
        kind => vec![hdov_tools::args::walk_kind(kind)?],
    };
    Ok(Options { db: args.db, size: args.size, steps: args.steps, walks, pictures: args.pictures })
}

struct Row {
    name: String,
    micros: Vec<f64>,
    pages: u64,
    faces: Vec<f64>,
    draw_ms: Vec<f64>,
    max_resident: u64,
    mean_resident: f64,
    /// PSNR of each step (∞ where equal) and coverage difference.
    psnr: Vec<f64>,
    coverage: Vec<f64>,
    images: Vec<Image>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let o = options()?;
    let [w, h] = o.size;
    let db = Database::open(&o.db)?;
    let grid = db.grid().cloned().ok_or("the database holds no viewing grid")?;
    let camera = walkthrough::camera(w, h);
    let fov_y = camera.fov_y_deg;
    let renderer = match Renderer::new() {
        Ok(r) => Some(r),
        Err(e) => {
            eprintln!("no fidelity columns: {e}");
            None
        }
    };
    println!("{}\n", hdov_tools::machine());
    println!(
        "{} ({} objects); images {w}×{h}, {FOV_H_DEG}° across ({fov_y:.1}° vertical){}; LOD rule of VISUAL rows: {} unless named.\n",
        o.db.display(),
        db.catalog().objects.len(),
        renderer.as_ref().map_or(String::from(", no adapter: no fidelity"), |r| format!(", on {}", r.adapter_name())),
        LodRule::default(),
    );
    for &kind in &o.walks {
        let path = hdov::city::walk(&grid, kind, o.steps);
        let views: Vec<View> = path.iter().map(|&(at, look)| View::new(at, look, fov_y, w, h)).collect();
        let full: Vec<Image> = match &renderer {
            Some(r) => views.iter().map(|v| r.render_full(&db, v, ColorMode::Shaded)).collect::<hdov::Result<_>>()?,
            None => Vec::new(),
        };
        let mut rows = Vec::new();
        for (name, method) in walkthrough::methods(camera) {
            rows.push(walk_one(&db, name, &method, &path, &views, &full, renderer.as_ref(), o.pictures.is_some())?);
        }
        println!("### The {} walk: {} steps\n", kind.name(), o.steps);
        print_table(&rows);
        if let (Some(dir), Some(_)) = (&o.pictures, &renderer) {
            let file = dir.join(format!("review-vs-visual-{}.png", kind.name()));
            if let Some(step) = picture_pair(&rows, &full, &file)? {
                println!(
                    "\nPicture: `{}`, step {step} (left to right: full detail, {VISUAL_PICTURED}, {REVIEW_PICTURED}).\n",
                    file.display()
                );
            }
        }
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn walk_one(
    db: &Database,
    name: &str,
    method: &WalkMethod,
    path: &[(Vec3, Vec3)],
    views: &[View],
    full: &[Image],
    renderer: Option<&Renderer>,
    keep_images: bool,
) -> hdov::Result<Row> {
    let mut session = method.open(db)?;
    for &(at, look) in path {
        session.step(at, Some(look))?;
    }
    let mut session = method.open(db)?;
    let mut steps: Vec<Step> = Vec::with_capacity(path.len());
    let (mut psnr, mut coverage, mut draw_ms, mut images) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, &(at, look)) in path.iter().enumerate() {
        steps.push(session.step(at, Some(look))?);
        if let Some(r) = renderer {
            let start = Instant::now();
            let image = r.render_session(&session, &views[i])?;
            draw_ms.push(start.elapsed().as_secs_f64() * 1e3);
            let f = fidelity::compare(&image, &full[i]);
            psnr.push(f.psnr);
            coverage.push(f.coverage_diff);
            let pictured = name == VISUAL_PICTURED || name == REVIEW_PICTURED;
            if keep_images && pictured {
                images.push(image);
            }
        }
    }
    Ok(Row {
        name: name.to_string(),
        micros: steps.iter().map(|s| s.micros as f64).collect(),
        pages: steps.iter().map(|s| s.pages_read).sum(),
        faces: steps.iter().map(|s| s.faces as f64).collect(),
        draw_ms,
        max_resident: steps.iter().map(|s| s.resident_bytes).max().unwrap_or(0),
        mean_resident: mean(&steps.iter().map(|s| s.resident_bytes as f64).collect::<Vec<_>>()),
        psnr,
        coverage,
        images,
    })
}

fn print_table(rows: &[Row]) {
    let frustum_faces = mean(&rows[0].faces);
    println!(
        "| method | step µs, mean | step µs², variance | pages read | faces drawn, mean | of frustum culling's | resident MB, mean / max | draw ms, mean | frame ms, mean ± sd | PSNR dB, mean (min) | frames ≥ 35 dB | coverage diff, mean |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        // Equal frames have PSNR ∞; the mean is over MSE (so ∞ frames count as zero error).
        let psnr = if r.psnr.is_empty() {
            "–".into()
        } else {
            let min = r.psnr.iter().copied().fold(f64::INFINITY, f64::min);
            format!("{} ({})", db_text(sequence_psnr(&r.psnr)), db_text(min))
        };
        let good = if r.psnr.is_empty() {
            "–".into()
        } else {
            format!("{} of {}", r.psnr.iter().filter(|&&p| p >= 35.0).count(), r.psnr.len())
        };
        let coverage = if r.coverage.is_empty() { "–".into() } else { format!("{:.4}", mean(&r.coverage)) };
        let draw = if r.draw_ms.is_empty() { "–".into() } else { format!("{:.0}", mean(&r.draw_ms)) };
        // A frame's cost: the step (query, loading, culling) and drawing what it chose.
        let frame: Vec<f64> = r.draw_ms.iter().zip(&r.micros).map(|(d, us)| d + us / 1e3).collect();
        let frame = if frame.is_empty() {
            "–".into()
        } else {
            format!("{:.0} ± {:.0}", mean(&frame), variance(&frame).sqrt())
        };
        println!(
            "| {} | {:.0} | {:.0} | {} | {:.0} | {:.1} % | {:.2} / {:.2} | {} | {} | {} | {} | {} |",
            r.name,
            mean(&r.micros),
            variance(&r.micros),
            r.pages,
            mean(&r.faces),
            100.0 * mean(&r.faces) / frustum_faces.max(1.0),
            r.mean_resident / 1e6,
            r.max_resident as f64 / 1e6,
            draw,
            frame,
            psnr,
            good,
            coverage
        );
    }
}

/// Writes full | VISUAL | REVIEW at the step where REVIEW's coverage differs most from full
/// detail; returns that step (`None` when REVIEW lost nothing).
fn picture_pair(rows: &[Row], full: &[Image], file: &std::path::Path) -> hdov::Result<Option<usize>> {
    let row = |name: &str| rows.iter().find(|r| r.name == name).expect("a pictured method");
    let (visual, review) = (row(VISUAL_PICTURED), row(REVIEW_PICTURED));
    let worst = (0..review.coverage.len()).max_by(|&a, &b| review.coverage[a].total_cmp(&review.coverage[b]));
    let Some(step) = worst.filter(|&s| review.coverage[s] > 0.0) else { return Ok(None) };
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(|e| hdov::Error::io(dir, e))?;
    }
    full[step].beside(&visual.images[step]).beside(&review.images[step]).write_png(file)?;
    Ok(Some(step))
}

fn db_text(p: f64) -> String {
    if p.is_finite() { format!("{p:.1}") } else { "∞".into() }
}
