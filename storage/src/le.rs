//! Little-endian field access that never slices out of bounds: a short buffer gives `None`.

pub(crate) fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at.checked_add(4)?)?.try_into().ok()?))
}

pub(crate) fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at.checked_add(8)?)?.try_into().ok()?))
}

/// A 4-byte kind tag as text for error messages (non-printable bytes escaped).
pub(crate) fn tag_str(tag: &[u8]) -> String {
    tag.iter().flat_map(|&c| std::ascii::escape_default(c)).map(char::from).collect()
}

pub(crate) fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at.checked_add(2)?)?.try_into().ok()?))
}
