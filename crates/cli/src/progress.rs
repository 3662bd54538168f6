//! Progress of a count of jobs on standard error: a bar with the time left when standard
//! error is a terminal (indicatif), otherwise a plain line at every tenth of the jobs, so that
//! a log or a pipe gets ten lines, not a redrawn bar; and the phase of one long piece of work
//! ([`Phases`]), a line a second once it has taken a second.

use std::io::IsTerminal;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

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
            crate::console::errln!(
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

/// Time a run may take before it reports progress: shorter runs stay silent.
const PROGRESS_AFTER: Duration = Duration::from_secs(1);
/// Interval between progress reports.
const PROGRESS_EVERY: Duration = Duration::from_secs(1);

/// The phase a long command (`simulate`, `identify`) is in, reported on standard error by a thread once the run has
/// taken [`PROGRESS_AFTER`], then every [`PROGRESS_EVERY`] and at each new phase: one line
/// rewritten on a terminal, plain lines otherwise. Dropping it ends the report.
pub struct Phases {
    shared: Arc<(Mutex<(String, bool)>, Condvar)>,
    reporter: Option<std::thread::JoinHandle<()>>,
}

impl Phases {
    /// Starts reporting the phases of `command` (nothing at all when `quiet`).
    pub fn start(command: &'static str, quiet: bool) -> Self {
        Phases::start_with(command, quiet, || None)
    }

    /// [`Phases::start`], each line with what `detail` says at that moment (e.g. the fit's
    /// steps so far) after its phase.
    pub fn start_with(command: &'static str, quiet: bool, detail: fn() -> Option<String>) -> Self {
        let shared = Arc::new((Mutex::new((String::new(), false)), Condvar::new()));
        let reporter = (!quiet).then(|| {
            let shared = Arc::clone(&shared);
            std::thread::spawn(move || report(command, detail, &shared))
        });
        Phases { shared, reporter }
    }

    /// Enters the phase described by `what`.
    pub fn enter(&self, what: String) {
        let (state, changed) = &*self.shared;
        if let Ok(mut s) = state.lock() {
            s.0 = what;
        }
        changed.notify_all();
    }
}

impl Drop for Phases {
    fn drop(&mut self) {
        let (state, changed) = &*self.shared;
        if let Ok(mut s) = state.lock() {
            s.1 = true;
        }
        changed.notify_all();
        if let Some(reporter) = self.reporter.take() {
            let _ = reporter.join();
        }
    }
}

/// The reporting thread of [`Phases`].
fn report(
    command: &str,
    detail: fn() -> Option<String>,
    shared: &(Mutex<(String, bool)>, Condvar),
) {
    let (state, changed) = shared;
    let started = Instant::now();
    let terminal = std::io::stderr().is_terminal();
    let mut shown: Option<(String, Instant)> = None;
    let Ok(mut s) = state.lock() else { return };
    loop {
        let wait = match &shown {
            None => PROGRESS_AFTER.saturating_sub(started.elapsed()),
            Some((_, at)) => PROGRESS_EVERY.saturating_sub(at.elapsed()),
        };
        s = match changed.wait_timeout(s, wait.max(Duration::from_millis(1))) {
            Ok((guard, _)) => guard,
            Err(_) => return,
        };
        if s.1 {
            break;
        }
        let due = match &shown {
            None => started.elapsed() >= PROGRESS_AFTER,
            Some((phase, at)) => *phase != s.0 || at.elapsed() >= PROGRESS_EVERY,
        };
        if due && !s.0.is_empty() {
            let line = format!(
                "  {command}: {}{} ({:.1} s)",
                s.0,
                detail().map_or(String::new(), |d| format!(", {d}")),
                started.elapsed().as_secs_f64()
            );
            if terminal {
                crate::console::errprint!("\r{line:<78}");
            } else {
                crate::console::errln!("{line}");
            }
            shown = Some((s.0.clone(), Instant::now()));
        }
    }
    if terminal && shown.is_some() {
        crate::console::errln!();
    }
}
