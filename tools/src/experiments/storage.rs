//! Item 1, thesis table 5.2: bytes per layout and codec, per visible (node, cell) and per visible
//! entry, against the tree's fan-out M.

use hdov::{LodRule, Mode, QueryParams};
use hdov_storage::DovCodec;

use super::charts::{Panel, Series};
use super::{Csv, Ctx, Result, err};

const LAYOUTS: [&str; 3] = ["horizontal", "vertical", "indexed-vertical"];

pub fn run(ctx: &mut Ctx) -> Result<()> {
    let city = ctx.cfg.scale.city();
    let scene = ctx.city(city, None)?;
    let mut csv = Csv::new(&[
        "fanout",
        "codec",
        "nodes",
        "height",
        "cells",
        "layout",
        "bytes",
        "vpage_bytes",
        "index_bytes",
        "visible_nodes_per_cell",
        "visible_entries_per_cell",
        "bytes_per_visible_node_cell",
        "bytes_per_visible_entry",
        "flip_pages_mean",
    ]);
    // The codecs are compared at the default fan-out; every fan-out is measured with f32.
    let mut runs: Vec<(u32, DovCodec)> = ctx.cfg.scale.fanouts().iter().map(|&m| (m, DovCodec::F32)).collect();
    runs.push((16, DovCodec::LogU16));
    let bar = ctx.bar("storage", runs.len());
    let mut by_layout: Vec<Vec<(f64, f64)>> = vec![Vec::new(); LAYOUTS.len()];
    let mut per_entry: Vec<Vec<(f64, f64)>> = vec![Vec::new(); LAYOUTS.len()];
    for (m, codec) in runs {
        let db = ctx.database(&city.to_string(), &scene, &ctx.build_params(m, codec))?;
        let info = db.info().map_err(err)?;
        // Visible entries per cell: every visible object (a leaf entry) and every visible node
        // but the root (an internal entry). The naive query lists the cell's visible objects.
        let grid = db.grid().cloned().ok_or("the database holds no grid")?;
        let centres = grid.cell_centres();
        let naive = QueryParams { mode: Mode::Naive, lod_rule: LodRule::Dov, ..Default::default() };
        let mut objects = 0usize;
        for &at in &centres {
            objects += db.query(at, &naive).map_err(err)?.items.len();
        }
        let objects_per_cell = objects as f64 / centres.len() as f64;
        for (i, name) in LAYOUTS.iter().enumerate() {
            let Some((_, l)) = info.layouts.iter().find(|(k, _)| k.name() == *name) else { continue };
            let nodes = l.visible_nodes_per_cell.mean;
            let entries = objects_per_cell + (nodes - 1.0).max(0.0);
            let per_visible_entry = l.vpage_bytes as f64 / (entries * info.cells as f64).max(1.0);
            csv.push(&[
                &m,
                &codec_name(codec),
                &info.nodes,
                &info.tree.height,
                &info.cells,
                name,
                &l.bytes,
                &l.vpage_bytes,
                &l.index_bytes,
                &format!("{nodes:.2}"),
                &format!("{entries:.2}"),
                &format!("{:.1}", l.bytes_per_visible_vpage),
                &format!("{per_visible_entry:.2}"),
                &format!("{:.2}", l.flip_pages.mean),
            ]);
            if codec == DovCodec::F32 {
                by_layout[i].push((m as f64, l.bytes as f64));
                per_entry[i].push((m as f64, per_visible_entry));
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    ctx.write_csv("storage", &csv)?;
    let series = |v: &[Vec<(f64, f64)>]| -> Vec<Series> {
        LAYOUTS.iter().zip(v).map(|(n, p)| Series::new(*n, p.clone())).collect()
    };
    let mut bytes = Panel::new("Bytes per layout (V-pages + index)", "fan-out M", "bytes").log_x().log_y();
    bytes.series.extend(series(&by_layout));
    let mut entry = Panel::new("V-page bytes per visible entry", "fan-out M", "bytes").log_x().log_y();
    entry.series.extend(series(&per_entry));
    ctx.write_chart("storage", &format!("Storage against fan-out, {city} city (thesis table 5.2)"), &[bytes, entry], 2)
}

pub fn codec_name(codec: DovCodec) -> &'static str {
    match codec {
        DovCodec::F32 => "f32",
        DovCodec::LogU16 => "log-u16",
    }
}
