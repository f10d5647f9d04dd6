//! A file of fixed-size pages, each ending with the crc32 of its payload.
//!
//! ```text
//! offset 0            : header page (page_size bytes)
//!   0..8   magic  b"HDOVPAGE"
//!   8..12  kind   caller's 4-byte tag (b"TREE", b"HORZ", ...)
//!   12..16 u32    format version (FORMAT_VERSION)
//!   16..20 u32    page size in bytes
//!   20..28 u64    data page count
//!   28..32 u32    crc32 of bytes 0..28
//!   32..   zero
//! offset (1+n)*page_size : data page n
//!   0..page_size-4          payload (zero-padded)
//!   page_size-4..page_size  u32 crc32 of the payload
//! ```
//! All integers are little-endian. The header is written last (by [`PageFileWriter::finish`]),
//! so a file whose writer died has a zero magic and does not open.

use std::borrow::Cow;
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use crate::error::{Error, Result, path_str};
use crate::le::{tag_str, u32_at, u64_at};

/// The page file format's magic number.
pub const PAGE_MAGIC: [u8; 8] = *b"HDOVPAGE";
/// The format version written by this build and the only one it reads.
pub const FORMAT_VERSION: u32 = 1;
/// Bytes of the header's fields (the rest of the header page is zero).
pub const HEADER_LEN: usize = 32;
/// Bytes at the end of each page holding the payload's crc32.
pub const PAGE_CRC_LEN: usize = 4;
/// The smallest page size accepted.
pub const MIN_PAGE_SIZE: u32 = 64;
/// The largest page size accepted (a sanity bound against corrupted headers).
pub const MAX_PAGE_SIZE: u32 = 1 << 24;

/// How a [`PageFile`] reads pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ReadMode {
    /// Map the file (warm: pages come from the OS cache once touched).
    #[default]
    Mmap,
    /// One `pread` per page access, into a fresh buffer (for cold-cache experiments, together
    /// with dropping the OS cache).
    Pread,
}

fn check_page_size(path: &Path, page_size: u32) -> Result<()> {
    if !(MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&page_size) {
        return Err(Error::invalid(path, format!("page size {page_size} outside {MIN_PAGE_SIZE}..={MAX_PAGE_SIZE}")));
    }
    Ok(())
}

fn encode_header(kind: [u8; 4], page_size: u32, page_count: u64) -> [u8; HEADER_LEN] {
    let mut h = [0u8; HEADER_LEN];
    h[0..8].copy_from_slice(&PAGE_MAGIC);
    h[8..12].copy_from_slice(&kind);
    h[12..16].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    h[16..20].copy_from_slice(&page_size.to_le_bytes());
    h[20..28].copy_from_slice(&page_count.to_le_bytes());
    let crc = crc32fast::hash(&h[0..28]);
    h[28..32].copy_from_slice(&crc.to_le_bytes());
    h
}

/// Writes a page file front to back.
pub struct PageFileWriter {
    path: PathBuf,
    file: std::io::BufWriter<File>,
    kind: [u8; 4],
    page_size: u32,
    page_count: u64,
    buf: Vec<u8>,
}

impl PageFileWriter {
    /// Creates (or truncates) `path`. The header is a zero page until [`finish`](Self::finish).
    pub fn create(path: &Path, kind: [u8; 4], page_size: u32) -> Result<Self> {
        check_page_size(path, page_size)?;
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut file = std::io::BufWriter::with_capacity(1 << 16, file);
        file.write_all(&vec![0u8; page_size as usize]).map_err(|e| Error::io(path, e))?;
        Ok(Self { path: path.to_path_buf(), file, kind, page_size, page_count: 0, buf: vec![0u8; page_size as usize] })
    }

    /// Bytes of payload a page holds: page size − 4.
    pub fn capacity(&self) -> usize {
        self.page_size as usize - PAGE_CRC_LEN
    }

    pub fn page_size(&self) -> u32 {
        self.page_size
    }

    /// Pages pushed so far; also the number the next pushed page will get.
    pub fn page_count(&self) -> u64 {
        self.page_count
    }

