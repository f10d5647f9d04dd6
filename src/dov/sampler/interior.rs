//! Fixed interior points: the same `k` stratified Halton points in every cell (none: the corners
//! alone, the thesis's sampling).

use super::{CellSampler, CellSite, Tally};
use crate::dov::sampling::interior_points;
use crate::dov::{DovBackend, PointDov};
use crate::error::Result;

/// `k` Halton points per cell ([`interior_points`]).
pub struct Interior(pub u32);

impl CellSampler for Interior {
    fn planned_points(&self) -> u32 {
        self.0
    }

    fn sample(&mut self, backend: &mut dyn DovBackend, cell: &CellSite, points: &mut Vec<PointDov>, tally: &mut Tally) -> Result<()> {
        let start = std::time::Instant::now();
        points.reserve(self.0 as usize);
        for p in interior_points(&cell.view_cell(), self.0) {
            points.push(backend.measure(p)?);
            tally.measured(false);
        }
        tally.phases.points += start.elapsed().as_secs_f64();
        Ok(())
    }
}
