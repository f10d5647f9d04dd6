//! `hdov serve`: one database, opened once and shared read-only by every request, over HTTP (axum
//! on tokio), with the viewer page at `/`.
//!
//! Routes: `/info`, `/query?at=…`, `/walk?path=…` (a session over a path: per step, what to load
//! and what to drop), `/mesh/{offset}-{crc}.glb` (one stored LOD level, immutable: the URL names
//! the record and its checksum), `/scene` (every object at full detail, the viewer's "full
//! scene"), `/recorded-walk?kind=…`, `/tiles/…` (the database as a 3D Tiles tileset with each
//! cell's visibility: the files `hdov export --3dtiles` writes) and the viewer's files. Safe by default: loopback unless
//! `--addr` says otherwise, GET only, nothing writes, parameters and URLs bounded, mesh references
//! checked against the catalog (no part of a request reaches the filesystem), a concurrency limit
//! and a per-request timeout. A client's mistake is a 400 or 404 with `{"error": …}` in the
//! command's words; only the database itself failing is a 500.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use axum::Router;
use axum::extract::{Path, RawQuery, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use clap::Args;
use serde::Serialize;
use serde_json::json;

use hdov::city::WalkKind;
use hdov::text::{QUERY_KEYS, UrlQuery, WALK_KEYS, quoted, url_key};
use hdov::{Database, Error, Item, LodRef, Mode};

/// Longest request target (path and query) served; a query needs under 200 bytes.
const MAX_TARGET: usize = 2048;
/// Most steps of a recorded walk.
const MAX_WALK_STEPS: u32 = 10_000;

#[derive(Args)]
pub struct ServeCmd {
    /// The database directory.
    db: PathBuf,
    /// Address to listen on: loopback unless you say otherwise (port 0 picks a free port).
    #[arg(long, default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
    /// Requests served at once; more wait for a turn.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=4096))]
    concurrency: u32,
    /// Seconds a request may take before it is answered 408.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=3600))]
    timeout: u64,
}

/// What every request shares: the database and the set of stored levels a URL may name.
struct Served {
    db: Database,
    /// Record offset → the stored level.
    lods: HashMap<u64, ServedLod>,
    /// The database as a 3D Tiles tileset under `/tiles/`: the files `hdov export --3dtiles`
    /// writes, byte for byte. Made on the first request for it (it reads every node page and
    /// decodes every base mesh), not at start.
    tiles: OnceLock<Result<ServedTiles, String>>,
}

/// The tileset as `/tiles/` serves it.
struct ServedTiles {
    set: hdov::tiles::Tileset,
    /// `tileset.json` and the visibility index, serialised once.
    tileset_json: Vec<u8>,
    index_json: Option<Vec<u8>>,
}

impl Served {
    /// The tileset, made on first use; a database that fails to give one is a 500.
    fn tiles(&self) -> Result<&ServedTiles, Reply> {
        let made = self.tiles.get_or_init(|| {
            let set = hdov::tiles::tileset(&self.db, None).map_err(|e| e.to_string())?;
            Ok(ServedTiles { tileset_json: set.tileset_bytes(), index_json: set.index_bytes(), set })
        });
        made.as_ref().map_err(|e| Reply::Status(StatusCode::INTERNAL_SERVER_ERROR, e.clone()))
    }
}

/// A stored level as the routes name it: written once at start, not per item of every answer.
struct ServedLod {
    lod: LodRef,
    /// The record's stored crc32.
    crc: u32,
    /// `/mesh/{offset}-{crc}.glb`.
    url: String,
}

pub fn serve(a: ServeCmd) -> hdov::Result<()> {
    let db = Database::open(&a.db)?;
    if db.grid().is_none() {
        return Err(Error::bad_file(&a.db, "holds no viewing grid; nothing to serve queries from"));
    }
    let mut lods = HashMap::new();
    for r in db.lod_refs() {
        let crc = db.lod_checksum(r)?;
        lods.insert(r.offset, ServedLod { lod: *r, crc, url: format!("/mesh/{}-{crc:08x}.glb", r.offset) });
    }
    let served = Arc::new(Served { db, lods, tiles: OnceLock::new() });
    // Database work is CPU-bound and short: threads beyond the cores only add memory (a heap
    // arena each) and switches; requests past them wait in the concurrency limit's queue.
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .max_blocking_threads(2 * cores)
        .enable_all()
        .build()
        .map_err(|e| Error::io("the server's runtime", e))?;
    runtime.block_on(async move {
        let listener =
            tokio::net::TcpListener::bind(a.addr).await.map_err(|e| Error::io(format!("--addr {}", a.addr), e))?;
        let addr = listener.local_addr().map_err(|e| Error::io(format!("--addr {}", a.addr), e))?;
        if !addr.ip().is_loopback() {
            eprintln!("warning: listening on {addr}, reachable from other machines (read-only)");
        }
        println!("hdov serve: http://{addr}/ ({})", a.db.display());
        let app = router(served, a.concurrency as usize, Duration::from_secs(a.timeout));
        axum::serve(listener, app)
            .with_graceful_shutdown(stop_signal())
            .await
            .map_err(|e| Error::io("the server", e))?;
        println!("hdov serve: stopped");
        Ok(())
    })
}

/// SIGINT (Ctrl-C) or SIGTERM: stop accepting, finish what is in flight, exit 0.
async fn stop_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .expect("a SIGTERM handler can be installed");
        tokio::select! {
            _ = interrupt => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = interrupt.await;
}

fn router(served: Arc<Served>, concurrency: usize, timeout: Duration) -> Router {
    use tower_http::limit::RequestBodyLimitLayer;
    use tower_http::timeout::TimeoutLayer;
    Router::new()
        .route("/", get(|| asset("text/html; charset=utf-8", include_bytes!("viewer/index.html"))))
        .route("/viewer.js", get(|| asset("text/javascript", include_bytes!("viewer/viewer.js"))))
        .route("/three.module.min.js", get(|| asset("text/javascript", include_bytes!("viewer/three.module.min.js"))))
        .route("/three.core.min.js", get(|| asset("text/javascript", include_bytes!("viewer/three.core.min.js"))))
        .route(
            "/three-LICENSE.txt",
            get(|| asset("text/plain; charset=utf-8", include_bytes!("viewer/three-LICENSE.txt"))),
        )
        .route("/stage.js", get(|| asset("text/javascript", include_bytes!("viewer/stage.js"))))
        .route("/controls.js", get(|| asset("text/javascript", include_bytes!("viewer/controls.js"))))
        .route("/tiles.html", get(|| asset("text/html; charset=utf-8", include_bytes!("viewer/tiles.html"))))
        .route("/tiles.js", get(|| asset("text/javascript", include_bytes!("viewer/tiles.js"))))
        .route("/hdov-tiles-plugin.js", get(|| asset("text/javascript", include_bytes!("viewer/hdov-tiles-plugin.js"))))
        .route(
            "/3d-tiles-renderer.min.js",
            get(|| asset("text/javascript", include_bytes!("viewer/3d-tiles-renderer.min.js"))),
        )
        .route(
            "/3d-tiles-renderer-LICENSE.txt",
            get(|| asset("text/plain; charset=utf-8", include_bytes!("viewer/3d-tiles-renderer-LICENSE.txt"))),
        )
        .route("/info", get(info))
        .route("/query", get(query))
        .route("/scene", get(scene))
        .route("/recorded-walk", get(recorded_walk))
        .route("/walk", get(walk))
        .route("/mesh/{name}", get(mesh))
        .route("/tiles/{*path}", get(tile_file))
        .fallback(|| async {
            Reply::NotFound("no such route (/, /info, /query, /scene, /recorded-walk, /mesh/…, /tiles/…)".into())
        })
        .layer(middleware::from_fn(only_small_gets))
        .layer(RequestBodyLimitLayer::new(1024))
        .layer(TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, timeout))
        .layer(tower::limit::ConcurrencyLimitLayer::new(concurrency))
        .with_state(served)
}

