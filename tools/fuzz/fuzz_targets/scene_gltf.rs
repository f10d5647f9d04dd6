//! glTF 2.0 import. Input: a `.glb` (or, starting with `{`, a `.gltf`) beside one buffer file
//! `b.bin` of 64 bytes; any bytes give a scene that passes its check or a one-line error naming
//! a file, never a panic, and nothing outside the scene's folder is read.
#![no_main]

use hdov::Scene;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("b.bin"), [0u8; 64]).unwrap();
    let name = if data.first() == Some(&b'{') { "s.gltf" } else { "s.glb" };
    let path = dir.path().join(name);
    std::fs::write(&path, data).unwrap();
    match Scene::load(&path) {
        Ok((scene, _)) => scene.check().unwrap(),
        Err(e) => assert!(!e.to_string().contains('\n'), "{e}"),
    }
});
