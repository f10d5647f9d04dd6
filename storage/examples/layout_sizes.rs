//! Writes the three layouts of a synthetic data set with each DoV codec, with and without
//! sparse V-pages, and prints a markdown table of sizes and flip costs (the tables in
//! `docs/storage-format.md`).
//!
//! `cargo run -p hdov-storage --release --example layout_sizes -- [CELLS FANOUT LEVELS]`: the
//! street model ([`synthetic_vdata`]);
//! `... -- sparse [CELLS FANOUT LEVELS ENTRY_PERCENT]`: [`sparse_vdata`], whose visible nodes
//! see ENTRY_PERCENT % of their entries.

use hdov_storage::synthetic::{SyntheticSpec, sparse_vdata, synthetic_vdata};
use hdov_storage::{DovCodec, Layout, LayoutKind, LayoutOptions, ReadMode, VEntry, write_layout};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let sparse_model = args.first().is_some_and(|a| a == "sparse");
    if sparse_model {
        args.remove(0);
    }
    let args: Vec<u32> = args.iter().map(|a| a.parse()).collect::<Result<_, _>>()?;
    let arg = |i: usize, d: u32| args.get(i).copied().unwrap_or(d);
    let data = if sparse_model {
        let (cells, fanout, levels, pct) = (arg(0, 256), arg(1, 126) as u16, arg(2, 2), arg(3, 5));
        println!("sparse model: fan-out {fanout}, {levels} levels, {pct} % of a visible node's entries visible");
        sparse_vdata(cells, fanout, levels, f64::from(pct) / 100.0, 1)
    } else {
        let spec = SyntheticSpec {
            cells: arg(0, 256),
            fanout: arg(1, 32) as u16,
            levels: arg(2, 3),
            reach: 0.02,
            visible_share: 0.3,
            seed: 1,
        };
        println!(
            "street model: fan-out {}, {} levels, {} objects",
            spec.fanout,
            spec.levels,
            u64::from(spec.fanout).pow(spec.levels)
        );
        synthetic_vdata(&spec)
    };
    let st = data.stats();
    let (mut pages, mut entries) = (0u64, 0u64);
    for (_, e) in data.cells.iter().flatten() {
        pages += 1;
        entries += e.iter().filter(|v| !VEntry::is_zero(v)).count() as u64;
    }
    println!(
        "{} cells, {} nodes, visible nodes per cell: mean {:.1}, max {}; visible entries per visible \
         node: {:.1}\n",
        st.cell_count,
        st.node_count,
        st.visible_mean,
        st.visible_max,
        entries as f64 / pages.max(1) as f64
    );
    println!("| layout | DoV | sparse | V-page bytes | index bytes | total | flip pages (mean / max) |");
    println!("|---|---|---|---:|---:|---:|---:|");
    let root = tempfile::tempdir()?;
    for kind in LayoutKind::ALL {
        for dov in [DovCodec::F32, DovCodec::LogU16] {
            // Horizontal has no sparse form.
            let modes: &[bool] = if kind == LayoutKind::Horizontal { &[false] } else { &[false, true] };
            for &sparse in modes {
                let dir = root.path().join(format!("{kind}-{dov}-{sparse}"));
                std::fs::create_dir(&dir)?;
                let size = write_layout(&dir, kind, &data, &LayoutOptions { dov, sparse, ..Default::default() })?;
                let s = Layout::open(&dir, kind, ReadMode::Mmap)?.summary();
                println!(
                    "| {kind} | {dov} | {} | {} | {} | {} | {:.2} / {} |",
                    if sparse { "yes" } else { "no" },
                    size.vpage_bytes,
                    size.index_bytes,
                    size.total_bytes(),
                    s.flip_pages_mean,
                    s.flip_pages_max
                );
                std::fs::remove_dir_all(&dir)?;
            }
        }
    }
    Ok(())
}
