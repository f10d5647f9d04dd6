//! Pages of `hdov serve` in a real browser: Debian's chromium, headless, with software WebGL
//! (SwiftShader), driven from the command line (`--dump-dom`, `--screenshot`).

use std::process::Command;

/// The chromium binary, or `None` (after [`crate::skip`], or a panic where `HDOV_REQUIRE_BROWSER`
/// is `1`, as `.ci/run` sets it).
pub fn chromium_or_skip() -> Option<&'static str> {
    let found =
        ["chromium", "chromium-browser"].into_iter().find(|c| Command::new(c).arg("--version").output().is_ok());
    if found.is_none() {
        assert!(std::env::var("HDOV_REQUIRE_BROWSER").as_deref() != Ok("1"), "chromium is required");
        crate::skip("no chromium");
    }
    found
}

/// Runs `chromium` headless on `url` with `what` (`--dump-dom`, `--screenshot=FILE`) in a window
/// of `size`, giving the page `budget_ms` of virtual time; its stdout, after checking that it
/// exited well and that nothing was uncaught in the page's console.
pub fn browse(chromium: &str, what: &str, url: &str, size: [u32; 2], budget_ms: u32) -> String {
    let out = Command::new(chromium)
        .args(["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
        .arg(format!("--window-size={},{}", size[0], size[1]))
        .arg(format!("--virtual-time-budget={budget_ms}"))
        .args(["--enable-logging=stderr", "--v=0"])
        .args([what, url])
        .output()
        .unwrap();
    assert!(out.status.success(), "chromium {what}: {:?}", out.status);
    let console = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!console.contains("Uncaught"), "{url}: an error in the console:\n{console}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The JSON a page wrote into its `<pre id="result">` (`tiles.html`), or the reason there is none
/// (the page's error line, or its state).
pub fn page_result(dom: &str) -> Result<serde_json::Value, String> {
    let between = |from: &str, to: &str| dom.split_once(from).and_then(|(_, rest)| rest.split_once(to)).map(|(x, _)| x);
    let text = between("<pre id=\"result\">", "</pre>").unwrap_or("");
    if text.is_empty() {
        let error = between("<div id=\"error\">", "</div>").unwrap_or("");
        let state = between("data-state=\"", "\"").unwrap_or("none");
        return Err(format!("no result (state {state}, error '{error}')"));
    }
    let unescaped = text.replace("&quot;", "\"").replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&");
    serde_json::from_str(&unescaped).map_err(|e| format!("result is not JSON: {e}"))
}
