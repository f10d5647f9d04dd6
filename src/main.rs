//! The `hdov` command: a thin face over the library (see `cli`).

mod cli;

fn main() -> std::process::ExitCode {
    // Rust ignores SIGPIPE, so printing into a closed pipe (`hdov info DB | head -1`) would panic;
    // a command-line tool ends quietly instead, as `cat` and `grep` do.
    #[cfg(unix)]
    // SAFETY: restoring a signal's default disposition at start-up, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    cli::main()
}
