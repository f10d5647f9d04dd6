//! Catalog decoder. Input: u32 node count, u64 geometry.blob length, then the catalog record.
//! Any bytes give Ok or Err (the decode is bounded); a catalog that passes its check answers
//! every object's LOD chain.
#![no_main]

use std::path::Path;

use hdov::format::catalog::Catalog;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 12 {
        return;
    }
    let nodes = u32::from_le_bytes(data[0..4].try_into().unwrap()) as usize;
    let geometry_len = u64::from_le_bytes(data[4..12].try_into().unwrap());
    let Ok(catalog) = hdov::record::decode::<Catalog>(&data[12..], Path::new("catalog.blob"), "catalog") else {
        return;
    };
    if catalog.check(nodes, geometry_len).is_ok() {
        for object in 0..catalog.objects.len() {
            assert!(!catalog.object_lods(object as u32).is_empty());
        }
    }
});
