//! The CPU backend's two-level BVH (instances of a base mesh traced in model space) against the
//! same geometry baked into world space, one base mesh per object (the flat path).

mod dov_common;

use dov_common::*;
use glam::{Mat4, Quat, Vec3};
use hdov::dov::{BACK_FACE_BIT, CpuBackend, DovBackend, IdCube, NO_OBJECT};
use hdov::scene::{BaseMesh, Mesh, Object, Scene};

/// Instances of one icosphere and one cube around the origin under varied transforms: plain
/// translations, random rotations, non-uniform scales, and mirroring scales (one or three negative
/// axes), plus a ground slab, a cube flattened to a square (a singular transform) below the
/// origin; object 1 is a big box around the viewpoint `inside`.
fn instanced_scene() -> (Scene, Vec3) {
    let mut rng = Rng(7);
    let mut b = SceneBuilder::default();
    let sphere = b.mesh("sphere", icosphere(3));
    let cube = b.mesh("cube", unit_cube());
    b.aabox(Vec3::new(-40.0, -4.0, -40.0), Vec3::new(40.0, -3.0, 40.0));
    let inside = Vec3::new(15.0, 2.0, -12.0);
    b.object(cube, Mat4::from_scale_rotation_translation(Vec3::new(4.0, 3.0, 5.0), Quat::from_rotation_y(0.3), inside));
    // A flattened (singular) transform: traced in world space, not as an instance.
    let flat = b.object(
        cube,
        Mat4::from_scale_rotation_translation(Vec3::new(6.0, 0.0, 6.0), Quat::IDENTITY, Vec3::new(0.0, -2.0, 0.0)),
    );
    while b.scene.objects.len() < 120 {
        let i = b.scene.objects.len();
        let c = Vec3::new(rng.range(-20.0, 20.0), rng.range(-2.0, 8.0), rng.range(-20.0, 20.0));
        if c.length() < 5.0 || (c - inside).length() < 8.0 {
            continue;
        }
        let axis = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize_or(Vec3::Y);
        let rotation = if i % 4 == 0 {
            Quat::IDENTITY
        } else {
            Quat::from_axis_angle(axis, rng.range(0.0, std::f32::consts::TAU))
        };
        let mut scale = match i % 3 {
            0 => Vec3::splat(rng.range(0.5, 2.0)),
            _ => Vec3::new(rng.range(0.3, 3.0), rng.range(0.3, 3.0), rng.range(0.3, 3.0)),
        };
        match i % 5 {
            1 => scale.x = -scale.x,
            3 => scale = -scale,
            _ => {}
        }
        b.object(if i % 2 == 0 { sphere } else { cube }, Mat4::from_scale_rotation_translation(scale, rotation, c));
    }
    assert_eq!(flat, 2);
    (b.build(), inside)
}

/// The flattened cube of [`instanced_scene`]: its bottom face lies on its top face, so about half
/// of its texels show a back face.
const FLATTENED: u32 = 2;

/// Every object as its own base mesh, already in world space (identity transform); mirrored
/// objects get their winding flipped so that counter-clockwise still faces outwards.
fn baked(scene: &Scene) -> Scene {
    let mut out = Scene::default();
    for (i, o) in scene.objects.iter().enumerate() {
        let mesh = scene.object_mesh(i);
        let positions = mesh.positions.iter().map(|p| o.transform.transform_point3(Vec3::from(*p)).into()).collect();
        let mut indices = mesh.indices.clone();
        if o.transform.determinant() < 0.0 {
            indices.chunks_exact_mut(3).for_each(|t| t.swap(1, 2));
        }
        out.meshes.push(BaseMesh { name: o.name.clone(), mesh: Mesh { positions, indices } });
        out.objects.push(Object { name: o.name.clone(), mesh: i as u32, transform: Mat4::IDENTITY });
    }
    out.check().unwrap();
    out
}

fn render(backend: &mut CpuBackend, p: Vec3) -> IdCube {
    let mut ids = IdCube::new(backend.resolution());
    backend.render_ids(p, &mut ids).unwrap();
    ids
}

#[test]
fn instances_trace_like_baked_world_meshes() {
    let (scene, inside) = instanced_scene();
    let flat = baked(&scene);
    let near = hdov::dov::default_near(&scene.bounds());
    let r = 128;
    let mut two_level = CpuBackend::with_near(&scene, r, near).unwrap();
    let mut world = CpuBackend::with_near(&flat, r, near).unwrap();
    assert_eq!(two_level.name(), world.name());
    for p in [Vec3::ZERO, Vec3::new(-3.0, 5.0, 2.5), inside] {
        let (a, b) = (render(&mut two_level, p), render(&mut world, p));
        let differ: Vec<usize> = (0..a.ids.len()).filter(|&i| a.ids[i] != b.ids[i]).collect();
        let seen: std::collections::BTreeSet<u32> =
            a.ids.iter().filter(|&&id| id != NO_OBJECT).map(|id| id & !BACK_FACE_BIT).collect();
        let back = a
            .ids
            .iter()
            .filter(|&&id| id != NO_OBJECT && id & BACK_FACE_BIT != 0 && id & !BACK_FACE_BIT != FLATTENED)
            .count();
        println!(
            "viewpoint {p}: {} of {} texels differ, {} objects seen, {back} back-face texels",
            differ.len(),
            a.ids.len(),
            seen.len()
        );
        for &i in differ.iter().take(8) {
            println!("  texel {i}: two-level {:#x}, world {:#x}", a.ids[i], b.ids[i]);
        }
        // Rays through a shared edge of two triangles, or grazing a silhouette, may come out either
        // way when the triangle is intersected in model rather than world coordinates (rounding).
        assert!(differ.len() <= 6, "{p}: {} texels differ", differ.len());
        if p == inside {
            assert_eq!(seen.len(), 1, "inside: {seen:?}");
            // Inside the box every texel sees its inner faces.
            assert!(back > a.ids.len() * 9 / 10, "inside: {back} back-face texels");
        } else {
            assert!(seen.len() > 50, "{p}: only {} objects seen", seen.len());
            assert!(back < a.ids.len() / 1000, "{p}: {back} back-face texels outside every object");
        }
    }
}
