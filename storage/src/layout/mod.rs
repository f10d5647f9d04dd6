//! The three V-page layouts of thesis §5.4: a [`Layout`] (opened once, shared by threads) and
//! its [`LayoutCursor`]s (one per query), which read pages through a [`PageReader`].
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

mod context;
mod horizontal;
mod indexed;
mod packing;
mod vertical;
mod writer;

use std::fmt;
use std::path::Path;

use crate::error::{Error, Result};
use crate::le::{u32_at, u64_at};
use crate::page_reader::PageReader;
use crate::pagefile::{PageFile, ReadMode};
use crate::vpage::{DovCodec, SparseCodec, VData, VEntry, VPageCodec};
use packing::{Addr, PagedFile, record_pages};
pub use writer::{LayoutWriter, VShape};

/// Which layout. Ordered as [`LayoutKind::ALL`] lists them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LayoutKind {
    Horizontal,
    Vertical,
    IndexedVertical,
}

crate::named!(LayoutKind, "layout");
crate::by_names!(LayoutKind);

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

/// What changing cell cost, in pages of the layout's index file as the [`PageReader`] counted
/// them (horizontal: always zero).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct FlipCost {
    /// Pages read from the file: those neither the read buffer nor the cache held.
    pub pages_read: u64,
    /// Pages of the segment requested (the thesis's flip cost, whatever answered them).
    pub requested: u64,
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

/// Writes the `kind` layout of `data` into the existing directory `dir` (through a
/// [`LayoutWriter`], cell by cell).
///
/// V-pages whose entries are all (0, 0) are treated as invisible and not stored.
pub fn write_layout(dir: &Path, kind: LayoutKind, data: &VData, opts: &LayoutOptions) -> Result<LayoutSize> {
    data.validate().map_err(|r| Error::invalid(dir, r))?;
    let mut w = LayoutWriter::create(dir, kind, &VShape::of(data), opts)?;
    for cell in &data.cells {
        w.push_cell(cell)?;
    }
    w.finish()
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
    pub fn read(file: &PagedFile, kind: LayoutKind, pages: &mut PageReader) -> Result<Meta> {
        let cap = file.file.capacity() as u64;
        let mut fixed = Vec::new();
        if file.file.page_count() == 0 {
            return Err(Error::truncated(file.path(), "no metadata page"));
        }
        file.read_record(pages, 0.0, Addr { page: 0, offset: 0 }, META_FIXED, &mut fixed)?;
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
        file.read_record(pages, 0.0, Addr { page: 0, offset: 0 }, len as usize, &mut b)?;
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

/// The priority index segments are read with: they are needed once per flip, their cell's
/// pointers then stay in the cursor, so they rank lowest in a DoV cache ("0 when unknown").
pub(crate) const SEGMENT_PRIORITY: f64 = 0.0;

/// Kind-specific layout state, immutable after open.
enum Shape {
    Horizontal(horizontal::Runs),
    Vertical(vertical::Segments),
    Indexed,
}

/// One open layout: its metadata and page files, immutable after open, so `Send + Sync` and
/// opened once per database. Reading is done by [`LayoutCursor`]s ([`cursor`](Self::cursor)),
/// one per query or session, each through the caller's [`PageReader`].
pub struct Layout {
    meta: Meta,
    /// The index file (vertical, indexed-vertical); `None` for horizontal.
    index: Option<PagedFile>,
    vpages: PagedFile,
    shape: Shape,
}

impl fmt::Debug for Layout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Layout")
            .field("kind", &self.meta.kind)
            .field("cells", &self.meta.cell_count)
            .field("nodes", &self.meta.node_count)
            .finish()
    }
}

/// A layout file, refused when its pages are larger than a layout's in-page u16 offsets reach
/// (a page file alone may declare pages up to 16 MiB).
fn open_paged(dir: &Path, name: &str, tag: [u8; 4], mode: ReadMode) -> Result<PagedFile> {
    let path = dir.join(name);
    let file = PageFile::open(&path, tag, mode)?;
    if file.page_size() > MAX_LAYOUT_PAGE_SIZE {
        let reason = format!("pages of {} bytes, more than a layout's {MAX_LAYOUT_PAGE_SIZE}", file.page_size());
        return Err(Error::corrupt(&path, reason));
    }
    Ok(PagedFile::new(file))
}

