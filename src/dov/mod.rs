//! Degree of visibility (DoV): how much of the sphere of directions around a point each object
//! covers, measured by cubic projection (thesis §5.5.2; docs/dov.md, "The measurement").
//!
//! - [`cubemap`]: texel centres and solid-angle weights shared by both backends;
//! - [`DovBackend`]: renders an *id cube* (one object id per texel) around a point; two
//!   independent implementations, [`cpu::CpuBackend`] (ray casting over a BVH) and
//!   [`gpu::GpuBackend`] (wgpu rasterisation), which must agree;
//! - [`sampler`]: where a cell is measured besides its corners, one file per sampler (interior
//!   points, adaptive points where new objects appear, rays aimed at what a cell might see);
//! - [`rays`]: single rays through a scene, for the samplers that cast them;
//! - [`precompute`]: from-region DoV of objects and tree nodes for every cell of a view grid.

pub mod cpu;
pub mod cubemap;
pub mod gpu;
pub mod precompute;
pub mod rays;
pub mod sampler;
pub mod sampling;

use std::collections::HashMap;

use glam::Vec3;

pub use cpu::CpuBackend;
pub use cubemap::CubeMap;
pub use gpu::GpuBackend;

use crate::error::{Param, Result};
pub use crate::format::params::BackendKind;

/// Id of a texel that sees no object.
pub const NO_OBJECT: u32 = u32::MAX;
/// Set in a texel's id when the nearest surface there is seen from behind (the point is inside or
/// behind a closed mesh); the low bits are still the object id.
pub const BACK_FACE_BIT: u32 = 1 << 31;
/// Largest object index an id cube can carry (the top bit is [`BACK_FACE_BIT`]).
pub const MAX_OBJECT_ID: u32 = BACK_FACE_BIT - 2;

/// Refuses a scene with more objects than an id cube can name (both backends check it).
pub fn check_object_count(scene: &crate::scene::Scene) -> crate::error::Result<()> {
    if scene.objects.len() > MAX_OBJECT_ID as usize {
        return Err(crate::error::Error::bad_param(
            Param::Scene,
            format!("{} objects exceed the DoV id limit {MAX_OBJECT_ID}", scene.objects.len()),
        ));
    }
    Ok(())
}

/// The per-texel result of one cube-map rendering: 6·R² ids, face-major, then rows top to
/// bottom, then columns left to right (the layout of [`cubemap`]). Each id is an object index,
/// possibly with [`BACK_FACE_BIT`] set, or [`NO_OBJECT`].
#[derive(Clone, Debug, PartialEq)]
pub struct IdCube {
    /// Texels per cube-face edge (R).
    pub resolution: u32,
    /// 6·R² ids, face-major, then rows, then columns.
    pub ids: Vec<u32>,
}

impl IdCube {
    /// A cube of R×R×6 texels that see nothing.
    pub fn new(resolution: u32) -> Self {
        let r = resolution as usize;
        Self { resolution, ids: vec![NO_OBJECT; 6 * r * r] }
    }

    /// The object seen through texel `index` (without the back-face flag), if any.
    pub fn object_at(&self, index: usize) -> Option<u32> {
        match self.ids[index] {
            NO_OBJECT => None,
            id => Some(id & !BACK_FACE_BIT),
        }
    }

    /// Weighs every texel by its solid angle and sums per object (in f64, in texel order, so the
    /// result is deterministic). Only objects with at least one texel appear. Costs O(R²) plus
    /// one hash update per run of equal ids along a row.
    ///
    /// # Panics
    /// If `cube` has another resolution.
    pub fn dov(&self, cube: &CubeMap) -> PointDov {
        assert_eq!(cube.resolution(), self.resolution, "id cube and cube map resolutions differ");
        let weights = cube.face_weights();
        let mut sums: HashMap<u32, f64> = HashMap::new();
        let mut back_face = 0.0;
        let mut empty = 0.0;
        let r = self.resolution as usize;
        for face in self.ids.chunks_exact(r * r) {
            for (row_ids, row_w) in face.chunks_exact(r).zip(weights.chunks_exact(r)) {
                // Runs of one id are long in real views: sum a run, then touch the map once.
                let mut run_id = row_ids[0];
                let mut run_sum = 0.0;
                for (&id, &w) in row_ids.iter().zip(row_w) {
                    if id != run_id {
                        add_run(&mut sums, &mut back_face, &mut empty, run_id, run_sum);
                        run_id = id;
                        run_sum = 0.0;
                    }
                    run_sum += w;
                }
                add_run(&mut sums, &mut back_face, &mut empty, run_id, run_sum);
            }
        }
        let total = cube.total_weight();
        let mut objects: Vec<(u32, f64)> = sums.into_iter().map(|(id, s)| (id, s / total)).collect();
        objects.sort_unstable_by_key(|&(id, _)| id);
        PointDov { resolution: self.resolution, objects, back_face: back_face / total, empty: empty / total }
    }
}

