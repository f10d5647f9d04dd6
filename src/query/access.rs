//! The query side's one way to pages: tree pages and V-pages of one layout, read for one
//! query or session through one [`PageReader`] (its read buffers and, for a session, its page
//! cache), and counted per file.

use crate::db::Database;
use crate::db::tree_page::NodePage;
use crate::error::{Error, Result};
use hdov_storage::{CacheLimits, FileIo, LayoutCursor, LayoutKind, PageReader, PolicyKind, VEntry};

/// Pages requested and read per file since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct PageIo {
    /// Pages read from each file (cache and read-buffer misses).
    pub tree: u64,
    pub vindex: u64,
    pub vpages: u64,
    /// Page requests over all files, and those the read buffers or the cache served.
    pub requested: u64,
    pub hits: u64,
}

/// A reader of one database through one layout.
pub(crate) struct Access<'db> {
    db: &'db Database,
    cursor: LayoutCursor<'db>,
    pages: PageReader,
}

impl<'db> Access<'db> {
    /// Opens `kind` (default: indexed-vertical if present, else the first layout written) with
    /// no cache beyond the read buffers: a one-off query.
    pub fn open(db: &'db Database, kind: Option<LayoutKind>) -> Result<Access<'db>> {
        Self::with_cache(db, kind, PageReader::uncached())
    }

    /// As [`open`](Self::open), reading through a cache of `limits` under `policy`.
    pub fn cached(
        db: &'db Database,
        kind: Option<LayoutKind>,
        limits: CacheLimits,
        policy: PolicyKind,
    ) -> Result<Self> {
        Self::with_cache(db, kind, PageReader::new(limits, policy))
    }

    fn with_cache(db: &'db Database, kind: Option<LayoutKind>, pages: PageReader) -> Result<Access<'db>> {
        let layouts = db.layouts();
        let kind = match kind {
            Some(k) => k,
            None if layouts.contains(&LayoutKind::IndexedVertical) => LayoutKind::IndexedVertical,
            None => *layouts.first().ok_or_else(|| {
                Error::bad_param("layout", format!("{} holds no visibility to query", db.dir().display()))
            })?,
        };
        Ok(Access { db, cursor: db.layout(kind)?.cursor(), pages })
    }

    pub fn layout_kind(&self) -> LayoutKind {
        self.cursor.layout().kind()
    }

    /// Selects the cell whose V-pages the next reads return (free if it is selected already).
    pub fn flip(&mut self, cell: u32) -> Result<()> {
        self.cursor.flip_to_cell(cell, &mut self.pages)?;
        Ok(())
    }

    /// The page of node `id`; `priority` is its DoV (for the cache's policy).
    pub fn node(&mut self, id: u32, priority: f64) -> Result<NodePage> {
        self.db.read_node(id, priority, &mut self.pages)
    }

    /// The V-page of `node` in the selected cell into `out`; false if the node is hidden there.
    pub fn vpage(&mut self, node: u32, priority: f64, out: &mut Vec<VEntry>) -> Result<bool> {
        Ok(self.cursor.vpage_into(node, priority, &mut self.pages, out)?)
    }

    pub fn io(&self) -> PageIo {
        let layout = self.cursor.layout();
        let of = |f: Option<&hdov_storage::PageFile>| f.map(|f| self.pages.file_io(f));
        let read = |io: &Option<FileIo>| io.as_ref().map_or(0, |i| i.pages_read);
        let files = [of(Some(self.db.tree_file())), of(layout.index_file()), of(Some(layout.vpage_file()))];
        PageIo {
            tree: read(&files[0]),
            vindex: read(&files[1]),
            vpages: read(&files[2]),
            requested: files.iter().flatten().map(|i| i.requested).sum(),
            hits: files.iter().flatten().map(|i| i.hits).sum(),
        }
    }

    /// The page cache's counts since the last reset: requests that got past the read buffers,
    /// and those the cache served.
    pub fn cache_stats(&self) -> hdov_storage::CacheStats {
        self.pages.cache().stats()
    }

    /// Zeroes the counts and forgets the read buffers (the cache keeps its pages).
    pub fn reset_io(&mut self) {
        self.pages.reset_io();
    }
}
