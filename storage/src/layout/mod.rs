//! The three V-page layouts of thesis §5.4 and a reader that counts the pages it reads.
//!
//! | layout | files | cell flip reads | V-page read |
//! |---|---|---|---|
//! | horizontal | `vpages.horizontal` | nothing | arithmetic: node's first page + slot of the cell |
//! | vertical | `vindex.vertical`, `vpages.vertical` | the cell's segment of N_node pointers | pointer from the segment |
//! | indexed-vertical | `vindex.indexed-vertical`, `vpages.indexed-vertical` | the cell's (node, pointer) pairs of visible nodes | binary search in the segment |
//!
//! Every file is a [`PageFile`]; records are packed into pages so that a
//! record no larger than a page never straddles two (`docs/storage-format.md` §4). The first file of each layout starts with a metadata record (cell and node
//! counts, V-entry codec, fan-outs, summary counts; for indexed-vertical also the per-cell
//! directory), read once at open. `docs/storage-format.md` gives every byte.

mod horizontal;
mod indexed;
mod packing;
mod vertical;

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use crate::error::{Error, Result};
use crate::io_stats::{FileIo, IoStats};
use crate::le::{u32_at, u64_at};
use crate::pagefile::{MIN_PAGE_SIZE, PageFile, ReadMode};
use crate::vpage::{DovCodec, SparseCodec, VData, VDataStats, VEntry, VPageCodec};
use packing::{Addr, PagedFile, record_pages};

/// Which layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LayoutKind {
    Horizontal,
    Vertical,
    IndexedVertical,
}

impl LayoutKind {
    pub const ALL: [LayoutKind; 3] = [LayoutKind::Horizontal, LayoutKind::Vertical, LayoutKind::IndexedVertical];

    /// The name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            LayoutKind::Horizontal => "horizontal",
            LayoutKind::Vertical => "vertical",
            LayoutKind::IndexedVertical => "indexed-vertical",
        }
    }

    /// The files this layout writes into a directory, index (if any) first.
    pub fn file_names(self) -> &'static [&'static str] {
        match self {
            LayoutKind::Horizontal => &[horizontal::VPAGES_FILE],
            LayoutKind::Vertical => &[vertical::INDEX_FILE, vertical::VPAGES_FILE],
            LayoutKind::IndexedVertical => &[indexed::INDEX_FILE, indexed::VPAGES_FILE],
        }
    }

    fn code(self) -> u8 {
        match self {
            LayoutKind::Horizontal => 0,
            LayoutKind::Vertical => 1,
            LayoutKind::IndexedVertical => 2,
        }
    }
}

impl fmt::Display for LayoutKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for LayoutKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        LayoutKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown layout {s:?} (horizontal, vertical, indexed-vertical)"))
    }
}

/// The largest page size a layout accepts: in-page offsets are u16.
pub const MAX_LAYOUT_PAGE_SIZE: u32 = 65536;

/// How to write a layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayoutOptions {
    /// Disk page size in bytes (the unit that reads are counted in).
    pub page_size: u32,
    /// How DoVs are stored.
    pub dov: DovCodec,
    /// Vertical and indexed-vertical: store each V-page densely or as its visible entries
    /// (index, V-entry), whichever is smaller (`docs/storage-format.md` §5). Horizontal ignores
    /// it: its V-page slots are found by arithmetic, so they keep one fixed size.
    pub sparse: bool,
}

impl Default for LayoutOptions {
    fn default() -> Self {
        Self { page_size: 4096, dov: DovCodec::F32, sparse: true }
    }
}

/// What a written layout takes on disk.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct LayoutSize {
    /// Bytes of the pages that hold V-pages.
    pub vpage_bytes: u64,
    /// All other bytes of the layout's files: file headers, metadata, directories, segments.
    pub index_bytes: u64,
    /// Each file's name and length in bytes.
    pub files: Vec<(String, u64)>,
}

impl LayoutSize {
    pub fn total_bytes(&self) -> u64 {
        self.vpage_bytes + self.index_bytes
    }
}

