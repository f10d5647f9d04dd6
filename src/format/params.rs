//! How a database is built: typed parameters, their documented bounds, and the one check that
//! runs before any work. Plain data: the stages that use them (`dov`, `lod`, `rtree`) add their
//! behaviour where they live, so the format names no algorithm.
//!
//! The parameters are recorded in `manifest.json` (names as strings there, typed here). Errors
//! name the parameter (`page_size`, `resolution`, ...); a user interface maps it to its own word
//! for it (the `hdov` command to its flags).

use serde::{Deserialize, Serialize};

use super::by_name::serde_by_name;

use crate::error::{Error, Param, Result};
use crate::grid::ViewGrid;
use crate::rtree::TreeAlgorithm;
pub use super::sampling::{AdaptiveSampling, RayProbing, SamplerSpec, Sampling};
use hdov_storage::{DovCodec, LayoutKind};

pub use super::limits;

/// The fan-out a build uses unless told otherwise, chosen by measurement (docs/query.md): on
/// the default city it keeps the pages a threshold query reads below the naive method's for
/// every η ≥ 1e-4 (M = 4 does not) while returning 14–26 % fewer faces than a full 4 KiB page's
/// 126 entries at η = 1e-3 … 8e-3.
pub const DEFAULT_FANOUT: u32 = 16;

/// Which backend to measure with (the CLI's `--backend auto|gpu|cpu`). `Auto` takes the GPU
/// backend on graphics hardware and the CPU ray caster otherwise: on Mesa's CPU rasterisers the
/// ray caster measures a city several times faster (docs/dov.md, speed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BackendKind {
    /// The GPU backend on a hardware adapter, else the CPU backend.
    #[default]
    Auto,
    /// The wgpu backend (fails without an adapter).
    Gpu,
    /// The CPU ray caster (obvhs), everywhere.
    Cpu,
}

impl BackendKind {
    /// Every choice.
    pub const ALL: [BackendKind; 3] = [BackendKind::Auto, BackendKind::Gpu, BackendKind::Cpu];

    /// The name `--backend` takes.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Auto => "auto",
            BackendKind::Gpu => "gpu",
            BackendKind::Cpu => "cpu",
        }
    }
}

hdov_storage::named!(BackendKind, "backend");
serde_by_name!(BackendKind);

impl std::fmt::Display for BackendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        hdov_storage::names::write_name(*self, f)
    }
}

impl std::str::FromStr for BackendKind {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        hdov_storage::names::parse_name(s).map_err(|r| Error::bad_param(Param::Backend, r))
    }
}

/// Part `index` of `count` of a grid's cells: a contiguous range of lattice cells holding about
/// `1/count` of the view cells ([`Shard::cells`]), with the further view cells of those lattice
/// cells ([`Shard::parts`]). Contiguous ranges keep most corners inside one shard.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(into = "[u32; 2]", try_from = "[u32; 2]")]
pub struct Shard {
    /// This part, 0-based.
    pub index: u32,
    /// Parts the grid is cut into.
    pub count: u32,
}

impl Shard {
    /// The whole grid.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Part `index` of `count`; refused unless 0 ≤ index < count.
    pub fn new(index: u32, count: u32) -> std::result::Result<Shard, String> {
        if count == 0 || index >= count {
            return Err(format!("{index}/{count}: need 0 ≤ I < N"));
        }
        Ok(Shard { index, count })
    }

    /// The lattice cell ids of this shard: a range holding its share of the lattice's view cells
    /// (the shards' ranges tile the lattice, so that a merge appends them in order).
    pub fn cells(&self, grid: &ViewGrid) -> std::ops::Range<usize> {
        let lattice = grid.lattice_count();
        let n = grid.present.as_ref().map_or(lattice, crate::grid::CellSet::len) as u64;
        // Where shard k starts: at its first view cell, the first shard at 0, past the last at
        // the lattice's end.
        let start = |k: u32| -> usize {
            let p = n * u64::from(k) / u64::from(self.count);
            match k {
                0 => 0,
                _ if p >= n => lattice,
                _ => grid.present_ids().nth(p as usize).expect("p < the lattice's view cells"),
            }
        };
        let end = if self.index + 1 == self.count { lattice } else { start(self.index + 1) };
        start(self.index)..end
    }

