//! An append-only file of variable-length records (e.g. bincode-encoded meshes).
//!
//! ```text
//! 0..8    magic  b"HDOVBLOB"
//! 8..12   kind   caller's 4-byte tag
//! 12..16  u32    format version (FORMAT_VERSION)
//! 16..24  u64    data length: bytes of records after the header
//! 24..28  u32    record count
//! 28..32  u32    crc32 of bytes 0..28
//! 32..    records, back to back:
//!           u32 len, u32 crc32 of the bytes, then len bytes
//! ```
//! A [`BlobRef`] points at a record's `len` field; the record's bytes start 8 bytes later.
//! Records are not aligned (bincode needs no alignment). The header is written last.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result, path_str};
use crate::le::{tag_str, u32_at, u64_at};
use crate::pagefile::FORMAT_VERSION;

/// The blob file format's magic number.
pub const BLOB_MAGIC: [u8; 8] = *b"HDOVBLOB";
/// Bytes of the blob file header.
pub const BLOB_HEADER_LEN: usize = 32;
/// Bytes before each record's data: its length and crc32.
pub const RECORD_HEADER_LEN: usize = 8;

/// Where a record lives: `offset` of its header in the file, `len` bytes of data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BlobRef {
    pub offset: u64,
    pub len: u32,
}

/// Writes a blob file front to back.
pub struct BlobWriter {
    path: PathBuf,
    file: std::io::BufWriter<File>,
    kind: [u8; 4],
    end: u64,
    count: u32,
}

impl BlobWriter {
    /// Creates (or truncates) `path`; the header stays zero until [`finish`](Self::finish).
    pub fn create(path: &Path, kind: [u8; 4]) -> Result<Self> {
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut file = std::io::BufWriter::with_capacity(1 << 16, file);
        file.write_all(&[0u8; BLOB_HEADER_LEN]).map_err(|e| Error::io(path, e))?;
        Ok(Self { path: path.to_path_buf(), file, kind, end: BLOB_HEADER_LEN as u64, count: 0 })
    }

    /// Appends one record; returns where it is.
    pub fn append(&mut self, bytes: &[u8]) -> Result<BlobRef> {
        let len = u32::try_from(bytes.len()).map_err(|_| Error::invalid(&self.path, "record longer than 4 GiB"))?;
        let count = self.count.checked_add(1).ok_or_else(|| Error::invalid(&self.path, "more than 2^32 records"))?;
        let mut head = [0u8; RECORD_HEADER_LEN];
        head[0..4].copy_from_slice(&len.to_le_bytes());
        head[4..8].copy_from_slice(&crc32fast::hash(bytes).to_le_bytes());
        self.file.write_all(&head).and_then(|()| self.file.write_all(bytes)).map_err(|e| Error::io(&self.path, e))?;
        let r = BlobRef { offset: self.end, len };
        self.end += (RECORD_HEADER_LEN + bytes.len()) as u64;
        self.count = count;
        Ok(r)
    }

    /// A reader of the records appended so far (the buffer is flushed; later appends are not
    /// its to read): so that a writer can stream records out and read some of them back while
    /// it goes on, holding none of them in memory.
    pub fn reader(&mut self) -> Result<AppendedRecords> {
        self.file.flush().map_err(|e| Error::io(&self.path, e))?;
        let file = File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
        Ok(AppendedRecords { path: self.path.clone(), file, end: self.end })
    }

    /// Writes the header and fsyncs. Returns the file's length in bytes.
    pub fn finish(self) -> Result<u64> {
        let path = self.path;
        let mut file = self.file.into_inner().map_err(|e| Error::io(&path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&path, e))?;
        let mut h = [0u8; BLOB_HEADER_LEN];
        h[0..8].copy_from_slice(&BLOB_MAGIC);
        h[8..12].copy_from_slice(&self.kind);
        h[12..16].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
        h[16..24].copy_from_slice(&(self.end - BLOB_HEADER_LEN as u64).to_le_bytes());
        h[24..28].copy_from_slice(&self.count.to_le_bytes());
        let crc = crc32fast::hash(&h[0..28]);
        h[28..32].copy_from_slice(&crc.to_le_bytes());
        file.seek(SeekFrom::Start(0))
            .and_then(|_| file.write_all(&h))
            .and_then(|()| file.sync_all())
            .map_err(|e| Error::io(&path, e))?;
        Ok(self.end)
    }
}

