//! `motorid simulate`: a record of a simulated test.

use anyhow::Result;
use motor_model::{Effects, Input, MotorParams, Simulator, StepResponse, Trace};

use crate::args::{SimulateArgs, SolverArg};
use crate::errors::BadInput;
use crate::progress::Phases;
use crate::settings::MeasurementOptions;
use crate::{record_csv, settings};

/// The solver `--solver` asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// The exact closed-form step response (a step on the nominal model only).
    Analytic,
    /// The stick-slip RK4 simulation (any waveform, effects).
    Ode,
}

/// What `motorid simulate` simulates, measures and writes, validated from its arguments.
pub struct Settings {
    /// The simulated motor.
    pub motor: MotorParams,
    /// Record length \[s\].
    pub duration_s: f64,
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// The input waveform.
    pub input: Input,
    /// Unmodelled effects in the plant.
    pub effects: Effects,
    /// The solver asked for; `None`: the exact response when it applies.
    pub solver: Option<Solver>,
    /// How the logger sees the plant.
    pub measurement: MeasurementOptions,
    /// The record file; `None`: standard output.
    pub output: Option<std::path::PathBuf>,
    /// No progress or summary on standard error.
    pub quiet: bool,
}

impl Settings {
    /// The options of `a`, each checked in the order the command line reads them: motor,
    /// record grid, input, effects, measurement chain.
    pub fn from_args(a: &SimulateArgs) -> Result<Settings> {
        let motor = settings::motor(&a.motor.motor)?;
        let (duration_s, rate_hz) = settings::record_grid(a.duration, a.rate)?;
        let input = settings::input(settings::InputSpec {
            voltage: a.voltage,
            sine: a.sine.as_deref(),
            levels: a.levels.as_deref(),
            prbs: a.prbs.as_deref(),
            step_at: a.step_at,
            duration: duration_s,
            rate: rate_hz,
        })?;
        let effects = settings::effects(&a.effects)?;
        Ok(Settings {
            motor,
            duration_s,
            rate_hz,
            input,
            effects,
            solver: a.solver.map(|solver| match solver {
                SolverArg::Analytic => Solver::Analytic,
                SolverArg::Ode => Solver::Ode,
            }),
            measurement: MeasurementOptions::from_args(&a.measurement)?,
            output: a.output.clone().filter(|path| path.as_os_str() != "-"),
            quiet: a.quiet,
        })
    }
}

/// Simulates `input` on `motor` with `effects`, choosing the solver: the exact analytic step
/// response when asked for (or by default when it applies), the stick-slip ODE otherwise.
pub fn trace(
    motor: &MotorParams,
    effects: Effects,
    input: &Input,
    solver: Option<Solver>,
    duration_s: f64,
    rate_hz: f64,
) -> Result<Trace> {
    let result = match (solver, input) {
        (None, _) => motor_model::simulate(motor, effects, input, duration_s, rate_hz),
        (Some(Solver::Analytic), Input::Step { volts, at_s }) if effects.is_nominal() => {
            StepResponse::new(motor, *volts).trace(*at_s, duration_s, rate_hz)
        }
        (Some(Solver::Analytic), _) => {
            return Err(BadInput(
                "--solver analytic covers a voltage step on the nominal model only; use --solver ode for a sine or for --effect".into(),
            )
            .into())
        }
        (Some(Solver::Ode), _) => Simulator::new(*motor, effects, input.clone())
            .and_then(|sim| sim.run(duration_s, rate_hz)),
    };
    result.map_err(|e| BadInput(e.to_string()).into())
}

/// Simulates the test, measures it through the logger and writes the record.
pub fn run(a: &Settings) -> Result<()> {
    let (motor, input, effects) = (&a.motor, &a.input, a.effects);
    let (duration_s, rate_hz) = (a.duration_s, a.rate_hz);
    let phases = Phases::start("simulate", a.quiet);
    let samples = (duration_s * rate_hz).floor() as u64 + 1;
    let analytic = matches!(
        (a.solver, input),
        (None | Some(Solver::Analytic), Input::Step { .. })
    ) && effects.is_nominal();
    phases.enter(format!(
        "simulating {samples} samples ({})",
        if analytic {
            "exact step response"
        } else {
            "stick-slip ODE"
        }
    ));
    let trace = trace(motor, effects, input, a.solver, duration_s, rate_hz)?;
    phases.enter(format!("measuring {samples} samples"));
    let measurement = a.measurement.model(&trace);
    let record = measurement
        .apply(&trace)
        .map_err(|e| BadInput(e.to_string()))?;
    phases.enter(format!(
        "writing {samples} samples to {}",
        match a.output.as_deref() {
            Some(path) => path.display().to_string(),
            None => "standard output".into(),
        }
    ));
    let mut meta = crate::simulated::metadata(motor, &effects, input);
    let ideal = measurement.is_ideal();
    meta.push((
        "measurement".into(),
        if ideal {
            crate::record_checks::IDEAL_MEASUREMENT.into()
        } else {
            serde_json::to_string(&measurement).unwrap_or_default()
        },
    ));
    match a.output.as_deref() {
        Some(path) => {
            record_csv::write_file(path, &record, &meta)?;
            drop(phases);
            // Samples at a non-zero rail, as `identify` will find them (a signal at rest on a
            // unipolar range sits on its zero rail: that is not lost information).
            let clipped: usize = match measurement.adc {
                Some(adc) => [
                    Some(&record.voltage),
                    Some(&record.current),
                    record.speed.as_ref(),
                ]
                .iter()
                .zip(measurement.ranges)
                .filter_map(|(col, range)| Some((col.as_ref()?, range?)))
                .map(|(col, r)| {
                    fit::find_clipping(col, Some([r.lo, r.hi]), 0.5 * adc.lsb(r))
                        .iter()
                        .filter(|&&c| c)
                        .count()
                })
                .sum(),
                None => 0,
            };
            if a.quiet {
                return Ok(());
            }
            crate::console::errln!(
                "wrote {} samples ({} s at {} Hz) to {}{}",
                record.t.len(),
                a.duration_s,
                a.rate_hz,
                path.display(),
                if clipped > 0 {
                    format!("; {clipped} samples sit on an ADC rail (clipped): widen --range-*")
                } else {
                    String::new()
                }
            );
        }
        None => {
            record_csv::write_file(std::path::Path::new("-"), &record, &meta)?;
            drop(phases);
        }
    }
    Ok(())
}
