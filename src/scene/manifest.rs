//! The scene manifest: a JSON file listing base meshes, objects (instances) and the default
//! viewing-cell grid, beside a binary file holding the base meshes' geometry (bincode 2).
//!
//! `city.json` names its geometry file `city.meshes`; JSON keeps the manifest readable and
//! diffable, the binary sidecar keeps millions of triangles compact and fast to load.

use std::path::{Path, PathBuf};

use glam::Mat4;
use serde::{Deserialize, Serialize};

use hdov_storage::{BlobFile, BlobWriter};

use super::{BaseMesh, Mesh, Object, Scene};
use crate::error::{Error, Result};
use crate::grid::ViewGrid;

/// `"format"` value of a scene manifest.
pub const FORMAT: &str = "hdov-scene";
pub const VERSION: u32 = 1;
/// Storage kind tag of the geometry sidecar (a blob file, one bincode record per mesh).
pub const MESHES_KIND: [u8; 4] = *b"MESH";

#[derive(Serialize, Deserialize)]
struct ManifestFile {
    format: String,
    version: u32,
    /// Geometry file, relative to the manifest.
    meshes_file: String,
    meshes: Vec<MeshEntry>,
    objects: Vec<ObjectEntry>,
    grid: Option<ViewGrid>,
}

#[derive(Serialize, Deserialize)]
struct MeshEntry {
    name: String,
    vertices: usize,
    triangles: usize,
}

#[derive(Serialize, Deserialize)]
struct ObjectEntry {
    name: String,
    mesh: u32,
    /// Column-major 4×4.
    transform: [f32; 16],
}

/// Writes `path` (the JSON manifest) and its geometry sidecar (same stem, `.meshes`).
pub fn write(scene: &Scene, path: &Path) -> Result<()> {
    let meshes_path = path.with_extension("meshes");
    let meshes_file = meshes_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let manifest = ManifestFile {
        format: FORMAT.into(),
        version: VERSION,
        meshes_file,
        meshes: scene
            .meshes
            .iter()
            .map(|m| MeshEntry {
                name: m.name.clone(),
                vertices: m.mesh.positions.len(),
                triangles: m.mesh.triangle_count(),
            })
            .collect(),
        objects: scene
            .objects
            .iter()
            .map(|o| ObjectEntry { name: o.name.clone(), mesh: o.mesh, transform: o.transform.to_cols_array() })
            .collect(),
        grid: scene.grid,
    };
    let mut blobs = BlobWriter::create(&meshes_path, MESHES_KIND)?;
    for m in &scene.meshes {
        let bytes = bincode::serde::encode_to_vec(&m.mesh, bincode::config::standard())
            .map_err(|e| Error::bad_file(&meshes_path, format!("encoding mesh '{}': {e}", m.name)))?;
        blobs.append(&bytes)?;
    }
    blobs.finish()?;
    let json = serde_json::to_vec_pretty(&manifest).map_err(|e| Error::bad_file(path, e.to_string()))?;
    std::fs::write(path, json).map_err(|e| Error::io(path, e))
}

/// Reads a manifest and its geometry. Every inconsistency is an error naming the file.
pub fn read(path: &Path) -> Result<Scene> {
    let text = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let m: ManifestFile =
        serde_json::from_slice(&text).map_err(|e| Error::bad_file(path, format!("not a scene manifest: {e}")))?;
    if m.format != FORMAT {
        return Err(Error::bad_file(path, format!("format is '{}', expected '{FORMAT}'", m.format)));
    }
    if m.version != VERSION {
        return Err(Error::bad_file(path, format!("scene manifest version {} (this hdov reads {VERSION})", m.version)));
    }
    let meshes_path: PathBuf = path.parent().unwrap_or(Path::new(".")).join(&m.meshes_file);
    let meshes = read_meshes(&meshes_path)?;
    if meshes.len() != m.meshes.len() {
        return Err(Error::bad_file(
            &meshes_path,
            format!("holds {} meshes, the manifest lists {}", meshes.len(), m.meshes.len()),
        ));
    }
    let mut scene = Scene { grid: m.grid, ..Default::default() };
    for (entry, mesh) in m.meshes.into_iter().zip(meshes) {
        if mesh.triangle_count() != entry.triangles || mesh.positions.len() != entry.vertices {
            return Err(Error::bad_file(&meshes_path, format!("mesh '{}' does not match the manifest", entry.name)));
        }
        scene.meshes.push(BaseMesh { name: entry.name, mesh });
    }
    scene.objects = m
        .objects
        .into_iter()
        .map(|o| Object { name: o.name, mesh: o.mesh, transform: Mat4::from_cols_array(&o.transform) })
        .collect();
    Ok(scene)
}

/// Reads every mesh record of the sidecar, each checked (magic, version, length, crc32).
fn read_meshes(path: &Path) -> Result<Vec<Mesh>> {
    let file = BlobFile::open(path, MESHES_KIND)?;
    file.iter()
        .map(|record| {
            let (_, bytes) = record?;
            let (mesh, _) = bincode::serde::decode_from_slice(bytes, bincode::config::standard())
                .map_err(|e| Error::bad_file(path, format!("decoding a mesh: {e}")))?;
            Ok(mesh)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Aabb;
    use glam::Vec3;

    fn scene() -> Scene {
        let mesh = Mesh { positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], indices: vec![0, 1, 2] };
        Scene {
            meshes: vec![BaseMesh { name: "tri".into(), mesh }],
            objects: vec![
                Object { name: "a".into(), mesh: 0, transform: Mat4::IDENTITY },
                Object { name: "b".into(), mesh: 0, transform: Mat4::from_translation(Vec3::X * 5.0) },
            ],
            grid: Some(ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::splat(6.0)), [2, 1, 2])),
        }
    }

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        write(&scene(), &p).unwrap();
        assert_eq!(read(&p).unwrap(), scene());
    }

    #[test]
    fn corrupted_or_truncated_geometry_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        write(&scene(), &p).unwrap();
        let mp = p.with_extension("meshes");
        let good = std::fs::read(&mp).unwrap();
        let mut flipped = good.clone();
        *flipped.last_mut().unwrap() ^= 0x40;
        std::fs::write(&mp, &flipped).unwrap();
        let err = read(&p).unwrap_err().to_string();
        assert!(err.contains("checksum") && err.contains("s.meshes"), "{err}");
        std::fs::write(&mp, &good[..good.len() - 3]).unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("truncated"));
        std::fs::write(&mp, b"garbage").unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("magic"));
        std::fs::write(&p, b"{\"format\":\"other\"").unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("s.json"));
    }
}
