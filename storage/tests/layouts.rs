//! The three layouts return the same V-pages, equal to the input (bit-exact with f32 DoVs,
//! within the stated bound with log-u16), and read the pages their design says they read.

use std::path::Path;

use hdov_storage::layout::MAX_LAYOUT_PAGE_SIZE;
use hdov_storage::synthetic::{SyntheticSpec, sparse_vdata, synthetic_vdata};
use hdov_storage::vpage::LOG_DOV_REL_ERROR;
use hdov_storage::{
    DovCodec, Error, Layout, LayoutKind, LayoutOptions, PageReader, ReadMode, VData, VEntry, write_layout,
};
use proptest::prelude::*;

fn write_all(dir: &Path, data: &VData, opts: &LayoutOptions) {
    for kind in LayoutKind::ALL {
        write_layout(dir, kind, data, opts).unwrap();
    }
}

/// The input's V-page for (cell, node), all-zero pages counting as hidden.
fn expected(data: &VData, cell: usize, node: u32) -> Option<&[VEntry]> {
    let c = &data.cells[cell];
    let i = c.binary_search_by_key(&node, |(n, _)| *n).ok()?;
    let e = &c[i].1;
    (!e.iter().all(VEntry::is_zero)).then_some(&e[..])
}

fn check_equal(got: &[VEntry], want: &[VEntry], codec: DovCodec) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.nvo, w.nvo);
        match codec {
            DovCodec::F32 => assert_eq!(g.dov.to_bits(), w.dov.to_bits()),
            DovCodec::LogU16 => {
                if w.dov == 0.0 {
                    assert_eq!(g.dov, 0.0);
                } else {
                    assert!(g.dov > 0.0, "visible entry became hidden");
                    let min = hdov_storage::vpage::LOG_DOV_MIN as f32;
                    let w_dov = w.dov.clamp(min, 1.0);
                    assert!((g.dov - w_dov).abs() <= w_dov * LOG_DOV_REL_ERROR, "{} stored as {}", w.dov, g.dov);
                }
            }
        }
    }
}

/// Reads every (cell, node) from every layout in both read modes and compares with the input.
fn check_layouts(dir: &Path, data: &VData, codec: DovCodec) {
    for kind in LayoutKind::ALL {
        for mode in [ReadMode::Mmap, ReadMode::Pread] {
            let layout = Layout::open(dir, kind, mode).unwrap();
            assert_eq!(layout.cell_count(), data.cell_count);
            assert_eq!(layout.node_count() as usize, data.node_fanout.len());
            let mut pages = PageReader::uncached();
            let mut r = layout.cursor();
            let mut buf = Vec::new();
            for cell in 0..data.cell_count {
                r.flip_to_cell(cell, &mut pages).unwrap();
                for node in 0..data.node_fanout.len() as u32 {
                    let want = expected(data, cell as usize, node);
                    let visible = r.vpage_into(node, 0.0, &mut pages, &mut buf).unwrap();
                    assert_eq!(visible, want.is_some(), "{kind} cell {cell} node {node}");
                    if let Some(want) = want {
                        check_equal(&buf, want, codec);
                    } else {
                        assert!(buf.is_empty());
                    }
                }
            }
            for f in pages.io().files {
                assert_eq!(f.requested, f.hits + f.pages_read, "{kind}: {f:?}");
            }
        }
    }
}

/// One node's V-page of `f` entries: dense visibility (about a third of the DoVs drawn are
/// zero) or sparse (each entry visible with probability 1/20), so that the sparse V-page
/// encoding is exercised with both forms.
fn arb_vpage(f: usize) -> impl Strategy<Value = Vec<VEntry>> {
    // DoVs: hidden, ordinary, and below the log scale's floor; NVOs small or needing u32.
    let entry = (prop_oneof![Just(0.0f32), 0.0f32..=1.0, 1e-12f32..1e-6], prop_oneof![0u32..10, Just(70_000u32)])
        .prop_map(|(dov, nvo)| VEntry { dov, nvo });
    (any::<bool>(), prop::collection::vec((entry, 0u8..20), f)).prop_map(|(sparse, v)| {
        v.into_iter().map(|(e, r)| if sparse && r != 0 { VEntry::default() } else { e }).collect()
    })
}

