//! Build cost against scene size (issue 21): for each city scale, generates the city and builds
//! its tree and LODs (`hdov build --no-visibility`) in a child process, one at a time, and
//! records wall time, the child's peak resident set (from `wait4`), the database's bytes and
//! the scene's size; then fits the scaling exponent b of `y = a·x^b` (least squares on the logs)
//! for build time and database bytes against stored triangles, and draws both on log axes.
//!
//! `cargo build --release && cargo run --release -p hdov-tools --bin build-scaling -- WORK_DIR OUT.csv OUT.svg [SCALES]`
//!
//! SCALES is comma-separated (default `default,large,huge`). WORK_DIR keeps the generated cities
//! and databases in `WORK_DIR/SCALE/` (the huge city takes 1.4 GB of scene and 3.8 GB of
//! database); a `SCALE/` folder that exists already is refused, never replaced.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use clap::Parser;
use hdov::city::CityScale;
use hdov_tools::experiments::charts::{Panel, Series, write_svg};

/// One measured build.
struct Row {
    scale: String,
    objects: u64,
    triangles: u64,
    stored_triangles: u64,
    generate_seconds: f64,
    build_seconds: f64,
    lod_seconds: f64,
    peak_rss_bytes: u64,
    database_bytes: u64,
}

#[derive(Parser)]
#[command(
    name = "build-scaling",
    about = "Build cost against scene size: wall time, peak RSS and database bytes of `hdov build --no-visibility` \
             per city scale, with fitted exponents",
    long_about = "Build cost against scene size (issue 21): for each city scale, generates the city (seed 1) and builds\n\
                  its tree and LODs (`hdov build --no-visibility`) in a child process, one at a time, and records wall\n\
                  time, the child's peak resident set (wait4), the database's bytes and the scene's size. Fits the\n\
                  exponent b of y = a·x^b for build time, database bytes and peak RSS against stored triangles, prints\n\
                  the CSV and the exponents, and draws both on log axes. Runs the `hdov` beside this program: `cargo\n\
                  build --release` first.\n\
                  \n\
                  Makes: docs/results.md, item 11 \"Build cost against scene size\": docs/data/build_scaling.csv and\n\
                  the chart docs/results/build_scaling.svg\n\
                  (`build-scaling WORK_DIR docs/data/build_scaling.csv docs/results/build_scaling.svg`)."
)]
struct Args {
    /// Where the generated cities and databases go, in WORK_DIR/SCALE/; a SCALE/ folder that exists already is
    /// refused, never replaced (the huge city takes 1.4 GB of scene and 3.8 GB of database).
    work_dir: PathBuf,
    /// The CSV written: one row per scale.
    #[arg(value_name = "OUT.csv")]
    csv: PathBuf,
    /// The chart written (SVG): build time and bytes against stored triangles, log axes.
    #[arg(value_name = "OUT.svg")]
    svg: PathBuf,
    /// City scales, comma-separated (tiny, small, default, large, huge).
    #[arg(
        value_name = "SCALES",
        value_delimiter = ',',
        default_value = "default,large,huge",
        value_parser = hdov_tools::args::city_scale
    )]
    scales: Vec<CityScale>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { work_dir: work, csv: csv_path, svg: svg_path, scales } = Args::parse();
    let hdov = std::env::current_exe()?.with_file_name("hdov");
    if !hdov.is_file() {
        return Err(format!("{} not found: run `cargo build --release` first", hdov.display()).into());
    }
    eprintln!("{}", hdov_tools::machine());
    std::fs::create_dir_all(&work)?;
    let mut rows = Vec::new();
    for scale in scales.iter().map(|s| s.name()) {
        let dir = work.join(scale);
        if dir.exists() {
            return Err(format!("{} exists: remove it, or give another WORK_DIR", dir.display()).into());
        }
        let city = dir.join("city");
        let t = Instant::now();
        run(Command::new(&hdov).args(["generate", "city", "--scale", scale, "--seed", "1", "--out"]).arg(&city))?;
        let generate_seconds = t.elapsed().as_secs_f64();
        let db = dir.join("db");
        let t = Instant::now();
        let (out, peak_rss_bytes) = run(Command::new(&hdov)
            .arg("build")
            .arg(city.join("city.json"))
            .arg("--out")
            .arg(&db)
            .args(["--no-visibility", "--json"]))?;
        let build_seconds = t.elapsed().as_secs_f64();
        let report: serde_json::Value = serde_json::from_slice(&out)?;
        let counts = &report["manifest"]["counts"];
        let count = |k: &str| counts[k].as_u64().unwrap_or(0);
        let row = Row {
            scale: scale.to_string(),
            objects: count("objects"),
            triangles: count("triangles"),
            stored_triangles: count("stored_triangles"),
            generate_seconds,
            build_seconds,
            lod_seconds: report["lod_seconds"].as_f64().unwrap_or(f64::NAN),
            peak_rss_bytes,
            database_bytes: dir_bytes(&db)?,
        };
        eprintln!(
            "{scale}: {} objects, {} stored triangles: build {:.1} s, peak {:.2} GB, {:.2} GB on disk",
            row.objects,
            row.stored_triangles,
            row.build_seconds,
            row.peak_rss_bytes as f64 / 1e9,
            row.database_bytes as f64 / 1e9
        );
        rows.push(row);
    }

    let mut csv = String::from(
        "scale,objects,triangles,stored_triangles,generate_s,build_s,lod_s,peak_rss_bytes,database_bytes\n",
    );
    for r in &rows {
        csv += &format!(
            "{},{},{},{},{:.2},{:.2},{:.2},{},{}\n",
            r.scale,
            r.objects,
            r.triangles,
            r.stored_triangles,
            r.generate_seconds,
            r.build_seconds,
            r.lod_seconds,
            r.peak_rss_bytes,
            r.database_bytes
        );
    }
    std::fs::write(&csv_path, &csv)?;
    print!("{csv}");

    let x: Vec<f64> = rows.iter().map(|r| r.stored_triangles as f64).collect();
    let fit = |y: Vec<f64>| exponent(&x, &y);
    let time_b = fit(rows.iter().map(|r| r.build_seconds).collect());
    let bytes_b = fit(rows.iter().map(|r| r.database_bytes as f64).collect());
    let rss_b = fit(rows.iter().map(|r| r.peak_rss_bytes as f64).collect());
    println!(
        "exponents against stored triangles: build time {time_b:.3}, database bytes {bytes_b:.3}, peak RSS {rss_b:.3}"
    );
    let points = |f: &dyn Fn(&Row) -> f64| rows.iter().map(|r| (r.stored_triangles as f64, f(r))).collect();
    let panels = [
        Panel::new(format!("tree + LOD build time (exponent {time_b:.2})"), "stored triangles", "seconds")
            .log_x()
            .log_y()
            .with(Series::new("hdov build --no-visibility", points(&|r| r.build_seconds))),
        Panel::new(format!("database bytes (exponent {bytes_b:.2})"), "stored triangles", "bytes")
            .log_x()
            .log_y()
            .with(Series::new("database on disk", points(&|r| r.database_bytes as f64)))
            .with(Series::new(
                format!("peak RSS of the build (exponent {rss_b:.2})"),
                points(&|r| r.peak_rss_bytes as f64),
            )),
    ];
    write_svg(&svg_path, "Build cost against scene size (default, large, huge city)", &panels, 2)?;
    Ok(())
}