impl Layout {
    /// Opens the `kind` layout in `dir` and reads its metadata (through a reader of its own:
    /// no caller's page count includes it), checking it against the files.
    pub fn open(dir: &Path, kind: LayoutKind, mode: ReadMode) -> Result<Layout> {
        let mut pages = PageReader::uncached();
        let (meta, index, vpages, shape) = match kind {
            LayoutKind::Horizontal => {
                let vp = open_paged(dir, horizontal::VPAGES_FILE, horizontal::TAG, mode)?;
                let meta = Meta::read(&vp, kind, &mut pages)?;
                let runs = horizontal::Runs::new(&meta, &vp)?;
                (meta, None, vp, Shape::Horizontal(runs))
            }
            LayoutKind::Vertical => {
                let ix = open_paged(dir, vertical::INDEX_FILE, vertical::INDEX_TAG, mode)?;
                let vp = open_paged(dir, vertical::VPAGES_FILE, vertical::VPAGES_TAG, mode)?;
                let meta = Meta::read(&ix, kind, &mut pages)?;
                let segments = vertical::Segments::new(&meta, &ix)?;
                (meta, Some(ix), vp, Shape::Vertical(segments))
            }
            LayoutKind::IndexedVertical => {
                let ix = open_paged(dir, indexed::INDEX_FILE, indexed::INDEX_TAG, mode)?;
                let vp = open_paged(dir, indexed::VPAGES_FILE, indexed::VPAGES_TAG, mode)?;
                let meta = Meta::read(&ix, kind, &mut pages)?;
                indexed::check(&meta, &ix)?;
                (meta, Some(ix), vp, Shape::Indexed)
            }
        };
        if vpages.file.page_count() != meta.vpages_pages {
            return Err(vpages.corrupt(format!(
                "{} pages, the layout's metadata says {}: files of different builds?",
                vpages.file.page_count(),
                meta.vpages_pages
            )));
        }
        Ok(Layout { meta, index, vpages, shape })
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

    /// The file holding the V-pages.
    pub fn vpage_file(&self) -> &PageFile {
        &self.vpages.file
    }
    /// The file holding the cells' segments (vertical, indexed-vertical); `None` for
    /// horizontal.
    pub fn index_file(&self) -> Option<&PageFile> {
        self.index.as_ref().map(|i| &i.file)
    }
    /// The layout's files, index (if any) first: as [`LayoutKind::file_names`] names them.
    pub fn files(&self) -> impl Iterator<Item = &PageFile> {
        self.index_file().into_iter().chain([self.vpage_file()])
    }

    /// Counts from the metadata; no I/O.
    pub fn summary(&self) -> LayoutSummary {
        let m = &self.meta;
        let cells = f64::from(m.cell_count.max(1));
        let page_size = self.vpages.file.page_size();
        let bytes = self.files().map(PageFile::file_len).sum();
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

    /// A cursor with no cell selected. Cheap: no I/O.
    pub fn cursor(&self) -> LayoutCursor<'_> {
        let segment = match self.shape {
            Shape::Horizontal(_) => Segment::Horizontal,
            Shape::Vertical(_) => Segment::Vertical(vertical::Segment::default()),
            Shape::Indexed => Segment::Indexed(indexed::Segment::default()),
        };
        LayoutCursor { layout: self, cell: None, segment, bytes: Vec::new() }
    }

    /// Reads every cell's index and every visible V-page, checking all checksums and
    /// pointers (an fsck), through a cursor and an uncached [`PageReader`] of its own. Returns
    /// the number of visible V-pages. Its work is bounded by the files' size.
    pub fn verify(&self) -> Result<u64> {
        let nodes: Vec<u32> = (0..self.meta.node_count).filter(|&n| self.meta.fanout[n as usize] > 0).collect();
        // Without nodes a vertical segment is empty, and a horizontal flip reads nothing: the
        // cell count is then unbounded by the file and there is nothing to read.
        let cells_matter = match self.meta.kind {
            LayoutKind::Horizontal => !nodes.is_empty(),
            LayoutKind::Vertical => self.meta.node_count > 0,
            LayoutKind::IndexedVertical => true,
        };
        if !cells_matter {
            return Ok(0);
        }
        let mut pages = PageReader::uncached();
        let mut cursor = self.cursor();
        let mut visible = 0u64;
        let mut buf = Vec::new();
        for cell in 0..self.meta.cell_count {
            cursor.flip_to_cell(cell, &mut pages)?;
            // Vertical layouts: only the nodes the segment points at (O(N_vnode) per cell).
            let candidates = cursor.visible_nodes().unwrap_or_else(|| nodes.clone());
            for n in candidates {
                visible += u64::from(cursor.vpage_into(n, 0.0, &mut pages, &mut buf)?);
            }
        }
        Ok(visible)
    }
}

/// A cursor's selected segment.
enum Segment {
    Horizontal,
    Vertical(vertical::Segment),
    Indexed(indexed::Segment),
}

/// Reads one [`Layout`] for one query or session: select a cell with
/// [`flip_to_cell`](Self::flip_to_cell), then fetch V-pages by node dfs number. It holds the
/// selected cell's index segment; the pages come through the caller's [`PageReader`], which
/// counts them. Any number of cursors of one layout may run at once, on any threads.
pub struct LayoutCursor<'a> {
    layout: &'a Layout,
    cell: Option<u32>,
    segment: Segment,
    bytes: Vec<u8>,
}

impl fmt::Debug for LayoutCursor<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LayoutCursor").field("layout", self.layout).field("cell", &self.cell).finish()
    }
}

