//! `hdov render`: draw the full-detail scene or a query's answer from a camera into a PNG, and
//! report the answer's fidelity against full detail.

use std::path::{Path, PathBuf};

use clap::Args;
use glam::Vec3;
use serde::Serialize;

use hdov::Database;
use hdov::Result;
use hdov::render::fidelity::{self, Fidelity};
use hdov::render::{ColorMode, Renderer, View};
use hdov::text::{parse_dims, parse_point};

#[derive(Args)]
pub struct RenderCmd {
    db: PathBuf,
    /// The viewpoint X,Y,Z.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    at: Vec3,
    /// View direction DX,DY,DZ (y up).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    look: Vec3,
    #[command(flatten)]
    answer: super::query::AnswerArgs,
    /// Colours: shaded (grey), dov (a ramp over log DoV) or lod (a palette by level).
    #[arg(long, default_value = "shaded")]
    color: ColorMode,
    /// Image size WxH in pixels.
    #[arg(long, default_value = "640x360", value_parser = parse_dims::<2>)]
    size: [u32; 2],
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f32,
    /// Draw the full-detail scene (every object at LOD 0) instead of the query's answer.
    #[arg(long)]
    full: bool,
    /// Write the full-detail image and the answer's side by side (left: full) into --out.
    #[arg(long, conflicts_with = "full")]
    pair: bool,
    /// The PNG to write.
    #[arg(long, default_value = "render.png")]
    out: PathBuf,
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Report {
    out: PathBuf,
    adapter: String,
    size: [u32; 2],
    full: bool,
    items: usize,
    faces: u64,
    coverage: f64,
    /// Against full detail (not with --full); PSNR `null` when the images are equal.
    #[serde(skip_serializing_if = "Option::is_none")]
    fidelity: Option<Fidelity>,
}

pub fn render(a: RenderCmd) -> Result<()> {
    let db = Database::open(&a.db)?;
    let view = View::new(a.at, a.look, a.fov, a.size[0], a.size[1]);
    view.check()?;
    let renderer = super::open_renderer()?;
    let full = renderer.render_full(&db, &view, a.color)?;
    let (image, items, faces, fid) = if a.full {
        let catalog = db.catalog();
        let faces = (0..catalog.objects.len() as u32).map(|o| u64::from(catalog.object_lods(o)[0].faces)).sum();
        (full, catalog.objects.len(), faces, None)
    } else {
        let params = a.answer.params(Some(view.camera()), None);
        let answer = db.query(a.at, &params)?;
        for w in &answer.warnings {
            eprintln!("warning: {w}");
        }
        let image = renderer.render_answer(&db, &answer, &view, a.color)?;
        // Fidelity is measured on shaded images whatever the colours drawn.
        let fid = if a.color == ColorMode::Shaded {
            fidelity::compare(&image, &full)
        } else {
            let shaded_full = renderer.render_full(&db, &view, ColorMode::Shaded)?;
            let shaded = renderer.render_answer(&db, &answer, &view, ColorMode::Shaded)?;
            fidelity::compare(&shaded, &shaded_full)
        };
        let image = if a.pair { full.beside(&image) } else { image };
        (image, answer.items.len(), answer.stats.faces, Some(fid))
    };
    image.write_png(&a.out)?;
    let report = Report {
        out: a.out.clone(),
        adapter: renderer.adapter_name().to_string(),
        size: a.size,
        full: a.full,
        items,
        faces,
        coverage: image.coverage(),
        fidelity: fid,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).expect("serialisable"));
        return Ok(());
    }
    println!(
        "{}: {}×{} {}, {} items, {} faces, {:.1} % covered ({})",
        a.out.display(),
        a.size[0],
        a.size[1],
        if a.full { "full detail" } else { "answer" },
        items,
        faces,
        report.coverage * 100.0,
        report.adapter
    );
    if let Some(f) = fid {
        println!(
            "  against full detail: PSNR {:.2} dB, coverage difference {:.3} % (silhouettes alone {:.3} %)",
            f.psnr,
            f.coverage_diff * 100.0,
            f.silhouette_diff * 100.0
        );
    }
    Ok(())
}

/// The demo's picture: full detail beside the default answer from `at` looking along `look`,
/// both coloured by LOD level, into `out` (a PNG). `None` without a graphics adapter.
pub(super) fn demo_picture(db: &Database, (at, look): (Vec3, Vec3), out: &Path) -> Result<Option<hdov::render::Image>> {
    let Ok(renderer) = Renderer::new() else { return Ok(None) };
    let view = View::new(at, look, 60.0, 640, 360);
    let answer = db.query(at, &hdov::QueryParams { camera: Some(view.camera()), ..Default::default() })?;
    let full = renderer.render_full(db, &view, ColorMode::Lod)?;
    let drawn = renderer.render_answer(db, &answer, &view, ColorMode::Lod)?;
    let pair = full.beside(&drawn);
    pair.write_png(out)?;
    Ok(Some(pair))
}
