//! Blob files: round trips, and each kind of damage gives its own error.

use std::fs;

use hdov_storage::{BlobFile, BlobRef, BlobWriter, Error, FORMAT_VERSION};

const KIND: [u8; 4] = *b"MESH";

fn sample() -> Vec<Vec<u8>> {
    vec![b"first".to_vec(), vec![], (0..1000u32).map(|i| i as u8).collect()]
}

fn write(path: &std::path::Path) -> Vec<BlobRef> {
    let mut w = BlobWriter::create(path, KIND).unwrap();
    let refs = sample().iter().map(|r| w.append(r).unwrap()).collect();
    let len = w.finish().unwrap();
    assert_eq!(len, fs::metadata(path).unwrap().len());
    refs
}

#[test]
fn round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b");
    let refs = write(&path);
    let f = BlobFile::open(&path, KIND).unwrap();
    assert_eq!(f.count(), 3);
    for (r, want) in refs.iter().zip(sample()) {
        assert_eq!(f.get(*r).unwrap(), &want[..]);
    }
    let all: Vec<_> = f.iter().map(|x| x.unwrap()).collect();
    assert_eq!(all.len(), 3);
    for ((r, b), (r2, want)) in all.iter().zip(refs.iter().zip(sample())) {
        assert_eq!((r, *b), (r2, &want[..]));
    }
}

#[test]
fn bad_references_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b");
    let refs = write(&path);
    let f = BlobFile::open(&path, KIND).unwrap();
    for r in [
        BlobRef { offset: 0, len: 5 },
        BlobRef { offset: u64::MAX, len: 5 },
        BlobRef { offset: refs[0].offset, len: 4 },
        BlobRef { offset: refs[0].offset + 1, len: 5 },
        BlobRef { offset: f.file_len() - 2, len: 0 },
    ] {
        assert!(f.get(r).is_err(), "{r:?}");
    }
}

#[test]
fn flipped_record_byte_fails_checksum() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b");
    let refs = write(&path);
    let mut bytes = fs::read(&path).unwrap();
    bytes[refs[2].offset as usize + 8 + 500] ^= 4;
    fs::write(&path, &bytes).unwrap();
    let f = BlobFile::open(&path, KIND).unwrap();
    assert!(f.get(refs[0]).is_ok());
    assert!(matches!(f.get(refs[2]), Err(Error::RecordChecksum { .. })));
    assert!(f.iter().any(|r| r.is_err()));
}

#[test]
fn header_damage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b");
    write(&path);
    let good = fs::read(&path).unwrap();
    let rehash = |b: &mut Vec<u8>| {
        let crc = crc32fast::hash(&b[0..28]);
        b[28..32].copy_from_slice(&crc.to_le_bytes());
    };

    let mut b = good.clone();
    b[3] = 0;
    fs::write(&path, &b).unwrap();
    assert!(matches!(BlobFile::open(&path, KIND), Err(Error::WrongMagic { .. })));

    let mut b = good.clone();
    b.truncate(good.len() - 1);
    fs::write(&path, &b).unwrap();
    assert!(matches!(BlobFile::open(&path, KIND), Err(Error::Truncated { .. })));

    for cut in [0, 4, 31] {
        fs::write(&path, &good[..cut]).unwrap();
        assert!(matches!(BlobFile::open(&path, KIND), Err(Error::Truncated { .. })));
    }

    fs::write(&path, &good).unwrap();
    assert!(matches!(BlobFile::open(&path, *b"TREE"), Err(Error::WrongKind { .. })));

    let mut b = good.clone();
    b[12..16].copy_from_slice(&(FORMAT_VERSION + 7).to_le_bytes());
    rehash(&mut b);
    fs::write(&path, &b).unwrap();
    assert!(matches!(BlobFile::open(&path, KIND), Err(Error::WrongVersion { .. })));

    let mut b = good.clone();
    b[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
    rehash(&mut b);
    fs::write(&path, &b).unwrap();
    assert!(matches!(BlobFile::open(&path, KIND), Err(Error::Corrupt { .. })));

    let mut b = good.clone();
    b[24] ^= 1;
    fs::write(&path, &b).unwrap();
    let e = BlobFile::open(&path, KIND).unwrap_err();
    assert!(e.to_string().contains("header checksum"), "{e}");
}

#[test]
fn records_read_back_while_writing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b");
    let mut w = BlobWriter::create(&path, KIND).unwrap();
    let refs: Vec<BlobRef> = sample().iter().map(|r| w.append(r).unwrap()).collect();
    let reader = w.reader().unwrap();
    let later = w.append(b"after the reader").unwrap();
    for (r, want) in refs.iter().zip(sample()) {
        assert_eq!(reader.read(*r).unwrap(), want);
    }
    // What came after the reader, and references that do not point at a record, are errors.
    for r in [later, BlobRef { offset: 0, len: 5 }, BlobRef { offset: u64::MAX, len: 5 }, BlobRef { len: 4, ..refs[0] }]
    {
        assert!(reader.read(r).is_err(), "{r:?}");
    }
    w.finish().unwrap();
    // A flipped byte under a reader fails the record's checksum.
    let mut bytes = fs::read(&path).unwrap();
    bytes[refs[2].offset as usize + 8 + 10] ^= 1;
    fs::write(&path, &bytes).unwrap();
    assert!(matches!(reader.read(refs[2]), Err(Error::RecordChecksum { .. })));
}
