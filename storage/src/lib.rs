//! hdov-storage: bytes on disk for the hdov visibility database. It knows pages, checksums,
//! records and V-page layouts, not geometry.
//!
//! - [`pagefile`]: files of fixed-size, checksummed pages, read by mmap or pread, every page
//!   access counted;
//! - [`blob`]: append-only files of checksummed variable-length records;
//! - [`vpage`]: V-entries and their encodings (f32 or log-scale u16 DoV);
//! - [`layout`]: the horizontal, vertical and indexed-vertical V-page layouts and their reader;
//! - [`cache`]: the page cache that tree pages and V-pages are read through, bounded in pages
//!   and bytes, with `none`, LRU, DoV and DoV-Time eviction (priorities as numbers);
//! - [`synthetic`]: reproducible synthetic V-data for tests, benchmarks and size tables;
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
pub mod pagefile;
pub mod synthetic;
pub mod vpage;

pub use atomic::{DirTxn, Overwrite, write_file_synced};
pub use blob::{BlobFile, BlobRef, BlobWriter};
pub use cache::{CacheLimits, CachePolicy, CacheStats, PageCache, PageKey, PolicyKind};
pub use error::{Error, Result};
pub use io_stats::{FileIo, IoStats, PageCounter};
pub use layout::{FlipCost, LayoutKind, LayoutOptions, LayoutReader, LayoutSize, LayoutSummary, write_layout};
pub use pagefile::{FORMAT_VERSION, PageFile, PageFileWriter, ReadMode};
pub use vpage::{DovCodec, VData, VDataStats, VEntry, VPageCodec};
