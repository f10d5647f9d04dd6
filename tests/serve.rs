//! `hdov serve` as a client sees it, over real sockets to the real binary: the routes answer what
//! the library answers; meshes are immutable glb with ETags and 304s; malformed, huge and hostile
//! requests each get their status and a one-line reason while the server keeps answering; SIGTERM
//! ends it cleanly; and the viewer page draws the answer in a real browser (Debian's chromium,
//! headless, software WebGL), when one is installed.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use hdov::{Database, QueryParams};
use serde_json::Value;

fn tiny_city(dir: &Path) -> std::path::PathBuf {
    hdov_testkit::scenes::tiny_city_database(dir).1
}

/// A running `hdov serve`, stopped (SIGTERM) when dropped.
struct Server {
    child: Child,
    addr: SocketAddr,
}

impl Server {
    fn start(db: &Path, extra: &[&str]) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_hdov"))
            .args(["serve", db.to_str().unwrap(), "--addr", "127.0.0.1:0"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap()).read_line(&mut line).unwrap();
        // "hdov serve: http://127.0.0.1:PORT/ (DB)"
        let url = line.split_whitespace().nth(2).unwrap_or_else(|| panic!("no URL in '{line}'"));
        let addr = url.trim_start_matches("http://").trim_end_matches('/').parse().unwrap();
        Server { child, addr }
    }

    fn terminate(&mut self) -> std::process::ExitStatus {
        // SAFETY: signalling our own child process.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        for _ in 0..100 {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        self.child.kill().unwrap();
        panic!("the server did not stop within 5 s of SIGTERM");
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.terminate();
        }
    }
}

/// One HTTP/1.1 response.
struct Response {
    status: u16,
    headers: HashMap<String, String>,
    body: Vec<u8>,
}

impl Response {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("{}: not JSON ({e}): {}", self.status, String::from_utf8_lossy(&self.body)))
    }
    fn error(&self) -> String {
        self.json()["error"].as_str().unwrap().to_string()
    }
}

fn parse(raw: &[u8]) -> Response {
    let split = raw.windows(4).position(|w| w == b"\r\n\r\n").expect("a whole response head");
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines.next().unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    Response { status, headers, body: raw[split + 4..].to_vec() }
}

/// Sends `request` (a whole HTTP request, or anything) and reads the reply to its end.
fn send(addr: SocketAddr, request: &[u8]) -> Response {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    // A huge request may be cut off by the server's answer; what matters is that answer.
    let _ = s.write_all(request);
    let mut raw = Vec::new();
    let _ = s.read_to_end(&mut raw);
    parse(&raw)
}

fn get_with(addr: SocketAddr, target: &str, headers: &str) -> Response {
    send(addr, format!("GET {target} HTTP/1.1\r\nHost: hdov\r\nConnection: close\r\n{headers}\r\n").as_bytes())
}

fn get(addr: SocketAddr, target: &str) -> Response {
    get_with(addr, target, "")
}

