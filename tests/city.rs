//! The city generator's promises: determinism, sizes per scale, well-formed closed meshes,
//! buildings that keep apart, a grid that covers the city, and a detail model stored once.

use std::collections::HashMap;

use glam::Vec3;
use hdov::city::{
    CityParams, CityScale, DETAIL_HEIGHT, DETAIL_MESH_NAME, MAX_BUILDING_TRIANGLES, MIN_BUILDING_TRIANGLES, generate,
};
use hdov::geom::Aabb;
use hdov::scene::{Mesh, Scene};

fn city(scale: CityScale, seed: u64) -> Scene {
    generate(&CityParams { seed, scale, ..CityParams::default() }).unwrap()
}

fn is_detail(scene: &Scene, object: usize) -> bool {
    scene.objects[object].mesh == 0
}

/// Every directed edge must have exactly one reverse twin: the surface is closed and
/// consistently wound (a union of closed parts is fine).
fn closed_problem(mesh: &Mesh) -> Option<String> {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    for t in mesh.indices.chunks_exact(3) {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    edges.iter().find_map(|(&(a, b), &n)| {
        (n != 1 || edges.get(&(b, a)) != Some(&1))
            .then(|| format!("edge {a}->{b} used {n} times, twin {:?}", edges.get(&(b, a))))
    })
}

/// Splits a mesh into its connected parts (by shared vertices) and returns each part's signed
/// volume: positive for every closed part whose triangles wind counter-clockwise from outside.
fn part_volumes(mesh: &Mesh) -> Vec<f64> {
    let mut parent: Vec<usize> = (0..mesh.positions.len()).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    for t in mesh.indices.chunks_exact(3) {
        for k in 1..3 {
            let (a, b) = (root(&mut parent, t[0] as usize), root(&mut parent, t[k] as usize));
            parent[a] = b;
        }
    }
    let mut volumes: HashMap<usize, f64> = HashMap::new();
    for t in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| Vec3::from(mesh.positions[t[k] as usize]).as_dvec3());
        *volumes.entry(root(&mut parent, t[0] as usize)).or_insert(0.0) += a.dot(b.cross(c)) / 6.0;
    }
    volumes.into_values().collect()
}

fn assert_well_formed(name: &str, mesh: &Mesh) {
    mesh.check().unwrap_or_else(|e| panic!("{name}: {e}"));
    if let Some(problem) = closed_problem(mesh) {
        panic!("{name} is not closed: {problem}");
    }
    for v in part_volumes(mesh) {
        assert!(v > 0.0, "{name} has a part of volume {v} (inside out)");
    }
    for (i, [a, b, c]) in mesh.triangles().enumerate() {
        let area = (b - a).cross(c - a).length() * 0.5;
        assert!(area > 1e-6, "{name}: triangle {i} is degenerate ({a} {b} {c})");
    }
}

#[test]
fn same_seed_same_city_other_seed_other_city() {
    let a = city(CityScale::Tiny, 42);
    assert_eq!(a, city(CityScale::Tiny, 42));
    let b = city(CityScale::Tiny, 43);
    assert_ne!(a.objects, b.objects);
    assert_ne!(a.meshes[1..], b.meshes[1..]);
    // Buildings are generated in parallel: one thread must give the same city as many.
    let small = city(CityScale::Small, 7);
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    assert_eq!(small, one_thread.install(|| city(CityScale::Small, 7)));
}

#[test]
fn scales_parse_and_print() {
    for scale in CityScale::ALL {
        assert_eq!(scale.to_string().parse::<CityScale>().unwrap(), scale);
    }
    assert_eq!("LARGE".parse::<CityScale>().unwrap(), CityScale::Large);
    assert_eq!("huge".parse::<CityScale>().unwrap(), CityScale::Huge);
    let err = "enormous".parse::<CityScale>().unwrap_err().to_string();
    assert!(err.starts_with("scale: ") && err.contains("enormous"), "{err}");
}

#[test]
fn object_counts_per_scale() {
    for seed in 0..6 {
        let tiny = city(CityScale::Tiny, seed);
        assert!((20..=100).contains(&tiny.objects.len()), "tiny seed {seed}: {} objects", tiny.objects.len());
        let small = city(CityScale::Small, seed);
        assert!((300..=500).contains(&small.objects.len()), "small seed {seed}: {} objects", small.objects.len());
    }
    for seed in 0..2 {
        let default = city(CityScale::Default, seed);
        let n = default.objects.len();
        assert!((1_700..=2_500).contains(&n), "default seed {seed}: {n} objects");
        let details = (0..n).filter(|&o| is_detail(&default, o)).count();
        assert!((30..=120).contains(&details), "default seed {seed}: {details} detail instances");
    }
}

