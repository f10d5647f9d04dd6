//! The scene model: base meshes stored once, objects as instances of them.
//!
//! An object is the unit the R-tree indexes and the DoV is measured for. Its geometry is its base
//! mesh under its transform; many objects may share one base mesh (instances are stored once).

pub mod files;
pub mod gltf;
pub mod manifest;
pub mod obj;
pub mod parts;
pub mod standable;

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::grid::ViewGrid;

/// An indexed triangle mesh in its own (model) space.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Three indices per triangle, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

impl Mesh {
    /// Triangles of the mesh.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The box of its vertices.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.positions.iter().map(|p| Vec3::from(*p)))
    }

    /// The triangles as corner positions.
    pub fn triangles(&self) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        self.indices.chunks_exact(3).map(|t| {
            [
                Vec3::from(self.positions[t[0] as usize]),
                Vec3::from(self.positions[t[1] as usize]),
                Vec3::from(self.positions[t[2] as usize]),
            ]
        })
    }

    /// This mesh with every position mapped by `m` (winding unchanged).
    pub fn transformed(&self, m: &glam::Mat4) -> Mesh {
        Mesh {
            positions: self.positions.iter().map(|p| m.transform_point3((*p).into()).to_array()).collect(),
            indices: self.indices.clone(),
        }
    }

    /// One mesh holding all `parts` (indices shifted).
    pub fn merged(parts: &[Mesh]) -> Mesh {
        let mut out = Mesh::default();
        for p in parts {
            let base = out.positions.len() as u32;
            out.positions.extend_from_slice(&p.positions);
            out.indices.extend(p.indices.iter().map(|i| i + base));
        }
        out
    }

    /// The cube [-0.5, 0.5]³: 8 vertices, 12 triangles, counter-clockwise seen from outside.
    pub fn unit_cube() -> Mesh {
        let positions: Vec<[f32; 3]> =
            (0..8).map(|i: u32| [i & 1, i & 2, i & 4].map(|bit| if bit == 0 { -0.5 } else { 0.5 })).collect();
        let quads: [[u32; 4]; 6] = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let indices = quads.iter().flat_map(|&[a, b, c, d]| [a, b, c, a, c, d]).collect();
        Mesh { positions, indices }
    }

    /// Removes zero-area triangles and returns how many went: they can never be seen, so they
    /// would only cost draw time and LOD bytes (tobj makes them of 1- and 2-vertex faces; CAD
    /// exports carry them). Triangles with out-of-range indices stay, for `check` to report.
    pub(crate) fn drop_degenerate(&mut self) -> usize {
        let before = self.indices.len() / 3;
        let positions = &self.positions;
        let p = |i: u32| Vec3::from(positions[i as usize]);
        let kept: Vec<u32> = self
            .indices
            .chunks_exact(3)
            .filter(|t| {
                !t.iter().all(|&i| (i as usize) < positions.len())
                    || (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])) != Vec3::ZERO
            })
            .flatten()
            .copied()
            .collect();
        self.indices = kept;
        before - self.indices.len() / 3
    }

    /// Checks what every consumer relies on: triangles, finite vertices, whole triangles and
    /// indices in range. Returns the reason of the first violation.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.indices.is_empty() {
            // An empty mesh has no box: it would poison the tree above it.
            return Err(format!("no triangles ({} vertices)", self.positions.len()));
        }
        if let Some(i) = self.positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(format!("vertex {i} has a non-finite coordinate {:?}", self.positions[i]));
        }
        if !self.indices.len().is_multiple_of(3) {
            return Err(format!("{} indices is not a whole number of triangles", self.indices.len()));
        }
        let n = self.positions.len();
        if let Some(&bad) = self.indices.iter().find(|&&i| i as usize >= n) {
            return Err(format!("index {bad} out of range ({n} vertices)"));
        }
        Ok(())
    }
}

