//! The adaptive sampler's parameters: `adaptive[:SEEDS:BUDGET]`.

use super::{SamplerSpec, parse_two_counts};
use crate::error::Param;
use crate::format::limits::MAX_INTERIOR_SAMPLES;

/// Parameters of the adaptive sampler: `seeds` spread points per cell first, at most `budget`
/// interior points per cell in all. Written `adaptive:SEEDS:BUDGET` (`adaptive` alone is
/// [`AdaptiveSampling::DEFAULT`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdaptiveSampling {
    /// Spread points per cell measured first.
    pub seeds: u32,
    /// Most interior points per cell in all.
    pub budget: u32,
}

impl AdaptiveSampling {
    /// Two seeds (one point sees past one side of an occluder, two see past both more often),
    /// at most 16 points: chosen by the audit in docs/journal/dov-sampling.md, §1.
    pub const DEFAULT: AdaptiveSampling = AdaptiveSampling { seeds: 2, budget: 16 };

    /// `1 ≤ seeds ≤ budget`.
    pub fn new(seeds: u32, budget: u32) -> Result<Self, String> {
        let a = Self { seeds, budget };
        if seeds == 0 || seeds > budget {
            return Err(format!("{a}: need 1 ≤ SEEDS ≤ BUDGET"));
        }
        Ok(a)
    }
}

impl SamplerSpec for AdaptiveSampling {
    const SYNTAX: &'static str = "adaptive[:SEEDS:BUDGET]";
    const PARAM: Param = Param::InteriorSamples;

    fn write_name(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "adaptive:{}:{}", self.seeds, self.budget)
    }

    /// `adaptive` or `adaptive:SEEDS:BUDGET`.
    fn parse(s: &str) -> Option<Result<Self, String>> {
        s.starts_with("adaptive").then(|| match parse_two_counts(s, "adaptive", "SEEDS:BUDGET")? {
            None => Ok(Self::DEFAULT),
            Some((seeds, budget)) => Self::new(seeds, budget),
        })
    }

    fn check(&self) -> Result<(), String> {
        Self::new(self.seeds, self.budget)?;
        if self.budget > MAX_INTERIOR_SAMPLES {
            return Err(format!("{self}: a budget above {MAX_INTERIOR_SAMPLES} per cell"));
        }
        Ok(())
    }

    fn max_points_per_cell(&self) -> u32 {
        self.budget
    }
}

spec_names!(AdaptiveSampling);
