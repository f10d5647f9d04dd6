//! Loads `hdov serve` with concurrent clients over loopback and reports throughput, latency per
//! route, peak RSS and errors; every answer is checked against `Database::query` and every mesh
//! against `hdov::lod_glb` (outside the timed part of each request).
//!
//! ```sh
//! cargo run --release -p hdov-tools --bin serve-load -- DB [--clients 32] [--requests 20000] [--out OUT.csv] [--no-check] [--hdov PATH]
//! ```
//!
//! The checks (`Database::query` and `lod_glb` again, in the client) share the machine's cores
//! with the server; `--no-check` leaves them out to time the server alone.
//!
//! It starts `hdov serve DB --addr 127.0.0.1:0` itself (`--hdov`, default: the `hdov` beside this
//! program, `target/release/hdov`). Each client holds one
//! keep-alive connection and repeats: a point query at a random viewpoint of the grid (seeded),
//! then a fetch of one mesh the answer names. REQUESTS counts both (default 20,000 with 32
//! clients). RSS is the server's, read from /proc: idle after start-up, and its peak (VmHWM).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use clap::Parser;
use glam::Vec3;
use hdov::{Database, QueryParams};
use hdov_testkit::scenes::Rng;
use hdov_tools::experiments::quantile;

/// One keep-alive HTTP/1.1 connection.
struct Client {
    reader: BufReader<TcpStream>,
}

impl Client {
    fn connect(addr: SocketAddr) -> Client {
        let s = TcpStream::connect(addr).expect("connects");
        s.set_nodelay(true).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        Client { reader: BufReader::new(s) }
    }

    /// `(status, body)` of `GET target`.
    fn get(&mut self, target: &str) -> (u16, Vec<u8>) {
        write!(self.reader.get_mut(), "GET {target} HTTP/1.1\r\nHost: load\r\n\r\n").unwrap();
        let mut line = String::new();
        self.reader.read_line(&mut line).unwrap();
        let status: u16 = line.split_whitespace().nth(1).and_then(|s| s.parse().ok()).expect("a status line");
        let mut len = 0usize;
        loop {
            line.clear();
            self.reader.read_line(&mut line).unwrap();
            if line == "\r\n" {
                break;
            }
            if let Some((k, v)) = line.split_once(':')
                && k.eq_ignore_ascii_case("content-length")
            {
                len = v.trim().parse().unwrap();
            }
        }
        let mut body = vec![0; len];
        self.reader.read_exact(&mut body).unwrap();
        (status, body)
    }
}

/// The server's resident set: (current, peak) in kB.
fn rss(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// What the client reads of an answer: borrowed from the body, every other key skipped, so
/// that the client's own parsing takes as little of the cores it shares with the server as it
/// can (a `serde_json::Value` tree took 70 % of both cores, mostly in malloc).
#[derive(serde::Deserialize)]
struct AnswerItems<'a> {
    #[serde(borrow)]
    items: Vec<AnswerItem<'a>>,
}

#[derive(serde::Deserialize)]
struct AnswerItem<'a> {
    kind: &'a str,
    id: u32,
    lod: u32,
    /// f32 written as its shortest decimal: parsed back to the same f32.
    dov: f32,
    mesh: &'a str,
}

impl AnswerItem<'_> {
    /// What the checks compare: kind, id, level and DoV.
    fn key(&self) -> (&str, u32, u32, u32) {
        (self.kind, self.id, self.lod, self.dov.to_bits())
    }
}

#[derive(Parser)]
#[command(
    name = "serve-load",
    about = "Loads `hdov serve` with concurrent clients over loopback: throughput, latency per route, server RSS and \
             errors",
    long_about = "Loads `hdov serve` with concurrent clients over loopback and reports throughput, p50/p99/max latency\n\
                  per route (query, mesh), the server's idle and peak RSS, and errors. It starts `hdov serve DB --addr\n\
                  127.0.0.1:0` itself. Each client holds one keep-alive connection and repeats: a point query at a\n\
                  seeded random viewpoint of the grid, then a fetch of one mesh the answer names. Unless --no-check,\n\
                  every answer is checked against `Database::query` and every mesh against `hdov::lod_glb` (in the\n\
                  client, outside the timed part of each request). Exits with status 1 if any request failed.\n\
                  \n\
                  Makes: docs/serve.md, \"Under load\", and docs/data/serve-load.csv (`serve-load\n\
                  /tmp/demo-serve/city.hdov --clients 32 --requests 20000 --out docs/data/serve-load.csv`)."
)]
struct Args {
    /// The database to serve (a directory `hdov build` or `hdov demo` wrote), with a viewing grid.
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// Concurrent clients, each on one keep-alive connection.
    #[arg(long, value_name = "N", default_value_t = 32)]
    clients: usize,
    /// Requests in all, queries and mesh fetches both counted.
    #[arg(long, value_name = "N", default_value_t = 20_000)]
    requests: usize,
    /// Also write every request's latency as CSV (route,latency_ms) to this file.
    #[arg(long, value_name = "OUT.csv")]
    out: Option<String>,
    /// Leave out the checks against the library, to time the server alone (the checks share the cores with it).
    #[arg(long)]
    no_check: bool,
    /// The `hdov` program to start (default: the `hdov` beside this program, e.g. target/release/hdov).
    #[arg(long, value_name = "PATH")]
    hdov: Option<PathBuf>,
}

