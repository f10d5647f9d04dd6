//! V-entries, V-pages and their byte encodings.
//!
//! A V-page holds one node's V-entries for one cell, one per entry of the node, in entry order.
//! On disk a V-entry is its DoV (f32, or u16 on a log scale) followed by its NVO (u16 when every
//! NVO of the layout fits, else u32), little-endian, with no padding.

/// One tree entry's view-variant data for one cell.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct VEntry {
    /// Degree of visibility in [0, 1].
    pub dov: f32,
    /// Number of visible objects under the entry.
    pub nvo: u32,
}

impl VEntry {
    /// Hidden: nothing of the entry is seen from the cell.
    pub fn is_zero(&self) -> bool {
        self.dov == 0.0 && self.nvo == 0
    }
}

/// The view-variant data of a whole tree over all cells: the input of the layout writers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VData {
    pub cell_count: u32,
    /// Entries per node, indexed by the node's depth-first number (0 = root).
    pub node_fanout: Vec<u16>,
    /// Per cell: V-pages of the visible nodes only, sorted by node dfs number; each
    /// `Vec<VEntry>` has `node_fanout[node]` entries.
    pub cells: Vec<Vec<(u32, Vec<VEntry>)>>,
}

/// Counts that describe a [`VData`] (and the layouts written from it).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct VDataStats {
    pub cell_count: u32,
    pub node_count: u32,
    /// Visible nodes (non-zero V-pages) over all cells.
    pub visible_total: u64,
    pub visible_mean: f64,
    pub visible_max: u32,
    /// The largest NVO of any entry (decides the NVO field width).
    pub nvo_max: u32,
}

impl VData {
    /// Checks the shape: cell count, sorted node numbers in range, entry counts, DoVs finite
    /// and ≥ 0. Returns the reason for the first violation.
    pub fn validate(&self) -> Result<(), String> {
        if self.cells.len() as u64 != u64::from(self.cell_count) {
            return Err(format!("cell_count {} but {} cells given", self.cell_count, self.cells.len()));
        }
        let n = self.node_fanout.len();
        if u32::try_from(n).is_err() {
            return Err(format!("{n} nodes: more than 2^32"));
        }
        for (c, cell) in self.cells.iter().enumerate() {
            validate_cell(c, cell, &self.node_fanout)?;
        }
        Ok(())
    }

    /// Visible-node counts and the largest NVO. All-zero V-pages do not count as visible.
    pub fn stats(&self) -> VDataStats {
        let mut s =
            VDataStats { cell_count: self.cell_count, node_count: self.node_fanout.len() as u32, ..Default::default() };
        for cell in &self.cells {
            let visible = cell.iter().filter(|(_, e)| !is_zero_page(e)).count() as u32;
            s.visible_total += u64::from(visible);
            s.visible_max = s.visible_max.max(visible);
            for (_, entries) in cell {
                for e in entries {
                    s.nvo_max = s.nvo_max.max(e.nvo);
                }
            }
        }
        s.visible_mean = if self.cell_count == 0 { 0.0 } else { s.visible_total as f64 / f64::from(self.cell_count) };
        s
    }
}

/// Checks one cell's V-pages (number `c`, for the message): node numbers strictly increasing
/// and in range of `node_fanout`, one V-entry per node entry, DoVs finite and ≥ 0.
pub fn validate_cell(c: usize, cell: &[(u32, Vec<VEntry>)], node_fanout: &[u16]) -> Result<(), String> {
    let n = node_fanout.len();
    let mut prev: Option<u32> = None;
    for (node, entries) in cell {
        if prev.is_some_and(|p| p >= *node) {
            return Err(format!("cell {c}: nodes not strictly increasing at node {node}"));
        }
        prev = Some(*node);
        let Some(&fanout) = node_fanout.get(*node as usize) else {
            return Err(format!("cell {c}: node {node} out of range ({n} nodes)"));
        };
        if entries.len() != usize::from(fanout) {
            return Err(format!("cell {c}, node {node}: {} V-entries for {fanout} entries", entries.len()));
        }
        if let Some(e) = entries.iter().find(|e| !(e.dov >= 0.0 && e.dov.is_finite())) {
            return Err(format!("cell {c}, node {node}: DoV {} not finite and ≥ 0", e.dov));
        }
    }
    Ok(())
}