/// GET and HEAD only, with a bounded request target.
async fn only_small_gets(request: Request, next: Next) -> Response {
    if request.method() != Method::GET && request.method() != Method::HEAD {
        let mut r =
            Reply::Status(StatusCode::METHOD_NOT_ALLOWED, "read-only: GET and HEAD only".into()).into_response();
        r.headers_mut().insert(header::ALLOW, HeaderValue::from_static("GET, HEAD"));
        return r;
    }
    let target = request.uri().path_and_query().map_or(0, |p| p.as_str().len());
    if target > MAX_TARGET {
        return Reply::Status(
            StatusCode::URI_TOO_LONG,
            format!("the request target is {target} bytes; at most {MAX_TARGET} are served"),
        )
        .into_response();
    }
    next.run(request).await
}

async fn asset(content_type: &'static str, bytes: &'static [u8]) -> Response {
    ([(header::CONTENT_TYPE, content_type), (header::CACHE_CONTROL, "no-cache")], bytes).into_response()
}

/// An answer to a request that failed: its status and one line.
enum Reply {
    Bad(String),
    NotFound(String),
    Status(StatusCode, String),
}

impl IntoResponse for Reply {
    fn into_response(self) -> Response {
        let (status, error) = match self {
            Reply::Bad(e) => (StatusCode::BAD_REQUEST, e),
            Reply::NotFound(e) => (StatusCode::NOT_FOUND, e),
            Reply::Status(s, e) => (s, e),
        };
        (status, axum::Json(json!({ "error": error }))).into_response()
    }
}

