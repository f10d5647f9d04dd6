//! Damaged files of every type give errors, never panics: targeted damage with the expected
//! error, then a bounded loop of random mutations (half of them with checksums recomputed, so
//! the decoders behind the checksums are exercised too) through open + verify.

use std::fs;
use std::path::{Path, PathBuf};

use hdov_storage::synthetic::{SyntheticSpec, sparse_vdata, synthetic_vdata};
use hdov_storage::{
    BlobFile, BlobWriter, DovCodec, Error, Layout, LayoutKind, LayoutOptions, PageFile, PageReader, ReadMode,
    write_layout,
};

use hdov_storage::mutation::Rng;

use hdov_storage::pagefile::reseal_checksums as refresh_page_checksums;

fn refresh_blob_checksums(b: &mut [u8]) {
    if b.len() >= 32 {
        let crc = crc32fast::hash(&b[0..28]);
        b[28..32].copy_from_slice(&crc.to_le_bytes());
    }
}

/// One random mutation of `good` (the storage crate's shared test kit).
fn mutate(rng: &mut Rng, good: &[u8]) -> Vec<u8> {
    hdov_storage::mutation::mutate(rng, good).0
}

fn sample_layouts(dir: &Path, page_size: u32, dov: DovCodec) {
    let data = synthetic_vdata(&SyntheticSpec { cells: 5, fanout: 6, levels: 3, reach: 0.3, ..Default::default() });
    for kind in LayoutKind::ALL {
        write_layout(dir, kind, &data, &LayoutOptions { page_size, dov, ..Default::default() }).unwrap();
    }
}

fn read_layout_fully(dir: &Path, kind: LayoutKind) -> Result<u64, Error> {
    let mut total = 0;
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        total += Layout::open(dir, kind, mode)?.verify()?;
    }
    Ok(total)
}

/// Sparse V-data (fan-out 20 with u8 entry indices, or 300 with u16) in the vertical layouts.
fn sparse_layouts(dir: &Path, fanout: u16) {
    let data = sparse_vdata(4, fanout, 2, 0.08, 5);
    for kind in [LayoutKind::Vertical, LayoutKind::IndexedVertical] {
        write_layout(dir, kind, &data, &LayoutOptions { page_size: 64, ..Default::default() }).unwrap();
    }
}

#[test]
fn random_mutations_of_layout_files_never_panic() {
    let good = tempfile::tempdir().unwrap();
    sample_layouts(good.path(), 64, DovCodec::F32);
    mutation_rounds(good.path(), &LayoutKind::ALL, 150, 0x5EED);
}

#[test]
fn random_mutations_of_sparse_vpages_never_panic() {
    let kinds = [LayoutKind::Vertical, LayoutKind::IndexedVertical];
    for (fanout, seed) in [(20, 0xA11CE), (300, 0xB0B)] {
        let good = tempfile::tempdir().unwrap();
        sparse_layouts(good.path(), fanout);
        mutation_rounds(good.path(), &kinds, 100, seed);
    }
}

/// `rounds` random mutations per layout of the layouts in `good`, half with checksums
/// recomputed, each through open + verify in both read modes.
fn mutation_rounds(good: &Path, kinds: &[LayoutKind], rounds: usize, seed: u64) {
    let mut rng = Rng(seed);
    let work = tempfile::tempdir().unwrap();
    let mut outcomes = [0usize; 2];
    for &kind in kinds {
        let expected = read_layout_fully(good, kind).unwrap();
        assert!(expected > 0);
        for round in 0..rounds {
            let victim = kind.file_names()[rng.below(kind.file_names().len())];
            let dir: PathBuf = work.path().join(format!("{kind}-{round}"));
            fs::create_dir(&dir).unwrap();
            for f in kind.file_names() {
                let mut bytes = fs::read(good.join(f)).unwrap();
                if *f == victim {
                    bytes = mutate(&mut rng, &bytes);
                    if round % 2 == 0 {
                        refresh_page_checksums(&mut bytes);
                    }
                }
                fs::write(dir.join(f), &bytes).unwrap();
            }
            let res = read_layout_fully(&dir, kind);
            outcomes[usize::from(res.is_ok())] += 1;
            if let Err(e) = res {
                let msg = e.to_string();
                // One line naming a file of the layout (damage to the index's fan-outs
                // surfaces as a bad V-page read, so not necessarily the damaged file).
                let names_a_file = kind.file_names().iter().any(|f| msg.contains(f));
                assert!(!msg.contains('\n') && names_a_file, "{msg}");
            }
            fs::remove_dir_all(&dir).unwrap();
        }
    }
    // Both outcomes occur: the loop probes the decoders, not only the checksums.
    let n = kinds.len() * rounds;
    assert!(outcomes[0] > n / 9 && outcomes[1] > n / 45, "{outcomes:?}");
}

