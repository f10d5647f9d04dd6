//! Tree node decoder. Input: u32 node count, u32 object count, u32 node id, then the page
//! payload. Any bytes give Ok or Err; a decoded node encodes back to itself.
#![no_main]

use hdov::format::tree_page::{check_position, decode, encode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 12 {
        return;
    }
    let word = |i: usize| u32::from_le_bytes(data[4 * i..4 * i + 4].try_into().unwrap());
    let (nodes, objects, id) = (word(0), word(1), word(2));
    if let Ok(page) = decode(&data[12..], nodes, objects) {
        assert_eq!(decode(&encode(&page), nodes, objects).as_ref(), Ok(&page));
        let _ = check_position(&page, id);
    }
});
