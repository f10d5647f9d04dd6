//! The CPU backend's fast path (`render_ids`: tiles, previous-hit bound, direct BLAS) against the
//! reference tracer (`render_ids_reference`: one plain obvhs traversal per texel): the same id
//! cube, texel for texel — except where a ray meets two surfaces at its nearest depth up to
//! rounding and both answers are among them — on random small scenes built to hit the hard cases — boxes on a coarse
//! integer lattice (shared and coplanar faces between objects), exact duplicates (ties at equal
//! t), instances of one mesh next to world-space copies, a flattened (two-sided, singular) box,
//! and viewpoints on faces or within the near distance of them.

use glam::{Mat4, Vec3};
use hdov::dov::{CpuBackend, DovBackend, IdCube};
use hdov_testkit::scenes::*;
use proptest::prelude::*;

/// One object of a random scene: a box from lattice corner `min` with lattice size `size`.
#[derive(Clone, Debug)]
struct BoxSpec {
    min: [i8; 3],
    size: [u8; 3],
    /// 0: a world-space box; 1: an instance of the shared unit cube; 2: a world box plus an exact
    /// duplicate (a tie at equal t); 3: an instance flattened to a square (singular transform).
    kind: u8,
}

fn box_spec() -> impl Strategy<Value = BoxSpec> {
    ([-2i8..4, -2..4, -2..4], [1u8..4, 1..4, 1..4], 0u8..4).prop_map(|(min, size, kind)| BoxSpec { min, size, kind })
}

fn scene_of(specs: &[BoxSpec]) -> hdov::scene::Scene {
    let mut b = SceneBuilder::default();
    let cube = b.mesh("cube", unit_cube());
    for s in specs {
        let min = Vec3::new(s.min[0] as f32, s.min[1] as f32, s.min[2] as f32);
        let size = Vec3::new(s.size[0] as f32, s.size[1] as f32, s.size[2] as f32);
        match s.kind {
            0 => {
                b.aabox(min, min + size);
            }
            1 => {
                b.object(cube, Mat4::from_translation(min + 0.5 * size) * Mat4::from_scale(size));
            }
            2 => {
                b.aabox(min, min + size);
                b.aabox(min, min + size);
            }
            _ => {
                let flat = Vec3::new(size.x, 0.0, size.z);
                b.object(cube, Mat4::from_translation(min + 0.5 * flat) * Mat4::from_scale(flat));
            }
        }
    }
    // Two uses of the cube make it an instanced base mesh (a TLAS with several instances).
    b.object(cube, Mat4::from_translation(Vec3::splat(-6.0)));
    b.object(cube, Mat4::from_translation(Vec3::splat(9.0)));
    b.build()
}

/// A viewpoint: a lattice point (on faces and edges) moved by `offset` multiples of `near` along
/// each axis (inside, at and just beyond the near distance of a face), or a generic point.
fn viewpoint() -> impl Strategy<Value = (Vec3, f32)> {
    let lattice = ([-2i8..6, -2..6, -2..6], [-3i8..4, -3..4, -3..4]);
    let near = prop_oneof![Just(1e-3f32), Just(0.05), Just(0.3)];
    (lattice, near, any::<bool>(), [-3.0f32..6.0, -3.0..6.0, -3.0..6.0]).prop_map(|((p, off), near, generic, g)| {
        if generic {
            (Vec3::from(g), near)
        } else {
            let at = |i: usize| p[i] as f32 + off[i] as f32 * 0.5 * near;
            (Vec3::new(at(0), at(1), at(2)), near)
        }
    })
}

/// The direction of texel `i` of the backend's id cube (faces, rows, columns in cube order).
fn texel_direction(backend: &CpuBackend, i: usize) -> Vec3 {
    let r = backend.resolution() as usize;
    backend.cube_map().texel_direction(i / (r * r), ((i / r) % r) as u32, (i % r) as u32)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    #[test]
    fn fast_path_equals_reference_tracer(
        specs in prop::collection::vec(box_spec(), 1..10),
        (p, near) in viewpoint(),
        r in prop_oneof![Just(5u32), Just(8), Just(13)],
    ) {
        let scene = scene_of(&specs);
        let mut backend = CpuBackend::with_near(&scene, r, near).unwrap();
        let mut reference = IdCube::new(r);
        backend.render_ids_reference(p, &mut reference).unwrap();
        for wide in [false, true] {
            backend.set_wide_instructions(wide);
            let mut fast = IdCube::new(r);
            backend.render_ids(p, &mut fast).unwrap();
            // Equal ids, except where surfaces tie up to rounding (a viewpoint within `near` of
            // coplanar faces): there both answers must be among the tied surfaces.
            let differing: Vec<usize> = (0..fast.ids.len())
                .filter(|&i| fast.ids[i] != reference.ids[i])
                .filter(|&i| {
                    let tied = backend.surfaces_at_nearest(p, texel_direction(&backend, i));
                    !(tied.len() >= 2 && tied.contains(&fast.ids[i]) && tied.contains(&reference.ids[i]))
                })
                .collect();
            prop_assert!(differing.is_empty(), "wide {wide}: {} texels differ, first at {:?}", differing.len(), differing.first());
        }
    }
}

/// A scene with many objects per ray (the engine-like case the previous-hit bound is for): the
/// fast path on a 1-thread pool and on the default pool, portable and wide, all equal the reference.
#[test]
fn fast_path_equals_reference_on_a_box_field_on_any_pool() {
    let scene = box_field(300, 11, true);
    let r = 32;
    let mut backend = CpuBackend::new(&scene, r).unwrap();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    for p in [Vec3::new(0.0, 1.5, 0.0), Vec3::new(13.0, 4.0, -7.0)] {
        let mut reference = IdCube::new(r);
        backend.render_ids_reference(p, &mut reference).unwrap();
        assert!(reference.ids.iter().filter(|&&id| id != hdov::dov::NO_OBJECT).count() > 100, "the point sees objects");
        for wide in [false, true] {
            backend.set_wide_instructions(wide);
            let (mut fast, mut pooled) = (IdCube::new(r), IdCube::new(r));
            one.install(|| backend.render_ids(p, &mut fast)).unwrap();
            backend.render_ids(p, &mut pooled).unwrap();
            assert_eq!(fast.ids, reference.ids, "wide {wide}, one thread");
            assert_eq!(pooled.ids, reference.ids, "wide {wide}, default pool");
        }
    }
}
