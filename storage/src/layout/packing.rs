//! How records (V-pages, index segments, metadata) are packed into the pages of a page file.
//!
//! The rule: a record no larger than a page's payload never straddles a page boundary (it goes
//! to the next page if the current one lacks room); a larger record starts on a page boundary
//! and fills consecutive pages. So reading any record costs the fewest pages possible:
//! 1 for a small record, ⌈len / capacity⌉ for a large one, 0 for an empty one.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::le::{u16_at, u32_at};
use crate::page_reader::PageReader;
use crate::pagefile::{PageFile, PageFileWriter};

/// A record's place: page number and byte offset in that page's payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Addr {
    pub page: u32,
    pub offset: u16,
}

/// Bytes of an encoded [`Addr`]: u32 page, u16 offset.
pub(crate) const ADDR_BYTES: usize = 6;

impl Addr {
    /// The nil pointer of the vertical layout: no V-page (the node is invisible).
    pub const NIL: Addr = Addr { page: u32::MAX, offset: u16::MAX };

    pub fn encode(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.page.to_le_bytes());
        out.extend_from_slice(&self.offset.to_le_bytes());
    }

    pub fn decode(b: &[u8], at: usize) -> Option<Addr> {
        Some(Addr { page: u32_at(b, at)?, offset: u16_at(b, at + 4)? })
    }
}

/// Pages that a record of `len` bytes occupies under the packing rule.
pub(crate) fn record_pages(len: u64, cap: u64) -> u64 {
    if len <= cap { u64::from(len > 0) } else { len.div_ceil(cap) }
}

/// Where slot `i` of an array of equal-size records starting on page `first` lies, and how
/// many pages `count` such slots take. Matches what [`Packer`] does with such an array.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlotArray {
    pub first: u64,
    pub size: u64,
    pub cap: u64,
}

impl SlotArray {
    pub fn addr(&self, i: u64) -> (u64, u64) {
        if self.size == 0 {
            (self.first, 0)
        } else if self.size <= self.cap {
            let per_page = self.cap / self.size;
            (self.first + i / per_page, (i % per_page) * self.size)
        } else {
            (self.first + i * self.size.div_ceil(self.cap), 0)
        }
    }

    /// Pages taken by `count` slots, or `None` on overflow (a corrupted count).
    pub fn pages(&self, count: u64) -> Option<u64> {
        if self.size == 0 {
            Some(0)
        } else if self.size <= self.cap {
            Some(count.div_ceil(self.cap / self.size))
        } else {
            count.checked_mul(self.size.div_ceil(self.cap))
        }
    }
}

/// Packs records into a page file.
pub(crate) struct Packer {
    /// The file written, for error messages.
    path: PathBuf,
    writer: PageFileWriter,
    cap: usize,
    /// Payload of the page being filled.
    cur: Vec<u8>,
    /// Number of the page being filled.
    cur_page: u64,
}

impl Packer {
    pub fn new(path: &Path, writer: PageFileWriter) -> Self {
        let cap = writer.capacity();
        Self { path: path.to_path_buf(), writer, cap, cur: Vec::with_capacity(cap), cur_page: 0 }
    }

    fn emit(&mut self, payload: Option<&[u8]>) -> Result<()> {
        self.writer.push(payload.unwrap_or(&self.cur))?;
        self.cur_page += 1;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        if !self.cur.is_empty() {
            self.emit(None)?;
            self.cur.clear();
        }
        Ok(())
    }

    fn addr(&self, offset: usize) -> Result<Addr> {
        let page = u32::try_from(self.cur_page).ok().filter(|&p| p != u32::MAX);
        match page {
            Some(page) => Ok(Addr { page, offset: offset as u16 }),
            None => Err(Error::invalid(&self.path, "more than 2^32 - 1 pages")),
        }
    }

    /// Starts the next record on a fresh page; returns that page's number.
    pub fn align(&mut self) -> Result<u64> {
        self.flush()?;
        Ok(self.cur_page)
    }