    /// The ids of the further view cells ([`ViewGrid::parts`]) of this shard's lattice cells: a
    /// range after the lattice. Parts are in their lattice cells' order, so these ranges tile
    /// the parts in shard order, and a lattice cell's view cells are measured by one shard.
    pub fn parts(&self, grid: &ViewGrid) -> std::ops::Range<usize> {
        let (lattice, cells) = (grid.lattice_count(), self.cells(grid));
        let at = |id: usize| lattice + grid.parts.partition_point(|p| (p.cell as usize) < id);
        at(cells.start)..at(cells.end)
    }
}

impl From<Shard> for [u32; 2] {
    fn from(s: Shard) -> [u32; 2] {
        [s.index, s.count]
    }
}

impl TryFrom<[u32; 2]> for Shard {
    type Error = String;
    fn try_from([index, count]: [u32; 2]) -> std::result::Result<Shard, String> {
        Shard::new(index, count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// `I/N` (0 ≤ I < N), as `--shard` takes it.
    fn from_str(s: &str) -> std::result::Result<Shard, String> {
        let (i, n) = s.split_once('/').ok_or_else(|| format!("'{s}': expected I/N"))?;
        let index: u32 = i.trim().parse().map_err(|_| format!("'{s}': I is not a number"))?;
        let count: u32 = n.trim().parse().map_err(|_| format!("'{s}': N is not a number"))?;
        Shard::new(index, count)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A test that marks an object *possibly visible* from a cell although none of the cell's sample
/// points sees it; such objects get the one-texel floor DoV.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FloorTest {
    /// The object's box lies within this distance of the cell's box (near objects: the corners
    /// can all be cut off from an object right next to the cell).
    BoxWithin(f32),
    /// Some corner of a neighbouring cell (the 4 × 4 × 4 block of corners around the cell,
    /// clipped to the grid) sees the object: views change continuously, so an object that a
    /// point just outside the cell sees is often seen from inside. Free in measurements: the
    /// neighbours' corners are measured for their own cells anyway (a shard measures one extra
    /// layer of corners around its cells).
    NeighbourCorners,
    /// A part that hdov cut (`--objects geometry`) whose neighbouring part of the same file
    /// object the cell's own points see, or, with [`FloorTest::NeighbourCorners`], what that test
    /// counts as seen nearby, and which turns a face to the cell (some point of the cell's box
    /// in front of one of its faces' planes, [`crate::scene::parts::turns_a_face_to`]): a cut
    /// surface seen up to a part's edge goes on past it (a strip of ground or a wall seen at a
    /// grazing angle through a gap), where rays aimed at the part's surface rarely land on its
    /// visible sliver; a part turned away (a wall's face to the next room, a floor's underside)
    /// shows the cell only its back, and only through a gap the samplers measure (decision
    /// 137). Free; finds nothing in a scene whose objects were not cut.
    PartNeighbours,
}

impl FloorTest {
    /// The names a build takes: `box` (the object's box meets the cell's), `neighbours` and
    /// `parts`.
    pub const NAMES: &'static str = "box, box:MARGIN, neighbours, parts";

    /// A build's floors unless it names its own: box, neighbours and parts.
    pub const DEFAULT: [FloorTest; 3] = [FloorTest::BoxWithin(0.0), FloorTest::NeighbourCorners, FloorTest::PartNeighbours];

    /// The floors a build with `sampling`, `objects` and view cells `cells` takes unless it
    /// names its own (`hdov build`): the box alone for ray probing without region rays (its
    /// rays check what the neighbours test would guess); box and parts for objects cut into
    /// parts on cells made where viewers stand ([`ViewGrid::where_viewers_stand`]: rooms,
    /// storeys and levels, whose neighbouring corners see into other rooms and along other
    /// corridors: the neighbours test made answers 1.3–1.6× larger on four game levels and 6.7×
    /// on a house, for misses that the parts test keeps within issue 31's bounds; decision
    /// 127); otherwise, and while the cells are not yet known (`None`), [`FloorTest::DEFAULT`]
    /// (open grids, where the neighbours test keeps street scenes' misses 15× lower, and the
    /// file's objects, which the parts test cannot reach).
    pub fn default_for(sampling: &Sampling, objects: ObjectParts, cells: Option<&ViewGrid>) -> Vec<FloorTest> {
        let rooms = objects == ObjectParts::Geometry && cells.is_some_and(ViewGrid::where_viewers_stand);
        match sampling {
            Sampling::Probe(p) if p.region == 0 => vec![FloorTest::BoxWithin(0.0)],
            _ if rooms => vec![FloorTest::BoxWithin(0.0), FloorTest::PartNeighbours],
            _ => FloorTest::DEFAULT.to_vec(),
        }
    }

    /// The tests `names` name (`--zero-dov-floor`, [`FloorTest::parse_list`]), or
    /// [`FloorTest::default_for`] the rest where it names none.
    pub fn chosen(
        names: &[String],
        sampling: &Sampling,
        objects: ObjectParts,
        cells: Option<&ViewGrid>,
    ) -> std::result::Result<Vec<FloorTest>, String> {
        if names.is_empty() {
            return Ok(FloorTest::default_for(sampling, objects, cells));
        }
        FloorTest::parse_list(names.iter().map(String::as_str))
    }

    /// The tests `names` name, as `--zero-dov-floor` lists them; `none` names no test.
    pub fn parse_list<'a>(names: impl IntoIterator<Item = &'a str>) -> std::result::Result<Vec<FloorTest>, String> {
        names.into_iter().filter(|n| *n != "none").map(str::parse).collect()
    }
}

impl std::fmt::Display for FloorTest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            FloorTest::BoxWithin(0.0) => f.write_str("box"),
            FloorTest::BoxWithin(m) => write!(f, "box:{m}"),
            FloorTest::NeighbourCorners => f.write_str("neighbours"),
            FloorTest::PartNeighbours => f.write_str("parts"),
        }
    }
}

