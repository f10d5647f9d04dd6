//! The reader's one way to pages: tree pages and V-pages of one layout, read for one
//! query or session through one [`PageReader`] (its read buffers and, for a session, its page
//! cache), and counted per file.

use super::Database;
use crate::error::{Error, Param, Result};
use crate::format::tree_page::NodePage;
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
    /// `None` for a spatial reader (REVIEW), which reads tree pages only.
    cursor: Option<LayoutCursor<'db>>,
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
                Error::bad_param(Param::Layout, format!("{} holds no visibility to query", db.dir().display()))
            })?,
        };
        Ok(Access { db, cursor: Some(db.layout(kind)?.cursor()), pages })
    }

    /// A reader of tree pages alone (no layout, so no visibility needed), through a cache of
    /// `limits` under `policy`: what REVIEW's searches read through.
    pub fn spatial(db: &'db Database, limits: CacheLimits, policy: PolicyKind) -> Access<'db> {
        Access { db, cursor: None, pages: PageReader::new(limits, policy) }
    }

    /// The database read.
    pub fn db(&self) -> &'db Database {
        self.db
    }

    /// The layout read (`None` for a spatial reader).
    pub fn layout_kind(&self) -> Option<LayoutKind> {
        self.cursor.as_ref().map(|c| c.layout().kind())
    }

    /// Selects the cell whose V-pages the next reads return (free if it is selected already).
    pub fn flip(&mut self, cell: u32) -> Result<()> {
        let pages = &mut self.pages;
        self.cursor
            .as_mut()
            .ok_or_else(|| Error::bad_param(Param::Layout, "a spatial reader reads no V-pages"))?
            .flip_to_cell(cell, pages)?;
        Ok(())
    }

    /// Updates the cache's priority of node `id`'s page if it is resident (REVIEW's DPLRU
    /// priorities follow the query cell); returns whether it was.
    pub fn set_node_priority(&mut self, id: u32, priority: f64) -> bool {
        self.pages.set_priority(self.db.tree_file(), u64::from(id), priority)
    }

    /// The page of node `id`; `priority` is its DoV (for the cache's policy).
    pub fn node(&mut self, id: u32, priority: f64) -> Result<NodePage> {
        self.db.read_node(id, priority, &mut self.pages)
    }

    /// Enters node `id` in the selected cell: its page, with its V-page read into `v` (one
    /// entry per entry of the node, checked); `None` when the node is hidden there. `priority`
    /// is its DoV (for the cache's policy).
    pub fn enter(&mut self, id: u32, priority: f64, v: &mut Vec<VEntry>) -> Result<Option<NodePage>> {
        let pages = &mut self.pages;
        let cursor =
            self.cursor.as_mut().ok_or_else(|| Error::bad_param(Param::Layout, "a spatial reader reads no V-pages"))?;
        if !cursor.vpage_into(id, priority, pages, v)? {
            return Ok(None);
        }
        let page = self.node(id, priority)?;
        if page.node.entries.len() != v.len() {
            return Err(Error::bad_file(
                self.db.dir(),
                format!("node {id} has {} entries, its V-page {}", page.node.entries.len(), v.len()),
            ));
        }
        Ok(Some(page))
    }

    pub fn io(&self) -> PageIo {
        let layout = self.cursor.as_ref().map(|c| c.layout());
        let of = |f: Option<&hdov_storage::PageFile>| f.map(|f| self.pages.file_io(f));
        let read = |io: &Option<FileIo>| io.as_ref().map_or(0, |i| i.pages_read);
        let files = [
            of(Some(self.db.tree_file())),
            of(layout.and_then(|l| l.index_file())),
            of(layout.map(|l| l.vpage_file())),
        ];
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
