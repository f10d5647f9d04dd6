//! The page-access seam: every page of every [`PageFile`], tree pages and V-pages alike, is
//! read through a [`PageReader`], and nowhere else.
//!
//! A reader belongs to one query or one walkthrough session (it is `Send`, not shared). A
//! request for page `n` of a file is answered, in order, by
//!
//! 1. the file's **read buffer**: one frame per file holding the page last read from it (a
//!    disk read fills a buffer, so this is the smallest cache any reader has; it is what lets
//!    a record read that lands on the page just read from the same file cost nothing —
//!    decision 7 of `docs/decisions.md`);
//! 2. the **page cache** ([`PageCache`], keyed by `PageKey { file: file.id(), page: n }`),
//!    bounded in pages and bytes, evicting by a pluggable [`PolicyKind`];
//! 3. a **read** from the file, whose page then fills the buffer and is offered to the cache.
//!
//! One counter per file tells them apart ([`IoStats`]): `requested = hits + pages_read`, where
//! hits are answered by 1 or 2 and `pages_read` are reads (3). The cache's own
//! [`CacheStats`](crate::CacheStats) count only the requests the buffer did not answer.
//!
//! ```
//! use hdov_storage::{CacheLimits, PageFile, PageFileWriter, PageReader, PolicyKind, ReadMode};
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("tree.pages");
//! let mut w = PageFileWriter::create(&path, *b"TREE", 64)?;
//! for text in [&b"root"[..], b"leaf a", b"leaf b"] {
//!     w.push(text)?;
//! }
//! w.finish()?;
//! let file = PageFile::open(&path, *b"TREE", ReadMode::Mmap)?;
//!
//! let mut pages = PageReader::new(CacheLimits::max_pages(8), PolicyKind::Dov);
//! assert_eq!(&pages.page(&file, 0, 1.0)?[..4], b"root"); // read from the file
//! pages.page(&file, 1, 0.3)?; // read
//! pages.page(&file, 1, 0.3)?; // the read buffer: a hit
//! pages.page(&file, 0, 1.0)?; // the cache: a hit
//! let io = pages.io();
//! let tree = io.get("tree.pages").unwrap();
//! assert_eq!((tree.requested, tree.hits, tree.pages_read), (4, 2, 2));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;
use std::sync::Arc;

use crate::cache::{CacheLimits, PageCache, PageKey, PolicyKind};
use crate::error::Result;
use crate::io_stats::{FileIo, IoStats};
use crate::pagefile::PageFile;

/// The read buffer of one file: the page last read from it.
struct Frame {
    file: u32,
    page: u64,
    data: Arc<[u8]>,
}

/// The counts of one file (by id; reported by name).
struct Count {
    file: u32,
    io: FileIo,
}

/// Reads pages through a read buffer per file and a [`PageCache`], counting per file what was
/// requested, what was answered without a read and what was read (module docs).
///
/// The read buffers hold one page per file beyond the cache's limits (the same bytes when the
/// page is also cached). Priorities are the policy's numbers: the engine passes the DoV of the
/// page's node in the current cell, 0 when it has none.
pub struct PageReader {
    cache: PageCache,
    buffers: Vec<Frame>,
    counts: Vec<Count>,
}

impl fmt::Debug for PageReader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PageReader")
            .field("cache", &self.cache)
            .field("buffers", &self.buffers.iter().map(|b| (b.file, b.page)).collect::<Vec<_>>())
            .field("io", &self.io())
            .finish()
    }
}

impl PageReader {
    /// A reader with a page cache of `limits` evicting by `policy`.
    pub fn new(limits: CacheLimits, policy: PolicyKind) -> PageReader {
        PageReader { cache: PageCache::with_kind(limits, policy), buffers: Vec::new(), counts: Vec::new() }
    }

    /// A reader with no cache beyond the read buffers: what a one-off point query uses.
    pub fn uncached() -> PageReader {
        PageReader::new(CacheLimits::max_pages(0), PolicyKind::None)
    }

