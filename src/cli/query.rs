//! `hdov query` and `hdov walk`: ask a database what is visible, from a point or along a path.

use std::path::{Path, PathBuf};

use clap::Args;
use glam::Vec3;
use serde::Serialize;

use hdov::city::WalkKind;
use hdov::render::{View, fidelity};
use hdov::review::{self, ReviewParams};
use hdov::text::{parse_dims, parse_point};
use hdov::{Answer, Database, QueryParams, SessionParams, Step};
use hdov::{Camera, Error, LodRule, Mode, Param, Result};
use hdov::{LayoutKind, PolicyKind};

/// What a query returns: its mode, η, level rule and the modes' own bounds (`query`, `walk` and
/// `render` alike).
#[derive(Args)]
pub(super) struct AnswerArgs {
    /// DoV threshold η (threshold mode): subtrees seen with DoV ≤ η come back as one coarse LOD.
    #[arg(long, default_value_t = hdov::DEFAULT_ETA)]
    eta: f64,
    /// Query mode: threshold, naive, budget, vmsse or frustum.
    #[arg(long, default_value = "threshold")]
    mode: Mode,
    /// Budget mode: faces to return at most.
    #[arg(long, default_value_t = 100_000)]
    budget: u64,
    /// Vmsse mode: screen-space error bound in pixels.
    #[arg(long, default_value_t = 1.0)]
    tau: f64,
    /// Levels of detail of threshold, naive and budget modes: `screen[:PIXELS]` (the coarsest
    /// level whose error is at most PIXELS, default 0.5, from anywhere in the cell) or `dov`
    /// (thesis eq. 5.6).
    #[arg(long, default_value = "screen:0.5")]
    lod_rule: LodRule,
}

impl AnswerArgs {
    pub(super) fn params(&self, camera: Option<Camera>, layout: Option<LayoutKind>) -> QueryParams {
        QueryParams {
            mode: self.mode,
            eta: self.eta,
            budget: self.budget,
            tau: self.tau,
            lod_rule: self.lod_rule,
            camera,
            layout,
        }
    }
}

/// What `query` and `walk` ask of each query.
#[derive(Args)]
pub struct QueryArgs {
    #[command(flatten)]
    answer: AnswerArgs,
    /// V-page layout to read (default: indexed-vertical).
    #[arg(long)]
    layout: Option<LayoutKind>,
    /// View direction DX,DY,DZ: cull the answer to the view frustum (what is drawn this frame).
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    look: Option<Vec3>,
    /// Field of view in degrees: vertical, with --look (default 60; vmsse without --look
    /// assumes 60); `walk --method review`: horizontal and vertical (default 45).
    #[arg(long)]
    fov: Option<f32>,
    /// Image height in pixels of vmsse's screen errors (with --look; else 1080).
    #[arg(long, default_value_t = 1080)]
    image_height: u32,
}

impl QueryArgs {
    fn params(&self) -> QueryParams {
        let camera =
            Camera { fov_y_deg: self.fov.unwrap_or(60.0), image_height: self.image_height, ..Camera::default() };
        self.answer.params(self.look.map(|look| Camera { look, ..camera }), self.layout)
    }
}

#[derive(Args)]
pub struct QueryCmd {
    db: PathBuf,
    /// The viewpoint X,Y,Z.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    at: Vec3,
    #[command(flatten)]
    query: QueryArgs,
    /// Items listed in the summary (all of them with --json).
    #[arg(long, default_value_t = 20)]
    list: usize,
    /// Also write the answer as a glTF binary (.glb): one node per item at its level.
    #[arg(long)]
    out: Option<PathBuf>,
    #[arg(long)]
    json: bool,
}

pub fn query(a: QueryCmd) -> Result<()> {
    let db = Database::open(&a.db)?;
    let answer = db.query(a.at, &a.query.params())?;
    for w in &answer.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(out) = &a.out {
        hdov::write_answer_glb(&db, &answer, out)?;
        if !a.json {
            println!("{}: {} items as glTF", out.display(), answer.items.len());
        }
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&answer).expect("serialisable"));
        return Ok(());
    }
    print_answer(&answer, a.list);
    Ok(())
}

