//! Layout decoders. Input: byte 0 picks the layout (bits 0-1) and whether to recompute the
//! page checksums (bit 7, so the fuzzer reaches the metadata, segment and V-page decoders);
//! bytes 1..5 split the rest into the layout's first and second file.
#![no_main]

use hdov_storage::pagefile::reseal_checksums as refresh_checksums;
use hdov_storage::{Layout, LayoutKind, ReadMode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 5 {
        return;
    }
    let kind = LayoutKind::ALL[usize::from(data[0] & 3) % 3];
    let fix = data[0] & 0x80 != 0;
    let rest = &data[5..];
    let split = (u32::from_le_bytes(data[1..5].try_into().unwrap()) as usize) % (rest.len() + 1);
    let (first, second) = rest.split_at(split);
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in kind.file_names().iter().zip([first, second]) {
        let mut bytes = bytes.to_vec();
        if fix {
            refresh_checksums(&mut bytes);
        }
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        if let Ok(layout) = Layout::open(dir.path(), kind, mode) {
            let _ = layout.verify();
        }
    }
});