#[test]
fn random_mutations_of_page_and_blob_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let blob_path = dir.path().join("blob");
    let mut w = BlobWriter::create(&blob_path, *b"MESH").unwrap();
    for i in 0..20u32 {
        w.append(&vec![i as u8; i as usize * 3]).unwrap();
    }
    w.finish().unwrap();
    sample_layouts(dir.path(), 64, DovCodec::LogU16);
    let page_path = dir.path().join("vpages.vertical");
    let good_blob = fs::read(&blob_path).unwrap();
    let good_page = fs::read(&page_path).unwrap();
    let mut rng = Rng(42);
    let probe = dir.path().join("probe");
    // Each outcome must be a one-line error naming the probe, or a file that reads back whole:
    // the same records (blob) or the same page count and a clean verify (pages).
    let good_records: Vec<Vec<u8>> =
        BlobFile::open(&blob_path, *b"MESH").unwrap().iter().map(|r| r.unwrap().1.to_vec()).collect();
    let refused = |e: Error| {
        let msg = e.to_string();
        assert!(!msg.contains('\n') && msg.contains("probe"), "{msg}");
    };
    let mut outcomes = [[0usize; 2]; 2];
    for round in 0..300 {
        let mut b = mutate(&mut rng, &good_blob);
        if round % 2 == 0 {
            refresh_blob_checksums(&mut b);
        }
        fs::write(&probe, &b).unwrap();
        match BlobFile::open(&probe, *b"MESH").and_then(|f| {
            f.verify()?;
            f.iter().map(|r| r.map(|(_, d)| d.to_vec())).collect::<Result<Vec<_>, Error>>()
        }) {
            Ok(records) => {
                // Damage the checks let through may only be in bytes no reader uses.
                assert_eq!(records, good_records, "round {round}: a blob read back differently");
                outcomes[0][1] += 1;
            }
            Err(e) => {
                refused(e);
                outcomes[0][0] += 1;
            }
        }
        let mut b = mutate(&mut rng, &good_page);
        if round % 2 == 0 {
            refresh_page_checksums(&mut b);
        }
        fs::write(&probe, &b).unwrap();
        for mode in [ReadMode::Mmap, ReadMode::Pread] {
            match PageFile::open(&probe, *b"VTVP", mode).and_then(|f| f.verify().map(|_| f.page_count())) {
                Ok(pages) => {
                    assert!(pages > 0, "round {round}: an empty page file verified");
                    outcomes[1][1] += 1;
                }
                Err(e) => {
                    refused(e);
                    outcomes[1][0] += 1;
                }
            }
        }
    }
    // Both outcomes occur for pages (resealed checksums let payload damage through to the
    // layout decoders, tested above); blobs refuse almost everything.
    assert!(outcomes[0][0] > 200 && outcomes[1][0] > 200 && outcomes[1][1] > 20, "{outcomes:?}");
    // Pure noise, with and without a plausible magic.
    for round in 0..200 {
        let mut b: Vec<u8> = (0..rng.below(400)).map(|_| rng.next() as u8).collect();
        if round % 2 == 0 && b.len() >= 8 {
            b[..8].copy_from_slice(if round % 4 == 0 { b"HDOVPAGE" } else { b"HDOVBLOB" });
        }
        fs::write(&probe, &b).unwrap();
        assert!(PageFile::open(&probe, *b"VTVP", ReadMode::Mmap).is_err());
        assert!(BlobFile::open(&probe, *b"MESH").is_err());
    }
}

/// Copies the three layouts to a fresh directory with `edit` applied to file `name`.
fn damaged(good: &Path, name: &str, edit: impl Fn(&mut Vec<u8>)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for kind in LayoutKind::ALL {
        for f in kind.file_names() {
            let mut b = fs::read(good.join(f)).unwrap();
            if *f == name {
                edit(&mut b);
            }
            fs::write(dir.path().join(f), b).unwrap();
        }
    }
    dir
}