/// The library's error as a reply: a bad parameter is the client's (named as the request names
/// it); anything else is the database's, a 500.
fn reply(e: Error) -> Reply {
    match e {
        Error::BadParam { param, reason } => Reply::Bad(format!("{}: {reason}", url_key(param))),
        e => Reply::Status(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// The request's query string as the route's `known` keys.
fn url_query(raw: Option<String>, known: &[&str]) -> Result<UrlQuery, Reply> {
    UrlQuery::parse(raw.as_deref().unwrap_or(""), known).map_err(Reply::Bad)
}

/// Runs the database work of a request off the async threads.
async fn blocking<T: Send + 'static>(
    served: Arc<Served>,
    work: impl FnOnce(&Served) -> Result<T, Reply> + Send + 'static,
) -> Result<T, Reply> {
    tokio::task::spawn_blocking(move || work(&served))
        .await
        .unwrap_or_else(|e| Err(Reply::Status(StatusCode::INTERNAL_SERVER_ERROR, format!("request failed: {e}"))))
}

async fn info(State(s): State<Arc<Served>>) -> Result<Response, Reply> {
    blocking(s, |s| Ok(json_response(&s.db.info().map_err(reply)?))).await
}

async fn query(State(s): State<Arc<Served>>, RawQuery(raw): RawQuery) -> Result<Response, Reply> {
    let q = url_query(raw, QUERY_KEYS)?;
    let at = q.point("at").map_err(Reply::Bad)?;
    let params = q.query_params().map_err(Reply::Bad)?;
    blocking(s, move |s| {
        let answer = s.db.query(at, &params).map_err(reply)?;
        let served = ServedAnswer {
            at: answer.at,
            cell: answer.cell,
            cell_id: answer.cell_id,
            mode: answer.mode,
            eta: answer.eta,
            layout: answer.layout.map(|k| k.to_string()),
            items: answer.items.iter().map(|i| ServedItem::of(s, i)).collect(),
            stats: answer.stats,
            warnings: &answer.warnings,
        };
        Ok(json_response(&served))
    })
    .await
}

/// [`hdov::Answer`] as `hdov query --json` writes it, each item with what a client needs to draw
/// it (the route's test checks that the keys stay the library's).
#[derive(Serialize)]
struct ServedAnswer<'a> {
    at: [f32; 3],
    cell: [u32; 3],
    cell_id: u32,
    mode: Mode,
    eta: f64,
    layout: Option<String>,
    items: Vec<ServedItem<'a>>,
    stats: hdov::QueryStats,
    warnings: &'a [String],
}

/// An item, the URL of its level and the matrix to draw it under (objects only: nodes' internal
/// LODs are stored in world space).
#[derive(Serialize)]
struct ServedItem<'a> {
    #[serde(flatten)]
    item: &'a Item,
    mesh: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    transform: Option<[f32; 16]>,
}