    /// Appends one page holding `payload` (zero-padded to the capacity); returns its number.
    pub fn push(&mut self, payload: &[u8]) -> Result<u32> {
        let cap = self.capacity();
        if payload.len() > cap {
            return Err(Error::invalid(
                &self.path,
                format!("payload of {} bytes exceeds page capacity {cap}", payload.len()),
            ));
        }
        let page_no = u32::try_from(self.page_count).map_err(|_| Error::invalid(&self.path, "more than 2^32 pages"))?;
        self.buf[..payload.len()].copy_from_slice(payload);
        self.buf[payload.len()..cap].fill(0);
        let crc = crc32fast::hash(&self.buf[..cap]);
        self.buf[cap..].copy_from_slice(&crc.to_le_bytes());
        self.file.write_all(&self.buf).map_err(|e| Error::io(&self.path, e))?;
        self.page_count += 1;
        Ok(page_no)
    }

    /// Replaces page `page` (< [`page_count`](Self::page_count)) with `payload`: for records
    /// whose contents are known only once the pages after them are written (a layout's
    /// metadata), and for pages filled out of order into a run made by
    /// [`extend_to`](Self::extend_to).
    pub fn rewrite(&mut self, page: u64, payload: &[u8]) -> Result<()> {
        let cap = self.capacity();
        if page >= self.page_count || payload.len() > cap {
            return Err(Error::invalid(
                &self.path,
                format!(
                    "rewrite of page {page} ({} bytes) outside the {} pages written",
                    payload.len(),
                    self.page_count
                ),
            ));
        }
        self.file.flush().map_err(|e| Error::io(&self.path, e))?;
        self.buf[..payload.len()].copy_from_slice(payload);
        self.buf[payload.len()..cap].fill(0);
        let crc = crc32fast::hash(&self.buf[..cap]);
        self.buf[cap..].copy_from_slice(&crc.to_le_bytes());
        let at = (page + 1) * u64::from(self.page_size);
        self.file.get_ref().write_all_at(&self.buf, at).map_err(|e| Error::io(&self.path, e))
    }

    /// Grows the file to `pages` data pages without writing them: each must then be written by
    /// [`rewrite`](Self::rewrite). A page left out keeps zero bytes, whose checksum fails on
    /// read, so a gap is found, never taken for data.
    pub fn extend_to(&mut self, pages: u64) -> Result<()> {
        if pages <= self.page_count {
            return Ok(());
        }
        self.file.flush().map_err(|e| Error::io(&self.path, e))?;
        let len = (pages + 1) * u64::from(self.page_size);
        let file = self.file.get_mut();
        file.set_len(len).and_then(|()| file.seek(SeekFrom::Start(len))).map_err(|e| Error::io(&self.path, e))?;
        self.page_count = pages;
        Ok(())
    }

    /// Writes the header and fsyncs the file. Returns the file's length in bytes.
    pub fn finish(self) -> Result<u64> {
        let path = self.path;
        let mut file = self.file.into_inner().map_err(|e| Error::io(&path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&path, e))?;
        // The header goes in only after the pages are durable: a torn write never opens.
        file.seek(SeekFrom::Start(0)).map_err(|e| Error::io(&path, e))?;
        file.write_all(&encode_header(self.kind, self.page_size, self.page_count)).map_err(|e| Error::io(&path, e))?;
        file.sync_all().map_err(|e| Error::io(&path, e))?;
        Ok((self.page_count + 1) * u64::from(self.page_size))
    }
}

enum Backing {
    Mmap(memmap2::Mmap),
    Pread(File),
}

/// The next [`PageFile::id`]: ids are unique within the process (they wrap only after 2^32
/// opens).
static NEXT_ID: AtomicU32 = AtomicU32::new(0);