/// What changing cell cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct FlipCost {
    pub pages_read: u64,
}

/// Counts describing a written layout, from its metadata (no I/O).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutSummary {
    pub kind: LayoutKind,
    pub dov: DovCodec,
    pub page_size: u32,
    pub cell_count: u32,
    pub node_count: u32,
    pub visible_nodes_mean: f64,
    pub visible_nodes_max: u32,
    /// Pages a cell flip reads (0 for horizontal; the segment's pages otherwise).
    pub flip_pages_mean: f64,
    pub flip_pages_max: u32,
    /// Bytes of all the layout's files.
    pub bytes: u64,
}

/// Writes the `kind` layout of `data` into the existing directory `dir`.
///
/// V-pages whose entries are all (0, 0) are treated as invisible and not stored.
pub fn write_layout(dir: &Path, kind: LayoutKind, data: &VData, opts: &LayoutOptions) -> Result<LayoutSize> {
    data.validate().map_err(|r| Error::invalid(dir, r))?;
    if !(MIN_PAGE_SIZE..=MAX_LAYOUT_PAGE_SIZE).contains(&opts.page_size) {
        return Err(Error::invalid(
            dir,
            format!("page size {} outside {MIN_PAGE_SIZE}..={MAX_LAYOUT_PAGE_SIZE}", opts.page_size),
        ));
    }
    let stats = data.stats();
    let codec = VPageCodec::new(opts.dov, stats.nvo_max);
    let sparse = (opts.sparse && kind != LayoutKind::Horizontal)
        .then(|| SparseCodec::for_max_fanout(data.node_fanout.iter().copied().max().unwrap_or(0)));
    let w = WriteCtx { dir, data, stats, codec, sparse, page_size: opts.page_size };
    match kind {
        LayoutKind::Horizontal => horizontal::write(&w),
        LayoutKind::Vertical => vertical::write(&w),
        LayoutKind::IndexedVertical => indexed::write(&w),
    }
}

/// What every layout writer needs.
pub(crate) struct WriteCtx<'a> {
    pub dir: &'a Path,
    pub data: &'a VData,
    pub stats: VDataStats,
    pub codec: VPageCodec,
    /// The sparse-capable V-page encoding, if used (never for horizontal).
    pub sparse: Option<SparseCodec>,
    pub page_size: u32,
}

impl WriteCtx<'_> {
    pub fn cap(&self) -> usize {
        self.page_size as usize - crate::pagefile::PAGE_CRC_LEN
    }

    /// Appends the record of one stored V-page (dense, or the shorter form when sparse).
    pub fn encode_vpage(&self, entries: &[VEntry], out: &mut Vec<u8>) {
        match &self.sparse {
            Some(sp) => sp.encode(&self.codec, entries, out),
            None => self.codec.encode(entries, out),
        }
    }
}

/// Bytes of the metadata record's fixed part.
pub(crate) const META_FIXED: usize = 48;
/// Bytes of one indexed-vertical directory entry: segment address, visible count.
pub(crate) const DIR_ENTRY_BYTES: usize = packing::ADDR_BYTES + 4;

/// The metadata record at the start of a layout's first file.
#[derive(Clone, Debug)]
pub(crate) struct Meta {
    pub kind: LayoutKind,
    pub codec: VPageCodec,
    /// The sparse-capable V-page encoding (metadata byte 3: 0 none, else its index bytes).
    pub sparse: Option<SparseCodec>,
    pub cell_count: u32,
    pub node_count: u32,
    /// First page after the metadata.
    pub data_start: u64,
    /// Pages of the file holding the V-pages (to catch files of different builds mixed).
    pub vpages_pages: u64,
    pub visible_total: u64,
    pub flip_pages_total: u64,
    pub visible_max: u32,
    pub flip_pages_max: u32,
    pub fanout: Vec<u16>,
    /// Indexed-vertical only: per cell, its segment's address and visible-node count.
    pub directory: Vec<(Addr, u32)>,
}

