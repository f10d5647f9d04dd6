//! What a 3D Tiles client loads along the recorded walks, with and without hdov's visibility
//! plugin (issue 33): `hdov serve DB` runs, and headless chromium opens its `/tiles.html` page
//! (3DTilesRendererJS on `/tiles/tileset.json`) once per walk and mode, recording per view the
//! requests and bytes so far and, every K-th view, the PSNR of the frame against the same view
//! at full detail (every tile in the frustum refined to geometric error 0, drawn by the same
//! page).
//!
//! `cargo run --release -p hdov-tools --bin tiles-walk -- DB [--steps N] [--reference-every K]
//! [--modes off,on,query] [--csv FILE] [--chart FILE]`. Prints a Markdown table.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};

use clap::Parser;
use hdov_tools::experiments::charts::{Panel, Series, write_svg};
use serde_json::Value;

#[derive(Parser)]
#[command(
    name = "tiles-walk",
    about = "Requests, bytes and PSNR of a 3D Tiles client along the recorded walks, with and without hdov's visibility plugin"
)]
struct Args {
    /// The database (with a viewing grid).
    #[arg(value_name = "DB")]
    db: PathBuf,
    /// Views per walk.
    #[arg(long, default_value_t = 30)]
    steps: u32,
    /// The PSNR against full detail every K-th view (the full-detail frames cost most); 0: no
    /// PSNR, requests and bytes only (a scene whose full detail a software renderer draws too
    /// slowly, such as the large city under SwiftShader).
    #[arg(long, default_value_t = 5)]
    reference_every: u32,
    /// The recorded walks.
    #[arg(long, value_delimiter = ',', default_value = "straight,turning,back-and-forth")]
    walks: Vec<String>,
    /// Modes: off (the client alone), on (with the plugin), query (the plugin drawing node levels
    /// only where the query stops).
    #[arg(long, value_delimiter = ',', default_value = "off,on")]
    modes: Vec<String>,
    /// The renderer's error target in pixels (default: 3DTilesRendererJS's own, 16).
    #[arg(long)]
    error_target: Option<f64>,
    /// The hdov binary.
    #[arg(long, default_value = "target/release/hdov")]
    hdov: PathBuf,
    /// Window size.
    #[arg(long, value_parser = hdov_tools::args::size, default_value = "800x600")]
    size: [u32; 2],
    #[arg(long)]
    csv: Option<PathBuf>,
    #[arg(long)]
    chart: Option<PathBuf>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = Args::parse();
    println!("{}", hdov_tools::machine());
    let mut server = Command::new(&a.hdov)
        .args(["serve", a.db.to_str().ok_or("DB is not UTF-8")?, "--addr", "127.0.0.1:0", "--timeout", "600"])
        .stdout(Stdio::piped())
        .spawn()?;
    let mut line = String::new();
    BufReader::new(server.stdout.as_mut().ok_or("no stdout")?).read_line(&mut line)?;
    let base =
        line.split_whitespace().nth(2).ok_or_else(|| format!("no URL in '{line}'"))?.trim_end_matches('/').to_string();
    let chromium = hdov_testkit::browser::chromium_or_skip().ok_or("no chromium")?;
    let mut csv = String::from("walk,mode,step,cell,requests,bytes,visibility_requests,visibility_bytes,psnr\n");
    let mut rows = Vec::new();
    let mut panel = Panel::new("bytes loaded against PSNR (mean of the measured views)", "MB loaded", "PSNR (dB)");
    for walk in &a.walks {
        for mode in &a.modes {
            let (plugin, nodes) = match mode.as_str() {
                "off" => (0, ""),
                "on" => (1, ""),
                "query" => (1, "&nodes=query"),
                m => return Err(format!("mode '{m}' is none of off, on, query").into()),
            };
            let target = a.error_target.map_or(String::new(), |e| format!("&errorTarget={e}"));
            let reference = match a.reference_every {
                0 => String::new(),
                k => format!("&reference=1&referenceEvery={k}"),
            };
            let url = format!(
                "{base}/tiles.html?frames=timer&hud=0&walk={walk}&steps={}&plugin={plugin}{nodes}{target}{reference}",
                a.steps
            );
            let t = std::time::Instant::now();
            let dom = hdov_testkit::browser::browse(chromium, "--dump-dom", &url, a.size, 36_000_000);
            let result = hdov_testkit::browser::page_result(&dom).map_err(|e| format!("{url}: {e}"))?;
            let steps = result["steps"].as_array().ok_or("no steps")?;
            let mut psnrs = Vec::new();
            for s in steps {
                let psnr = s["psnr"].as_f64();
                psnrs.extend(psnr);
                csv += &format!(
                    "{walk},{mode},{},{},{},{},{},{},{}\n",
                    s["step"],
                    s["cell"],
                    s["requests"],
                    s["bytes"],
                    s["visibility_requests"],
                    s["visibility_bytes"],
                    psnr.map_or(String::new(), |p| format!("{p:.2}"))
                );
            }
            let last = steps.last().ok_or("no steps")?;
            let num = |v: &Value| v.as_f64().unwrap_or(0.0);
            let bytes = num(&last["bytes"]) + num(&last["visibility_bytes"]);
            let requests = num(&last["requests"]) + num(&last["visibility_requests"]);
            let min = psnrs.iter().copied().fold(f64::INFINITY, f64::min);
            let mean = psnrs.iter().sum::<f64>() / psnrs.len().max(1) as f64;
            eprintln!("{walk} {mode}: {:.0} s", t.elapsed().as_secs_f64());
            panel = panel.with(Series::new(format!("{walk}, {mode}"), vec![(bytes / 1e6, mean)]));
            rows.push((walk.clone(), mode.clone(), requests, bytes, min, mean, psnrs));
        }
    }
    println!("\n| walk | mode | requests | MB | vs off | PSNR min / mean (dB) |");
    println!("|---|---|---|---|---|---|");
    for (walk, mode, requests, bytes, min, mean, psnrs) in &rows {
        let off = rows.iter().find(|r| &r.0 == walk && r.1 == "off");
        let share = off.map_or(String::from("–"), |o| {
            format!("{:.0} % of the requests, {:.0} % of the bytes", 100.0 * requests / o.2, 100.0 * bytes / o.3)
        });
        let psnr = if psnrs.is_empty() { String::from("–") } else { format!("{min:.1} / {mean:.1}") };
        println!("| {walk} | {mode} | {requests:.0} | {:.2} | {share} | {psnr} |", bytes / 1e6);
    }
    // Frame by frame: how much worse than the client alone, at worst.
    for (walk, mode, .., psnrs) in rows.iter().filter(|r| r.1 != "off" && !r.6.is_empty()) {
        if let Some(off) = rows.iter().find(|r| &r.0 == walk && r.1 == "off") {
            let worst = psnrs.iter().zip(&off.6).map(|(p, o)| o - p).fold(f64::NEG_INFINITY, f64::max);
            println!("{walk}, {mode}: worst frame {worst:.2} dB below the client alone");
        }
    }
    if let Some(path) = &a.csv {
        std::fs::write(path, csv)?;
    }
    if let Some(path) = &a.chart {
        write_svg(path, "tiles-walk: a 3D Tiles client with and without hdov's visibility", &[panel], 1)?;
    }
    let _ = server.kill();
    Ok(())
}
