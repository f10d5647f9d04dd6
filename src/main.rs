//! The `hdov` command: a thin face over the library (see `cli`).

fn main() -> std::process::ExitCode {
    hdov::cli::main()
}
