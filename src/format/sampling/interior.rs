//! Fixed interior points: `corners` (none) or a count of stratified Halton points per cell.

use super::SamplerSpec;
use crate::error::Param;
use crate::format::limits::MAX_INTERIOR_SAMPLES;

/// The count of interior points; 0 is written `corners`.
impl SamplerSpec for u32 {
    const SYNTAX: &'static str = "corners, a number of interior points";
    const PARAM: Param = Param::InteriorSamples;

    fn write_name(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            0 => f.write_str("corners"),
            k => write!(f, "{k}"),
        }
    }

    fn parse(s: &str) -> Option<Result<u32, String>> {
        if s == "corners" {
            return Some(Ok(0));
        }
        s.parse().ok().map(Ok)
    }

    fn check(&self) -> Result<(), String> {
        if *self > MAX_INTERIOR_SAMPLES {
            return Err(format!("{self} is above {MAX_INTERIOR_SAMPLES} per cell"));
        }
        Ok(())
    }

    fn max_points_per_cell(&self) -> u32 {
        *self
    }
}