impl std::str::FromStr for FloorTest {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<FloorTest, String> {
        let margin = |m: &str| m.parse::<f32>().ok().filter(|m| m.is_finite() && *m >= 0.0);
        match s.split_once(':') {
            None if s == "box" => Ok(FloorTest::BoxWithin(0.0)),
            None if s == "neighbours" => Ok(FloorTest::NeighbourCorners),
            None if s == "parts" => Ok(FloorTest::PartNeighbours),
            Some(("box", m)) => margin(m)
                .map(FloorTest::BoxWithin)
                .ok_or_else(|| format!("'{s}': the margin must be a finite length >= 0")),
            _ => Err(format!("unknown test '{s}' (expected {})", FloorTest::NAMES)),
        }
    }
}

/// How LOD chains are simplified.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LodParams {
    /// Leaf chains: target faces of a level / faces of the level before.
    pub ratio: f32,
    /// A chain stops once a level has at most this many faces.
    pub min_faces: usize,
    /// How internal (tree node) LODs are built.
    #[serde(with = "super::by_name::one")]
    pub internal: InternalLods,
}

impl Default for LodParams {
    fn default() -> Self {
        Self { ratio: 0.5, min_faces: 32, internal: InternalLods::Hlod }
    }
}

/// How a tree node's internal LOD chain is built (docs/query.md, "Internal LODs").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InternalLods {
    /// Levels by geometric error (HLOD): level k of every node is its children's levels at error
    /// ≤ e_k/2 merged and simplified to error ≤ e_k/2, e_k doubling per level, kept where it cuts
    /// faces by a quarter; the recorded error is the simplifier's plus the worst part's, so a
    /// parent's error is never below its children's. Internal bytes are bounded by the leaf
    /// LODs' (`hlod`).
    #[default]
    Hlod,
    /// The thesis's §5.6: the children's coarsest levels merged and simplified by a face ratio,
    /// so a parent's finest level has fewer faces than its children's coarsest (`thesis`).
    Thesis,
}

impl InternalLods {
    /// Both ways.
    pub const ALL: [InternalLods; 2] = [InternalLods::Hlod, InternalLods::Thesis];

    /// The name `--internal-lods` takes.
    pub fn name(self) -> &'static str {
        match self {
            InternalLods::Hlod => "hlod",
            InternalLods::Thesis => "thesis",
        }
    }
}

hdov_storage::named!(InternalLods, "internal LODs");
hdov_storage::by_names!(InternalLods);

/// Largest [`VisibilityParams::region_views`]: a region view of 16² texels a face already holds
/// 1,536 rays from one origin, where region sampling needs many origins.
pub const MAX_REGION_VIEW_RESOLUTION: u32 = 16;

/// Default of [`VisibilityParams::lod_draw_tolerance`] (the GPU backend's LOD-aware drawing): a twentieth of a texel at the face centre.
/// Half a texel (the first guess) changes some objects' DoV by up to 10 centre texels on a
/// generated city, because the simplifier's error is not a bound on silhouette movement and a
/// shifted silhouette changes an area in proportion to its length; 0.05 keeps every object within
/// the backends' agreement tolerance (0.5 % of its DoV + 2 centre texels) at R = 128 and 256
/// (docs/dov.md, "LOD-aware drawing").
pub const DEFAULT_LOD_TOLERANCE_TEXELS: f32 = 0.05;