impl Meta {
    pub fn encoded_len(kind: LayoutKind, cells: u64, nodes: u64) -> u64 {
        let dir = if kind == LayoutKind::IndexedVertical { cells * DIR_ENTRY_BYTES as u64 } else { 0 };
        META_FIXED as u64 + 2 * nodes + dir
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut b =
            Vec::with_capacity(
                Meta::encoded_len(self.kind, u64::from(self.cell_count), u64::from(self.node_count)) as usize
            );
        let sparse = self.sparse.map_or(0, |s| s.index_bytes);
        b.extend_from_slice(&[self.kind.code(), self.codec.dov.code(), self.codec.nvo_bytes, sparse]);
        b.extend_from_slice(&self.cell_count.to_le_bytes());
        b.extend_from_slice(&self.node_count.to_le_bytes());
        b.extend_from_slice(&(self.data_start as u32).to_le_bytes());
        b.extend_from_slice(&self.vpages_pages.to_le_bytes());
        b.extend_from_slice(&self.visible_total.to_le_bytes());
        b.extend_from_slice(&self.flip_pages_total.to_le_bytes());
        b.extend_from_slice(&self.visible_max.to_le_bytes());
        b.extend_from_slice(&self.flip_pages_max.to_le_bytes());
        for f in &self.fanout {
            b.extend_from_slice(&f.to_le_bytes());
        }
        for (addr, count) in &self.directory {
            addr.encode(&mut b);
            b.extend_from_slice(&count.to_le_bytes());
        }
        b
    }

    /// Reads and checks the metadata record at the start of `file`.
    pub fn read(file: &mut PagedFile, kind: LayoutKind) -> Result<Meta> {
        let cap = file.file.capacity() as u64;
        let mut fixed = Vec::new();
        if file.file.page_count() == 0 {
            return Err(Error::truncated(file.path(), "no metadata page"));
        }
        file.read_record(Addr { page: 0, offset: 0 }, META_FIXED, &mut fixed)?;
        let bad = |r: String| Error::corrupt(file.path(), format!("layout metadata: {r}"));
        if fixed[0] != kind.code() {
            return Err(bad(format!("layout code {}, expected {} ({kind})", fixed[0], kind.code())));
        }
        let dov = DovCodec::from_code(fixed[1]).ok_or_else(|| bad(format!("unknown DoV codec {}", fixed[1])))?;
        let nvo_bytes = fixed[2];
        if nvo_bytes != 2 && nvo_bytes != 4 {
            return Err(bad(format!("NVO width {nvo_bytes}, expected 2 or 4")));
        }
        let sparse = match fixed[3] {
            0 => None,
            1 | 2 if kind != LayoutKind::Horizontal => Some(SparseCodec { index_bytes: fixed[3] }),
            v => {
                return Err(bad(format!(
                    "V-page encoding {v}, expected 0{}",
                    if kind == LayoutKind::Horizontal { "" } else { ", 1 or 2" }
                )));
            }
        };
        let field32 = |at| u32_at(&fixed, at).unwrap_or(0);
        let field64 = |at| u64_at(&fixed, at).unwrap_or(0);
        let cell_count = field32(4);
        let node_count = field32(8);
        let data_start = u64::from(field32(12));
        let len = Meta::encoded_len(kind, u64::from(cell_count), u64::from(node_count));
        // Check the claimed sizes against the file before allocating anything for them.
        if record_pages(len, cap) != data_start || data_start > file.file.page_count() {
            return Err(bad(format!(
                "{cell_count} cells and {node_count} nodes need {} metadata pages; header says \
                 {data_start} of {} pages",
                record_pages(len, cap),
                file.file.page_count()
            )));
        }
        let mut b = Vec::new();
        file.read_record(Addr { page: 0, offset: 0 }, len as usize, &mut b)?;
        let fanout: Vec<u16> = b[META_FIXED..META_FIXED + 2 * node_count as usize]
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        if let Some(sp) = sparse {
            let want = SparseCodec::for_max_fanout(fanout.iter().copied().max().unwrap_or(0));
            if sp != want {
                return Err(Error::corrupt(
                    file.path(),
                    format!(
                        "layout metadata: sparse V-pages with {}-byte indices, the fan-outs need {}",
                        sp.index_bytes, want.index_bytes
                    ),
                ));
            }
        }
        let mut directory = Vec::new();
        if kind == LayoutKind::IndexedVertical {
            let start = META_FIXED + 2 * node_count as usize;
            directory = b[start..]
                .chunks_exact(DIR_ENTRY_BYTES)
                .map(|c| {
                    let addr = Addr::decode(c, 0).unwrap_or(Addr::NIL);
                    (addr, u32_at(c, packing::ADDR_BYTES).unwrap_or(0))
                })
                .collect();
        }
        Ok(Meta {
            kind,
            codec: VPageCodec { dov, nvo_bytes },
            sparse,
            cell_count,
            node_count,
            data_start,
            vpages_pages: field64(16),
            visible_total: field64(24),
            flip_pages_total: field64(32),
            visible_max: field32(40),
            flip_pages_max: field32(44),
            fanout,
            directory,
        })
    }
}

