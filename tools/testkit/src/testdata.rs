//! Test data and tools that Debian packages bring (`assimp-testmodels`, the npm
//! `gltf-validator`): a test that needs them skips with a visible line where they are missing,
//! unless CI, which installs them, has asked for them to be required.

use std::path::PathBuf;

/// Environment variable that makes such tests fail instead of skip when their data is missing.
pub const REQUIRE_TESTDATA_ENV: &str = "HDOV_REQUIRE_TESTDATA";

/// Skips the calling test for want of `what`: prints `skipped: no WHAT`, or panics where
/// [`REQUIRE_TESTDATA_ENV`] is `1`.
pub fn skip_for_want_of(what: &str) {
    assert!(std::env::var(REQUIRE_TESTDATA_ENV).as_deref() != Ok("1"), "{what} is required ({REQUIRE_TESTDATA_ENV}=1)");
    crate::skip(&format!("no {what}"));
}

/// `/usr/share/assimp/models/SUB` where `assimp-testmodels` is installed; otherwise `None`,
/// after [`skip_for_want_of`].
pub fn assimp_models(sub: &str) -> Option<PathBuf> {
    let path = PathBuf::from("/usr/share/assimp/models").join(sub);
    if path.exists() {
        return Some(path);
    }
    skip_for_want_of("assimp-testmodels (apt-get install assimp-testmodels)");
    None
}
