//! The dense "detail" model instanced across the city, standing in for the thesis's Stanford
//! bunny (69,451 faces): a user's mesh normalised to statue size, or a procedural figure.

use std::collections::HashMap;

use glam::{IVec3, Vec3};

use crate::scene::Mesh;

/// Height a detail model is scaled to, in metres.
pub const DETAIL_HEIGHT: f32 = 3.0;
/// Widest a detail model may be after scaling, in metres (flat models are scaled by width).
pub const DETAIL_MAX_WIDTH: f32 = 5.0;

/// Cells along each cube edge of the procedural figure: 6 faces × 76² cells × 2 triangles =
/// 69,312 triangles, the bunny's size.
const CUBE_CELLS: i32 = 76;

/// `model` scaled uniformly to [`DETAIL_HEIGHT`] tall (or [`DETAIL_MAX_WIDTH`] wide where it is
/// flatter than that allows), centred on the y axis and standing on y = 0. `None` when it has no
/// triangles or no finite, non-zero extent to scale.
pub fn normalise_detail(model: &Mesh) -> Option<Mesh> {
    if model.triangle_count() == 0 || model.check().is_err() {
        return None;
    }
    let bounds = model.bounds();
    let extent = bounds.extent();
    let width = extent.x.max(extent.z);
    let mut scale = if extent.y > 0.0 { DETAIL_HEIGHT / extent.y } else { f32::INFINITY };
    if width > 0.0 {
        scale = scale.min(DETAIL_MAX_WIDTH / width);
    }
    if !scale.is_finite() {
        return None;
    }
    let centre = bounds.center();
    let origin = Vec3::new(centre.x, bounds.min.y, centre.z);
    let positions = model.positions.iter().map(|&p| ((Vec3::from(p) - origin) * scale).to_array()).collect();
    Some(Mesh { positions, indices: model.indices.clone() })
}

/// A closed, outward-facing figure of 69,312 triangles, [`DETAIL_HEIGHT`] tall, standing on
/// y = 0: a subdivided cube projected onto a star-shaped surface (a squat body with a head, two
/// ears and a rippled skin). Star-shaped means every ray from the centre meets the surface
/// once, so the projection keeps the cube's closed, non-self-intersecting topology.
pub fn procedural_detail() -> Mesh {
    let n = CUBE_CELLS;
    let mut positions = Vec::new();
    let mut ids: HashMap<IVec3, u32> = HashMap::new();
    let mut vertex = |lattice: IVec3| -> u32 {
        *ids.entry(lattice).or_insert_with(|| {
            let dir = (lattice.as_vec3() / n as f32 * 2.0 - Vec3::ONE).normalize();
            positions.push((dir * figure_radius(dir)).to_array());
            (positions.len() - 1) as u32
        })
    };
    let mut indices = Vec::with_capacity((6 * n * n * 6) as usize);
    for axis in 0..3 {
        for positive in [false, true] {
            // Tangents (u, v) with u × v pointing out of the face, so (u, v) order is CCW.
            let (mut u, mut v) = (IVec3::ZERO, IVec3::ZERO);
            u[(axis + 1) % 3] = 1;
            v[(axis + 2) % 3] = 1;
            if !positive {
                std::mem::swap(&mut u, &mut v);
            }
            let mut base = IVec3::ZERO;
            base[axis] = if positive { n } else { 0 };
            for i in 0..n {
                for j in 0..n {
                    let corner = |di: i32, dj: i32| base + u * (i + di) + v * (j + dj);
                    let q = [vertex(corner(0, 0)), vertex(corner(1, 0)), vertex(corner(1, 1)), vertex(corner(0, 1))];
                    indices.extend_from_slice(&[q[0], q[1], q[2], q[0], q[2], q[3]]);
                }
            }
        }
    }
    stand_on_ground(Mesh { positions, indices })
}

/// Distance from the figure's centre to its surface along the unit direction `dir`.
fn figure_radius(dir: Vec3) -> f32 {
    // A bump of `height` around direction `centre`, `width` wide (in 1 - cos of the angle).
    let lobe = |centre: Vec3, width: f32, height: f32| height * (-(1.0 - dir.dot(centre.normalize())) / width).exp();
    let body = 1.0 / (dir.x * dir.x / 1.0 + dir.y * dir.y / 0.8 + dir.z * dir.z / 1.3).sqrt();
    let head = lobe(Vec3::new(0.0, 0.8, 0.6), 0.08, 0.45);
    let ears = lobe(Vec3::new(0.25, 1.0, 0.1), 0.012, 0.9) + lobe(Vec3::new(-0.25, 1.0, 0.1), 0.012, 0.9);
    let tail = lobe(Vec3::new(0.0, 0.1, -1.0), 0.02, 0.25);
    let skin = 0.015 * (dir.x * 23.0).sin() * (dir.y * 19.0).sin() * (dir.z * 29.0).sin();
    body + head + ears + tail + skin
}

/// Scales a mesh to [`DETAIL_HEIGHT`] and stands it on y = 0, centred on the y axis.
fn stand_on_ground(mesh: Mesh) -> Mesh {
    normalise_detail(&mesh).expect("the procedural figure has a finite, non-zero extent")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalising_scales_and_stands_the_model_up() {
        let flat =
            Mesh { positions: vec![[10.0, 5.0, 10.0], [30.0, 5.0, 10.0], [10.0, 5.0, 20.0]], indices: vec![0, 1, 2] };
        let m = normalise_detail(&flat).unwrap();
        let b = m.bounds();
        assert!((b.extent().x - DETAIL_MAX_WIDTH).abs() < 1e-4 && b.min.y == 0.0 && b.center().x.abs() < 1e-4);
        let tall =
            Mesh { positions: vec![[0.0, 0.0, 0.0], [1.0, 100.0, 0.0], [0.0, 50.0, 1.0]], indices: vec![0, 1, 2] };
        let b = normalise_detail(&tall).unwrap().bounds();
        assert!((b.extent().y - DETAIL_HEIGHT).abs() < 1e-4 && b.min.y == 0.0);
        assert!(normalise_detail(&Mesh::default()).is_none());
        let point = Mesh { positions: vec![[1.0; 3]; 3], indices: vec![0, 1, 2] };
        assert!(normalise_detail(&point).is_none());
    }
}
