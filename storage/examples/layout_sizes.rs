//! Writes the three layouts of a synthetic data set with each DoV codec and prints a markdown
//! table of sizes and flip costs (the table in `docs/storage-format.md`).
//!
//! `cargo run -p hdov-storage --release --example layout_sizes -- [CELLS FANOUT LEVELS]`

use hdov_storage::synthetic::{SyntheticSpec, synthetic_vdata};
use hdov_storage::{DovCodec, LayoutKind, LayoutOptions, LayoutReader, ReadMode, write_layout};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<u32> = std::env::args().skip(1).map(|a| a.parse()).collect::<Result<_, _>>()?;
    let spec = SyntheticSpec {
        cells: args.first().copied().unwrap_or(256),
        fanout: args.get(1).copied().unwrap_or(32) as u16,
        levels: args.get(2).copied().unwrap_or(3),
        reach: 0.02,
        visible_share: 0.3,
        seed: 1,
    };
    let data = synthetic_vdata(&spec);
    let st = data.stats();
    println!(
        "{} cells, {} nodes (fan-out {}, {} levels, {} objects), visible nodes per cell: mean \
         {:.1}, max {}\n",
        st.cell_count,
        st.node_count,
        spec.fanout,
        spec.levels,
        u64::from(spec.fanout).pow(spec.levels),
        st.visible_mean,
        st.visible_max
    );
    println!("| layout | DoV | V-page bytes | index bytes | total | flip pages (mean / max) |");
    println!("|---|---|---:|---:|---:|---:|");
    let root = tempfile::tempdir()?;
    for kind in LayoutKind::ALL {
        for dov in [DovCodec::F32, DovCodec::LogU16] {
            let dir = root.path().join(format!("{kind}-{dov}"));
            std::fs::create_dir(&dir)?;
            let size = write_layout(&dir, kind, &data, &LayoutOptions { dov, ..Default::default() })?;
            let s = LayoutReader::open(&dir, kind, ReadMode::Mmap)?.summary();
            println!(
                "| {kind} | {dov} | {} | {} | {} | {:.2} / {} |",
                size.vpage_bytes,
                size.index_bytes,
                size.total_bytes(),
                s.flip_pages_mean,
                s.flip_pages_max
            );
            std::fs::remove_dir_all(&dir)?;
        }
    }
    Ok(())
}