/// The default [`VisibilityParams::slot_budget`]: 512 MiB. The horizontal layout of a level of
/// 8,445 parts in 29,594 view cells would take 14.5 GB of slots, where indexed-vertical holds
/// the same V-pages in 0.75 GB; the large city's 0.3 GB stays in (decision 134).
pub const DEFAULT_SLOT_BUDGET: u64 = 512 << 20;

/// Where a database's objects come from (`--objects`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjectParts {
    /// The file's objects as they are (one per OBJ group or glTF node instance).
    File,
    /// The file's objects, each one far larger than a cell cut into parts of about two cells
    /// (`scene::parts`): what an exporter groups by material or storey spans the scene. The
    /// default (decision 124).
    Geometry,
}

impl ObjectParts {
    /// Both sources.
    pub const ALL: [ObjectParts; 2] = [ObjectParts::Geometry, ObjectParts::File];

    /// The name `--objects` takes.
    pub fn name(self) -> &'static str {
        match self {
            ObjectParts::File => "file",
            ObjectParts::Geometry => "geometry",
        }
    }

    /// Manifests without the field were built before objects were cut.
    fn unrecorded() -> Self {
        ObjectParts::File
    }
}

hdov_storage::named!(ObjectParts, "object source");
hdov_storage::by_names!(ObjectParts);
serde_by_name!(ObjectParts);

/// How a database was built.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildParams {
    /// Where the objects come from.
    #[serde(default = "ObjectParts::unrecorded")]
    pub objects: ObjectParts,
    /// Bytes per page of the tree file and of the V-page layouts.
    pub page_size: u32,
    /// Most entries per tree node (M); `None`: [`DEFAULT_FANOUT`], or what a page holds if
    /// fewer. A smaller M makes a deeper tree whose nodes cover less of the scene, so the DoV
    /// threshold can stop early; a larger one reads fewer pages (docs/query.md, fan-out table).
    #[serde(default)]
    pub fanout: Option<u32>,
    /// Which algorithm builds the R-tree.
    pub tree: TreeAlgorithm,
    /// How leaf LOD chains are simplified.
    pub lod: LodParams,
    /// `None` builds tree and LODs only.
    pub visibility: Option<VisibilityParams>,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            // Objects far larger than a cell are cut (decision 124); the file's objects are kept
            // where they are already small.
            objects: ObjectParts::Geometry,
            page_size: 4096,
            fanout: None,
            tree: TreeAlgorithm::Str,
            lod: LodParams::default(),
            visibility: Some(VisibilityParams::default()),
        }
    }
}


/// How DoV is measured and stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibilityParams {
    /// Texels per cube-face edge (R).
    pub resolution: u32,
    /// Which backend measures the DoV.
    pub backend: BackendKind,
    /// Where each cell is sampled besides its 8 shared corners (the manifest's `sampling`, by
    /// name).
    #[serde(flatten, with = "super::sampling::record")]
    pub sampling: Sampling,
    /// Layouts to write.
    #[serde(with = "super::by_name::list")]
    pub layouts: Vec<LayoutKind>,
    /// How V-entries store DoV.
    #[serde(with = "super::by_name::one")]
    pub dov_codec: DovCodec,
    /// This database holds part I of N of the grid's cells (`[I, N]` in the manifest).
    pub shard: Option<Shard>,
    /// Visible-zero-DoV tests (thesis §5.5.2) that give unseen objects the one-texel floor.
    /// Empty: no floor.
    #[serde(default, with = "super::by_name::list")]
    pub zero_dov_floor: Vec<FloorTest>,
    /// GPU backend: texels of LOD error below which an object is drawn coarser (0 = off).
    #[serde(default)]
    pub lod_draw_tolerance: f32,
    /// GPU backend: draw the region rays as small turned cube maps of this many texels a face
    /// edge, one from each of as many origins as that takes ([`crate::dov::sampling::RegionViews`]),
    /// instead of casting them on the CPU; 0 = cast them (the reference).
    #[serde(default)]
    pub region_views: u32,
    /// Leave the horizontal and vertical layouts out where their slots for every (node, cell),
    /// seen or not ([`hdov_storage::VShape::slot_bytes`]), would take more than this many bytes; `None` writes
    /// every layout asked for. Applies only where indexed-vertical, which has no such slots and
    /// is what queries read by default, is asked for too (decision 134).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slot_budget: Option<u64>,
}

