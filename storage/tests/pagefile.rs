//! Page files: round trips in both read modes, and each kind of damage gives its own error.

use std::fs;
use std::path::Path;

use hdov_storage::{Error, FORMAT_VERSION, PageFile, PageFileWriter, PageReader, ReadMode};

const KIND: [u8; 4] = *b"TEST";

fn write_sample(path: &Path, page_size: u32, pages: &[Vec<u8>]) {
    let mut w = PageFileWriter::create(path, KIND, page_size).unwrap();
    for (i, p) in pages.iter().enumerate() {
        assert_eq!(w.push(p).unwrap() as usize, i);
    }
    let len = w.finish().unwrap();
    assert_eq!(len, fs::metadata(path).unwrap().len());
}

fn sample_pages(cap: usize) -> Vec<Vec<u8>> {
    vec![vec![], (0..cap).map(|i| (i * 7 + 1) as u8).collect(), b"hello".to_vec()]
}

#[test]
fn round_trip_mmap_and_pread() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    let pages = sample_pages(128 - 4);
    write_sample(&path, 128, &pages);
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        let f = PageFile::open(&path, KIND, mode).unwrap();
        assert_eq!(f.page_count(), 3);
        assert_eq!(f.capacity(), 124);
        assert_eq!(f.name(), "p");
        let mut r = PageReader::uncached();
        assert_eq!(r.io().file("p"), 0);
        for (i, want) in pages.iter().enumerate() {
            let got = r.page(&f, i as u64, 0.0).unwrap();
            assert_eq!(got.len(), 124);
            assert_eq!(&got[..want.len()], &want[..]);
            assert!(got[want.len()..].iter().all(|&b| b == 0));
        }
        assert_eq!(r.io().file("p"), 3);
        r.page(&f, 1, 0.0).unwrap();
        assert_eq!(r.io().file("p"), 4);
        r.reset_io();
        assert_eq!(r.io().file("p"), 0);
        assert!(matches!(r.page(&f, 3, 0.0), Err(Error::Invalid { .. })));
    }
}

/// A page is checked on its first read in both modes; after that a mapped page is trusted (the
/// file is immutable) while a page read with `pread` comes from the disk, and is checked, anew.
#[test]
fn damage_after_open_is_caught_on_first_read_and_on_every_pread() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    write_sample(&path, 128, &sample_pages(124));
    let damage_page = |n: u64| {
        let mut b = fs::read(&path).unwrap();
        b[((n + 1) * 128 + 5) as usize] ^= 0x40;
        fs::write(&path, &b).unwrap();
    };
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        write_sample(&path, 128, &sample_pages(124));
        let f = PageFile::open(&path, KIND, mode).unwrap();
        let mut r = PageReader::uncached();
        r.page(&f, 0, 0.0).unwrap();
        // Page 1, never read before, is damaged after open: its first read refuses it.
        damage_page(1);
        assert!(matches!(r.page(&f, 1, 0.0), Err(Error::Checksum { page: 1, .. })), "{mode:?}");
        if mode == ReadMode::Pread {
            // A pread page that read cleanly once is checked again on the next read.
            damage_page(0);
            r.reset_io();
            assert!(matches!(r.page(&f, 0, 0.0), Err(Error::Checksum { page: 0, .. })));
        }
    }
}

#[test]
fn empty_file_opens_with_no_pages() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    write_sample(&path, 64, &[]);
    let f = PageFile::open(&path, KIND, ReadMode::Mmap).unwrap();
    assert_eq!(f.page_count(), 0);
    assert!(PageReader::uncached().page(&f, 0, 0.0).is_err());
}

#[test]
fn oversized_payload_and_bad_page_size_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    assert!(matches!(PageFileWriter::create(&path, KIND, 16), Err(Error::Invalid { .. })));
    let mut w = PageFileWriter::create(&path, KIND, 64).unwrap();
    assert!(w.push(&[0u8; 60]).is_ok());
    assert!(matches!(w.push(&[0u8; 61]), Err(Error::Invalid { .. })));
}

