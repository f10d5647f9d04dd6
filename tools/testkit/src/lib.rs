//! hdov's test kit: what the tests (`tests/`), benchmarks (`benches/`) and experiment tools
//! (`tools/`) share, kept out of the library's public face. A dev-dependency of `hdov` and a
//! dependency of `hdov-tools`.
//!
//! - [`scenes`]: scenes built in code (spheres, boxes, walls with holes, a city block, a town);
//! - [`gpu`]: skipping GPU tests where no adapter exists, unless CI requires one;
//! - [`audit`]: the DoV audits (backend agreement, the dense from-region reference, floor tests);
//! - [`bench`]: the query benchmarks' database fixture and viewpoints;
//! - [`view_error`]: from-region error as a user sees it (wrong share of a view, per frame);
//! - [`testdata`]: assimp's test models and the glTF-Validator, skipped or required;
//! - [`browser`]: pages of `hdov serve` in headless chromium;
//! - [`tiles`]: a 3D Tiles tileset with its subtree tilesets put in place.

pub mod audit;
pub mod bench;
pub mod browser;
pub mod gpu;
pub mod scenes;
pub mod testdata;
pub mod tiles;
pub mod view_error;

/// Prints `skipped: WHY (TEST)` where `cargo test` shows it: on the stderr handle itself, not
/// through `println!` or `eprintln!`, which the test harness captures and hides for passing tests.
pub fn skip(why: &str) {
    use std::io::Write;
    let test = std::thread::current().name().unwrap_or("a test").to_string();
    let _ = writeln!(std::io::stderr(), "skipped: {why} ({test})");
}
