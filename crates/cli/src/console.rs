//! The CLI's report and messages: [`outln!`] writes a line of the report to standard output and
//! returns a failure to write (a full disk, a closed descriptor) as an error instead of
//! panicking as `println!` does; [`errln!`] and [`errprint!`] write messages to standard error
//! and drop what cannot be written.

use std::io::Write;

use anyhow::{Context, Result};

/// The context of every failed write to standard output.
pub(crate) const STDOUT_FAILED: &str = "cannot write to standard output";

/// Writes `args` and a newline to standard output and flushes it; a failure is an error
/// (`cannot write to standard output: No space left on device (os error 28)`), not a panic.
/// Called through [`outln!`].
pub fn stdout_line(args: std::fmt::Arguments<'_>) -> Result<()> {
    WROTE_STDOUT.store(true, std::sync::atomic::Ordering::Relaxed);
    let mut out = std::io::stdout().lock();
    out.write_fmt(format_args!("{args}\n"))
        .and_then(|()| out.flush())
        .context(STDOUT_FAILED)
}

/// Whether the report has begun on standard output ([`stdout_line`]).
static WROTE_STDOUT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether anything of the report has been written to standard output: a command that fails
/// before its `--json` object is printed gets one carrying its error instead.
pub fn wrote_stdout() -> bool {
    WROTE_STDOUT.load(std::sync::atomic::Ordering::Relaxed)
}

/// `println!` that returns `anyhow::Result<()>` instead of panicking when standard output
/// cannot be written: `outln!("{x} V")?;` ([`stdout_line`]).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::console::stdout_line(format_args!($($arg)*))
    };
}
pub(crate) use outln;

/// Writes `args` to standard error, ignoring a failure: a message that cannot be written
/// (`2>/dev/full`, a closed descriptor) has nowhere else to go, and the exit code still says
/// how the command ended. Called through [`errln!`] and [`errprint!`].
pub fn stderr_text(args: std::fmt::Arguments<'_>) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_fmt(args).and_then(|()| err.flush());
}

/// `eprintln!` that does not panic when standard error cannot be written ([`stderr_text`]).
macro_rules! errln {
    () => {
        $crate::console::stderr_text(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::console::stderr_text(format_args!("{}\n", format_args!($($arg)*)))
    };
}
pub(crate) use errln;

/// `eprint!` that does not panic when standard error cannot be written ([`stderr_text`]).
macro_rules! errprint {
    ($($arg:tt)*) => {
        $crate::console::stderr_text(format_args!($($arg)*))
    };
}
pub(crate) use errprint;