impl Default for VisibilityParams {
    fn default() -> Self {
        Self {
            resolution: 128,
            backend: BackendKind::Auto,
            sampling: Sampling::default(),
            layouts: LayoutKind::ALL.to_vec(),
            dov_codec: DovCodec::F32,
            shard: None,
            zero_dov_floor: FloorTest::DEFAULT.to_vec(),
            lod_draw_tolerance: DEFAULT_LOD_TOLERANCE_TEXELS,
            region_views: 0,
            slot_budget: Some(DEFAULT_SLOT_BUDGET),
        }
    }
}

impl VisibilityParams {
    /// The layouts a build with these parameters writes: those asked for, but a shard writes
    /// indexed-vertical alone, the one layout that stores nothing for cells it did not compute
    /// (horizontal keeps a slot per cell and node: the large city's shards were 347 MB each,
    /// nearly all zeros); the merge writes the layouts asked for.
    pub fn stored_layouts(&self) -> Vec<hdov_storage::LayoutKind> {
        match self.shard {
            Some(_) => vec![hdov_storage::LayoutKind::IndexedVertical],
            None => self.layouts.clone(),
        }
    }

    /// Whether the build draws objects at their leaf LODs (the GPU backend with a tolerance), and
    /// so needs the leaf chains in memory for the visibility stage.
    pub fn draws_lods(&self) -> bool {
        self.backend != BackendKind::Cpu && self.lod_draw_tolerance > 0.0
    }

    /// The shard this build computes ([`Shard::ALL`] without one).
    pub fn shard(&self) -> Shard {
        self.shard.unwrap_or(Shard::ALL)
    }
}

impl BuildParams {
    /// These parameters less visibility: what a shard and its base build must share.
    pub fn without_visibility(&self) -> BuildParams {
        BuildParams { visibility: None, ..self.clone() }
    }

    /// Most entries per node: `fanout`, else [`DEFAULT_FANOUT`], at most what a page holds.
    pub fn max_entries(&self) -> usize {
        let page = crate::format::tree_page::fanout(self.page_size);
        (self.fanout.unwrap_or(DEFAULT_FANOUT) as usize).min(page)
    }

    /// Checks every parameter against its bounds, and the grid (if any) against the cell and
    /// sample-point limits. Costs nothing; [`crate::build()`] calls it before any work.
    pub fn check(&self, grid: Option<&ViewGrid>) -> Result<()> {
        use limits::*;
        let fanout = crate::format::tree_page::fanout(self.page_size);
        if !(MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&self.page_size) || fanout < 2 {
            return Err(Error::bad_param(
                Param::PageSize,
                format!("{} bytes is outside {MIN_PAGE_SIZE}..={MAX_PAGE_SIZE}", self.page_size),
            ));
        }
        if let Some(m) = self.fanout
            && !(2..=fanout as u32).contains(&m)
        {
            return Err(Error::bad_param(
                Param::Fanout,
                format!("{m} entries is outside 2..={fanout}, what a {}-byte page holds", self.page_size),
            ));
        }
        let lod = &self.lod;
        if !(lod.ratio > 0.0 && lod.ratio < 1.0) {
            return Err(Error::bad_param(Param::LodRatio, format!("{} is not in (0, 1)", lod.ratio)));
        }
        let Some(v) = &self.visibility else { return Ok(()) };
        if !(1..=MAX_RESOLUTION).contains(&v.resolution) {
            return Err(Error::bad_param(Param::Resolution, format!("{} is outside 1..={MAX_RESOLUTION}", v.resolution)));
        }
        v.sampling.check()?;
        if v.layouts.is_empty() {
            return Err(Error::bad_param(Param::Layouts, "names no layout"));
        }
        if let Some(k) = v.layouts.iter().enumerate().find_map(|(i, k)| v.layouts[..i].contains(k).then_some(k)) {
            return Err(Error::bad_param(Param::Layouts, format!("names {k} twice")));
        }
        if !(0.0..=MAX_LOD_DRAW_TOLERANCE).contains(&v.lod_draw_tolerance) {
            return Err(Error::bad_param(
                Param::LodDrawTolerance,
                format!("{} texels is outside 0..={MAX_LOD_DRAW_TOLERANCE}", v.lod_draw_tolerance),
            ));
        }
        if v.region_views > MAX_REGION_VIEW_RESOLUTION {
            return Err(Error::bad_param(
                Param::RegionViews,
                format!("{} texels is outside 0..={MAX_REGION_VIEW_RESOLUTION}", v.region_views),
            ));
        }
        if v.region_views > 0 && v.backend == BackendKind::Cpu {
            return Err(Error::bad_param(
                Param::RegionViews,
                "draws region views on the GPU backend; the cpu backend casts region rays",
            ));
        }
        if let Some(FloorTest::BoxWithin(m)) =
            v.zero_dov_floor.iter().find(|t| matches!(t, FloorTest::BoxWithin(m) if !(m.is_finite() && *m >= 0.0)))
        {
            return Err(Error::bad_param(Param::ZeroDovFloor, format!("box margin {m} must be a finite length >= 0")));
        }
        // The grid first: its cell count is only meaningful (and only fits a word) once checked.
        if let Some(g) = grid {
            // The adaptive budget is the most a cell can take.
            check_grid(g, v.sampling.max_points_per_cell())?;
        }
        if let Some(s) = v.shard {
            Shard::new(s.index, s.count).map_err(|r| Error::bad_param(Param::Shard, r))?;
            let cells = grid.map_or(MAX_CELLS, |g| g.cell_count() as u64);
            if u64::from(s.count) > cells {
                return Err(Error::bad_param(Param::Shard, format!("{s}: more shards than the {cells} cells")));
            }
        }
        Ok(())
    }
}

