//! Writes seed inputs for the fuzz targets in `storage/fuzz/` (valid files of each type, in
//! each target's input format), so fuzzing starts past the magic and checksum checks.
//!
//! `cargo run -p hdov-storage --example fuzz_seeds -- storage/fuzz/corpus`

use std::fs;
use std::path::PathBuf;

use hdov_storage::synthetic::{SyntheticSpec, sparse_vdata, synthetic_vdata};
use hdov_storage::{BlobWriter, DovCodec, LayoutKind, LayoutOptions, PageFileWriter, write_layout};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(std::env::args().nth(1).ok_or("usage: fuzz_seeds CORPUS_DIR")?);
    let tmp = tempfile::tempdir()?;
    for t in ["pagefile", "blob", "layout"] {
        fs::create_dir_all(out.join(t))?;
    }

    let p = tmp.path().join("p");
    let mut w = PageFileWriter::create(&p, *b"SEED", 64)?;
    w.push(b"first page")?;
    w.push(&[7u8; 60])?;
    w.finish()?;
    fs::copy(&p, out.join("pagefile/two-pages"))?;

    let b = tmp.path().join("b");
    let mut w = BlobWriter::create(&b, *b"SEED")?;
    for r in [&b"one"[..], b"", &[9u8; 40]] {
        w.append(r)?;
    }
    w.finish()?;
    fs::copy(&b, out.join("blob/three-records"))?;

    // Dense V-pages (the street model at fan-out 4 sees most entries), sparse ones with u8
    // indices (fan-out 20, 10 % of entries) and with u16 indices (fan-out 300).
    let sets = [
        ("", synthetic_vdata(&SyntheticSpec { cells: 3, fanout: 4, levels: 2, reach: 0.5, ..Default::default() })),
        ("-sparse", sparse_vdata(3, 20, 2, 0.1, 1)),
        ("-sparse-u16", sparse_vdata(2, 300, 2, 0.01, 1)),
    ];
    for (i, kind) in LayoutKind::ALL.into_iter().enumerate() {
        for ((name, data), dov) in sets.iter().flat_map(|s| [(s, DovCodec::F32), (s, DovCodec::LogU16)]) {
            if !name.is_empty() && kind == LayoutKind::Horizontal {
                continue;
            }
            let dir = tmp.path().join(format!("{kind}-{dov}{name}"));
            fs::create_dir(&dir)?;
            write_layout(&dir, kind, data, &LayoutOptions { page_size: 64, dov, ..Default::default() })?;
            let files: Vec<Vec<u8>> =
                kind.file_names().iter().map(|f| fs::read(dir.join(f))).collect::<Result<_, _>>()?;
            // The layout target's format: selector byte, u32 split, first file, second file.
            // Bit 7 set: the target recomputes checksums after mutation.
            let mut input = vec![i as u8 | 0x80];
            input.extend_from_slice(&(files[0].len() as u32).to_le_bytes());
            for f in &files {
                input.extend_from_slice(f);
            }
            fs::write(out.join(format!("layout/{kind}-{dov}{name}")), input)?;
        }
    }
    Ok(())
}
