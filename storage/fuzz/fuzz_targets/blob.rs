//! Blob file decoder: any bytes, opened and read in full, give Ok or Err.
#![no_main]

use hdov_storage::BlobFile;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f");
    std::fs::write(&path, data).unwrap();
    let kind: [u8; 4] = data.get(8..12).and_then(|k| k.try_into().ok()).unwrap_or(*b"FUZZ");
    if let Ok(f) = BlobFile::open(&path, kind) {
        let _ = f.verify();
        if let Some(r) = f.iter().next() {
            let _ = r.and_then(|(r, _)| f.get(r));
        }
    }
});
