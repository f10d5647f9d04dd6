//! Wavefront OBJ import: each `o`/`g` group becomes one object (identity transform, its own base
//! mesh); polygons are triangulated. Materials, normals and texture coordinates are ignored:
//! visibility needs positions only.

use std::io::BufReader;
use std::path::Path;

use glam::Mat4;

use super::{BaseMesh, Mesh, Object, Scene};
use crate::error::{Error, Result};

/// Reads an OBJ file. Groups without faces are skipped, each with a warning in the second value.
pub fn read(path: &Path) -> Result<(Scene, Vec<String>)> {
    let bytes = super::files::read_whole(path)?;
    // Exporters write group names in legacy 8-bit encodings; tobj needs UTF-8 lines.
    let text = String::from_utf8_lossy(&bytes);
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    // Materials do not matter for visibility; a missing .mtl must not fail the import.
    let (models, _materials) = tobj::load_obj_buf(&mut BufReader::new(text.as_bytes()), &options, |_| {
        Err(tobj::LoadError::MaterialParseError)
    })
    .map_err(|e| Error::bad_file(path, format!("malformed OBJ: {e}")))?;

    let mut warnings = Vec::new();
    let mut scene = Scene::default();
    let group_name = |name: &str| if name.is_empty() { "unnamed".to_string() } else { name.to_string() };
    let file_names: Vec<String> = models.iter().map(|m| group_name(&m.name)).collect();
    let mut names = super::UniqueNames::new(file_names.iter().map(String::as_str));
    for model in models {
        let m = model.mesh;
        let group = group_name(&model.name);
        let mut mesh =
            Mesh { positions: m.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(), indices: m.indices };
        mesh.drop_degenerate();
        if mesh.indices.is_empty() {
            warnings.push(format!("{}: group '{group}' has no faces; skipped", path.display()));
            continue;
        }
        mesh.check().map_err(|r| Error::bad_file(path, format!("group '{group}': {r}")))?;
        // Repeated group names are common in CAD exports; suffixes keep object names unique.
        let name = names.give(&group);
        scene.objects.push(Object { name: name.clone(), mesh: scene.meshes.len() as u32, transform: Mat4::IDENTITY, part: None });
        scene.meshes.push(BaseMesh { name, mesh });
    }
    if scene.objects.is_empty() {
        return Err(Error::bad_file(path, "no faces: the OBJ file holds no triangle or polygon"));
    }
    Ok((scene, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.obj");
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn groups_become_objects_and_quads_are_triangulated() {
        let (_d, p) = write(
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
             o a\nf 1 2 3 4\ng b\nf 1 2 3\no a\nf 2 3 4\ng empty\n",
        );
        let (scene, warnings) = read(&p).unwrap();
        let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["a", "b", "a#2"]);
        assert_eq!(scene.object_mesh(0).triangle_count(), 2);
        assert_eq!(scene.triangle_count(), 4);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].contains("'empty'"));
    }

    #[test]
    fn repeated_names_never_collide_with_a_name_the_file_has() {
        // Issue 32: `a#2` suffixed onto the second `a` collided with the third group's own name.
        let (_d, p) = write("v 0 0 0\nv 1 0 0\nv 1 1 0\no a\nf 1 2 3\no a\nf 1 2 3\no a#2\nf 1 2 3\no a\nf 1 2 3\n");
        let (scene, _) = read(&p).unwrap();
        let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["a", "a#3", "a#2", "a#4"]);
        scene.check().unwrap();
    }

    #[test]
    fn bad_inputs_are_one_line_errors_naming_the_file() {
        for (text, reason) in [
            ("", "no faces"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "out of bounds"),
            ("v 0 0 zero\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "parse"),
            ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"),
            ("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"),
            ("v 0 0 0\nv 1 0 0\nf 1 2\n", "no faces"),
        ] {
            let (_d, p) = write(text);
            let err = read(&p).err().unwrap_or_else(|| panic!("accepted {text:?}")).to_string();
            assert!(err.contains("t.obj"), "{err}");
            assert!(err.contains(reason), "{text:?}: {err}");
            assert!(!err.contains('\n'), "{err}");
        }
    }

    #[test]
    fn missing_file_is_an_error() {
        let err = read(Path::new("/nonexistent/x.obj")).unwrap_err().to_string();
        assert!(err.contains("/nonexistent/x.obj") && err.contains("No such file"), "{err}");
    }
}
