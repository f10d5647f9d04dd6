//! The page-access seam: a `PageReader` answers from its read buffer, then its cache, then the
//! file, and counts each per file; a `Layout` is shared by threads, each with its own cursor.

use std::path::Path;

use hdov_storage::synthetic::{SyntheticSpec, synthetic_vdata};
use hdov_storage::{
    CacheLimits, FileIo, Layout, LayoutCursor, LayoutKind, LayoutOptions, PageFile, PageFileWriter, PageReader,
    PolicyKind, ReadMode, VData, VEntry, write_layout,
};

const KIND: [u8; 4] = *b"TEST";
const PAGE: u32 = 128;

/// A page file of `n` pages, page `i` starting with `i` as a u32.
fn pages_file(dir: &Path, name: &str, n: u32) -> PageFile {
    let path = dir.join(name);
    let mut w = PageFileWriter::create(&path, KIND, PAGE).unwrap();
    for i in 0..n {
        w.push(&i.to_le_bytes()).unwrap();
    }
    w.finish().unwrap();
    PageFile::open(&path, KIND, ReadMode::Mmap).unwrap()
}

fn counts(io: &FileIo) -> (u64, u64, u64) {
    (io.requested, io.hits, io.pages_read)
}

fn read(r: &mut PageReader, f: &PageFile, n: u64, priority: f64) {
    let p = r.page(f, n, priority).unwrap();
    assert_eq!(&p[..4], &(n as u32).to_le_bytes());
    assert_eq!(p.len(), f.capacity());
}

#[test]
fn types_are_send_and_sync_where_promised() {
    fn send<T: Send>() {}
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Layout>();
    send_sync::<PageFile>();
    send::<PageReader>();
    send::<LayoutCursor<'static>>();
}

#[test]
fn files_get_distinct_ids_and_their_names() {
    let dir = tempfile::tempdir().unwrap();
    let a = pages_file(dir.path(), "a.pages", 2);
    let b = pages_file(dir.path(), "b.pages", 2);
    let a2 = PageFile::open(a.path(), KIND, ReadMode::Pread).unwrap();
    assert_ne!(a.id(), b.id());
    assert_ne!(a.id(), a2.id(), "every open is its own file for the cache");
    assert_eq!((a.name(), b.name(), a2.name()), ("a.pages", "b.pages", "a.pages"));
}

#[test]
fn the_read_buffer_makes_a_re_read_free_and_counts_it_as_a_hit() {
    let dir = tempfile::tempdir().unwrap();
    let f = pages_file(dir.path(), "f", 4);
    let g = pages_file(dir.path(), "g", 4);
    let mut r = PageReader::uncached();
    read(&mut r, &f, 1, 0.0);
    read(&mut r, &f, 1, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (2, 1, 1));
    // One frame per file: reading another file keeps f's page.
    read(&mut r, &g, 3, 0.0);
    read(&mut r, &f, 1, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (3, 2, 1));
    // Another page of f replaces its frame; there is no cache behind it.
    read(&mut r, &f, 2, 0.0);
    read(&mut r, &f, 1, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (5, 2, 3));
    assert_eq!(r.cache().len(), 0, "uncached keeps nothing");
    assert_eq!(r.cache().stats().requests, 4, "the cache sees only what the buffer missed");
    let io = r.io();
    assert_eq!(io.files.iter().map(|f| f.file.as_str()).collect::<Vec<_>>(), ["f", "g"]);
    assert_eq!((io.requested(), io.hits(), io.pages_read()), (6, 2, 4));
    assert_eq!(io.file("g"), 1);
    // A cold start forgets the buffer: the same page is read again.
    r.reset_io();
    assert_eq!(io_total(&r), (0, 0, 0));
    read(&mut r, &f, 1, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (1, 0, 1));
    // A failed read is counted as a read and empties the buffer.
    assert!(r.page(&f, 9, 0.0).is_err());
    read(&mut r, &f, 1, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (3, 0, 3));
}

fn io_total(r: &PageReader) -> (u64, u64, u64) {
    let io = r.io();
    (io.requested(), io.hits(), io.pages_read())
}

