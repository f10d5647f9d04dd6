//! The synthetic city generator: the thesis's data set (§3.3, §5.8.1, §6.2), rebuilt.
//!
//! The thesis evaluated the HDoV-tree on synthetic cities of many buildings (houses of 240–1,812
//! polygons, towers of 540–1,702) and instances of the Stanford bunny (69,451 faces). This module
//! generates such a city, deterministically from a seed:
//!
//! - a street grid (streets 10–16 m, avenues 18–22 m) around blocks of 60–120 m, cut into lots
//!   (`layout.rs`);
//! - on each lot one building (`building.rs`, from parts in `builder.rs`): a house (6–15 m) or a tower (30–150 m, likelier and
//!   taller downtown) with plinths, ledges and cornices, setback tiers, recessed windows and a
//!   roof, of 240–1,800 triangles;
//! - in plazas (about 7 % of the blocks), six instances each of one dense detail model
//!   (`detail.rs`): the user's model, normalised to statue size, or a procedural figure of 69,312
//!   triangles;
//! - a viewing-cell grid over the whole footprint at eye height (y 1.5–2.0 m, one layer), with
//!   cells of 30–50 m: `tiny` ≈ 40 cells, `small` ≈ 220, `default` ≈ 840, `large` ≈ 4,200, `huge` ≈ 42,000.
//!
//! **Storage.** Every building is its own base mesh (so buildings differ, as in a real city, and
//! each gets its own leaf LODs), instanced once under a translation (and possibly a half turn)
//! that puts its local frame (footprint centred on the origin, ground at y = 0) on its lot. The
//! detail model is stored once, as base mesh 0, and instanced by every statue with its own
//! yaw and scale: the instancing the thesis did by duplicating the bunny. So the `large` city
//! counts ~37 M triangles over its instances but stores ~11 M.
//!
//! Objects are named `b00012_tower`, `b00013_house` (the building's index) and `detail_0003`;
//! base meshes carry the same names (`detail` for the detail model).
//!
//! **Determinism.** The street grid, the choice of plazas, each block and each building draw
//! from their own random streams, derived from the seed and their index (`rng.rs`, SplitMix64),
//! so the scene is identical bit for bit for a seed whatever the thread count, and buildings are
//! generated in parallel (rayon).

mod builder;
mod building;
mod detail;
mod layout;

use std::fmt;
use std::str::FromStr;

use glam::{Mat4, Quat, Vec2, Vec3};
use rayon::prelude::*;

pub use building::{BuildingKind, MAX_TRIANGLES as MAX_BUILDING_TRIANGLES, MIN_TRIANGLES as MIN_BUILDING_TRIANGLES};
pub use detail::{DETAIL_HEIGHT, DETAIL_MAX_WIDTH, normalise_detail, procedural_detail};

use crate::error::{Error, Param};
use crate::geom::Aabb;
use crate::grid::ViewGrid;
use crate::rng::Rng;
use crate::scene::{BaseMesh, Mesh, Object, Scene};
use layout::CityPlan;

/// Random stream of the buildings' designs (apart from the layout's streams).
const BUILDING_STREAM: u64 = 100;

/// Eye-height range of the viewing cells, in metres above the street.
pub const EYE_HEIGHT: [f32; 2] = [1.5, 2.0];

/// Name of the detail model's base mesh (always base mesh 0).
pub const DETAIL_MESH_NAME: &str = "detail";

/// How big a city to generate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum CityScale {
    /// 2 × 2 blocks: 40–60 objects, for tests.
    Tiny,
    /// 6 × 6 blocks: 300–500 objects (about 440).
    Small,
    /// 13 × 13 blocks: about 2,100 objects (7 M triangles over instances), the demo.
    #[default]
    Default,
    /// 30 × 30 blocks: about 11,300 objects and 37 M triangles over instances (11 M stored), the
    /// thesis's scale.
    Large,
    /// 96 × 96 blocks: about 116,000 objects and 380 M triangles over instances (about 115 M
    /// stored), ten times the thesis's: for the memory-bounded build and sharded visibility
    /// (docs/sharding.md); one machine does not measure its grid's visibility in a day.
    Huge,
}

impl CityScale {
    /// Every scale, smallest first.
    pub const ALL: [CityScale; 5] =
        [CityScale::Tiny, CityScale::Small, CityScale::Default, CityScale::Large, CityScale::Huge];

    /// Blocks along x and z.
    pub fn blocks(self) -> [u32; 2] {
        match self {
            CityScale::Tiny => [2, 2],
            CityScale::Small => [6, 6],
            CityScale::Default => [13, 13],
            CityScale::Large => [30, 30],
            CityScale::Huge => [96, 96],
        }
    }