fn print_answer(a: &Answer, list: usize) {
    let s = &a.stats;
    let nodes = a.items.iter().filter(|i| i.kind == hdov::ItemKind::Node).count();
    println!(
        "cell {:?} ({}), {} mode, η = {}, {} layout: {} items ({} internal LODs), {} faces",
        a.cell,
        a.cell_id,
        a.mode,
        a.eta,
        a.layout.map_or_else(|| "no".to_string(), |k| k.to_string()),
        a.items.len(),
        nodes,
        s.faces
    );
    println!(
        "  pages read {} (tree {}, V-index {}, V-pages {}), nodes visited {}, {} µs{}",
        s.pages_read,
        s.tree_pages,
        s.vindex_pages,
        s.vpage_pages,
        s.nodes_visited,
        s.micros,
        if s.over_budget { ", over budget" } else { "" }
    );
    let mut items: Vec<_> = a.items.iter().collect();
    items.sort_by(|x, y| y.dov.total_cmp(&x.dov));
    for i in items.iter().take(list) {
        println!(
            "  {:>10.6}  {:<6} #{:<6} LOD {:<2} {:>7} faces  {}",
            i.dov,
            format!("{:?}", i.kind).to_lowercase(),
            i.id,
            i.lod,
            i.faces,
            i.name
        );
    }
    if items.len() > list {
        println!("  … {} more (--list N, or --json)", items.len() - list);
    }
}

#[derive(Args)]
pub struct WalkCmd {
    db: PathBuf,
    /// The path: a CSV file of viewpoints, `x,y,z` or `x,y,z,dx,dy,dz` (a view direction) per line.
    #[arg(long, required_unless_present = "walk")]
    path: Option<PathBuf>,
    /// Instead of --path, a recorded walk along a generated city's first avenue: straight,
    /// turning (the gaze swinging ±70°) or back-and-forth (thesis §5.8.5).
    #[arg(long, conflicts_with = "path", value_parser = |s: &str| s.parse::<WalkKind>())]
    walk: Option<WalkKind>,
    /// --walk: steps along it.
    #[arg(long, default_value_t = 150, requires = "walk", value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    steps: u32,
    #[command(flatten)]
    query: QueryArgs,
    /// visual (the HDoV-tree) or review (the spatial baseline: disk cells and CSearch).
    #[arg(long, value_enum, default_value_t = WalkMethod::Visual)]
    method: WalkMethod,
    /// Review: the disk cell over the frustum cell, per axis (SF).
    #[arg(long, default_value_t = review::DEFAULT_REVIEW_BOX)]
    review_box: f32,
    /// Review: the depth of the view frustum, in metres.
    #[arg(long, default_value_t = review::DEFAULT_EYESIGHT)]
    eyesight: f32,
    /// Tree-page and V-page cache: none, lru, dov, dov-time or dplru.
    #[arg(long, default_value = "lru")]
    cache: PolicyKind,
    /// Cache capacity in pages.
    #[arg(long, default_value_t = 256)]
    cache_pages: usize,
    /// Cache capacity in bytes (unbounded if not given).
    #[arg(long)]
    cache_bytes: Option<u64>,
    /// Most bytes of LOD geometry to keep resident (unbounded if not given).
    #[arg(long)]
    resident_bytes: Option<u64>,
    /// Query the cell ahead along the motion, so its pages are cached on arrival.
    #[arg(long)]
    prefetch: bool,
    /// At each step with a view direction, render full detail and the drawn answer from the
    /// step's camera and report PSNR and coverage difference (needs a graphics adapter).
    #[arg(long)]
    fidelity: bool,
    /// --fidelity: image size WxH in pixels.
    #[arg(long, default_value = "320x200", value_parser = parse_dims::<2>, requires = "fidelity")]
    size: [u32; 2],
    #[arg(long)]
    json: bool,
}

/// `hdov walk --method`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WalkMethod {
    Visual,
    Review,
}

/// A walk's totals.
#[derive(Serialize)]
pub(super) struct WalkSummary {
    steps: usize,
    flips: usize,
    pages_read: u64,
    hits: u64,
    misses: u64,
    prefetch_pages: u64,
    loaded_bytes: u64,
    evicted_bytes: u64,
    max_resident_bytes: u64,
    mean_faces: f64,
    micros_mean: f64,
    micros_p99: u64,
}

