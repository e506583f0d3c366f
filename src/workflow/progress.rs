//! Progress bars counted in units of work (frames, passes), silenced by `--quiet`.

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar that is a no-op when quiet.
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A bar named `what` over `total` units; hidden when `quiet` or stderr is not a terminal.
    pub fn new(what: &str, total: u64, quiet: bool) -> Progress {
        if quiet {
            return Progress { bar: None };
        }
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{msg:>16} [{bar:40}] {pos}/{len} {per_sec} eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        Progress { bar: Some(bar) }
    }

    /// The bar itself, for a library stage that ticks it (`None` when quiet).
    pub fn bar(&self) -> Option<ProgressBar> {
        self.bar.clone()
    }

    /// One unit done.
    pub fn inc(&self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }

    /// Remove the bar.
    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
