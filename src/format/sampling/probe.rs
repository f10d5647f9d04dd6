//! Ray probing's parameters: `probe[:POINTS:RAYS[:REGION[:NEAREST]]]`, and `region` (the
//! default).

use super::{SamplerSpec, parse_two_counts};
use crate::error::Param;

/// Parameters of ray probing: `points` probe points per cell, `rays` rays from each towards each
/// unseen candidate, and optionally REGION rays from points spread over the cell in directions
/// spread over the sphere; a candidate seen from nearby places is searched for from the NEAREST
/// probe points to them. Written `probe:POINTS:RAYS[:REGION[:NEAREST]]` (`probe` alone is
/// [`RayProbing::DEFAULT`]; NEAREST is POINTS, every point, unless given).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RayProbing {
    /// Probe points per cell.
    pub points: u32,
    /// Rays from each probe point towards each unseen candidate.
    pub rays: u32,
    /// Rays from the cell's region in spread directions, whatever they meet first being seen
    /// (guided visibility sampling's random stage); 0: none.
    pub region: u32,
    /// How many probe points search for a candidate that neighbouring corners or region rays
    /// saw: those nearest the places that saw it (every point where this is `points`; a
    /// candidate whose box meets the cell is searched for from every point whatever this is).
    /// Fewer is faster and misses more (docs/dov.md, "Region rays").
    pub nearest: u32,
}

impl RayProbing {
    /// Chosen by the audit in docs/journal/dov-sampling.md, §2.
    pub const DEFAULT: RayProbing = RayProbing { points: 32, rays: 4, region: 0, nearest: 32 };

    /// `--samples region`: probing with 24,576 region rays per cell, the fewest that met issue
    /// 22's wrong-pixel targets on every street scene (docs/dov.md, "Region rays").
    pub const REGION: RayProbing = RayProbing { points: 32, rays: 4, region: 24576, nearest: 32 };

    /// Most region rays per cell.
    pub const MAX_REGION: u32 = 1 << 24;

    /// `1 ≤ points ≤ 4096`, `1 ≤ rays ≤ 4096`, `region ≤ 2^24`; every point searches for every
    /// candidate.
    pub fn new(points: u32, rays: u32, region: u32) -> Result<Self, String> {
        Self::with_nearest(points, rays, region, points)
    }

    /// [`RayProbing::new`] with `1 ≤ nearest ≤ points` points searching for a candidate seen
    /// nearby.
    pub fn with_nearest(points: u32, rays: u32, region: u32, nearest: u32) -> Result<Self, String> {
        if !(1..=4096).contains(&points)
            || !(1..=4096).contains(&rays)
            || region > Self::MAX_REGION
            || !(1..=points).contains(&nearest)
        {
            return Err(format!(
                "probe:{points}:{rays}:{region}:{nearest}: need 1 ≤ POINTS ≤ 4096, 1 ≤ RAYS ≤ 4096, REGION ≤ {} and 1 ≤ NEAREST ≤ POINTS",
                Self::MAX_REGION
            ));
        }
        Ok(Self { points, rays, region, nearest })
    }
}

impl SamplerSpec for RayProbing {
    const SYNTAX: &'static str = "probe[:POINTS:RAYS[:REGION[:NEAREST]]], region";
    const PARAM: Param = Param::Samples;

    fn write_name(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "probe:{}:{}", self.points, self.rays)?;
        if self.nearest < self.points {
            write!(f, ":{}:{}", self.region, self.nearest)?;
        } else if self.region > 0 {
            write!(f, ":{}", self.region)?;
        }
        Ok(())
    }

    /// `probe`, `probe:POINTS:RAYS`, `probe:POINTS:RAYS:REGION`,
    /// `probe:POINTS:RAYS:REGION:NEAREST` or `region` ([`RayProbing::REGION`]).
    fn parse(s: &str) -> Option<Result<Self, String>> {
        if s == "region" {
            return Some(Ok(Self::REGION));
        }
        if !s.starts_with("probe") {
            return None;
        }
        // POINTS:RAYS, then the optional counts after them.
        let (two, more) = match s.match_indices(':').nth(2) {
            Some((at, _)) => (&s[..at], s[at + 1..].split(':').collect::<Vec<_>>()),
            None => (s, Vec::new()),
        };
        let mut counts = Vec::new();
        for field in &more {
            match field.trim().parse::<u32>() {
                Ok(n) => counts.push(n),
                Err(_) => return Some(Err(format!("'{s}': '{field}' is not a count"))),
            }
        }
        Some(match (parse_two_counts(two, "probe", "POINTS:RAYS[:REGION[:NEAREST]]"), &counts[..]) {
            (Err(e), _) => Err(e),
            (Ok(None), []) => Ok(Self::DEFAULT),
            (Ok(Some((points, rays))), []) => Self::new(points, rays, 0),
            (Ok(Some((points, rays))), &[region]) => Self::new(points, rays, region),
            (Ok(Some((points, rays))), &[region, nearest]) => Self::with_nearest(points, rays, region, nearest),
            _ => Err(format!("'{s}': expected probe or probe:POINTS:RAYS[:REGION[:NEAREST]]")),
        })
    }

    fn check(&self) -> Result<(), String> {
        Self::with_nearest(self.points, self.rays, self.region, self.nearest).map(|_| ())
    }
}

spec_names!(RayProbing);