impl<'a> ServedItem<'a> {
    fn of(s: &'a Served, item: &'a Item) -> ServedItem<'a> {
        let m = s.db.item_transform(item);
        ServedItem {
            item,
            // Every item's level is a stored one (the catalog's, as the map is).
            mesh: s.lods.get(&item.lod_ref.offset).map_or("", |l| l.url.as_str()),
            transform: (m != glam::Mat4::IDENTITY).then(|| m.to_cols_array()),
        }
    }
}

/// `value` as a JSON response, serialised once and straight to text: an `f32` is written as
/// its shortest decimal, as `--json` writes it (a `serde_json::Value` would widen it to f64's
/// digits).
fn json_response(value: &impl Serialize) -> Response {
    // An answer of 150 items is about 55 KB: growing the buffer from empty copied it 4 times.
    let mut body = Vec::with_capacity(64 << 10);
    serde_json::to_writer(&mut body, value).expect("serialisable");
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn scene(State(s): State<Arc<Served>>, RawQuery(raw): RawQuery) -> Result<Response, Reply> {
    let q = url_query(raw, &["lod"])?;
    let lod = q.number::<u32>("lod", "a level").map_err(Reply::Bad)?.unwrap_or(0);
    blocking(s, move |s| {
        let items = hdov::scene_items(&s.db, lod).map_err(reply)?;
        let items: Vec<ServedItem> = items.iter().map(|i| ServedItem::of(s, i)).collect();
        Ok(json_response(&SceneItems { items }))
    })
    .await
}

/// `/scene`'s answer.
#[derive(Serialize)]
struct SceneItems<'a> {
    items: Vec<ServedItem<'a>>,
}

/// `/walk`'s answer.
#[derive(Serialize)]
struct Walk<'a> {
    steps: Vec<ServedStep<'a>>,
}

/// `/recorded-walk`'s answer: the walk's name and its viewpoints with their looks.
#[derive(Serialize)]
struct RecordedWalk {
    kind: &'static str,
    steps: Vec<RecordedStep>,
}

#[derive(Serialize)]
struct RecordedStep {
    at: [f32; 3],
    look: [f32; 3],
}

async fn recorded_walk(State(s): State<Arc<Served>>, RawQuery(raw): RawQuery) -> Result<Response, Reply> {
    let q = url_query(raw, &["kind", "steps"])?;
    let kind = q.value("kind", str::parse::<WalkKind>).map_err(Reply::Bad)?.unwrap_or(WalkKind::Turning);
    let steps = q.number::<u32>("steps", "a count").map_err(Reply::Bad)?.unwrap_or(300);
    if !(1..=MAX_WALK_STEPS).contains(&steps) {
        return Err(Reply::Bad(format!("steps: {steps} is outside 1..={MAX_WALK_STEPS}")));
    }
    let grid = s.db.grid().expect("checked at start");
    let path = hdov::city::walk(grid, kind, steps as usize);
    let steps = path.iter().map(|(at, look)| RecordedStep { at: at.to_array(), look: look.to_array() }).collect();
    Ok(json_response(&RecordedWalk { kind: kind.name(), steps }))
}

/// One step of a walk as a client needs it: what to load and what to drop since the last step.
#[derive(Serialize)]
struct ServedStep<'a> {
    #[serde(flatten)]
    step: &'a hdov::Step,
    load: Vec<ServedItem<'a>>,
    drop: Vec<(hdov::ItemKind, u32, u32)>,
}

