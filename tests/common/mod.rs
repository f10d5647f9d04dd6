//! Scenes for integration tests, built in code so tests do not depend on the generator.
#![allow(dead_code)]

use glam::{Mat4, Vec3};
use hdov::scene::{BaseMesh, Mesh, Object, Scene};

/// An axis-aligned box mesh from `min` to `max` (12 triangles, outward facing).
pub fn box_mesh(min: Vec3, max: Vec3) -> Mesh {
    let c = |i: usize| {
        [
            if i & 1 == 0 { min.x } else { max.x },
            if i & 2 == 0 { min.y } else { max.y },
            if i & 4 == 0 { min.z } else { max.z },
        ]
    };
    let positions = (0..8).map(c).collect();
    #[rustfmt::skip]
    let indices = vec![
        0, 2, 3, 0, 3, 1, // -z
        4, 5, 7, 4, 7, 6, // +z
        0, 4, 6, 0, 6, 2, // -x
        1, 3, 7, 1, 7, 5, // +x
        0, 1, 5, 0, 5, 4, // -y
        2, 6, 7, 2, 7, 3, // +y
    ];
    Mesh { positions, indices }
}

/// A UV sphere of radius 1 with `2·n²` triangles.
pub fn sphere(n: usize) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..=n {
        for j in 0..=n {
            let (t, f) = (std::f32::consts::PI * i as f32 / n as f32, std::f32::consts::TAU * j as f32 / n as f32);
            m.positions.push([t.sin() * f.cos(), t.cos(), t.sin() * f.sin()]);
        }
    }
    for i in 0..n as u32 {
        for j in 0..n as u32 {
            let a = i * (n as u32 + 1) + j;
            let b = a + n as u32 + 1;
            m.indices.extend([a, b, b + 1, a, b + 1, a + 1]);
        }
    }
    m
}

/// A small town: `n × n` boxes of varied height and a sphere instanced on every other street
/// corner (so instancing is exercised).
pub fn town(n: usize) -> Scene {
    let mut scene = Scene::default();
    scene.meshes.push(BaseMesh { name: "ball".into(), mesh: sphere(24) });
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (i as f32 * 20.0, j as f32 * 20.0);
            let h = 5.0 + ((i * 7 + j * 13) % 11) as f32 * 3.0;
            scene.objects.push(Object {
                name: format!("house_{i}_{j}"),
                mesh: scene.meshes.len() as u32,
                transform: Mat4::IDENTITY,
            });
            scene.meshes.push(BaseMesh {
                name: format!("house_{i}_{j}"),
                mesh: box_mesh(Vec3::new(x, 0.0, z), Vec3::new(x + 12.0, h, z + 12.0)),
            });
            if (i + j) % 2 == 0 {
                scene.objects.push(Object {
                    name: format!("ball_{i}_{j}"),
                    mesh: 0,
                    transform: Mat4::from_translation(Vec3::new(x + 16.0, 1.0, z + 16.0)),
                });
            }
        }
    }
    scene
}
