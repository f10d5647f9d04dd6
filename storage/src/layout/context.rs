//! What every layout writer shares: the directory, the shape, the encodings and the page size
//! ([`WriteCtx`]), and the counts its metadata keeps ([`Tally`]).

use std::path::PathBuf;

use super::packing::{Addr, Packer};
use super::{LayoutKind, Meta};
use crate::error::Result;
use crate::pagefile::PageFileWriter;
use crate::vpage::{SparseCodec, VEntry, VPageCodec, is_zero_page};

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
    /// ([`super::vertical::finish`] puts it there).
    pub fn index_after_placeholder(&self, name: &str, tag: [u8; 4], meta_len: u64) -> Result<Packer> {
        let path = self.dir.join(name);
        let mut index = Packer::new(&path, PageFileWriter::create(&path, tag, self.page_size)?);
        index.put(&vec![0; meta_len as usize])?;
        index.align()?;
        Ok(index)
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