#[test]
fn routes_answer_what_the_library_answers() {
    let tmp = tempfile::tempdir().unwrap();
    let db_dir = tiny_city(tmp.path());
    let db = Database::open(&db_dir).unwrap();
    let server = Server::start(&db_dir, &[]);
    let addr = server.addr;

    let info = get(addr, "/info");
    assert_eq!(info.status, 200);
    assert_eq!(info.json()["objects"].as_u64().unwrap(), db.info().unwrap().objects);

    // /query is Database::query, each item with its mesh URL and (objects) its transform.
    let at = db.grid().unwrap().cell_centres()[4];
    let r = get(addr, &format!("/query?at={},{},{}&eta=0.001", at.x, at.y, at.z));
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let answer = r.json();
    let direct = db.query(at, &QueryParams { eta: 0.001, ..Default::default() }).unwrap();
    // The same JSON as `hdov query --json` writes, less the timing, plus what draws each item.
    let mut same = answer.clone();
    // (Through text, as `--json` writes it: to_value would widen each f32 to its f64 digits.)
    let mut library: Value = serde_json::from_str(&serde_json::to_string(&direct).unwrap()).unwrap();
    for v in [&mut same, &mut library] {
        v["stats"]["micros"] = 0.into();
        for i in v["items"].as_array_mut().unwrap() {
            let i = i.as_object_mut().unwrap();
            i.remove("mesh");
            i.remove("transform");
        }
    }
    assert_eq!(same, library);
    let items = answer["items"].as_array().unwrap();
    assert_eq!(items.len(), direct.items.len());
    assert!(items.len() > 5);
    for (j, i) in items.iter().zip(&direct.items) {
        assert_eq!(j["name"].as_str().unwrap(), &*i.name);
        assert_eq!(j["lod"].as_u64().unwrap(), u64::from(i.lod));
        assert_eq!(j["transform"].is_null(), i.kind == hdov::ItemKind::Node);
    }

    // A mesh: glb bytes of the item's level, immutable, with a strong ETag and 304 on a match.
    let item = &direct.items[0];
    let url = items[0]["mesh"].as_str().unwrap();
    let m = get(addr, url);
    assert_eq!(m.status, 200);
    assert_eq!(m.headers["content-type"], "model/gltf-binary");
    assert!(m.headers["cache-control"].contains("immutable"));
    let etag = m.headers["etag"].clone();
    assert!(etag.starts_with('"') && etag.ends_with('"'), "a strong ETag: {etag}");
    let glb = tmp.path().join("mesh.glb");
    std::fs::write(&glb, &m.body).unwrap();
    let (mesh, _) = hdov::Scene::load(&glb).unwrap();
    assert_eq!(mesh.triangle_count(), u64::from(item.faces));
    let again = get_with(addr, url, &format!("If-None-Match: {etag}\r\n"));
    assert_eq!(again.status, 304);
    assert!(again.body.is_empty());
    assert_eq!(get_with(addr, url, "If-None-Match: \"other\"\r\n").status, 200);

    // Every mesh URL /query hands out is served, and instances share one URL.
    let mut urls: Vec<&str> = items.iter().map(|j| j["mesh"].as_str().unwrap()).collect();
    urls.sort_unstable();
    urls.dedup();
    for u in &urls {
        assert_eq!(get_with(addr, u, "").status, 200, "{u}");
    }
    // The full scene: every object at full detail.
    let scene = get(addr, "/scene").json();
    assert_eq!(scene["items"].as_array().unwrap().len() as u64, db.info().unwrap().objects);
    assert!(scene["items"].as_array().unwrap().iter().all(|i| i["lod"] == 0 && i["mesh"].is_string()));
    let walk = get(addr, "/recorded-walk?kind=turning&steps=20").json();
    assert_eq!(walk["steps"].as_array().unwrap().len(), 20);

    // /walk: a session over a path; applying each step's loads and drops holds exactly the
    // answer a library session holds at that step.
    let centres = db.grid().unwrap().cell_centres();
    let path = [centres[0], centres[0] + glam::Vec3::new(0.5, 0.0, 0.0), centres[1], centres[5], centres[0]];
    let text: Vec<String> = path.iter().map(|p| format!("{},{},{}", p.x, p.y, p.z)).collect();
    let served = get(addr, &format!("/walk?path={}", text.join(";")));
    assert_eq!(served.status, 200, "{}", String::from_utf8_lossy(&served.body));
    let served = served.json();
    let steps = served["steps"].as_array().unwrap();
    assert_eq!(steps.len(), path.len());
    let mut session = db.session(&hdov::SessionParams::default()).unwrap();
    let mut held: std::collections::BTreeSet<(String, u64, u64)> = Default::default();
    let key = |v: &Value| (v[0].as_str().unwrap().to_string(), v[1].as_u64().unwrap(), v[2].as_u64().unwrap());
    for (k, (step, at)) in steps.iter().zip(path).enumerate() {
        session.step(at, None).unwrap();
        for d in step["drop"].as_array().unwrap() {
            assert!(held.remove(&key(d)), "step {k}: drops what it does not hold");
        }
        for l in step["load"].as_array().unwrap() {
            assert!(l["mesh"].is_string());
            let item = (l["kind"].as_str().unwrap().to_string(), l["id"].as_u64().unwrap(), l["lod"].as_u64().unwrap());
            assert!(held.insert(item), "step {k}: loads what it holds");
        }
        let want: std::collections::BTreeSet<_> = session
            .answer()
            .unwrap()
            .items
            .iter()
            .map(|i| {
                (
                    if i.kind == hdov::ItemKind::Node { "node" } else { "object" }.to_string(),
                    u64::from(i.id),
                    u64::from(i.lod),
                )
            })
            .collect();
        assert_eq!(held, want, "step {k}");
    }
    assert_eq!(steps[1]["flipped"], false, "a step inside the same cell asks nothing");
    assert!(steps[1]["load"].as_array().unwrap().is_empty() && steps[1]["drop"].as_array().unwrap().is_empty());
    assert_eq!(
        get(addr, "/walk?path=1,2;3,4,5").error(),
        "path: step 0: expected 3 comma-separated numbers for a point X,Y,Z, got 2 in '1,2'"
    );

    // /tiles/ serves what `hdov export --3dtiles` writes, byte for byte, and nothing else.
    let exported = tmp.path().join("tiles");
    hdov::tiles::write_tileset(&db, &exported, None, &hdov::Progress::hidden()).unwrap();
    let first = |folder: &str| {
        let mut names: Vec<String> = std::fs::read_dir(exported.join(folder))
            .unwrap()
            .map(|e| format!("{folder}/{}", e.unwrap().file_name().to_string_lossy()))
            .collect();
        names.sort();
        names.swap_remove(0)
    };
    let (subtree, content) = (first("subtrees"), first("content"));
    for file in
        ["tileset.json".to_string(), "visibility/index.json".into(), subtree, content, hdov::tiles::cell_file(3)]
    {
        let r = get(addr, &format!("/tiles/{file}"));
        assert_eq!(r.status, 200, "{file}");
        assert_eq!(r.body, std::fs::read(exported.join(&file)).unwrap(), "{file}");
    }
    let cells = db.grid().unwrap().cell_count();
    for wrong in [
        "/tiles/content/n0-99-0.glb",
        "/tiles/subtrees/n0.json",
        "/tiles/visibility/cells/03.bin",
        "/tiles/../manifest.json",
    ] {
        assert_eq!(get(addr, wrong).status, 404, "{wrong}");
    }
    assert_eq!(get(addr, &format!("/tiles/visibility/cells/{cells}.bin")).status, 404);
}

