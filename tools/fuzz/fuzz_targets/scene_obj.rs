//! OBJ import. Input: an `.obj` file; any bytes give a scene that passes its check or a
//! one-line error naming the file, never a panic.
#![no_main]

use hdov::Scene;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.obj");
    std::fs::write(&path, data).unwrap();
    match Scene::load(&path) {
        Ok((scene, _)) => scene.check().unwrap(),
        Err(e) => assert!(!e.to_string().contains('\n'), "{e}"),
    }
});
