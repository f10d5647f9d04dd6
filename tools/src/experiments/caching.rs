//! Item 2, thesis figs. 5.15–5.20: the page cache's hit rate against its size for each policy
//! (none, LRU, DoV, DoV-Time, DPLRU) on a continuous query sequence (walks along the streets) and
//! a random one (cell centres in a shuffled order), for η ∈ {1e-5, 1e-4, 5e-4}.

use glam::Vec3;
use hdov::grid::ViewGrid;
use hdov::{LodRule, QueryParams, SessionParams};
use hdov_storage::PolicyKind;

use super::charts::{Panel, Series};
use super::{Csv, Ctx, Result, err};

const CACHE_PAGES: [usize; 8] = [2, 4, 8, 16, 32, 64, 128, 256];
const ETAS: [f64; 3] = [1e-5, 1e-4, 5e-4];
const POLICIES: [PolicyKind; 4] = [PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME, PolicyKind::Dplru];

pub fn run(ctx: &mut Ctx) -> Result<()> {
    let (_, db) = ctx.main_database()?;
    let grid = db.grid().cloned().ok_or("the database holds no grid")?;
    let continuous = street_walks(&grid);
    let mut random = grid.cell_centres();
    shuffle(&mut random, 7);
    let mut csv = Csv::new(&[
        "sequence",
        "eta",
        "policy",
        "cache_pages",
        "queries",
        "cache_requests",
        "cache_hits",
        "hit_rate",
        "pages_read",
    ]);
    let mut panels = Vec::new();
    let bar = ctx.bar("caching", 2 * ETAS.len() * POLICIES.len() * CACHE_PAGES.len());
    for (name, seq) in [("continuous", &continuous), ("random", &random)] {
        for eta in ETAS {
            let mut panel = Panel::new(format!("{name}, η = {eta}"), "cache size (pages)", "hit rate").log_x();
            for policy in POLICIES {
                let mut points = Vec::new();
                for pages in CACHE_PAGES {
                    let params = SessionParams {
                        query: QueryParams { eta, lod_rule: LodRule::Dov, ..Default::default() },
                        cache: policy,
                        cache_pages: Some(pages),
                        ..Default::default()
                    };
                    let mut s = db.session(&params).map_err(err)?;
                    // The cache's own hit rate: requests that got past the reader's one-page
                    // read buffer (which serves consecutive V-pages of one disk page under any
                    // policy).
                    let (mut hits, mut requests, mut read) = (0u64, 0u64, 0u64);
                    for &at in seq.iter() {
                        let step = s.step(at, None).map_err(err)?;
                        hits += step.cache_hits;
                        requests += step.cache_requests;
                        read += step.pages_read;
                    }
                    let rate = hits as f64 / requests.max(1) as f64;
                    points.push((pages as f64, rate));
                    csv.push(&[
                        &name,
                        &eta,
                        &policy,
                        &pages,
                        &seq.len(),
                        &requests,
                        &hits,
                        &format!("{rate:.4}"),
                        &read,
                    ]);
                    bar.inc(1);
                }
                panel.series.push(Series::new(policy.to_string(), points));
            }
            panels.push(panel);
        }
    }
    bar.finish_and_clear();
    ctx.write_csv("caching", &csv)?;
    ctx.write_chart("caching", "Page-cache hit rate against cache size (thesis figs. 5.15–5.20)", &panels, 3)
}

/// Walks along the first avenue and back, then across the grid diagonally: viewpoints a few
/// metres apart, so cells are entered and left as a walker does.
pub fn street_walks(grid: &ViewGrid) -> Vec<Vec3> {
    let mut path: Vec<Vec3> = hdov::city::avenue_walk(grid, 200).into_iter().map(|(p, _)| p).collect();
    path.extend(path.clone().into_iter().rev());
    let r = grid.region;
    let y = (r.min.y + r.max.y) / 2.0;
    path.extend((0..200).map(|i| {
        let t = i as f32 / 199.0;
        Vec3::new(r.min.x + (r.max.x - r.min.x) * t, y, r.min.z + (r.max.z - r.min.z) * t).min(r.max).max(r.min)
    }));
    path
}

/// A deterministic Fisher–Yates shuffle (SplitMix64).
pub fn shuffle<T>(v: &mut [T], seed: u64) {
    let mut s = seed;
    for i in (1..v.len()).rev() {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        v.swap(i, ((z ^ (z >> 31)) % (i as u64 + 1)) as usize);
    }
}
