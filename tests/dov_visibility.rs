//! Occlusion on both backends: hidden objects get 0, a one-texel hole shows one texel, the DoVs of
//! one point never sum above 1.

use glam::Vec3;
use hdov::dov::{CpuBackend, DovBackend, GpuBackend};
use hdov::scene::Scene;
use hdov_testkit::scenes::*;

type Make = dyn FnMut(&Scene, u32) -> Box<dyn DovBackend>;

fn cpu(s: &Scene, r: u32) -> Box<dyn DovBackend> {
    Box::new(CpuBackend::new(s, r).unwrap())
}

fn gpu(s: &Scene, r: u32) -> Box<dyn DovBackend> {
    Box::new(GpuBackend::new(s, r).unwrap())
}

/// A wall in the plane z = 5 (x, y in [-20, 20]) made of four slabs around a square hole of side
/// `hole` centred at `(hx, hy)`; behind it (z in [8, 10]) the target box, object 0. With
/// `hole = 0` the wall is closed.
fn wall_scene(hx: f32, hy: f32, hole: f32) -> Scene {
    let mut b = SceneBuilder::default();
    b.aabox(Vec3::new(-3.0, -3.0, 8.0), Vec3::new(3.0, 3.0, 10.0));
    let h = hole / 2.0;
    let (z0, z1) = (5.0, 5.05);
    b.aabox(Vec3::new(-20.0, -20.0, z0), Vec3::new(hx - h, 20.0, z1)); // left of the hole
    b.aabox(Vec3::new(hx + h, -20.0, z0), Vec3::new(20.0, 20.0, z1)); // right
    b.aabox(Vec3::new(hx - h, -20.0, z0), Vec3::new(hx + h, hy - h, z1)); // below
    b.aabox(Vec3::new(hx - h, hy + h, z0), Vec3::new(hx + h, 20.0, z1)); // above
    b.build()
}

fn check_hidden_and_hole(make: &mut Make) {
    let r = 128;
    // A texel of the +Z face (face 4) near its centre; its centre direction meets z = 5 at the
    // hole's centre. The hole is 1.5 texels wide there: only this texel's centre passes.
    let (face, row, col) = (4, 61, 70);
    let cube = hdov::dov::CubeMap::new(r);
    let d = cube.texel_direction(face, row, col);
    let at = d * (5.0 / d.z);
    let texel_width = 5.0 * 2.0 / r as f32;

    let closed = wall_scene(at.x, at.y, 0.0);
    let got = make(&closed, r).measure(Vec3::ZERO).unwrap();
    assert_eq!(got.get(0), 0.0, "object behind a closed wall is seen");

    let holed = wall_scene(at.x, at.y, 1.5 * texel_width);
    let mut backend = make(&holed, r);
    let got = backend.measure(Vec3::ZERO).unwrap();
    let one_texel = cube.weight(row, col) / cube.total_weight();
    assert!(got.get(0) > 0.0, "{}: object behind a one-texel hole is not seen", backend.name());
    assert!(
        (got.get(0) - one_texel).abs() < 1e-12,
        "{}: expected exactly one texel ({one_texel}), got {}",
        backend.name(),
        got.get(0)
    );

    // Inside a closed box: object 0 sits in a hollow cube (object 1); the viewer is outside.
    let mut b = SceneBuilder::default();
    b.aabox(Vec3::new(4.0, -0.5, -0.5), Vec3::new(5.0, 0.5, 0.5));
    b.aabox(Vec3::new(3.0, -2.0, -2.0), Vec3::new(6.0, 2.0, 2.0));
    let boxed = b.build();
    let got = make(&boxed, r).measure(Vec3::ZERO).unwrap();
    assert_eq!(got.get(0), 0.0, "object inside a closed box is seen");
    assert!(got.get(1) > 0.0);
}

#[test]
fn cpu_hidden_objects_and_one_texel_hole() {
    check_hidden_and_hole(&mut cpu);
}

#[test]
fn gpu_hidden_objects_and_one_texel_hole() {
    if !gpu_or_skip() {
        return;
    }
    check_hidden_and_hole(&mut gpu);
}

fn check_sums(make: &mut Make) {
    let r = 64;
    let field = box_field(200, 11, false);
    let mut backend = make(&field, r);
    for p in [Vec3::ZERO, Vec3::new(0.5, 0.2, -0.4)] {
        let got = backend.measure(p).unwrap();
        let total = got.total();
        assert!(total <= 1.0 + 1e-12, "sum of DoVs {total} > 1");
        assert!((total + got.empty - 1.0).abs() < 1e-9, "covered + empty = {}", total + got.empty);
    }
    // Inside a closed room every direction hits a wall: the DoVs sum to 1 and all faces are seen
    // from behind (the room's faces point outwards).
    let mut b = SceneBuilder::default();
    b.aabox(Vec3::splat(-10.0), Vec3::splat(10.0));
    b.aabox(Vec3::new(2.0, -1.0, -1.0), Vec3::new(4.0, 1.0, 1.0));
    let room = b.build();
    let got = make(&room, r).measure(Vec3::new(-1.0, 0.5, 0.3)).unwrap();
    assert!((got.total() - 1.0).abs() < 1e-12, "room: DoVs sum to {}", got.total());
    assert!(got.empty == 0.0);
    assert!(got.get(1) > 0.0 && got.back_face > 0.9, "room walls seen from inside: back {}", got.back_face);
}

#[test]
fn cpu_point_dovs_sum_to_at_most_one() {
    check_sums(&mut cpu);
}

#[test]
fn gpu_point_dovs_sum_to_at_most_one() {
    if !gpu_or_skip() {
        return;
    }
    check_sums(&mut gpu);
}

/// Coplanar faces of two objects: the lower object id wins, on both backends, everywhere.
fn check_coplanar_tie(make: &mut Make) {
    let mut b = SceneBuilder::default();
    // Two boxes sharing their front face (x = 3) over the same square; object 0 is the deeper one.
    b.aabox(Vec3::new(3.0, -1.0, -1.0), Vec3::new(5.0, 1.0, 1.0));
    b.aabox(Vec3::new(3.0, -1.0, -1.0), Vec3::new(3.5, 1.0, 1.0));
    let scene = b.build();
    let got = make(&scene, 64).measure(Vec3::ZERO).unwrap();
    assert!(got.get(0) > 0.0);
    assert_eq!(got.get(1), 0.0, "the higher id won a depth tie");
}

#[test]
fn cpu_coplanar_tie_goes_to_lower_id() {
    check_coplanar_tie(&mut cpu);
}

#[test]
fn gpu_coplanar_tie_goes_to_lower_id() {
    if !gpu_or_skip() {
        return;
    }
    check_coplanar_tie(&mut gpu);
}
