//! `motorid montecarlo`: how accurate are the two methods, and are the full method's 95 %
//! intervals honest? Many noisy record pairs of one motor, identified by both methods.

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use fit::{
    accuracy, identify_step_pair, parameter_estimates, summarize, LmSettings, ParameterAccuracy,
    StepMethod, StepPairError,
};
use motor_model::{MotorParams, NoiseRng};
use serde_json::json;

use crate::args::MontecarloArgs;
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};
use crate::progress::Jobs;
use crate::settings::{self, Logger};
use crate::simulated::{record_at, StepTiming};

/// Most record pairs a study may ask for (200 take about 10 s on 2 cores; a million, a day).
const MAX_RUNS: usize = 1_000_000;

/// Largest stretch of the conditioning ranges with `--vary-range` (a fraction: more than one
/// ADC step at full scale, so a level's place between codes is uniform over the runs).
const RANGE_STRETCH: f64 = 0.05;

/// Outcome of one record pair.
struct Run {
    /// `None` where the paper's method does not apply (e.g. an underdamped motor).
    paper: Option<Vec<ParameterAccuracy>>,
    full: Vec<ParameterAccuracy>,
    converged: bool,
    /// Termination and cost of a fit that did not converge.
    stop: Option<String>,
}

/// How each run's motor and measurement vary (checked before the first run).
struct Chain {
    /// Noise on the voltage channel \[LSB\], if other than the logger's.
    voltage_noise_lsb: Option<f64>,
    /// Step instants drawn uniformly within a sample period.
    subsample_step: bool,
    /// Relative spread of each run's motor around the nominal one.
    motor_spread: f64,
    /// ADC ranges stretched at random (up to [`RANGE_STRETCH`]).
    vary_range: bool,
    /// How long each step holds before the voltage returns to 0 V \[s\], if it does (the
    /// record then runs as long again).
    hold_s: Option<f64>,
}

/// The validated settings of a Monte Carlo study.
pub struct Settings {
    /// The nominal motor.
    motor: MotorParams,
    /// The simulated logger.
    logger: Logger,
    /// How each run's motor and measurement vary.
    chain: Chain,
    /// High-voltage step \[V\].
    high_voltage_v: f64,
    /// Low-voltage step \[V\].
    low_voltage_v: f64,
    /// First noise seed.
    seed: u64,
    /// Number of record pairs.
    runs: usize,
    /// One JSON object instead of the table.
    json: bool,
    /// No progress on standard error.
    quiet: bool,
}

fn one_run(study: &Settings, i: usize) -> Result<Run> {
    let seed = study.seed.wrapping_add(2 * i as u64);
    let (a, nominal, logger) = (&study.chain, &study.motor, &study.logger);
    // Run i's own motor and step instants (a generator apart from the noise's).
    let mut rng = NoiseRng::new(seed ^ 0x5eed_5eed_5eed_5eed);
    let spread = nominal
        .values()
        .map(|v| v * (1.0 + a.motor_spread * rng.normal()));
    let motor = &MotorParams::from_values(spread)
        .map_err(|e| BadInput(format!("run {i}: --motor-spread {}: {e}", a.motor_spread)))?;
    let mut at = || {
        if a.subsample_step {
            rng.uniform() / logger.rate_hz
        } else {
            0.0
        }
    };
    let mut timing = || StepTiming {
        at_s: at(),
        fall_at_s: a.hold_s.map(|hold| hold + at()),
    };
    let (at_high, at_low) = (timing(), timing());
    let mut chain = || {
        let stretch = if a.vary_range {
            1.0 + RANGE_STRETCH * rng.uniform()
        } else {
            1.0
        };
        (a.voltage_noise_lsb, stretch)
    };
    let (chain_high, chain_low) = (chain(), chain());
    let hv = record_at(
        logger,
        chain_high,
        motor,
        study.high_voltage_v,
        at_high,
        seed,
    )?;
    let lv = record_at(
        logger,
        chain_low,
        motor,
        study.low_voltage_v,
        at_low,
        seed.wrapping_add(1),
    )?;
    let result = identify_step_pair(
        &hv.step_record(),
        &lv.step_record(),
        StepMethod::Full,
        LmSettings::default(),
    )
    .map_err(|e| match e {
        StepPairError::Start(e) => BadInput(format!("run {i}: start: {e}")),
        e => BadInput(format!("run {i}: full method: {e}")),
    })?;
    let full = result
        .full
        .ok_or_else(|| BadInput(format!("run {i}: full method: no fit")))?;
    Ok(Run {
        paper: result.paper.ok().map(|p| accuracy(&p.params, None, motor)),
        full: accuracy(&full.params, full.ci95.as_ref(), motor),
        converged: full.accepted(),
        stop: full.failure().map(|why| format!("run {i}: {why}")),
    })
}

