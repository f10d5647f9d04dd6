//! From-region samplers against dense interior sampling: per scene, for corners only (with the
//! box floor and with the neighbour floor), fixed interior points, the adaptive sampler and ray
//! probing, the rate of visible (cell, object) pairs that no sample point sees (misses), the share
//! of the truth's DoV they carry, the false floors, the distance of the cell DoV from the dense
//! max, and the cost (points measured, rays, CPU time) against corners only. The numbers of
//! docs/journal/dov-sampling.md, §1–3 (summarised in docs/dov.md, "Misses against a dense truth").
//!
//! `cargo run --release -p hdov-tools --bin sampler-audit -- SCENE [R] [SHARD I/N] [DENSE] [SAMPLERS]`
//!
//! SCENE: `street` (issue 22's street), `audit` (tests/dov_audit.rs's street block), `fence` (a picket fence of bars 0.25–8
//! texels wide in front of small objects) or `city` (the default generated city). SHARD picks the
//! cells the truth is taken for (it costs DENSE cube maps per cell); the samplers run on the whole
//! grid, as a build does, so their costs per cell are a whole build's. SAMPLERS: comma-separated
//! `corners`, `neighbours` (corners + the neighbour floor), K (interior points),
//! `adaptive[:SEEDS:BUDGET]` or `probe[:POINTS:RAYS]` (without floor tests: its entries at the
//! floor DoV are objects a ray saw, thinner than a texel, and count as found). A sampler written
//! `NAME@shard` runs on SHARD's cells only (and the corners their candidates need), for dense rows
//! too costly on the whole grid, such as `64@shard`: the truth's own method at other points, which
//! measures how far the truth is from agreeing with itself. Its CPU time is compared per cell.
//!
//! Dense truth ([`dense_cells`]): per cell, the 8 corners and DENSE (default 64) Halton points
//! from 1001 on (bases 2, 3, 5): a different part of the sequence from the samplers' points 1…,
//! so that no sampler point coincides with a truth point. Points inside geometry are left out as
//! in the build. Misses are also counted among pairs whose dense DoV is ≥ 4 centre texels. With
//! `HDOV_AUDIT_MISSES=1` the tool also prints every missed pair and the misses by size.

use std::time::Instant;

use clap::Parser;
use hdov::RayProbing;
use hdov::dov::precompute::{CellDov, FloorTest, PrecomputeOptions, Shard, TreeShape, precompute_shard};
use hdov::dov::{CpuBackend, CubeMap, DovBackend};
use hdov::{AdaptiveSampling, Sampling};
use hdov_testkit::audit::{DENSE_HALTON_START, dense_cells};

/// One row of the table: a way of sampling.
#[derive(Clone, Copy, Debug)]
enum Sampler {
    Corners { neighbours: bool },
    Interior(u32),
    Adaptive(AdaptiveSampling),
    Probe(RayProbing),
}

impl Sampler {
    fn parse(s: &str) -> Result<Sampler, String> {
        match s {
            "corners" => Ok(Sampler::Corners { neighbours: false }),
            "neighbours" => Ok(Sampler::Corners { neighbours: true }),
            _ if s.starts_with("adaptive") => s.parse().map(Sampler::Adaptive),
            _ if s.starts_with("probe") => s.parse().map(Sampler::Probe),
            _ => s.parse().map(Sampler::Interior).map_err(|_| format!("unknown sampler '{s}'")),
        }
    }

    fn name(&self) -> String {
        match self {
            Sampler::Corners { neighbours: false } => "corners + box floor".into(),
            Sampler::Corners { neighbours: true } => "corners + box, neighbours floors".into(),
            Sampler::Interior(k) => format!("corners + {k} interior + box floor"),
            Sampler::Adaptive(a) => format!("corners + {a} + box floor"),
            Sampler::Probe(p) => format!("corners + {p}, no floor"),
        }
    }

    fn options(&self) -> PrecomputeOptions {
        let mut o = PrecomputeOptions { zero_dov_tests: vec![FloorTest::BoxWithin(0.0)], ..Default::default() };
        match *self {
            Sampler::Corners { neighbours } if neighbours => o.zero_dov_tests.push(FloorTest::NeighbourCorners),
            Sampler::Corners { .. } => {}
            Sampler::Interior(k) => o.samplers.push(Sampling::Interior(k)),
            Sampler::Adaptive(a) => o.samplers.push(Sampling::Adaptive(a)),
            // No floor: every entry at the floor DoV is then one a probe ray verified (an object
            // thinner than a texel), not a guess, and counts as found.
            Sampler::Probe(p) => {
                o.samplers.push(Sampling::Probe(p));
                o.zero_dov_tests.clear();
            }
        }
        o
    }
}

/// Each object its own leaf under one root: the samplers' object entries do not depend on the
/// tree, and node DoVs are not compared here.
fn flat_shape(objects: usize) -> TreeShape {
    TreeShape {
        object_leaf: (0..objects as u32).collect(),
        node_parent: (0..=objects).map(|n| (n < objects).then_some(objects as u32)).collect(),
        ..Default::default()
    }
}