fn kind_of(name: &str) -> LayoutKind {
    LayoutKind::ALL.into_iter().find(|k| k.file_names().contains(&name)).unwrap()
}

#[test]
fn targeted_damage_to_each_layout_file() {
    let good = tempfile::tempdir().unwrap();
    sample_layouts(good.path(), 64, DovCodec::F32);
    let names: Vec<&str> = LayoutKind::ALL.iter().flat_map(|k| k.file_names().iter().copied()).collect();
    for name in names {
        let kind = kind_of(name);
        let len = fs::metadata(good.path().join(name)).unwrap().len() as usize;

        let d = damaged(good.path(), name, |b| b.truncate(len - 10));
        let e = Layout::open(d.path(), kind, ReadMode::Mmap).unwrap_err();
        assert!(matches!(e, Error::Truncated { .. }), "{name}: {e}");

        // A flipped bit in the last page: found when that page is read.
        let d = damaged(good.path(), name, |b| b[len - 20] ^= 0x10);
        let e = read_layout_fully(d.path(), kind).unwrap_err();
        assert!(matches!(e, Error::Checksum { .. }), "{name}: {e}");

        let d = damaged(good.path(), name, |b| b[1] ^= 0x10);
        let e = Layout::open(d.path(), kind, ReadMode::Pread).unwrap_err();
        assert!(matches!(e, Error::WrongMagic { .. }), "{name}: {e}");

        let d = damaged(good.path(), name, |b| {
            b[8..12].copy_from_slice(b"ZZZZ");
            refresh_page_checksums(b);
        });
        let e = Layout::open(d.path(), kind, ReadMode::Mmap).unwrap_err();
        assert!(matches!(e, Error::WrongKind { .. }), "{name}: {e}");

        let d = damaged(good.path(), name, |b| {
            b[12] = 9;
            refresh_page_checksums(b);
        });
        let e = Layout::open(d.path(), kind, ReadMode::Mmap).unwrap_err();
        assert!(matches!(e, Error::WrongVersion { found: 9, .. }), "{name}: {e}");
    }
}

#[test]
fn mismatched_builds_and_bad_metadata_are_corrupt() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    sample_layouts(a.path(), 64, DovCodec::F32);
    sample_layouts(b.path(), 4096, DovCodec::F32);
    // vpages.vertical of another build next to this build's index.
    fs::copy(b.path().join("vpages.vertical"), a.path().join("vpages.vertical")).unwrap();
    let e = Layout::open(a.path(), LayoutKind::Vertical, ReadMode::Mmap).unwrap_err();
    assert!(matches!(e, Error::Corrupt { .. }), "{e}");

    // A metadata layout code that names another layout (checksums made valid).
    let d = damaged(b.path(), "vindex.indexed-vertical", |bytes| {
        bytes[4096] = 1;
        refresh_page_checksums(bytes);
    });
    let e = Layout::open(d.path(), LayoutKind::IndexedVertical, ReadMode::Mmap).unwrap_err();
    assert!(e.to_string().contains("layout code"), "{e}");

    // A node count that the file cannot hold.
    let d = damaged(b.path(), "vindex.vertical", |bytes| {
        bytes[4096 + 8..4096 + 12].copy_from_slice(&u32::MAX.to_le_bytes());
        refresh_page_checksums(bytes);
    });
    let e = Layout::open(d.path(), LayoutKind::Vertical, ReadMode::Mmap).unwrap_err();
    assert!(matches!(e, Error::Corrupt { .. }), "{e}");
}

/// A damage to a file image.
type Edit<'a> = Box<dyn Fn(&mut Vec<u8>) + 'a>;

