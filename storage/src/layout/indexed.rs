//! Indexed-vertical layout (thesis §5.4.3): per cell only the (node, V-page pointer) pairs of
//! its visible nodes, in variable-length segments; a per-cell directory (in the metadata, read
//! at open) locates them. A flip reads O(N_vnode) bytes.
//!
//! Files: `vindex.indexed-vertical` = metadata with directory (C × [u32 page, u16 offset,
//! u32 count]), then the segments packed by the rule of [`packing`](super::packing), each
//! `count` × [u32 node, u32 page, u16 offset] sorted by node; `vpages.indexed-vertical` =
//! as `vpages.vertical`.

use super::packing::{ADDR_BYTES, Addr, Packer, PagedFile, record_pages};
use super::vertical::{CellVPages, write_cell_vpages};
use super::{LayoutKind, LayoutSize, Meta, SEGMENT_PRIORITY, WriteCtx, layout_size};
use crate::error::Result;
use crate::le::u32_at;
use crate::page_reader::PageReader;
use crate::pagefile::PageFileWriter;

pub(crate) const INDEX_FILE: &str = "vindex.indexed-vertical";
pub(crate) const VPAGES_FILE: &str = "vpages.indexed-vertical";
pub(crate) const INDEX_TAG: [u8; 4] = *b"IVIX";
pub(crate) const VPAGES_TAG: [u8; 4] = *b"IVVP";

/// Bytes of one segment entry: node number, V-page address.
const PAIR_BYTES: usize = 4 + ADDR_BYTES;

pub(crate) fn write(w: &WriteCtx<'_>) -> Result<LayoutSize> {
    let data = w.data;
    let nodes = data.node_fanout.len();
    let cap = w.cap();
    let CellVPages { addrs, pages: vp_pages, bytes: vp_bytes } =
        write_cell_vpages(w, &w.dir.join(VPAGES_FILE), VPAGES_TAG)?;

    let meta_len = Meta::encoded_len(LayoutKind::IndexedVertical, u64::from(data.cell_count), nodes as u64);
    let data_start = record_pages(meta_len, cap as u64);
    // Place the segments first (no writing) so the directory can go in the metadata.
    let mut dry = Packer::dry_run(&w.dir.join(INDEX_FILE), cap, data_start);
    let mut directory = Vec::with_capacity(addrs.len());
    let mut flip_total = 0u64;
    let mut flip_max = 0u64;
    let mut zeros = Vec::new();
    for cell in &addrs {
        zeros.resize(cell.len() * PAIR_BYTES, 0);
        directory.push((dry.put(&zeros)?, cell.len() as u32));
        let flip = record_pages(zeros.len() as u64, cap as u64);
        flip_total += flip;
        flip_max = flip_max.max(flip);
    }
    let meta = Meta {
        kind: LayoutKind::IndexedVertical,
        codec: w.codec,
        sparse: w.sparse,
        cell_count: data.cell_count,
        node_count: nodes as u32,
        data_start,
        vpages_pages: vp_pages,
        visible_total: w.stats.visible_total,
        flip_pages_total: flip_total,
        visible_max: w.stats.visible_max,
        flip_pages_max: flip_max as u32,
        fanout: data.node_fanout.clone(),
        directory,
    };
    let index_path = w.dir.join(INDEX_FILE);
    let mut p = Packer::new(&index_path, PageFileWriter::create(&index_path, INDEX_TAG, w.page_size)?);
    p.put(&meta.encode())?;
    p.align()?;
    let mut bytes = Vec::new();
    for (cell, (want, _)) in addrs.iter().zip(&meta.directory) {
        bytes.clear();
        for &(node, addr) in cell {
            bytes.extend_from_slice(&node.to_le_bytes());
            addr.encode(&mut bytes);
        }
        let got = p.put(&bytes)?;
        debug_assert_eq!(got, *want);
    }
    let (_, ix_bytes) = p.finish()?;
    Ok(layout_size(
        vec![(INDEX_FILE.to_string(), ix_bytes), (VPAGES_FILE.to_string(), vp_bytes)],
        vp_pages * u64::from(w.page_size),
    ))
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