#[test]
fn lru_floods_on_a_cyclic_scan_while_dov_keeps_the_important_pages() {
    let dir = tempfile::tempdir().unwrap();
    let k = 4u64;
    let f = pages_file(dir.path(), "f", k as u32 + 1);
    // Pages 0 and 1 are the important ones (high DoV).
    let priority = |n: u64| if n < 2 { 0.9 } else { 0.1 };
    let rounds = 10;
    let scan = |r: &mut PageReader| {
        for _ in 0..rounds {
            for n in 0..=k {
                read(r, &f, n, priority(n));
            }
        }
    };
    let mut lru = PageReader::new(CacheLimits::max_pages(k as usize), PolicyKind::Lru);
    scan(&mut lru);
    let io = lru.file_io(&f);
    // Consecutive requests differ, so the buffer never answers, and LRU evicts each page just
    // before it comes round again.
    assert_eq!(counts(&io), (rounds * (k + 1), 0, rounds * (k + 1)));
    assert_eq!(lru.cache().stats().hits, 0);

    for policy in [PolicyKind::Dov, PolicyKind::DOV_TIME] {
        let mut dov = PageReader::new(CacheLimits::max_pages(k as usize), policy);
        scan(&mut dov);
        let io = dov.file_io(&f);
        // After the first round pages 0 and 1 always hit; the rest share k − 2 frames.
        assert!(io.hits >= 2 * (rounds - 1), "{policy}: {io:?}");
        assert_eq!(io.requested, io.hits + io.pages_read);
        let resident = (0..2).filter(|&n| dov.set_priority(&f, n, priority(n))).count();
        assert_eq!(resident, 2, "{policy}: the important pages stay");
    }
}

#[test]
fn requested_is_hits_plus_reads_per_file_and_limits_hold() {
    let dir = tempfile::tempdir().unwrap();
    let files: Vec<PageFile> = (0..3).map(|i| pages_file(dir.path(), &format!("f{i}"), 16)).collect();
    let cap = files[0].capacity() as u64;
    // Room for 5 pages by bytes (pages: unlimited), then for 3 by pages and 5 by bytes.
    for limits in [CacheLimits::max_bytes(5 * cap + cap / 2), CacheLimits { pages: Some(3), bytes: Some(5 * cap) }] {
        for policy in [PolicyKind::None, PolicyKind::Lru, PolicyKind::Dov, PolicyKind::DOV_TIME] {
            let mut r = PageReader::new(limits, policy);
            let mut x = 7u64;
            for step in 0..600u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let f = &files[((x >> 33) % 3) as usize];
                let n = (x >> 40) % if step % 3 == 0 { 2 } else { 16 };
                read(&mut r, f, n, (n as f64) / 16.0);
                let c = r.cache();
                assert!(c.bytes() <= limits.bytes.unwrap(), "{policy}: {} bytes", c.bytes());
                assert!(limits.pages.is_none_or(|p| c.len() <= p));
                assert_eq!(c.bytes(), c.len() as u64 * cap);
            }
            let io = r.io();
            assert_eq!(io.files.len(), 3);
            for f in &io.files {
                assert_eq!(f.requested, f.hits + f.pages_read, "{policy}: {f:?}");
            }
            // The cache's counts are what the buffers passed on.
            let s = r.cache().stats();
            assert_eq!(s.misses, io.pages_read());
            assert!(s.requests <= io.requested());
            if policy == PolicyKind::None {
                assert_eq!(s.hits, 0);
            } else {
                assert!(s.hits > 0, "{policy}");
            }
        }
    }
}

#[test]
fn reset_io_keeps_the_cache_and_clear_empties_it() {
    let dir = tempfile::tempdir().unwrap();
    let f = pages_file(dir.path(), "f", 8);
    let mut r = PageReader::new(CacheLimits::UNLIMITED, PolicyKind::Lru);
    for n in 0..8 {
        read(&mut r, &f, n, 0.0);
    }
    r.reset_io();
    assert_eq!(r.cache().len(), 8);
    assert_eq!(r.cache().stats().requests, 0);
    for n in 0..8 {
        read(&mut r, &f, n, 0.0);
    }
    assert_eq!(counts(&r.file_io(&f)), (8, 8, 0), "a warm cache");
    r.clear();
    assert!(r.cache().is_empty());
    read(&mut r, &f, 7, 0.0);
    assert_eq!(counts(&r.file_io(&f)), (9, 8, 1), "clear keeps the counts, drops the pages and buffer");
    assert!(!r.set_priority(&f, 0, 1.0));
    assert!(r.set_priority(&f, 7, 1.0));
}

fn layouts(dir: &Path) -> VData {
    let data = synthetic_vdata(&SyntheticSpec { cells: 6, fanout: 8, levels: 3, reach: 0.2, ..Default::default() });
    for kind in LayoutKind::ALL {
        write_layout(dir, kind, &data, &LayoutOptions { page_size: 256, ..Default::default() }).unwrap();
    }
    data
}

/// Every (cell, node) of `layout`, each cell's nodes in the given order.
fn all_vpages(layout: &Layout, pages: &mut PageReader, cells: &[u32]) -> Vec<(u32, u32, Option<Vec<VEntry>>)> {
    let mut cursor = layout.cursor();
    let mut out = Vec::new();
    for &cell in cells {
        cursor.flip_to_cell(cell, pages).unwrap();
        assert_eq!(cursor.cell(), Some(cell));
        for node in 0..layout.node_count() {
            out.push((cell, node, cursor.vpage(node, f64::from(node % 3), pages).unwrap()));
        }
    }
    out
}

