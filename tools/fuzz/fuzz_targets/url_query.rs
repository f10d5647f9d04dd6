//! URL query strings as `hdov serve` reads them (`/query?…`, `/walk?…`): any bytes give a point,
//! a path and query parameters, or a one-line reason, never a panic. What parses is checked the
//! way the library then checks it: points finite, a walk's every step finite.
#![no_main]

use hdov::text::{QUERY_KEYS, UrlQuery, WALK_KEYS};
use libfuzzer_sys::fuzz_target;

fn one_line(e: &str) {
    assert!(!e.contains('\n'), "{e}");
}

fuzz_target!(|data: &[u8]| {
    let Ok(raw) = std::str::from_utf8(data) else { return };
    for keys in [QUERY_KEYS, WALK_KEYS] {
        match UrlQuery::parse(raw, keys) {
            Ok(q) => {
                match q.point("at") {
                    Ok(at) => assert!(at.is_finite()),
                    Err(e) => one_line(&e),
                }
                match q.path() {
                    Ok(path) => assert!(path.iter().all(|p| p.is_finite())),
                    Err(e) => one_line(&e),
                }
                match q.query_params() {
                    Ok(p) => assert!(p.camera.is_none_or(|c| c.look.is_finite())),
                    Err(e) => one_line(&e),
                }
            }
            Err(e) => one_line(&e),
        }
    }
});
