//! Ray probing's parameters: `probe[:POINTS:RAYS[:REGION]]`, and `region` (the default).

use super::{SamplerSpec, parse_two_counts};
use crate::error::Param;

/// Parameters of ray probing: `points` probe points per cell, `rays` rays from each towards each
/// unseen candidate, and optionally REGION rays from points spread over the cell in directions
/// spread over the sphere. Written `probe:POINTS:RAYS[:REGION]` (`probe` alone is
/// [`RayProbing::DEFAULT`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RayProbing {
    /// Probe points per cell.
    pub points: u32,
    /// Rays from each probe point towards each unseen candidate.
    pub rays: u32,
    /// Rays from the cell's region in spread directions, whatever they meet first being seen
    /// (guided visibility sampling's random stage); 0: none.
    pub region: u32,
}

impl RayProbing {
    /// Chosen by the audit in docs/journal/dov-sampling.md, §2.
    pub const DEFAULT: RayProbing = RayProbing { points: 32, rays: 4, region: 0 };

    /// `--samples region`: probing with 24,576 region rays per cell, the fewest that met issue
    /// 22's wrong-pixel targets on every street scene (docs/dov.md, "Region rays").
    pub const REGION: RayProbing = RayProbing { points: 32, rays: 4, region: 24576 };

    /// Most region rays per cell.
    pub const MAX_REGION: u32 = 1 << 24;

    /// `1 ≤ points ≤ 4096`, `1 ≤ rays ≤ 4096`, `region ≤ 2^24`.
    pub fn new(points: u32, rays: u32, region: u32) -> Result<Self, String> {
        if !(1..=4096).contains(&points) || !(1..=4096).contains(&rays) || region > Self::MAX_REGION {
            return Err(format!(
                "probe:{points}:{rays}:{region}: need 1 ≤ POINTS ≤ 4096, 1 ≤ RAYS ≤ 4096 and REGION ≤ {}",
                Self::MAX_REGION
            ));
        }
        Ok(Self { points, rays, region })
    }
}

impl SamplerSpec for RayProbing {
    const SYNTAX: &'static str = "probe[:POINTS:RAYS[:REGION]], region";
    const PARAM: Param = Param::Samples;

    fn write_name(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "probe:{}:{}", self.points, self.rays)?;
        if self.region > 0 {
            write!(f, ":{}", self.region)?;
        }
        Ok(())
    }

    /// `probe`, `probe:POINTS:RAYS`, `probe:POINTS:RAYS:REGION` or `region`
    /// ([`RayProbing::REGION`]).
    fn parse(s: &str) -> Option<Result<Self, String>> {
        if s == "region" {
            return Some(Ok(Self::REGION));
        }
        if !s.starts_with("probe") {
            return None;
        }
        let (two, region) = match s.rsplit_once(':') {
            Some((head, last)) if head.matches(':').count() == 2 => match last.trim().parse::<u32>() {
                Ok(region) => (head, region),
                Err(_) => return Some(Err(format!("'{s}': '{last}' is not a count"))),
            },
            _ => (s, 0),
        };
        Some(match parse_two_counts(two, "probe", "POINTS:RAYS[:REGION]") {
            Err(e) => Err(e),
            Ok(None) => Ok(Self::DEFAULT),
            Ok(Some((points, rays))) => Self::new(points, rays, region),
        })
    }

    fn check(&self) -> Result<(), String> {
        Self::new(self.points, self.rays, self.region).map(|_| ())
    }
}

spec_names!(RayProbing);
