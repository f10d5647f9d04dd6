//! Page accounting: every page a reader asks for is counted, so experiments report I/O in pages
//! as the thesis does, whether or not the OS cache served the access. The counts are kept by a
//! [`PageReader`](crate::PageReader), the one place pages are read; these are its reports.

/// What one reader asked of one file, and how it was answered.
///
/// `requested = hits + pages_read`: a request is answered by the reader's read buffer or its
/// page cache (a hit), or by a read from the file (a failed read included).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FileIo {
    /// The file's name inside its directory (e.g. `vpages.vertical`).
    pub file: String,
    /// Pages requested.
    pub requested: u64,
    /// Requests answered from the read buffer or the page cache, without reading the file.
    pub hits: u64,
    /// Pages read from the file.
    pub pages_read: u64,
}

/// Pages requested and read per file since the reader's last reset.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct IoStats {
    /// One entry per file name, in the order the files were first requested.
    pub files: Vec<FileIo>,
}

impl IoStats {
    /// Pages read over all files.
    pub fn pages_read(&self) -> u64 {
        self.files.iter().map(|f| f.pages_read).sum()
    }
    /// Pages requested over all files.
    pub fn requested(&self) -> u64 {
        self.files.iter().map(|f| f.requested).sum()
    }
    /// Requests answered without a read, over all files.
    pub fn hits(&self) -> u64 {
        self.files.iter().map(|f| f.hits).sum()
    }
    /// Pages read from the named file (0 if the reader never asked it for a page).
    pub fn file(&self, name: &str) -> u64 {
        self.get(name).map_or(0, |f| f.pages_read)
    }
    /// All counts of the named file, if the reader asked it for a page.
    pub fn get(&self, name: &str) -> Option<&FileIo> {
        self.files.iter().find(|f| f.file == name)
    }
}
