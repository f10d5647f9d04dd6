//! One recorded walk, several methods (thesis table 5.3): the database's avenue walk
//! (`hdov::city::avenue_walk`, 60 steps looking +x) walked by VISUAL at η = 0, 1e-3 and 8e-3,
//! by REVIEW at two disk-cell sizes, and by frustum culling alone (`Mode::Frustum` through the
//! session: every object of the cell whose box meets the view, at full detail). Per method: mean
//! and variance of a step's time, pages read, faces drawn, resident bytes and, with a graphics
//! adapter, mean PSNR and coverage difference of what is drawn against full detail from the
//! step's camera. Prints a Markdown table, with the machine.
//!
//! `cargo run --release -p hdov-tools --bin walk-compare -- DB [WxH]` (image size, default
//! 320x200). Each method walks once untimed (the OS file cache warm, its session cold), then
//! once timed in a fresh session; images are drawn after each timed step, outside its time.

use glam::Vec3;
use hdov::query::{Camera, Method, Mode};
use hdov::render::fidelity;
use hdov::render::{ColorMode, Image, Renderer, View};
use hdov::review::ReviewParams;
use hdov::{Database, QueryParams, SessionParams, Step};
use hdov_storage::PolicyKind;

/// Steps of the walk.
const STEPS: usize = 60;
/// REVIEW's field of view, both ways (the thesis's 45°); the image's horizontal field of view
/// is the same, so that no method culled what the image shows.
const FOV_H_DEG: f32 = 45.0;

struct Row {
    name: String,
    micros: Vec<f64>,
    pages: u64,
    faces: Vec<f64>,
    max_resident: u64,
    mean_resident: f64,
    /// PSNR of each step (∞ where equal) and coverage difference.
    psnr: Vec<f64>,
    coverage: Vec<f64>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let db_path = args.next().ok_or("usage: walk-compare DB [WxH]")?;
    let size: Vec<u32> =
        args.next().unwrap_or_else(|| "320x200".into()).split('x').map(str::parse).collect::<Result<_, _>>()?;
    let [w, h] = size[..] else { return Err("size is WxH".into()) };
    let db = Database::open(std::path::Path::new(&db_path))?;
    let grid = *db.grid().ok_or("the database holds no viewing grid")?;
    let path = hdov::city::avenue_walk(&grid, STEPS);
    let aspect = w as f32 / h as f32;
    let fov_y = (2.0 * ((FOV_H_DEG.to_radians() / 2.0).tan() / aspect).atan()).to_degrees();
    let camera = Camera { look: Vec3::X, fov_y_deg: fov_y, aspect, image_height: h };
    let visual = |eta: f64| SessionParams {
        query: QueryParams { eta, camera: Some(camera), ..QueryParams::default() },
        ..SessionParams::default()
    };
    let review = |review_box: f32, eyesight: f32| SessionParams {
        method: Method::Review(ReviewParams { review_box, eyesight, fov_deg: FOV_H_DEG, ..ReviewParams::default() }),
        query: QueryParams { camera: Some(camera), ..QueryParams::default() },
        cache: PolicyKind::Dplru,
        ..SessionParams::default()
    };
    let methods = [
        (
            "frustum culling",
            SessionParams {
                query: QueryParams { mode: Mode::Frustum, camera: Some(camera), ..QueryParams::default() },
                ..SessionParams::default()
            },
        ),
        ("VISUAL η = 0", visual(0.0)),
        ("VISUAL η = 1e-3", visual(1e-3)),
        ("VISUAL η = 8e-3", visual(8e-3)),
        ("REVIEW SF 1, eyesight 200 m", review(1.0, 200.0)),
        ("REVIEW SF 2, eyesight 1 km", review(2.0, 1000.0)),
    ];
    let renderer = match Renderer::new() {
        Ok(r) => Some(r),
        Err(e) => {
            eprintln!("no fidelity columns: {e}");
            None
        }
    };
    let views: Vec<View> = path.iter().map(|&(at, look)| View::new(at, look, fov_y, w, h)).collect();
    let full: Vec<Image> = match &renderer {
        Some(r) => views.iter().map(|v| r.render_full(&db, v, ColorMode::Shaded)).collect::<hdov::Result<_>>()?,
        None => Vec::new(),
    };
    let mut rows = Vec::new();
    for (name, params) in &methods {
        let mut session = db.session(params)?;
        for &(at, look) in &path {
            session.step(at, Some(look))?;
        }
        let mut session = db.session(params)?;
        let mut steps: Vec<Step> = Vec::with_capacity(path.len());
        let (mut psnr, mut coverage) = (Vec::new(), Vec::new());
        for (i, &(at, look)) in path.iter().enumerate() {
            steps.push(session.step(at, Some(look))?);
            if let Some(r) = &renderer {
                let f = fidelity::compare(&session.draw(r, &views[i])?, &full[i]);
                psnr.push(f.psnr);
                coverage.push(f.coverage_diff);
            }
        }
        rows.push(Row {
            name: name.to_string(),
            micros: steps.iter().map(|s| s.micros as f64).collect(),
            pages: steps.iter().map(|s| s.pages_read).sum(),
            faces: steps.iter().map(|s| s.faces as f64).collect(),
            max_resident: steps.iter().map(|s| s.resident_bytes).max().unwrap_or(0),
            mean_resident: mean(&steps.iter().map(|s| s.resident_bytes as f64).collect::<Vec<_>>()),
            psnr,
            coverage,
        });
    }
    println!("{}\n", hdov_tools::machine());
    println!(
        "{} ({} objects), {STEPS} steps along the first avenue looking +x; images {w}×{h}, {FOV_H_DEG}° across ({fov_y:.1}° vertical){}.\n",
        db_path,
        db.catalog().objects.len(),
        renderer.as_ref().map_or(String::from(", no adapter: no fidelity"), |r| format!(", on {}", r.adapter_name()))
    );
    let frustum_faces = mean(&rows[0].faces);
    println!(
        "| method | step µs, mean | step µs², variance | pages read | faces drawn, mean | of frustum culling's | resident MB, mean / max | PSNR dB, mean of finite (frames equal to full detail) | coverage diff, mean |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in &rows {
        let finite: Vec<f64> = r.psnr.iter().copied().filter(|p| p.is_finite()).collect();
        let psnr = if r.psnr.is_empty() {
            "–".into()
        } else if finite.is_empty() {
            format!("∞ ({})", r.psnr.len())
        } else {
            format!("{:.1} ({})", mean(&finite), r.psnr.len() - finite.len())
        };
        let coverage = if r.coverage.is_empty() { "–".into() } else { format!("{:.4}", mean(&r.coverage)) };
        println!(
            "| {} | {:.0} | {:.0} | {} | {:.0} | {:.1} % | {:.2} / {:.2} | {} | {} |",
            r.name,
            mean(&r.micros),
            variance(&r.micros),
            r.pages,
            mean(&r.faces),
            100.0 * mean(&r.faces) / frustum_faces.max(1.0),
            r.mean_resident / 1e6,
            r.max_resident as f64 / 1e6,
            psnr,
            coverage
        );
    }
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Population variance.
fn variance(v: &[f64]) -> f64 {
    let m = mean(v);
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64
}
