//! Objects from the geometry: a file's objects are what its exporter grouped (one per material
//! in a game level, one slab per storey in a BIM model, one mesh per scan tile), and such an
//! object spans the scene, so that every cell sees some of it and every answer holds all of it.
//! [`split_large_objects`] cuts each object far larger than a cell into spatially coherent parts
//! of bounded extent, and keeps the file's objects where they are already small.
//!
//! Parts are made per base mesh, in model space, so an instanced mesh is cut once and its
//! instances stay instances (of its parts). Every part keeps its source object's name and says
//! which part it is ([`Object::part`]).

use glam::{Vec3, Vec4};

use super::{BaseMesh, Mesh, Object, Scene};
use crate::geom::{Aabb, max_scale};

/// The longest extent a part may have, for cells of edge `cell_edge` (their longest edge): two
/// cells, so that a cell sees parts of about its own neighbourhood. An object is cut only where
/// it is more than twice that ([`split_large_objects`]).
pub fn part_extent_for_cells(cell_edge: f32) -> f32 {
    2.0 * cell_edge
}

/// `scene` with every object whose world extent is more than twice `part_extent` replaced by
/// parts no longer than `part_extent` (where a single triangle is not longer itself): its base
/// mesh's triangles cut in two at the middle of their centres' box along its longest axis, again
/// and again. A base mesh is cut for its largest instance (the largest scale of its transforms),
/// so that every instance of it stays an instance. Object order is kept, parts in place of
/// their object; part meshes are named `MESH [part K]`. Costs O(triangles · log) per cut mesh.
pub fn split_large_objects(scene: &Scene, part_extent: f32) -> Scene {
    // The largest scale each base mesh is drawn at.
    let mut scale = vec![0.0f32; scene.meshes.len()];
    for o in &scene.objects {
        let s = &mut scale[o.mesh as usize];
        *s = s.max(max_scale(&o.transform));
    }
    let mut out = Scene { meshes: Vec::new(), objects: Vec::new(), grid: scene.grid.clone() };
    // The meshes each base mesh became in `out`.
    let mut became: Vec<Vec<u32>> = Vec::with_capacity(scene.meshes.len());
    for (m, base) in scene.meshes.iter().enumerate() {
        let limit = part_extent / scale[m].max(f32::MIN_POSITIVE);
        let parts = if scale[m] > 0.0 && base.mesh.bounds().extent().max_element() > 2.0 * limit {
            cut(&base.mesh, limit)
        } else {
            Vec::new()
        };
        if parts.len() < 2 {
            out.meshes.push(base.clone());
            became.push(vec![out.meshes.len() as u32 - 1]);
            continue;
        }
        let first = out.meshes.len() as u32;
        out.meshes.extend(
            parts.into_iter().enumerate().map(|(k, mesh)| BaseMesh { name: display_name(&base.name, Some(k as u32)), mesh }),
        );
        became.push((first..out.meshes.len() as u32).collect());
    }
    for o in &scene.objects {
        let meshes = &became[o.mesh as usize];
        if meshes.len() == 1 {
            out.objects.push(Object { mesh: meshes[0], ..o.clone() });
            continue;
        }
        out.objects.extend(meshes.iter().enumerate().map(|(k, &mesh)| Object {
            name: o.name.clone(),
            mesh,
            transform: o.transform,
            part: Some(k as u32),
        }));
    }
    out
}