#[test]
fn bad_and_hostile_requests_get_their_status_and_the_server_keeps_answering() {
    let tmp = tempfile::tempdir().unwrap();
    let db_dir = tiny_city(tmp.path());
    let mut server = Server::start(&db_dir, &["--concurrency", "8"]);
    let addr = server.addr;
    let db = Database::open(&db_dir).unwrap();
    let c = db.grid().unwrap().cell_centres()[0];
    let at = format!("{},{},{}", c.x, c.y, c.z);
    let good = get(addr, &format!("/query?at={at}"));
    assert_eq!(good.status, 200);
    let mesh = good.json()["items"][0]["mesh"].as_str().unwrap().to_string();
    let (offset, crc) = mesh.trim_start_matches("/mesh/").trim_end_matches(".glb").split_once('-').unwrap();

    let cases: Vec<(String, u16, &str)> = vec![
        ("/query?at=1,nan,3".into(), 400, "at: "),
        ("/query?at=1,inf,3".into(), 400, "non-finite"),
        ("/query?at=1e9,1.7,3".into(), 400, "outside the grid"),
        ("/query?at=1,2".into(), 400, "3 comma-separated"),
        ("/query".into(), 400, "at: missing"),
        (format!("/query?at={at}&eta=2"), 400, "eta: 2 is not in [0, 1]"),
        (format!("/query?at={at}&eta=NaN"), 400, "eta:"),
        (format!("/query?at={at}&mode=fastest"), 400, "unknown mode"),
        (format!("/query?at={at}&look=0,0,0"), 400, "look:"),
        (format!("/query?at={at}&look=1,0,0&fov=400"), 400, "look:"),
        (format!("/query?at={at}&tau=-1"), 400, "tau:"),
        (format!("/query?at={at}&budget=-5"), 400, "budget:"),
        (format!("/query?at={at}&layout=../../etc"), 400, "layout:"),
        (format!("/query?at={at}&at={at}"), 400, "given twice"),
        (format!("/query?at={at}&path=/etc/passwd"), 400, "unknown parameter 'path'"),
        ("/query?at=%ZZ".into(), 400, "at:"),
        ("/recorded-walk?steps=100000000".into(), 400, "steps:"),
        ("/recorded-walk?kind=sideways".into(), 400, "kind:"),
        ("/scene?lod=x".into(), 400, "lod:"),
        ("/mesh/999999999-00000000.glb".into(), 404, "no stored LOD"),
        (format!("/mesh/{offset}-{:08x}.glb", u32::from_str_radix(crc, 16).unwrap() ^ 1), 404, "no stored LOD"),
        (format!("/mesh/0{offset}-{crc}.glb"), 404, "no stored LOD"),
        (format!("/mesh/{offset}-{crc}.obj"), 404, "no stored LOD"),
        ("/mesh/..%2F..%2Fmanifest.json".into(), 404, "no stored LOD"),
        ("/mesh/%2e%2e%2fgeometry.blob".into(), 404, "no stored LOD"),
        ("/../manifest.json".into(), 404, "no such route"),
        ("/geometry.blob".into(), 404, "no such route"),
        (format!("/query?at={at}&x={}", "a".repeat(5000)), 414, "request target"),
    ];
    for (target, status, reason) in &cases {
        let r = get(addr, target);
        assert_eq!(r.status, *status, "{target}: {}", String::from_utf8_lossy(&r.body));
        let e = r.error();
        assert!(e.contains(reason) && !e.contains('\n'), "{target}: '{e}' lacks '{reason}'");
    }
    // Writes are refused.
    for method in ["POST", "PUT", "DELETE", "PATCH"] {
        let r = send(
            addr,
            format!("{method} /query HTTP/1.1\r\nHost: h\r\nContent-Length: 2\r\nConnection: close\r\n\r\n{{}}")
                .as_bytes(),
        );
        assert_eq!(r.status, 405, "{method}");
    }
    // A 10 MB query string and 1 MB of headers: refused before anything reads them.
    let huge =
        format!("GET /query?at={at}&x={} HTTP/1.1\r\nHost: h\r\nConnection: close\r\n\r\n", "a".repeat(10 << 20));
    assert!([414, 431, 400].contains(&send(addr, huge.as_bytes()).status));
    let fat = format!("GET /info HTTP/1.1\r\nHost: h\r\nX-Fat: {}\r\nConnection: close\r\n\r\n", "b".repeat(1 << 20));
    assert!([431, 400].contains(&send(addr, fat.as_bytes()).status));
    // Not HTTP at all.
    let junk = {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let _ = s.write_all(b"\x00\x01\x02 hello\r\n\r\n");
        let mut raw = Vec::new();
        let _ = s.read_to_end(&mut raw);
        raw
    };
    assert!(junk.is_empty() || junk.starts_with(b"HTTP/1.1 400"), "{}", String::from_utf8_lossy(&junk));

    // The same bad input gets the same reason from the command line.
    let cli = Command::new(env!("CARGO_BIN_EXE_hdov"))
        .args(["query", db_dir.to_str().unwrap(), "--at", "1e9,1.7,3"])
        .output()
        .unwrap();
    let served = get(addr, "/query?at=1e9,1.7,3").error();
    let reason = served.strip_prefix("at: ").unwrap();
    assert!(String::from_utf8_lossy(&cli.stderr).contains(reason), "{reason}");

    // 1,000 connections at once, each asking a query: every one is answered 200 (eight at a
    // time; the rest wait their turn).
    let request = format!("GET /query?at={at} HTTP/1.1\r\nHost: h\r\nConnection: close\r\n\r\n");
    let mut streams: Vec<TcpStream> = (0..1000).map(|_| TcpStream::connect(addr).unwrap()).collect();
    for s in &mut streams {
        s.write_all(request.as_bytes()).unwrap();
    }
    let statuses: Vec<u16> = streams
        .into_iter()
        .map(|mut s| {
            s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
            let mut raw = Vec::new();
            s.read_to_end(&mut raw).unwrap();
            parse(&raw).status
        })
        .collect();
    assert!(statuses.iter().all(|&s| s == 200), "{:?}", statuses.iter().filter(|&&s| s != 200).collect::<Vec<_>>());
    // Still answering, and SIGTERM ends it cleanly.
    assert_eq!(get(addr, "/info").status, 200);
    let status = server.terminate();
    assert!(status.success(), "{status:?}");
    let mut out = String::new();
    server.child.stdout.take().unwrap().read_to_string(&mut out).unwrap();
    assert!(out.contains("stopped"), "{out}");
}

