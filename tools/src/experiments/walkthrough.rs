//! Item 5, thesis figs. 5.24–5.27 and tables 5.3, 6.1: one recorded walk (the city's avenue,
//! looking +x) by VISUAL at several η, by REVIEW at two disk-cell sizes, and by frustum culling
//! alone. Per step: query time, geometry loaded, faces drawn and (with an adapter) PSNR against
//! full detail; per method: the frame-cost proxy's mean and variance.
//!
//! The frame-cost proxy adds what a frame waits for: the step's own time (queries, cache),
//! loading its new geometry at [`DISK_MB_PER_S`] and drawing its faces at [`FACES_PER_S`]
//! (decision 56). The `walk-compare` tool walks the same methods along all three recorded walks
//! and prints tables with measured drawing times.

use glam::Vec3;
use hdov::query::{Camera, LodRule};
use hdov::render::{ColorMode, Image, Renderer, View, fidelity};
use hdov::review::ReviewParams;
use hdov::{Database, Mode, QueryParams, Session, SessionParams};
use hdov_storage::PolicyKind;

use super::charts::{Panel, Series};
use super::{Csv, Ctx, Result, err, mean, sequence_psnr, variance};

/// Disk read rate of the frame-cost proxy (a 2002 disk read ~20 MB/s; an SSD several hundred).
pub const DISK_MB_PER_S: f64 = 200.0;
/// Drawing rate of the frame-cost proxy (a hardware GPU draws hundreds of millions a second;
/// 100 M/s keeps faces visible in the sum).
pub const FACES_PER_S: f64 = 100e6;
/// REVIEW's field of view, both ways (the thesis's 45°); the images' horizontal field of view
/// is the same, so that no method culled what an image shows.
pub const FOV_H_DEG: f32 = 45.0;
const WIDTH: u32 = 320;
const HEIGHT: u32 = 200;
/// The rows whose frames make the picture pair of REVIEW's lost far objects (fig. 5.26).
pub const VISUAL_PICTURED: &str = "VISUAL η = 1e-3";
pub const REVIEW_PICTURED: &str = "REVIEW SF 1, eyesight 200 m";

/// The camera of a `width × height` image, [`FOV_H_DEG`] across, looking +x (each step gives
/// its own look).
pub fn camera(width: u32, height: u32) -> Camera {
    let aspect = width as f32 / height as f32;
    let fov_y_deg = (2.0 * ((FOV_H_DEG.to_radians() / 2.0).tan() / aspect).atan()).to_degrees();
    Camera { look: Vec3::X, fov_y_deg, aspect, image_height: height }
}

/// A walk's session: VISUAL with `params`, or REVIEW with `review` too.
pub struct WalkMethod {
    pub params: SessionParams,
    pub review: Option<ReviewParams>,
}

impl WalkMethod {
    /// A fresh session of this method over `db`.
    pub fn open<'db>(&self, db: &'db Database) -> hdov::Result<Session<'db>> {
        match self.review {
            None => db.session(&self.params),
            Some(r) => db.review_session(&self.params, r),
        }
    }
}

/// The methods every walk compares: frustum culling alone; VISUAL (the HDoV-tree) at several η
/// and LOD rules, and at full detail (visibility's own loss); REVIEW at two disk-cell sizes.
pub fn methods(camera: Camera) -> Vec<(&'static str, WalkMethod)> {
    let visual = |eta: f64, lod_rule: LodRule| WalkMethod {
        params: SessionParams {
            query: QueryParams { eta, lod_rule, camera: Some(camera), ..QueryParams::default() },
            ..SessionParams::default()
        },
        review: None,
    };
    let review = |review_box: f32, eyesight: f32| WalkMethod {
        params: SessionParams {
            query: QueryParams { camera: Some(camera), ..QueryParams::default() },
            cache: PolicyKind::Dplru,
            ..SessionParams::default()
        },
        review: Some(ReviewParams { review_box, eyesight, fov_deg: FOV_H_DEG, ..ReviewParams::default() }),
    };
    let screen = LodRule::default();
    let frustum = WalkMethod {
        params: SessionParams {
            query: QueryParams { mode: Mode::Frustum, camera: Some(camera), ..QueryParams::default() },
            ..SessionParams::default()
        },
        review: None,
    };
    vec![
        ("frustum culling", frustum),
        ("VISUAL η = 0, LOD 0 (visibility alone)", visual(0.0, LodRule::ScreenError { pixels: 0.0 })),
        ("VISUAL η = 0", visual(0.0, screen)),
        (VISUAL_PICTURED, visual(1e-3, screen)),
        ("VISUAL η = 3e-2 (default)", visual(hdov::query::DEFAULT_ETA, screen)),
        ("VISUAL η = 1e-3, 1 px", visual(1e-3, LodRule::ScreenError { pixels: 1.0 })),
        ("VISUAL η = 1e-3, eq. 5.6 levels (thesis)", visual(1e-3, LodRule::Dov)),
        (REVIEW_PICTURED, review(1.0, 200.0)),
        ("REVIEW SF 2, eyesight 1 km", review(2.0, 1000.0)),
    ]
}