/// A read-only page file. Its pages are read through a [`PageReader`](crate::page_reader::PageReader), which counts every
/// request and every read (the file itself counts nothing). Immutable after open, so it is
/// `Send + Sync`: any number of readers on any threads may read it at once.
pub struct PageFile {
    path: PathBuf,
    /// The file's name inside its directory, as [`IoStats`](crate::IoStats) reports it.
    name: String,
    /// Process-unique: the `file` of the [`PageKey`](crate::PageKey)s of its pages.
    id: u32,
    backing: Backing,
    page_size: u32,
    page_count: u64,
    /// One bit per page: its checksum has been checked. A mapped page of an immutable file is
    /// checked once per open (pages read with `pread` come from the disk anew, and every time).
    checked: Box<[AtomicU64]>,
}

impl std::fmt::Debug for PageFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PageFile")
            .field("path", &self.path)
            .field("id", &self.id)
            .field("page_size", &self.page_size)
            .field("page_count", &self.page_count)
            .finish()
    }
}

impl PageFile {
    /// Opens `path`, checking magic, header checksum, kind, version, page size and page count
    /// against the file's length before any page is touched.
    pub fn open(path: &Path, kind: [u8; 4], mode: ReadMode) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut header = [0u8; HEADER_LEN];
        let got = usize::try_from(len).map_or(HEADER_LEN, |l| l.min(HEADER_LEN));
        file.read_exact_at(&mut header[..got], 0).map_err(|e| Error::io(path, e))?;
        if header[..got.min(8)] != PAGE_MAGIC[..got.min(8)] {
            return Err(Error::WrongMagic { path: path_str(path), expected: "page" });
        }
        if got < HEADER_LEN {
            return Err(Error::truncated(path, format!("{len} bytes, shorter than the {HEADER_LEN}-byte header")));
        }
        let (page_size, page_count) = decode_header(path, &header, kind)?;
        let expected = page_count
            .checked_add(1)
            .and_then(|n| n.checked_mul(u64::from(page_size)))
            .ok_or_else(|| Error::corrupt(path, format!("page count {page_count} overflows")))?;
        if len < expected {
            return Err(Error::truncated(
                path,
                format!("{len} bytes, header says {page_count} pages of {page_size} bytes ({expected} bytes)"),
            ));
        }
        if len > expected {
            return Err(Error::corrupt(path, format!("{len} bytes, header says {expected}: trailing bytes")));
        }
        let backing = match mode {
            ReadMode::Mmap => {
                // SAFETY: database files are immutable once renamed into place; nothing in
                // this process writes them, and the length was checked above.
                let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
                if map.len() as u64 != expected {
                    return Err(Error::corrupt(path, "file changed while opening"));
                }
                Backing::Mmap(map)
            }
            ReadMode::Pread => Backing::Pread(file),
        };
        let name = path.file_name().map_or_else(|| path_str(path), |n| n.to_string_lossy().into_owned());
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let checked = (0..page_count.div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
        Ok(Self { path: path.to_path_buf(), name, id, backing, page_size, page_count, checked })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
    /// The file's name inside its directory (e.g. `vpages.vertical`).
    pub fn name(&self) -> &str {
        &self.name
    }
    /// A number unique to this open file within the process, assigned at open: the `file` of
    /// its pages' [`PageKey`](crate::PageKey)s in a [`PageCache`](crate::PageCache).
    pub fn id(&self) -> u32 {
        self.id
    }
    pub fn page_size(&self) -> u32 {
        self.page_size
    }
    /// Bytes of payload per page: page size − 4.
    pub fn capacity(&self) -> usize {
        self.page_size as usize - PAGE_CRC_LEN
    }
    /// Data pages (the header page not included).
    pub fn page_count(&self) -> u64 {
        self.page_count
    }
    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        (self.page_count + 1) * u64::from(self.page_size)
    }