/// The tiny city built in `dir`, opened and served, and the centre of its middle cell.
fn served_tiny_city(dir: &Path) -> (Database, Server, glam::Vec3) {
    let db_dir = tiny_city(dir);
    let db = Database::open(&db_dir).unwrap();
    let server = Server::start(&db_dir, &[]);
    let grid = db.grid().unwrap();
    let centre = grid.cell_centres()[grid.cell_id([grid.dims[0] / 2, 0, grid.dims[2] / 2])];
    (db, server, centre)
}

/// The renderer's background, which the viewer clears to as well.
const SKY: [u8; 3] = hdov::render::BACKGROUND;

/// The viewer in a real browser: Debian's chromium, headless, with software WebGL (SwiftShader).
/// At a fixed viewpoint and look it asks /query, loads the meshes the answer names and draws
/// them: the page's overlay counts the answer's items, its screenshot covers what `hdov render`
/// covers for the same view and answer, and a recorded walk of 30 steps completes without an
/// error on the page or in the console.
#[test]
fn the_viewer_draws_the_answer_in_a_real_browser() {
    let Some(chromium) = hdov_testkit::browser::chromium_or_skip() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (db, server, c) = served_tiny_city(tmp.path());
    let look = glam::Vec3::new(1.0, -0.05, 0.3);
    let answer = db.query(c, &QueryParams::default()).unwrap();
    let page = |extra: &str| {
        format!("http://{}/?at={},{},{}&look={},{},{}{extra}", server.addr, c.x, c.y, c.z, look.x, look.y, look.z)
    };
    let browse = |what: &str, url: &str| hdov_testkit::browser::browse(chromium, what, url, [800, 600], 20000);
    let dom = browse("--dump-dom", &page(""));
    assert!(dom.contains("data-state=\"ready\""), "the viewer never got ready:\n{dom}");
    assert!(dom.contains(&format!("items    {}", answer.items.len())), "overlay:\n{dom}");
    assert!(dom.contains("<div id=\"error\"></div>"), "{dom}");

    // The screenshot, without the overlay.
    let shot = tmp.path().join("viewer.png");
    browse(&format!("--screenshot={}", shot.display()), &page("&hud=0"));
    if let Ok(keep) = std::env::var("HDOV_VIEWER_SCREENSHOT") {
        browse(&format!("--screenshot={keep}"), &page("&colour=dov"));
    }
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&shot).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut pixels).unwrap();
    let (w, h, channels) = (frame.width, frame.height, frame.color_type.samples());
    let rgb = |x: u32, y: u32| {
        let at = y as usize * frame.line_size + x as usize * channels;
        [pixels[at], pixels[at + 1], pixels[at + 2]]
    };
    let covered = |p: [u8; 3]| p.iter().zip(SKY).any(|(&a, b)| a.abs_diff(b) > 12);
    let drawn: Vec<[u8; 3]> =
        (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| rgb(x, y)).filter(|&p| covered(p)).collect();
    let share = drawn.len() as f64 / f64::from(w * h);
    assert!(share > 0.05, "only {:.1} % of the view is drawn", share * 100.0);
    let shades: std::collections::HashSet<[u8; 3]> = drawn.iter().copied().collect();
    assert!(shades.len() > 20, "{} shades: lit and shaded faces, not one flat block", shades.len());

    // The same view and answer through hdov's renderer: the same pixels are covered.
    if hdov_testkit::gpu::adapter_or_skip() {
        let renderer = hdov::render::Renderer::new().unwrap();
        let view = hdov::render::View::new(c, look, 60.0, w, h);
        let image = renderer.render_answer(&db, &answer, &view, hdov::render::ColorMode::Shaded).unwrap();
        let differ = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| image.covered(x, y) != covered(rgb(x, y)))
            .count();
        let share = differ as f64 / f64::from(w * h);
        println!("coverage differs from hdov render on {:.3} % of the pixels", share * 100.0);
        assert!(share <= 0.02, "coverage differs from hdov render on {:.2} % of the pixels", share * 100.0);
    }

    // A recorded walk of 30 steps completes, every step's answer loaded, with no error.
    let walk = format!("http://{}/?walk=turning&steps=30", server.addr);
    let dom = browse("--dump-dom", &walk);
    assert!(dom.contains("data-walk=\"done\""), "the walk did not finish:\n{dom}");
    assert!(dom.contains("walk done, 30 steps") && dom.contains("<div id=\"error\"></div>"), "{dom}");
}