    /// Places `rec` under the packing rule; returns its address.
    pub fn put(&mut self, rec: &[u8]) -> Result<Addr> {
        if rec.len() <= self.cap {
            if self.cur.len() + rec.len() > self.cap {
                self.flush()?;
            }
            let addr = self.addr(self.cur.len())?;
            self.cur.extend_from_slice(rec);
            return Ok(addr);
        }
        self.flush()?;
        let addr = self.addr(0)?;
        for chunk in rec.chunks(self.cap) {
            if chunk.len() == self.cap {
                self.emit(Some(chunk))?;
            } else {
                self.cur.extend_from_slice(chunk);
            }
        }
        Ok(addr)
    }

    /// Writes the last page, puts `front` over the first pages (a metadata record that was put
    /// first as a placeholder of the same length: only now are its counts known) and finishes
    /// the file; returns (pages, file bytes).
    pub fn finish_with_front(mut self, front: &[u8]) -> Result<(u64, u64)> {
        self.flush()?;
        rewrite_front(&mut self.writer, front)?;
        self.finish()
    }

    /// Writes the last page and finishes the file; returns (pages, file bytes).
    pub fn finish(mut self) -> Result<(u64, u64)> {
        self.flush()?;
        let pages = self.cur_page;
        Ok((pages, self.writer.finish()?))
    }
}

/// Writes `rec` over the first pages of `file` as [`Packer::put`] placed it there: a record that
/// starts the file on page 0 and fills as many pages as it needs.
pub(crate) fn rewrite_front(file: &mut PageFileWriter, rec: &[u8]) -> Result<()> {
    let cap = file.capacity();
    for (i, chunk) in rec.chunks(cap).enumerate() {
        file.rewrite(i as u64, chunk)?;
    }
    Ok(())
}

/// A page file of a layout, with the record reader of the packing rule. It holds no page:
/// pages come through the caller's [`PageReader`], whose read buffer makes a record read that
/// lands on the page just read from the same file cost no new read.
pub(crate) struct PagedFile {
    pub file: PageFile,
}

impl PagedFile {
    pub fn new(file: PageFile) -> Self {
        Self { file }
    }

    pub fn path(&self) -> &Path {
        self.file.path()
    }

    pub fn corrupt(&self, reason: impl Into<String>) -> Error {
        Error::corrupt(self.file.path(), reason)
    }

    fn load(&self, pages: &mut PageReader, n: u64, priority: f64) -> Result<Arc<[u8]>> {
        if n >= self.file.page_count() {
            return Err(self.corrupt(format!("pointer to page {n}, file has {} pages", self.file.page_count())));
        }
        pages.page(&self.file, n, priority)
    }

    /// Reads the `len`-byte record at `addr` into `out` (cleared first), its pages through
    /// `pages` with `priority`.
    pub fn read_record(
        &self,
        pages: &mut PageReader,
        priority: f64,
        addr: Addr,
        len: usize,
        out: &mut Vec<u8>,
    ) -> Result<()> {
        out.clear();
        if len == 0 {
            return Ok(());
        }
        let cap = self.file.capacity();
        let offset = usize::from(addr.offset);
        let page = u64::from(addr.page);
        if len <= cap {
            if offset + len > cap {
                return Err(
                    self.corrupt(format!("record of {len} bytes at page {page} offset {offset} crosses the page end"))
                );
            }
            let p = self.load(pages, page, priority)?;
            out.extend_from_slice(&p[offset..offset + len]);
            return Ok(());
        }
        if offset != 0 {
            return Err(self.corrupt(format!("multi-page record at page {page} starts at offset {offset}, not 0")));
        }
        let count = len.div_ceil(cap) as u64;
        if page.checked_add(count).is_none_or(|end| end > self.file.page_count()) {
            return Err(self.corrupt(format!("record of {len} bytes at page {page} runs past the file's end")));
        }
        out.reserve(len);
        for i in 0..count {
            let want = (len - out.len()).min(cap);
            let p = self.load(pages, page + i, priority)?;
            out.extend_from_slice(&p[..want]);
        }
        Ok(())
    }
}