fn add_run(sums: &mut HashMap<u32, f64>, back_face: &mut f64, empty: &mut f64, id: u32, sum: f64) {
    if id == NO_OBJECT {
        *empty += sum;
        return;
    }
    if id & BACK_FACE_BIT != 0 {
        *back_face += sum;
    }
    *sums.entry(id & !BACK_FACE_BIT).or_insert(0.0) += sum;
}

/// The DoV of every object seen from one point, as fractions of the sphere of directions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointDov {
    /// Texels per cube-face edge (R) of the measurement.
    pub resolution: u32,
    /// `(object index, DoV)`, sorted by object index, DoV > 0 only.
    pub objects: Vec<(u32, f64)>,
    /// Fraction of the sphere whose nearest surface is seen from behind. Near 0 for a point in
    /// open space among closed meshes; near 1 for a point inside a building.
    pub back_face: f64,
    /// Fraction of the sphere that sees no object (sky).
    pub empty: f64,
}

impl PointDov {
    /// The DoV of `object`, 0 when it is not seen. O(log n).
    pub fn get(&self, object: u32) -> f64 {
        self.objects.binary_search_by_key(&object, |&(id, _)| id).map_or(0.0, |i| self.objects[i].1)
    }

    /// Sum over all objects: the covered fraction of the sphere, ≤ 1 up to rounding.
    pub fn total(&self) -> f64 {
        self.objects.iter().map(|&(_, d)| d).sum()
    }
}

/// Up to `n` grid corners in open space (the backend sees no surface from behind there), spread
/// evenly over the grid's corners: street sample points for experiments. Measures about `12·n`
/// corners.
pub fn open_corners(grid: &crate::grid::ViewGrid, backend: &mut dyn DovBackend, n: usize) -> Result<Vec<Vec3>> {
    let corners = grid.corner_count();
    let step = (corners / (12 * n.max(1))).max(1);
    let mut points = Vec::new();
    for id in (0..corners).step_by(step) {
        let p = grid.corner_position(grid.corner_coords(id));
        if backend.measure(p)?.back_face == 0.0 {
            points.push(p);
        }
    }
    let keep = (points.len() / n.max(1)).max(1);
    Ok(points.into_iter().step_by(keep).take(n).collect())
}

/// A way of rendering the id cube around a point. The resolution is fixed at construction.
pub trait DovBackend {
    /// Human-readable name, with the adapter for the GPU backend.
    fn name(&self) -> String;

    /// Texels per face edge (R).
    fn resolution(&self) -> u32;

    /// The cube map (texel centres and weights) this backend measures with.
    fn cube_map(&self) -> &CubeMap;

    /// Renders the id cube around `p` into `out` (which must have this backend's resolution):
    /// for every texel, the nearest surface along the texel's centre direction beyond the near
    /// plane. Equal depths go to a front face, then the lower object id (the GPU: the lower id).
    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()>;

    /// Point DoV of every object seen from `p`.
    fn measure(&mut self, p: Vec3) -> Result<PointDov> {
        let mut ids = IdCube::new(self.resolution());
        self.render_ids(p, &mut ids)?;
        Ok(ids.dov(self.cube_map()))
    }

    /// Single rays through the same scene, for ray probing ([`sampler`]); `None` where the backend has none
    /// (the GPU backend draws whole cube maps).
    fn ray_caster(&self) -> Option<&dyn rays::RayCaster> {
        None
    }

