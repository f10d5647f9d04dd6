//! Progress bars for long steps: shown on a terminal, silent otherwise (scripts, CI, `--json`).

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