    /// About how many viewing cells the default grid has (it scales with the footprint when the
    /// block count is overridden, keeping the cell size of the scale's own block count).
    pub fn target_cells(self) -> f32 {
        match self {
            CityScale::Tiny => 36.0,
            CityScale::Small => 200.0,
            CityScale::Default => 800.0,
            CityScale::Large => 4096.0,
            // The large city's cell size (about 47 m) over 10.24 times its footprint.
            CityScale::Huge => 4096.0 * (96.0 * 96.0) / (30.0 * 30.0),
        }
    }

    /// The scale's name, as `--scale` takes it.
    pub fn name(self) -> &'static str {
        match self {
            CityScale::Tiny => "tiny",
            CityScale::Small => "small",
            CityScale::Default => "default",
            CityScale::Large => "large",
            CityScale::Huge => "huge",
        }
    }
}

hdov_storage::named!(CityScale, "scale");

impl fmt::Display for CityScale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        hdov_storage::names::write_name(*self, f)
    }
}

/// Any case (`Large`, `large`).
impl FromStr for CityScale {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self, Error> {
        hdov_storage::names::parse_name(&s.to_ascii_lowercase()).map_err(|r| Error::bad_param(Param::Scale, r))
    }
}

/// Most blocks along one axis: 256 × 256 blocks is about 70 times the large city (30 × 30
/// blocks, 37 M triangles), past what one machine builds a database for.
pub const MAX_BLOCKS: u32 = 256;

/// What to generate.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CityParams {
    /// Seed of the generator: equal seeds give equal cities.
    pub seed: u64,
    /// Blocks along x and z, overriding the scale's count (zeros count as one).
    pub blocks: Option<[u32; 2]>,
    /// How big a city to generate.
    pub scale: CityScale,
    /// The dense model to instance in plazas (e.g. from `--detail-model PATH.obj`); the
    /// procedural figure when `None` or when it has no triangles or no extent.
    pub detail_model: Option<Mesh>,
}

/// Generates the city for `params`: base mesh 0 is the detail model, then one base mesh per
/// building; objects are the buildings (in block order) then the detail instances; the grid
/// covers the footprint at eye height.
///
/// Cost: linear in the buildings (about 0.1 ms each on one core, in parallel) plus the detail
/// model: `default` takes ~0.4 s and 37 MB of meshes, `large` ~2 s and ~200 MB (release build,
/// two cores).
pub fn generate(params: &CityParams) -> Result<Scene, Error> {
    params.check()?;
    let blocks = params.blocks.unwrap_or(params.scale.blocks()).map(|b| b.max(1));
    let plan = layout::plan_city(params.seed, blocks);
    let detail = params.detail_model.as_ref().and_then(normalise_detail).unwrap_or_else(procedural_detail);
    let building_meshes = building_meshes(params.seed, &plan);

    let mut meshes = Vec::with_capacity(1 + building_meshes.len());
    let mut objects = Vec::with_capacity(plan.buildings.len() + plan.details.len());
    meshes.push(BaseMesh { name: DETAIL_MESH_NAME.to_string(), mesh: detail });
    for (index, (site, mesh)) in plan.buildings.iter().zip(building_meshes).enumerate() {
        let name = format!("b{index:05}_{}", site.kind.name());
        let turn = if site.turned { std::f32::consts::PI } else { 0.0 };
        let transform =
            Mat4::from_translation(Vec3::new(site.centre.x, 0.0, site.centre.y)) * Mat4::from_rotation_y(turn);
        objects.push(Object { name: name.clone(), mesh: meshes.len() as u32, transform, part: None });
        meshes.push(BaseMesh { name, mesh });
    }
    for (index, site) in plan.details.iter().enumerate() {
        let transform = Mat4::from_scale_rotation_translation(
            Vec3::splat(site.scale),
            Quat::from_rotation_y(site.yaw),
            Vec3::new(site.position.x, 0.0, site.position.y),
        );
        objects.push(Object { name: format!("detail_{index:04}"), mesh: 0, transform, part: None });
    }
    let grid = Some(view_grid(plan.extent, params.scale));
    Ok(Scene { meshes, objects, grid })
}

impl CityParams {
    /// Checks the block counts against [`MAX_BLOCKS`]; costs nothing.
    pub fn check(&self) -> Result<(), Error> {
        match self.blocks {
            Some(b) if b.iter().any(|&n| n > MAX_BLOCKS) => Err(Error::bad_param(
                Param::Blocks,
                format!("{}x{} is more than {MAX_BLOCKS} along an axis", b[0], b[1]),
            )),
            _ => Ok(()),
        }
    }
}

