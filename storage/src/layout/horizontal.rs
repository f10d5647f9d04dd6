//! Horizontal layout (thesis §5.4.1): every node has C V-pages, one per cell, hidden ones
//! included, so a V-page is found by arithmetic and a cell flip reads nothing.
//!
//! File `vpages.horizontal`: metadata, then per node in dfs order a run of pages starting on a
//! page boundary, holding the node's C V-pages as equal-size slots packed by the rule of
//! [`packing`](super::packing): slot `c` of node `n` lies at
//! `first(n) + c / k` with `k = ⌊capacity / size⌋` slots per page (or `first(n) + c·⌈size /
//! capacity⌉` when a V-page exceeds a page). `first(n)` follows from the fan-outs (the thesis
//! keeps it as a pointer in the node); hidden nodes' slots are zero.

use super::context::{Tally, WriteCtx};
use super::packing::{Addr, PagedFile, SlotArray, rewrite_front};
use super::{LayoutKind, LayoutSize, Meta, layout_size};
use crate::error::Result;
use crate::pagefile::PageFileWriter;
use crate::vpage::{VEntry, VPageCodec, is_zero_page};

pub(crate) const VPAGES_FILE: &str = "vpages.horizontal";
pub(crate) const TAG: [u8; 4] = *b"HZVP";

/// Writes `vpages.horizontal` cell by cell. Each node's run of pages has a place fixed by the
/// fan-outs, so the file is sized first and each page is written where it belongs as soon as
/// its slots are filled: the writer holds one page per node.
pub(crate) struct Writer {
    w: WriteCtx,
    file: PageFileWriter,
    data_start: u64,
    /// First page of each node's run.
    first: Vec<u64>,
    /// Per node, the payload of the page being filled.
    open: Vec<Vec<u8>>,
    cell: u64,
    tally: Tally,
    slot: Vec<u8>,
}

impl Writer {
    pub fn create(w: WriteCtx) -> Result<Self> {
        let cap = w.cap() as u64;
        let path = w.dir.join(VPAGES_FILE);
        let meta_len = Meta::encoded_len(LayoutKind::Horizontal, u64::from(w.cell_count), w.fanout.len() as u64);
        let data_start = super::record_pages(meta_len, cap);
        let (first, page) = run_starts(&w.fanout, w.codec, w.cell_count, data_start, cap, u64::MAX)
            .ok_or_else(|| crate::error::Error::invalid(&path, "V-page runs beyond 2^64 pages"))?;
        let mut file = PageFileWriter::create(&path, TAG, w.page_size)?;
        file.extend_to(page)?;
        let open = vec![Vec::new(); w.fanout.len()];
        Ok(Self { w, file, data_start, first, open, cell: 0, tally: Tally::default(), slot: Vec::new() })
    }

    /// Every node's slot for the next cell: its V-page, or zeros where it is hidden.
    pub fn push(&mut self, cell: &[(u32, Vec<VEntry>)]) -> Result<()> {
        let cap = self.w.cap();
        let c = self.cell;
        let mut pages = cell.iter().peekable();
        for (node, &fanout) in self.w.fanout.iter().enumerate() {
            let size = self.w.codec.vpage_bytes(fanout);
            self.slot.clear();
            if let Some((_, entries)) = pages.next_if(|(n, _)| *n as usize == node)
                && !is_zero_page(entries)
            {
                self.w.codec.encode(entries, &mut self.slot);
            }
            self.slot.resize(size, 0);
            if size == 0 {
                continue;
            }
            let first = self.first[node];
            if size <= cap {
                let per_page = (cap / size) as u64;
                let open = &mut self.open[node];
                open.extend_from_slice(&self.slot);
                if open.len() == per_page as usize * size {
                    self.file.rewrite(first + c / per_page, open)?;
                    open.clear();
                }
            } else {
                let span = size.div_ceil(cap) as u64;
                for (i, chunk) in self.slot.chunks(cap).enumerate() {
                    self.file.rewrite(first + c * span + i as u64, chunk)?;
                }
            }
        }
        self.tally.add(cell);
        self.cell += 1;
        Ok(())
    }

    pub fn finish(mut self) -> Result<LayoutSize> {
        let cap = self.w.cap();
        // The last page of each run, partly filled.
        for (node, open) in self.open.iter().enumerate() {
            if !open.is_empty() {
                let per_page = (cap / self.w.codec.vpage_bytes(self.w.fanout[node])) as u64;
                self.file.rewrite(self.first[node] + (self.cell - 1) / per_page, open)?;
            }
        }
        let pages = self.file.page_count();
        let meta = self.w.meta(LayoutKind::Horizontal, self.data_start, pages, self.tally, (0, 0), Vec::new());
        rewrite_front(&mut self.file, &meta.encode())?;
        let page_size = u64::from(self.w.page_size);
        let bytes = self.file.finish()?;
        Ok(layout_size(vec![(VPAGES_FILE.to_string(), bytes)], (pages - self.data_start) * page_size))
    }
}

/// Where each node's run of V-pages starts, for `cells` slots of each node's V-page size
/// packed from page `data_start` on, and the page after the last run; `None` if a run would
/// end past page `limit` (a reader's file length) or overflow.
fn run_starts(
    fanout: &[u16],
    codec: VPageCodec,
    cells: u32,
    data_start: u64,
    cap: u64,
    limit: u64,
) -> Option<(Vec<u64>, u64)> {
    let mut first = Vec::with_capacity(fanout.len());
    let mut page = data_start;
    for &f in fanout {
        first.push(page);
        page = slots(codec.vpage_bytes(f) as u64, cap).pages(u64::from(cells)).and_then(|n| page.checked_add(n))?;
        if page > limit {
            return None;
        }
    }
    Some((first, page))
}

/// Pages the node runs of a layout of `cells` cells take (`None` past 2^64).
pub(crate) fn run_pages(fanout: &[u16], codec: VPageCodec, cells: u32, cap: u64) -> Option<u64> {
    run_starts(fanout, codec, cells, 0, cap, u64::MAX).map(|(_, pages)| pages)
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
        let (first, page) =
            run_starts(&meta.fanout, meta.codec, meta.cell_count, meta.data_start, cap, file.file.page_count())
                .ok_or_else(|| file.corrupt("V-page runs exceed the file"))?;
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
