//! DoV measurement speed: sample points per second for both backends, rays per second per thread
//! for the CPU backend, on a generated block of buildings.
//!
//! `cargo bench --bench dov` (short default run: 10 samples per benchmark).

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Mat4, Quat, Vec3};
use hdov::dov::{CpuBackend, DovBackend, GpuBackend, IdCube};
use hdov::scene::{BaseMesh, Mesh, Object, Scene};

/// 20 × 20 buildings (boxes of varied height) on a ground slab: 401 objects, a street grid
/// between them. The viewpoints are at eye height in the streets.
fn city_block() -> Scene {
    let cube = Mesh {
        positions: (0..8)
            .map(|i| {
                [
                    if i & 1 == 0 { -0.5 } else { 0.5 },
                    if i & 2 == 0 { -0.5 } else { 0.5 },
                    if i & 4 == 0 { -0.5 } else { 0.5 },
                ]
            })
            .collect(),
        indices: vec![
            0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6,
        ],
    };
    let mut scene = Scene { meshes: vec![BaseMesh { name: "cube".into(), mesh: cube }], ..Default::default() };
    let mut add = |name: String, min: Vec3, max: Vec3| {
        scene.objects.push(Object {
            name,
            mesh: 0,
            transform: Mat4::from_scale_rotation_translation(max - min, Quat::IDENTITY, (min + max) * 0.5),
        });
    };
    add("ground".into(), Vec3::new(-10.0, -1.0, -10.0), Vec3::new(410.0, 0.0, 410.0));
    for i in 0..20 {
        for j in 0..20 {
            // Deterministic varied heights: 10..70.
            let h = 10.0 + ((i * 7 + j * 13) % 13) as f32 * 5.0;
            let (x, z) = (i as f32 * 20.0, j as f32 * 20.0);
            add(format!("b{i}_{j}"), Vec3::new(x, 0.0, z), Vec3::new(x + 14.0, h, z + 14.0));
        }
    }
    scene
}

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
    let scene = city_block();
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
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    targets = dov_benches
}
criterion_main!(benches);
