//! Sub-texel features: a pole a fraction of a texel wide flips between 0 and a full column of
//! texels as the viewpoint moves by less than a texel. Measures the mean and the spread of its
//! DoV under sub-texel jitter of the viewpoint, for widths from 0.25 to 8 texels (numbers in
//! docs/dov.md: `cargo test --test dov_stability -- --nocapture`).

use glam::Vec3;
use hdov::dov::{CpuBackend, CubeMap, DovBackend};
use hdov_testkit::scenes::*;

/// `(width in texels, mean DoV / analytic, coefficient of variation)` for each width.
fn pole_jitter(widths: &[f32]) -> Vec<(f32, f64, f64)> {
    let r = 64;
    let distance = 20.0;
    let texel = 2.0 * distance / r as f32; // world width of a texel at the +Z face's centre
    let height = 10.0 * texel;
    let jitters = 32;
    let cube = CubeMap::new(r);
    widths
        .iter()
        .map(|&w| {
            let half = 0.5 * w * texel;
            let mut b = SceneBuilder::default();
            // A thin upright pole straight ahead on +Z (face 4), its front face at `distance`.
            b.aabox(Vec3::new(-half, -height / 2.0, distance), Vec3::new(half, height / 2.0, distance + 0.1));
            let scene = b.build();
            let mut backend = CpuBackend::new(&scene, r).unwrap();
            // Solid angle of the front rectangle (small-angle approximation is within 0.1 % here).
            let analytic = (w * texel * height) as f64 / (distance as f64).powi(2) / cube.total_weight();
            // Stratified sideways offsets across one texel: the pole's image slides over one
            // texel column.
            let dovs: Vec<f64> = (0..jitters)
                .map(|i| {
                    let dx = ((i as f32 + 0.5) / jitters as f32 - 0.5) * texel;
                    backend.measure(Vec3::new(dx, 0.0, 0.0)).unwrap().get(0)
                })
                .collect();
            let mean = dovs.iter().sum::<f64>() / jitters as f64;
            let var = dovs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / jitters as f64;
            (w, mean / analytic, var.sqrt() / mean)
        })
        .collect()
}

#[test]
fn sub_texel_poles_are_unbiased_on_average_and_flicker_when_thin() {
    let rows = pole_jitter(&[0.25, 0.5, 1.0, 1.5, 2.5, 4.0, 8.0]);
    println!("| width (texels) | mean DoV / analytic | coefficient of variation |");
    for (w, mean, cv) in &rows {
        println!("| {w} | {mean:.3} | {cv:.3} |");
    }
    for &(w, mean, _) in &rows {
        // Averaged over the jitter, coverage is unbiased at every width (texel-centre sampling
        // is a point sampler); edge and height quantisation leave a few percent.
        assert!((mean - 1.0).abs() < 0.1, "width {w}: mean DoV off by {:.1} %", 100.0 * (mean - 1.0));
    }
    // A pole n + f texels wide covers n or n + 1 texel columns (with probabilities 1 − f and f),
    // so its DoV's coefficient of variation is √(f(1 − f)) / (n + f): √3 for a quarter texel,
    // 0 for whole texels.
    for &(w, _, cv) in &rows {
        let f = (w - w.floor()) as f64;
        let want = (f * (1.0 - f)).sqrt() / w as f64;
        assert!((cv - want).abs() < 0.02, "width {w}: CV {cv:.3}, expected {want:.3}");
    }
}

/// A closed room of `n` × `n` quads a wall, each quad two triangles, every wall its own object:
/// shared edges everywhere, along the walls' seams, the quads' sides and their diagonals.
fn closed_room(min: Vec3, max: Vec3, n: usize) -> hdov::scene::Scene {
    let mut b = SceneBuilder::default();
    let size = max - min;
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut positions = Vec::new();
            for i in 0..=n {
                for j in 0..=n {
                    let mut p = [0.0f32; 3];
                    p[axis] = min[axis] + side * size[axis];
                    p[u] = min[u] + size[u] * i as f32 / n as f32;
                    p[v] = min[v] + size[v] * j as f32 / n as f32;
                    positions.push(p);
                }
            }
            let at = |i: usize, j: usize| (i * (n + 1) + j) as u32;
            let mut indices = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    indices.extend([
                        at(i, j),
                        at(i + 1, j),
                        at(i + 1, j + 1),
                        at(i, j),
                        at(i + 1, j + 1),
                        at(i, j + 1),
                    ]);
                }
            }
            let mesh = b.mesh(&format!("wall {axis} {side}"), hdov::Mesh { positions, indices });
            b.object(mesh, glam::Mat4::IDENTITY);
        }
    }
    b.build()
}

