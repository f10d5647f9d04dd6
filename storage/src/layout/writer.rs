//! Writing a layout cell by cell: [`LayoutWriter`] takes the V-pages of cell 0, then cell 1,
//! and so on, and holds only its write buffers (a page per node for horizontal; the current
//! page of each file and the cells' directory for the vertical layouts), never the grid's
//! V-data. So a merge of shards, or a build whose cells come from disk, writes every layout in
//! memory bounded by what one cell (or one shard) brings. The files are the same, byte for
//! byte, as those written from a whole [`VData`] ([`super::write_layout`] uses this writer).

use std::path::{Path, PathBuf};

use super::packing::Addr;
use super::{LayoutKind, LayoutOptions, LayoutSize, MAX_LAYOUT_PAGE_SIZE, Meta, horizontal, indexed, vertical};
use crate::error::{Error, Result};
use crate::pagefile::MIN_PAGE_SIZE;
use crate::vpage::{SparseCodec, VData, VEntry, VPageCodec, is_zero_page, validate_cell};

/// What a layout must know before its first cell: the grid's cell count, the tree's fan-outs,
/// and the largest NVO of any entry (it decides the NVO field's width).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VShape {
    pub cell_count: u32,
    /// Entries per node, by depth-first number.
    pub node_fanout: Vec<u16>,
    pub nvo_max: u32,
}

impl VShape {
    /// The shape of a whole V-data.
    pub fn of(data: &VData) -> VShape {
        VShape { cell_count: data.cell_count, node_fanout: data.node_fanout.clone(), nvo_max: data.stats().nvo_max }
    }
}

/// What every layout writer needs: the directory, the shape, the encodings, the page size.
pub(crate) struct WriteCtx {
    pub dir: PathBuf,
    pub cell_count: u32,
    pub fanout: Vec<u16>,
    pub codec: VPageCodec,
    /// The sparse-capable V-page encoding, if used (never for horizontal).
    pub sparse: Option<SparseCodec>,
    pub page_size: u32,
}

impl WriteCtx {
    pub fn cap(&self) -> usize {
        self.page_size as usize - crate::pagefile::PAGE_CRC_LEN
    }

    /// The layout's metadata record, once its counts are known.
    #[allow(clippy::too_many_arguments)]
    pub fn meta(
        &self,
        kind: LayoutKind,
        data_start: u64,
        vpages_pages: u64,
        tally: Tally,
        flip_pages: (u64, u64),
        directory: Vec<(Addr, u32)>,
    ) -> Meta {
        Meta {
            kind,
            codec: self.codec,
            sparse: self.sparse,
            cell_count: self.cell_count,
            node_count: self.fanout.len() as u32,
            data_start,
            vpages_pages,
            visible_total: tally.visible_total,
            flip_pages_total: flip_pages.0,
            visible_max: tally.visible_max,
            flip_pages_max: flip_pages.1 as u32,
            fanout: self.fanout.clone(),
            directory,
        }
    }

    /// A vertical layout's index file, its first `meta_len` bytes a placeholder for the metadata
    /// record, whose counts (and, for indexed-vertical, directory) are known only at the end
    /// ([`WriteCtx::finish_vertical`] puts it there).
    pub fn index_after_placeholder(&self, name: &str, tag: [u8; 4], meta_len: u64) -> Result<super::packing::Packer> {
        let path = self.dir.join(name);
        let mut index =
            super::packing::Packer::new(&path, crate::pagefile::PageFileWriter::create(&path, tag, self.page_size)?);
        index.put(&vec![0; meta_len as usize])?;
        index.align()?;
        Ok(index)
    }

    /// Finishes a vertical layout's two files: the V-pages, then the index with `meta` over its
    /// placeholder.
    pub fn finish_vertical(
        &self,
        vpages: super::vertical::CellVPageWriter,
        index: super::packing::Packer,
        meta: impl FnOnce(u64) -> Meta,
        names: [&str; 2],
    ) -> Result<LayoutSize> {
        let (vp_pages, vp_bytes) = vpages.finish()?;
        let (_, ix_bytes) = index.finish_with_front(&meta(vp_pages).encode())?;
        Ok(super::layout_size(
            vec![(names[0].to_string(), ix_bytes), (names[1].to_string(), vp_bytes)],
            vp_pages * u64::from(self.page_size),
        ))
    }

    /// Appends the record of one stored V-page (dense, or the shorter form when sparse).
    pub fn encode_vpage(&self, entries: &[VEntry], out: &mut Vec<u8>) {
        match &self.sparse {
            Some(sp) => sp.encode(&self.codec, entries, out),
            None => self.codec.encode(entries, out),
        }
    }
}

