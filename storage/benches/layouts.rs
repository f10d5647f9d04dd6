//! Cell flips and V-page fetches per layout, warm (mmap) and pread, plus a page-count table
//! showing flip cost O(N_node) for vertical against O(N_vnode) for indexed-vertical.
//!
//! `cargo bench -p hdov-storage --bench layouts` (short by default: 10 samples, 1 s each).

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, criterion_group};
use hdov_storage::synthetic::{SyntheticSpec, synthetic_vdata};
use hdov_storage::{Layout, LayoutCursor, LayoutKind, LayoutOptions, PageReader, ReadMode, VData, write_layout};

fn spec(fanout: u16, levels: u32, cells: u32) -> SyntheticSpec {
    SyntheticSpec { cells, fanout, levels, reach: 0.02, visible_share: 0.3, seed: 3 }
}

fn write_all(dir: &Path, data: &VData) {
    for kind in LayoutKind::ALL {
        write_layout(dir, kind, data, &LayoutOptions::default()).expect("write layout");
    }
}

/// Visible V-pages of `cell` read in dfs order, as a query that sees everything would.
fn read_cell(
    r: &mut LayoutCursor<'_>,
    pages: &mut PageReader,
    cell: u32,
    nodes: &[u32],
    buf: &mut Vec<hdov_storage::VEntry>,
) {
    r.flip_to_cell(cell, pages).expect("flip");
    for &n in nodes {
        black_box(r.vpage_into(n, 0.0, pages, buf).expect("vpage"));
    }
}

/// Pages per flip and per full-cell read, for trees of growing size with the same visibility.
fn print_page_table() {
    println!("\npages per cell flip and per read of all visible V-pages (4 KiB pages, f32 DoV)");
    println!("| N_node | N_vnode mean | layout | flip pages | V-page pages | bytes |");
    println!("|---:|---:|---|---:|---:|---:|");
    for (fanout, levels) in [(16, 2), (16, 3), (16, 4)] {
        let data = synthetic_vdata(&spec(fanout, levels, 16));
        let st = data.stats();
        let dir = tempfile::tempdir().expect("tempdir");
        write_all(dir.path(), &data);
        for kind in LayoutKind::ALL {
            let layout = Layout::open(dir.path(), kind, ReadMode::Mmap).expect("open");
            let mut r = layout.cursor();
            // No cache: each cell starts cold (reset_io forgets the read buffers).
            let mut pages = PageReader::uncached();
            let (mut flip, mut vp) = (0u64, 0u64);
            let mut buf = Vec::new();
            for cell in 0..st.cell_count {
                pages.reset_io();
                flip += r.flip_to_cell(cell, &mut pages).expect("flip").pages_read;
                let nodes: Vec<u32> = data.cells[cell as usize].iter().map(|(n, _)| *n).collect();
                for n in nodes {
                    r.vpage_into(n, 0.0, &mut pages, &mut buf).expect("vpage");
                }
                vp += pages.io().file(kind.file_names().last().expect("vpages file"));
            }
            let c = f64::from(st.cell_count);
            println!(
                "| {} | {:.1} | {kind} | {:.2} | {:.2} | {} |",
                st.node_count,
                st.visible_mean,
                flip as f64 / c,
                vp as f64 / c,
                layout.summary().bytes
            );
        }
    }
    println!();
}

fn bench_layouts(c: &mut Criterion) {
    // 1 + 16 + 256 + 4096 = 4369 nodes, 65536 objects, 32 cells.
    let data = synthetic_vdata(&spec(16, 4, 32));
    let dir = tempfile::tempdir().expect("tempdir");
    write_all(dir.path(), &data);
    let visible: Vec<Vec<u32>> = data.cells.iter().map(|c| c.iter().map(|(n, _)| *n).collect()).collect();
    let cells = data.cell_count;
    for mode in [ReadMode::Mmap, ReadMode::Pread] {
        let m = if mode == ReadMode::Mmap { "mmap" } else { "pread" };
        let mut flip = c.benchmark_group(format!("flip/{m}"));
        for kind in LayoutKind::ALL {
            let layout = Layout::open(dir.path(), kind, mode).expect("open");
            let mut r = layout.cursor();
            let mut pages = PageReader::uncached();
            let mut cell = 0;
            flip.bench_function(kind.name(), |b| {
                b.iter(|| {
                    // Consecutive cells: every iteration is a real flip.
                    cell = (cell + 1) % cells;
                    black_box(r.flip_to_cell(cell, &mut pages).expect("flip"));
                })
            });
        }
        flip.finish();
        let mut fetch = c.benchmark_group(format!("flip+all-visible-vpages/{m}"));
        for kind in LayoutKind::ALL {
            let layout = Layout::open(dir.path(), kind, mode).expect("open");
            let mut r = layout.cursor();
            let mut pages = PageReader::uncached();
            let mut buf = Vec::new();
            let mut cell = 0;
            fetch.bench_function(kind.name(), |b| {
                b.iter(|| {
                    cell = (cell + 1) % cells;
                    read_cell(&mut r, &mut pages, cell, &visible[cell as usize], &mut buf);
                })
            });
        }
        fetch.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    targets = bench_layouts
}

fn main() {
    print_page_table();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