/// `mesh` cut into parts whose triangles' box is at most `limit` long (a part of one triangle
/// may be longer), each with its own vertices; in a fixed order (low side first).
fn cut(mesh: &Mesh, limit: f32) -> Vec<Mesh> {
    let triangles: Vec<[Vec3; 3]> = mesh.triangles().collect();
    let centre = |t: &[Vec3; 3]| (t[0] + t[1] + t[2]) / 3.0;
    let mut parts = Vec::new();
    let mut stack: Vec<Vec<u32>> = vec![(0..triangles.len() as u32).collect()];
    while let Some(set) = stack.pop() {
        let bounds = Aabb::from_points(set.iter().flat_map(|&t| triangles[t as usize]));
        if set.len() <= 1 || bounds.extent().max_element() <= limit {
            parts.push(set);
            continue;
        }
        let centres = Aabb::from_points(set.iter().map(|&t| centre(&triangles[t as usize])));
        let axis = centres.extent().max_position();
        let middle = centres.center()[axis];
        let (mut low, mut high): (Vec<u32>, Vec<u32>) =
            set.iter().partition(|&&t| centre(&triangles[t as usize])[axis] < middle);
        if low.is_empty() || high.is_empty() {
            // Every centre at one place along the axis (a fan around a point): halve by order.
            let mut all = if low.is_empty() { high } else { low };
            high = all.split_off(all.len() / 2);
            low = all;
        }
        // Popped last-in first: push high first so that parts come out low side first.
        stack.push(high);
        stack.push(low);
    }
    parts.into_iter().map(|set| submesh(mesh, &set)).collect()
}

/// The triangles `set` of `mesh` as a mesh of their own vertices, in first-use order.
fn submesh(mesh: &Mesh, set: &[u32]) -> Mesh {
    let mut index_of = std::collections::HashMap::new();
    let mut out = Mesh::default();
    for &t in set {
        for &i in &mesh.indices[3 * t as usize..3 * t as usize + 3] {
            let j = *index_of.entry(i).or_insert_with(|| {
                out.positions.push(mesh.positions[i as usize]);
                out.positions.len() as u32 - 1
            });
            out.indices.push(j);
        }
    }
    out
}

/// How people see a part named: `NAME [part K]` (answers' glTF nodes, part meshes, tools'
/// reports); a whole object by its name alone.
pub fn display_name(name: &str, part: Option<u32>) -> String {
    match part {
        Some(k) => format!("{name} [part {k}]"),
        None => name.to_string(),
    }
}

/// For each object of `scene` (world boxes `bounds`, [`Scene::all_object_bounds`]), the other
/// parts of its file object whose boxes, grown by a thousandth of the larger one's extent, meet
/// its own: where a cut surface goes on. Empty for an object that was not cut. The parts of an
/// object are consecutive, numbered from 0 ([`split_large_objects`]). O(parts²) per cut object.
pub fn part_neighbours(scene: &Scene, bounds: &[Aabb]) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); scene.objects.len()];
    let mut start = 0;
    while start < scene.objects.len() {
        let mut end = start + 1;
        if scene.objects[start].part == Some(0) {
            while end < scene.objects.len() && scene.objects[end].part == Some((end - start) as u32) {
                end += 1;
            }
        }
        for i in start..end {
            for j in i + 1..end {
                let pad = Vec3::splat(1e-3 * bounds[i].extent().max_element().max(bounds[j].extent().max_element()));
                if Aabb::new(bounds[i].min - pad, bounds[i].max + pad).intersects(&bounds[j]) {
                    out[i].push(j as u32);
                    out[j].push(i as u32);
                }
            }
        }
        start = end;
    }
    out
}

/// The most face planes [`part_planes`] lists for one part: a part whose faces turn more ways (a
/// curved or scanned surface) lists none, and [`turns_a_face_to`] counts it as facing every box.
pub const MAX_PART_PLANES: usize = 32;

/// How far apart two planes may be and still be listed once ([`part_planes`]): in their unit
/// normals' components, and in their offsets relative to the larger offset plus one.
const SAME_PLANE: f32 = 1e-5;

/// How far behind a plane a box may lie and still count as in front of it, relative to one plus
/// the plane's offset plus the box's largest coordinate: ten times what listing nearly equal
/// planes once can move `n · p` at a point of the box, so that the facing test errs towards
/// the floor wherever the scene lies.
const PLANE_SLACK: f32 = 10.0 * SAME_PLANE;