/// A V-page whose entries are all (0, 0) is invisible: the layouts store it as absent.
pub(crate) fn is_zero_page(entries: &[VEntry]) -> bool {
    entries.iter().all(VEntry::is_zero)
}

/// How DoVs are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DovCodec {
    /// f32, bit-exact.
    #[default]
    F32,
    /// u16 on a log scale; relative error ≤ [`LOG_DOV_REL_ERROR`] (see [`quantize_dov`]).
    LogU16,
}

impl DovCodec {
    pub(crate) fn code(self) -> u8 {
        match self {
            DovCodec::F32 => 0,
            DovCodec::LogU16 => 1,
        }
    }
    pub(crate) fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(DovCodec::F32),
            1 => Some(DovCodec::LogU16),
            _ => None,
        }
    }
}

impl DovCodec {
    /// Both codecs.
    pub const ALL: [DovCodec; 2] = [DovCodec::F32, DovCodec::LogU16];

    /// The name used on the command line and in manifests.
    pub fn name(self) -> &'static str {
        match self {
            DovCodec::F32 => "f32",
            DovCodec::LogU16 => "log-u16",
        }
    }
}

crate::named!(DovCodec, "DoV codec");
crate::by_names!(DovCodec);

/// The smallest non-zero DoV the log scale represents: 2^-32 ≈ 2.3e-10, far below one texel
/// of any practical cube map (1.2e-6 at R = 512, 7.6e-8 at R = 2048). Smaller positive DoVs
/// are stored as this value, so a visible entry never becomes hidden.
pub const LOG_DOV_MIN: f64 = 1.0 / 4_294_967_296.0;
/// Codes 1..=65535 span [LOG_DOV_MIN, 1] in 65534 equal steps of ln(DoV).
const LOG_STEPS: f64 = 65534.0;
/// Bound on |decoded − dov| / dov for dov in [LOG_DOV_MIN, 1]: half a log step,
/// e^(ln(2^32)/(2·65534)) − 1 = 1.6926e-4, plus f32 rounding.
pub const LOG_DOV_REL_ERROR: f32 = 1.7e-4;

/// Encodes a DoV on the log scale: 0 (and anything ≤ 0) → 0; (0, LOG_DOV_MIN] → 1;
/// values above 1 are stored as 1. Monotone: a ≤ b implies code(a) ≤ code(b).
pub fn quantize_dov(dov: f32) -> u16 {
    if dov.is_nan() || dov <= 0.0 {
        return 0;
    }
    let x = (f64::from(dov.min(1.0)) / LOG_DOV_MIN).ln() / (1.0 / LOG_DOV_MIN).ln();
    (x * LOG_STEPS).round().clamp(0.0, LOG_STEPS) as u16 + 1
}

/// Decodes [`quantize_dov`]'s code.
pub fn dequantize_dov(code: u16) -> f32 {
    if code == 0 {
        return 0.0;
    }
    let x = f64::from(code - 1) / LOG_STEPS;
    ((LOG_DOV_MIN.ln() * (1.0 - x)).exp() as f32).min(1.0)
}

/// The byte encoding of the V-entries of one layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VPageCodec {
    pub dov: DovCodec,
    /// Bytes of the NVO field: 2 or 4.
    pub nvo_bytes: u8,
}

impl VPageCodec {
    /// The codec for `dov` storage and NVOs up to `nvo_max`.
    pub fn new(dov: DovCodec, nvo_max: u32) -> Self {
        let nvo_bytes = if nvo_max <= u32::from(u16::MAX) { 2 } else { 4 };
        Self { dov, nvo_bytes }
    }