/// `GET /walk?path=X,Y,Z;X,Y,Z;…`: a walkthrough session over the path (the library's
/// `Session`, its page cache and delta loading), answered step by step with the items to load
/// and the (kind, id, level) keys to drop, so that a client holds exactly the last answer.
async fn walk(State(s): State<Arc<Served>>, RawQuery(raw): RawQuery) -> Result<Response, Reply> {
    let q = url_query(raw, WALK_KEYS)?;
    let points = q.path().map_err(Reply::Bad)?;
    let params = hdov::SessionParams { query: q.query_params().map_err(Reply::Bad)?, ..Default::default() };
    blocking(s, move |s| {
        let mut session = s.db.session(&params).map_err(reply)?;
        let mut held: std::collections::HashSet<(hdov::ItemKind, u32, u32)> = Default::default();
        let mut steps = Vec::new();
        let mut answers = Vec::new();
        for at in points {
            let step = session.step(at, None).map_err(reply)?;
            let answer = session.answer().cloned().expect("a step leaves an answer");
            answers.push((step, answer));
        }
        for (step, answer) in &answers {
            let now: std::collections::HashSet<_> = answer.items.iter().map(Item::key).collect();
            let load = answer.items.iter().filter(|i| !held.contains(&i.key())).map(|i| ServedItem::of(s, i)).collect();
            let mut drop: Vec<_> = held.difference(&now).copied().collect();
            drop.sort_unstable();
            held = now;
            steps.push(ServedStep { step, load, drop });
        }
        Ok(json_response(&Walk { steps }))
    })
    .await
}

async fn mesh(State(s): State<Arc<Served>>, Path(name): Path<String>, headers: HeaderMap) -> Result<Response, Reply> {
    let unknown = || Reply::NotFound(format!("no stored LOD {} (mesh URLs come from /query)", quoted(&name)));
    // `{offset}-{crc}.glb`, byte for byte the URL /query writes for that level.
    let offset: u64 = name.split_once('-').and_then(|(o, _)| o.parse().ok()).ok_or_else(unknown)?;
    let served = s.lods.get(&offset).filter(|l| l.url.strip_prefix("/mesh/") == Some(&name)).ok_or_else(unknown)?;
    let (lod, stored) = (served.lod, served.crc);
    let etag = format!("\"{offset:x}-{stored:08x}\"");
    let cache = [(header::ETAG, etag.clone()), (header::CACHE_CONTROL, "public, max-age=31536000, immutable".into())];
    let matches = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"));
    if matches {
        return Ok((StatusCode::NOT_MODIFIED, cache).into_response());
    }
    let bytes = blocking(s, move |s| hdov::lod_glb(&s.db, &lod).map_err(reply)).await?;
    Ok((cache, [(header::CONTENT_TYPE, "model/gltf-binary")], bytes).into_response())
}

/// `/tiles/PATH`: the file PATH of the 3D Tiles export (`tileset.json`, `subtrees/…`, `content/…`,
/// `visibility/index.json`, `visibility/cells/{id}.bin`), made from the database as the export
/// makes it. Only names the tileset lists are served.
async fn tile_file(State(s): State<Arc<Served>>, Path(path): Path<String>) -> Result<Response, Reply> {
    blocking(s, move |s| {
        let t = s.tiles()?;
        let file = |kind: &'static str, bytes: Vec<u8>| ([(header::CONTENT_TYPE, kind)], bytes).into_response();
        if path == hdov::tiles::TILESET_FILE {
            return Ok(file("application/json", t.tileset_json.clone()));
        }
        if let Some(index) = t.index_json.as_ref().filter(|_| path == hdov::tiles::VISIBILITY_INDEX) {
            return Ok(file("application/json", index.clone()));
        }
        if let Some(sub) = t.set.subtrees.get(&path) {
            return Ok(file("application/json", sub.clone()));
        }
        if let Some(content) = t.set.contents.get(&path) {
            return Ok(file("model/gltf-binary", hdov::tiles::content_glb(&s.db, content).map_err(reply)?));
        }
        let cells = if t.index_json.is_some() { s.db.grid().map_or(0, |g| g.cell_count()) } else { 0 };
        let cell = path
            .strip_prefix("visibility/cells/")
            .and_then(|f| f.strip_suffix(".bin"))
            .and_then(|c| c.parse::<u32>().ok())
            .filter(|&c| (c as usize) < cells && path == hdov::tiles::cell_file(c))
            .ok_or_else(|| {
                Reply::NotFound(format!("no tileset file {} (names come from /tiles/tileset.json)", quoted(&path)))
            })?;
        Ok(file("application/octet-stream", hdov::tiles::cell_file_bytes(&s.db, cell).map_err(reply)?))
    })
    .await
}
