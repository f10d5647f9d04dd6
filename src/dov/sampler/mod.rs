//! Samplers: where a cell is measured besides its 8 shared corners. Each sampler is one file
//! here, the behaviour of one [`Sampling`] variant (its parameters, name and bounds live in
//! `format::sampling`, beside the manifest that records them);
//! [`precompute_shard`](super::precompute::precompute_shard) runs a cell's samplers in turn, each
//! seeing the points measured before it.
//!
//! A new sampler is a parameter type in `format::sampling`, a file here implementing
//! [`CellSampler`], and one line of [`Sampling::sampler`].

mod adaptive;
mod interior;
mod probe;

pub use adaptive::sample_cell;
pub use probe::{Candidate, CellProbe, Leads, RegionFind, probe_cell, region_finds};

use super::{CubeMap, DovBackend, PointDov};
use crate::error::Result;
use crate::format::BakePhases;
use crate::format::sampling::Sampling;
use crate::geom::Aabb;
use crate::grid::{ViewCell, ViewGrid};
use crate::progress::Report;

/// The cell a sampler samples, and what is known of it when the sampler starts.
pub struct CellSite<'a> {
    /// The cell's id in the grid.
    pub id: usize,
    /// The cell's coordinates in the grid.
    pub coords: [u32; 3],
    /// The cell's box (its lattice cell's).
    pub bounds: Aabb,
    /// Where in the box viewers stand ([`ViewCell::places`]).
    pub places: u64,
    pub grid: &'a ViewGrid,
    /// The cell's own corners ([`ViewGrid::view_corners`]), measured.
    pub corners: &'a [&'a PointDov],
    /// The corners of the neighbouring cells within [`CellSampler::corner_ring`] (the widest
    /// ring any sampler of the build asks for), measured; the cell's own corners not included.
    pub nearby: &'a [&'a PointDov],
    /// Where each of `nearby` is.
    pub nearby_at: &'a [glam::Vec3],
    /// Every object's world box.
    pub object_bounds: &'a [Aabb],
    /// The cube map of the measurements.
    pub cube: &'a CubeMap,
}

impl CellSite<'_> {
    /// The cell as its samplers place points in it.
    pub fn view_cell(&self) -> ViewCell {
        ViewCell { bounds: self.bounds, places: self.places }
    }
}

/// Counts of a shard's work: measurements done and planned (reported as progress as they
/// change), and rays cast.
pub struct Tally<'a> {
    done: usize,
    planned: usize,
    progress: &'a dyn Report,
    /// Rays cast towards targets (and to tell inside points).
    pub probe_rays: u64,
    /// Rays cast to measure the footprints of what was found.
    pub footprint_rays: u64,
    /// Region views drawn (the GPU's region sampling, [`DovBackend::region_views`]).
    pub region_views: u64,
    /// Where the time went, phase by phase.
    pub phases: BakePhases,
}

impl<'a> Tally<'a> {
    /// A tally of `planned` measurements, none done.
    pub fn new(planned: usize, progress: &'a dyn Report) -> Self {
        Tally { done: 0, planned, progress, probe_rays: 0, footprint_rays: 0, region_views: 0, phases: BakePhases::default() }
    }

    /// One more measurement done; `beyond_plan` when it was not counted in the plan.
    pub fn measured(&mut self, beyond_plan: bool) {
        self.done += 1;
        self.planned += usize::from(beyond_plan);
        self.progress.set(self.done as u64, self.planned as u64);
    }

    /// Measurements done.
    pub fn done(&self) -> usize {
        self.done
    }
}

/// One way of choosing a cell's sample points besides its corners. Its findings are whole or
/// partial point views ([`PointDov`]); the cell's DoV is the max over all of them
/// ([`super::precompute::cell_dov`]).
pub trait CellSampler {
    /// How many rings of neighbouring cells' corners it reads ([`CellSite::nearby`]).
    fn corner_ring(&self) -> u32 {
        0
    }

    /// Whether it casts single rays ([`DovBackend::ray_caster`]): a backend without them is
    /// given a CPU ray caster of the same scene (`dov::WithRays`).
    fn casts_rays(&self) -> bool {
        false
    }

    /// Measurements it plans per cell (progress; it may take more).
    fn planned_points(&self) -> u32 {
        0
    }

    /// Work done once for a shard before its view cells (`cells`, ascending ids), such as region
    /// rays over them and their neighbours. Refuses a backend that lacks what the sampler needs.
    fn prepare(&mut self, _backend: &mut dyn DovBackend, _grid: &ViewGrid, _cells: &[usize], _tally: &mut Tally) -> Result<()> {
        Ok(())
    }

    /// Adds the cell's sample points to `points`, which holds those that earlier samplers
    /// measured for the cell.
    fn sample(&mut self, backend: &mut dyn DovBackend, cell: &CellSite, points: &mut Vec<PointDov>, tally: &mut Tally) -> Result<()>;

    /// What the cell it sampled last (`cell`) sees from some of its squares, `places`: `seen`
    /// (what their corners see), its findings placed there, and what rays from points there
    /// aimed at `candidates` (what the whole cell sees) meet first. `None`: its findings
    /// have no place, and the squares take the whole cell's.
    fn refine(
        &mut self,
        _backend: &mut dyn DovBackend,
        _cell: &CellSite,
        _places: u64,
        _seen: &std::collections::HashSet<u32>,
        _candidates: &[u32],
        _tally: &mut Tally,
    ) -> Result<Option<std::collections::HashSet<u32>>> {
        Ok(None)
    }

    /// The objects it found from cell `cell` by itself (during [`CellSampler::prepare`]), which
    /// the neighbours floor counts as seen nearby; `None`: it keeps no such finds.
    fn found_from(&self, _cell: usize) -> Option<Vec<u32>> {
        None
    }
}

impl Sampling {
    /// The sampler these parameters name.
    pub fn sampler(&self) -> Box<dyn CellSampler> {
        match *self {
            Sampling::Interior(k) => Box::new(interior::Interior(k)),
            Sampling::Adaptive(a) => Box::new(adaptive::Adaptive(a)),
            Sampling::Probe(p) => Box::new(probe::Probe::new(p)),
        }
    }
}