pub fn walk(a: WalkCmd) -> Result<()> {
    let db = Database::open(&a.db)?;
    // Steps are named by their line in the path file, or by their index along a recorded walk.
    let (path, source) = match (&a.path, a.walk) {
        (Some(file), _) => (read_path(file)?, file.clone()),
        (None, Some(kind)) => {
            let grid = db.grid().ok_or_else(|| Error::bad_file(&a.db, "holds no grid to walk"))?;
            let walk = hdov::city::walk(grid, kind, a.steps as usize);
            (walk.into_iter().enumerate().map(|(i, (at, look))| (i, at, Some(look))).collect(), a.db.clone())
        }
        (None, None) => return Err(Error::bad_param(Param::Path, "give --path FILE or --walk KIND")),
    };
    let review = match a.method {
        WalkMethod::Visual => None,
        WalkMethod::Review => Some(ReviewParams {
            review_box: a.review_box,
            eyesight: a.eyesight,
            fov_deg: a.query.fov.unwrap_or(review::DEFAULT_FOV_DEG),
            ..ReviewParams::default()
        }),
    };
    let params = SessionParams {
        query: a.query.params(),
        cache: a.cache,
        cache_pages: Some(a.cache_pages),
        cache_bytes: a.cache_bytes,
        resident_bytes: a.resident_bytes,
        prefetch: a.prefetch,
    };
    let mut session = match review {
        None => db.session(&params)?,
        Some(r) => db.review_session(&params, r)?,
    };
    let renderer = if a.fidelity { Some(super::open_renderer()?) } else { None };
    let mut steps: Vec<Step> = Vec::with_capacity(path.len());
    for (line, at, look) in path {
        let mut step = session.step(at, look).map_err(|e| match e {
            Error::BadParam { param: Param::At, reason } => Error::bad_file(&source, format!("line {line}: {reason}")),
            e => e,
        })?;
        if let (Some(renderer), Some(look)) = (&renderer, look.or(a.query.look)) {
            let view = fidelity_view(review, a.query.fov, at, look, a.size);
            view.check()?;
            let f = fidelity::of_session(renderer, &session, &view)?;
            (step.psnr, step.coverage_diff) = (Some(f.psnr), Some(f.coverage_diff));
        }
        steps.push(step);
    }
    let summary = summarise(&steps);
    if a.json {
        let doc = serde_json::json!({"steps": steps, "summary": summary});
        println!("{}", serde_json::to_string_pretty(&doc).expect("serialisable"));
        return Ok(());
    }
    for s in &steps {
        println!(
            "step {:>4} cell {:?}{} items {:>5} faces {:>9} pages {:>4} hits {:>4} loaded {:>3} ({:>9} B) evicted {:>3} resident {:>10} B {:>6} µs{}",
            s.step,
            s.cell,
            if s.flipped { " flip" } else { "     " },
            s.items,
            s.faces,
            s.pages_read,
            s.hits,
            s.loaded,
            s.loaded_bytes,
            s.evicted,
            s.resident_bytes,
            s.micros,
            match (s.psnr, s.coverage_diff) {
                (Some(p), Some(c)) => format!("  PSNR {p:.1} dB coverage diff {c:.4}"),
                _ => String::new(),
            }
        );
    }
    print_summary(&summary);
    Ok(())
}

/// The camera `hdov walk --fidelity` renders a step from: VISUAL's vertical field of view
/// (`fov`, default 60°); REVIEW's, narrowed so that the image's horizontal field of view is
/// REVIEW's own (`fov`, default 45°, both ways) and nothing at the image's edges was culled.
fn fidelity_view(review: Option<ReviewParams>, fov: Option<f32>, at: Vec3, look: Vec3, size: [u32; 2]) -> View {
    let aspect = size[0] as f32 / size[1].max(1) as f32;
    let fov_y = match review {
        None => fov.unwrap_or(60.0),
        Some(r) => {
            let h = fov.unwrap_or(r.fov_deg).to_radians();
            (2.0 * ((h / 2.0).tan() / aspect.max(1.0)).atan()).to_degrees()
        }
    };
    View::new(at, look, fov_y, size[0], size[1])
}

pub(super) fn print_summary(summary: &WalkSummary) {
    println!(
        "{} steps, {} flips, {} pages read ({} hits, {} misses, {} prefetched), {} bytes loaded, {} evicted, mean {:.0} faces, {:.0} µs mean, {} µs p99",
        summary.steps,
        summary.flips,
        summary.pages_read,
        summary.hits,
        summary.misses,
        summary.prefetch_pages,
        summary.loaded_bytes,
        summary.evicted_bytes,
        summary.mean_faces,
        summary.micros_mean,
        summary.micros_p99
    );
}