/// Runs `cmd` to completion; its stdout and the child's peak resident set in bytes, or its
/// stderr as the error when it fails.
fn run(cmd: &mut Command) -> Result<(Vec<u8>, u64), Box<dyn std::error::Error>> {
    let child = cmd.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn()?;
    let pid = child.id() as libc::pid_t;
    // Read the pipes on threads so the child never blocks on a full pipe.
    let mut child = child;
    let mut stdout = child.stdout.take().ok_or("no stdout")?;
    let mut stderr = child.stderr.take().ok_or("no stderr")?;
    let out = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut stdout, &mut v).map(|_| v)
    });
    let err = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut stderr, &mut v).map(|_| v)
    });
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value; wait4 fills it for our own child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for the child spawned above, whose pid we hold; `child` is not waited on again.
    let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    if waited != pid {
        return Err(format!("wait4: {}", std::io::Error::last_os_error()).into());
    }
    drop(child);
    let (out, err) = (out.join().map_err(|_| "stdout reader")??, err.join().map_err(|_| "stderr reader")??);
    if !(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0) {
        return Err(format!("{:?} failed: {}", cmd, String::from_utf8_lossy(&err).trim()).into());
    }
    // ru_maxrss is in kilobytes on Linux.
    Ok((out, usage.ru_maxrss as u64 * 1024))
}

/// Bytes of the files in `dir`.
fn dir_bytes(dir: &Path) -> std::io::Result<u64> {
    std::fs::read_dir(dir)?.map(|e| Ok(e?.metadata()?.len())).sum()
}

/// The exponent b of the least-squares fit `log y = log a + b·log x`.
fn exponent(x: &[f64], y: &[f64]) -> f64 {
    let (lx, ly): (Vec<f64>, Vec<f64>) = x.iter().zip(y).map(|(a, b)| (a.ln(), b.ln())).unzip();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let cov: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let var: f64 = lx.iter().map(|a| (a - mx).powi(2)).sum();
    cov / var
}