/// For each object of `scene` that has neighbouring parts (`neighbours`, [`part_neighbours`]),
/// the planes of its faces, each as its unit normal towards the front (counter-clockwise,
/// [`Scene::object_faces`]) and its offset along it, nearly equal planes once; at most
/// [`MAX_PART_PLANES`], else none. Empty for every other object. O(triangles of cut parts ·
/// planes).
pub fn part_planes(scene: &Scene, neighbours: &[Vec<u32>]) -> Vec<Vec<Vec4>> {
    (0..scene.objects.len())
        .map(|object| {
            if neighbours.get(object).is_none_or(Vec::is_empty) {
                return Vec::new();
            }
            let mut planes: Vec<Vec4> = Vec::new();
            for [a, b, c] in scene.object_faces(object) {
                let n = (b - a).cross(c - a).normalize_or_zero();
                if n == Vec3::ZERO {
                    continue;
                }
                let plane = n.extend(n.dot(a));
                let same = |q: &Vec4| {
                    (q.truncate() - n).abs().max_element() <= SAME_PLANE
                        && (q.w - plane.w).abs() <= SAME_PLANE * (1.0 + q.w.abs().max(plane.w.abs()))
                };
                if !planes.iter().any(same) {
                    if planes.len() == MAX_PART_PLANES {
                        return Vec::new();
                    }
                    planes.push(plane);
                }
            }
            planes
        })
        .collect()
}

/// Whether some face of a part with face planes `planes` ([`part_planes`]) turns its front to
/// some point of `b`: some point of the box lies in front of one of its planes. True for a part
/// that lists no planes. A point behind every plane of a part sees, of it, only backs: through a
/// gap in what lies in front (a sampler's rays find those), never a surface going on past a
/// seen edge, which is what the parts floor is for.
pub fn turns_a_face_to(planes: &[Vec4], b: &Aabb) -> bool {
    let reach = b.min.abs().max(b.max.abs()).max_element();
    planes.is_empty() || planes.iter().any(|q| b.max_along(q.truncate()) > q.w - PLANE_SLACK * (1.0 + q.w.abs() + reach))
}

#[cfg(test)]
mod tests {
    use glam::Mat4;

    use super::*;

    /// A flat `size` × `size` slab at y = 0 of `n` × `n` quads.
    fn slab(size: f32, n: u32) -> Mesh {
        let mut m = Mesh::default();
        for j in 0..=n {
            for i in 0..=n {
                m.positions.push([size * i as f32 / n as f32, 0.0, size * j as f32 / n as f32]);
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                m.indices.extend([a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]);
            }
        }
        m
    }

    fn scene_of(meshes: Vec<Mesh>, objects: &[(&str, u32, Mat4)]) -> Scene {
        let mut s = Scene::default();
        for (k, m) in meshes.into_iter().enumerate() {
            s.add_mesh(&format!("m{k}"), m);
        }
        for &(name, mesh, t) in objects {
            s.add_object(name, mesh, t);
        }
        s
    }

    #[test]
    fn a_slab_far_larger_than_a_cell_is_cut_into_bounded_parts() {
        let scene = scene_of(vec![slab(40.0, 40), Mesh::unit_cube()], &[("floor", 0, Mat4::IDENTITY), ("box", 1, Mat4::IDENTITY)]);
        let split = split_large_objects(&scene, 4.0);
        split.check().unwrap();
        // One mesh cut (the box's stays one), one object cut.
        assert_eq!(split.meshes.iter().filter(|m| m.name.starts_with("m0 [part")).count() + 1, split.meshes.len());
        assert_eq!(split.objects.iter().filter(|o| o.part.is_none()).count(), 1);
        let parts: Vec<&Object> = split.objects.iter().filter(|o| o.name == "floor").collect();
        // 40 m cut at the middle until ≤ 4 m: 16 × 16 parts of 2.5 m.
        assert_eq!(parts.len(), 256);
        for (k, o) in parts.iter().enumerate() {
            assert_eq!(o.part, Some(k as u32));
            assert!(split.object_bounds(split.objects.iter().position(|x| x == *o).unwrap()).extent().max_element() <= 4.0);
        }
        // Nothing lost, nothing doubled; the small object kept whole.
        assert_eq!(split.triangle_count(), scene.triangle_count());
        let whole = split.objects.iter().find(|o| o.name == "box").unwrap();
        assert_eq!(whole.part, None);
        assert_eq!(split.meshes[whole.mesh as usize].mesh, Mesh::unit_cube());
    }

