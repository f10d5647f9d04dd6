//! Vertical layout (thesis §5.4.2): per cell a segment of N_node V-page pointers, nil for
//! hidden nodes; a cell's V-pages stored together in dfs order. A flip reads one segment:
//! O(N_node) bytes whatever the cell sees.
//!
//! Files: `vindex.vertical` = metadata, then the C segments as equal-size slots (6·N_node
//! bytes each: u32 page + u16 offset per node, nil = 0xFFFFFFFF/0xFFFF), slot `c` found by
//! arithmetic; `vpages.vertical` = the visible V-pages, cell by cell, dfs order within a cell,
//! each dense or, with sparse encoding on, as the shorter of the two forms of
//! [`SparseCodec`](crate::vpage::SparseCodec).

use std::path::Path;

use super::packing::{ADDR_BYTES, Addr, Packer, PagedFile, SlotArray, record_pages};
use super::{LayoutKind, LayoutSize, Meta, SEGMENT_PRIORITY, WriteCtx, layout_size};
use crate::error::Result;
use crate::page_reader::PageReader;
use crate::pagefile::PageFileWriter;
use crate::vpage::is_zero_page;

pub(crate) const INDEX_FILE: &str = "vindex.vertical";
pub(crate) const VPAGES_FILE: &str = "vpages.vertical";
pub(crate) const INDEX_TAG: [u8; 4] = *b"VTIX";
pub(crate) const VPAGES_TAG: [u8; 4] = *b"VTVP";

/// The V-page file of the vertical layouts, as written.
pub(crate) struct CellVPages {
    /// Per cell, the (node, address) of each stored V-page.
    pub addrs: Vec<Vec<(u32, Addr)>>,
    pub pages: u64,
    pub bytes: u64,
}

/// Writes the visible V-pages of every cell, cell after cell, dfs order within a cell.
pub(crate) fn write_cell_vpages(w: &WriteCtx<'_>, path: &Path, tag: [u8; 4]) -> Result<CellVPages> {
    let mut p = Packer::new(path, PageFileWriter::create(path, tag, w.page_size)?);
    let mut buf = Vec::new();
    let mut addrs = Vec::with_capacity(w.data.cells.len());
    for cell in &w.data.cells {
        let mut a = Vec::with_capacity(cell.len());
        for (node, entries) in cell {
            if is_zero_page(entries) {
                continue;
            }
            buf.clear();
            w.encode_vpage(entries, &mut buf);
            a.push((*node, p.put(&buf)?));
        }
        addrs.push(a);
    }
    let (pages, bytes) = p.finish()?;
    Ok(CellVPages { addrs, pages, bytes })
}

pub(crate) fn write(w: &WriteCtx<'_>) -> Result<LayoutSize> {
    let data = w.data;
    let nodes = data.node_fanout.len();
    let cap = w.cap() as u64;
    let CellVPages { addrs, pages: vp_pages, bytes: vp_bytes } =
        write_cell_vpages(w, &w.dir.join(VPAGES_FILE), VPAGES_TAG)?;

    let meta_len = Meta::encoded_len(LayoutKind::Vertical, u64::from(data.cell_count), nodes as u64);
    let data_start = record_pages(meta_len, cap);
    let seg_len = (ADDR_BYTES * nodes) as u64;
    let flip = record_pages(seg_len, cap);
    let meta = Meta {
        kind: LayoutKind::Vertical,
        codec: w.codec,
        sparse: w.sparse,
        cell_count: data.cell_count,
        node_count: nodes as u32,
        data_start,
        vpages_pages: vp_pages,
        visible_total: w.stats.visible_total,
        flip_pages_total: flip * u64::from(data.cell_count),
        visible_max: w.stats.visible_max,
        flip_pages_max: flip as u32,
        fanout: data.node_fanout.clone(),
        directory: Vec::new(),
    };
    let index_path = w.dir.join(INDEX_FILE);
    let mut p = Packer::new(&index_path, PageFileWriter::create(&index_path, INDEX_TAG, w.page_size)?);
    p.put(&meta.encode())?;
    p.align()?;
    let mut seg = vec![Addr::NIL; nodes];
    let mut bytes = Vec::with_capacity(seg_len as usize);
    for cell in &addrs {
        seg.fill(Addr::NIL);
        for &(node, addr) in cell {
            seg[node as usize] = addr;
        }
        bytes.clear();
        for a in &seg {
            a.encode(&mut bytes);
        }
        p.put(&bytes)?;
    }
    let (_, ix_bytes) = p.finish()?;
    Ok(layout_size(
        vec![(INDEX_FILE.to_string(), ix_bytes), (VPAGES_FILE.to_string(), vp_bytes)],
        vp_pages * u64::from(w.page_size),
    ))
}

/// Where the cells' segments lie (immutable, shared by all cursors).
pub(crate) struct Segments {
    slots: SlotArray,
}

impl Segments {
    pub fn new(meta: &Meta, index: &PagedFile) -> Result<Self> {
        let slots = SlotArray {
            first: meta.data_start,
            size: (ADDR_BYTES as u64) * u64::from(meta.node_count),
            cap: index.file.capacity() as u64,
        };
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
