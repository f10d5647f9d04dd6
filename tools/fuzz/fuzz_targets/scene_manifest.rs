//! Scene manifests (`city.json` + `city.meshes`). A tiny city is written once; each input
//! replaces its `.json` (input byte 0 even) or its `.meshes` (odd), and the scene is loaded: any
//! bytes give a scene that passes its check or a one-line error, never a panic, and the meshes
//! file is never looked for outside the folder.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use hdov::Scene;
use libfuzzer_sys::fuzz_target;

struct Clean {
    dir: PathBuf,
    json: Vec<u8>,
    meshes: Vec<u8>,
}

fn clean() -> &'static Clean {
    static CLEAN: OnceLock<Clean> = OnceLock::new();
    CLEAN.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("hdov-fuzz-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut scene = Scene::default();
        scene.add_box("a", glam::Vec3::ZERO, glam::Vec3::ONE);
        scene.add_box("b", glam::Vec3::splat(2.0), glam::Vec3::splat(3.0));
        let path = dir.join("s.json");
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(dir.join("s.meshes"));
        scene.write_manifest(&path, hdov::Overwrite::Never).unwrap();
        let json = std::fs::read(&path).unwrap();
        let meshes = std::fs::read(dir.join("s.meshes")).unwrap();
        Clean { dir, json, meshes }
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else { return };
    let c = clean();
    let (json, meshes) = if pick % 2 == 0 { (rest, &c.meshes[..]) } else { (&c.json[..], rest) };
    let path = c.dir.join("s.json");
    std::fs::write(&path, json).unwrap();
    std::fs::write(c.dir.join("s.meshes"), meshes).unwrap();
    match Scene::load(&path) {
        Ok((scene, _)) => scene.check().unwrap(),
        Err(e) => assert!(!e.to_string().contains('\n'), "{e}"),
    }
});
