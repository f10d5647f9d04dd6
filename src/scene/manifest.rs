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
use crate::overwrite::Overwrite;

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

/// Whether `path` is a scene manifest written by hdov (its `"format"` says so).
fn is_scene_manifest(path: &Path) -> bool {
    #[derive(Deserialize)]
    struct Head {
        format: String,
    }
    std::fs::read(path).is_ok_and(|b| serde_json::from_slice::<Head>(&b).is_ok_and(|h| h.format == FORMAT))
}

/// Refuses to overwrite `path` unless `overwrite` allows ours and `ours` says hdov wrote it.
fn claim(path: &Path, overwrite: Overwrite, ours: bool) -> Result<()> {
    if std::fs::symlink_metadata(path).is_err() {
        return Ok(());
    }
    let path_s = path.display().to_string();
    match (overwrite == Overwrite::Ours, ours) {
        (false, _) => Err(hdov_storage::Error::Exists { path: path_s }.into()),
        (true, false) => Err(hdov_storage::Error::NotOurs { path: path_s }.into()),
        (true, true) => Ok(()),
    }
}

/// Writes `bytes` to a temporary file beside `path`, syncs it and renames it into place, so
/// `path` is always either the old file or the new one.
fn replace_file(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let temp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let result = write(&temp).and_then(|()| std::fs::rename(&temp, path).map_err(|e| Error::io(path, e)));
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

impl Scene {
    /// Writes the scene as a manifest at `path` and its geometry sidecar: see [`write`].
    pub fn write_manifest(&self, path: &Path, overwrite: Overwrite) -> Result<()> {
        write(self, path, overwrite)
    }
}

/// Writes `path` (the JSON manifest) and its geometry sidecar (same stem, `.meshes`). Existing
/// files are refused unless `overwrite` is [`Overwrite::Ours`] and they are a scene manifest and mesh file of hdov's;
/// each is replaced whole (written beside it, synced, renamed).
pub fn write(scene: &Scene, path: &Path, overwrite: Overwrite) -> Result<()> {
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
        grid: scene.grid.clone(),
    };
    claim(path, overwrite, is_scene_manifest(path))?;
    claim(&meshes_path, overwrite, BlobFile::open(&meshes_path, MESHES_KIND).is_ok())?;
    replace_file(&meshes_path, |temp| {
        let mut blobs = BlobWriter::create(temp, MESHES_KIND)?;
        for m in &scene.meshes {
            let bytes = crate::record::encode(&m.mesh, &meshes_path)?;
            blobs.append(&bytes)?;
        }
        blobs.finish()?;
        Ok(())
    })?;
    let json = serde_json::to_vec_pretty(&manifest).map_err(|e| Error::bad_file(path, e.to_string()))?;
    replace_file(path, |temp| Ok(hdov_storage::write_file_synced(temp, &json)?))
}

/// Reads a manifest and its geometry. Every inconsistency is an error naming the file.
pub fn read(path: &Path) -> Result<Scene> {
    let text = super::files::read_whole(path)?;
    let m: ManifestFile =
        serde_json::from_slice(&text).map_err(|e| Error::bad_file(path, format!("not a scene manifest: {e}")))?;
    if m.format != FORMAT {
        return Err(Error::bad_file(path, format!("format is '{}', expected '{FORMAT}'", m.format)));
    }
    if m.version != VERSION {
        return Err(Error::bad_file(path, format!("scene manifest version {} (this hdov reads {VERSION})", m.version)));
    }
    let meshes_path: PathBuf = super::files::beside(path, &m.meshes_file)?;
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
        .map(|o| Object { name: o.name, mesh: o.mesh, transform: Mat4::from_cols_array(&o.transform), part: None })
        .collect();
    Ok(scene)
}

/// Reads every mesh record of the sidecar, each checked (magic, version, length, crc32).
fn read_meshes(path: &Path) -> Result<Vec<Mesh>> {
    let file = BlobFile::open(path, MESHES_KIND)?;
    file.iter()
        .map(|record| {
            let (_, bytes) = record?;
            crate::record::decode(bytes, path, "mesh")
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
                Object { name: "a".into(), mesh: 0, transform: Mat4::IDENTITY, part: None },
                Object { name: "b".into(), mesh: 0, transform: Mat4::from_translation(Vec3::X * 5.0), part: None },
            ],
            grid: Some(ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::splat(6.0)), [2, 1, 2])),
        }
    }

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        write(&scene(), &p, Overwrite::Never).unwrap();
        assert_eq!(read(&p).unwrap(), scene());
    }

    #[test]
    fn existing_files_are_replaced_only_if_ours() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        write(&scene(), &p, Overwrite::Never).unwrap();
        let err = write(&scene(), &p, Overwrite::Never).unwrap_err().to_string();
        assert!(err.ends_with("s.json: exists"), "{err}");
        write(&scene(), &p, Overwrite::Ours).unwrap();
        // A user's file with the sidecar's name survives, as does one with the manifest's.
        std::fs::write(p.with_extension("meshes"), b"my notes").unwrap();
        let err = write(&scene(), &p, Overwrite::Ours).unwrap_err().to_string();
        assert!(err.contains("s.meshes") && err.contains("refusing"), "{err}");
        assert_eq!(std::fs::read(p.with_extension("meshes")).unwrap(), b"my notes");
        let q = dir.path().join("mine.json");
        std::fs::write(&q, b"{\"format\": \"not hdov\"}").unwrap();
        assert!(write(&scene(), &q, Overwrite::Ours).unwrap_err().to_string().contains("refusing"));
        assert_eq!(std::fs::read(&q).unwrap(), b"{\"format\": \"not hdov\"}");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 3, "no temporary files left: {names:?}");
    }

    #[test]
    fn corrupted_or_truncated_geometry_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        write(&scene(), &p, Overwrite::Never).unwrap();
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

    #[test]
    fn a_meshes_file_outside_the_scene_folder_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let inner = dir.path().join("scene");
        std::fs::create_dir(&inner).unwrap();
        let p = inner.join("s.json");
        write(&scene(), &p, Overwrite::Never).unwrap();
        std::fs::copy(p.with_extension("meshes"), dir.path().join("s.meshes")).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        for name in ["../s.meshes", "/etc/hostname"] {
            std::fs::write(&p, text.replace("\"s.meshes\"", &format!("{name:?}"))).unwrap();
            let err = read(&p).unwrap_err().to_string();
            assert!(err.contains("s.json") && err.contains(name) && !err.contains('\n'), "{name}: {err}");
        }
    }
}
