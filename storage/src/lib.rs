//! hdov-storage: bytes on disk for the hdov visibility database. It knows pages, checksums,
//! records and V-page layouts, not geometry.
//!
//! - [`pagefile`]: files of fixed-size, checksummed pages, read by mmap or pread;
//! - [`page_reader`]: the one place pages are read: a read buffer per file, then a page cache,
//!   then the file, every request counted per file ([`io_stats`]);
//! - [`blob`]: append-only files of checksummed variable-length records;
//! - [`vpage`]: V-entries and their encodings (f32 or log-scale u16 DoV);
//! - [`layout`]: the horizontal, vertical and indexed-vertical V-page layouts: a [`Layout`]
//!   shared by threads, a [`LayoutCursor`] per query;
//! - [`cache`]: the page cache behind every [`PageReader`], bounded in pages and bytes, with
//!   `none`, LRU, DoV and DoV-Time eviction (priorities as numbers);
//! - [`synthetic`]: reproducible synthetic V-data for tests, benchmarks and size tables;
//! - [`mutation`]: reproducible damage to files, for mutation tests and fuzz seeds;
//! - [`atomic`]: a database directory is written beside its target and swapped into place.
//!
//! Every decoder checks bounds and checksums: a corrupted file gives an [`Error`], never a panic.

pub mod atomic;
pub mod blob;
pub mod cache;
pub mod error;
pub mod io_stats;
pub mod layout;
mod le;
pub mod mutation;
pub mod names;
pub mod page_reader;
pub mod pagefile;
pub mod synthetic;
pub mod vpage;

pub use atomic::{DirTxn, Overwrite, copy_file_synced, write_file_synced};
pub use blob::{AppendedRecords, BlobFile, BlobRef, BlobWriter};
pub use cache::{CacheLimits, CachePolicy, CacheStats, PageCache, PageKey, PolicyKind};
pub use error::{Error, Result};
pub use io_stats::{FileIo, IoStats};
pub use layout::{
    FlipCost, Layout, LayoutCursor, LayoutKind, LayoutOptions, LayoutSize, LayoutSummary, LayoutWriter, VShape,
    write_layout,
};
pub use names::Named;
pub use page_reader::PageReader;
pub use pagefile::{FORMAT_VERSION, PageFile, PageFileWriter, ReadMode};
pub use vpage::{DovCodec, VData, VDataStats, VEntry, VPageCodec};