/// Records a [`BlobWriter`] has appended, read back by reference ([`BlobWriter::reader`]);
/// shareable between threads (positioned reads).
pub struct AppendedRecords {
    path: PathBuf,
    file: File,
    end: u64,
}

impl AppendedRecords {
    /// The bytes of the record at `r`, with bounds, length and crc32 checked.
    pub fn read(&self, r: BlobRef) -> Result<Vec<u8>> {
        let bad = |reason: String| Error::corrupt(&self.path, reason);
        let data_end = r.offset.checked_add(RECORD_HEADER_LEN as u64 + u64::from(r.len));
        if r.offset < BLOB_HEADER_LEN as u64 || data_end.is_none_or(|e| e > self.end) {
            return Err(bad(format!("record at byte {} lies outside the {} bytes written", r.offset, self.end)));
        }
        let mut head = [0u8; RECORD_HEADER_LEN];
        self.file.read_exact_at(&mut head, r.offset).map_err(|e| Error::io(&self.path, e))?;
        if u32_at(&head, 0) != Some(r.len) {
            return Err(bad(format!("record at byte {} is not {} bytes long", r.offset, r.len)));
        }
        let mut data = vec![0u8; r.len as usize];
        self.file
            .read_exact_at(&mut data, r.offset + RECORD_HEADER_LEN as u64)
            .map_err(|e| Error::io(&self.path, e))?;
        if Some(crc32fast::hash(&data)) != u32_at(&head, 4) {
            return Err(Error::RecordChecksum { path: path_str(&self.path), offset: r.offset });
        }
        Ok(data)
    }
}

/// A read-only, memory-mapped blob file.
pub struct BlobFile {
    path: PathBuf,
    map: memmap2::Mmap,
    count: u32,
}

impl std::fmt::Debug for BlobFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlobFile")
            .field("path", &self.path)
            .field("len", &self.map.len())
            .field("count", &self.count)
            .finish()
    }
}

