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

/// The Khronos glTF-Validator's error and warning counts and first messages for each of
/// `files`, in one `node` run; `None` without node or the npm package `gltf-validator` (call
/// [`skip_for_want_of`] then).
pub fn gltf_validator(files: &[PathBuf]) -> Option<Vec<(u64, u64, String)>> {
    use std::process::Command;
    let root = Command::new("npm").args(["root", "-g"]).output().ok()?;
    let node_path = String::from_utf8_lossy(&root.stdout).trim().to_string();
    let script = r#"
        const fs = require('fs');
        const v = require('gltf-validator');
        (async () => {
          for (const f of process.argv.slice(1)) {
            const r = await v.validateBytes(new Uint8Array(fs.readFileSync(f)), { maxIssues: 20 });
            console.log(JSON.stringify({ e: r.issues.numErrors, w: r.issues.numWarnings, m: r.issues.messages }));
          }
        })().catch((e) => { console.error(String(e)); process.exit(3); });
    "#;
    let mut results = Vec::with_capacity(files.len());
    // A few hundred paths per run keep the command line short.
    for chunk in files.chunks(256) {
        let out = Command::new("node").arg("-e").arg(script).args(chunk).env("NODE_PATH", &node_path).output().ok()?;
        if !out.status.success() {
            return None;
        }
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let report: serde_json::Value = serde_json::from_str(line).ok()?;
            results.push((report["e"].as_u64()?, report["w"].as_u64()?, report["m"].to_string()));
        }
    }
    (results.len() == files.len()).then_some(results)
}