/// One mesh per planned building, generated in parallel; each draws from its own stream, so
/// the result does not depend on scheduling.
fn building_meshes(seed: u64, plan: &CityPlan) -> Vec<Mesh> {
    plan.buildings
        .par_iter()
        .enumerate()
        .map(|(index, site)| {
            let mut rng = Rng::derive(seed, BUILDING_STREAM, index as u64);
            let mut mesh = building::building_mesh(site.kind, site.size, site.height, &mut rng);
            // Built by pushing, a mesh holds up to twice its size: the huge city's generation
            // peaked at 6.4 GB for 3 GB of meshes.
            mesh.positions.shrink_to_fit();
            mesh.indices.shrink_to_fit();
            mesh
        })
        .collect()
}

/// A street-level walk along the city's first avenue, `steps` points from x = 5 m to 5 m before
/// the far end, at z = 8 m and 1.7 m above the ground, each looking along +x: the band z ∈ [0, 18]
/// is a street in every generated city (its first street line is 18–22 m wide). Points are
/// clamped into `grid`'s region, so the walk can be queried.
pub fn avenue_walk(grid: &ViewGrid, steps: usize) -> Vec<(Vec3, Vec3)> {
    walk(grid, WalkKind::Straight, steps)
}

/// The three recorded walks of thesis §5.8.5, all on the first avenue (see [`avenue_walk`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WalkKind {
    /// End to end, looking ahead (+x).
    Straight,
    /// End to end, the gaze swinging left and right by up to 70° (a period of 20 steps).
    Turning,
    /// Forward over the first 40 % of the avenue, back, and forward again, looking where it
    /// goes: every cell is seen again after the walker turned.
    BackAndForth,
}

impl WalkKind {
    /// Every recorded walk.
    pub const ALL: [WalkKind; 3] = [WalkKind::Straight, WalkKind::Turning, WalkKind::BackAndForth];

    /// The walk's name, as `--walk` takes it.
    pub fn name(self) -> &'static str {
        match self {
            WalkKind::Straight => "straight",
            WalkKind::Turning => "turning",
            WalkKind::BackAndForth => "back-and-forth",
        }
    }
}

hdov_storage::named!(WalkKind, "walk");
hdov_storage::by_names!(WalkKind);

/// `steps` (position, look direction) pairs of walk `kind` in `grid`'s region.
pub fn walk(grid: &ViewGrid, kind: WalkKind, steps: usize) -> Vec<(Vec3, Vec3)> {
    let r = grid.region;
    let (x0, x1) = (r.min.x + 5.0, (r.max.x - 5.0).max(r.min.x + 5.0));
    let y = (r.min.y + 0.2).min(r.max.y);
    let z = (r.min.z + 8.0).min(r.max.z);
    (0..steps)
        .map(|i| {
            let t = if steps > 1 { i as f32 / (steps - 1) as f32 } else { 0.0 };
            match kind {
                WalkKind::Straight => (Vec3::new(x0 + (x1 - x0) * t, y, z), Vec3::X),
                WalkKind::Turning => {
                    let yaw = 70f32.to_radians() * (i as f32 * std::f32::consts::TAU / 20.0).sin();
                    (Vec3::new(x0 + (x1 - x0) * t, y, z), Vec3::new(yaw.cos(), 0.0, yaw.sin()))
                }
                WalkKind::BackAndForth => {
                    // Three legs: 0 → 0.4, 0.4 → 0, 0 → 0.4 of the avenue.
                    let leg = (t * 3.0).min(2.999);
                    let (u, forward) = match leg as u32 {
                        0 => (leg, true),
                        1 => (2.0 - leg, false),
                        _ => (leg - 2.0, true),
                    };
                    let x = x0 + (x1 - x0) * 0.4 * u;
                    (Vec3::new(x, y, z), if forward { Vec3::X } else { Vec3::NEG_X })
                }
            }
        })
        .collect()
}

/// The viewing-cell grid: the whole footprint (streets included) at [`EYE_HEIGHT`], one layer,
/// with square-ish cells sized so the scale's own block count gives about
/// [`CityScale::target_cells`] cells (tens of metres: a few street widths).
fn view_grid(extent: Vec2, scale: CityScale) -> ViewGrid {
    let own = scale.blocks();
    // The scale's cell size, from its nominal footprint (mean block 90 m plus a 14 m street).
    let nominal_area = (own[0] * own[1]) as f32 * 104.0 * 104.0;
    let cell = (nominal_area / scale.target_cells()).sqrt();
    let dims = [((extent.x / cell).round() as u32).max(1), 1, ((extent.y / cell).round() as u32).max(1)];
    let region = Aabb::new(Vec3::new(0.0, EYE_HEIGHT[0], 0.0), Vec3::new(extent.x, EYE_HEIGHT[1], extent.y));
    ViewGrid::new(region, dims)
}
