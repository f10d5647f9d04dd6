//! How a database is built: typed parameters, their documented bounds, and the one check that
//! runs before any work.
//!
//! The parameters are recorded in `manifest.json` (names as strings there, typed here). Errors
//! name the parameter (`page_size`, `resolution`, ...); a user interface maps it to its own word
//! for it (the `hdov` command to its flags).

use serde::{Deserialize, Serialize};

use crate::dov::BackendKind;
use crate::dov::adaptive::AdaptiveSampling;
use crate::dov::precompute::{FloorTest, Shard};
use crate::dov::probe::RayProbing;
use crate::error::{Error, Result};
use crate::grid::ViewGrid;
use crate::lod::LodParams;
use crate::rtree::TreeAlgorithm;
use hdov_storage::{DovCodec, LayoutKind};

/// Upper bounds of a build. They keep every count inside its on-disk integer and a mistyped
/// argument from asking for days of work or an allocation the machine cannot make.
pub mod limits {
    /// Viewing cells of a grid.
    pub const MAX_CELLS: u64 = crate::grid::ViewGrid::MAX_CELLS;
    /// Sample points a build measures: grid corners plus interior points of every cell.
    pub const MAX_SAMPLE_POINTS: u64 = 1 << 26;
    /// Interior sample points per cell.
    pub const MAX_INTERIOR_SAMPLES: u32 = 4096;
    /// Texels per cube-face edge.
    pub const MAX_RESOLUTION: u32 = crate::dov::cubemap::MAX_RESOLUTION;
    /// Smallest tree page: a node header, two entries and the page checksum.
    pub const MIN_PAGE_SIZE: u32 = 100;
    /// Largest tree page: 65,534 entries, so a node's entry count fits the V-page layouts' u16.
    pub const MAX_PAGE_SIZE: u32 = 1 << 21;
    /// Largest LOD-aware drawing tolerance, in texels.
    pub const MAX_LOD_DRAW_TOLERANCE: f32 = 64.0;
}

/// The fan-out a build uses unless told otherwise, chosen by measurement (docs/query.md): on
/// the default city it keeps the pages a threshold query reads below the naive method's for
/// every η ≥ 1e-4 (M = 4 does not) while returning 14–26 % fewer faces than a full 4 KiB page's
/// 126 entries at η = 1e-3 … 8e-3.
pub const DEFAULT_FANOUT: u32 = 16;

/// How a database was built.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildParams {
    /// Bytes per page of the tree file and of the V-page layouts.
    pub page_size: u32,
    /// Most entries per tree node (M); `None`: [`DEFAULT_FANOUT`], or what a page holds if
    /// fewer. A smaller M makes a deeper tree whose nodes cover less of the scene, so the DoV
    /// threshold can stop early; a larger one reads fewer pages (docs/query.md, fan-out table).
    #[serde(default)]
    pub fanout: Option<u32>,
    pub tree: TreeAlgorithm,
    pub lod: LodParams,
    /// `None` builds tree and LODs only.
    pub visibility: Option<VisibilityParams>,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
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
    pub backend: BackendKind,
    /// Stratified interior sample points per cell, besides the 8 shared corners.
    pub interior_samples: u32,
    /// Adaptive sample points per cell after the corners (`"adaptive:SEEDS:BUDGET"` in the
    /// manifest, absent when off, so manifests of other builds are unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive: Option<AdaptiveSampling>,
    /// Ray probing after the measured points (`"probe:POINTS:RAYS"` in the manifest, absent when
    /// off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe: Option<RayProbing>,
    /// Layouts to write.
    #[serde(with = "names")]
    pub layouts: Vec<LayoutKind>,
    /// How V-entries store DoV.
    #[serde(with = "name")]
    pub dov_codec: DovCodec,
    /// This database holds part I of N of the grid's cells (`[I, N]` in the manifest).
    pub shard: Option<Shard>,
    /// Visible-zero-DoV tests (thesis §5.5.2) that give unseen objects the one-texel floor.
    /// Empty: no floor.
    #[serde(default, with = "names")]
    pub zero_dov_floor: Vec<FloorTest>,
    /// GPU backend: texels of LOD error below which an object is drawn coarser (0 = off).
    #[serde(default)]
    pub lod_draw_tolerance: f32,
}

impl Default for VisibilityParams {
    fn default() -> Self {
        Self {
            resolution: 128,
            backend: BackendKind::Auto,
            interior_samples: 0,
            adaptive: None,
            probe: None,
            layouts: LayoutKind::ALL.to_vec(),
            dov_codec: DovCodec::F32,
            shard: None,
            zero_dov_floor: vec![FloorTest::BoxWithin(0.0), FloorTest::NeighbourCorners],
            lod_draw_tolerance: crate::dov::gpu::DEFAULT_LOD_TOLERANCE_TEXELS,
        }
    }
}

impl VisibilityParams {
    /// The shard this build computes ([`Shard::ALL`] without one).
    pub fn shard(&self) -> Shard {
        self.shard.unwrap_or(Shard::ALL)
    }
}