    /// A slab cut into a 4 × 4 lattice of parts: each part's neighbours are the parts its box
    /// touches (edges and corners, 3 to 8 of them), never another object's parts, and an object
    /// left whole has none.
    #[test]
    fn parts_touching_each_other_are_neighbours() {
        let far = Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0));
        let scene = scene_of(
            vec![slab(16.0, 16), Mesh::unit_cube()],
            &[("floor", 0, Mat4::IDENTITY), ("box", 1, Mat4::IDENTITY), ("other", 0, far)],
        );
        let split = split_large_objects(&scene, 4.0);
        let bounds = split.all_object_bounds();
        let neighbours = part_neighbours(&split, &bounds);
        assert_eq!(neighbours.len(), split.objects.len());
        for (i, o) in split.objects.iter().enumerate() {
            let mine = &neighbours[i];
            if o.part.is_none() {
                assert!(mine.is_empty(), "{o:?}");
                continue;
            }
            assert!((3..=8).contains(&mine.len()), "{o:?}: {mine:?}");
            for &j in mine {
                assert_eq!(split.objects[j as usize].name, o.name);
                assert!(neighbours[j as usize].contains(&(i as u32)), "symmetric");
                let gap = (bounds[i].min - bounds[j as usize].max).max(bounds[j as usize].min - bounds[i].max);
                assert!(gap.max_element() <= 1e-3, "{i} and {j} touch");
            }
        }
    }

    #[test]
    fn an_instanced_mesh_is_cut_once_and_its_instances_share_the_parts() {
        let far = Mat4::from_translation(Vec3::new(100.0, 0.0, 0.0));
        let scene = scene_of(vec![slab(20.0, 10)], &[("a", 0, Mat4::IDENTITY), ("b", 0, far)]);
        let split = split_large_objects(&scene, 4.0);
        split.check().unwrap();
        // Both objects cut, into parts of one cut mesh.
        assert!(split.objects.iter().all(|o| o.part.is_some()));
        assert!(split.meshes.iter().all(|m| m.name.starts_with("m0 [part")));
        let meshes_of = |name: &str| -> Vec<u32> { split.objects.iter().filter(|o| o.name == name).map(|o| o.mesh).collect() };
        assert_eq!(meshes_of("a"), meshes_of("b"));
        assert_eq!(split.meshes.len(), meshes_of("a").len());
        assert_eq!(split.stored_triangle_count(), scene.stored_triangle_count());
    }

    #[test]
    fn a_mesh_is_cut_for_its_largest_instance_and_small_objects_stay_whole() {
        // A 6 m slab is within twice 4 m: kept. Scaled by 4 in one instance it is 24 m: cut,
        // for both instances alike.
        let big = Mat4::from_scale(Vec3::splat(4.0));
        let kept = scene_of(vec![slab(6.0, 6)], &[("a", 0, Mat4::IDENTITY)]);
        assert_eq!(split_large_objects(&kept, 4.0), kept);
        let scaled = scene_of(vec![slab(6.0, 6)], &[("a", 0, Mat4::IDENTITY), ("b", 0, big)]);
        let split = split_large_objects(&scaled, 4.0);
        assert!(split.objects.iter().filter(|o| o.name == "b").count() > 1);
        for (i, o) in split.objects.iter().enumerate().filter(|(_, o)| o.name == "b") {
            assert!(split.object_bounds(i).extent().max_element() <= 4.0 + 1e-4, "{o:?}");
        }
    }

    #[test]
    fn one_long_triangle_is_a_part_of_its_own() {
        let mut m = Mesh { positions: vec![[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 0.0, 1.0]], indices: vec![0, 1, 2] };
        m.positions.extend([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]);
        m.indices.extend([3, 4, 5]);
        let scene = scene_of(vec![m], &[("sliver", 0, Mat4::IDENTITY)]);
        let split = split_large_objects(&scene, 4.0);
        assert_eq!(split.objects.len(), 2);
        assert_eq!(split.triangle_count(), 2);
    }

    #[test]
    fn a_slab_s_parts_face_the_boxes_above_it_only() {
        // `slab` is wound counter-clockwise seen from above: every part's one plane is y = 0, up.
        let split = split_large_objects(&scene_of(vec![slab(16.0, 16)], &[("slab", 0, Mat4::IDENTITY)]), 4.0);
        let planes = part_planes(&split, &part_neighbours(&split, &split.all_object_bounds()));
        assert!(split.objects.len() > 1);
        for p in &planes {
            assert_eq!(p.len(), 1);
            assert!((p[0] - Vec4::new(0.0, 1.0, 0.0, 0.0)).abs().max_element() < 1e-6, "{p:?}");
        }
        let cell = |y0: f32, y1: f32| Aabb::new(Vec3::new(1.0, y0, 1.0), Vec3::new(3.0, y1, 3.0));
        assert!(turns_a_face_to(&planes[0], &cell(1.0, 2.0)));
        assert!(turns_a_face_to(&planes[0], &cell(-1.0, 0.5)));
        assert!(!turns_a_face_to(&planes[0], &cell(-2.0, -1.0)));
        // A box whose top lies on the plane sees the faces edge-on: counted as facing them.
        assert!(turns_a_face_to(&planes[0], &cell(-2.0, 0.0)));
        assert!(turns_a_face_to(&[], &cell(-2.0, -1.0)));
    }

    #[test]
    fn far_from_the_origin_faces_turned_apart_stay_apart() {
        // Two faces through one point 14 km out, turned 0.6° apart, both planes 10 km from the
        // origin: listed as two planes (a tolerance relative to the offset merged them), and
        // each is in front of exactly the boxes it is in front of.
        let (a, t) = (0.6f32.to_radians().sin(), 0.6f32.to_radians().cos());
        let far = Vec3::new(10_000.0, 10_000.0, 10_000.0 * (1.0 - t) / a);
        let p = |v: Vec3| (far + v).to_array();
        let m = Mesh {
            positions: vec![
                p(Vec3::ZERO),
                p(Vec3::Z),
                p(Vec3::X),
                p(Vec3::ZERO),
                p(Vec3::new(0.0, -a, t)),
                p(Vec3::new(1.0, 0.0, 0.0)),
            ],
            indices: vec![0, 1, 2, 3, 4, 5],
        };
        let scene = scene_of(vec![m, slab(1.0, 1)], &[("two", 0, Mat4::IDENTITY), ("flat", 1, Mat4::IDENTITY)]);
        let planes = part_planes(&scene, &[vec![1], vec![0]]);
        assert_eq!(planes[0].len(), 2, "{:?}", planes[0]);
        for q in &planes[0] {
            let n = q.truncate();
            let below = Aabb::new(far + Vec3::new(0.0, -31.0, 30.0), far + Vec3::new(1.0, -30.0, 31.0));
            let facing = turns_a_face_to(&[*q], &below);
            assert_eq!(facing, below.max_along(n) > q.w, "{q:?}");
        }
    }

    #[test]
    fn a_part_whose_faces_turn_too_many_ways_lists_no_plane() {
        // A fan of 40 triangles around the y axis, each turned its own way; and one flat one.
        let mut fan = Mesh::default();
        for k in 0..40 {
            let a = k as f32 * std::f32::consts::TAU / 40.0;
            let at = |a: f32, y: f32| [a.cos(), y, a.sin()];
            let first = fan.positions.len() as u32;
            fan.positions.extend([at(a, 0.0), at(a, 1.0), at(a + 0.1, 0.0)]);
            fan.indices.extend([first, first + 1, first + 2]);
        }
        let scene = scene_of(vec![fan, slab(1.0, 1)], &[("fan", 0, Mat4::IDENTITY), ("flat", 1, Mat4::IDENTITY)]);
        let neighbours = vec![vec![1], vec![0]];
        let planes = part_planes(&scene, &neighbours);
        assert!(planes[0].is_empty());
        assert_eq!(planes[1].len(), 1);
        assert!(part_planes(&scene, &[vec![], vec![]]).iter().all(Vec::is_empty));
    }
}
