//! Page accounting: every logical page access is counted, so experiments report I/O in pages
//! as the thesis does, whether or not the OS cache served the access.

use std::sync::atomic::{AtomicU64, Ordering};

/// A shareable counter of page reads (relaxed atomics: readers may run on several threads).
#[derive(Debug, Default)]
pub struct PageCounter(AtomicU64);

impl PageCounter {
    pub fn add(&self, pages: u64) {
        self.0.fetch_add(pages, Ordering::Relaxed);
    }
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
    pub fn reset(&self) {
        self.0.store(0, Ordering::Relaxed);
    }
}

/// Pages read from one file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileIo {
    /// The file's name inside its directory (e.g. `vpages.vertical`).
    pub file: String,
    pub pages_read: u64,
}

/// Pages read per file since the last reset.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct IoStats {
    pub files: Vec<FileIo>,
}

impl IoStats {
    /// Pages read over all files.
    pub fn pages_read(&self) -> u64 {
        self.files.iter().map(|f| f.pages_read).sum()
    }
    /// Pages read from the named file (0 if this reader has no such file).
    pub fn file(&self, name: &str) -> u64 {
        self.files.iter().find(|f| f.file == name).map_or(0, |f| f.pages_read)
    }
}
