//! `motorid`: identify DC servomotor parameters; simulate, acquire, diagnose.
//!
//! `main` is glue: parse the command line, validate it into typed settings, run, and map the
//! outcome to an exit code (0 success, 2 bad input, 3 a fit that did not converge, 1 anything
//! else).

// Doc comments of `args` are the `--help` text, where units read naturally as `[V]`, `[s]`.
#![allow(rustdoc::broken_intra_doc_links)]

mod args;
mod commands;
mod console;
mod csv_table;
mod errors;
mod fifo;
mod figures;
mod output;
mod paper_values;
mod parallel;
mod plot;
mod progress;
mod record_checks;
mod record_csv;
mod servo_csv;
mod servo_report;
mod settings;
mod simulated;
mod steps;

use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches};

use crate::errors::BadInput;
use crate::errors::NotConverged;
use args::{Cli, Command};

/// mimalloc rather than the system's malloc: it backs large blocks with transparent huge
/// pages, so that a record's columns (400 kB each for 50,000 samples) fault in a few 2 MiB
/// pages instead of a hundred 4 KiB pages each, and it reuses freed blocks without handing
/// them back to the system. `identify --method paper` on two 50,001-sample records: 1,920
/// page faults with glibc's malloc, about 310 with mimalloc (see the README).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Exit code for input the user must fix (bad options, unreadable or invalid files).
const EXIT_BAD_INPUT: u8 = 2;
/// Exit code for any other failure (I/O while writing, internal errors).
const EXIT_FAILURE: u8 = 1;
/// Exit code for a fit that ran but did not converge (its results are still printed).
const EXIT_NOT_CONVERGED: u8 = 3;

/// Restores the default action of SIGPIPE (the Rust runtime ignores it), so that
/// `motorid ... | head` ends quietly when the reader goes away, like other command-line tools,
/// instead of failing to print.
fn quiet_broken_pipe() {
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to SIG_DFL at start-up, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The output paths a command line names, for [`output::check`] before any work starts.
fn declared_outputs(command: &Command) -> Vec<output::Declared> {
    use output::Declared::{Dir, File};
    use std::path::PathBuf;
    let file = |flag, path: &PathBuf| File {
        flag,
        path: path.clone(),
    };
    let dir = |flag, path: &PathBuf| Dir {
        flag,
        path: path.clone(),
    };
    let mut outputs = Vec::new();
    match command {
        Command::Simulate(a) => outputs.extend(a.output.iter().map(|p| file("-o", p))),
        Command::Acquire(a) => outputs.push(file("-o", &a.output)),
        Command::Demo(a) => outputs.extend(a.out.iter().map(|p| dir("--out", p))),
        Command::Fleet(a) => outputs.push(dir("--out", &a.out)),
        Command::Emps(a) => outputs.extend(a.plot.iter().map(|p| dir("--plot", p))),
        Command::Identify(a) => {
            outputs.extend(a.plot.iter().map(|p| dir("--plot", p)));
            outputs.extend(a.save_model.iter().map(|p| output::Declared::Document {
                flag: "--save-model",
                path: p.clone(),
            }));
            // The summaries go into the batch folder; a missing folder is the batch's own error.
            if let Some(batch) = a.batch.as_ref().filter(|d| d.is_dir()) {
                for name in ["summary.csv", "summary.json"] {
                    outputs.push(file("--batch", &batch.join(name)));
                }
            }
        }
        Command::Diagnose(a) => outputs.extend(a.plot.iter().map(|p| dir("--plot", p))),
        Command::Replay(a) => outputs.extend(a.plot.iter().map(|p| dir("--plot", p))),
        Command::Model(_) | Command::Montecarlo(_) | Command::Emulate(_) => {}
    }
    outputs
}

fn main() -> ExitCode {
    quiet_broken_pipe();
    // A negative number is an option's value (`--torque-constant -0.05`), never a flag.
    let command = Cli::command().mut_subcommands(|c| c.allow_negative_numbers(true));
    let cli = match command
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m))
    {
        Ok(cli) => cli,
        Err(e) => {
            // A command line asking for JSON gets its refusal as JSON too.
            let json = std::env::args().any(|a| a == "--json");
            if json && e.use_stderr() {
                let first = e.to_string();
                let message = first.lines().next().unwrap_or_default();
                let message = message.strip_prefix("error: ").unwrap_or(message);
                json_failure(message, EXIT_BAD_INPUT);
            }
            e.exit()
        }
    };
    let json = wants_json(&cli.command);
    let outcome =
        output::check(&declared_outputs(&cli.command)).and_then(|()| match cli.command {
            Command::Model(a) => {
                commands::model::Settings::from_args(&a).and_then(|s| commands::model::run(&s))
            }
            Command::Simulate(a) => commands::simulate::Settings::from_args(&a)
                .and_then(|s| commands::simulate::run(&s)),
            Command::Identify(a) => commands::identify::Settings::from_args(&a)
                .and_then(|s| commands::identify::run(&s)),
            Command::Demo(a) => commands::demo::run(&commands::demo::Settings::from_args(&a)),
            Command::Montecarlo(a) => commands::montecarlo::Settings::from_args(&a)
                .and_then(|s| commands::montecarlo::run(&s)),
            Command::Fleet(a) => {
                commands::fleet::Settings::from_args(&a).and_then(|s| commands::fleet::run(&s))
            }
            Command::Emulate(a) => {
                commands::emulate::Settings::from_args(&a).and_then(|s| commands::emulate::run(&s))
            }
            Command::Acquire(a) => {
                commands::acquire::Settings::from_args(&a).and_then(|s| commands::acquire::run(&s))
            }
            Command::Emps(a) => commands::emps::run(&commands::emps::Settings::from_args(&a)),
            Command::Replay(a) => {
                commands::replay::Settings::from_args(&a).and_then(|s| commands::replay::run(&s))
            }
            Command::Diagnose(a) => {
                commands::diagnose::settings(&a).and_then(|s| commands::diagnose::run(&s))
            }
        });
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            crate::console::errln!("error: {err:#}");
            let code = if err.chain().any(|e| e.is::<BadInput>()) {
                EXIT_BAD_INPUT
            } else if err.chain().any(|e| e.is::<NotConverged>()) {
                EXIT_NOT_CONVERGED
            } else {
                EXIT_FAILURE
            };
            if json && !crate::console::wrote_stdout() {
                json_failure(&format!("{err:#}"), code);
            }
            ExitCode::from(code)
        }
    }
}

/// Whether the command was asked for one JSON object on standard output.
fn wants_json(command: &Command) -> bool {
    match command {
        Command::Model(a) => a.json,
        Command::Identify(a) => a.json,
        Command::Montecarlo(a) => a.json,
        Command::Emps(a) => a.json,
        Command::Diagnose(a) => a.json,
        Command::Replay(a) => a.json,
        _ => false,
    }
}

/// The one JSON object of a `--json` command that failed before printing its own:
/// `{"error": MESSAGE, "exit_code": CODE}` (the message also goes to standard error).
fn json_failure(message: &str, code: u8) {
    let object = serde_json::json!({ "error": message, "exit_code": code });
    let _ = crate::console::stdout_line(format_args!("{object}"));
}