pub fn run(ctx: &mut Ctx) -> Result<()> {
    let (_, db) = ctx.main_database()?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let steps = if ctx.cfg.scale == super::Scale::Small { 30 } else { 80 };
    let path = hdov::city::avenue_walk(&grid, steps);
    let camera = camera(WIDTH, HEIGHT);
    let fov_y = camera.fov_y_deg;
    let methods = methods(camera);
    let renderer = Renderer::new().ok();
    let views: Vec<View> = path.iter().map(|&(at, look)| View::new(at, look, fov_y, WIDTH, HEIGHT)).collect();
    // Full detail from every step's camera, drawn once for all methods.
    let full: Vec<Image> = match &renderer {
        Some(r) => {
            views.iter().map(|v| r.render_full(&db, v, ColorMode::Shaded)).collect::<hdov::Result<_>>().map_err(err)?
        }
        None => Vec::new(),
    };
    let mut steps_csv = Csv::new(&[
        "method",
        "step",
        "flipped",
        "micros",
        "pages_read",
        "loaded_bytes",
        "faces",
        "frame_cost_ms",
        "psnr_db",
    ]);
    let mut summary = Csv::new(&[
        "method",
        "steps",
        "step_micros_mean",
        "pages_read",
        "loaded_mb",
        "faces_mean",
        "faces_variance",
        "frame_cost_ms_mean",
        "frame_cost_ms_variance",
        "frame_cost_ms_max",
        "psnr_db_of_mean_mse",
        "frames_equal_to_full",
    ]);
    let bar = ctx.bar("walkthrough", methods.len());
    let (mut faces_series, mut cost_series) = (Vec::new(), Vec::new());
    for (name, method) in &methods {
        // Once untimed (the OS file cache warm), then timed in a fresh session.
        let mut session = method.open(&db).map_err(err)?;
        for &(at, look) in &path {
            session.step(at, Some(look)).map_err(err)?;
        }
        let mut session = method.open(&db).map_err(err)?;
        let (mut costs, mut faces, mut psnrs, mut micros) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut pages, mut loaded) = (0u64, 0u64);
        for (i, &(at, look)) in path.iter().enumerate() {
            let s = session.step(at, Some(look)).map_err(err)?;
            let cost = s.micros as f64 / 1e3
                + s.loaded_bytes as f64 / (DISK_MB_PER_S * 1e6) * 1e3
                + s.faces as f64 / FACES_PER_S * 1e3;
            let psnr = match &renderer {
                Some(r) => Some(fidelity::compare(&r.render_session(&session, &views[i]).map_err(err)?, &full[i]).psnr),
                None => None,
            };
            steps_csv.push(&[
                name,
                &i,
                &s.flipped,
                &s.micros,
                &s.pages_read,
                &s.loaded_bytes,
                &s.faces,
                &format!("{cost:.4}"),
                &psnr.map_or(String::new(), |p| format!("{p:.2}")),
            ]);
            costs.push(cost);
            faces.push(s.faces as f64);
            micros.push(s.micros as f64);
            psnrs.extend(psnr);
            pages += s.pages_read;
            loaded += s.loaded_bytes;
        }

        summary.push(&[
            name,
            &path.len(),
            &format!("{:.1}", mean(&micros)),
            &pages,
            &format!("{:.2}", loaded as f64 / 1e6),
            &format!("{:.0}", mean(&faces)),
            &format!("{:.4e}", variance(&faces)),
            &format!("{:.4}", mean(&costs)),
            &format!("{:.4e}", variance(&costs)),
            &format!("{:.3}", costs.iter().copied().fold(0.0, f64::max)),
            &if psnrs.is_empty() { String::new() } else { format!("{:.2}", sequence_psnr(&psnrs)) },
            &psnrs.iter().filter(|p| p.is_infinite()).count(),
        ]);
        let per_step = |v: &[f64], scale: f64| v.iter().enumerate().map(|(i, x)| (i as f64, x * scale)).collect();
        faces_series.push(Series::new(*name, per_step(&faces, 1e-3)));
        cost_series.push(Series::new(*name, per_step(&costs, 1.0)));
        bar.inc(1);
    }
    bar.finish_and_clear();
    ctx.write_csv("walkthrough_steps", &steps_csv)?;
    ctx.write_csv("walkthrough", &summary)?;
    let mut faces = Panel::new("Faces drawn per step", "step", "thousand faces");
    faces.series = faces_series;
    let mut cost = Panel::new("Frame-cost proxy per step (query + load + faces)", "step", "ms").log_y();
    cost.series = cost_series;
    ctx.write_chart(
        "walkthrough",
        &format!("Walkthrough along the avenue, {} steps (thesis figs. 5.24–5.27)", path.len()),
        &[faces, cost],
        1,
    )
}