    /// Bytes of one V-entry.
    pub fn entry_bytes(&self) -> usize {
        let dov = match self.dov {
            DovCodec::F32 => 4,
            DovCodec::LogU16 => 2,
        };
        dov + usize::from(self.nvo_bytes)
    }

    /// Bytes of a V-page of `fanout` entries.
    pub fn vpage_bytes(&self, fanout: u16) -> usize {
        usize::from(fanout) * self.entry_bytes()
    }

    /// Appends the encoding of `entries` to `out`.
    pub(crate) fn encode(&self, entries: &[VEntry], out: &mut Vec<u8>) {
        for e in entries {
            match self.dov {
                DovCodec::F32 => out.extend_from_slice(&e.dov.to_le_bytes()),
                DovCodec::LogU16 => out.extend_from_slice(&quantize_dov(e.dov).to_le_bytes()),
            }
            if self.nvo_bytes == 2 {
                // The writer chose 2 bytes only when every NVO fits.
                out.extend_from_slice(&(e.nvo.min(u32::from(u16::MAX)) as u16).to_le_bytes());
            } else {
                out.extend_from_slice(&e.nvo.to_le_bytes());
            }
        }
    }

    /// Decodes `bytes` (a whole number of entries) into `out` (cleared first).
    pub(crate) fn decode(&self, bytes: &[u8], out: &mut Vec<VEntry>) {
        out.clear();
        out.extend(bytes.chunks_exact(self.entry_bytes()).map(|b| self.decode_one(b)));
    }

    /// Decodes one V-entry from the first [`entry_bytes`](Self::entry_bytes) bytes of `b`.
    fn decode_one(&self, b: &[u8]) -> VEntry {
        let (dov, rest) = match self.dov {
            DovCodec::F32 => (f32::from_le_bytes([b[0], b[1], b[2], b[3]]), &b[4..]),
            DovCodec::LogU16 => (dequantize_dov(u16::from_le_bytes([b[0], b[1]])), &b[2..]),
        };
        let nvo = if self.nvo_bytes == 2 {
            u32::from(u16::from_le_bytes([rest[0], rest[1]]))
        } else {
            u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]])
        };
        VEntry { dov, nvo }
    }
}

/// The sparse-capable V-page encoding of the pointer-addressed layouts (vertical,
/// indexed-vertical). A V-page record starts with a header `h` of `index_bytes` bytes (u8 when
/// the layout's largest fan-out is ≤ 256, else u16, little-endian):
///
/// - `h = 0`: dense; the node's `fanout` V-entries follow, as without this encoding;
/// - `h = k ≥ 1`: sparse; `k` pairs follow, each an entry index (`index_bytes` bytes, strictly
///   ascending, `< fanout`) and that entry's V-entry; all other entries are (0, 0).
///
/// A stored V-page is visible, so it has at least one non-zero entry and `h = 0` is free to mark
/// the dense form. The writer picks the shorter form (dense on a tie); sparse is shorter only
/// when `k < fanout`, so `k` fits the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SparseCodec {
    /// Bytes of the header and of each entry index: 1 or 2.
    pub index_bytes: u8,
}

impl SparseCodec {
    /// The encoding for a layout whose largest fan-out is `max_fanout`.
    pub fn for_max_fanout(max_fanout: u16) -> Self {
        Self { index_bytes: if max_fanout <= 256 { 1 } else { 2 } }
    }

    /// Bytes of the header (also of one entry index).
    pub fn header_len(&self) -> usize {
        usize::from(self.index_bytes)
    }

    fn put(&self, v: usize, out: &mut Vec<u8>) {
        if self.index_bytes == 1 {
            out.push(v as u8);
        } else {
            out.extend_from_slice(&(v as u16).to_le_bytes());
        }
    }

    fn get(&self, b: &[u8]) -> usize {
        if self.index_bytes == 1 { usize::from(b[0]) } else { usize::from(u16::from_le_bytes([b[0], b[1]])) }
    }