impl BuildParams {
    /// Most entries per node: `fanout`, else [`DEFAULT_FANOUT`], at most what a page holds.
    pub fn max_entries(&self) -> usize {
        let page = crate::db::tree_page::fanout(self.page_size);
        (self.fanout.unwrap_or(DEFAULT_FANOUT) as usize).min(page)
    }

    /// Checks every parameter against its bounds, and the grid (if any) against the cell and
    /// sample-point limits. Costs nothing; [`crate::build()`] calls it before any work.
    pub fn check(&self, grid: Option<&ViewGrid>) -> Result<()> {
        use limits::*;
        let fanout = crate::db::tree_page::fanout(self.page_size);
        if !(MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&self.page_size) || fanout < 2 {
            return Err(Error::bad_param(
                "page_size",
                format!("{} bytes is outside {MIN_PAGE_SIZE}..={MAX_PAGE_SIZE}", self.page_size),
            ));
        }
        if let Some(m) = self.fanout
            && !(2..=fanout as u32).contains(&m)
        {
            return Err(Error::bad_param(
                "fanout",
                format!("{m} entries is outside 2..={fanout}, what a {}-byte page holds", self.page_size),
            ));
        }
        let lod = &self.lod;
        if !(lod.ratio > 0.0 && lod.ratio < 1.0) {
            return Err(Error::bad_param("lod.ratio", format!("{} is not in (0, 1)", lod.ratio)));
        }
        let Some(v) = &self.visibility else { return Ok(()) };
        if !(1..=MAX_RESOLUTION).contains(&v.resolution) {
            return Err(Error::bad_param("resolution", format!("{} is outside 1..={MAX_RESOLUTION}", v.resolution)));
        }
        if v.interior_samples > MAX_INTERIOR_SAMPLES {
            return Err(Error::bad_param(
                "interior_samples",
                format!("{} is above {MAX_INTERIOR_SAMPLES} per cell", v.interior_samples),
            ));
        }
        if let Some(a) = v.adaptive {
            AdaptiveSampling::new(a.seeds, a.budget).map_err(|r| Error::bad_param("interior_samples", r))?;
            if a.budget > MAX_INTERIOR_SAMPLES {
                return Err(Error::bad_param(
                    "interior_samples",
                    format!("{a}: a budget above {MAX_INTERIOR_SAMPLES} per cell"),
                ));
            }
        }
        if v.layouts.is_empty() {
            return Err(Error::bad_param("layouts", "names no layout"));
        }
        if let Some(k) = v.layouts.iter().enumerate().find_map(|(i, k)| v.layouts[..i].contains(k).then_some(k)) {
            return Err(Error::bad_param("layouts", format!("names {k} twice")));
        }
        if !(0.0..=MAX_LOD_DRAW_TOLERANCE).contains(&v.lod_draw_tolerance) {
            return Err(Error::bad_param(
                "lod_draw_tolerance",
                format!("{} texels is outside 0..={MAX_LOD_DRAW_TOLERANCE}", v.lod_draw_tolerance),
            ));
        }
        if let Some(FloorTest::BoxWithin(m)) =
            v.zero_dov_floor.iter().find(|t| matches!(t, FloorTest::BoxWithin(m) if !(m.is_finite() && *m >= 0.0)))
        {
            return Err(Error::bad_param("zero_dov_floor", format!("box margin {m} must be a finite length >= 0")));
        }
        if let Some(s) = v.shard {
            Shard::new(s.index, s.count).map_err(|r| Error::bad_param("shard", r))?;
            let cells = grid.map_or(MAX_CELLS, |g| g.cell_count() as u64);
            if u64::from(s.count) > cells {
                return Err(Error::bad_param("shard", format!("{s}: more shards than the {cells} cells")));
            }
        }
        if let Some(g) = grid {
            // The adaptive budget is the most a cell can take.
            check_grid(g, v.interior_samples + v.adaptive.map_or(0, |a| a.budget))?;
        }
        Ok(())
    }
}

/// Checks a grid against [`limits::MAX_CELLS`] and, with `interior_samples` per cell,
/// [`limits::MAX_SAMPLE_POINTS`], in integers that cannot overflow.
pub fn check_grid(grid: &ViewGrid, interior_samples: u32) -> Result<()> {
    use limits::*;
    grid.check().map_err(|r| Error::bad_param("grid", r))?;
    let [nx, ny, nz] = grid.dims.map(u64::from);
    // Three u32 counts multiply to 96 bits at most.
    let cells = u128::from(nx) * u128::from(ny) * u128::from(nz);
    if cells > u128::from(MAX_CELLS) {
        return Err(Error::bad_param(
            "grid",
            format!("{nx}x{ny}x{nz} is more than {MAX_CELLS} cells; use fewer or larger cells"),
        ));
    }
    // Below MAX_CELLS, corners are at most 8 per cell and the sum fits in u64.
    let points = (nx + 1) * (ny + 1) * (nz + 1) + cells as u64 * u64::from(interior_samples);
    if points > MAX_SAMPLE_POINTS {
        return Err(Error::bad_param(
            "interior_samples",
            format!(
                "{nx}x{ny}x{nz} cells with {interior_samples} interior points each is {points} sample points, more than {MAX_SAMPLE_POINTS}"
            ),
        ));
    }
    Ok(())
}

