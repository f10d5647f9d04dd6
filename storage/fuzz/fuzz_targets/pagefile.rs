//! Page file decoder: any bytes, opened in both read modes and read in full, give Ok or Err.
#![no_main]

use hdov_storage::{PageFile, ReadMode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f");
    std::fs::write(&path, data).unwrap();
    // Take the kind tag from the input so the fuzzer can get past the kind check.
    let kind: [u8; 4] = data.get(8..12).and_then(|k| k.try_into().ok()).unwrap_or(*b"FUZZ");
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        if let Ok(f) = PageFile::open(&path, kind, mode) {
            let _ = f.verify();
        }
    }
});