impl<'a> LayoutCursor<'a> {
    /// The layout this cursor reads.
    pub fn layout(&self) -> &'a Layout {
        self.layout
    }

    /// The selected cell, if any.
    pub fn cell(&self) -> Option<u32> {
        self.cell
    }

    /// Selects `cell`: reads its index segment through `pages` (vertical: N_node pointers;
    /// indexed-vertical: its visible nodes' pairs; horizontal: nothing). Selecting the current
    /// cell again is free. The cost counts the index file's pages as `pages` counts them:
    /// requested, and read (not answered by the read buffer or the cache).
    pub fn flip_to_cell(&mut self, cell: u32, pages: &mut PageReader) -> Result<FlipCost> {
        let l = self.layout;
        if cell >= l.meta.cell_count {
            return Err(Error::invalid(
                l.vpages.path(),
                format!("cell {cell} out of range ({} cells)", l.meta.cell_count),
            ));
        }
        if self.cell == Some(cell) {
            return Ok(FlipCost::default());
        }
        self.cell = None;
        let Some(ix) = &l.index else {
            self.cell = Some(cell);
            return Ok(FlipCost::default());
        };
        let before = pages.file_io(&ix.file);
        match (&mut self.segment, &l.shape) {
            (Segment::Vertical(seg), Shape::Vertical(segments)) => {
                seg.flip(segments, &l.meta, ix, pages, cell, &mut self.bytes)?;
            }
            (Segment::Indexed(seg), Shape::Indexed) => seg.flip(&l.meta, ix, pages, cell, &mut self.bytes)?,
            _ => unreachable!("a cursor's segment matches its layout's shape"),
        }
        self.cell = Some(cell);
        let after = pages.file_io(&ix.file);
        Ok(FlipCost { pages_read: after.pages_read - before.pages_read, requested: after.requested - before.requested })
    }

    /// The nodes the selected cell's index segment points at, ascending (vertical,
    /// indexed-vertical; no I/O): those with a stored V-page there. `None` for horizontal
    /// (which learns visibility only by reading) and when no cell is selected.
    pub fn visible_nodes(&self) -> Option<Vec<u32>> {
        self.cell?;
        match &self.segment {
            Segment::Horizontal => None,
            Segment::Vertical(seg) => Some(seg.pointed_nodes().collect()),
            Segment::Indexed(seg) => Some(seg.pointed_nodes().collect()),
        }
    }

    /// The V-page of `node` in the selected cell; `None` if the node is invisible there.
    /// `priority` is the cache policy's number for its page (the node's DoV; 0 when unknown).
    pub fn vpage(&mut self, node: u32, priority: f64, pages: &mut PageReader) -> Result<Option<Vec<VEntry>>> {
        let mut out = Vec::new();
        Ok(self.vpage_into(node, priority, pages, &mut out)?.then_some(out))
    }

    /// Like [`vpage`](Self::vpage) into a reused buffer; returns whether the node is visible
    /// (when not, `out` is left empty).
    pub fn vpage_into(
        &mut self,
        node: u32,
        priority: f64,
        pages: &mut PageReader,
        out: &mut Vec<VEntry>,
    ) -> Result<bool> {
        out.clear();
        let l = self.layout;
        let Some(cell) = self.cell else {
            return Err(Error::invalid(l.vpages.path(), "no cell selected: call flip_to_cell first"));
        };
        let Some(&fanout) = l.meta.fanout.get(node as usize) else {
            return Err(Error::invalid(
                l.vpages.path(),
                format!("node {node} out of range ({} nodes)", l.meta.node_count),
            ));
        };
        let len = l.meta.codec.vpage_bytes(fanout);
        let addr = match (&self.segment, &l.shape) {
            (Segment::Horizontal, Shape::Horizontal(runs)) => runs.locate(node, cell, len, &l.vpages)?,
            (Segment::Vertical(seg), _) => seg.locate(node),
            (Segment::Indexed(seg), _) => seg.locate(node),
            _ => unreachable!("a cursor's segment matches its layout's shape"),
        };
        let Some(addr) = addr else {
            return Ok(false);
        };
        let vp = &l.vpages;
        if let Some(sp) = l.meta.sparse {
            // Header first (its page then fills the read buffer, so the record read costs no
            // more pages).
            let codec = l.meta.codec;
            let bad = |r: String| vp.corrupt(format!("cell {cell}, node {node}: {r}"));
            vp.read_record(pages, priority, addr, sp.header_len(), &mut self.bytes)?;
            let len = sp.record_len(&codec, fanout, &self.bytes).map_err(bad)?;
            vp.read_record(pages, priority, addr, len, &mut self.bytes)?;
            sp.decode(&codec, fanout, &self.bytes, out).map_err(bad)?;
            return Ok(true);
        }
        vp.read_record(pages, priority, addr, len, &mut self.bytes)?;
        if matches!(self.segment, Segment::Horizontal) && self.bytes.iter().all(|&b| b == 0) {
            // Horizontal stores hidden nodes as zero V-pages.
            return Ok(false);
        }
        l.meta.codec.decode(&self.bytes, out);
        Ok(true)
    }
}

/// Total length of the files named in `files` and the `LayoutSize` split.
pub(crate) fn layout_size(files: Vec<(String, u64)>, vpage_bytes: u64) -> LayoutSize {
    let total: u64 = files.iter().map(|(_, b)| b).sum();
    LayoutSize { vpage_bytes, index_bytes: total - vpage_bytes, files }
}
