//! Vertical layout (thesis §5.4.2): per cell a segment of N_node V-page pointers, nil for
//! hidden nodes; a cell's V-pages stored together in dfs order. A flip reads one segment:
//! O(N_node) bytes whatever the cell sees.
//!
//! Files: `vindex.vertical` = metadata, then the C segments as equal-size slots (6·N_node
//! bytes each: u32 page + u16 offset per node, nil = 0xFFFFFFFF/0xFFFF), slot `c` found by
//! arithmetic; `vpages.vertical` = the visible V-pages, cell by cell, dfs order within a cell,
//! each dense or, with sparse encoding on, as the shorter of the two forms of
//! [`SparseCodec`](crate::vpage::SparseCodec).

use super::context::{Tally, WriteCtx};
use super::packing::{ADDR_BYTES, Addr, Packer, PagedFile, SlotArray, record_pages};
use super::{LayoutKind, LayoutSize, Meta, SEGMENT_PRIORITY, layout_size};
use crate::error::Result;
use crate::page_reader::PageReader;
use crate::pagefile::PageFileWriter;
use crate::vpage::{VEntry, is_zero_page};

pub(crate) const INDEX_FILE: &str = "vindex.vertical";
pub(crate) const VPAGES_FILE: &str = "vpages.vertical";
pub(crate) const INDEX_TAG: [u8; 4] = *b"VTIX";
pub(crate) const VPAGES_TAG: [u8; 4] = *b"VTVP";

/// The V-page file of the vertical layouts, written cell after cell, dfs order within a cell.
pub(crate) struct CellVPageWriter {
    p: Packer,
    buf: Vec<u8>,
}

impl CellVPageWriter {
    pub fn create(w: &WriteCtx, name: &str, tag: [u8; 4]) -> Result<Self> {
        let path = w.dir.join(name);
        Ok(Self { p: Packer::new(&path, PageFileWriter::create(&path, tag, w.page_size)?), buf: Vec::new() })
    }

    /// Stores the cell's visible V-pages; returns (node, address) of each, ascending node.
    pub fn put_cell(&mut self, w: &WriteCtx, cell: &[(u32, Vec<VEntry>)], out: &mut Vec<(u32, Addr)>) -> Result<()> {
        out.clear();
        for (node, entries) in cell {
            if is_zero_page(entries) {
                continue;
            }
            self.buf.clear();
            w.encode_vpage(entries, &mut self.buf);
            out.push((*node, self.p.put(&self.buf)?));
        }
        Ok(())
    }

    /// Finishes the file; returns (pages, file bytes).
    pub fn finish(self) -> Result<(u64, u64)> {
        self.p.finish()
    }
}

/// Writes the vertical layout cell by cell: each cell's V-pages, then its segment.
pub(crate) struct Writer {
    w: WriteCtx,
    vpages: CellVPageWriter,
    index: Packer,
    data_start: u64,
    flip: u64,
    tally: Tally,
    seg: Vec<Addr>,
    addrs: Vec<(u32, Addr)>,
    bytes: Vec<u8>,
}

impl Writer {
    pub fn create(w: WriteCtx) -> Result<Self> {
        let nodes = w.fanout.len();
        let cap = w.cap() as u64;
        let vpages = CellVPageWriter::create(&w, VPAGES_FILE, VPAGES_TAG)?;
        let meta_len = Meta::encoded_len(LayoutKind::Vertical, u64::from(w.cell_count), nodes as u64);
        let data_start = record_pages(meta_len, cap);
        let flip = record_pages((ADDR_BYTES * nodes) as u64, cap);
        let index = w.index_after_placeholder(INDEX_FILE, INDEX_TAG, meta_len)?;
        let seg = vec![Addr::NIL; nodes];
        Ok(Self {
            w,
            vpages,
            index,
            data_start,
            flip,
            tally: Tally::default(),
            seg,
            addrs: Vec::new(),
            bytes: Vec::new(),
        })
    }