    /// Region sampling drawn rather than traced: `cell`'s region views of at least `rays`
    /// texels ([`sampling::RegionViews`], at the backend's own resolution) and the ids they see,
    /// view after view, each in [`IdCube`]'s texel order, with this backend's id rule. `None`
    /// where the backend draws none (the CPU backend, the reference, casts the region rays one
    /// by one, [`rays::RayCaster::first_hits`]; the GPU backend unless asked to,
    /// [`gpu::GpuOptions::region_views`]).
    fn region_views(&mut self, _cell: &crate::grid::ViewCell, _rays: u32) -> Option<Result<(sampling::RegionViews, Vec<u32>)>> {
        None
    }
}

/// A backend that measures with another and casts single rays ([`DovBackend::ray_caster`]) with a
/// CPU backend of the same scene: what probing needs from the GPU backend, which only draws
/// whole cube maps. Costs the CPU backend's BVHs in memory besides the other's.
pub struct WithRays {
    measuring: Box<dyn DovBackend>,
    rays: CpuBackend,
}

impl WithRays {
    /// `measuring` itself when it casts rays already.
    pub fn wrap(measuring: Box<dyn DovBackend>, scene: &crate::scene::Scene) -> Result<Box<dyn DovBackend>> {
        if measuring.ray_caster().is_some() {
            return Ok(measuring);
        }
        let rays = CpuBackend::new(scene, measuring.resolution())?;
        Ok(Box::new(WithRays { measuring, rays }))
    }
}

impl DovBackend for WithRays {
    fn name(&self) -> String {
        format!("{}, rays by the cpu backend", self.measuring.name())
    }
    fn resolution(&self) -> u32 {
        self.measuring.resolution()
    }
    fn cube_map(&self) -> &CubeMap {
        self.measuring.cube_map()
    }
    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()> {
        self.measuring.render_ids(p, out)
    }
    fn measure(&mut self, p: Vec3) -> Result<PointDov> {
        self.measuring.measure(p)
    }
    fn ray_caster(&self) -> Option<&dyn rays::RayCaster> {
        Some(&self.rays)
    }
    fn region_views(&mut self, cell: &crate::grid::ViewCell, rays: u32) -> Option<Result<(sampling::RegionViews, Vec<u32>)>> {
        self.measuring.region_views(cell, rays)
    }
}

/// Distance of the near plane for a scene: 1e-4 of the scene's diagonal, at least 1e-4 (scene
/// units). Surfaces nearer than this along a texel's forward depth are not seen by either backend.
pub fn default_near(scene_bounds: &crate::geom::Aabb) -> f32 {
    let diag = scene_bounds.extent().length();
    if diag.is_finite() { (diag * 1e-4).max(1e-4) } else { 1e-4 }
}

/// Opens the backend `kind` for `scene` at `resolution`. `Auto` uses the CPU backend when no
/// hardware adapter exists or the GPU backend cannot be set up (the reason is dropped: ask for
/// `Gpu` explicitly to see it). Costs the backend's construction: a BVH build or an upload.
///
/// `gpu` configures the GPU backend (LOD-aware drawing); the CPU backend ignores it.
pub fn open_backend(
    scene: &crate::scene::Scene,
    resolution: u32,
    kind: BackendKind,
    gpu: &gpu::GpuOptions,
) -> Result<Box<dyn DovBackend>> {
    // The one bound of the build's parameters; an adapter with a smaller texture limit is
    // refused by the GPU backend itself, naming that limit.
    let max = cubemap::MAX_RESOLUTION;
    if !(1..=max).contains(&resolution) {
        return Err(crate::Error::bad_param(
            Param::Resolution,
            format!("{resolution} is outside 1..={max} texels per face edge (the bound of every build)"),
        ));
    }
    match kind {
        BackendKind::Cpu => Ok(Box::new(CpuBackend::new(scene, resolution)?)),
        BackendKind::Gpu => Ok(Box::new(GpuBackend::with_options(scene, resolution, gpu)?)),
        BackendKind::Auto if !gpu::hardware_adapter_available() => Ok(Box::new(CpuBackend::new(scene, resolution)?)),
        BackendKind::Auto => match GpuBackend::with_options(scene, resolution, gpu) {
            Ok(gpu) => Ok(Box::new(gpu)),
            Err(crate::Error::Gpu(_)) => Ok(Box::new(CpuBackend::new(scene, resolution)?)),
            Err(e) => Err(e),
        },
    }
}