fn main() {
    let args = Args::parse();
    let db_dir = args.db;
    let (clients, requests) = (args.clients, args.requests);
    let out = args.out.as_ref();
    let check = !args.no_check;
    let db = Database::open(&db_dir).expect("opens");
    let grid = db.grid().cloned().expect("a grid");
    let hdov = args.hdov.unwrap_or_else(|| std::env::current_exe().unwrap().with_file_name("hdov"));
    let mut server = Command::new(&hdov)
        .args(["serve", db_dir.to_str().unwrap(), "--addr", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{}: {e} (cargo build --release first)", hdov.display()));
    let mut line = String::new();
    BufReader::new(server.stdout.as_mut().unwrap()).read_line(&mut line).unwrap();
    let addr: SocketAddr =
        line.split_whitespace().nth(2).unwrap().trim_start_matches("http://").trim_end_matches('/').parse().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let idle = rss(server.id()).0;

    let done = AtomicUsize::new(0);
    let errors = AtomicUsize::new(0);
    let start = Instant::now();
    let per_client: Vec<(Vec<f64>, Vec<f64>)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..clients)
            .map(|c| {
                let (db, grid, done, errors) = (&db, &grid, &done, &errors);
                s.spawn(move || {
                    let mut client = Client::connect(addr);
                    // A seeded stream per client, the same every run.
                    let mut rng = Rng(c as u64 + 1);
                    let (mut queries, mut meshes) = (Vec::new(), Vec::new());
                    while done.fetch_add(2, Ordering::Relaxed) < requests {
                        let r = grid.region;
                        let at = r.min + (r.max - r.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                        let t = Instant::now();
                        let (status, body) = client.get(&format!("/query?at={},{},{}", at.x, at.y, at.z));
                        queries.push(t.elapsed().as_secs_f64() * 1e3);
                        if status != 200 {
                            errors.fetch_add(1, Ordering::Relaxed);
                            continue;
                        }
                        let Ok(answer) = serde_json::from_slice::<AnswerItems>(&body) else {
                            errors.fetch_add(1, Ordering::Relaxed);
                            continue;
                        };
                        let items = &answer.items;
                        if !check {
                            if items.is_empty() {
                                continue;
                            }
                            let k = (rng.next_f32() * items.len() as f32) as usize % items.len();
                            let t = Instant::now();
                            let (status, _) = client.get(items[k].mesh);
                            meshes.push(t.elapsed().as_secs_f64() * 1e3);
                            if status != 200 {
                                errors.fetch_add(1, Ordering::Relaxed);
                            }
                            continue;
                        }
                        let expected = db.query(at, &QueryParams::default()).expect("the library answers");
                        let kind = |i: &hdov::Item| if i.kind == hdov::ItemKind::Node { "node" } else { "object" };
                        if !items
                            .iter()
                            .map(AnswerItem::key)
                            .eq(expected.items.iter().map(|i| (kind(i), i.id, i.lod, i.dov.to_bits())))
                        {
                            errors.fetch_add(1, Ordering::Relaxed);
                            continue;
                        }
                        let Some(k) = (!expected.items.is_empty())
                            .then(|| (rng.next_f32() * expected.items.len() as f32) as usize % expected.items.len())
                        else {
                            continue;
                        };
                        let t = Instant::now();
                        let (status, body) = client.get(items[k].mesh);
                        meshes.push(t.elapsed().as_secs_f64() * 1e3);
                        if status != 200 || body != hdov::lod_glb(db, &expected.items[k].lod_ref).unwrap() {
                            errors.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    (queries, meshes)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let wall = start.elapsed().as_secs_f64();
    let (_, peak) = rss(server.id());
    // SAFETY: signalling our own child process.
    unsafe { libc::kill(server.id() as i32, libc::SIGTERM) };
    let _ = server.wait();

    let queries: Vec<f64> = per_client.iter().flat_map(|c| c.0.iter().copied()).collect();
    let meshes: Vec<f64> = per_client.iter().flat_map(|c| c.1.iter().copied()).collect();
    let total = queries.len() + meshes.len();
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("{} clients, {total} requests in {wall:.2} s: {:.0} requests/s", clients, total as f64 / wall);
    for (route, ms) in [("query:", &queries), ("mesh: ", &meshes)] {
        let max = ms.iter().copied().fold(f64::NAN, f64::max);
        println!(
            "{route} {} requests, p50 {:.2} ms, p99 {:.2} ms, max {max:.2} ms",
            ms.len(),
            quantile(ms, 0.5),
            quantile(ms, 0.99)
        );
    }
    println!(
        "server RSS: idle {} MB, peak {} MB ({:.2}x); errors {}; load average {}",
        idle / 1024,
        peak / 1024,
        peak as f64 / idle.max(1) as f64,
        errors.load(Ordering::Relaxed),
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    println!("answers checked against the library: {}", if check { "yes" } else { "no (--no-check)" });
    if let Some(out) = out {
        let mut csv = String::from("route,latency_ms\n");
        for (route, list) in [("query", &queries), ("mesh", &meshes)] {
            for l in list.iter() {
                csv += &format!("{route},{l:.4}\n");
            }
        }
        std::fs::write(Path::new(out), csv).unwrap();
        println!("wrote {out}");
    }
    if errors.load(Ordering::Relaxed) > 0 {
        std::process::exit(1);
    }
}
