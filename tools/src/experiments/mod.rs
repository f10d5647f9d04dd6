//! The experiments harness (issue 10): every measurement of the thesis's §5.8 and §6.3 that this
//! project reproduces, plus speed-against-accuracy charts and where the DoV measurement fails.
//! Each experiment writes its data as CSV and its charts as SVG into one output folder, and a
//! Markdown summary of what ran (`summary.md`). Databases are built into a cache folder and
//! reused when their manifest says they were built with the same parameters from the same scene.
//!
//! `cargo run --release -p hdov-tools --bin experiments -- --scale small|default|large`

pub mod caching;
pub mod charts;
pub mod precompute;
pub mod query;
pub mod scalability;
pub mod stability;
pub mod storage;
pub mod walkthrough;

use std::fmt::Display;
use std::path::{Path, PathBuf};
use std::time::Instant;

use hdov::Overwrite;
use hdov::city::{CityParams, CityScale};
use hdov::dov::BackendKind;
use hdov::format::Manifest;
use hdov::progress::Progress;
use hdov::{BuildParams, Database, Scene, VisibilityParams};
use hdov_storage::DovCodec;

/// How big a run is: which city and which sweeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// The small city and short sweeps: a few minutes on two cores (the CI smoke test).
    Small,
    /// The default city (about 2,100 objects), the large city for scalability.
    Default,
    /// The large city (about 11,300 objects) everywhere the default uses the default city.
    Large,
}

hdov_storage::named!(Scale, "scale");
hdov_storage::by_names!(Scale);

impl Scale {
    /// Every scale.
    pub const ALL: [Scale; 3] = [Scale::Small, Scale::Default, Scale::Large];

    /// The name `--scale` takes.
    pub fn name(self) -> &'static str {
        match self {
            Scale::Small => "small",
            Scale::Default => "default",
            Scale::Large => "large",
        }
    }

    /// The city most experiments run on.
    pub fn city(self) -> CityScale {
        match self {
            Scale::Small => CityScale::Small,
            Scale::Default => CityScale::Default,
            Scale::Large => CityScale::Large,
        }
    }

    /// Fan-outs of the storage experiment.
    pub fn fanouts(self) -> &'static [u32] {
        match self {
            Scale::Small => &[4, 16, 126],
            _ => &[4, 8, 16, 32, 126],
        }
    }
}

/// The experiments, by name (`--only NAME,..`).
pub const EXPERIMENTS: [&str; 8] =
    ["storage", "caching", "query", "scalability", "walkthrough", "precompute", "accuracy", "stability"];

/// What a run is asked to do.
#[derive(Clone, Debug)]
pub struct Config {
    pub scale: Scale,
    /// Folders searched for cached databases; builds go into the first.
    pub caches: Vec<PathBuf>,
    /// Where CSV, SVG and `summary.md` go.
    pub out: PathBuf,
    /// Only these experiments (all when empty).
    pub only: Vec<String>,
    /// Resolution R of every database built.
    pub resolution: u32,
    /// Progress bars (on a terminal).
    pub progress: bool,
}

impl Config {
    pub fn new(scale: Scale) -> Config {
        Config {
            scale,
            caches: vec![PathBuf::from("target/experiments")],
            out: PathBuf::from("docs/results"),
            only: Vec::new(),
            resolution: 64,
            progress: true,
        }
    }
}

/// What the experiments share while they run: the configuration, the cities, the summary.
pub struct Ctx {
    pub cfg: Config,
    pub progress: Progress,
    summary: Vec<String>,
}

/// A CSV table under construction.
pub struct Csv {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Csv {
    pub fn new(header: &[&str]) -> Csv {
        Csv { header: header.iter().map(|s| s.to_string()).collect(), rows: Vec::new() }
    }

    /// Adds a row; numbers are written as `Display` writes them.
    pub fn push(&mut self, cells: &[&dyn Display]) {
        assert_eq!(cells.len(), self.header.len(), "a CSV row has one cell per column");
        self.rows.push(cells.iter().map(|c| c.to_string()).collect());
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let quote = |s: &String| if s.contains(',') { format!("\"{s}\"") } else { s.clone() };
        let mut text = self.header.join(",") + "\n";
        for row in &self.rows {
            text += &(row.iter().map(quote).collect::<Vec<_>>().join(",") + "\n");
        }
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
    }
}

pub type Result<T> = std::result::Result<T, String>;

/// An hdov error as one line.
pub fn err(e: impl Display) -> String {
    e.to_string()
}

impl Ctx {
    pub fn new(cfg: Config) -> Ctx {
        let progress = if cfg.progress { Progress::for_terminal(false) } else { Progress::hidden() };
        Ctx { cfg, progress, summary: Vec::new() }
    }

    /// The generated city of `scale` (seed 1), or one with `blocks` × `blocks` blocks.
    pub fn city(&self, scale: CityScale, blocks: Option<u32>) -> Result<Scene> {
        hdov::city::generate(&CityParams { seed: 1, scale, blocks: blocks.map(|b| [b, b]), ..Default::default() })
            .map_err(err)
    }

