//! Coverage of the 95 % intervals on records of the reference simulator and logger written
//! apart from `motor_model` (`crates/fit/tests/reference/mod.rs`: Heun integration with
//! located breakaway and reversals, its own quantiser and noise), each run's motor and ADC
//! ranges varied:
//!
//! `cargo run --release -p fit --example output_error_coverage -- [RUNS] [--full]
//!  [--noise-lsb X] [--voltage-noise-lsb X] [--subsample-step] [--return-to-zero] [--seed N]`
//!
//! Output error on a staircase (40, −20, 0, 2.5 V; or 40 V then back to 0 V on a unipolar
//! voltage range with `--return-to-zero`), or with `--full` the step-pair full fit (40 V and
//! 2.5 V; with `--return-to-zero` each back to 0 V after 50 s and recorded for 100 s, the rise
//! and the fall fitted). Prints how many intervals of each parameter contained the truth.
#[path = "../tests/reference/mod.rs"]
mod reference;

use reference::{output_error_coverage, step_pair_coverage, Config};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str, default: f64| -> f64 {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let flag = |name: &str| args.iter().any(|a| a == name);
    let runs: u64 = args.first().and_then(|a| a.parse().ok()).unwrap_or(20);
    let noise = value("--noise-lsb", 1.0);
    let cfg = Config {
        noise_lsb: noise,
        voltage_noise_lsb: value("--voltage-noise-lsb", noise),
        subsample_step: flag("--subsample-step"),
        return_to_zero: flag("--return-to-zero"),
    };
    let seed = value("--seed", 1.0) as u64;
    let started = std::time::Instant::now();
    let (inside, with_ci) = if flag("--full") {
        step_pair_coverage(runs, cfg, seed)
    } else {
        output_error_coverage(runs, cfg, seed)
    };
    println!(
        "{} method, {cfg:?}: {runs} runs, {with_ci} with intervals, {:.0} s",
        if flag("--full") {
            "full step-pair"
        } else {
            "output-error"
        },
        started.elapsed().as_secs_f64()
    );
    for (name, n) in fit::PARAM_NAMES.iter().zip(inside) {
        println!(
            "{name}: {n}/{runs} intervals contain the truth ({:.1} %)",
            100.0 * n as f64 / runs as f64
        );
    }
}