#[test]
fn blocks_override_the_scale() {
    let one = generate(&CityParams { blocks: Some([1, 1]), ..CityParams::default() }).unwrap();
    let zero = generate(&CityParams { blocks: Some([0, 0]), ..CityParams::default() }).unwrap();
    assert_eq!(zero, one, "zero blocks count as one");
    one.check().unwrap();
    let wide = generate(&CityParams { blocks: Some([6, 2]), scale: CityScale::Tiny, ..CityParams::default() }).unwrap();
    let tiny = city(CityScale::Tiny, 0);
    let one_details = (0..one.objects.len()).filter(|&o| is_detail(&one, o)).count();
    assert_eq!(one_details, 4, "a one-block city has statues at its four street corners");
    assert!((4..=40).contains(&(one.objects.len() - one_details)), "{} buildings on one block", one.objects.len() - 4);
    assert!(wide.objects.len() > tiny.objects.len() * 2, "{} vs {}", wide.objects.len(), tiny.objects.len());
    let [w, d] = [wide.grid.clone().unwrap().region.extent().x, wide.grid.clone().unwrap().region.extent().z];
    assert!(w > d * 2.0, "6 x 2 blocks make a wide city: {w} x {d}");
}

#[test]
fn large_scale_has_the_thesis_size() {
    // Generation is fast enough (about a second) to test the real thing rather than a formula.
    let large = city(CityScale::Large, 1);
    assert!(large.objects.len() >= 10_000, "{} objects", large.objects.len());
    assert!(large.triangle_count() >= 20_000_000, "{} triangles over instances", large.triangle_count());
    assert!(large.stored_triangle_count() < large.triangle_count() / 2 + 1);
    let cells = large.grid.clone().unwrap().cell_count();
    assert!((2_000..=8_000).contains(&cells), "{cells} cells");
    large.check().unwrap();
}

#[test]
fn buildings_are_well_formed_closed_and_in_budget() {
    for (scale, seed) in [(CityScale::Small, 3), (CityScale::Tiny, 9)] {
        let scene = city(scale, seed);
        scene.check().unwrap();
        let mut kinds = HashMap::new();
        for object in &scene.objects[..] {
            if object.mesh == 0 {
                continue;
            }
            let mesh = &scene.meshes[object.mesh as usize];
            assert_eq!(mesh.name, object.name);
            let n = mesh.mesh.triangle_count();
            assert!((MIN_BUILDING_TRIANGLES..=MAX_BUILDING_TRIANGLES).contains(&n), "{}: {n} triangles", object.name);
            assert_well_formed(&object.name, &mesh.mesh);
            *kinds.entry(object.name.rsplit('_').next().unwrap().to_string()).or_insert(0) += 1;
        }
        if scale == CityScale::Small {
            assert!(kinds.get("house").copied().unwrap_or(0) > 50, "{kinds:?}");
            assert!(kinds.get("tower").copied().unwrap_or(0) > 20, "{kinds:?}");
        }
    }
}

#[test]
fn every_building_of_the_default_city_is_in_budget() {
    let scene = city(CityScale::Default, 5);
    for m in &scene.meshes[1..] {
        let n = m.mesh.triangle_count();
        assert!((MIN_BUILDING_TRIANGLES..=MAX_BUILDING_TRIANGLES).contains(&n), "{}: {n} triangles", m.name);
    }
    let heights: Vec<f32> = (0..scene.objects.len())
        .filter(|&o| scene.objects[o].name.ends_with("tower"))
        .map(|o| scene.object_bounds(o).max.y)
        .collect();
    assert!(heights.iter().all(|h| (30.0..=170.0).contains(h)), "tower heights");
    assert!(heights.iter().any(|&h| h > 100.0), "downtown has tall towers");
}

