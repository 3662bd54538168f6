//! Progress of a count of jobs on standard error: a bar with the time left when standard
//! error is a terminal (indicatif), otherwise a plain line at every tenth of the jobs, so that
//! a log or a pipe gets ten lines, not a redrawn bar.

use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

/// The bar: `  ████░░░░ 12/200 motors: 12 identified, 0 failed [3s, 47s left]`.
const TEMPLATE: &str = "  {bar:30} {pos}/{len} {prefix}{msg} [{elapsed}, {eta} left]";

/// Progress of `total` jobs (see the module docs).
pub struct Jobs {
    bar: ProgressBar,
    total: usize,
    what: &'static str,
    quiet: bool,
    started: Instant,
}

impl Jobs {
    /// Progress of `total` jobs, each a `what` ("motors", "record pairs done"); nothing at all
    /// when `quiet`.
    pub fn new(total: usize, what: &'static str, quiet: bool) -> Jobs {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(total as u64)
        };
        if let Ok(style) = ProgressStyle::with_template(TEMPLATE) {
            bar.set_style(style);
        }
        bar.set_prefix(what);
        Jobs {
            bar,
            total,
            what,
            quiet,
            started: Instant::now(),
        }
    }

    /// `done` jobs are finished; `detail` (e.g. `": 12 identified, 0 failed"`) follows the
    /// count.
    pub fn done(&self, done: usize, detail: impl FnOnce() -> String) {
        if self.quiet {
            return;
        }
        if !self.bar.is_hidden() {
            self.bar.set_message(detail());
            self.bar.set_position(done as u64);
        } else if done.is_multiple_of((self.total / 10).max(1)) || done == self.total {
            eprintln!(
                "  {done}/{} {}{} ({:.1} s)",
                self.total,
                self.what,
                detail(),
                self.started.elapsed().as_secs_f64()
            );
        }
    }
}

impl Drop for Jobs {
    /// Clears the bar, so that what follows is printed on a clean line.
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
