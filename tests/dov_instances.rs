//! Instanced geometry against the same geometry baked into world space, one base mesh per object
//! (the flat path): the CPU backend's two-level BVH (instances traced in model space), and the
//! GPU backend's instanced drawing (model-space meshes, per-instance transforms in the shader).

use glam::{Mat4, Quat, Vec3, Vec4};
use hdov::dov::gpu::GpuOptions;
use hdov::dov::{BACK_FACE_BIT, CpuBackend, DovBackend, GpuBackend, IdCube, NO_OBJECT};
use hdov::geom::max_scale;
use hdov::lod::{LodLevel, LodParams, leaf_chain};
use hdov::scene::{BaseMesh, Mesh, Object, Scene};
use hdov_testkit::scenes::*;

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
        out.objects.push(Object { name: o.name.clone(), mesh: i as u32, transform: Mat4::IDENTITY, part: None });
    }
    out.check().unwrap();
    out
}

fn render(backend: &mut dyn DovBackend, p: Vec3) -> IdCube {
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

/// Base meshes whose coordinates are multiples of 1/64 (a snapped icosphere, the unit cube, a
/// slab), instanced under signed axis permutations with power-of-two scales (mirroring ones
/// included) and translations in 1/8 steps; object 1 is a big cube around the viewpoint
/// `inside`, objects 2 and 3 a cube and a slab (different base meshes) whose top faces are
/// coplanar. Every product and sum in transforming these meshes is exact in f32 — on the CPU
/// and in a shader, fused or not — so baked and instanced positions are bit-identical, and any
/// texel that differs is the drawing's fault, not rounding's.
fn exact_scene() -> (Scene, Vec3) {
    let mut rng = Rng(11);
    let mut b = SceneBuilder::default();
    let mut ball = icosphere(2);
    ball.positions.iter_mut().for_each(|p| *p = p.map(|c| (c * 64.0).round() / 64.0));
    let ball = b.mesh("ball", ball);
    let cube = b.mesh("cube", unit_cube());
    let mut slab = unit_cube();
    slab.positions.iter_mut().for_each(|p| *p = [p[0] * 4.0, p[1] * 0.5, p[2] * 4.0]);
    let slab = b.mesh("slab", slab);
    b.aabox(Vec3::new(-32.0, -4.0, -32.0), Vec3::new(32.0, -3.0, 32.0));
    let inside = Vec3::new(15.0, 2.0, -12.0);
    b.object(cube, Mat4::from_scale_rotation_translation(Vec3::splat(8.0), Quat::IDENTITY, inside));
    // Top faces at y = 1.25: the cube's (scale 2, centre y 0.25), the slab's (half height 0.25).
    b.object(cube, Mat4::from_scale_rotation_translation(Vec3::splat(2.0), Quat::IDENTITY, Vec3::new(-6.0, 0.25, 6.0)));
    b.object(slab, Mat4::from_translation(Vec3::new(-6.5, 1.0, 6.5)));
    let permutations = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    while b.scene.objects.len() < 150 {
        let i = b.scene.objects.len();
        let c = Vec3::new(rng.range(-20.0, 20.0), rng.range(-2.0, 8.0), rng.range(-20.0, 20.0))
            .map(|x| (x * 8.0).round() / 8.0);
        if c.length() < 5.0 || (c - inside).length() < 10.0 || (c - Vec3::new(-6.0, 0.0, 6.0)).length() < 5.0 {
            continue;
        }
        let perm = permutations[(rng.next_f32() * 6.0) as usize % 6];
        let mut cols = [Vec4::ZERO; 3];
        for (j, col) in cols.iter_mut().enumerate() {
            let scale = [0.5, 1.0, 2.0][(rng.next_f32() * 3.0) as usize % 3];
            let sign = if rng.next_f32() < 0.3 { -1.0 } else { 1.0 };
            col[perm[j]] = sign * scale;
        }
        // Runs of the same mesh (consecutive ids share one instanced draw) and changes of mesh.
        let mesh = [ball, ball, ball, cube, slab, ball, cube, cube][i % 8];
        b.object(mesh, Mat4::from_cols(cols[0], cols[1], cols[2], c.extend(1.0)));
    }
    (b.build(), inside)
}

/// `baked` with LOD chains to match: per object its base mesh's chain in world space (winding
/// flipped where the transform mirrors, as the scene's meshes are), errors times the transform's
/// largest axis scale.
fn baked_lods(scene: &Scene, lods: &[Vec<LodLevel>]) -> Vec<Vec<LodLevel>> {
    scene
        .objects
        .iter()
        .map(|o| {
            let m = o.transform;
            let scale = max_scale(&m);
            lods[o.mesh as usize]
                .iter()
                .map(|l| {
                    let mut mesh = l.mesh.transformed(&m);
                    if m.determinant() < 0.0 {
                        mesh.indices.chunks_exact_mut(3).for_each(|t| t.swap(1, 2));
                    }
                    LodLevel { mesh, error: l.error * scale }
                })
                .collect()
        })
        .collect()
}

/// Whether the backend draws through GL.
fn draws_through_gl(backend: &GpuBackend) -> bool {
    backend.adapter_name().ends_with("on Gl")
}

/// Texels where two id cubes differ.
fn differing(a: &IdCube, b: &IdCube) -> Vec<usize> {
    (0..a.ids.len()).filter(|&i| a.ids[i] != b.ids[i]).collect()
}

/// Object ids seen, back-face bit stripped.
fn seen(a: &IdCube) -> std::collections::BTreeSet<u32> {
    a.ids.iter().filter(|&&id| id != NO_OBJECT).map(|id| id & !BACK_FACE_BIT).collect()
}

/// Instanced GPU drawing against the same backend drawing the baked scene (every object its own
/// world-space mesh under the identity transform, i.e. the world-space drawing it replaced):
/// texel for texel equal, with full detail and with LODs, through indirect multi-draws (where
/// the device has them) and direct draws alike. Exact equality is expected because the scene's
/// arithmetic is exact (see `exact_scene`); the CPU backend is not the reference here, since ray
/// casting and rasterisation legitimately disagree on texels along edges.
#[test]
fn gpu_instances_draw_like_baked_world_meshes_texel_for_texel() {
    if !gpu_or_skip() {
        return;
    }
    let (scene, inside) = exact_scene();
    let flat = baked(&scene);
    let lods: Vec<Vec<LodLevel>> = scene.meshes.iter().map(|m| leaf_chain(&m.mesh, &LodParams::default())).collect();
    assert!(lods.iter().any(|c| c.len() > 1), "the ball must have coarser levels");
    let flat_lods = baked_lods(&scene, &lods);
    let near = hdov::dov::default_near(&scene.bounds());
    let r = 96;
    let mirrored: std::collections::BTreeSet<u32> =
        (0..scene.objects.len() as u32).filter(|&o| scene.objects[o as usize].transform.determinant() < 0.0).collect();
    assert!(mirrored.len() > 20, "{} mirrored instances", mirrored.len());
    // Two texels a face, so that coarse levels are drawn at the distances of this scene.
    let tolerance = 2.0;
    let mut full_detail_triangles = 0;
    for with_lods in [false, true] {
        let (lods, flat_lods) = if with_lods { (Some(&lods[..]), Some(&flat_lods[..])) } else { (None, None) };
        let options = |lods, direct_draws| GpuOptions {
            near: Some(near),
            lods,
            lod_tolerance_texels: tolerance,
            direct_draws,
            region_views: 0,
        };
        let mut world = GpuBackend::with_options(&flat, r, &options(flat_lods, true)).unwrap();
        let mut indirect = GpuBackend::with_options(&scene, r, &options(lods, false)).unwrap();
        let mut direct = GpuBackend::with_options(&scene, r, &options(lods, true)).unwrap();
        assert!(!direct.indirect_draws());
        println!("indirect multi-draws on this device: {}", indirect.indirect_draws());
        assert!(indirect.bytes_uploaded() < world.bytes_uploaded(), "instancing must upload less than baking");
        for p in [Vec3::ZERO, Vec3::new(-3.0, 5.0, 2.5), Vec3::new(-6.0, 9.0, 6.0), inside] {
            let expected = render(&mut world, p);
            for backend in [&mut indirect, &mut direct] {
                let got = render(backend, p);
                let differ = differing(&got, &expected);
                for &i in differ.iter().take(8) {
                    println!("  {p} texel {i}: instanced {:#x}, baked {:#x}", got.ids[i], expected.ids[i]);
                }
                // llvmpipe through GL (not lavapipe, nor any Vulkan driver seen here) gives a
                // pixel centre lying exactly on a shared edge, which this dyadic scene makes
                // common, sometimes to neither of the two triangles sharing it, so the object's
                // inside shows through: 6 texels of a row of the instanced drawing at (−3, 5, 2.5),
                // 1 of the baked one at (−6, 9, 6) with LODs. The driver's fill rule, then, not
                // instancing (the baked drawing has it too); on GL only, such texels (same
                // object, only the back-face bit differs) may differ, at most 1 in 5,000. Any
                // other difference fails everywhere.
                let gl = draws_through_gl(backend);
                let tie = |&i: &usize| gl && (got.ids[i] ^ expected.ids[i]) == BACK_FACE_BIT;
                let ties = differ.iter().filter(|i| tie(i)).count();
                assert!(
                    differ.len() == ties && ties * 5_000 <= got.ids.len(),
                    "LODs {with_lods}, {p}: {} texels differ ({ties} edge ties on GL)",
                    differ.len()
                );
            }
            let objects = seen(&expected);
            let back = expected.ids.iter().filter(|&&id| id != NO_OBJECT && id & BACK_FACE_BIT != 0).count();
            if p == inside {
                assert_eq!(objects.len(), 1, "inside: {objects:?}");
                assert!(back > expected.ids.len() * 9 / 10, "inside: {back} back-face texels");
            } else {
                assert!(objects.len() > 40, "{p}: only {} objects seen", objects.len());
                assert!(objects.intersection(&mirrored).count() > 10, "{p}: too few mirrored instances seen");
                assert!(back < expected.ids.len() / 1000, "{p}: {back} back-face texels outside every object");
            }
            if p == Vec3::new(-6.0, 9.0, 6.0) {
                // Straight down onto the coplanar tops of the cube (2) and the slab (3): the tie
                // goes to the lower id.
                let (face, row, col) = indirect.cube_map().texel_of_direction(Vec3::NEG_Y).unwrap();
                let r = r as usize;
                assert_eq!(expected.ids[face * r * r + row as usize * r + col as usize], 2);
            }
        }
        assert_eq!(indirect.triangles_drawn(), direct.triangles_drawn());
        assert_eq!(indirect.triangles_drawn(), world.triangles_drawn());
        assert!(
            indirect.draw_commands() < world.draw_commands(),
            "runs of one mesh should share draws: {} vs {}",
            indirect.draw_commands(),
            world.draw_commands()
        );
        if with_lods {
            let drawn = indirect.triangles_drawn();
            assert!(drawn < full_detail_triangles, "coarse levels should be drawn: {drawn} of {full_detail_triangles}");
        } else {
            full_detail_triangles = indirect.triangles_drawn();
        }
    }
}

/// The same comparison on `instanced_scene` (arbitrary rotations and scales): there the shader's
/// transform rounds differently from the CPU's baking, so a few texels along edges may differ.
#[test]
fn gpu_instances_with_arbitrary_rotations_draw_like_baked_world_meshes() {
    if !gpu_or_skip() {
        return;
    }
    let (scene, inside) = instanced_scene();
    let flat = baked(&scene);
    let near = hdov::dov::default_near(&scene.bounds());
    let r = 128;
    let mut instanced = GpuBackend::with_near(&scene, r, near).unwrap();
    let mut world = GpuBackend::with_near(&flat, r, near).unwrap();
    for p in [Vec3::ZERO, Vec3::new(-3.0, 5.0, 2.5), inside] {
        let (a, b) = (render(&mut instanced, p), render(&mut world, p));
        let differ = differing(&a, &b);
        let back = a
            .ids
            .iter()
            .filter(|&&id| id != NO_OBJECT && id & BACK_FACE_BIT != 0 && id & !BACK_FACE_BIT != FLATTENED)
            .count();
        println!("viewpoint {p}: {} of {} texels differ, {back} back-face texels", differ.len(), a.ids.len());
        assert!(differ.len() <= 12, "{p}: {} texels differ", differ.len());
        if p != inside {
            assert!(seen(&a).len() > 50, "{p}: only {} objects seen", seen(&a).len());
            assert!(back < a.ids.len() / 1000, "{p}: {back} back-face texels outside every object");
        }
    }
}
