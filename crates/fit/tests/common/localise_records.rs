//! Simulated step records of a small servo for the localisation's tests, example and bench:
//! the data from a motor with (or without) unmodelled effects through the paper's logger, the
//! prediction from the nominal model with the true parameters.

#![allow(dead_code)]

use fit::diagnose::localise::{ResidualChannel, ResidualRecord};
use fit::Channel;
use motor_model::{
    central_difference, Effects, Input, MeasurementModel, MotorParams, Simulator, SpeedSource,
    Trace,
};

/// Sample rate \[Hz\].
pub const RATE_HZ: f64 = 2000.0;
/// Record length \[s\]: 5,000 samples at [`RATE_HZ`].
pub const DURATION_S: f64 = 2.4996;
/// Pre-trigger samples at 0 V \[s\].
pub const PRE_TRIGGER_S: f64 = 0.05;

/// A small servo: R 2 Ω, L 10 mH (τe = 5 ms), k 0.03 N·m/A, f 2e-5 N·m·s/rad, J 2e-5 kg·m²,
/// Ts 2 mN·m.
pub fn servo() -> MotorParams {
    MotorParams::new(2.0, 0.01, 0.03, 2e-5, 2e-5, 0.002).expect("valid motor")
}

/// A measured record and the nominal model's prediction of it.
pub struct Simulated {
    /// Name.
    pub name: String,
    /// Sample period \[s\].
    pub dt: f64,
    /// Measured voltage \[V\].
    pub voltage: Vec<f64>,
    /// Measured current \[A\].
    pub current: Vec<f64>,
    /// Speed \[rad/s\] (encoder or tachometer).
    pub speed: Vec<f64>,
    /// Encoder angle \[rad\].
    pub angle: Vec<f64>,
    /// Model current \[A\].
    pub model_current: Vec<f64>,
    /// Model speed: the central difference of the model's angle for an encoder speed
    /// \[rad/s\].
    pub model_speed: Vec<f64>,
    /// The speed channel's kind.
    pub speed_kind: Channel,
}

/// The stick-slip simulator for data and model alike (the analytic step response of
/// `simulate` differs from it by the integration error, which is not a gap).
fn run(motor: &MotorParams, effects: Effects, input: &Input) -> Trace {
    Simulator::new(*motor, effects, input.clone())
        .and_then(|s| s.run(DURATION_S, RATE_HZ))
        .expect("simulation")
}

impl Simulated {
    /// A step of `volts` on the servo with `effects`, measured by the paper's logger (10-bit
    /// ADC, 1 LSB of noise, 2000-count encoder) with `seed`.
    pub fn step(name: &str, volts: f64, effects: Effects, seed: u64) -> Self {
        let input = Input::step(volts, PRE_TRIGGER_S).expect("step");
        Self::driven(name, &input, effects, seed)
    }

    /// `input` on the servo with `effects`, measured as [`Simulated::step`].
    pub fn driven(name: &str, input: &Input, effects: Effects, seed: u64) -> Self {
        Self::measured_by(name, input, effects, |t| {
            MeasurementModel::paper_logger(t, seed)
        })
    }

    /// `input` on the servo with `effects`, measured by the chain `logger` makes for the
    /// trace; a tachometer speed is the channel [`Channel::Speed`], an encoder speed
    /// [`Channel::EncoderSpeed`].
    pub fn measured_by(
        name: &str,
        input: &Input,
        effects: Effects,
        logger: impl Fn(&Trace) -> MeasurementModel,
    ) -> Self {
        let motor = servo();
        let truth = run(&motor, effects, input);
        let nominal = run(&motor, Effects::none(), input);
        let chain = logger(&truth);
        let rec = chain.apply(&truth).expect("measurement");
        let tacho = chain.speed_source == SpeedSource::Tacho;
        Simulated {
            name: name.to_string(),
            dt: 1.0 / RATE_HZ,
            voltage: rec.voltage,
            current: rec.current,
            speed: rec.speed.expect("encoder speed"),
            angle: rec.position.expect("angle"),
            model_current: nominal.current,
            model_speed: if tacho {
                nominal.speed
            } else {
                central_difference(&nominal.t, &nominal.position)
            },
            speed_kind: if tacho {
                Channel::Speed
            } else {
                Channel::EncoderSpeed
            },
        }
    }

    /// The record for [`fit::diagnose::localise::localise`]: current and speed.
    pub fn record(&self) -> ResidualRecord<'_> {
        ResidualRecord {
            name: &self.name,
            dt: self.dt,
            voltage: &self.voltage,
            current: Some(&self.current),
            speed: Some(&self.speed),
            angle: Some(&self.angle),
            channels: vec![
                ResidualChannel {
                    kind: Channel::Current,
                    measured: &self.current,
                    model: &self.model_current,
                },
                ResidualChannel {
                    kind: self.speed_kind,
                    measured: &self.speed,
                    model: &self.model_speed,
                },
            ],
        }
    }
}