#[test]
fn buildings_and_statues_keep_apart_inside_the_grid() {
    for (scale, seed) in [(CityScale::Small, 1), (CityScale::Tiny, 2)] {
        let scene = city(scale, seed);
        let grid = scene.grid.clone().expect("the city brings its grid");
        let bounds = scene.all_object_bounds();
        for (o, b) in bounds.iter().enumerate() {
            let inside = grid.region.min.x <= b.min.x
                && b.max.x <= grid.region.max.x
                && grid.region.min.z <= b.min.z
                && b.max.z <= grid.region.max.z;
            assert!(inside, "{} at {:?} is outside the grid {:?}", scene.objects[o].name, b, grid.region);
            assert!(b.min.y.abs() < 1e-3, "{} does not stand on the ground", scene.objects[o].name);
        }
        // Sort by min x and sweep: footprints (xz) of any two objects must not overlap.
        let mut order: Vec<usize> = (0..bounds.len()).collect();
        order.sort_by(|&a, &b| bounds[a].min.x.total_cmp(&bounds[b].min.x));
        let footprints_overlap =
            |a: &Aabb, b: &Aabb| a.min.x < b.max.x && b.min.x < a.max.x && a.min.z < b.max.z && b.min.z < a.max.z;
        for (k, &a) in order.iter().enumerate() {
            for &b in order[k + 1..].iter().take_while(|&&b| bounds[b].min.x < bounds[a].max.x) {
                assert!(
                    !footprints_overlap(&bounds[a], &bounds[b]),
                    "{} and {} overlap",
                    scene.objects[a].name,
                    scene.objects[b].name
                );
            }
        }
    }
}

#[test]
fn grid_sits_at_eye_height_with_sensible_cell_counts() {
    for (scale, cells) in [(CityScale::Tiny, 16..=64), (CityScale::Small, 120..=320), (CityScale::Default, 300..=1_000)]
    {
        let scene = city(scale, 11);
        let grid = scene.grid.clone().unwrap();
        grid.check().unwrap();
        assert_eq!(grid.dims[1], 1);
        assert_eq!((grid.region.min.y, grid.region.max.y), (1.5, 2.0));
        assert!(cells.contains(&grid.cell_count()), "{scale}: {} cells", grid.cell_count());
        let size = grid.cell_size();
        assert!((10.0..=80.0).contains(&size.x) && (10.0..=80.0).contains(&size.z), "{scale}: cells {size}");
        assert!(grid.region.contains(&Aabb::new(Vec3::new(0.0, 1.5, 0.0), Vec3::new(0.0, 2.0, 0.0))));
        assert!((scene.bounds().min.x - grid.region.min.x) > 10.0, "a street rings the city");
    }
}

#[test]
fn detail_model_is_dense_closed_and_stored_once() {
    let scene = city(CityScale::Small, 4);
    assert_eq!(scene.meshes[0].name, DETAIL_MESH_NAME);
    let detail = &scene.meshes[0].mesh;
    assert!((60_000..=80_000).contains(&detail.triangle_count()), "{} triangles", detail.triangle_count());
    assert_well_formed("detail", detail);
    let height = detail.bounds().extent().y;
    assert!((2.0..=4.0).contains(&height), "detail is {height} m tall");
    let instances: Vec<_> = scene.objects.iter().filter(|o| o.mesh == 0).collect();
    assert!(instances.len() >= 6 && instances.iter().all(|o| o.name.starts_with("detail_")));
    assert_eq!(scene.meshes.iter().filter(|m| m.mesh == *detail).count(), 1, "stored once");
    // Every building mesh is used by exactly one object.
    let mut uses = vec![0; scene.meshes.len()];
    scene.objects.iter().for_each(|o| uses[o.mesh as usize] += 1);
    assert!(uses[1..].iter().all(|&u| u == 1));
    // Instances differ in pose.
    assert_ne!(instances[0].transform, instances[1].transform);
}

#[test]
fn a_given_detail_model_is_normalised_and_used() {
    // A 200-unit tetrahedron standing below the ground: it must come out 3 m tall, on y = 0.
    let model = Mesh {
        positions: vec![[0.0, -100.0, 0.0], [100.0, -100.0, 0.0], [0.0, -100.0, 100.0], [0.0, 100.0, 0.0]],
        indices: vec![0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2],
    };
    let scene =
        generate(&CityParams { detail_model: Some(model), scale: CityScale::Tiny, ..CityParams::default() }).unwrap();
    let detail = &scene.meshes[0].mesh;
    assert_eq!(detail.triangle_count(), 4);
    let b = detail.bounds();
    assert!((b.extent().y - DETAIL_HEIGHT).abs() < 1e-4 && b.min.y.abs() < 1e-6, "{b:?}");
    let instance = (0..scene.objects.len()).find(|&o| is_detail(&scene, o)).unwrap();
    assert!(scene.object_bounds(instance).min.y.abs() < 1e-3);
    // An empty model falls back to the procedural figure.
    let empty =
        generate(&CityParams { detail_model: Some(Mesh::default()), scale: CityScale::Tiny, ..CityParams::default() })
            .unwrap();
    assert!(empty.meshes[0].mesh.triangle_count() > 60_000);
}
