//! GPU tests on machines with and without a graphics adapter: a test that needs one skips with
//! a visible line where none exists, unless CI has asked for adapters to be required.

use hdov::gfx::adapter_available;

/// Environment variable that makes the GPU tests fail instead of skip when no adapter exists.
pub const REQUIRE_ADAPTER_ENV: &str = "HDOV_REQUIRE_ADAPTER";

/// For tests: `true` when a GPU test can run. Without an adapter it prints
/// `skipped: no adapter (TEST)` and returns `false`, unless [`REQUIRE_ADAPTER_ENV`] is `1`, in
/// which case it panics (CI sets it after installing Mesa, so a missing driver cannot pass
/// silently).
pub fn adapter_or_skip() -> bool {
    if adapter_available().is_some() {
        return true;
    }
    if std::env::var(REQUIRE_ADAPTER_ENV).is_ok_and(|v| v == "1") {
        panic!("no wgpu adapter, and {REQUIRE_ADAPTER_ENV}=1 requires one");
    }
    crate::skip("no adapter");
    false
}
