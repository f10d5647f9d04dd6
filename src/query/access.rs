//! The query side's one way to pages: tree pages and V-pages of one layout, read for one
//! query or session, and counted per file.

use crate::db::Database;
use crate::db::tree_page::NodePage;
use crate::error::{Error, Result};
use hdov_storage::{LayoutKind, LayoutReader, ReadMode, VEntry};

/// Pages read per file since the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct PageIo {
    pub tree: u64,
    pub vindex: u64,
    pub vpages: u64,
}

/// A reader of one database through one layout.
pub(crate) struct Access<'db> {
    db: &'db Database,
    layout: LayoutReader,
    tree_reads: u64,
}

impl<'db> Access<'db> {
    /// Opens `kind` (default: indexed-vertical if present, else the first layout written).
    pub fn open(db: &'db Database, kind: Option<LayoutKind>) -> Result<Access<'db>> {
        let layouts = db.layouts();
        let kind = match kind {
            Some(k) => k,
            None if layouts.contains(&LayoutKind::IndexedVertical) => LayoutKind::IndexedVertical,
            None => *layouts.first().ok_or_else(|| {
                Error::bad_param("layout", format!("{} holds no visibility to query", db.dir().display()))
            })?,
        };
        Ok(Access { db, layout: db.layout(kind, ReadMode::Mmap)?, tree_reads: 0 })
    }

    pub fn layout_kind(&self) -> LayoutKind {
        self.layout.kind()
    }

    /// Selects the cell whose V-pages the next reads return (free if it is selected already).
    pub fn flip(&mut self, cell: u32) -> Result<()> {
        self.layout.flip_to_cell(cell)?;
        Ok(())
    }

    /// The page of node `id`; `priority` is its DoV (for the cache's policy).
    pub fn node(&mut self, id: u32, _priority: f64) -> Result<NodePage> {
        self.tree_reads += 1;
        self.db.node(id)
    }

    /// The V-page of `node` in the selected cell into `out`; false if the node is hidden there.
    pub fn vpage(&mut self, node: u32, _priority: f64, out: &mut Vec<VEntry>) -> Result<bool> {
        Ok(self.layout.vpage_into(node, out)?)
    }

    pub fn io(&self) -> PageIo {
        let io = self.layout.io();
        let files = &io.files;
        let (vindex, vpages) = match files.len() {
            2 => (files[0].pages_read, files[1].pages_read),
            _ => (0, files.first().map_or(0, |f| f.pages_read)),
        };
        PageIo { tree: self.tree_reads, vindex, vpages }
    }

    pub fn reset_io(&mut self) {
        self.tree_reads = 0;
        self.layout.reset_io();
    }
}