/// How one sampler's cells compare with the truth.
#[derive(Default)]
struct Compare {
    truth_pairs: usize,
    missed: usize,
    missed_large: usize,
    not_stored: usize,
    false_floors: usize,
    deficit_sum_rel: f64,
    deficit_max: f64,
    over_tolerance: usize,
    found: usize,
    /// The truth's DoV summed over all pairs and over the missed ones.
    truth_mass: f64,
    missed_mass: f64,
    /// Misses by the truth's DoV in centre texels (< 2, < 4, < 16, ≥ 16): not stored, floored.
    by_size: [[usize; 4]; 2],
}

/// `guessed_floors`: the sampler's entries at the floor DoV come from floor tests (guesses), so
/// they count as misses where the truth saw more than the floor.
fn compare(truth: &[CellDov], got: &[(u32, CellDov)], cube: &CubeMap, guessed_floors: bool) -> Compare {
    let texel = cube.texel_floor();
    let floor = texel as f32;
    let mut c = Compare::default();
    for (t, (got_cell, g)) in truth.iter().zip(got) {
        c.truth_pairs += t.objects.len();
        for &(object, dense) in &t.objects {
            let v = g.object(object);
            c.truth_mass += dense as f64;
            // A floored entry is stored (fetched at η ≤ floor) but was not sampled.
            if v == 0.0 || (guessed_floors && v == floor && dense > floor) {
                c.missed += 1;
                c.missed_large += usize::from(dense as f64 >= 4.0 * texel);
                c.not_stored += usize::from(v == 0.0);
                c.missed_mass += dense as f64;
                let texels = dense as f64 / texel;
                let bucket = [2.0, 4.0, 16.0].iter().filter(|&&b| texels >= b).count();
                c.by_size[usize::from(v != 0.0)][bucket] += 1;
                if std::env::var_os("HDOV_AUDIT_MISSES").is_some() {
                    println!("    miss: cell {got_cell} object {object} truth {texels:.1} texels stored {}", v != 0.0);
                }
                continue;
            }
            let deficit = (dense - v).max(0.0) as f64;
            c.found += 1;
            c.deficit_sum_rel += deficit / dense as f64;
            c.deficit_max = c.deficit_max.max(deficit);
            c.over_tolerance += usize::from(deficit > 0.005 * dense as f64 + 2.0 * texel);
        }
        c.false_floors += g.objects.iter().filter(|&&(o, v)| v == floor && t.object(o) == 0.0).count();
    }
    c
}

