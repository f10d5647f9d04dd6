//! The query benchmarks' fixture, shared by `benches/query.rs` and the `query-latency` tool: a generated city built once at R = 64 on the CPU backend
//! with fan-out 16, cached under `<target>/bench-data/<scale>-r64-m16.hdov`, and the viewpoints
//! the benchmarks query.
//!
//! `<target>` is `$CARGO_TARGET_DIR` when set, else the workspace's `target/`;
//! `$HDOV_BENCH_DATA` overrides the whole folder. A cached database is reused when it opens and
//! was built with these parameters; otherwise it is rebuilt in place (`replace = true`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use hdov::Overwrite;
use hdov::city::{CityParams, CityScale, avenue_walk};
use hdov::dov::BackendKind;
use hdov::progress::Progress;
use hdov::query::Camera;
use hdov::{BuildParams, Database, Mode, QueryParams, VisibilityParams};
use hdov_storage::LayoutKind;

/// Texels per cube-face edge of the fixture's DoV.
pub const RESOLUTION: u32 = 64;
/// Most entries per tree node.
pub const FANOUT: u32 = 16;
/// Viewpoints of the point-query benchmarks: `avenue_walk(grid, WALK_POINTS)`.
pub const WALK_POINTS: usize = 64;
/// The budget mode's faces.
pub const BUDGET_FACES: u64 = 20_000;

/// The point-query configurations: (benchmark name, parameters). Seven modes (threshold at
/// η = 0, 1e-4, 1e-3; naive; budget; vmsse at τ = 1; frustum looking +x), then threshold at
/// η = 1e-3 in each layout.
pub fn point_configs() -> Vec<(String, QueryParams)> {
    let threshold = |eta: f64| QueryParams { mode: Mode::Threshold, eta, ..Default::default() };
    let mut configs = vec![
        ("default".to_string(), QueryParams::default()),
        ("threshold-0".to_string(), threshold(0.0)),
        ("threshold-1e-4".to_string(), threshold(1e-4)),
        ("threshold-1e-3".to_string(), threshold(1e-3)),
        ("naive".to_string(), QueryParams { mode: Mode::Naive, ..Default::default() }),
        ("budget".to_string(), QueryParams { mode: Mode::Budget, budget: BUDGET_FACES, ..Default::default() }),
        ("vmsse".to_string(), QueryParams { mode: Mode::Vmsse, tau: 1.0, ..Default::default() }),
        (
            "frustum".to_string(),
            QueryParams {
                mode: Mode::Frustum,
                camera: Some(Camera { look: Vec3::X, ..Default::default() }),
                ..Default::default()
            },
        ),
    ];
    for layout in LayoutKind::ALL {
        configs.push((format!("threshold-1e-3/{layout}"), QueryParams { layout: Some(layout), ..threshold(1e-3) }));
    }
    configs
}

/// Where cached databases live.
pub fn data_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("HDOV_BENCH_DATA") {
        return dir.into();
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root(Path::new(env!("CARGO_MANIFEST_DIR"))).join("target"));
    target.join("bench-data")
}

/// The first folder at or above `start` that holds `Cargo.lock` (the workspace root).
fn workspace_root(start: &Path) -> PathBuf {
    start.ancestors().find(|d| d.join("Cargo.lock").is_file()).unwrap_or(start).to_path_buf()
}

/// Whether the large city was asked for (`HDOV_BENCH_LARGE=1`).
pub fn large_wanted() -> bool {
    std::env::var("HDOV_BENCH_LARGE").is_ok_and(|v| v == "1")
}

/// The scales to measure: default, and large when [`large_wanted`].
pub fn scales() -> Vec<CityScale> {
    let mut s = vec![CityScale::Default];
    if large_wanted() {
        s.push(CityScale::Large);
    }
    s
}

/// The fixture's folder for `scale`.
pub fn fixture_dir(scale: CityScale) -> PathBuf {
    data_dir().join(format!("{}-r{RESOLUTION}-m{FANOUT}.hdov", scale.name()))
}

fn build_params() -> BuildParams {
    BuildParams {
        fanout: Some(FANOUT),
        visibility: Some(VisibilityParams { resolution: RESOLUTION, backend: BackendKind::Cpu, ..Default::default() }),
        ..Default::default()
    }
}

/// Opens the cached database of `scale`, building it first when it is missing, does not open,
/// or was built with other parameters (default city: 1–2 minutes on two cores; large: more).
pub fn open_or_build(scale: CityScale) -> Result<Database, Box<dyn std::error::Error>> {
    let dir = fixture_dir(scale);
    let wanted = build_params();
    match Database::open(&dir) {
        Ok(db) if built_as_wanted(&db) => return Ok(db),
        Ok(_) => eprintln!("{}: built with other parameters, rebuilding", dir.display()),
        Err(e) => eprintln!("{e} (building it)"),
    }
    let t = Instant::now();
    let scene = hdov::city::generate(&CityParams { seed: 1, scale, ..Default::default() })?;
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent)?;
    }
    hdov::build(&scene, &dir, &wanted, Overwrite::Ours, &Progress::hidden())?;
    eprintln!("{}: built in {:.1} s", dir.display(), t.elapsed().as_secs_f64());
    Ok(Database::open(&dir)?)
}

/// Whether `db` was built at [`RESOLUTION`] with fan-out [`FANOUT`].
fn built_as_wanted(db: &Database) -> bool {
    let b = &db.manifest().build;
    b.fanout == Some(FANOUT) && b.visibility.as_ref().is_some_and(|v| v.resolution == RESOLUTION)
}

/// The point queries' viewpoints: [`WALK_POINTS`] points along the first avenue, looking +x.
pub fn walk(db: &Database) -> Vec<Vec3> {
    let grid = db.grid().expect("the fixture has a grid");
    avenue_walk(grid, WALK_POINTS).into_iter().map(|(at, _)| at).collect()
}

/// Two points inside one cell (no flip between them): a quarter and three quarters of the way
/// along x through the cell holding the walk's 10th point, at its height and z.
pub fn same_cell_pair(db: &Database) -> [Vec3; 2] {
    let grid = db.grid().expect("the fixture has a grid");
    let at = walk(db)[10];
    let cell = grid.cell_box(grid.cell_of(at).expect("the walk lies in the grid"));
    let x = |t: f32| cell.min.x + (cell.max.x - cell.min.x) * t;
    [Vec3::new(x(0.25), at.y, at.z), Vec3::new(x(0.75), at.y, at.z)]
}

/// Two points in neighbouring cells along x (every step between them flips): the centres, in
/// x, of the cell holding the walk's 10th point and of the next cell.
pub fn neighbour_pair(db: &Database) -> [Vec3; 2] {
    let grid = db.grid().expect("the fixture has a grid");
    let at = walk(db)[10];
    let c = grid.cell_of(at).expect("the walk lies in the grid");
    let next = [c[0] + 1, c[1], c[2]];
    assert!(next[0] < grid.dims[0], "the walk's 10th point is not in the last column");
    let centre = |c: [u32; 3]| grid.cell_box(c).center().x;
    [Vec3::new(centre(c), at.y, at.z), Vec3::new(centre(next), at.y, at.z)]
}
