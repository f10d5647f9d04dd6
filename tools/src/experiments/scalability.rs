//! Item 4, thesis fig. 5.23: query time and pages read against the database's size, over cities
//! of at least four sizes (up to the large city at scale default and large).

use hdov::city::CityScale;
use hdov::{LodRule, Mode, QueryParams};
use hdov_storage::DovCodec;

use super::charts::{Panel, Series};
use super::query::mean_costs;
use super::{Csv, Ctx, Result, Scale, err, quantile};

const ETAS: [f64; 3] = [0.0, 1e-4, 1e-3];

pub fn run(ctx: &mut Ctx) -> Result<()> {
    // (label, city, blocks override)
    let sizes: Vec<(String, CityScale, Option<u32>)> = match ctx.cfg.scale {
        Scale::Small => vec![
            ("tiny".into(), CityScale::Tiny, None),
            ("blocks3".into(), CityScale::Small, Some(3)),
            ("blocks4".into(), CityScale::Small, Some(4)),
            ("small".into(), CityScale::Small, None),
        ],
        // The huge city's visibility is a cluster's job (docs/sharding.md), not an experiment's.
        _ => CityScale::ALL.iter().filter(|&&c| c != CityScale::Huge).map(|&c| (c.to_string(), c, None)).collect(),
    };
    let mut csv = Csv::new(&[
        "city",
        "objects",
        "triangles",
        "nodes",
        "cells",
        "db_bytes",
        "query",
        "eta",
        "faces",
        "pages",
        "micros_mean",
        "micros_p50",
        "micros_p99",
    ]);
    let bar = ctx.bar("scalability", sizes.len());
    let mut pages: Vec<Vec<(f64, f64)>> = vec![Vec::new(); ETAS.len() + 1];
    let mut micros = pages.clone();
    for (label, city, blocks) in &sizes {
        let scene = ctx.city(*city, *blocks)?;
        let db = ctx.database(label, &scene, &ctx.build_params(16, DovCodec::F32))?;
        let info = db.info().map_err(err)?;
        let db_bytes: u64 = info.files.iter().map(|f| f.bytes).sum();
        let centres = db.grid().ok_or("the database holds no grid")?.cell_centres();
        mean_costs(&db, &centres, &QueryParams::default())?;
        let runs = std::iter::once((
            "naive",
            0.0,
            QueryParams { mode: Mode::Naive, lod_rule: LodRule::Dov, ..Default::default() },
        ))
        .chain(
            ETAS.iter()
                .map(|&eta| ("threshold", eta, QueryParams { eta, lod_rule: LodRule::Dov, ..Default::default() })),
        );
        for (i, (query, eta, params)) in runs.enumerate() {
            let mut us = Vec::with_capacity(centres.len());
            let (mut faces, mut read) = (0u64, 0u64);
            for &at in &centres {
                let a = db.query(at, &params).map_err(err)?;
                us.push(a.stats.micros as f64);
                faces += a.stats.faces;
                read += a.stats.pages_read;
            }
            let n = centres.len() as f64;
            let mean_us = us.iter().sum::<f64>() / n;
            csv.push(&[
                label,
                &info.objects,
                &info.triangles,
                &info.nodes,
                &info.cells,
                &db_bytes,
                &query,
                &eta,
                &format!("{:.0}", faces as f64 / n),
                &format!("{:.2}", read as f64 / n),
                &format!("{mean_us:.1}"),
                &quantile(&us, 0.5),
                &quantile(&us, 0.99),
            ]);
            let mb = db_bytes as f64 / 1e6;
            pages[i].push((mb, read as f64 / n));
            micros[i].push((mb, mean_us));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    ctx.write_csv("scalability", &csv)?;
    let names: Vec<String> =
        std::iter::once("naive".to_string()).chain(ETAS.iter().map(|e| format!("HDoV η = {e}"))).collect();
    let panel = |title: &str, y: &str, data: &[Vec<(f64, f64)>]| {
        let mut p = Panel::new(title, "database size (MB)", y).log_x();
        p.series = names.iter().zip(data).map(|(n, d)| Series::new(n.clone(), d.clone())).collect();
        p
    };
    ctx.write_chart(
        "scalability",
        &format!("Scalability over {} city sizes, fan-out 16 (thesis fig. 5.23)", sizes.len()),
        &[panel("Pages read per query", "pages", &pages), panel("Query time (warm)", "µs / query", &micros)],
        2,
    )
}
