//! Indexed-vertical layout (thesis §5.4.3): per cell only the (node, V-page pointer) pairs of
//! its visible nodes, in variable-length segments; a per-cell directory (in the metadata, read
//! at open) locates them. A flip reads O(N_vnode) bytes.
//!
//! Files: `vindex.indexed-vertical` = metadata with directory (C × [u32 page, u16 offset,
//! u32 count]), then the segments packed by the rule of [`packing`](super::packing), each
//! `count` × [u32 node, u32 page, u16 offset] sorted by node; `vpages.indexed-vertical` =
//! as `vpages.vertical`.

use super::context::{Tally, WriteCtx};
use super::packing::{ADDR_BYTES, Addr, Packer, PagedFile, record_pages};
use super::vertical::{CellVPageWriter, finish};
use super::{LayoutKind, LayoutSize, Meta, SEGMENT_PRIORITY};
use crate::error::Result;
use crate::le::u32_at;
use crate::page_reader::PageReader;
use crate::vpage::VEntry;

pub(crate) const INDEX_FILE: &str = "vindex.indexed-vertical";
pub(crate) const VPAGES_FILE: &str = "vpages.indexed-vertical";
pub(crate) const INDEX_TAG: [u8; 4] = *b"IVIX";
pub(crate) const VPAGES_TAG: [u8; 4] = *b"IVVP";

/// Bytes of one segment entry: node number, V-page address.
const PAIR_BYTES: usize = 4 + ADDR_BYTES;

/// Writes the indexed-vertical layout cell by cell: each cell's V-pages, then its segment,
/// whose address goes into the directory that the metadata gets at the end.
pub(crate) struct Writer {
    w: WriteCtx,
    vpages: CellVPageWriter,
    index: Packer,
    data_start: u64,
    directory: Vec<(Addr, u32)>,
    flip_total: u64,
    flip_max: u64,
    tally: Tally,
    addrs: Vec<(u32, Addr)>,
    bytes: Vec<u8>,
}

impl Writer {
    pub fn create(w: WriteCtx) -> Result<Self> {
        let vpages = CellVPageWriter::create(&w, VPAGES_FILE, VPAGES_TAG)?;
        let meta_len = Meta::encoded_len(LayoutKind::IndexedVertical, u64::from(w.cell_count), w.fanout.len() as u64);
        let data_start = record_pages(meta_len, w.cap() as u64);
        let index = w.index_after_placeholder(INDEX_FILE, INDEX_TAG, meta_len)?;
        let directory = Vec::with_capacity(w.cell_count as usize);
        Ok(Self {
            w,
            vpages,
            index,
            data_start,
            directory,
            flip_total: 0,
            flip_max: 0,
            tally: Tally::default(),
            addrs: Vec::new(),
            bytes: Vec::new(),
        })
    }

    pub fn push(&mut self, cell: &[(u32, Vec<VEntry>)]) -> Result<()> {
        self.vpages.put_cell(&self.w, cell, &mut self.addrs)?;
        self.bytes.clear();
        for &(node, addr) in &self.addrs {
            self.bytes.extend_from_slice(&node.to_le_bytes());
            addr.encode(&mut self.bytes);
        }
        self.directory.push((self.index.put(&self.bytes)?, self.addrs.len() as u32));
        let flip = record_pages(self.bytes.len() as u64, self.w.cap() as u64);
        self.flip_total += flip;
        self.flip_max = self.flip_max.max(flip);
        self.tally.add(cell);
        Ok(())
    }

    pub fn finish(self) -> Result<LayoutSize> {
        let w = &self.w;
        let (flips, tally, start, dir) =
            ((self.flip_total, self.flip_max), self.tally, self.data_start, self.directory);
        let meta = |vp_pages| w.meta(LayoutKind::IndexedVertical, start, vp_pages, tally, flips, dir);
        finish(w, self.vpages, self.index, meta, [INDEX_FILE, VPAGES_FILE])
    }
}

/// Checks what the cursors rely on: one directory entry per cell.
pub(crate) fn check(meta: &Meta, index: &PagedFile) -> Result<()> {
    if meta.directory.len() != meta.cell_count as usize {
        return Err(index.corrupt("directory length differs from the cell count"));
    }
    Ok(())
}

/// A cursor's selected segment: the cell's visible nodes (ascending) and their V-page
/// addresses.
#[derive(Default)]
pub(crate) struct Segment {
    seg: Vec<(u32, Addr)>,
}

impl Segment {
    pub fn flip(
        &mut self,
        meta: &Meta,
        index: &PagedFile,
        pages: &mut PageReader,
        cell: u32,
        bytes: &mut Vec<u8>,
    ) -> Result<()> {
        self.seg.clear();
        let (addr, count) = meta.directory[cell as usize];
        let len = (count as usize)
            .checked_mul(PAIR_BYTES)
            .filter(|&l| (l as u64) <= index.file.file_len())
            .ok_or_else(|| index.corrupt(format!("cell {cell}: {count} visible nodes cannot fit")))?;
        index.read_record(pages, SEGMENT_PRIORITY, addr, len, bytes)?;
        let mut prev: Option<u32> = None;
        for pair in bytes.chunks_exact(PAIR_BYTES) {
            let node = u32_at(pair, 0).unwrap_or(u32::MAX);
            let addr = Addr::decode(pair, 4).unwrap_or(Addr::NIL);
            if node >= meta.node_count || prev.is_some_and(|p| p >= node) {
                self.seg.clear();
                return Err(index.corrupt(format!("cell {cell}: segment lists node {node} out of order or range")));
            }
            prev = Some(node);
            self.seg.push((node, addr));
        }
        Ok(())
    }

    /// Nodes with a V-page in the selected cell.
    pub fn pointed_nodes(&self) -> impl Iterator<Item = u32> + '_ {
        self.seg.iter().map(|&(n, _)| n)
    }

    pub fn locate(&self, node: u32) -> Option<Addr> {
        self.seg.binary_search_by_key(&node, |&(n, _)| n).ok().map(|i| self.seg[i].1)
    }
}