/// Kind-specific reader state.
enum State {
    Horizontal(horizontal::Reader),
    Vertical(vertical::Reader),
    Indexed(indexed::Reader),
}

/// Reads one layout: select a cell with [`flip_to_cell`](Self::flip_to_cell), then fetch
/// V-pages by node dfs number. Counts pages read per file.
pub struct LayoutReader {
    meta: Meta,
    /// The index file (vertical, indexed-vertical); `None` for horizontal.
    index: Option<PagedFile>,
    vpages: PagedFile,
    state: State,
    cell: Option<u32>,
    bytes: Vec<u8>,
}

impl fmt::Debug for LayoutReader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LayoutReader")
            .field("kind", &self.meta.kind)
            .field("cells", &self.meta.cell_count)
            .field("nodes", &self.meta.node_count)
            .field("cell", &self.cell)
            .finish()
    }
}

fn open_paged(dir: &Path, name: &str, tag: [u8; 4], mode: ReadMode) -> Result<PagedFile> {
    Ok(PagedFile::new(PageFile::open(&dir.join(name), tag, mode)?, name))
}

impl LayoutReader {
    /// Opens the `kind` layout in `dir` and reads its metadata. Page counts start at zero
    /// after open: the metadata read is not counted.
    pub fn open(dir: &Path, kind: LayoutKind, mode: ReadMode) -> Result<Self> {
        let (meta, index, vpages, state) = match kind {
            LayoutKind::Horizontal => {
                let mut vp = open_paged(dir, horizontal::VPAGES_FILE, horizontal::TAG, mode)?;
                let meta = Meta::read(&mut vp, kind)?;
                let st = horizontal::Reader::new(&meta, &vp)?;
                (meta, None, vp, State::Horizontal(st))
            }
            LayoutKind::Vertical => {
                let mut ix = open_paged(dir, vertical::INDEX_FILE, vertical::INDEX_TAG, mode)?;
                let vp = open_paged(dir, vertical::VPAGES_FILE, vertical::VPAGES_TAG, mode)?;
                let meta = Meta::read(&mut ix, kind)?;
                let st = vertical::Reader::new(&meta, &ix)?;
                (meta, Some(ix), vp, State::Vertical(st))
            }
            LayoutKind::IndexedVertical => {
                let mut ix = open_paged(dir, indexed::INDEX_FILE, indexed::INDEX_TAG, mode)?;
                let vp = open_paged(dir, indexed::VPAGES_FILE, indexed::VPAGES_TAG, mode)?;
                let meta = Meta::read(&mut ix, kind)?;
                let st = indexed::Reader::new(&meta, &ix)?;
                (meta, Some(ix), vp, State::Indexed(st))
            }
        };
        if vpages.file.page_count() != meta.vpages_pages {
            return Err(vpages.corrupt(format!(
                "{} pages, the layout's metadata says {}: files of different builds?",
                vpages.file.page_count(),
                meta.vpages_pages
            )));
        }
        let mut r = Self { meta, index, vpages, state, cell: None, bytes: Vec::new() };
        r.reset_io();
        Ok(r)
    }