    pub fn push(&mut self, cell: &[(u32, Vec<VEntry>)]) -> Result<()> {
        self.vpages.put_cell(&self.w, cell, &mut self.addrs)?;
        self.seg.fill(Addr::NIL);
        for &(node, addr) in &self.addrs {
            self.seg[node as usize] = addr;
        }
        self.bytes.clear();
        for a in &self.seg {
            a.encode(&mut self.bytes);
        }
        self.index.put(&self.bytes)?;
        self.tally.add(cell);
        Ok(())
    }

    pub fn finish(self) -> Result<LayoutSize> {
        let (w, flip) = (&self.w, self.flip);
        let flips = (flip * u64::from(w.cell_count), flip);
        let meta = |vp_pages| w.meta(LayoutKind::Vertical, self.data_start, vp_pages, self.tally, flips, Vec::new());
        finish(w, self.vpages, self.index, meta, [INDEX_FILE, VPAGES_FILE])
    }
}

/// The cells' segments, one address per node each, as equal-size slots from page `first`.
pub(crate) fn segment_slots(first: u64, nodes: u64, cap: u64) -> SlotArray {
    SlotArray { first, size: ADDR_BYTES as u64 * nodes, cap }
}

/// Where the cells' segments lie (immutable, shared by all cursors).
pub(crate) struct Segments {
    slots: SlotArray,
}

impl Segments {
    pub fn new(meta: &Meta, index: &PagedFile) -> Result<Self> {
        let slots = segment_slots(meta.data_start, u64::from(meta.node_count), index.file.capacity() as u64);
        let end = slots.pages(u64::from(meta.cell_count)).and_then(|n| n.checked_add(meta.data_start));
        if end != Some(index.file.page_count()) {
            return Err(index.corrupt(format!(
                "{} segments of {} nodes do not fill the file's {} pages",
                meta.cell_count,
                meta.node_count,
                index.file.page_count()
            )));
        }
        Ok(Self { slots })
    }
}

/// A cursor's selected segment: one pointer per node.
#[derive(Default)]
pub(crate) struct Segment {
    seg: Vec<Addr>,
}

impl Segment {
    pub fn flip(
        &mut self,
        segments: &Segments,
        meta: &Meta,
        index: &PagedFile,
        pages: &mut PageReader,
        cell: u32,
        bytes: &mut Vec<u8>,
    ) -> Result<()> {
        self.seg.clear();
        let (page, offset) = segments.slots.addr(u64::from(cell));
        let addr = Addr {
            page: u32::try_from(page).map_err(|_| index.corrupt("page number beyond 2^32"))?,
            offset: offset as u16,
        };
        index.read_record(pages, SEGMENT_PRIORITY, addr, segments.slots.size as usize, bytes)?;
        self.seg.extend(bytes.chunks_exact(ADDR_BYTES).map(|c| Addr::decode(c, 0).unwrap_or(Addr::NIL)));
        debug_assert_eq!(self.seg.len(), meta.node_count as usize);
        Ok(())
    }

    /// Nodes with a V-page in the selected cell.
    pub fn pointed_nodes(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.seg.len() as u32).filter(|&n| self.seg[n as usize] != Addr::NIL)
    }

    pub fn locate(&self, node: u32) -> Option<Addr> {
        self.seg.get(node as usize).copied().filter(|&a| a != Addr::NIL)
    }
}

/// Finishes a vertical layout's two files: the V-pages, then the index with `meta` over its
/// placeholder.
pub(super) fn finish(
    w: &WriteCtx,
    vpages: CellVPageWriter,
    index: Packer,
    meta: impl FnOnce(u64) -> Meta,
    names: [&str; 2],
) -> Result<LayoutSize> {
    let (vp_pages, vp_bytes) = vpages.finish()?;
    let (_, ix_bytes) = index.finish_with_front(&meta(vp_pages).encode())?;
    Ok(layout_size(
        vec![(names[0].to_string(), ix_bytes), (names[1].to_string(), vp_bytes)],
        vp_pages * u64::from(w.page_size),
    ))
}
