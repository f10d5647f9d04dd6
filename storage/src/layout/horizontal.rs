//! Horizontal layout (thesis §5.4.1): every node has C V-pages, one per cell, hidden ones
//! included, so a V-page is found by arithmetic and a cell flip reads nothing.
//!
//! File `vpages.horizontal`: metadata, then per node in dfs order a run of pages starting on a
//! page boundary, holding the node's C V-pages as equal-size slots packed by the rule of
//! [`packing`](super::packing): slot `c` of node `n` lies at
//! `first(n) + c / k` with `k = ⌊capacity / size⌋` slots per page (or `first(n) + c·⌈size /
//! capacity⌉` when a V-page exceeds a page). `first(n)` follows from the fan-outs (the thesis
//! keeps it as a pointer in the node); hidden nodes' slots are zero.

use super::packing::{Addr, Packer, PagedFile, SlotArray};
use super::{LayoutKind, LayoutSize, Meta, WriteCtx, layout_size};
use crate::error::Result;
use crate::pagefile::PageFileWriter;
use crate::vpage::is_zero_page;

pub(crate) const VPAGES_FILE: &str = "vpages.horizontal";
pub(crate) const TAG: [u8; 4] = *b"HZVP";

pub(crate) fn write(w: &WriteCtx<'_>) -> Result<LayoutSize> {
    let data = w.data;
    let cells = data.cell_count as usize;
    let cap = w.cap() as u64;
    let path = w.dir.join(VPAGES_FILE);
    let meta_len = Meta::encoded_len(LayoutKind::Horizontal, u64::from(data.cell_count), data.node_fanout.len() as u64);
    let data_start = super::record_pages(meta_len, cap);
    let node_pages: u64 = data
        .node_fanout
        .iter()
        .map(|&f| slots(w.codec.vpage_bytes(f) as u64, cap).pages(cells as u64).unwrap_or(0))
        .sum();
    let meta = Meta {
        kind: LayoutKind::Horizontal,
        codec: w.codec,
        sparse: w.sparse,
        cell_count: data.cell_count,
        node_count: data.node_fanout.len() as u32,
        data_start,
        vpages_pages: data_start + node_pages,
        visible_total: w.stats.visible_total,
        flip_pages_total: 0,
        visible_max: w.stats.visible_max,
        flip_pages_max: 0,
        fanout: data.node_fanout.clone(),
        directory: Vec::new(),
    };
    let mut p = Packer::new(&path, PageFileWriter::create(&path, TAG, w.page_size)?);
    p.put(&meta.encode())?;
    // Each cell's list is sorted by node: one cursor per cell walks it as nodes advance.
    let mut cursor = vec![0usize; cells];
    let mut buf = Vec::new();
    for (node, &fanout) in data.node_fanout.iter().enumerate() {
        p.align()?;
        let size = w.codec.vpage_bytes(fanout);
        for (c, cell) in data.cells.iter().enumerate() {
            buf.clear();
            match cell.get(cursor[c]) {
                Some((n, entries)) if *n as usize == node => {
                    cursor[c] += 1;
                    if !is_zero_page(entries) {
                        w.codec.encode(entries, &mut buf);
                    }
                }
                _ => {}
            }
            buf.resize(size, 0);
            p.put(&buf)?;
        }
    }
    let (pages, bytes) = p.finish()?;
    debug_assert_eq!(pages, meta.vpages_pages);
    let vpage_bytes = (pages - data_start) * u64::from(w.page_size);
    Ok(layout_size(vec![(VPAGES_FILE.to_string(), bytes)], vpage_bytes))
}

fn slots(size: u64, cap: u64) -> SlotArray {
    SlotArray { first: 0, size, cap }
}

/// Where each node's run of V-pages starts (computed at open; immutable).
pub(crate) struct Runs {
    /// First page of each node's run of V-pages.
    first: Vec<u64>,
}

impl Runs {
    pub fn new(meta: &Meta, file: &PagedFile) -> Result<Self> {
        let cap = file.file.capacity() as u64;
        let mut first = Vec::with_capacity(meta.fanout.len());
        let mut page = meta.data_start;
        for &f in &meta.fanout {
            first.push(page);
            let run = slots(meta.codec.vpage_bytes(f) as u64, cap)
                .pages(u64::from(meta.cell_count))
                .and_then(|n| page.checked_add(n));
            page = match run {
                Some(p) if p <= file.file.page_count() => p,
                _ => return Err(file.corrupt("V-page runs exceed the file")),
            };
        }
        if page != file.file.page_count() {
            return Err(
                file.corrupt(format!("V-page runs end at page {page}, file has {} pages", file.file.page_count()))
            );
        }
        Ok(Self { first })
    }

    /// The slot of `node` for `cell` (always present: hidden nodes have zero slots).
    pub fn locate(&self, node: u32, cell: u32, len: usize, file: &PagedFile) -> Result<Option<Addr>> {
        if len == 0 {
            return Ok(None);
        }
        let cap = file.file.capacity() as u64;
        let s = SlotArray { first: self.first[node as usize], size: len as u64, cap };
        let (page, offset) = s.addr(u64::from(cell));
        let page = u32::try_from(page).map_err(|_| file.corrupt("page number beyond 2^32"))?;
        Ok(Some(Addr { page, offset: offset as u16 }))
    }
}