    /// Appends the shorter encoding of `entries` (one node's whole V-page) to `out`.
    pub fn encode(&self, codec: &VPageCodec, entries: &[VEntry], out: &mut Vec<u8>) {
        let e = codec.entry_bytes();
        let visible = entries.iter().filter(|v| !v.is_zero()).count();
        if visible > 0 && visible * (self.header_len() + e) < entries.len() * e {
            self.put(visible, out);
            for (i, v) in entries.iter().enumerate().filter(|(_, v)| !v.is_zero()) {
                self.put(i, out);
                codec.encode(std::slice::from_ref(v), out);
            }
        } else {
            self.put(0, out);
            codec.encode(entries, out);
        }
    }

    /// The length of the whole record of a V-page of `fanout` entries whose first
    /// [`header_len`](Self::header_len) bytes are `header`.
    pub fn record_len(&self, codec: &VPageCodec, fanout: u16, header: &[u8]) -> Result<usize, String> {
        let e = codec.entry_bytes();
        match self.get(header) {
            0 => Ok(self.header_len() + codec.vpage_bytes(fanout)),
            k if k <= usize::from(fanout) => Ok(self.header_len() + k * (self.header_len() + e)),
            k => Err(format!("sparse V-page lists {k} entries, the node has {fanout}")),
        }
    }

