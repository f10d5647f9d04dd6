//! The `hdov` command line (clap). Each subcommand parses its arguments, calls one library
//! function and prints a summary, or one JSON document with `--json`. Errors print one line,
//! `error: <file or argument>: <reason>`, and exit with status 2.

mod commands;
mod query;
mod render;
mod serve;

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use hdov::render::Renderer;
use hdov::{Error, Param, Result};

#[derive(Parser)]
#[command(name = "hdov", version, about = "A disk-resident visibility database for large 3D scenes (HDoV-tree)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate the default city, build its database and print a summary: the main job, end to end.
    Demo(commands::DemoArgs),
    /// Generate a synthetic scene.
    #[command(subcommand)]
    Generate(commands::GenerateCommand),
    /// Build a database from a scene (a glTF file, an OBJ file or a scene manifest .json).
    Build(commands::BuildArgs),
    /// Join shards (built with --shard I/N) with their base build (--no-visibility) into one database.
    Merge(commands::MergeArgs),
    /// Describe a database: counts, build parameters, file sizes.
    Info(commands::InfoArgs),
    /// Point DoV of every object of a scene seen from one point.
    Dov(commands::DovArgs),
    /// What is visible from a point, at which detail, and what finding it cost.
    Query(query::QueryCmd),
    /// Walk a path of viewpoints through a database: cell flips, delta loads, cache hits.
    Walk(query::WalkCmd),
    /// Draw the full-detail scene or a query's answer from a camera into a PNG; report PSNR and
    /// coverage difference against full detail.
    Render(render::RenderCmd),
    /// Write a database's whole scene as a glTF binary (.glb), to check its geometry in any viewer.
    Export(commands::ExportArgs),
    /// Serve a database over HTTP, read-only: what is visible from here and its meshes as glTF,
    /// with a walkthrough viewer at /.
    Serve(serve::ServeCmd),
}

pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version: clap's own text on stdout.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("error: {}", clap_one_line(&e));
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        Command::Demo(a) => commands::demo(a),
        Command::Generate(g) => commands::generate(g),
        Command::Build(a) => commands::build(a),
        Command::Merge(a) => commands::merge(a),
        Command::Info(a) => commands::info(a),
        Command::Dov(a) => commands::dov(a),
        Command::Query(a) => query::query(a),
        Command::Walk(a) => query::walk(a),
        Command::Render(a) => render::render(a),
        Command::Export(a) => commands::export(a),
        Command::Serve(a) => serve::serve(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", user_message(&e));
            ExitCode::from(2)
        }
    }
}

/// clap's error as one line: its first paragraph (the message and what it lists, e.g. the
/// missing arguments) joined, without the `error: ` prefix, the usage and the tips.
fn clap_one_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let message: Vec<&str> = text
        .lines()
        .map(str::trim)
        .take_while(|l| !l.is_empty() && !l.starts_with("Usage:"))
        .filter(|l| !l.starts_with("tip:"))
        .collect();
    let message = message.join(" ");
    let message = message.strip_prefix("error: ").unwrap_or(&message);
    format!("{message} (see hdov --help)")
}

/// The library's error in the command's words: parameters become the flags that set them, and
/// a refused target says how to replace it.
fn user_message(e: &Error) -> String {
    use hdov::StorageError as S;
    match e {
        Error::BadParam { param, reason } => format!("{}: {reason}", flag_of(*param)),
        Error::Storage(S::Exists { .. }) => format!("{e}; pass --force to replace it"),
        _ => e.to_string(),
    }
}

/// The flag (or argument) that sets a library parameter: every parameter has one, and the
/// compiler checks that none is left out.
fn flag_of(param: Param) -> &'static str {
    match param {
        Param::At => "--at",
        Param::Backend => "--backend",
        Param::Blocks => "--blocks",
        Param::Camera => "--look",
        Param::CellSize => "--cell-size",
        Param::DovCodec => "--dov-codec",
        Param::Eta => "--eta",
        Param::EyeHeights => "--eye-heights",
        Param::Eyesight => "--eyesight",
        Param::Fanout => "--fanout",
        Param::Fidelity => "--fidelity",
        Param::Fov => "--fov",
        Param::Grid => "--grid",
        Param::InteriorSamples => "--samples",
        Param::Layout => "--layout",
        Param::Layouts => "--layouts",
        Param::LodDrawTolerance => "--lod-draw-tolerance",
        Param::Mode => "--mode",
        Param::PageSize => "--page-size",
        Param::Path => "--path",
        Param::Region => "--region",
        Param::RegionViews => "--region-views",
        Param::Render => "render",
        Param::Resolution => "--resolution",
        Param::ReviewBox => "--review-box",
        Param::RootTransform => "--root-transform",
        Param::Scale => "--scale",
        Param::Scene => "SCENE",
        Param::Base => "--base",
        Param::Shard => "--shard",
        Param::Shards => "SHARD_DB",
        Param::Size => "--size",
        Param::Tau => "--tau",
        Param::ZeroDovFloor => "--zero-dov-floor",
        // Set by no flag: the library's own inputs, named as the library names them.
        Param::Cell
        | Param::IdCube
        | Param::LodRatio
        | Param::Lods
        | Param::Near
        | Param::Point
        | Param::PrefetchK
        | Param::Samples
        | Param::TreeShape => param.name(),
    }
}

/// The renderer, or a one-line error without a graphics adapter.
fn open_renderer() -> Result<Renderer> {
    Renderer::new().map_err(|e| match e {
        Error::Gpu(reason) if reason.starts_with("no adapter") => {
            Error::bad_param(Param::Render, "no graphics adapter (install mesa-vulkan-drivers)")
        }
        e => e,
    })
}