    /// The payload of data page `n` (capacity bytes), checksum verified: one read from the
    /// file. Only [`PageReader::page`](crate::page_reader::PageReader::page) calls it, so that
    /// every read is counted in one place, and [`PageFile::verify`], whose reads count nowhere.
    pub(crate) fn read_page(&self, n: u64) -> Result<Cow<'_, [u8]>> {
        if n >= self.page_count {
            return Err(Error::invalid(
                &self.path,
                format!("page {n} out of range (file has {} pages)", self.page_count),
            ));
        }
        let ps = self.page_size as usize;
        // n < page_count and (page_count+1)*page_size fits the file (checked at open).
        let start = (n + 1) * u64::from(self.page_size);
        let page: Cow<'_, [u8]> = match &self.backing {
            Backing::Mmap(map) => {
                let start = start as usize;
                Cow::Borrowed(
                    map.get(start..start + ps)
                        .ok_or_else(|| Error::truncated(&self.path, format!("page {n} beyond the mapping")))?,
                )
            }
            Backing::Pread(file) => {
                let mut buf = vec![0u8; ps];
                file.read_exact_at(&mut buf, start).map_err(|e| Error::io(&self.path, e))?;
                Cow::Owned(buf)
            }
        };
        let cap = ps - PAGE_CRC_LEN;
        let (word, bit) = (&self.checked[(n / 64) as usize], 1u64 << (n % 64));
        let mapped = matches!(page, Cow::Borrowed(_));
        if !(mapped && word.load(Ordering::Relaxed) & bit != 0) {
            let stored = u32_at(&page, cap).unwrap_or(0);
            if crc32fast::hash(&page[..cap]) != stored {
                return Err(Error::Checksum { path: path_str(&self.path), page: n });
            }
            word.fetch_or(bit, Ordering::Relaxed);
        }
        Ok(match page {
            Cow::Borrowed(b) => Cow::Borrowed(&b[..cap]),
            Cow::Owned(mut v) => {
                v.truncate(cap);
                Cow::Owned(v)
            }
        })
    }

    /// Reads every page, checking each checksum, past any cache and uncounted.
    pub fn verify(&self) -> Result<()> {
        (0..self.page_count).try_for_each(|n| self.read_page(n).map(drop))
    }
}

/// Checks magic, header crc, kind, version and page size; returns (page size, page count).
fn decode_header(path: &Path, h: &[u8; HEADER_LEN], kind: [u8; 4]) -> Result<(u32, u64)> {
    if h[0..8] != PAGE_MAGIC {
        return Err(Error::WrongMagic { path: path_str(path), expected: "page" });
    }
    let crc = u32_at(h, 28).unwrap_or(0);
    if crc32fast::hash(&h[0..28]) != crc {
        return Err(Error::corrupt(path, "header checksum mismatch"));
    }
    if h[8..12] != kind {
        return Err(Error::WrongKind { path: path_str(path), found: tag_str(&h[8..12]), expected: tag_str(&kind) });
    }
    let version = u32_at(h, 12).unwrap_or(0);
    if version != FORMAT_VERSION {
        return Err(Error::WrongVersion { path: path_str(path), found: version, expected: FORMAT_VERSION });
    }
    let page_size = u32_at(h, 16).unwrap_or(0);
    if !(MIN_PAGE_SIZE..=MAX_PAGE_SIZE).contains(&page_size) {
        return Err(Error::corrupt(path, format!("page size {page_size} outside {MIN_PAGE_SIZE}..={MAX_PAGE_SIZE}")));
    }
    let page_count = u64_at(h, 20).unwrap_or(0);
    Ok((page_size, page_count))
}

/// Recomputes the header and page checksums of a page-file image in memory, so that a mutated
/// payload reaches the decoders behind the checksum check. For fault-injection tests and
/// fuzzing only; images with an implausible page size are left alone.
pub fn reseal_checksums(image: &mut [u8]) {
    if image.len() < HEADER_LEN {
        return;
    }
    let ps = u32::from_le_bytes(image[16..20].try_into().expect("4 bytes")) as usize;
    if !(MIN_PAGE_SIZE as usize..=65536).contains(&ps) {
        return;
    }
    let crc = crc32fast::hash(&image[0..28]);
    image[28..32].copy_from_slice(&crc.to_le_bytes());
    for page in image.chunks_mut(ps).skip(1) {
        if page.len() == ps {
            let crc = crc32fast::hash(&page[..ps - PAGE_CRC_LEN]);
            page[ps - PAGE_CRC_LEN..].copy_from_slice(&crc.to_le_bytes());
        }
    }
}
