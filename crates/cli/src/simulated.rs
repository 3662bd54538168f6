//! The simulated data logger of `montecarlo`, `fleet` and `demo`: a step on a motor recorded
//! through [`MeasurementModel::logger`], and the metadata that describes a simulated record.

use anyhow::Result;
use motor_model::{Adc, Effects, Input, MeasurementModel, MotorParams, Range, Record};

use crate::errors::BadInput;
use crate::settings::Logger;
use crate::steps::{step_from_record_with, LoadedStep};

/// A step of `volts` at `at_s` \[s\] on `motor` recorded by `logger` with noise seed `seed`,
/// with the measurement chain used.
pub fn measured_step(
    logger: &Logger,
    motor: &MotorParams,
    volts: f64,
    at_s: f64,
    seed: u64,
) -> Result<(Record, MeasurementModel)> {
    measured_step_with(
        logger,
        (None, 1.0),
        motor,
        volts,
        StepTiming::step(at_s),
        seed,
    )
}

/// When a simulated step is applied and, for a step that returns to 0 V, when it ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepTiming {
    /// Step instant \[s\] from the record's start.
    pub at_s: f64,
    /// Instant the voltage returns to 0 V \[s\] from the record's start, if it does.
    pub fall_at_s: Option<f64>,
}

impl StepTiming {
    /// A step at `at_s` \[s\] held to the record's end.
    pub fn step(at_s: f64) -> Self {
        StepTiming {
            at_s,
            fall_at_s: None,
        }
    }

    /// The voltage waveform of a step of `volts` \[V\] with this timing.
    fn input(self, volts: f64) -> Result<Input> {
        match self.fall_at_s {
            None => Input::step(volts, self.at_s),
            Some(fall) => Input::piecewise(&[(self.at_s, volts), (fall, 0.0)]),
        }
        .map_err(|e| BadInput(e.to_string()).into())
    }
}

/// [`measured_step`] with `voltage_noise_lsb` \[LSB\] of noise on the voltage channel instead
/// of the logger's `noise_lsb`, if given, every conditioning range stretched by `range_scale`
/// \[-\] (≥ 1: the signals sit elsewhere between the ADC's codes), and the step's `timing`
/// (a return to 0 V included: the exact response of the piecewise-constant voltage,
/// [`motor_model::simulate`]).
pub fn measured_step_with(
    logger: &Logger,
    (voltage_noise_lsb, range_scale): (Option<f64>, f64),
    motor: &MotorParams,
    volts: f64,
    timing: StepTiming,
    seed: u64,
) -> Result<(Record, MeasurementModel)> {
    let trace = motor_model::simulate(
        motor,
        Effects::none(),
        &timing.input(volts)?,
        logger.duration_s,
        logger.rate_hz,
    )
    .map_err(|e| BadInput(e.to_string()))?;
    let mut ranges = [&trace.voltage, &trace.current, &trace.speed].map(|s| Range::covering(s));
    for r in &mut ranges {
        *r = Range::new(r.lo * range_scale, r.hi * range_scale)
            .map_err(|e| BadInput(e.to_string()))?;
    }
    let mut model = MeasurementModel::logger(
        logger.adc_bits,
        ranges,
        logger.noise_lsb,
        logger.encoder_cpr,
        seed,
    );
    if let Some(lsb) = voltage_noise_lsb {
        let adc = Adc {
            bits: logger.adc_bits,
        };
        model.noise_std[0] = lsb * adc.lsb(ranges[0]);
    }
    let rec = model.apply(&trace).map_err(|e| BadInput(e.to_string()))?;
    Ok((rec, model))
}

/// A step of `volts` on `motor` recorded by `logger` with noise seed `seed`, located.
pub fn record(logger: &Logger, motor: &MotorParams, volts: f64, seed: u64) -> Result<LoadedStep> {
    record_at(
        logger,
        (None, 1.0),
        motor,
        volts,
        StepTiming::step(0.0),
        seed,
    )
}

/// A step of `volts` with `timing` on `motor` recorded by `logger` (with `voltage_noise_lsb`
/// on the voltage if given, ranges stretched by `range_scale`) with noise seed `seed`,
/// located.
pub fn record_at(
    logger: &Logger,
    chain: (Option<f64>, f64),
    motor: &MotorParams,
    volts: f64,
    timing: StepTiming,
    seed: u64,
) -> Result<LoadedStep> {
    let (rec, model) = measured_step_with(logger, chain, motor, volts, timing, seed)?;
    let lsb = |c: usize| model.adc.zip(model.ranges[c]).map(|(adc, r)| adc.lsb(r));
    let mut step = step_from_record_with(
        format!("simulated {volts} V record (seed {seed})"),
        rec,
        lsb(0),
        None,
    )?;
    step.inputs.current_lsb_a = lsb(1).unwrap_or(0.0);
    Ok(step)
}

/// Metadata lines describing a simulated record.
pub fn metadata(motor: &MotorParams, effects: &Effects, input: &Input) -> Vec<(String, String)> {
    let input_text = match input {
        Input::Step { volts, at_s } => format!("step {volts} V at {at_s} s"),
        Input::Sine {
            amplitude_v,
            frequency_hz,
        } => format!("sine {amplitude_v} V, {frequency_hz} Hz"),
        Input::Piecewise { times_s, volts } => {
            let levels: Vec<String> = times_s
                .iter()
                .zip(volts)
                .map(|(t, v)| format!("{t}:{v}"))
                .collect();
            format!("levels {}", levels.join(","))
        }
        Input::Sampled { volts, dt_s, .. } => {
            format!("sampled, {} samples every {dt_s} s", volts.len())
        }
    };
    let effect_text = if effects.is_nominal() {
        "none".to_string()
    } else {
        effects
            .list()
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    };
    vec![
        ("source".into(), "motorid simulate".into()),
        (
            "motor".into(),
            serde_json::to_string(motor).unwrap_or_default(),
        ),
        ("input".into(), input_text),
        ("effects".into(), effect_text),
    ]
}