/// Object names that stay unique: the first use of a name keeps it, a repeat gets `#k`, the
/// smallest k ≥ 2 that no name of the file and no earlier repeat has (a file with groups `a`,
/// `a`, `a#2` gives `a`, `a#3`, `a#2`).
pub(crate) struct UniqueNames {
    /// Every name the file has, repeated or not.
    in_file: std::collections::HashSet<String>,
    /// Names given so far.
    given: std::collections::HashSet<String>,
    /// Per repeated name, the suffix to try next: n repeats of one name cost O(n), not O(n²).
    next: std::collections::HashMap<String, u64>,
}

impl UniqueNames {
    /// For a file whose names are `names`.
    pub fn new<'a>(names: impl IntoIterator<Item = &'a str>) -> Self {
        UniqueNames {
            in_file: names.into_iter().map(str::to_string).collect(),
            given: Default::default(),
            next: Default::default(),
        }
    }

    /// The unique name for the next use of `name`.
    pub fn give(&mut self, name: &str) -> String {
        let unique = if self.given.contains(name) {
            let k = self.next.entry(name.to_string()).or_insert(2);
            let unique = (*k..)
                .map(|k| format!("{name}#{k}"))
                .find(|n| !self.in_file.contains(n) && !self.given.contains(n))
                .expect("a free suffix exists");
            *k = unique[name.len() + 1..].parse::<u64>().expect("the suffix just written") + 1;
            unique
        } else {
            name.to_string()
        };
        self.given.insert(unique.clone());
        unique
    }
}

/// Geometry stored once and instanced by objects.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaseMesh {
    pub name: String,
    pub mesh: Mesh,
}

/// One instance: a base mesh under a transform, with a unique name (and part).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Object {
    /// The name of the object in the scene's file.
    pub name: String,
    /// Index into [`Scene::meshes`].
    pub mesh: u32,
    pub transform: Mat4,
    /// Which part of the file's object this is, where hdov cut it ([`parts`]); `None`: the
    /// file's object whole.
    #[serde(default)]
    pub part: Option<u32>,
}

/// A static world: base meshes, their instances and, optionally, the viewing-cell grid it brings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    /// Base meshes, each stored once.
    pub meshes: Vec<BaseMesh>,
    /// Objects: instances of base meshes under transforms.
    pub objects: Vec<Object>,
    /// The default viewing-cell grid (the city generator writes one; OBJ files have none).
    pub grid: Option<ViewGrid>,
}

impl Scene {
    /// The whole scene as one mesh: every object's mesh under its transform.
    pub fn merged_mesh(&self) -> Mesh {
        let parts: Vec<Mesh> =
            self.objects.iter().enumerate().map(|(i, o)| self.object_mesh(i).transformed(&o.transform)).collect();
        Mesh::merged(&parts)
    }