/// Serde for one value through its `Display` and `FromStr` (the manifest keeps readable names).
mod name {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<T: Display, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(v)
    }

    pub fn deserialize<'de, T, D>(d: D) -> Result<T, D::Error>
    where
        T: FromStr<Err: Display>,
        D: Deserializer<'de>,
    {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// Serde for a list of values through their names, as [`name`].
mod names {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<T: Display, S: Serializer>(v: &[T], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| x.to_string()))
    }

    pub fn deserialize<'de, T, D>(d: D) -> Result<Vec<T>, D::Error>
    where
        T: FromStr<Err: Display>,
        D: Deserializer<'de>,
    {
        Vec::<String>::deserialize(d)?.iter().map(|x| x.parse().map_err(serde::de::Error::custom)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Aabb;
    use glam::Vec3;

    #[test]
    fn manifest_names_round_trip() {
        let p = BuildParams {
            visibility: Some(VisibilityParams {
                shard: Some(Shard::new(1, 3).unwrap()),
                zero_dov_floor: vec![FloorTest::BoxWithin(2.5), FloorTest::NeighbourCorners],
                dov_codec: DovCodec::LogU16,
                adaptive: Some(AdaptiveSampling { seeds: 3, budget: 24 }),
                probe: Some(RayProbing { points: 16, rays: 2 }),
                ..Default::default()
            }),
            ..Default::default()
        };
        let json = serde_json::to_value(&p).unwrap();
        let v = &json["visibility"];
        assert_eq!(v["layouts"], serde_json::json!(["horizontal", "vertical", "indexed-vertical"]));
        assert_eq!(v["zero_dov_floor"], serde_json::json!(["box:2.5", "neighbours"]));
        assert_eq!(v["shard"], serde_json::json!([1, 3]));
        assert_eq!(v["dov_codec"], "log-u16");
        assert_eq!(v["adaptive"], "adaptive:3:24");
        assert_eq!(v["probe"], "probe:16:2");
        assert_eq!(serde_json::from_value::<BuildParams>(json).unwrap(), p);
    }

    #[test]
    fn manifests_without_adaptive_sampling_read_and_write_unchanged() {
        let json = serde_json::to_value(BuildParams::default()).unwrap();
        assert!(json["visibility"].get("adaptive").is_none());
        assert!(json["visibility"].get("probe").is_none());
        assert_eq!(serde_json::from_value::<BuildParams>(json).unwrap().visibility.unwrap().adaptive, None);
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["adaptive"] = serde_json::json!("adaptive:0:3");
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("SEEDS"));
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["probe"] = serde_json::json!("probe:0:3");
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("POINTS"));
    }

    #[test]
    fn bad_shard_in_a_manifest_is_refused() {
        let mut json = serde_json::to_value(BuildParams::default()).unwrap();
        json["visibility"]["shard"] = serde_json::json!([3, 3]);
        assert!(serde_json::from_value::<BuildParams>(json).unwrap_err().to_string().contains("0 ≤ I < N"));
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
        assert!(with(|v| v.interior_samples = 5000).starts_with("interior_samples:"));
        assert!(with(|v| v.layouts.clear()).starts_with("layouts:"));
        assert!(with(|v| v.adaptive = Some(AdaptiveSampling { seeds: 0, budget: 4 })).starts_with("interior_samples:"));
        assert!(
            with(|v| v.adaptive = Some(AdaptiveSampling { seeds: 2, budget: 5000 })).starts_with("interior_samples:")
        );
        assert!(with(|v| v.layouts.push(LayoutKind::Vertical)).contains("twice"));
        assert!(with(|v| v.lod_draw_tolerance = f32::NAN).starts_with("lod_draw_tolerance:"));
        let page = BuildParams { page_size: 64, ..Default::default() };
        assert!(page.check(None).unwrap_err().to_string().starts_with("page_size:"));
        let p = BuildParams::default();
        assert!(p.check(Some(&grid([4, 1, 4]))).is_ok());
        // Billions of cells, and a product that would overflow 32 bits, are refused.
        assert!(p.check(Some(&grid([100_000, 1, 100_000]))).unwrap_err().to_string().starts_with("grid:"));
        assert!(p.check(Some(&grid([u32::MAX, u32::MAX, u32::MAX]))).unwrap_err().to_string().starts_with("grid:"));
        let many = BuildParams {
            visibility: Some(VisibilityParams { interior_samples: 4096, ..Default::default() }),
            ..Default::default()
        };
        assert!(many.check(Some(&grid([200, 1, 200]))).unwrap_err().to_string().starts_with("interior_samples:"));
    }
}
