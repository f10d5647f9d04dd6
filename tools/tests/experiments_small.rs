//! The experiments harness at `--scale small` into a temporary folder (the CI smoke test): every
//! CSV and chart is written, charts carry their text, and the numbers are sane — hit rates in
//! [0, 1], pages and faces never growing with η, DoV errors small on analytic shapes and falling
//! with R, thin features flagged where they fail.

use std::collections::HashMap;
use std::path::Path;

use hdov_tools::experiments::{Config, Scale, run};

/// Rows of `name.csv` as maps from column to value.
fn rows(out: &Path, name: &str) -> Vec<HashMap<String, String>> {
    let text = std::fs::read_to_string(out.join(format!("{name}.csv"))).unwrap_or_else(|e| panic!("{name}.csv: {e}"));
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().expect("a header").split(',').map(str::to_string).collect();
    let rows: Vec<_> = lines
        .map(|l| {
            // Quoted cells hold no commas in these files except where quoted; split on the rest.
            let mut cells = Vec::new();
            let mut cur = String::new();
            let mut quoted = false;
            for ch in l.chars() {
                match ch {
                    '"' => quoted = !quoted,
                    ',' if !quoted => cells.push(std::mem::take(&mut cur)),
                    c => cur.push(c),
                }
            }
            cells.push(cur);
            assert_eq!(cells.len(), header.len(), "{name}.csv: {l}");
            header.iter().cloned().zip(cells).collect()
        })
        .collect();
    assert!(!rows.is_empty(), "{name}.csv has no rows");
    rows
}

fn num(row: &HashMap<String, String>, col: &str) -> f64 {
    row[col].parse().unwrap_or_else(|_| panic!("{col} = '{}' is not a number", row[col]))
}