/// A ray cannot pass between two triangles that share an edge: from inside a closed room every
/// texel shows a wall. Rays through seams are not rare where a scene and its viewpoints lie on a
/// grid (game levels are built on one): from a viewpoint at the room's centre the diagonals of
/// its quads run through texel centres, and from points on the grid so do its seams. A test that
/// rejects a ray through an edge by the sign of a rounding error lets such rays through both
/// triangles, and the truth then shows what lies behind a wall (docs/dov.md, "Watertight
/// triangles").
#[test]
fn a_closed_room_shows_no_seam_from_inside() {
    let scene = closed_room(Vec3::new(-2.0, -1.5, -3.0), Vec3::new(4.0, 2.5, 3.0), 6);
    for r in [64, 256] {
        let mut backend = CpuBackend::new(&scene, r).unwrap();
        for eye in [Vec3::ZERO, Vec3::new(1.0, 0.5, 0.0), Vec3::new(0.25, -0.125, 1.5), Vec3::new(3.0, 1.5, -2.0)] {
            let mut ids = hdov::IdCube::new(r);
            backend.render_ids(eye, &mut ids).unwrap();
            let leaks = (0..ids.ids.len()).filter(|&t| ids.object_at(t).is_none()).count();
            assert_eq!(leaks, 0, "R = {r}, eye {eye}: {leaks} texels see through a seam");
            let mut reference = hdov::IdCube::new(r);
            backend.render_ids_reference(eye, &mut reference).unwrap();
            let leaks = (0..reference.ids.len()).filter(|&t| reference.object_at(t).is_none()).count();
            assert_eq!(leaks, 0, "R = {r}, eye {eye}: the reference tracer sees through {leaks} texels");
        }
    }
}

/// A ray through the edge of a solid meets the face it sees and, at the same distance, the face
/// behind the edge (the watertight test hits both): the face it sees wins the tie, whatever the
/// objects' order. The eye stands where texel centres of a 64² cube map line up with the box's
/// near edges (u = v = 17/64 on the +z face), each face of the box its own object, the sides
/// numbered before the front.
#[test]
fn a_solid_seen_along_its_edges_shows_its_faces_not_their_backs() {
    let mut b = SceneBuilder::default();
    let (lo, hi) = (Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, 1.0, 4.0));
    let corner = |k: usize| Vec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][k >> 1 & 1], [lo.z, hi.z][k >> 2]);
    // Faces by corner indices, counter-clockwise from outside: +x, +y, −x, −y, +z (far), −z (front).
    let faces = [[1, 3, 7, 5], [2, 6, 7, 3], [0, 4, 6, 2], [0, 1, 5, 4], [4, 5, 7, 6], [0, 2, 3, 1]];
    for (k, f) in faces.iter().enumerate() {
        let positions = f.iter().map(|&c| corner(c).to_array()).collect();
        let mesh = b.mesh(&format!("face {k}"), hdov::Mesh { positions, indices: vec![0, 1, 2, 0, 2, 3] });
        b.object(mesh, glam::Mat4::IDENTITY);
    }
    let scene = b.build();
    let mut backend = CpuBackend::new(&scene, 64).unwrap();
    let eye = Vec3::new(1.0 - 2.0 * 17.0 / 64.0, 1.0 - 2.0 * 17.0 / 64.0, 0.0);
    let mut ids = hdov::IdCube::new(64);
    backend.render_ids(eye, &mut ids).unwrap();
    let front = (0..ids.ids.len()).filter(|&t| ids.object_at(t) == Some(5)).count();
    let backs = (0..ids.ids.len())
        .filter(|&t| ids.object_at(t).is_some() && ids.ids[t] & hdov::dov::BACK_FACE_BIT != 0)
        .count();
    assert!(front > 100, "the front face shows in {front} texels");
    assert_eq!(backs, 0, "{backs} texels show a face of the box from behind");
}