    /// Page `n` of `file` (its payload, checksum verified): from the file's read buffer, else
    /// from the cache, else read from the file. `priority` is the policy's number for the page
    /// (a node's DoV; 0 when unknown). A failed read is counted as a read and empties the
    /// file's read buffer.
    pub fn page(&mut self, file: &PageFile, n: u64, priority: f64) -> Result<Arc<[u8]>> {
        let id = file.id();
        let slot = self.count_slot(file);
        self.counts[slot].io.requested += 1;
        let frame = self.buffers.iter().position(|b| b.file == id);
        if let Some(b) = frame.map(|i| &self.buffers[i])
            && b.page == n
        {
            self.counts[slot].io.hits += 1;
            return Ok(Arc::clone(&b.data));
        }
        let mut read = false;
        let got = self.cache.get_or_load(PageKey { file: id, page: n }, priority, || {
            read = true;
            file.read_page(n).map(|p| Arc::<[u8]>::from(&*p))
        });
        let io = &mut self.counts[slot].io;
        if read {
            io.pages_read += 1;
        } else {
            io.hits += 1;
        }
        match (got, frame) {
            (Ok(data), Some(i)) => {
                self.buffers[i].page = n;
                self.buffers[i].data = Arc::clone(&data);
                Ok(data)
            }
            (Ok(data), None) => {
                self.buffers.push(Frame { file: id, page: n, data: Arc::clone(&data) });
                Ok(data)
            }
            (Err(e), frame) => {
                if let Some(i) = frame {
                    self.buffers.swap_remove(i);
                }
                Err(e)
            }
        }
    }

    fn count_slot(&mut self, file: &PageFile) -> usize {
        let id = file.id();
        match self.counts.iter().position(|c| c.file == id) {
            Some(i) => i,
            None => {
                let io = FileIo { file: file.name().to_string(), ..FileIo::default() };
                self.counts.push(Count { file: id, io });
                self.counts.len() - 1
            }
        }
    }

    /// Updates the priority of page `n` of `file` if it is in the cache (a node's DoV changes
    /// when the viewer changes cell); not a request. Returns whether it was resident.
    pub fn set_priority(&mut self, file: &PageFile, n: u64, priority: f64) -> bool {
        self.cache.set_priority(PageKey { file: file.id(), page: n }, priority)
    }

    /// Counts per file name since creation or [`reset_io`](Self::reset_io), in the order the
    /// files were first requested (files of equal name, e.g. of two databases, are summed).
    pub fn io(&self) -> IoStats {
        let mut files: Vec<FileIo> = Vec::with_capacity(self.counts.len());
        for c in &self.counts {
            match files.iter_mut().find(|f| f.file == c.io.file) {
                Some(f) => {
                    f.requested += c.io.requested;
                    f.hits += c.io.hits;
                    f.pages_read += c.io.pages_read;
                }
                None => files.push(c.io.clone()),
            }
        }
        IoStats { files }
    }

    /// The counts of `file` alone (zero if never requested).
    pub fn file_io(&self, file: &PageFile) -> FileIo {
        let id = file.id();
        self.counts
            .iter()
            .find(|c| c.file == id)
            .map_or_else(|| FileIo { file: file.name().to_string(), ..FileIo::default() }, |c| c.io.clone())
    }

    /// A cold start: zeroes the counts (the cache's statistics too) and forgets the read
    /// buffers. The cache keeps its pages (to measure a warm cache, clear nothing else).
    pub fn reset_io(&mut self) {
        for c in &mut self.counts {
            c.io = FileIo { file: std::mem::take(&mut c.io.file), ..FileIo::default() };
        }
        self.buffers.clear();
        self.cache.reset_stats();
    }

    /// The page cache (its statistics, resident pages and bytes, limits).
    pub fn cache(&self) -> &PageCache {
        &self.cache
    }

    /// Drops the cache's pages and the read buffers; the counts are kept.
    pub fn clear(&mut self) {
        self.cache.clear();
        self.buffers.clear();
    }
}
