//! The `hdov` command line (clap). Each subcommand parses its arguments, calls one library
//! function and prints a summary, or one JSON document with `--json`. Errors print one line,
//! `error: <file or argument>: <reason>`, and exit with status 2.

mod args;
mod commands;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub use args::{parse_dims, parse_region, parse_vec3};

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
    /// Build a database from a scene (an OBJ file or a scene manifest .json).
    Build(commands::BuildArgs),
    /// Join shard databases (built with --shard I/N) into one.
    Merge(commands::MergeArgs),
    /// Describe a database: counts, build parameters, file sizes.
    Info(commands::InfoArgs),
    /// Point DoV of every object of a scene seen from one point.
    Dov(commands::DovArgs),
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => commands::demo(a),
        Command::Generate(g) => commands::generate(g),
        Command::Build(a) => commands::build(a),
        Command::Merge(a) => commands::merge(a),
        Command::Info(a) => commands::info(a),
        Command::Dov(a) => commands::dov(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