    /// Decodes a whole record (as long as [`record_len`](Self::record_len) says) into the dense
    /// V-page of `fanout` entries in `out` (cleared first).
    pub fn decode(&self, codec: &VPageCodec, fanout: u16, bytes: &[u8], out: &mut Vec<VEntry>) -> Result<(), String> {
        out.clear();
        let want = self.record_len(codec, fanout, bytes)?;
        if bytes.len() != want {
            return Err(format!("V-page record of {} bytes, its header needs {want}", bytes.len()));
        }
        let h = self.header_len();
        let body = &bytes[h..];
        if self.get(bytes) == 0 {
            codec.decode(body, out);
            return Ok(());
        }
        out.resize(usize::from(fanout), VEntry::default());
        let mut next = 0usize;
        for pair in body.chunks_exact(h + codec.entry_bytes()) {
            let i = self.get(pair);
            if i < next || i >= usize::from(fanout) {
                out.clear();
                return Err(format!("sparse V-page: entry index {i} out of order or range (fan-out {fanout})"));
            }
            out[i] = codec.decode_one(&pair[h..]);
            next = i + 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_scale_error_bound_holds_across_the_range() {
        let mut worst = 0.0f64;
        let mut prev_code = 0u16;
        // Geometric sweep over [2^-32, 1] plus the ends.
        let mut d = LOG_DOV_MIN as f32;
        while d <= 1.0 {
            let code = quantize_dov(d);
            assert!(code >= prev_code, "not monotone at {d}");
            prev_code = code;
            let r = dequantize_dov(code);
            let rel = ((f64::from(r) - f64::from(d)) / f64::from(d)).abs();
            worst = worst.max(rel);
            assert!(rel <= f64::from(LOG_DOV_REL_ERROR), "{d} -> {r}: {rel}");
            d *= 1.000_37;
        }
        assert!(worst > 1.0e-4, "sweep too coarse to probe the bound: {worst}");
        assert_eq!(dequantize_dov(quantize_dov(1.0)), 1.0);
        assert_eq!(quantize_dov(0.0), 0);
        assert_eq!(dequantize_dov(0), 0.0);
        assert_eq!(quantize_dov(-0.0), 0);
        assert_eq!(quantize_dov(2.0), u16::MAX);
    }

    #[test]
    fn tiny_positive_dov_stays_visible() {
        for d in [f32::MIN_POSITIVE, 1e-30, 1e-12, LOG_DOV_MIN as f32] {
            let r = dequantize_dov(quantize_dov(d));
            assert!(r > 0.0 && f64::from(r) <= LOG_DOV_MIN * 1.001, "{d} -> {r}");
        }
    }

    #[test]
    fn codec_round_trip() {
        let entries = [VEntry { dov: 0.25, nvo: 3 }, VEntry { dov: 0.0, nvo: 0 }, VEntry { dov: 1.0, nvo: 65535 }];
        for codec in [VPageCodec::new(DovCodec::F32, 65535), VPageCodec::new(DovCodec::F32, 70000)] {
            let mut bytes = Vec::new();
            codec.encode(&entries, &mut bytes);
            assert_eq!(bytes.len(), codec.vpage_bytes(3));
            let mut out = Vec::new();
            codec.decode(&bytes, &mut out);
            assert_eq!(out, entries);
        }
        let big = [VEntry { dov: 0.5, nvo: 70000 }];
        let codec = VPageCodec::new(DovCodec::LogU16, 70000);
        assert_eq!(codec.entry_bytes(), 6);
        let mut bytes = Vec::new();
        codec.encode(&big, &mut bytes);
        let mut out = Vec::new();
        codec.decode(&bytes, &mut out);
        assert_eq!(out[0].nvo, 70000);
        assert!((out[0].dov - 0.5).abs() <= 0.5 * LOG_DOV_REL_ERROR);
    }

    #[test]
    fn sparse_form_is_chosen_exactly_when_shorter() {
        // Fan-out 126, 6-byte entries, u8 indices: dense 1 + 756 bytes, sparse 1 + 7k.
        let codec = VPageCodec::new(DovCodec::F32, 10);
        let sp = SparseCodec::for_max_fanout(126);
        for (k, sparse) in [(1usize, true), (107, true), (108, false), (126, false)] {
            let mut page = vec![VEntry::default(); 126];
            for e in page.iter_mut().rev().take(k) {
                *e = VEntry { dov: 0.5, nvo: 2 };
            }
            let mut bytes = Vec::new();
            sp.encode(&codec, &page, &mut bytes);
            assert_eq!(bytes.len(), if sparse { 1 + 7 * k } else { 757 }, "k = {k}");
            assert_eq!(bytes[0] as usize, if sparse { k } else { 0 });
            assert_eq!(sp.record_len(&codec, 126, &bytes), Ok(bytes.len()));
            let mut out = Vec::new();
            sp.decode(&codec, 126, &bytes, &mut out).unwrap();
            assert_eq!(out, page);
            // A record cut short or extended is refused.
            assert!(sp.decode(&codec, 126, &bytes[..bytes.len() - 1], &mut out).is_err());
        }
        // u16 indices above fan-out 256; a count above the fan-out is refused.
        let sp = SparseCodec::for_max_fanout(300);
        assert_eq!(sp.header_len(), 2);
        assert!(sp.record_len(&codec, 300, &301u16.to_le_bytes()).is_err());
        let mut page = vec![VEntry::default(); 300];
        page[299] = VEntry { dov: 1.0, nvo: 1 };
        let mut bytes = Vec::new();
        sp.encode(&codec, &page, &mut bytes);
        assert_eq!(
            bytes,
            [&1u16.to_le_bytes()[..], &299u16.to_le_bytes(), &1.0f32.to_le_bytes(), &1u16.to_le_bytes()].concat()
        );
    }

    #[test]
    fn validate_rejects_bad_shapes() {
        let ok = VData {
            cell_count: 1,
            node_fanout: vec![2, 1],
            cells: vec![vec![(0, vec![VEntry::default(); 2]), (1, vec![VEntry::default()])]],
        };
        assert!(ok.validate().is_ok());
        let mut bad = ok.clone();
        bad.cell_count = 2;
        assert!(bad.validate().is_err());
        let mut bad = ok.clone();
        bad.cells[0].swap(0, 1);
        assert!(bad.validate().is_err());
        let mut bad = ok.clone();
        bad.cells[0][1].0 = 2;
        assert!(bad.validate().is_err());
        let mut bad = ok.clone();
        bad.cells[0][0].1.pop();
        assert!(bad.validate().is_err());
        let mut bad = ok;
        bad.cells[0][0].1[0].dov = f32::NAN;
        assert!(bad.validate().is_err());
    }
}