impl Settings {
    /// The options of `a`, every one checked before the first run: `--runs`, `--motor`, the
    /// logger, the two steps (they must break away within the record), the variations.
    pub fn from_args(a: &MontecarloArgs) -> Result<Settings> {
        if a.runs == 0 || a.runs > MAX_RUNS {
            return Err(BadInput(format!(
                "--runs {}: expected 1 to {MAX_RUNS} record pairs",
                a.runs
            ))
            .into());
        }
        // Every setting is checked before the first run: a study whose runs cannot succeed is
        // refused with what to fix, not run into a table of NaN.
        let motor = settings::motor(&a.motor.motor)?;
        let logger = Logger::new(a.duration, a.rate, a.adc_bits, a.noise_lsb, a.encoder_cpr)?;
        // Without noise a reading is the code of its level, the same in every run unless the
        // ranges (or, for the current, the motor) move: the runs would share one quantisation
        // error (the paper's 40 V sits exactly halfway between two codes of the 0–48 V range)
        // and count one place of the grid, not the intervals' coverage.
        let silent = if a.noise_lsb == 0.0 && a.voltage_noise_lsb.is_none_or(|v| v == 0.0) {
            Some("--noise-lsb 0")
        } else if a.voltage_noise_lsb == Some(0.0) {
            Some("--voltage-noise-lsb 0")
        } else if a.noise_lsb == 0.0 && a.motor_spread == 0.0 {
            // A noisy voltage leaves the true current where it was: only another motor moves it.
            Some("--noise-lsb 0 (current and speed, no --motor-spread)")
        } else {
            None
        };
        if let (Some(flag), false) = (silent, a.vary_range) {
            return Err(BadInput(format!(
                "{flag} without --vary-range: with no noise every run reads each level at the same place between two ADC codes, so the runs share one quantisation error and their coverage measures that one place, not the intervals; add --vary-range"
            ))
            .into());
        }
        // A step that returns to 0 V holds for --duration, and the record runs as long again.
        let hold_s = a.return_to_zero.then_some(logger.duration_s);
        let record_logger = match hold_s {
            Some(hold) => {
                let (duration_s, _) = settings::record_grid(2.0 * hold, a.rate).map_err(|e| {
                    BadInput(format!(
                        "--return-to-zero records twice --duration {}: {e}",
                        settings::shown(a.duration)
                    ))
                })?;
                Logger {
                    duration_s,
                    ..logger
                }
            }
            None => logger,
        };
        Ok(Settings {
            high_voltage_v: settings::breakaway_step(
                "--high-voltage",
                &motor,
                a.high_voltage,
                logger.duration_s,
            )?,
            low_voltage_v: settings::breakaway_step(
                "--low-voltage",
                &motor,
                a.low_voltage,
                logger.duration_s,
            )?,
            motor,
            logger: record_logger,
            chain: Chain {
                voltage_noise_lsb: match a.voltage_noise_lsb {
                    Some(v) if !(v.is_finite() && v >= 0.0) => {
                        return Err(BadInput(format!(
                            "--voltage-noise-lsb {v}: expected a noise level of 0 LSB or more"
                        ))
                        .into())
                    }
                    other => other,
                },
                subsample_step: a.subsample_step,
                motor_spread: if a.motor_spread.is_finite() && (0.0..0.5).contains(&a.motor_spread)
                {
                    a.motor_spread
                } else {
                    return Err(BadInput(format!(
                        "--motor-spread {}: expected a relative spread from 0 to 0.5",
                        a.motor_spread
                    ))
                    .into());
                },
                vary_range: a.vary_range,
                hold_s,
            },
            seed: a.seed,
            runs: a.runs,
            json: a.json,
            quiet: a.quiet,
        })
    }
}

