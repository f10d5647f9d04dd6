//! Where a build samples each cell besides its 8 shared corners: the samplers by name, their
//! parameters and bounds. Plain data, as the rest of `format`: each sampler's behaviour lives
//! in `dov::sampler`, in a file of the same name.
//!
//! A sampler is one parameter type implementing [`SamplerSpec`] in a file of its own here, and
//! one line of [`samplers!`] below; `dov::sampler` builds it from one line of its own.

/// `Display` and `FromStr` of a sampler's parameter type, from its [`SamplerSpec`] name.
macro_rules! spec_names {
    ($t:ty) => {
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                super::SamplerSpec::write_name(self, f)
            }
        }

        impl std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                <$t as super::SamplerSpec>::parse(s)
                    .unwrap_or_else(|| Err(format!("'{s}': expected {}", <$t as super::SamplerSpec>::SYNTAX)))
            }
        }
    };
}

mod adaptive;
mod interior;
mod probe;

use std::fmt;

pub use adaptive::AdaptiveSampling;
pub use probe::RayProbing;

use crate::error::{Error, Param, Result};

/// A sampler's parameters: how they are written (the `--samples` syntax and the manifest's
/// `sampling` field are one name), and their bounds.
pub trait SamplerSpec: Sized {
    /// The names it takes, for messages (`adaptive[:SEEDS:BUDGET]`).
    const SYNTAX: &'static str;
    /// The parameter an out-of-bounds value is reported as.
    const PARAM: Param;

    /// Writes the name that [`SamplerSpec::parse`] reads back.
    fn write_name(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result;

    /// Parses `s` if it names this sampler (`None`: it names another one).
    fn parse(s: &str) -> Option<std::result::Result<Self, String>>;

    /// Checks the bounds; the reason when out of them.
    fn check(&self) -> std::result::Result<(), String>;

    /// The most interior points it measures per cell (the sample-point limit counts them).
    fn max_points_per_cell(&self) -> u32 {
        0
    }
}

/// Declares [`Sampling`] from its variants, each one sampler, and the name dispatch that every
/// variant shares.
macro_rules! samplers {
    ($($(#[$doc:meta])* $variant:ident($spec:ty),)*) => {
        /// Where a build samples each cell besides its 8 shared corners: one sampler, by name.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub enum Sampling {
            $($(#[$doc])* $variant($spec),)*
        }

        impl Sampling {
            /// `s` parsed by the first sampler that takes the name.
            fn parse_any(s: &str) -> Option<std::result::Result<Sampling, String>> {
                None$(.or_else(|| <$spec as SamplerSpec>::parse(s).map(|r| r.map(Sampling::$variant))))*
            }

            /// Every sampler's syntax, for messages.
            fn syntaxes() -> Vec<&'static str> {
                vec![$(<$spec as SamplerSpec>::SYNTAX),*]
            }

            fn check_spec(&self) -> std::result::Result<(), (Param, String)> {
                match self {
                    $(Sampling::$variant(s) => s.check().map_err(|r| (<$spec as SamplerSpec>::PARAM, r)),)*
                }
            }

            /// The most interior points a cell can take.
            pub fn max_points_per_cell(&self) -> u32 {
                match self {
                    $(Sampling::$variant(s) => s.max_points_per_cell(),)*
                }
            }
        }

        impl fmt::Display for Sampling {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                match self {
                    $(Sampling::$variant(s) => s.write_name(f),)*
                }
            }
        }
    };
}

samplers! {
    /// This many stratified (Halton) interior points per cell; 0 = the corners alone (the
    /// thesis's sampling, and the cheap option, `corners`).
    Interior(u32),
    /// Adaptive points where new objects appear (`adaptive:SEEDS:BUDGET`).
    Adaptive(AdaptiveSampling),
    /// Rays aimed at what the cell's neighbourhood sees (`probe:POINTS:RAYS[:REGION]`, `region`).
    Probe(RayProbing),
}

/// Region rays by default (decision 98): the fewest wrong pixels from anywhere in a cell, at
/// under twice the corners' visibility time on street scenes (docs/dov.md).
impl Default for Sampling {
    fn default() -> Self {
        Sampling::Probe(RayProbing::REGION)
    }
}

impl Sampling {
    /// The corners alone.
    pub const CORNERS: Sampling = Sampling::Interior(0);

    /// Checks the sampler's bounds, naming the parameter.
    pub fn check(&self) -> Result<()> {
        self.check_spec().map_err(|(param, reason)| Error::bad_param(param, reason))
    }
}

impl std::str::FromStr for Sampling {
    type Err = String;
    /// Any sampler's name (`corners`, `7`, `adaptive:2:16`, `probe:32:4:24576`, `region`, ...).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Sampling::parse_any(s)
            .unwrap_or_else(|| Err(format!("'{s}' is none of {}", Sampling::syntaxes().join(", "))))
    }
}

/// Parses `NAME` (`None`: the defaults) or `NAME:A:B` (two counts); `shape` names the counts in
/// errors (`SEEDS:BUDGET`).
fn parse_two_counts(s: &str, name: &str, shape: &str) -> std::result::Result<Option<(u32, u32)>, String> {
    let expected = || format!("'{s}': expected {name} or {name}:{shape}");
    let Some(rest) = s.strip_prefix(name) else { return Err(expected()) };
    if rest.is_empty() {
        return Ok(None);
    }
    let count = |x: &str| x.trim().parse::<u32>().map_err(|_| format!("'{s}': '{x}' is not a count"));
    match rest.strip_prefix(':').and_then(|r| r.split_once(':')) {
        Some((a, b)) => Ok(Some((count(a)?, count(b)?))),
        None => Err(expected()),
    }
}

/// The manifest's record of [`Sampling`]: its name in the field `sampling`. Manifests written
/// before there was one field (format 3 up to hdov 0.x of decision 101) named the sampler in
/// up to three fields, `interior_samples` always, `adaptive` and `probe` when chosen; they still
/// read. Used flattened into `VisibilityParams`.
pub(crate) mod record {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::{AdaptiveSampling, RayProbing, Sampling};

    #[derive(Serialize)]
    struct Written {
        #[serde(with = "crate::format::by_name::one")]
        sampling: Sampling,
    }

    #[derive(Deserialize)]
    struct Read {
        #[serde(default, with = "crate::format::by_name::optional")]
        sampling: Option<Sampling>,
        // The fields of earlier manifests.
        #[serde(default)]
        interior_samples: Option<u32>,
        #[serde(default, with = "crate::format::by_name::optional")]
        adaptive: Option<AdaptiveSampling>,
        #[serde(default, with = "crate::format::by_name::optional")]
        probe: Option<RayProbing>,
    }

    pub fn serialize<S: Serializer>(sampling: &Sampling, s: S) -> Result<S::Ok, S::Error> {
        Written { sampling: *sampling }.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Sampling, D::Error> {
        let r = Read::deserialize(d)?;
        let earlier = (r.interior_samples.unwrap_or(0), r.adaptive, r.probe);
        match (r.sampling, earlier) {
            (Some(s), (0, None, None)) => Ok(s),
            (None, (k, None, None)) => Ok(Sampling::Interior(k)),
            (None, (0, Some(a), None)) => Ok(Sampling::Adaptive(a)),
            (None, (0, None, Some(p))) => Ok(Sampling::Probe(p)),
            _ => Err(serde::de::Error::custom("more than one sampler (sampling, interior_samples, adaptive, probe)")),
        }
    }
}