#[derive(Parser)]
#[command(
    name = "sampler-audit",
    about = "From-region samplers against dense interior sampling: misses, missed DoV, false floors, DoV deficit and \
             cost per sampler",
    long_about = "From-region samplers against dense interior sampling: per scene, for each sampler, the rate of visible\n\
                  (cell, object) pairs that no sample point sees (misses, also among pairs of at least 4 centre\n\
                  texels), the share of the truth's DoV they carry, the false floors, the distance of the cell DoV\n\
                  from the dense max, and the cost (points measured, probe and footprint rays, CPU time) against\n\
                  corners only. CPU backend. The truth (for SHARD's cells): per cell, the 8 corners and DENSE Halton\n\
                  points from index 1001 on; the samplers run on the whole grid, as a build does. Prints a Markdown\n\
                  table. With HDOV_AUDIT_MISSES=1 in the environment, also every missed pair and the misses by size.\n\
                  \n\
                  Makes: docs/journal/dov-sampling.md, §1–3 (the adaptive, probing and truth-against-itself tables;\n\
                  tables), and docs/results.md, \"From-region sampling against dense sampling\"\n\
                  (`sampler-audit audit 64 0/1 64 corners,neighbours,16,adaptive:2:16`; `fence`; `city 128 14/29 ...`)."
)]
struct Args {
    /// The scene: `street` (issue 22's street), `audit` (tests/dov_audit.rs's street block), `fence` (a picket
    /// fence of bars 0.25–8 texels wide in front of small objects) or `city` (the default generated city).
    #[arg(value_name = "SCENE", default_value = "audit")]
    scene: String,
    /// Cube-map resolution R (texels per face edge).
    #[arg(default_value_t = 64)]
    r: u32,
    /// The cells the truth is taken for (it costs DENSE cube maps per cell): shard I of N equal parts of the
    /// grid's cells.
    #[arg(value_name = "SHARD", default_value = "0/1", value_parser = hdov_tools::args::shard)]
    shard: Shard,
    /// Halton points per cell of the dense truth, besides its 8 corners.
    #[arg(default_value_t = 64)]
    dense: u32,
    /// Samplers, comma-separated: `corners`, `neighbours` (corners + the neighbour floor), K (K interior points),
    /// `adaptive[:SEEDS:BUDGET]` or `probe[:POINTS:RAYS]` (without floor tests). `NAME@shard` runs on SHARD's
    /// cells only (and the corners their candidates need), for rows too costly on the whole grid, e.g.
    /// `64@shard`.
    #[arg(value_name = "SAMPLERS", value_delimiter = ',', default_value = "corners,neighbours,4,16,adaptive")]
    samplers: Vec<String>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let (scene_name, r, shard, dense) = (args.scene.as_str(), args.r, args.shard, args.dense);
    // Each sampler, and whether it runs on SHARD's cells only.
    let samplers: Vec<(Sampler, bool)> = args
        .samplers
        .iter()
        .map(|s| {
            let (name, on_shard) = s.strip_suffix("@shard").map_or((s.as_str(), false), |name| (name, true));
            Sampler::parse(name).map(|x| (x, on_shard))
        })
        .collect::<Result<_, _>>()?;
    let (scene, grid) = hdov_testkit::scenes::audit_scene(scene_name, r)?;
    println!("{}", hdov_tools::machine());
    let bounds = scene.all_object_bounds();
    let shape = flat_shape(bounds.len());
    let mut backend = CpuBackend::new(&scene, r)?;
    let cube = backend.cube_map().clone();
    let cells = shard.cells(&grid);
    println!(
        "scene {scene_name}: {} objects, cells {cells:?} of {} ({:?}), R = {r}, CPU backend, truth: corners + {dense} Halton points per cell",
        bounds.len(),
        grid.cell_count(),
        grid.dims
    );
    let t = Instant::now();
    let truth = dense_cells(&mut backend, &grid, &bounds, &shape, shard.cells(&grid), dense)?;
    println!("truth (Halton points from {DENSE_HALTON_START}): {:.1} s", t.elapsed().as_secs_f64());
    println!(
        "| sampler | points / cell | probe + footprint rays / cell | time (s) | CPU time (s) | CPU time / corners | misses (rate) | missed DoV | misses ≥ 4 texels | not stored | false floors (% of true) | mean DoV deficit | max deficit (texels) | beyond 0.5 % + 2 texels |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut corner_time = None;
    for (sampler, on_shard) in samplers {
        let options = sampler.options();
        let (t, cpu) = (Instant::now(), hdov_tools::process_cpu_time());
        // The whole grid, as a build measures it (corners shared by all their cells), unless
        // `@shard`; compared on the truth's cells.
        let run_on = if on_shard { shard } else { Shard::ALL };
        let out = precompute_shard(&mut backend, &grid, &bounds, &shape, &options, run_on, &hdov::progress::Quiet)?;
        let all_cells = out.cells.len() as f64;
        let secs = t.elapsed().as_secs_f64();
        let cpu = (hdov_tools::process_cpu_time() - cpu).as_secs_f64();
        // CPU time per cell: steadier than the wall clock on a shared machine.
        let base = *corner_time.get_or_insert(cpu / all_cells);
        let compared = if on_shard { &out.cells[..] } else { &out.cells[cells.clone()] };
        let c = compare(&truth, compared, &cube, !options.zero_dov_tests.is_empty());
        let pct = |n: usize| 100.0 * n as f64 / c.truth_pairs.max(1) as f64;
        println!(
            "| {} | {:.2} | {:.0} + {:.0} | {secs:.1} | {cpu:.1} | {:.2}× | {} ({:.2} %) | {:.3} % | {} ({:.2} %) | {} ({:.2} %) | {} ({:.1} %) | {:.2} % | {:.1} | {} |",
            sampler.name() + if on_shard { " (shard only)" } else { "" },
            out.points_measured as f64 / all_cells,
            out.probe_rays as f64 / all_cells,
            out.footprint_rays as f64 / all_cells,
            cpu / all_cells / base,
            c.missed,
            pct(c.missed),
            100.0 * c.missed_mass / c.truth_mass.max(f64::MIN_POSITIVE),
            c.missed_large,
            pct(c.missed_large),
            c.not_stored,
            pct(c.not_stored),
            c.false_floors,
            pct(c.false_floors),
            100.0 * c.deficit_sum_rel / c.found.max(1) as f64,
            c.deficit_max / cube.texel_floor(),
            c.over_tolerance
        );
        if std::env::var_os("HDOV_AUDIT_MISSES").is_some() {
            println!(
                "    misses by truth texels (<2, <4, <16, ≥16): not stored {:?}, floored {:?}",
                c.by_size[0], c.by_size[1]
            );
        }
    }
    println!(
        "true (cell, object) pairs: {}; load average now: {}",
        truth.iter().map(|c| c.objects.len()).sum::<usize>(),
        {
            std::fs::read_to_string("/proc/loadavg")
                .unwrap_or_default()
                .split_whitespace()
                .take(3)
                .collect::<Vec<_>>()
                .join(" ")
        }
    );
    Ok(())
}