#[test]
fn unfinished_file_does_not_open() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    let mut w = PageFileWriter::create(&path, KIND, 64).unwrap();
    w.push(b"x").unwrap();
    drop(w);
    assert!(matches!(PageFile::open(&path, KIND, ReadMode::Mmap), Err(Error::WrongMagic { .. })));
}

fn damaged(edit: impl FnOnce(&mut Vec<u8>)) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    write_sample(&path, 64, &sample_pages(60));
    let mut bytes = fs::read(&path).unwrap();
    edit(&mut bytes);
    fs::write(&path, &bytes).unwrap();
    (dir, path)
}

fn rehash_header(b: &mut [u8]) {
    let crc = crc32fast::hash(&b[0..28]);
    b[28..32].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn truncated_file() {
    for cut in [0usize, 5, 20, 64, 64 * 3 + 10, 64 * 4 - 1] {
        let (_d, path) = damaged(|b| b.truncate(cut));
        for mode in [ReadMode::Mmap, ReadMode::Pread] {
            let e = PageFile::open(&path, KIND, mode).unwrap_err();
            assert!(matches!(e, Error::Truncated { .. }), "cut {cut}: {e}");
        }
    }
}

#[test]
fn trailing_bytes() {
    let (_d, path) = damaged(|b| b.extend_from_slice(&[0; 3]));
    assert!(matches!(PageFile::open(&path, KIND, ReadMode::Mmap), Err(Error::Corrupt { .. })));
}

#[test]
fn flipped_payload_byte_fails_checksum() {
    let (_d, path) = damaged(|b| b[64 * 2 + 10] ^= 0x40);
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        let f = PageFile::open(&path, KIND, mode).unwrap();
        let mut r = PageReader::uncached();
        assert!(r.page(&f, 0, 0.0).is_ok());
        match r.page(&f, 1, 0.0) {
            Err(Error::Checksum { page: 1, .. }) => {}
            other => panic!("expected checksum error, got {other:?}"),
        }
        assert!(r.page(&f, 2, 0.0).is_ok());
        assert!(f.verify().is_err());
    }
}

#[test]
fn flipped_header_byte_fails_header_checksum() {
    let (_d, path) = damaged(|b| b[21] ^= 1);
    let e = PageFile::open(&path, KIND, ReadMode::Mmap).unwrap_err();
    assert!(e.to_string().contains("header checksum"), "{e}");
}

#[test]
fn wrong_magic() {
    let (_d, path) = damaged(|b| b[0] = b'X');
    assert!(matches!(PageFile::open(&path, KIND, ReadMode::Mmap), Err(Error::WrongMagic { .. })));
}

#[test]
fn wrong_kind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p");
    write_sample(&path, 64, &[]);
    let e = PageFile::open(&path, *b"TREE", ReadMode::Mmap).unwrap_err();
    assert!(matches!(e, Error::WrongKind { .. }));
    let msg = e.to_string();
    assert!(msg.contains("TEST") && msg.contains("TREE") && !msg.contains('\n'), "{msg}");
}

#[test]
fn wrong_version() {
    let (_d, path) = damaged(|b| {
        b[12..16].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        rehash_header(b);
    });
    match PageFile::open(&path, KIND, ReadMode::Mmap) {
        Err(Error::WrongVersion { found, expected, .. }) => {
            assert_eq!((found, expected), (FORMAT_VERSION + 1, FORMAT_VERSION))
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn huge_page_count_is_truncation_not_overflow() {
    let (_d, path) = damaged(|b| {
        b[20..28].copy_from_slice(&u64::MAX.to_le_bytes());
        rehash_header(b);
    });
    assert!(PageFile::open(&path, KIND, ReadMode::Mmap).is_err());
    let (_d, path) = damaged(|b| {
        b[20..28].copy_from_slice(&(1u64 << 40).to_le_bytes());
        rehash_header(b);
    });
    assert!(matches!(PageFile::open(&path, KIND, ReadMode::Mmap), Err(Error::Truncated { .. })));
}

#[test]
fn missing_file_is_io_error_naming_it() {
    let e = PageFile::open(Path::new("/nonexistent/x.pages"), KIND, ReadMode::Mmap).unwrap_err();
    assert!(matches!(e, Error::Io { .. }));
    assert!(e.to_string().starts_with("/nonexistent/x.pages: "));
}
