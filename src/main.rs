//! The `hdov` command: a thin face over the library (see `cli`).

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
