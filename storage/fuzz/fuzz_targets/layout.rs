//! Layout decoders. Input: byte 0 picks the layout (bits 0-1) and whether to recompute the
//! page checksums (bit 7, so the fuzzer reaches the metadata, segment and V-page decoders);
//! bytes 1..5 split the rest into the layout's first and second file.
#![no_main]

use hdov_storage::{LayoutKind, LayoutReader, ReadMode};
use libfuzzer_sys::fuzz_target;

fn refresh_checksums(b: &mut [u8]) {
    if b.len() < 32 {
        return;
    }
    let ps = u32::from_le_bytes(b[16..20].try_into().unwrap()) as usize;
    if !(64..=65536).contains(&ps) {
        return;
    }
    let crc = crc32fast::hash(&b[0..28]);
    b[28..32].copy_from_slice(&crc.to_le_bytes());
    for page in b.chunks_mut(ps).skip(1) {
        if page.len() == ps {
            let crc = crc32fast::hash(&page[..ps - 4]);
            page[ps - 4..].copy_from_slice(&crc.to_le_bytes());
        }
    }
}

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
        if let Ok(mut r) = LayoutReader::open(dir.path(), kind, mode) {
            let _ = r.verify();
        }
    }
});