fn arb_vdata() -> impl Strategy<Value = VData> {
    // Fan-outs from 0, and some above 256 (sparse entry indices then take u16).
    let fanout = prop_oneof![3 => 0u16..40, 1 => 250u16..=300];
    (1u32..6, prop::collection::vec(fanout, 1..12)).prop_flat_map(|(cells, fanout)| {
        // Per node, visible with probability 1/2: its V-page, else nothing.
        let cell: Vec<_> = fanout.iter().map(|&f| prop::option::weighted(0.5, arb_vpage(usize::from(f)))).collect();
        let cells_strategy = prop::collection::vec(cell, cells as usize);
        (Just(fanout), cells_strategy).prop_map(move |(node_fanout, raw)| VData {
            cell_count: cells,
            node_fanout,
            cells: raw
                .into_iter()
                .map(|c| {
                    let visible = c.into_iter().enumerate();
                    visible.filter_map(|(n, p)| p.map(|p| (n as u32, p))).collect()
                })
                .collect(),
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn layouts_agree_with_input(
        data in arb_vdata(),
        page_size in prop_oneof![Just(64u32), Just(100), Just(4096)],
        quantise in any::<bool>(),
        sparse in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let dov = if quantise { DovCodec::LogU16 } else { DovCodec::F32 };
        write_all(dir.path(), &data, &LayoutOptions { page_size, dov, sparse });
        check_layouts(dir.path(), &data, dov);
    }
}

/// Byte 3 of a layout's metadata (page 0 of its first file, after the `page_size`-byte header).
fn meta_sparse_byte(dir: &Path, kind: LayoutKind, page_size: usize) -> u8 {
    std::fs::read(dir.join(kind.file_names()[0])).unwrap()[page_size + 3]
}

#[test]
fn sparse_vpages_round_trip_and_shrink_the_vertical_layouts() {
    // Fan-out 126 with 5 % of a visible node's entries visible (u8 indices), and fan-out 300
    // (u16 indices).
    for (fanout, index_bytes) in [(126u16, 1u8), (300, 2)] {
        let data = sparse_vdata(12, fanout, 2, 0.05, 3);
        let mut entries = 0;
        for (_, e) in data.cells.iter().flatten() {
            entries += e.iter().filter(|v| !v.is_zero()).count();
        }
        let pages: usize = data.cells.iter().map(Vec::len).sum();
        assert!(entries < pages * usize::from(fanout) / 10, "the data set is sparse");
        for dov in [DovCodec::F32, DovCodec::LogU16] {
            let dense = tempfile::tempdir().unwrap();
            let sparse = tempfile::tempdir().unwrap();
            write_all(dense.path(), &data, &LayoutOptions { dov, sparse: false, ..Default::default() });
            write_all(sparse.path(), &data, &LayoutOptions { dov, ..Default::default() });
            check_layouts(sparse.path(), &data, dov);
            check_layouts(dense.path(), &data, dov);
            for kind in LayoutKind::ALL {
                let stored = if kind == LayoutKind::Horizontal { 0 } else { index_bytes };
                assert_eq!(meta_sparse_byte(sparse.path(), kind, 4096), stored, "{kind}");
                assert_eq!(meta_sparse_byte(dense.path(), kind, 4096), 0, "{kind}");
                let bytes = |d: &Path| -> u64 {
                    kind.file_names().iter().map(|f| std::fs::metadata(d.join(f)).unwrap().len()).sum()
                };
                let (d, s) = (bytes(dense.path()), bytes(sparse.path()));
                match kind {
                    LayoutKind::Horizontal => assert_eq!(d, s),
                    // V-page bytes: each entry of 4..8 bytes becomes index + entry for 5 % of
                    // entries, so the V-page file shrinks by far more than 3×.
                    _ => {
                        let vp = kind.file_names()[1];
                        let size = |d: &Path| std::fs::metadata(d.join(vp)).unwrap().len();
                        assert!(size(sparse.path()) * 3 < size(dense.path()), "{kind} {dov}: {s} vs {d}");
                        assert!(s < d);
                    }
                }
            }
        }
    }
}

#[test]
fn sparse_encoding_picks_the_smaller_form() {
    // A V-page with every entry visible stays dense (header 0) in a sparse layout; one with a
    // single visible entry becomes header 1, its index, its entry.
    let full = vec![VEntry { dov: 0.5, nvo: 1 }; 4];
    let mut one = vec![VEntry::default(); 4];
    one[2] = VEntry { dov: 0.25, nvo: 7 };
    let data = VData { cell_count: 1, node_fanout: vec![4, 4], cells: vec![vec![(0, full), (1, one)]] };
    let dir = tempfile::tempdir().unwrap();
    write_layout(dir.path(), LayoutKind::Vertical, &data, &LayoutOptions { page_size: 64, ..Default::default() })
        .unwrap();
    let b = std::fs::read(dir.path().join("vpages.vertical")).unwrap();
    let page = &b[64..128];
    // Dense: header 0, 4 × (f32 0.5, u16 1).
    assert_eq!(page[0], 0);
    assert_eq!(&page[1..5], &0.5f32.to_le_bytes());
    assert_eq!(&page[5..7], &1u16.to_le_bytes());
    // Sparse: at 1 + 4·6 = 25: count 1, index 2, f32 0.25, u16 7; then zero padding.
    assert_eq!(&page[25..27], &[1, 2]);
    assert_eq!(&page[27..31], &0.25f32.to_le_bytes());
    assert_eq!(&page[31..33], &7u16.to_le_bytes());
    assert!(page[33..60].iter().all(|&x| x == 0));
    check_layouts_one(dir.path(), LayoutKind::Vertical, &data);
}

fn check_layouts_one(dir: &Path, kind: LayoutKind, data: &VData) {
    let layout = Layout::open(dir, kind, ReadMode::Mmap).unwrap();
    let mut pages = PageReader::uncached();
    let mut r = layout.cursor();
    r.flip_to_cell(0, &mut pages).unwrap();
    for (node, want) in &data.cells[0] {
        assert_eq!(r.vpage(*node, 0.0, &mut pages).unwrap().as_deref(), Some(&want[..]));
    }
}

#[test]
fn synthetic_round_trip_small_pages() {
    // Page size 64: many V-pages span pages, many segments too.
    let data = synthetic_vdata(&SyntheticSpec { cells: 7, fanout: 9, levels: 3, ..Default::default() });
    assert!(data.stats().visible_total > 0);
    for dov in [DovCodec::F32, DovCodec::LogU16] {
        for page_size in [64, 4096] {
            let dir = tempfile::tempdir().unwrap();
            write_all(dir.path(), &data, &LayoutOptions { page_size, dov, ..Default::default() });
            check_layouts(dir.path(), &data, dov);
        }
    }
}

#[test]
fn flip_costs_follow_the_design() {
    // 1 + 32 + 32^2 = 1057 nodes; a vertical segment is 6342 bytes = 2 pages of 4 KiB.
    let data =
        synthetic_vdata(&SyntheticSpec { cells: 20, fanout: 32, levels: 3, reach: 0.05, visible_share: 0.2, seed: 7 });
    let dir = tempfile::tempdir().unwrap();
    write_all(dir.path(), &data, &LayoutOptions::default());
    let stats = data.stats();
    for kind in LayoutKind::ALL {
        let layout = Layout::open(dir.path(), kind, ReadMode::Mmap).unwrap();
        let s = layout.summary();
        assert_eq!(s.visible_nodes_max, stats.visible_max);
        let mut pages = PageReader::uncached();
        let mut r = layout.cursor();
        for cell in [3u32, 11, 0, 19] {
            let cost = r.flip_to_cell(cell, &mut pages).unwrap();
            let visible = data.cells[cell as usize].len() as u64;
            match kind {
                LayoutKind::Horizontal => assert_eq!(cost.pages_read, 0),
                LayoutKind::Vertical => assert_eq!(cost.pages_read, 2),
                // 10 bytes per visible node, at most one page here.
                LayoutKind::IndexedVertical => {
                    assert_eq!(cost.pages_read, u64::from(visible > 0) * (visible * 10).div_ceil(4092))
                }
            }
            // Segments of these cells share no page: with no cache, all is read.
            assert_eq!(cost.requested, cost.pages_read);
            assert!(cost.pages_read <= u64::from(s.flip_pages_max));
            assert_eq!(r.flip_to_cell(cell, &mut pages).unwrap(), Default::default(), "same cell is free");
        }
        // Reading every visible V-page of a cell in dfs order: vertical layouts read each page
        // of the cell's run once; horizontal reads one page per visible node.
        r.flip_to_cell(5, &mut pages).unwrap();
        pages.reset_io();
        let visible: Vec<u32> = data.cells[5].iter().map(|(n, _)| *n).collect();
        for &n in &visible {
            assert!(r.vpage(n, 0.0, &mut pages).unwrap().is_some());
        }
        let vp_file = kind.file_names().last().unwrap();
        let pages = pages.io().file(vp_file);
        match kind {
            LayoutKind::Horizontal => assert_eq!(pages, visible.len() as u64),
            _ => {
                let bytes = visible.len() as u64 * 32 * 6;
                assert!(pages <= bytes.div_ceil(4092) + 1, "{kind}: {pages} pages");
            }
        }
    }
}

#[test]
fn sizes_rank_as_in_the_thesis() {
    let data = synthetic_vdata(&SyntheticSpec { cells: 30, fanout: 16, levels: 3, ..Default::default() });
    let dir = tempfile::tempdir().unwrap();
    let size = |kind, dov| {
        let d = dir.path().join(format!("{kind}-{dov}"));
        std::fs::create_dir(&d).unwrap();
        let s = write_layout(&d, kind, &data, &LayoutOptions { dov, ..Default::default() }).unwrap();
        let on_disk: u64 = s
            .files
            .iter()
            .map(|(f, b)| {
                assert_eq!(std::fs::metadata(d.join(f)).unwrap().len(), *b);
                b
            })
            .sum();
        assert_eq!(on_disk, s.total_bytes());
        s.total_bytes()
    };
    let h = size(LayoutKind::Horizontal, DovCodec::F32);
    let v = size(LayoutKind::Vertical, DovCodec::F32);
    let iv = size(LayoutKind::IndexedVertical, DovCodec::F32);
    assert!(h > v && v > iv, "horizontal {h}, vertical {v}, indexed {iv}");
    let iv_q = size(LayoutKind::IndexedVertical, DovCodec::LogU16);
    assert!(iv_q < iv);
}

#[test]
fn misuse_is_an_error() {
    let data = synthetic_vdata(&SyntheticSpec { cells: 3, fanout: 4, levels: 2, ..Default::default() });
    let dir = tempfile::tempdir().unwrap();
    write_all(dir.path(), &data, &LayoutOptions::default());
    for kind in LayoutKind::ALL {
        let layout = Layout::open(dir.path(), kind, ReadMode::Mmap).unwrap();
        let mut pages = PageReader::uncached();
        let mut r = layout.cursor();
        assert!(matches!(r.vpage(0, 0.0, &mut pages), Err(Error::Invalid { .. })), "before any flip");
        assert!(r.flip_to_cell(3, &mut pages).is_err());
        r.flip_to_cell(2, &mut pages).unwrap();
        assert!(r.vpage(5, 0.0, &mut pages).is_err());
        // Another layout's directory is not this one.
        let other = tempfile::tempdir().unwrap();
        assert!(matches!(Layout::open(other.path(), kind, ReadMode::Mmap), Err(Error::Io { .. })));
    }
    let mut bad = data.clone();
    bad.cell_count = 4;
    assert!(matches!(
        write_layout(dir.path(), LayoutKind::Vertical, &bad, &LayoutOptions::default()),
        Err(Error::Invalid { .. })
    ));
    let opts = LayoutOptions { page_size: MAX_LAYOUT_PAGE_SIZE * 2, ..Default::default() };
    assert!(write_layout(dir.path(), LayoutKind::Vertical, &data, &opts).is_err());
    assert_eq!("indexed-vertical".parse::<LayoutKind>(), Ok(LayoutKind::IndexedVertical));
    assert_eq!(LayoutKind::Vertical.to_string(), "vertical");
    assert!("diagonal".parse::<LayoutKind>().is_err());
}

/// A layout written cell by cell refuses what does not fit its shape, in one error, and a
/// writer finished early writes nothing that opens.
#[test]
fn layout_writer_refuses_what_breaks_its_shape() {
    use hdov_storage::{LayoutWriter, VShape};
    let data = synthetic_vdata(&SyntheticSpec { cells: 5, fanout: 4, levels: 2, ..Default::default() });
    let shape = VShape::of(&data);
    let opts = LayoutOptions { page_size: 256, ..Default::default() };
    for kind in LayoutKind::ALL {
        let dir = tempfile::tempdir().unwrap();
        let mut w = LayoutWriter::create(dir.path(), kind, &shape, &opts).unwrap();
        // An NVO above the shape's largest would not fit the field width chosen for it.
        let mut big = data.cells[0].clone();
        if let Some((_, e)) = big.first_mut() {
            e[0].nvo = shape.nvo_max + 1;
            assert!(w.push_cell(&big).is_err(), "{kind}: NVO above the shape");
        }
        // Nodes out of order, and out of range.
        let fanout = data.node_fanout[0] as usize;
        let entry = VEntry { dov: 0.5, nvo: 1 };
        assert!(w.push_cell(&[(1, vec![entry; data.node_fanout[1] as usize]), (0, vec![entry; fanout])]).is_err());
        assert!(w.push_cell(&[(data.node_fanout.len() as u32, vec![entry; 1])]).is_err());
        for cell in &data.cells[..4] {
            w.push_cell(cell).unwrap();
        }
        let msg = w.finish().unwrap_err().to_string();
        assert!(msg.contains("4 of 5 cells"), "{kind}: {msg}");
        assert!(Layout::open(dir.path(), kind, ReadMode::Mmap).is_err(), "{kind}: a half-written layout opened");
        // One cell too many.
        let mut w = LayoutWriter::create(dir.path(), kind, &shape, &opts).unwrap();
        for cell in &data.cells {
            w.push_cell(cell).unwrap();
        }
        assert!(w.push_cell(&data.cells[0]).is_err(), "{kind}: a sixth cell of five");
        w.finish().unwrap();
        Layout::open(dir.path(), kind, ReadMode::Mmap).unwrap().verify().unwrap();
    }
}