pub(super) fn summarise(steps: &[Step]) -> WalkSummary {
    let n = steps.len().max(1) as f64;
    let mut micros: Vec<u64> = steps.iter().map(|s| s.micros).collect();
    micros.sort_unstable();
    let p99 = micros.get(((micros.len() as f64 * 0.99).ceil() as usize).saturating_sub(1)).copied().unwrap_or(0);
    WalkSummary {
        steps: steps.len(),
        flips: steps.iter().filter(|s| s.flipped).count(),
        pages_read: steps.iter().map(|s| s.pages_read).sum(),
        hits: steps.iter().map(|s| s.hits).sum(),
        misses: steps.iter().map(|s| s.misses).sum(),
        prefetch_pages: steps.iter().map(|s| s.prefetch_pages).sum(),
        loaded_bytes: steps.iter().map(|s| s.loaded_bytes).sum(),
        evicted_bytes: steps.iter().map(|s| s.evicted_bytes).sum(),
        max_resident_bytes: steps.iter().map(|s| s.resident_bytes).max().unwrap_or(0),
        mean_faces: steps.iter().map(|s| s.faces as f64).sum::<f64>() / n,
        micros_mean: micros.iter().sum::<u64>() as f64 / n,
        micros_p99: p99,
    }
}

/// The demo's questions to its database: point queries in every mode from one street corner,
/// and a walk along the first avenue. Prints them unless `json`; returns them as JSON.
/// The demo's queries from one street viewpoint and its walk; returns them as JSON, and the
/// viewpoint with the walk's direction there.
pub(super) fn demo_queries(db: &Database, json: bool) -> Result<(serde_json::Value, serde_json::Value, (Vec3, Vec3))> {
    let grid = db.grid().ok_or_else(|| Error::bad_file(db.dir(), "holds no grid"))?;
    let path = hdov::city::avenue_walk(grid, 150);
    let (at, along) = path[path.len() / 3];
    let ahead = Camera { look: Vec3::X, ..Camera::default() };
    let asks = [
        ("naive", QueryParams { mode: Mode::Naive, ..Default::default() }),
        ("threshold η = 0", QueryParams { eta: 0.0, ..Default::default() }),
        ("threshold η = 1e-4", QueryParams { eta: 1e-4, ..Default::default() }),
        ("threshold η = 1e-3", QueryParams { eta: 1e-3, ..Default::default() }),
        ("threshold η = 3e-2", QueryParams { eta: 3e-2, ..Default::default() }),
        ("budget 20k faces", QueryParams { mode: Mode::Budget, budget: 20_000, ..Default::default() }),
        ("vmsse τ = 1 px", QueryParams { mode: Mode::Vmsse, ..Default::default() }),
        ("frustum, looking +x", QueryParams { mode: Mode::Frustum, camera: Some(ahead), ..Default::default() }),
        ("η = 3e-2, looking +x", QueryParams { camera: Some(ahead), ..Default::default() }),
    ];
    let mut queries = Vec::new();
    if !json {
        println!("queries from {:?}:", at.to_array());
    }
    for (label, p) in asks {
        let a = db.query(at, &p)?;
        let s = &a.stats;
        let nodes = a.items.iter().filter(|i| i.kind == hdov::ItemKind::Node).count();
        if !json {
            println!(
                "  {label:<22} {:>5} items ({nodes:>2} internal LODs) {:>9} faces  {:>3} pages  {:>5} µs",
                a.items.len(),
                s.faces,
                s.pages_read,
                s.micros
            );
        }
        queries.push(serde_json::json!({"query": label, "items": a.items.len(), "internal_lods": nodes, "stats": s}));
    }
    let params = SessionParams { cache: PolicyKind::DOV_TIME, cache_pages: Some(64), ..Default::default() };
    let mut session = db.session(&params)?;
    let steps = path.iter().map(|&(at, look)| session.step(at, Some(look))).collect::<Result<Vec<_>>>()?;
    let summary = summarise(&steps);
    if !json {
        print!("walk along the first avenue, η = 3e-2, DoV-Time cache of 64 pages: ");
        print_summary(&summary);
    }
    Ok((serde_json::Value::Array(queries), serde_json::to_value(&summary).expect("serialisable"), (at, along)))
}

/// A path file: `(line number, viewpoint, view direction)` per point.
fn read_path(path: &Path) -> Result<Vec<(usize, Vec3, Option<Vec3>)>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |r: String| Error::bad_file(path, format!("line {}: {r}", i + 1));
        let v: Vec<f32> = line
            .split(',')
            .map(|x| x.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad(format!("'{line}' is not finite numbers x,y,z[,dx,dy,dz]")))?;
        match v.len() {
            3 => out.push((i + 1, Vec3::new(v[0], v[1], v[2]), None)),
            6 => out.push((i + 1, Vec3::new(v[0], v[1], v[2]), Some(Vec3::new(v[3], v[4], v[5])))),
            n => return Err(bad(format!("{n} numbers; expected x,y,z or x,y,z,dx,dy,dz"))),
        }
    }
    if out.is_empty() {
        return Err(Error::bad_file(path, "holds no viewpoints"));
    }
    Ok(out)
}