/// The first V-page record of cell 0 (the root's) in `vpages.vertical` written with 4 KiB
/// pages: its header and first entry index, edited, must give a `Corrupt` error on read.
#[test]
fn sparse_vpage_count_or_index_out_of_range_is_corrupt() {
    const P: usize = 4096;
    for (fanout, idx) in [(126u16, 1usize), (300, 2)] {
        let good = tempfile::tempdir().unwrap();
        let data = sparse_vdata(2, fanout, 2, 0.05, 9);
        for kind in [LayoutKind::Vertical, LayoutKind::IndexedVertical] {
            write_layout(good.path(), kind, &data, &LayoutOptions::default()).unwrap();
        }
        let vp = fs::read(good.path().join("vpages.vertical")).unwrap();
        let get = |at: usize| {
            if idx == 1 { usize::from(vp[at]) } else { usize::from(u16::from_le_bytes([vp[at], vp[at + 1]])) }
        };
        let count = get(P);
        assert!(count >= 2 && count < usize::from(fanout), "root V-page is sparse with ≥ 2 entries: {count}");
        let entry = 6; // f32 DoV, u16 NVO
        let first_index = P + idx;
        let second_index = first_index + idx + entry;
        let put = |b: &mut Vec<u8>, at: usize, v: usize| {
            if idx == 1 {
                b[at] = v as u8;
            } else {
                b[at..at + 2].copy_from_slice(&(v as u16).to_le_bytes());
            }
        };
        let cases: Vec<(&str, Edit)> = vec![
            ("count above the fan-out", Box::new(|b| put(b, P, usize::from(fanout) + 1))),
            ("largest count", Box::new(|b| put(b, P, if idx == 1 { 255 } else { 65535 }))),
            ("index = fan-out", Box::new(|b| put(b, first_index, usize::from(fanout)))),
            ("largest index", Box::new(|b| put(b, first_index, if idx == 1 { 255 } else { 65535 }))),
            ("indices not ascending", Box::new(|b| put(b, second_index, get(first_index)))),
        ];
        for (what, edit) in cases {
            if idx == 1 && what == "largest count" && fanout > 255 {
                continue;
            }
            let d = damaged_vertical(good.path(), "vpages.vertical", |b| {
                edit(b);
                refresh_page_checksums(b);
            });
            let layout = Layout::open(d.path(), LayoutKind::Vertical, ReadMode::Mmap).unwrap();
            let mut pages = PageReader::uncached();
            let mut r = layout.cursor();
            r.flip_to_cell(0, &mut pages).unwrap();
            let e = r.vpage(0, 0.0, &mut pages).unwrap_err();
            assert!(matches!(e, Error::Corrupt { .. }), "{fanout}, {what}: {e}");
            assert!(e.to_string().contains("node 0"), "{e}");
            let e = read_layout_fully(d.path(), LayoutKind::Vertical).unwrap_err();
            assert!(matches!(e, Error::Corrupt { .. }), "{fanout}, {what}: {e}");
        }
    }
}

#[test]
fn sparse_metadata_must_match_the_fan_outs() {
    let good = tempfile::tempdir().unwrap();
    sparse_layouts(good.path(), 20);
    // u8 indices recorded as 1; 2 (u16) does not fit fan-outs ≤ 256, 3 is unknown.
    for (v, msg) in [(2u8, "the fan-outs need 1"), (3, "V-page encoding 3")] {
        let d = damaged_vertical(good.path(), "vindex.vertical", |b| {
            assert_eq!(b[64 + 3], 1);
            b[64 + 3] = v;
            refresh_page_checksums(b);
        });
        let e = Layout::open(d.path(), LayoutKind::Vertical, ReadMode::Mmap).unwrap_err();
        assert!(matches!(e, Error::Corrupt { .. }) && e.to_string().contains(msg), "{e}");
    }
    // Horizontal never has sparse V-pages.
    let h = tempfile::tempdir().unwrap();
    sample_layouts(h.path(), 64, DovCodec::F32);
    let path = h.path().join("vpages.horizontal");
    let mut b = fs::read(&path).unwrap();
    b[64 + 3] = 1;
    refresh_page_checksums(&mut b);
    fs::write(&path, b).unwrap();
    let e = Layout::open(h.path(), LayoutKind::Horizontal, ReadMode::Mmap).unwrap_err();
    assert!(matches!(e, Error::Corrupt { .. }) && e.to_string().contains("V-page encoding 1"), "{e}");
}

/// Copies the vertical layouts to a fresh directory with `edit` applied to file `name`.
fn damaged_vertical(good: &Path, name: &str, edit: impl Fn(&mut Vec<u8>)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for kind in [LayoutKind::Vertical, LayoutKind::IndexedVertical] {
        for f in kind.file_names() {
            let mut b = fs::read(good.join(f)).unwrap();
            if *f == name {
                edit(&mut b);
            }
            fs::write(dir.path().join(f), b).unwrap();
        }
    }
    dir
}