#[test]
fn small_scale_writes_every_csv_and_chart_with_sane_numbers() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("results");
    let mut cfg = Config::new(Scale::Small);
    cfg.caches = vec![tmp.path().join("cache")];
    cfg.out = out.clone();
    cfg.progress = false;
    let summary = run(cfg).expect("the harness runs");
    assert!(summary.contains("Machine:"), "{summary}");
    let gpu = hdov_testkit::gpu::adapter_or_skip();

    let mut charts = vec!["storage", "caching", "query_eta", "scalability", "walkthrough", "precompute", "stability"];
    if gpu {
        charts.push("accuracy");
    }
    for chart in charts {
        let svg = std::fs::read_to_string(out.join(format!("{chart}.svg"))).unwrap();
        // Titles, axis labels and legends are <text> elements (SVG needs no font files).
        assert!(svg.matches("<text").count() >= 10, "{chart}.svg carries too little text");
        assert!(svg.contains("<polyline") || svg.contains("<path"), "{chart}.svg draws no lines");
    }

    // Storage: indexed-vertical and vertical never larger than horizontal.
    for r in rows(&out, "storage").iter().filter(|r| r["layout"] != "horizontal") {
        assert!(num(r, "bytes") > 0.0);
    }
    let storage = rows(&out, "storage");
    for m in ["4", "16", "126"] {
        let bytes = |l: &str| {
            storage
                .iter()
                .find(|r| r["fanout"] == m && r["codec"] == "f32" && r["layout"] == l)
                .map(|r| num(r, "bytes"))
        };
        assert!(bytes("indexed-vertical").unwrap() < bytes("horizontal").unwrap(), "M = {m}");
    }

    // Caching: hit rates in [0, 1]; more cache never fewer hits for LRU on one sequence.
    let caching = rows(&out, "caching");
    for r in &caching {
        let h = num(r, "hit_rate");
        assert!((0.0..=1.0).contains(&h), "hit rate {h}");
        assert!(num(r, "cache_hits") <= num(r, "cache_requests"));
    }

    // Query vs η: pages and faces never grow with η (per layout, decision 20); η = 0 draws
    // what the naive method draws.
    let q = rows(&out, "query_eta");
    for layout in ["horizontal", "vertical", "indexed-vertical"] {
        let hdov: Vec<_> = q.iter().filter(|r| r["layout"] == layout && r["method"] == "hdov").collect();
        for w in hdov.windows(2) {
            assert!(num(w[1], "pages") <= num(w[0], "pages") + 1e-9, "{layout}: pages grow with η");
            assert!(num(w[1], "faces") <= num(w[0], "faces") + 1e-9, "{layout}: faces grow with η");
        }
        let naive = q.iter().find(|r| r["layout"] == layout && r["method"] == "naive").unwrap();
        assert_eq!(num(naive, "faces"), num(hdov[0], "faces"), "{layout}: η = 0 is the naive answer");
    }

    // Scalability: four sizes, bigger cities make bigger databases.
    let s = rows(&out, "scalability");
    let mut sizes: Vec<(f64, f64)> =
        s.iter().filter(|r| r["query"] == "naive").map(|r| (num(r, "objects"), num(r, "db_bytes"))).collect();
    assert_eq!(sizes.len(), 4);
    sizes.sort_by(|a, b| a.0.total_cmp(&b.0));
    assert!(sizes.windows(2).all(|w| w[1].1 > w[0].1), "{sizes:?}");

    // Walkthrough: frustum culling draws at least as much as VISUAL η = 0 on the whole walk.
    let w = rows(&out, "walkthrough");
    let faces = |m: &str| num(w.iter().find(|r| r["method"] == m).unwrap(), "faces_mean");
    assert!(faces("frustum culling") >= faces("VISUAL η = 0"));
    assert!(faces("VISUAL η = 3e-2 (default)") <= faces("VISUAL η = 0"));

    // Precompute: the sphere's DoV within 5 % of analytic at R = 128 on the CPU, error falling
    // from R = 32 to 128; more interior samples never leave more zero-DoV objects.
    let a = rows(&out, "precompute_analytic");
    let err = |r: &str| {
        let v: Vec<f64> = a
            .iter()
            .filter(|x| x["backend"] == "cpu" && x["resolution"] == r)
            .map(|x| num(x, "mean_rel_error"))
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    assert!(err("128") < 0.05, "{}", err("128"));
    assert!(err("128") < err("32"));
    let z = rows(&out, "precompute_zero_dov");
    for r in &z {
        assert!(num(r, "caught") <= num(r, "zero_dov"));
        assert!((0.0..=1.0).contains(&num(r, "zero_dov_rate")));
    }
    let pe = rows(&out, "precompute_speed_error");
    assert!(pe.iter().all(|r| num(r, "mean_abs_dov_error") >= 0.0 && num(r, "s_per_cell") > 0.0));

    // Stability: wide features are measured within 10 % and steadily; a quarter-texel pole
    // flickers (the documented failure).
    let st = rows(&out, "stability");
    let case = |c: &str, w: &str| st.iter().find(|r| r["case"] == c && r["width_texels"] == w).unwrap();
    for c in ["pole", "bar", "fence"] {
        assert!(num(case(c, "8"), "rel_error").abs() < 0.1, "{c} at 8 texels");
        assert!(num(case(c, "8"), "cv_under_jitter") < 0.1, "{c} at 8 texels");
    }
    assert!(num(case("pole", "0.25"), "cv_under_jitter") > 0.5);
    assert_eq!(case("pole", "0.25")["verdict"], "fails");
    let coplanar = st.iter().find(|r| r["case"].starts_with("coplanar A")).unwrap();
    assert!(num(coplanar, "cv_under_jitter") < 0.1, "the tie rule keeps coplanar faces steady");

    if gpu {
        // Accuracy: under each LOD rule η = 0 is at least as faithful as η = 8e-3 (the thesis's
        // within 0.25 dB) and draws at least as many faces; the default screen-error levels beat
        // the thesis's eq. 5.6 levels; a larger pixel bound never draws more.
        let acc = rows(&out, "accuracy");
        let row = |rule: &str, p: &str| acc.iter().find(|r| r["rule"] == rule && r["parameter"] == p).unwrap();
        let psnr = |rule: &str, p: &str| row(rule, p)["psnr_db"].parse::<f64>().unwrap_or(f64::INFINITY);
        // The thesis's levels are not monotone in PSNR: where eq. 5.6 puts barely visible
        // objects at very coarse levels, a subtree's internal LOD can look a little better
        // (23.50 against 23.57 dB on the small city built with region rays).
        for (rule, slack) in [("η, screen 0.5 px (default)", 0.0), ("η, eq. 5.6 (thesis)", 0.25)] {
            assert!(psnr(rule, "0") >= psnr(rule, "0.008") - slack, "{rule}");
            assert!(num(row(rule, "0"), "faces") >= num(row(rule, "0.008"), "faces"), "{rule}");
        }
        assert!(psnr("η, screen 0.5 px (default)", "0.001") > psnr("η, eq. 5.6 (thesis)", "0.001"));
        let px = "screen px at the default η";
        assert!(num(row(px, "0.25"), "faces") >= num(row(px, "1"), "faces"));
        assert!(num(row(px, "1"), "faces") >= num(row(px, "8"), "faces"));
    }
}