/// The 3D Tiles page in a real browser, 3DTilesRendererJS with and without hdov's visibility
/// plugin, at three viewpoints of the tiny city, refining to one pixel of error (so that what is
/// hidden but in the frustum is wanted): with the plugin it finds the cell the library locates,
/// and every tile it requests is one the cell may see and not below a stop of the cell; without
/// it, tiles the cell cannot see are requested.
#[test]
fn the_tiles_plugin_never_requests_what_the_cell_cannot_see() {
    let Some(chromium) = hdov_testkit::browser::chromium_or_skip() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let db_dir = tiny_city(tmp.path());
    let db = Database::open(&db_dir).unwrap();
    let server = Server::start(&db_dir, &[]);
    let set = hdov_testkit::tiles::resolved(&get(server.addr, "/tiles/tileset.json").json(), &mut |p| {
        get(server.addr, &format!("/tiles/{p}")).json()
    });
    let nodes = u64::from(db.node_count());
    let grid = db.grid().unwrap();
    let (mut fewer, mut hidden) = (0, 0);
    for (k, cell) in [[1, 0, 1], [grid.dims[0] / 2, 0, grid.dims[2] / 2], [grid.dims[0] - 2, 0, grid.dims[2] - 1]]
        .into_iter()
        .enumerate()
    {
        let at = grid.cell_centres()[grid.cell_id(cell)];
        let look = [glam::Vec3::X, glam::Vec3::new(-0.3, -0.05, 1.0), glam::Vec3::new(-1.0, 0.0, -1.0)][k];
        let run = |plugin: u32| {
            let url = format!(
                "http://{}/tiles.html?frames=timer&errorTarget=1&plugin={plugin}&at={},{},{}&look={},{},{}",
                server.addr, at.x, at.y, at.z, look.x, look.y, look.z
            );
            let dom = hdov_testkit::browser::browse(chromium, "--dump-dom", &url, [800, 600], 120_000);
            hdov_testkit::browser::page_result(&dom).unwrap_or_else(|e| panic!("{url}: {e}"))
        };
        let with = run(1);
        let (_, id) = db.locate(at).unwrap();
        assert_eq!(with["steps"][0]["cell"], id, "the plugin's cell");
        let file = hdov::tiles::decode_cell(&get(server.addr, &format!("/tiles/{}", hdov::tiles::cell_file(id))).body)
            .unwrap();
        let seen: HashMap<u64, u16> = file.entries.iter().copied().collect();
        let stops: HashMap<u64, u32> = file.stops.iter().copied().collect();
        // Content a tile of the cell may draw: seen, and under no stop of the cell.
        let mut allowed = std::collections::HashSet::new();
        let mut stack = vec![(&set["root"], false)];
        while let Some((tile, under_stop)) = stack.pop() {
            let h = &tile["extras"]["hdov"];
            let key = h["node"].as_u64().unwrap_or_else(|| nodes + h["object"].as_u64().unwrap());
            // A slice of a node's level is the cell's where it sees one of its entries.
            let visible = match h["entries"].as_array() {
                Some(entries) => entries.iter().any(|k| seen.contains_key(&k.as_u64().unwrap())),
                None => seen.contains_key(&key),
            };
            if !visible || under_stop {
                continue;
            }
            if let Some(uri) = tile["content"]["uri"].as_str() {
                allowed.insert(format!("/tiles/{uri}"));
            }
            let stop = h["level"].as_u64().is_some_and(|l| stops.get(&key).is_some_and(|&s| l <= u64::from(s)));
            for c in tile["children"].as_array().into_iter().flatten() {
                stack.push((c, stop));
            }
        }
        let requested: Vec<String> = serde_json::from_value(with["requested"].clone()).unwrap();
        let content: Vec<&String> = requested.iter().filter(|u| u.contains("/content/")).collect();
        assert!(!content.is_empty(), "cell {id}: nothing drawn");
        for u in &content {
            assert!(allowed.contains(*u), "cell {id}: {u} requested, which the cell cannot see or stops above");
        }
        // Without the plugin the renderer requests tiles the cell cannot see: the viewpoint tests
        // something.
        let without: Vec<String> = serde_json::from_value(run(0)["requested"].clone()).unwrap();
        hidden += without.iter().filter(|u| u.contains("/content/") && !allowed.contains(*u)).count();
        fewer += usize::from(without.len() > requested.len());
    }
    assert!(hidden > 0, "no viewpoint had a hidden tile in view");
    assert!(fewer >= 2, "the plugin saves requests at {fewer} of 3 viewpoints");
}

