//! `motorid fleet`: a folder of simulated motors (a fleet of axes) for `identify --batch`.
//!
//! Each motor is the base motor with every parameter scaled by a factor drawn log-uniformly in
//! `[1/spread, spread]`; it gets a folder `motor_NNN` holding its truth (`motor.json`) and a
//! high- and a low-voltage step record (`high.csv`, `low.csv`) through the paper's logger
//! (10-bit ADC, 1 LSB of noise, 2000-count encoder). Each record spans 8 slow time constants
//! in about 2000 samples (at least 10 per electrical time constant).

use anyhow::Result;
use motor_model::{Derived, Effects, Input, MotorParams, NoiseRng};

use crate::args::FleetArgs;
use crate::console::outln;
use crate::errors::BadInput;
use crate::progress::Jobs;
use crate::record_csv::write_generated_file;
use crate::settings::Logger;
use crate::simulated::{measured_step, metadata};
use crate::{output, settings};

/// Samples aimed at per record.
const SAMPLES: f64 = 2000.0;
/// Record length in slow time constants.
const TIME_CONSTANTS: f64 = 8.0;
/// Largest `--spread`: parameters from a hundredth to a hundred times the base motor's.
const MAX_SPREAD: f64 = 100.0;
/// Pre-trigger samples before each step.
const PRE_TRIGGER: f64 = 5.0;

/// Record length \[s\] and sample rate \[Hz\] for `motor`.
pub fn record_timing(motor: &MotorParams) -> (f64, f64) {
    let d = Derived::new(motor);
    let slow_rate = if d.zeta > 1.0 {
        d.sigma - d.omega_a
    } else {
        d.sigma
    };
    let duration = TIME_CONSTANTS / slow_rate;
    let rate = (SAMPLES / duration).max(10.0 / d.tau_e);
    (duration, rate)
}

/// The fleet `motorid fleet` writes, validated from its arguments.
pub struct Settings {
    /// Folder the motors go into.
    pub out: std::path::PathBuf,
    /// Number of motors.
    pub motors: usize,
    /// Each parameter is the base motor's times a factor in `[1/spread, spread]` \[-\].
    pub spread: f64,
    /// The base motor.
    pub base: MotorParams,
    /// High-voltage step \[V\].
    pub high_voltage_v: f64,
    /// Low-voltage step \[V\].
    pub low_voltage_v: f64,
    /// Seed of the parameter draws and of the noise.
    pub seed: u64,
    /// No progress messages.
    pub quiet: bool,
}

impl Settings {
    /// The options of `a`, each checked: `--motors` 1–100000, `--spread` 1–[`MAX_SPREAD`],
    /// the step voltages ([`settings::volts`]), `--motor`.
    pub fn from_args(a: &FleetArgs) -> Result<Settings> {
        if a.motors == 0 || a.motors > 100_000 {
            return Err(BadInput(format!("--motors {}: expected 1 to 100000", a.motors)).into());
        }
        if !(a.spread.is_finite() && (1.0..=MAX_SPREAD).contains(&a.spread)) {
            return Err(BadInput(format!(
                "--spread {}: expected a factor from 1 to {MAX_SPREAD}",
                settings::shown(a.spread)
            ))
            .into());
        }
        Ok(Settings {
            high_voltage_v: settings::volts("--high-voltage", a.high_voltage)?,
            low_voltage_v: settings::volts("--low-voltage", a.low_voltage)?,
            base: settings::motor(&a.motor.motor)?,
            out: a.out.clone(),
            motors: a.motors,
            spread: a.spread,
            seed: a.seed,
            quiet: a.quiet,
        })
    }
}

/// Draws the motors and writes each one's truth and step records into its folder.
pub fn run(a: &Settings) -> Result<()> {
    let base = a.base;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| BadInput(format!("cannot create {}: {e}", a.out.display())))?;
    let mut rng = NoiseRng::new(a.seed);
    let width = a.motors.to_string().len().max(3);
    let progress = Jobs::new(a.motors, "motors written", a.quiet);
    for m in 0..a.motors {
        let values = base
            .values()
            .map(|v| v * a.spread.powf(2.0 * rng.uniform() - 1.0));
        let motor = MotorParams::from_values(values).map_err(|e| BadInput(e.to_string()))?;
        let name = format!("motor_{:0width$}", m + 1);
        settings::sane_motor(&motor)
            .map_err(|e| BadInput(format!("{name}: {e}; lower --spread")))?;
        let (duration, rate) = record_timing(&motor);
        // Each drawn motor must break away within its records, or its low step is useless.
        for (option, volts) in [
            ("--high-voltage", a.high_voltage_v),
            ("--low-voltage", a.low_voltage_v),
        ] {
            settings::breakaway_step(option, &motor, volts, duration)
                .map_err(|e| BadInput(format!("{name}: {e:#}")))?;
        }
        let logger = Logger::paper(duration, rate);
        let dir = a.out.join(&name);
        output::create_generated_dir(&dir)?;
        output::write_generated(
            &dir.join("motor.json"),
            serde_json::to_string_pretty(&motor)?.as_bytes(),
        )?;
        for (name, volts, k) in [
            ("high.csv", a.high_voltage_v, 0u64),
            ("low.csv", a.low_voltage_v, 1),
        ] {
            // On the sample grid exactly (the grid is i·(1/rate)): the identification takes the
            // first sample at the new level as the step instant.
            let at = PRE_TRIGGER * (1.0 / rate);
            let seed = a
                .seed
                .wrapping_mul(1_000_003)
                .wrapping_add(2 * m as u64 + k);
            let (rec, measurement) = measured_step(&logger, &motor, volts, at, seed)?;
            let mut meta = metadata(&motor, &Effects::none(), &Input::step(volts, at)?);
            meta[0].1 = "motorid fleet".into();
            meta.push(("measurement".into(), serde_json::to_string(&measurement)?));
            write_generated_file(&dir.join(name), &rec, &meta)?;
        }
        progress.done(m + 1, String::new);
    }
    drop(progress);
    outln!("{} motors in {}", a.motors, a.out.display())?;
    Ok(())
}