    /// Loads a glTF 2.0 file (`.gltf`, `.glb`), an OBJ file or a scene manifest (`.json`), chosen
    /// by extension, and checks it.
    /// The second value holds warnings (e.g. skipped empty OBJ groups).
    pub fn load(path: &std::path::Path) -> Result<(Scene, Vec<String>)> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let (scene, warnings) = match ext.as_str() {
            "json" => (manifest::read(path)?, Vec::new()),
            "obj" => obj::read(path)?,
            "gltf" | "glb" => gltf::read(path)?,
            _ => {
                return Err(Error::bad_file(
                    path,
                    "unknown scene format: expected .gltf, .glb, .obj or .json (a scene manifest)",
                ));
            }
        };
        scene.check().map_err(|reason| Error::bad_file(path, reason))?;
        Ok((scene, warnings))
    }

    /// The base mesh of `object`.
    pub fn object_mesh(&self, object: usize) -> &Mesh {
        &self.meshes[self.objects[object].mesh as usize].mesh
    }

    /// World-space bounds of one object (its mesh box under the transform: conservative).
    pub fn object_bounds(&self, object: usize) -> Aabb {
        self.object_mesh(object).bounds().transformed(&self.objects[object].transform)
    }

    /// World-space bounds of every object, in object order (computes each mesh box once).
    pub fn all_object_bounds(&self) -> Vec<Aabb> {
        let mesh_boxes: Vec<Aabb> = self.meshes.iter().map(|m| m.mesh.bounds()).collect();
        self.objects.iter().map(|o| mesh_boxes[o.mesh as usize].transformed(&o.transform)).collect()
    }

    /// The box of every object under its transform.
    pub fn bounds(&self) -> Aabb {
        self.all_object_bounds().into_iter().fold(Aabb::EMPTY, Aabb::union)
    }

    /// Full-detail triangles of one object, in world space.
    pub fn object_triangles(&self, object: usize) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        let m = self.objects[object].transform;
        self.object_mesh(object).triangles().map(move |t| t.map(|p| m.transform_point3(p)))
    }

    /// [`Scene::object_triangles`] wound counter-clockwise seen from outside: a mirroring
    /// transform (negative determinant) has its winding flipped back.
    pub fn object_faces(&self, object: usize) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        let mirrored = self.objects[object].transform.determinant() < 0.0;
        self.object_triangles(object).map(move |t| if mirrored { [t[0], t[2], t[1]] } else { t })
    }

    /// Faces of every instance at full detail (instances counted each time).
    pub fn triangle_count(&self) -> u64 {
        self.objects.iter().map(|o| self.meshes[o.mesh as usize].mesh.triangle_count() as u64).sum()
    }

    /// Faces of the base meshes (what is stored).
    pub fn stored_triangle_count(&self) -> u64 {
        self.meshes.iter().map(|m| m.mesh.triangle_count() as u64).sum()
    }

    /// Checks the invariants every stage relies on; returns the first violation as one line.
    /// Adds a base mesh; returns its index.
    pub fn add_mesh(&mut self, name: &str, mesh: Mesh) -> u32 {
        self.meshes.push(BaseMesh { name: name.into(), mesh });
        self.meshes.len() as u32 - 1
    }

    /// Adds an object instancing base mesh `mesh` under `transform`; returns its index.
    pub fn add_object(&mut self, name: &str, mesh: u32, transform: Mat4) -> u32 {
        self.objects.push(Object { name: name.into(), mesh, transform, part: None });
        self.objects.len() as u32 - 1
    }

    /// Adds an axis-aligned box object with corners `min` and `max`, an instance of one shared
    /// unit cube (base mesh `"cube"`, added on first use); returns the object's index.
    pub fn add_box(&mut self, name: &str, min: Vec3, max: Vec3) -> u32 {
        let cube = match self.meshes.iter().position(|m| m.name == "cube") {
            Some(i) => i as u32,
            None => self.add_mesh("cube", Mesh::unit_cube()),
        };
        let transform = Mat4::from_scale_rotation_translation(max - min, glam::Quat::IDENTITY, (min + max) * 0.5);
        self.add_object(name, cube, transform)
    }

    /// Checks that the scene can be built: objects exist, meshes are valid and non-empty,
    /// references are in range, transforms finite, names unique, the grid (if any) valid.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.objects.is_empty() {
            return Err("scene has no objects".into());
        }
        for m in &self.meshes {
            m.mesh.check().map_err(|r| format!("mesh '{}': {r}", m.name))?;
        }
        let mut names = std::collections::HashSet::new();
        for o in &self.objects {
            if o.mesh as usize >= self.meshes.len() {
                return Err(format!("object '{}' refers to mesh {} of {}", o.name, o.mesh, self.meshes.len()));
            }
            if !o.transform.is_finite() {
                return Err(format!("object '{}' has a non-finite transform", o.name));
            }
            if !names.insert((o.name.as_str(), o.part)) {
                return Err(match o.part {
                    None => format!("object name '{}' is not unique", o.name),
                    Some(k) => format!("object '{}' has part {k} twice", o.name),
                });
            }
        }
        if let Some(g) = &self.grid {
            g.check()?;
        }
        Ok(())
    }
}