/// The summary counts a layout's metadata keeps: visible (stored) V-pages over all cells and in
/// the fullest cell.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Tally {
    pub visible_total: u64,
    pub visible_max: u32,
}

impl Tally {
    pub fn add(&mut self, cell: &[(u32, Vec<VEntry>)]) {
        let visible = cell.iter().filter(|(_, e)| !is_zero_page(e)).count() as u32;
        self.visible_total += u64::from(visible);
        self.visible_max = self.visible_max.max(visible);
    }
}

enum Inner {
    Horizontal(horizontal::Writer),
    Vertical(vertical::Writer),
    Indexed(indexed::Writer),
}

/// Writes one layout into a directory, one cell at a time, in cell order.
pub struct LayoutWriter {
    dir: PathBuf,
    fanout: Vec<u16>,
    cell_count: u32,
    nvo_max: u32,
    pushed: u32,
    inner: Inner,
}

impl LayoutWriter {
    /// Creates the `kind` layout's files in the existing directory `dir`.
    pub fn create(dir: &Path, kind: LayoutKind, shape: &VShape, opts: &LayoutOptions) -> Result<LayoutWriter> {
        if !(MIN_PAGE_SIZE..=MAX_LAYOUT_PAGE_SIZE).contains(&opts.page_size) {
            return Err(Error::invalid(
                dir,
                format!("page size {} outside {MIN_PAGE_SIZE}..={MAX_LAYOUT_PAGE_SIZE}", opts.page_size),
            ));
        }
        if u32::try_from(shape.node_fanout.len()).is_err() {
            return Err(Error::invalid(dir, format!("{} nodes: more than 2^32", shape.node_fanout.len())));
        }
        let codec = VPageCodec::new(opts.dov, shape.nvo_max);
        let sparse = (opts.sparse && kind != LayoutKind::Horizontal)
            .then(|| SparseCodec::for_max_fanout(shape.node_fanout.iter().copied().max().unwrap_or(0)));
        let w = WriteCtx {
            dir: dir.to_path_buf(),
            cell_count: shape.cell_count,
            fanout: shape.node_fanout.clone(),
            codec,
            sparse,
            page_size: opts.page_size,
        };
        let inner = match kind {
            LayoutKind::Horizontal => Inner::Horizontal(horizontal::Writer::create(w)?),
            LayoutKind::Vertical => Inner::Vertical(vertical::Writer::create(w)?),
            LayoutKind::IndexedVertical => Inner::Indexed(indexed::Writer::create(w)?),
        };
        Ok(LayoutWriter {
            dir: dir.to_path_buf(),
            fanout: shape.node_fanout.clone(),
            cell_count: shape.cell_count,
            nvo_max: shape.nvo_max,
            pushed: 0,
            inner,
        })
    }

    /// Writes the next cell's visible V-pages: (node, V-entries), ascending node, as
    /// [`VData::cells`] holds them. Checked as [`VData::validate`] checks a cell, and every NVO
    /// against the shape's largest.
    pub fn push_cell(&mut self, cell: &[(u32, Vec<VEntry>)]) -> Result<()> {
        let c = self.pushed;
        if c >= self.cell_count {
            return Err(Error::invalid(&self.dir, format!("cell {c} pushed to a layout of {} cells", self.cell_count)));
        }
        validate_cell(c as usize, cell, &self.fanout).map_err(|r| Error::invalid(&self.dir, r))?;
        if let Some(e) = cell.iter().flat_map(|(_, e)| e).find(|e| e.nvo > self.nvo_max) {
            return Err(Error::invalid(
                &self.dir,
                format!("cell {c}: NVO {} above the shape's {}", e.nvo, self.nvo_max),
            ));
        }
        match &mut self.inner {
            Inner::Horizontal(w) => w.push(cell)?,
            Inner::Vertical(w) => w.push(cell)?,
            Inner::Indexed(w) => w.push(cell)?,
        }
        self.pushed += 1;
        Ok(())
    }

    /// Writes the metadata and finishes (syncs) the files once every cell is in.
    pub fn finish(self) -> Result<LayoutSize> {
        if self.pushed != self.cell_count {
            return Err(Error::invalid(&self.dir, format!("{} of {} cells written", self.pushed, self.cell_count)));
        }
        match self.inner {
            Inner::Horizontal(w) => w.finish(),
            Inner::Vertical(w) => w.finish(),
            Inner::Indexed(w) => w.finish(),
        }
    }
}