    /// The build parameters every experiment database uses, at fan-out `m` and `codec`.
    pub fn build_params(&self, fanout: u32, codec: DovCodec) -> BuildParams {
        BuildParams {
            fanout: Some(fanout),
            visibility: Some(VisibilityParams {
                resolution: self.cfg.resolution,
                backend: BackendKind::Cpu,
                dov_codec: codec,
                // The experiments compare the layouts: every one is written, whatever its size.
                slot_budget: None,
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// The database of `scene` (called `label`) built with `params`: a cached one whose manifest
    /// records the same build parameters and the scene's counts, else a new build into the
    /// first cache folder.
    pub fn database(&self, label: &str, scene: &Scene, params: &BuildParams) -> Result<Database> {
        let vis = params.visibility.as_ref();
        let codec = vis.map_or(DovCodec::F32, |v| v.dov_codec);
        let name = format!(
            "{label}-r{}-m{}{}.hdov",
            vis.map_or(0, |v| v.resolution),
            params.fanout.unwrap_or(0),
            if codec == DovCodec::F32 { String::new() } else { format!("-{codec}") }
        );
        // A manifest without a fan-out was built at the default one: compare the tree's own.
        let matches = |m: &Manifest| {
            let mut built = m.build.clone();
            built.fanout = built.fanout.or(Some(m.tree.max_entries as u32));
            built == *params
                && m.counts.objects == scene.objects.len() as u64
                && m.counts.triangles == scene.triangle_count()
        };
        for dir in &self.cfg.caches {
            let path = dir.join(&name);
            if Manifest::read(&path).is_ok_and(|m| matches(&m)) {
                return Database::open(&path).map_err(err);
            }
        }
        let dir = self.cfg.caches.first().ok_or("no cache folder")?;
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let path = dir.join(&name);
        let t = Instant::now();
        hdov::build(scene, &path, params, Overwrite::Ours, &self.progress).map_err(err)?;
        eprintln!("built {} in {:.1} s", path.display(), t.elapsed().as_secs_f64());
        Database::open(&path).map_err(err)
    }

    /// The main database of this scale: its city at fan-out 16 (the default), f32 DoV.
    pub fn main_database(&self) -> Result<(Scene, Database)> {
        let city = self.cfg.scale.city();
        let scene = self.city(city, None)?;
        let db = self.database(&city.to_string(), &scene, &self.build_params(16, DovCodec::F32))?;
        Ok((scene, db))
    }

    /// Writes `csv` as `name.csv` in the output folder.
    pub fn write_csv(&self, name: &str, csv: &Csv) -> Result<()> {
        csv.write(&self.cfg.out.join(format!("{name}.csv")))
    }

    /// Writes `panels` as `name.svg` in the output folder.
    pub fn write_chart(&self, name: &str, title: &str, panels: &[charts::Panel], cols: usize) -> Result<()> {
        charts::write_svg(&self.cfg.out.join(format!("{name}.svg")), title, panels, cols)
    }

    /// A line of the summary (Markdown).
    pub fn note(&mut self, line: impl Into<String>) {
        self.summary.push(line.into());
    }

    /// A progress bar for `total` steps of `label`.
    pub fn bar(&self, label: &str, total: usize) -> indicatif::ProgressBar {
        self.progress.bar(label, total as u64)
    }
}

/// Runs the experiments `cfg` asks for; writes `summary.md` last. Returns the summary.
pub fn run(cfg: Config) -> Result<String> {
    for name in &cfg.only {
        if !EXPERIMENTS.contains(&name.as_str()) {
            return Err(format!("--only: unknown experiment '{name}' ({})", EXPERIMENTS.join(", ")));
        }
    }
    std::fs::create_dir_all(&cfg.out).map_err(|e| format!("{}: {e}", cfg.out.display()))?;
    let mut ctx = Ctx::new(cfg);
    ctx.note(format!("# Experiments at scale `{}`\n", ctx.cfg.scale.name()));
    ctx.note(crate::machine());
    ctx.note(format!(
        "\nCommand: `cargo run --release -p hdov-tools --bin experiments -- --scale {}` (databases at R = {}, CPU backend).\n",
        ctx.cfg.scale.name(),
        ctx.cfg.resolution
    ));
    type Experiment = fn(&mut Ctx) -> Result<()>;
    let all: [(&str, Experiment); 8] = [
        ("storage", storage::run),
        ("caching", caching::run),
        ("query", query::run),
        ("scalability", scalability::run),
        ("walkthrough", walkthrough::run),
        ("precompute", precompute::run),
        ("accuracy", query::run_accuracy),
        ("stability", stability::run),
    ];
    for (name, experiment) in all {
        if !ctx.cfg.only.is_empty() && !ctx.cfg.only.iter().any(|o| o == name) {
            continue;
        }
        let t = Instant::now();
        eprintln!("experiment {name} …");
        experiment(&mut ctx).map_err(|e| format!("{name}: {e}"))?;
        let secs = t.elapsed().as_secs_f64();
        eprintln!("experiment {name}: {secs:.1} s");
        ctx.note(format!("- `{name}`: {secs:.1} s wall"));
    }
    let summary = ctx.summary.join("\n") + "\n";
    std::fs::write(ctx.cfg.out.join("summary.md"), &summary).map_err(|e| e.to_string())?;
    Ok(summary)
}

/// Mean of `v` (0 for none).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Population variance of `v`.
pub fn variance(v: &[f64]) -> f64 {
    let m = mean(v);
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len().max(1) as f64
}

/// The `q`-quantile of `v` (nearest rank; 0 for none).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return 0.0;
    }
    s[((q * s.len() as f64).ceil() as usize).clamp(1, s.len()) - 1]
}

/// The PSNR of a sequence of frames: of the mean of their squared errors (frames equal to the
/// reference, PSNR ∞, add zero error), ∞ when every frame is equal (decision 31).
pub fn sequence_psnr(psnr: &[f64]) -> f64 {
    let mse = mean(
        &psnr
            .iter()
            .map(|&p| if p.is_finite() { 255f64.powi(2) / 10f64.powf(p / 10.0) } else { 0.0 })
            .collect::<Vec<_>>(),
    );
    if mse > 0.0 { 10.0 * (255f64.powi(2) / mse).log10() } else { f64::INFINITY }
}
