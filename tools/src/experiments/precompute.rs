//! Item 6, speed against accuracy of the DoV precompute: time per cell against DoV error for
//! R × sample sets (corners, + 8, 27, 64 interior points), the error measured against the most
//! expensive configuration, against analytic spheres and against the other backend; and the
//! rate of visible zero-DoV objects against dense interior sampling, per floor test.

use std::time::Instant;

use glam::Vec3;
use hdov::city::CityScale;
use hdov::dov::precompute::{FloorTest, PrecomputeOptions, TreeShape, cell_dov};
use hdov::dov::sampling::interior_points;
use hdov::dov::{CpuBackend, DovBackend, GpuBackend, PointDov};

use super::charts::{Panel, Series};
use super::{Csv, Ctx, Result, Scale, err, mean};
use hdov_testkit::audit::audit_zero_dov;
use hdov_testkit::scenes::{sphere_dov, sphere_scene};

pub fn run(ctx: &mut Ctx) -> Result<()> {
    let small = ctx.cfg.scale == Scale::Small;
    let (resolutions, ks, cells_measured, dense): (&[u32], &[u32], usize, u32) =
        if small { (&[32, 64, 128], &[0, 8], 2, 16) } else { (&[64, 128, 256, 512, 1024], &[0, 8, 27, 64], 3, 64) };
    // A smaller city than the scale's: per-point cost grows with R², and R = 1024 is here.
    let city = if small { CityScale::Tiny } else { CityScale::Small };
    let scene = ctx.city(city, None)?;
    let grid = scene.grid.clone().ok_or("the city brings no grid")?;
    let bounds = scene.all_object_bounds();
    let corners_per_cell = grid.corner_count() as f64 / grid.cell_count() as f64;
    let k_max = *ks.iter().max().unwrap_or(&0);
    // Street-level cells spread over the grid.
    let cells: Vec<usize> = (0..cells_measured)
        .map(|i| (i * grid.cell_count() / cells_measured + grid.cell_count() / 7) % grid.cell_count())
        .collect();
    let gpu_available = hdov::gfx::adapter_available().is_some();
    // Per R: seconds per point, per cell the point DoVs (8 corners then k_max interior).
    let bar = ctx.bar("precompute", resolutions.len());
    let mut measured: Vec<(u32, f64, Vec<Vec<PointDov>>)> = Vec::new();
    let mut backends =
        Csv::new(&["resolution", "points", "mean_abs_diff_gpu_vs_cpu", "max_abs_diff_gpu_vs_cpu", "pairs"]);
    for &r in resolutions {
        let mut cpu = CpuBackend::new(&scene, r).map_err(err)?;
        let mut per_cell = Vec::new();
        let t = Instant::now();
        let mut points = 0;
        for &id in &cells {
            let at: Vec<Vec3> = grid
                .view_corners(id)
                .iter()
                .map(|&c| grid.corner_position(grid.corner_coords(c)))
                .chain(interior_points(&grid.view_cell(id), k_max))
                .collect();
            points += at.len();
            per_cell.push(at.iter().map(|&p| cpu.measure(p)).collect::<hdov::Result<Vec<_>>>().map_err(err)?);
        }
        let s_per_point = t.elapsed().as_secs_f64() / points as f64;
        if gpu_available {
            // The other backend at the first cell's corners.
            let mut gpu = GpuBackend::new(&scene, r).map_err(err)?;
            let mut d = hdov_testkit::audit::DovDiff::default();
            let first = grid.cell_coords(cells[0]);
            for (i, &c) in grid.cell_corners(first).iter().enumerate() {
                let g = gpu.measure(grid.corner_position(grid.corner_coords(c))).map_err(err)?;
                d.add_points(&per_cell[0][i], &g, 0.0);
            }
            backends.push(&[&r, &8, &format!("{:.3e}", d.mean_abs()), &format!("{:.3e}", d.max_abs), &d.objects]);
        }
        measured.push((r, s_per_point, per_cell));
        bar.inc(1);
    }
    bar.finish_and_clear();
    if gpu_available {
        ctx.write_csv("precompute_backends", &backends)?;
    }

    // Cell DoV of every (R, K) against the reference: the largest R with the most points.
    let shape = TreeShape { object_leaf: vec![0; bounds.len()], node_parent: vec![None], ..Default::default() };
    let options = PrecomputeOptions { zero_dov_tests: Vec::new(), skip_inside_points: true, ..Default::default() };
    let cell_dovs = |r_index: usize, k: u32| -> Vec<Vec<(u32, f32)>> {
        let (r, _, per_cell) = &measured[r_index];
        let cube = hdov::dov::CubeMap::new(*r);
        per_cell
            .iter()
            .zip(&cells)
            .map(|(points, &id)| {
                let used: Vec<&PointDov> = points.iter().take(8 + k as usize).collect();
                let cell_box = grid.cell_box(grid.cell_coords(id));
                cell_dov(&used, &[], &cell_box, &bounds, &shape, &options, &cube).objects
            })
            .collect()
    };
    let reference = cell_dovs(measured.len() - 1, k_max);
    let mut csv = Csv::new(&[
        "resolution",
        "interior_samples",
        "s_per_point",
        "s_per_cell",
        "mean_abs_dov_error",
        "max_abs_dov_error",
        "pairs",
        "missed_pairs",
    ]);
    let mut speed_error: Vec<Series> = Vec::new();
    for &k in ks {
        let mut pts = Vec::new();
        for (ri, (r, s_per_point, _)) in measured.iter().enumerate() {
            let (mut errors, mut missed) = (Vec::new(), 0);
            for (got, want) in cell_dovs(ri, k).iter().zip(&reference) {
                let get = |v: &[(u32, f32)], o: u32| v.binary_search_by_key(&o, |e| e.0).map_or(0.0, |i| v[i].1 as f64);
                let objects: std::collections::BTreeSet<u32> = got.iter().chain(want).map(|e| e.0).collect();
                for o in objects {
                    let (g, w) = (get(got, o), get(want, o));
                    errors.push((g - w).abs());
                    missed += usize::from(g == 0.0 && w > 0.0);
                }
            }
            let s_per_cell = s_per_point * (corners_per_cell + k as f64);
            let m = mean(&errors);
            csv.push(&[
                r,
                &k,
                &format!("{s_per_point:.5}"),
                &format!("{s_per_cell:.4}"),
                &format!("{m:.3e}"),
                &format!("{:.3e}", errors.iter().copied().fold(0.0, f64::max)),
                &errors.len(),
                &missed,
            ]);
            // The reference itself has no error to draw on a log axis.
            if m > 0.0 {
                pts.push((s_per_cell, m));
            }
        }
        speed_error.push(Series::new(if k == 0 { "corners".to_string() } else { format!("corners + {k}") }, pts));
    }
    ctx.write_csv("precompute_speed_error", &csv)?;

    // Point DoV of a sphere against its analytic solid angle, per R and backend.
    let mut analytic =
        Csv::new(&["backend", "resolution", "distance_over_radius", "views", "mean_rel_error", "max_rel_error"]);
    let mut analytic_series = Vec::new();
    for backend in ["cpu", "gpu"] {
        if backend == "gpu" && !gpu_available {
            continue;
        }
        let mut pts = Vec::new();
        for &r in resolutions {
            let mut errors = Vec::new();
            for d in [4.0f32, 16.0] {
                // A sphere in 8 directions, off the face centres and across face edges.
                let mut rel = Vec::new();
                for i in 0..8 {
                    let dir = hdov::dov::sampling::halton3(i + 1) * 2.0 - Vec3::ONE;
                    let centre = dir.normalize_or(Vec3::X) * d;
                    let scene = sphere_scene(5, centre, 1.0);
                    let mut b: Box<dyn DovBackend> = match backend {
                        "cpu" => Box::new(CpuBackend::new(&scene, r).map_err(err)?),
                        _ => Box::new(GpuBackend::new(&scene, r).map_err(err)?),
                    };
                    // The icosphere's own solid angle differs from the sphere's by its
                    // tessellation (5 subdivisions: < 0.1 %), far below these errors at R ≤ 1024.
                    let got = b.measure(Vec3::ZERO).map_err(err)?.get(0);
                    rel.push((got / sphere_dov(1.0, d as f64) - 1.0).abs());
                }
                analytic.push(&[
                    &backend,
                    &r,
                    &d,
                    &rel.len(),
                    &format!("{:.3e}", mean(&rel)),
                    &format!("{:.3e}", rel.iter().copied().fold(0.0, f64::max)),
                ]);
                errors.extend(rel);
            }
            pts.push((r as f64, mean(&errors)));
        }
        analytic_series.push(Series::new(backend, pts));
    }
    ctx.write_csv("precompute_analytic", &analytic)?;

    // Visible zero-DoV objects against dense interior sampling, per floor test.
    let audit_cells: Vec<usize> = {
        let n = if small { 6 } else { 32 };
        (0..n).map(|i| (i * grid.cell_count() / n + 3) % grid.cell_count()).collect()
    };
    let tests = [FloorTest::BoxWithin(0.0), FloorTest::BoxWithin(2.5), FloorTest::NeighbourCorners];
    let audit_ks: Vec<u32> = ks.iter().copied().filter(|&k| k < dense).collect();
    let mut backend = CpuBackend::new(&scene, ctx.cfg.resolution).map_err(err)?;
    let audits = audit_zero_dov(&mut backend, &grid, &bounds, audit_cells.iter().copied(), dense, &audit_ks, &tests)
        .map_err(err)?;
    let mut zero = Csv::new(&[
        "interior_samples",
        "floor_test",
        "cells",
        "dense_points",
        "sparse_visible",
        "zero_dov",
        "zero_dov_rate",
        "caught",
        "missed_after_floor_rate",
        "false_floors",
    ]);
    let mut missed_series: Vec<Series> = vec![Series::new("no floor", Vec::new())];
    missed_series.extend(tests.iter().map(|t| Series::new(format!("floor: {t}"), Vec::new())));
    for a in &audits {
        let all = (a.sparse_visible + a.zero_dov).max(1) as f64;
        let rate = a.zero_dov as f64 / all;
        let after = (a.zero_dov - a.caught) as f64 / all;
        zero.push(&[
            &a.interior_samples,
            &a.test,
            &a.cells,
            &dense,
            &a.sparse_visible,
            &a.zero_dov,
            &format!("{rate:.4}"),
            &a.caught,
            &format!("{after:.4}"),
            &a.false_floors,
        ]);
        let k = a.interior_samples as f64;
        if a.test == tests[0] {
            missed_series[0].points.push((k, rate));
        }
        let i = 1 + tests.iter().position(|t| *t == a.test).unwrap_or(0);
        missed_series[i].points.push((k, after));
    }
    ctx.write_csv("precompute_zero_dov", &zero)?;
    let mut p1 =
        Panel::new("Cell DoV error against time per cell", "s / cell (CPU, 2 cores)", "mean |ΔDoV| vs reference")
            .log_x()
            .log_y();
    p1.series = speed_error;
    let mut p2 = Panel::new("Sphere: point DoV against analytic", "R (texels per face edge)", "mean relative error")
        .log_x()
        .log_y();
    p2.series = analytic_series;
    let mut p3 = Panel::new(
        format!("Visible zero-DoV objects ({dense} dense points/cell)"),
        "interior samples K",
        "share of visible (cell, object) pairs",
    );
    p3.series = missed_series;
    let reference = format!("R = {}, corners + {k_max}", resolutions[resolutions.len() - 1]);
    ctx.write_chart(
        "precompute",
        &format!("DoV precompute, speed against accuracy ({city} city; reference {reference})"),
        &[p1, p2, p3],
        3,
    )?;
    Ok(())
}
