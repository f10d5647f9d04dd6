//! Progress of long work, reported one way: every stage takes a [`Report`] (how far its step
//! got). [`Progress`] makes them: bars on a terminal, silent otherwise (scripts, CI, `--json`);
//! [`Quiet`] reports nowhere.

use indicatif::{ProgressBar, ProgressStyle};

/// Where long steps report progress: bars on a terminal, nothing otherwise.
#[derive(Clone, Copy, Debug, Default)]
pub struct Progress {
    visible: bool,
}

impl Progress {
    /// Bars on stderr, visible only when stdout is a terminal and `quiet` is false.
    pub fn for_terminal(quiet: bool) -> Self {
        use std::io::IsTerminal;
        Self { visible: !quiet && std::io::stdout().is_terminal() }
    }

    /// No bars at all.
    pub fn hidden() -> Self {
        Self { visible: false }
    }

    /// A bar for `total` units of a step called `label` (with rate and ETA).
    pub fn bar(&self, label: &str, total: u64) -> ProgressBar {
        if !self.visible {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{msg:>14} [{bar:32}] {pos}/{len} {per_sec} eta {eta}")
                .expect("static template")
                .progress_chars("=> "),
        );
        bar.set_message(label.to_string());
        bar
    }
}

/// How far one step of long work got: the one way the stages (LODs, sample points) report it.
/// An indicatif `ProgressBar` is one; [`Quiet`] is the one that reports nowhere.
pub trait Report: Sync {
    /// `n` more units are done.
    fn advance(&self, n: u64);
    /// `done` of `total` units are done (the total may grow as work is found).
    fn set(&self, done: u64, total: u64);
}

impl Report for ProgressBar {
    fn advance(&self, n: u64) {
        self.inc(n);
    }

    fn set(&self, done: u64, total: u64) {
        self.set_length(total);
        self.set_position(done);
    }
}

/// Reports nowhere.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl Report for Quiet {
    fn advance(&self, _: u64) {}
    fn set(&self, _: u64, _: u64) {}
}