    pub fn kind(&self) -> LayoutKind {
        self.meta.kind
    }
    pub fn cell_count(&self) -> u32 {
        self.meta.cell_count
    }
    pub fn node_count(&self) -> u32 {
        self.meta.node_count
    }
    /// Entries of node `node` (its V-page's length).
    pub fn node_fanout(&self, node: u32) -> Option<u16> {
        self.meta.fanout.get(node as usize).copied()
    }
    pub fn codec(&self) -> VPageCodec {
        self.meta.codec
    }
    /// The selected cell, if any.
    pub fn cell(&self) -> Option<u32> {
        self.cell
    }

    /// Counts from the metadata; no I/O.
    pub fn summary(&self) -> LayoutSummary {
        let m = &self.meta;
        let cells = f64::from(m.cell_count.max(1));
        let page_size = self.vpages.file.page_size();
        let bytes = self.vpages.file.file_len() + self.index.as_ref().map_or(0, |i| i.file.file_len());
        LayoutSummary {
            kind: m.kind,
            dov: m.codec.dov,
            page_size,
            cell_count: m.cell_count,
            node_count: m.node_count,
            visible_nodes_mean: m.visible_total as f64 / cells,
            visible_nodes_max: m.visible_max,
            flip_pages_mean: m.flip_pages_total as f64 / cells,
            flip_pages_max: m.flip_pages_max,
            bytes,
        }
    }

    /// Selects `cell`: reads its index segment (vertical: N_node pointers; indexed-vertical:
    /// its visible nodes' pairs; horizontal: nothing). Selecting the current cell again is free.
    pub fn flip_to_cell(&mut self, cell: u32) -> Result<FlipCost> {
        if cell >= self.meta.cell_count {
            return Err(Error::invalid(
                self.vpages.path(),
                format!("cell {cell} out of range ({} cells)", self.meta.cell_count),
            ));
        }
        if self.cell == Some(cell) {
            return Ok(FlipCost::default());
        }
        self.cell = None;
        let before = self.pages_read();
        match &mut self.state {
            State::Horizontal(_) => {}
            State::Vertical(st) => {
                let ix = self.index.as_mut().expect("vertical has an index file");
                st.flip(&self.meta, ix, cell, &mut self.bytes)?;
            }
            State::Indexed(st) => {
                let ix = self.index.as_mut().expect("indexed-vertical has an index file");
                st.flip(&self.meta, ix, cell, &mut self.bytes)?;
            }
        }
        self.cell = Some(cell);
        Ok(FlipCost { pages_read: self.pages_read() - before })
    }

    /// The V-page of `node` in the selected cell; `None` if the node is invisible there.
    pub fn vpage(&mut self, node: u32) -> Result<Option<Vec<VEntry>>> {
        let mut out = Vec::new();
        Ok(self.vpage_into(node, &mut out)?.then_some(out))
    }

