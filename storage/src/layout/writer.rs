//! Writing a layout cell by cell: [`LayoutWriter`] takes the V-pages of cell 0, then cell 1,
//! and so on, and holds only its write buffers (a page per node for horizontal; the current
//! page of each file and the cells' directory for the vertical layouts), never the grid's
//! V-data. So a merge of shards, or a build whose cells come from disk, writes every layout in
//! memory bounded by what one cell (or one shard) brings. The files are the same, byte for
//! byte, as those written from a whole [`VData`] ([`super::write_layout`] uses this writer).

use std::path::{Path, PathBuf};

use super::context::WriteCtx;
use super::{LayoutKind, LayoutOptions, LayoutSize, MAX_LAYOUT_PAGE_SIZE, horizontal, indexed, vertical};
use crate::error::{Error, Result};
use crate::pagefile::{MIN_PAGE_SIZE, PAGE_CRC_LEN};
use crate::vpage::{SparseCodec, VData, VEntry, VPageCodec, validate_cell};

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

    /// Bytes the `kind` layout spends on a slot for every (node, cell), seen or not: the
    /// horizontal layout's V-page runs, the vertical layout's segments; none for indexed-vertical,
    /// which stores only what each cell sees. They grow as cells × nodes and are known before a
    /// V-page is written, so a build can leave out a layout that would be mostly empty slots
    /// (saturates at `u64::MAX`). A page size the writers refuse is taken as the nearest they
    /// accept: [`LayoutWriter::create`] refuses it.
    pub fn slot_bytes(&self, kind: LayoutKind, opts: &LayoutOptions) -> u64 {
        let page = opts.page_size.clamp(MIN_PAGE_SIZE, MAX_LAYOUT_PAGE_SIZE);
        let cap = u64::from(page) - PAGE_CRC_LEN as u64;
        let pages = match kind {
            LayoutKind::Horizontal => {
                let codec = VPageCodec::new(opts.dov, self.nvo_max);
                horizontal::run_pages(&self.node_fanout, codec, self.cell_count, cap)
            }
            LayoutKind::Vertical => {
                vertical::segment_slots(0, self.node_fanout.len() as u64, cap).pages(u64::from(self.cell_count))
            }
            LayoutKind::IndexedVertical => Some(0),
        };
        pages.map_or(u64::MAX, |p| p.saturating_mul(u64::from(page)))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::{Meta, record_pages, write_layout};
    use crate::pagefile::{PageFile, ReadMode};
    use crate::synthetic::{SyntheticSpec, synthetic_vdata};
    use crate::vpage::DovCodec;

    /// `slot_bytes` is what the writers lay down: horizontal's V-page pages, vertical's
    /// segment pages, for slots smaller and larger than a page.
    #[test]
    fn slot_bytes_are_the_slots_written() {
        for (cells, fanout, levels, page_size, dov) in
            [(30, 16, 3, 4096, DovCodec::F32), (7, 4, 2, 256, DovCodec::LogU16), (5, 16, 2, 64, DovCodec::F32)]
        {
            let data = synthetic_vdata(&SyntheticSpec { cells, fanout, levels, ..Default::default() });
            let shape = VShape::of(&data);
            let opts = LayoutOptions { page_size, dov, ..Default::default() };
            let dir = tempfile::tempdir().unwrap();
            let h = write_layout(dir.path(), LayoutKind::Horizontal, &data, &opts).unwrap();
            assert_eq!(shape.slot_bytes(LayoutKind::Horizontal, &opts), h.vpage_bytes, "{page_size}");
            // The same by the thesis's arithmetic: per node, C slots of its V-page size packed
            // whole into pages, or each spread over whole pages.
            let cap = u64::from(page_size) - PAGE_CRC_LEN as u64;
            let codec = VPageCodec::new(dov, shape.nvo_max);
            let c = u64::from(cells);
            let runs: u64 = (shape.node_fanout.iter())
                .map(|&f| codec.vpage_bytes(f) as u64)
                .map(|s| if s <= cap { c.div_ceil(cap / s) } else { c * s.div_ceil(cap) })
                .sum();
            assert_eq!(h.vpage_bytes, runs * u64::from(page_size), "{page_size}");
            write_layout(dir.path(), LayoutKind::Vertical, &data, &opts).unwrap();
            let path = dir.path().join(vertical::INDEX_FILE);
            let index = PageFile::open(&path, vertical::INDEX_TAG, ReadMode::Mmap).unwrap();
            let meta = Meta::encoded_len(LayoutKind::Vertical, u64::from(cells), shape.node_fanout.len() as u64);
            let segments = index.page_count() - record_pages(meta, cap);
            assert_eq!(shape.slot_bytes(LayoutKind::Vertical, &opts), segments * u64::from(page_size));
            assert_eq!(shape.slot_bytes(LayoutKind::IndexedVertical, &opts), 0);
        }
    }
}