/// Simulates and identifies the record pairs in parallel and prints the accuracy of both
/// methods and the coverage of the full method's intervals.
pub fn run(study: &Settings) -> Result<()> {
    let threads = crate::parallel::threads(study.runs);
    let started = std::time::Instant::now();
    let identified = AtomicUsize::new(0);
    let failed = AtomicUsize::new(0);
    let progress = Jobs::new(study.runs, "record pairs done", study.json || study.quiet);
    let results = crate::parallel::map(
        study.runs,
        |i| {
            let result = one_run(study, i);
            let counter = if result.is_ok() { &identified } else { &failed };
            counter.fetch_add(1, Ordering::Relaxed);
            result
        },
        |n| {
            progress.done(n, || {
                let (ok, bad) = (
                    identified.load(Ordering::Relaxed),
                    failed.load(Ordering::Relaxed),
                );
                format!(": {ok} identified, {bad} failed")
            })
        },
    );
    drop(progress);
    let mut runs = Vec::new();
    let mut failures = Vec::new();
    for r in results {
        match r {
            Ok(run) => runs.push(run),
            Err(e) => failures.push(e.to_string()),
        }
    }
    if runs.is_empty() {
        let first = failures.first().map_or("", String::as_str);
        return Err(NotConverged(format!(
            "all {} runs failed; nothing to report. The first: {first}",
            study.runs
        ))
        .into());
    }
    let elapsed = started.elapsed().as_secs_f64();
    let with_ci = runs
        .iter()
        .filter(|r| r.full.iter().any(|p| p.covered.is_some()))
        .count();
    let converged = runs.iter().filter(|r| r.converged).count();
    let paper_applied = runs.iter().filter(|r| r.paper.is_some()).count();
    let paper = summarize(runs.iter().filter_map(|r| r.paper.as_deref()));
    let full = summarize(runs.iter().map(|r| r.full.as_slice()));
    let rows: Vec<_> = parameter_estimates(&study.motor, None)
        .into_iter()
        .zip(paper.iter().zip(&full))
        .map(|(truth, (paper, full))| {
            (
                truth.name,
                truth.value,
                paper.median_abs_relative_error.unwrap_or(f64::NAN),
                full.median_abs_relative_error.unwrap_or(f64::NAN),
                full.coverage(),
            )
        })
        .collect();
    if study.json {
        let report = json!({
            "runs": runs.len(), "failed": failures, "paper_method_applied": paper_applied, "runs_with_ci": with_ci, "converged": converged, "seconds": elapsed,
            "parameters": rows.iter().map(|(name, truth, paper, full, coverage)| json!({
                "name": name, "truth": truth, "paper_median_abs_rel_error": paper,
                "full_median_abs_rel_error": full, "full_ci95_coverage": coverage,
            })).collect::<Vec<_>>(),
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
        return failed_runs(&failures, study.runs);
    }
    let hold = study
        .chain
        .hold_s
        .map_or(String::new(), |h| format!(", back to 0 V after {h} s"));
    let voltage_noise = study
        .chain
        .voltage_noise_lsb
        .map_or(String::new(), |v| format!(" ({v} LSB on the voltage)"));
    outln!(
        "Monte Carlo: {} record pairs ({} V and {} V steps{hold}, {} s at {} Hz; {}-bit ADC, {} LSB noise{voltage_noise}, encoder {} counts/rev, speed from the encoder)",
        runs.len(), study.high_voltage_v, study.low_voltage_v, study.logger.duration_s, study.logger.rate_hz, study.logger.adc_bits, study.logger.noise_lsb, study.logger.encoder_cpr
    )?;
    outln!(
        "  param        truth   paper median |error|   full median |error|   full 95% CI coverage"
    )?;
    for (name, truth, paper, full, coverage) in &rows {
        outln!(
            "  {name:<5} {truth:>12.6}   {:>19.4} %   {:>18.5} %   {:>19.1} %",
            100.0 * paper,
            100.0 * full,
            100.0 * coverage
        )?;
    }
    outln!(
        "full fits converged: {converged}/{}; intervals available: {with_ci}/{}; {elapsed:.1} s on {threads} threads",
        runs.len(),
        runs.len()
    )?;
    for stop in runs.iter().filter_map(|r| r.stop.as_ref()).take(5) {
        outln!("  not converged: {stop}")?;
    }
    if paper_applied < runs.len() {
        outln!(
            "the paper's method applied to {paper_applied}/{} runs (it needs an overdamped response); the others started from the steady states",
            runs.len()
        )?;
    }
    if !failures.is_empty() {
        outln!(
            "{} of {} runs failed; the first:",
            failures.len(),
            study.runs
        )?;
        for f in failures.iter().take(5) {
            outln!("  {f}")?;
        }
    }
    failed_runs(&failures, study.runs)
}

/// Exit code 3 when any run failed: the table covers only the runs that succeeded.
fn failed_runs(failures: &[String], runs: usize) -> Result<()> {
    if failures.is_empty() {
        return Ok(());
    }
    Err(NotConverged(format!(
        "{} of {runs} runs failed: the results above cover the other {}",
        failures.len(),
        runs - failures.len()
    ))
    .into())
}