    /// Like [`vpage`](Self::vpage) into a reused buffer; returns whether the node is visible
    /// (when not, `out` is left empty).
    pub fn vpage_into(&mut self, node: u32, out: &mut Vec<VEntry>) -> Result<bool> {
        out.clear();
        let Some(cell) = self.cell else {
            return Err(Error::invalid(self.vpages.path(), "no cell selected: call flip_to_cell first"));
        };
        let Some(&fanout) = self.meta.fanout.get(node as usize) else {
            return Err(Error::invalid(
                self.vpages.path(),
                format!("node {node} out of range ({} nodes)", self.meta.node_count),
            ));
        };
        let len = self.meta.codec.vpage_bytes(fanout);
        let addr = match &self.state {
            State::Horizontal(st) => st.locate(node, cell, len, &self.vpages)?,
            State::Vertical(st) => st.locate(node),
            State::Indexed(st) => st.locate(node),
        };
        let Some(addr) = addr else {
            return Ok(false);
        };
        if let Some(sp) = self.meta.sparse {
            // Header first (its page is then held, so the record read costs no more pages).
            let codec = self.meta.codec;
            let bad = |f: &PagedFile, r: String| f.corrupt(format!("cell {cell}, node {node}: {r}"));
            self.vpages.read_record(addr, sp.header_len(), &mut self.bytes)?;
            let len = sp.record_len(&codec, fanout, &self.bytes).map_err(|r| bad(&self.vpages, r))?;
            self.vpages.read_record(addr, len, &mut self.bytes)?;
            sp.decode(&codec, fanout, &self.bytes, out).map_err(|r| bad(&self.vpages, r))?;
            return Ok(true);
        }
        self.vpages.read_record(addr, len, &mut self.bytes)?;
        if matches!(self.state, State::Horizontal(_)) && self.bytes.iter().all(|&b| b == 0) {
            // Horizontal stores hidden nodes as zero V-pages.
            return Ok(false);
        }
        self.meta.codec.decode(&self.bytes, out);
        Ok(true)
    }

    /// Reads every cell's index and every visible V-page, checking all checksums and
    /// pointers (an fsck). Returns the number of visible V-pages. Leaves no cell selected and
    /// the page counts at zero. Its work is bounded by the files' size.
    pub fn verify(&mut self) -> Result<u64> {
        let nodes: Vec<u32> = (0..self.meta.node_count).filter(|&n| self.meta.fanout[n as usize] > 0).collect();
        // Without nodes a vertical segment is empty, and a horizontal flip reads nothing: the
        // cell count is then unbounded by the file and there is nothing to read.
        let cells_matter = match self.meta.kind {
            LayoutKind::Horizontal => !nodes.is_empty(),
            LayoutKind::Vertical => self.meta.node_count > 0,
            LayoutKind::IndexedVertical => true,
        };
        let mut visible = 0u64;
        let mut buf = Vec::new();
        let result = (|| {
            if !cells_matter {
                return Ok(());
            }
            let mut candidates = Vec::new();
            for cell in 0..self.meta.cell_count {
                self.flip_to_cell(cell)?;
                // Vertical layouts: only the nodes the segment points at (O(N_vnode) per cell).
                candidates.clear();
                match &self.state {
                    State::Horizontal(_) => candidates.extend_from_slice(&nodes),
                    State::Vertical(st) => candidates.extend(st.pointed_nodes()),
                    State::Indexed(st) => candidates.extend(st.pointed_nodes()),
                }
                for &n in &candidates {
                    visible += u64::from(self.vpage_into(n, &mut buf)?);
                }
            }
            Ok(())
        })();
        self.cell = None;
        self.reset_io();
        result.map(|()| visible)
    }

    fn pages_read(&self) -> u64 {
        self.vpages.reads() + self.index.as_ref().map_or(0, PagedFile::reads)
    }

    /// Pages read per file since open or the last [`reset_io`](Self::reset_io). A record read
    /// that lands on the page read just before from the same file costs nothing (the reader
    /// holds that page).
    pub fn io(&self) -> IoStats {
        let mut files = Vec::new();
        if let Some(ix) = &self.index {
            files.push(FileIo { file: ix.name().to_string(), pages_read: ix.reads() });
        }
        files.push(FileIo { file: self.vpages.name().to_string(), pages_read: self.vpages.reads() });
        IoStats { files }
    }

    /// Zeroes the page counts and drops the held pages (the next read starts cold).
    pub fn reset_io(&mut self) {
        self.vpages.reset_reads();
        if let Some(ix) = &mut self.index {
            ix.reset_reads();
        }
    }
}

/// Total length of the files named in `files` and the `LayoutSize` split.
pub(crate) fn layout_size(files: Vec<(String, u64)>, vpage_bytes: u64) -> LayoutSize {
    let total: u64 = files.iter().map(|(_, b)| b).sum();
    LayoutSize { vpage_bytes, index_bytes: total - vpage_bytes, files }
}
