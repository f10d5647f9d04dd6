//! DoV measurement speed: sample points per second for both backends, rays per second per thread
//! for the CPU backend, on a generated block of 20 × 20 buildings (`hdov_testkit::scenes`); and
//! on the audit block of the from-region samplers, region rays per second per thread beside a
//! corner cube map's (what `--samples region` adds to `corners`, per ray).
//!
//! `cargo bench --bench dov` (short default run: 10 samples per benchmark).

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use hdov::dov::{CpuBackend, DovBackend, GpuBackend, IdCube};

fn street_points() -> Vec<Vec3> {
    (0..16).map(|k| Vec3::new(17.0 + 20.0 * (k % 4) as f32 * 4.0, 1.7, 3.0 + 23.0 * (k / 4) as f32 * 4.0)).collect()
}

fn bench_backend(c: &mut Criterion, label: &str, backend: &mut dyn DovBackend) {
    let points = street_points();
    let mut group = c.benchmark_group(format!("dov/{label}"));
    group.throughput(Throughput::Elements(1));
    let mut k = 0;
    group.bench_function(format!("points R={}", backend.resolution()), |b| {
        b.iter(|| {
            k = (k + 1) % points.len();
            backend.measure(points[k]).unwrap()
        })
    });
    group.finish();
}

fn dov_benches(c: &mut Criterion) {
    // 20 × 20 buildings on a ground slab: 401 objects; the viewpoints are at eye height in streets.
    let scene = hdov_testkit::scenes::city_block(20, false);
    for r in [128, 256] {
        let mut cpu = CpuBackend::new(&scene, r).unwrap();
        println!("backend: {}", cpu.name());
        bench_backend(c, "cpu", &mut cpu);
        match GpuBackend::new(&scene, r) {
            Ok(mut gpu) => {
                println!("backend: {}", gpu.name());
                bench_backend(c, "gpu", &mut gpu);
            }
            Err(e) => println!("gpu backend skipped: {e}"),
        }
    }

    // Rays per second on one thread: the id cube only (no weighing), in a 1-thread pool.
    let r = 256;
    let cpu = CpuBackend::new(&scene, r).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let points = street_points();
    let mut group = c.benchmark_group("dov/cpu-1-thread");
    group.throughput(Throughput::Elements(6 * (r as u64) * (r as u64)));
    let mut cpu = cpu;
    let mut ids = IdCube::new(r);
    let mut k = 0;
    group.bench_function(format!("rays R={r}"), |b| {
        b.iter(|| {
            k = (k + 1) % points.len();
            pool.install(|| cpu.render_ids(points[k], &mut ids).unwrap())
        })
    });
    group.finish();

    // Region rays (one cell's 24,576, `--samples region`) against cube-map rays at R = 128, the
    // build's resolution, on one thread, over the audit block's cells.
    let (scene, grid) = hdov_testkit::scenes::audit_block();
    let r = 128;
    let mut cpu = CpuBackend::new(&scene, r).unwrap();
    let cells: Vec<_> = (0..grid.cell_count()).step_by(7).map(|id| grid.cell_box(grid.cell_coords(id))).collect();
    let mut group = c.benchmark_group("dov/audit-1-thread");
    group.throughput(Throughput::Elements(6 * (r as u64) * (r as u64)));
    let mut ids = IdCube::new(r);
    let mut k = 0;
    group.bench_function(format!("cube-map rays R={r}"), |b| {
        b.iter(|| {
            k = (k + 1) % cells.len();
            pool.install(|| cpu.render_ids(cells[k].min, &mut ids).unwrap())
        })
    });
    let rays = 24_576;
    let sequence = hdov::dov::sampling::RegionSequence::new(rays);
    group.throughput(Throughput::Elements(u64::from(rays)));
    group.bench_function(format!("region rays {rays}"), |b| {
        b.iter(|| {
            k = (k + 1) % cells.len();
            pool.install(|| hdov::dov::sampler::region_finds(&cpu, &hdov::grid::ViewCell::whole(cells[k]), &sequence))
        })
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    targets = dov_benches
}
criterion_main!(benches);