/// The viewer draws through the plugin: `/?draw=tiles` (what its "draw" menu does) hands the walk,
/// where it stands, to the 3D Tiles page with hdov's plugin, which finds the cell the library
/// locates and draws tiles there; the 3D Tiles page offers the way back, and `draw=tiles-alone`
/// draws without the plugin.
#[test]
fn the_viewer_hands_its_walk_to_the_tiles_plugin() {
    let Some(chromium) = hdov_testkit::browser::chromium_or_skip() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (db, server, at) = served_tiny_city(tmp.path());
    let (_, id) = db.locate(at).unwrap();
    for (how, plugin) in [("tiles", true), ("tiles-alone", false)] {
        let url = format!("http://{}/?draw={how}&frames=timer&at={},{},{}&look=1,0,0.3", server.addr, at.x, at.y, at.z);
        let dom = hdov_testkit::browser::browse(chromium, "--dump-dom", &url, [800, 600], 120_000);
        let result = hdov_testkit::browser::page_result(&dom).unwrap_or_else(|e| panic!("{url}: {e}"));
        assert_eq!(result["plugin"], plugin, "{how}");
        assert!(result["steps"][0]["requests"].as_u64().unwrap() > 0, "{how}: nothing loaded");
        if plugin {
            assert_eq!(result["steps"][0]["cell"], id, "the plugin's cell");
        }
        assert!(dom.contains("<option value=\"query\">"), "{how}: no way back to the viewer's answers");
    }
}
