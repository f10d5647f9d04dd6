//! The crate's error type: every failure a user can cause names the file or argument and the reason.

use std::path::PathBuf;

/// Errors of the hdov library. `Display` is one line, fit for the CLI's `error: ...`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O failure on a named file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A file whose contents are not what they must be (malformed, truncated, corrupted).
    #[error("{}: {reason}", path.display())]
    BadFile {
        /// The file (or database directory).
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A parameter that cannot be used, named as the library names it (`resolution`,
    /// `grid`, ...); a user interface maps the name to its own (the `hdov` command to a flag).
    #[error("{param}: {reason}")]
    BadParam {
        /// The parameter's name in the library.
        param: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// An error from the storage crate (pages, layouts).
    #[error(transparent)]
    Storage(#[from] hdov_storage::Error),
    /// No graphics adapter could run the GPU backend, or the graphics driver refused a request.
    /// Shown on one line, however many lines wgpu's own report has.
    #[error("gpu: {}", one_line(.0))]
    Gpu(String),
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O failure on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// A malformed, truncated or corrupted file at `path`.
    pub fn bad_file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::BadFile { path: path.into(), reason: reason.into() }
    }
    /// A parameter, named as the library names it, that cannot be used.
    pub fn bad_param(param: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::BadParam { param: param.into(), reason: reason.into() }
    }
}

/// `text` on one line: its non-empty lines trimmed and joined with ": ", leaving out wgpu's
/// "Caused by:" headings (a wgpu error is a heading, then its causes indented below it).
pub fn one_line(text: &str) -> String {
    let parts: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && *l != "Caused by:").collect();
    parts.join(": ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wgpu_report_reads_as_one_line() {
        let report = "Validation Error\n\nCaused by:\n  In Device::create_render_pipeline, label = 'render'\n    Color state [2] is invalid\n      Format R32Float is not renderable\n";
        let e = Error::Gpu(format!("llvmpipe on Gl: setting up the renderer: {report}"));
        assert_eq!(
            e.to_string(),
            "gpu: llvmpipe on Gl: setting up the renderer: Validation Error: In Device::create_render_pipeline, \
             label = 'render': Color state [2] is invalid: Format R32Float is not renderable"
        );
        assert_eq!(one_line("one line"), "one line");
    }
}