#[test]
fn cursors_on_threads_read_what_one_cursor_reads() {
    let dir = tempfile::tempdir().unwrap();
    let data = layouts(dir.path());
    let cells: Vec<u32> = (0..data.cell_count).collect();
    for kind in LayoutKind::ALL {
        let layout = Layout::open(dir.path(), kind, ReadMode::Mmap).unwrap();
        let one = all_vpages(&layout, &mut PageReader::uncached(), &cells);
        let reversed: Vec<u32> = cells.iter().rev().copied().collect();
        let (a, b) = std::thread::scope(|s| {
            let a = s.spawn(|| {
                let mut pages = PageReader::new(CacheLimits::max_pages(3), PolicyKind::Dov);
                all_vpages(&layout, &mut pages, &cells)
            });
            let b = s.spawn(|| {
                let mut pages = PageReader::new(CacheLimits::max_pages(2), PolicyKind::Lru);
                all_vpages(&layout, &mut pages, &reversed)
            });
            (a.join().unwrap(), b.join().unwrap())
        });
        assert_eq!(a, one, "{kind}");
        let mut b = b;
        b.sort_by_key(|&(c, n, _)| (c, n));
        assert_eq!(b, one, "{kind}");
    }
}

#[test]
fn a_cache_saves_reads_and_the_counts_say_where_they_went() {
    let dir = tempfile::tempdir().unwrap();
    let data = layouts(dir.path());
    let cells: Vec<u32> = (0..data.cell_count).chain(0..data.cell_count).collect();
    for kind in LayoutKind::ALL {
        let layout = Layout::open(dir.path(), kind, ReadMode::Mmap).unwrap();
        let mut cold = PageReader::uncached();
        let mut warm = PageReader::new(CacheLimits::UNLIMITED, PolicyKind::Lru);
        assert_eq!(all_vpages(&layout, &mut cold, &cells), all_vpages(&layout, &mut warm, &cells));
        let (c, w) = (cold.io(), warm.io());
        assert_eq!(c.requested(), w.requested(), "{kind}: the same requests");
        // The second pass over the cells reads nothing with an unlimited cache.
        let file_pages: u64 = layout.files().map(PageFile::page_count).sum();
        assert!(w.pages_read() <= file_pages, "{kind}: {w:?}");
        assert!(w.pages_read() < c.pages_read(), "{kind}");
        let names: Vec<&str> = w.files.iter().map(|f| f.file.as_str()).collect();
        let expected: Vec<&str> = kind.file_names().to_vec();
        assert_eq!(names, expected, "{kind}: one entry per file, index first");
        // A flip's cost is the index file's pages, as requested and as read.
        let mut cursor = layout.cursor();
        let mut pages = PageReader::new(CacheLimits::UNLIMITED, PolicyKind::Lru);
        let first = cursor.flip_to_cell(1, &mut pages).unwrap();
        cursor.flip_to_cell(2, &mut pages).unwrap();
        let again = cursor.flip_to_cell(1, &mut pages).unwrap();
        assert_eq!(first.requested, again.requested);
        assert_eq!(again.pages_read, 0, "{kind}: the segment is cached");
        if kind == LayoutKind::Horizontal {
            assert_eq!(first.requested, 0);
            assert_eq!(cursor.visible_nodes(), None);
        } else {
            assert!(first.requested > 0 && first.pages_read == first.requested);
            let stored = data.cells[1].iter().filter(|(_, e)| !e.iter().all(VEntry::is_zero));
            let visible: Vec<u32> = stored.map(|(n, _)| *n).collect();
            assert_eq!(cursor.visible_nodes(), Some(visible));
        }
        assert_eq!(layout.cursor().visible_nodes(), None, "no cell selected");
    }
}

#[test]
fn layouts_agree_through_any_reader() {
    let dir = tempfile::tempdir().unwrap();
    let data = layouts(dir.path());
    let cells: Vec<u32> = (0..data.cell_count).collect();
    let mut per_kind = Vec::new();
    for kind in LayoutKind::ALL {
        let layout = Layout::open(dir.path(), kind, ReadMode::Pread).unwrap();
        assert!(layout.verify().unwrap() > 0);
        let mut pages = PageReader::new(CacheLimits::max_pages(2), PolicyKind::DOV_TIME);
        per_kind.push(all_vpages(&layout, &mut pages, &cells));
    }
    assert_eq!(per_kind[0], per_kind[1]);
    assert_eq!(per_kind[1], per_kind[2]);
    let visible = per_kind[0].iter().filter(|(_, _, v)| v.is_some()).count();
    let stored = data.cells.iter().flatten().filter(|(_, e)| !e.iter().all(VEntry::is_zero)).count();
    assert_eq!(visible, stored);
}