/// Checks a grid against [`limits::MAX_CELLS`] and, with `interior_samples` per cell,
/// [`limits::MAX_SAMPLE_POINTS`], in integers that cannot overflow.
pub fn check_grid(grid: &ViewGrid, interior_samples: u32) -> Result<()> {
    use limits::*;
    grid.check().map_err(|r| Error::bad_param(Param::Grid, r))?;
    let [nx, ny, nz] = grid.dims.map(u64::from);
    // Three u32 counts multiply to 96 bits at most.
    let cells = u128::from(nx) * u128::from(ny) * u128::from(nz);
    if cells > u128::from(MAX_CELLS) {
        return Err(Error::bad_param(
            Param::Grid,
            format!("{nx}x{ny}x{nz} is more than {MAX_CELLS} cells; use fewer or larger cells"),
        ));
    }
    // Below MAX_CELLS, corners are at most 8 per cell and the sum fits in u64.
    let points = (nx + 1) * (ny + 1) * (nz + 1) + cells as u64 * u64::from(interior_samples);
    if points > MAX_SAMPLE_POINTS {
        return Err(Error::bad_param(
            Param::InteriorSamples,
            format!(
                "{nx}x{ny}x{nz} cells with {interior_samples} interior points each is {points} sample points, more than {MAX_SAMPLE_POINTS}"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Aabb;
    use glam::Vec3;

    #[test]
    fn manifest_names_round_trip() {
        let with = |sampling| BuildParams {
            visibility: Some(VisibilityParams {
                shard: Some(Shard::new(1, 3).unwrap()),
                zero_dov_floor: vec![FloorTest::BoxWithin(2.5), FloorTest::NeighbourCorners],
                dov_codec: DovCodec::LogU16,
                sampling,
                ..Default::default()
            }),
            ..Default::default()
        };
        let p = with(Sampling::Adaptive(AdaptiveSampling { seeds: 3, budget: 24 }));
        let json = serde_json::to_value(&p).unwrap();
        let v = &json["visibility"];
        assert_eq!(v["layouts"], serde_json::json!(["horizontal", "vertical", "indexed-vertical"]));
        assert_eq!(v["zero_dov_floor"], serde_json::json!(["box:2.5", "neighbours"]));
        assert_eq!(v["shard"], serde_json::json!([1, 3]));
        assert_eq!(v["dov_codec"], "log-u16");
        assert_eq!(v["sampling"], "adaptive:3:24");
        assert!(v.get("interior_samples").is_none() && v.get("adaptive").is_none());
        assert_eq!(serde_json::from_value::<BuildParams>(json).unwrap(), p);
        for (sampling, name) in [
            (Sampling::Probe(RayProbing { points: 16, rays: 2, region: 0, nearest: 16 }), "probe:16:2"),
            (Sampling::Probe(RayProbing { points: 32, rays: 4, region: 32768, nearest: 32 }), "probe:32:4:32768"),
            (Sampling::Probe(RayProbing { points: 32, rays: 4, region: 24576, nearest: 8 }), "probe:32:4:24576:8"),
            (Sampling::Probe(RayProbing { points: 32, rays: 4, region: 0, nearest: 4 }), "probe:32:4:0:4"),
            (Sampling::Interior(5), "5"),
            (Sampling::CORNERS, "corners"),
        ] {
            let p = with(sampling);
            let json = serde_json::to_value(&p).unwrap();
            assert_eq!(json["visibility"]["sampling"], name);
            assert_eq!(serde_json::from_value::<BuildParams>(json).unwrap(), p);
        }
    }

    #[test]
    fn a_manifest_naming_two_samplers_is_refused() {
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["probe"] = serde_json::json!("probe:8:2");
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("more than one sampler"));
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["interior_samples"] = serde_json::json!(4);
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("more than one sampler"));
    }

    #[test]
    fn sampling_names_round_trip() {
        for s in ["corners", "7", "adaptive:2:16", "probe:32:4", "probe:32:4:32768", "probe:32:4:24576:8"] {
            assert_eq!(s.parse::<Sampling>().unwrap().to_string(), s);
        }
        assert_eq!("adaptive".parse::<Sampling>().unwrap(), Sampling::Adaptive(AdaptiveSampling::DEFAULT));
        assert_eq!("probe:32:4:0".parse::<Sampling>().unwrap().to_string(), "probe:32:4");
        assert_eq!("region".parse::<Sampling>().unwrap().to_string(), "probe:32:4:24576");
        // Every point searching is the default, not written.
        assert_eq!("probe:32:4:24576:32".parse::<Sampling>().unwrap().to_string(), "probe:32:4:24576");
        let unknown = "halton".parse::<Sampling>().unwrap_err();
        assert!(unknown.contains("adaptive[:SEEDS:BUDGET]") && unknown.contains("region"), "{unknown}");
        for bad in
            ["probe:32:4:many", "probe:32:4:-1", "probe:32:4:16777217", "probe:32:4:5:33", "probe:32:4:5:0", "probe:32:4:5:6:7", "probe:32"]
        {
            assert!(bad.parse::<Sampling>().is_err(), "{bad}");
        }
    }

    #[test]
    fn manifests_written_before_the_sampling_field_still_read() {
        // Up to decision 101 the manifest named the sampler in up to three fields:
        // `interior_samples` always, `adaptive` and `probe` when chosen.
        let earlier = |fields: serde_json::Value| {
            let mut json = serde_json::to_value(BuildParams::default()).unwrap();
            let v = json["visibility"].as_object_mut().unwrap();
            v.remove("sampling");
            v.extend(fields.as_object().unwrap().clone());
            serde_json::from_value::<BuildParams>(json).map(|p| p.visibility.unwrap().sampling)
        };
        assert_eq!(earlier(serde_json::json!({ "interior_samples": 0 })).unwrap(), Sampling::CORNERS);
        assert_eq!(earlier(serde_json::json!({ "interior_samples": 5 })).unwrap(), Sampling::Interior(5));
        assert_eq!(
            earlier(serde_json::json!({ "interior_samples": 0, "adaptive": "adaptive:3:24" })).unwrap(),
            Sampling::Adaptive(AdaptiveSampling { seeds: 3, budget: 24 })
        );
        assert_eq!(
            earlier(serde_json::json!({ "interior_samples": 0, "probe": "probe:32:4:24576" })).unwrap(),
            Sampling::Probe(RayProbing::REGION)
        );
        assert!(earlier(serde_json::json!({ "interior_samples": 0, "adaptive": "adaptive:0:3" })).unwrap_err().to_string().contains("SEEDS"));
        assert!(earlier(serde_json::json!({ "interior_samples": 0, "probe": "probe:0:3" })).unwrap_err().to_string().contains("POINTS"));
        // The default (region rays) is written by name.
        let json = serde_json::to_value(BuildParams::default()).unwrap();
        assert_eq!(json["visibility"]["sampling"], "probe:32:4:24576");
    }

    #[test]
    fn bad_shard_in_a_manifest_is_refused() {
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["shard"] = serde_json::json!([3, 3]);
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("0 ≤ I < N"));
    }

    #[test]
    fn a_huge_grid_with_a_shard_is_refused_before_its_cells_are_counted() {
        // 2^21 · 2^21 · 2^22 cells wraps to 0 in 64 bits: the grid must be refused as too big, not
        // the shard as "more shards than the 0 cells".
        let grid = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::ONE), [1 << 21, 1 << 21, 1 << 22]);
        assert_eq!(grid.cell_count(), usize::MAX);
        let p = BuildParams {
            visibility: Some(VisibilityParams { shard: Some(Shard::new(0, 2).unwrap()), ..Default::default() }),
            ..Default::default()
        };
        let err = p.check(Some(&grid)).unwrap_err().to_string();
        assert!(err.starts_with("grid:") && err.contains("more than"), "{err}");
    }

    #[test]
    fn default_floors_follow_the_sampler_and_the_cells() {
        let (b, n, p) = (FloorTest::BoxWithin(0.0), FloorTest::NeighbourCorners, FloorTest::PartNeighbours);
        let mut rooms = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::ONE), [2, 1, 2]);
        rooms.places = Some(vec![crate::grid::ALL_PLACES; 4]);
        let grid = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::ONE), [2, 1, 2]);
        let (parts, file) = (ObjectParts::Geometry, ObjectParts::File);
        let region = Sampling::default();
        assert_eq!(FloorTest::default_for(&region, parts, Some(&grid)), [b, n, p]);
        assert_eq!(FloorTest::default_for(&region, parts, Some(&rooms)), [b, p]);
        assert_eq!(FloorTest::default_for(&region, parts, None), [b, n, p]);
        assert_eq!(FloorTest::default_for(&region, file, Some(&rooms)), [b, n, p]);
        assert_eq!(FloorTest::default_for(&Sampling::CORNERS, parts, Some(&rooms)), [b, p]);
        let no_region = Sampling::Probe(RayProbing { region: 0, ..RayProbing::DEFAULT });
        for cells in [&grid, &rooms] {
            assert_eq!(FloorTest::default_for(&no_region, parts, Some(cells)), [b]);
        }
        let named = FloorTest::chosen(&["box".into(), "neighbours".into()], &region, parts, Some(&rooms));
        assert_eq!(named.unwrap(), [b, n]);
        assert_eq!(FloorTest::chosen(&["none".into()], &region, parts, None).unwrap(), []);
        assert!(FloorTest::chosen(&["walls".into()], &region, parts, None).is_err());
    }

    #[test]
    fn bounds_name_the_parameter() {
        let grid = |dims| ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::ONE), dims);
        let with = |f: fn(&mut VisibilityParams)| {
            let mut p = BuildParams::default();
            f(p.visibility.as_mut().unwrap());
            p.check(Some(&grid([4, 1, 4]))).unwrap_err().to_string()
        };
        assert!(with(|v| v.resolution = 0).starts_with("resolution:"));
        assert!(with(|v| v.resolution = 100_000).starts_with("resolution:"));
        assert!(with(|v| v.sampling = Sampling::Interior(5000)).starts_with("interior_samples:"));
        assert!(with(|v| v.layouts.clear()).starts_with("layouts:"));
        assert!(with(|v| v.sampling = Sampling::Adaptive(AdaptiveSampling { seeds: 0, budget: 4 })).starts_with("interior_samples:"));
        assert!(
            with(|v| v.sampling = Sampling::Adaptive(AdaptiveSampling { seeds: 2, budget: 5000 })).starts_with("interior_samples:")
        );
        assert!(with(|v| v.layouts.push(LayoutKind::Vertical)).contains("twice"));
        assert!(with(|v| v.lod_draw_tolerance = f32::NAN).starts_with("lod_draw_tolerance:"));
        assert!(with(|v| v.region_views = 17).starts_with("region_views:"));
        let cpu_views = with(|v| (v.backend, v.region_views) = (BackendKind::Cpu, 2));
        assert!(cpu_views.starts_with("region_views:") && cpu_views.contains("cpu backend"), "{cpu_views}");
        let page = BuildParams { page_size: 64, ..Default::default() };
        assert!(page.check(None).unwrap_err().to_string().starts_with("page_size:"));
        let p = BuildParams::default();
        assert!(p.check(Some(&grid([4, 1, 4]))).is_ok());
        // Billions of cells, and a product that would overflow 32 bits, are refused.
        assert!(p.check(Some(&grid([100_000, 1, 100_000]))).unwrap_err().to_string().starts_with("grid:"));
        assert!(p.check(Some(&grid([u32::MAX, u32::MAX, u32::MAX]))).unwrap_err().to_string().starts_with("grid:"));
        let many = BuildParams {
            visibility: Some(VisibilityParams { sampling: Sampling::Interior(4096), ..Default::default() }),
            ..Default::default()
        };
        assert!(many.check(Some(&grid([200, 1, 200]))).unwrap_err().to_string().starts_with("interior_samples:"));
    }
}