impl BlobFile {
    /// Opens `path`, checking magic, header checksum, kind, version and length.
    pub fn open(path: &Path, kind: [u8; 4]) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut h = [0u8; BLOB_HEADER_LEN];
        let got = usize::try_from(len).map_or(BLOB_HEADER_LEN, |l| l.min(BLOB_HEADER_LEN));
        file.read_exact_at(&mut h[..got], 0).map_err(|e| Error::io(path, e))?;
        if h[..got.min(8)] != BLOB_MAGIC[..got.min(8)] {
            return Err(Error::WrongMagic { path: path_str(path), expected: "blob" });
        }
        if got < BLOB_HEADER_LEN {
            return Err(Error::truncated(path, format!("{len} bytes, shorter than the {BLOB_HEADER_LEN}-byte header")));
        }
        if crc32fast::hash(&h[0..28]) != u32_at(&h, 28).unwrap_or(0) {
            return Err(Error::corrupt(path, "header checksum mismatch"));
        }
        if h[8..12] != kind {
            return Err(Error::WrongKind { path: path_str(path), found: tag_str(&h[8..12]), expected: tag_str(&kind) });
        }
        let version = u32_at(&h, 12).unwrap_or(0);
        if version != FORMAT_VERSION {
            return Err(Error::WrongVersion { path: path_str(path), found: version, expected: FORMAT_VERSION });
        }
        let data_len = u64_at(&h, 16).unwrap_or(0);
        let count = u32_at(&h, 24).unwrap_or(0);
        let expected = data_len
            .checked_add(BLOB_HEADER_LEN as u64)
            .ok_or_else(|| Error::corrupt(path, "data length overflows"))?;
        if len < expected {
            return Err(Error::truncated(path, format!("{len} bytes, header says {expected}")));
        }
        if len > expected {
            return Err(Error::corrupt(path, format!("{len} bytes, header says {expected}: trailing bytes")));
        }
        if data_len / (RECORD_HEADER_LEN as u64) < u64::from(count) {
            return Err(Error::corrupt(path, format!("{count} records cannot fit in {data_len} bytes")));
        }
        // SAFETY: database files are immutable once renamed into place; the length is checked.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        if map.len() as u64 != expected {
            return Err(Error::corrupt(path, "file changed while opening"));
        }
        Ok(Self { path: path.to_path_buf(), map, count })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Records in the file.
    pub fn count(&self) -> u32 {
        self.count
    }
    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        self.map.len() as u64
    }

    /// The bytes of the record at `r`, with bounds, length and crc32 checked.
    pub fn get(&self, r: BlobRef) -> Result<&[u8]> {
        let (data, crc) = self.locate(r)?;
        let data = &self.map[data];
        if crc32fast::hash(data) != crc {
            return Err(Error::RecordChecksum { path: path_str(&self.path), offset: r.offset });
        }
        Ok(data)
    }

    /// The crc32 stored for the record at `r` (bounds and length checked, the bytes not hashed;
    /// [`BlobFile::get`] checks them): a content tag for the record, such as an HTTP ETag.
    pub fn checksum(&self, r: BlobRef) -> Result<u32> {
        Ok(self.locate(r)?.1)
    }

    /// Where the data of the record at `r` lies in the file, and its stored crc32.
    fn locate(&self, r: BlobRef) -> Result<(std::ops::Range<usize>, u32)> {
        let bad = |reason: String| Error::corrupt(&self.path, reason);
        let start = usize::try_from(r.offset)
            .ok()
            .filter(|&s| s >= BLOB_HEADER_LEN)
            .ok_or_else(|| bad(format!("record offset {} outside the data", r.offset)))?;
        let stored_len =
            u32_at(&self.map, start).ok_or_else(|| bad(format!("record offset {} beyond the end", r.offset)))?;
        if stored_len != r.len {
            return Err(bad(format!("record at byte {} has {stored_len} bytes, reference says {}", r.offset, r.len)));
        }
        let data_start = start + RECORD_HEADER_LEN;
        let end = data_start
            .checked_add(r.len as usize)
            .filter(|&end| end <= self.map.len())
            .ok_or_else(|| bad(format!("record at byte {} runs past the end", r.offset)))?;
        Ok((data_start..end, u32_at(&self.map, start + 4).unwrap_or(0)))
    }

    /// Reads every record, checking lengths and checksums, and that the records fill the data
    /// exactly.
    pub fn verify(&self) -> Result<()> {
        let mut end = BLOB_HEADER_LEN as u64;
        for r in self.iter() {
            let (r, _) = r?;
            end = r.offset + (RECORD_HEADER_LEN as u64) + u64::from(r.len);
        }
        if end != self.file_len() {
            return Err(Error::corrupt(&self.path, format!("records end at byte {end}, data at {}", self.file_len())));
        }
        Ok(())
    }

    /// Every record in file order, each checked; stops at the first error.
    pub fn iter(&self) -> impl Iterator<Item = Result<(BlobRef, &[u8])>> + '_ {
        let mut offset = BLOB_HEADER_LEN as u64;
        let mut left = self.count;
        std::iter::from_fn(move || {
            if left == 0 {
                return None;
            }
            let index = self.count - left;
            left -= 1;
            let Some(len) = u32_at(&self.map, offset as usize) else {
                left = 0;
                return Some(Err(Error::truncated(&self.path, format!("record {index} of {} missing", self.count))));
            };
            let r = BlobRef { offset, len };
            let item = self.get(r).map(|b| (r, b));
            if item.is_err() {
                left = 0;
            }
            offset += RECORD_HEADER_LEN as u64 + u64::from(len);
            Some(item)
        })
    }
}

/// Recomputes the header checksum and that of every record whose bytes lie in a blob-file
/// image in memory, so that a mutated payload reaches the decoders behind the checksum check.
/// For fault-injection tests and fuzzing only (the twin of `pagefile::reseal_checksums`).
pub fn reseal_checksums(b: &mut [u8]) {
    if b.len() < BLOB_HEADER_LEN {
        return;
    }
    let crc = crc32fast::hash(&b[0..28]);
    b[28..32].copy_from_slice(&crc.to_le_bytes());
    let mut at = BLOB_HEADER_LEN;
    while at + RECORD_HEADER_LEN <= b.len() {
        let len = u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes")) as usize;
        let data = at + RECORD_HEADER_LEN;
        let Some(end) = data.checked_add(len).filter(|&e| e <= b.len()) else { break };
        let crc = crc32fast::hash(&b[data..end]);
        b[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
        at = end;
    }
}
