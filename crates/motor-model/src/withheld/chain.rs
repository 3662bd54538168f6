//! The benchmark's measurement chain: coloured noise added here, then the ADC, the ranges and
//! the encoder of [`crate::MeasurementModel`].

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::measure::{Adc, MeasurementModel, Range, Record, SpeedSource};
use crate::rng::NoiseRng;
use crate::sim::trace::Trace;

/// How the speed is sensed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "sensor", rename_all = "snake_case", deny_unknown_fields)]
pub enum SpeedSensor {
    /// A quadrature encoder: the record has the quantised angle and its central difference as
    /// speed.
    Encoder {
        /// Counts per revolution after quadrature decoding \[-\].
        counts_per_rev: u32,
    },
    /// A tachometer through the ADC with its own noise; the record has no angle.
    Tachometer {
        /// Standard deviation of the tachometer's noise \[LSB of the speed range\].
        noise_lsb: f64,
    },
}

/// Additive noise on the analog channels: AR(1), `e_k = ρ e_{k−1} + √(1 − ρ²) σ w_k`
/// (stationary standard deviation σ; white when ρ = 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Standard deviation σ on voltage and current \[LSB of each channel's range\].
    pub lsb: f64,
    /// Pole ρ of the AR(1) process \[-\], in \[0, 1).
    pub ar1_pole: f64,
}

/// The logger's settings for one case.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSpec {
    /// ADC resolution \[bits\].
    pub adc_bits: u8,
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// Samples recorded at 0 V before each step or waveform starts \[-\] (the step falls
    /// between the last of them and the next sample: the logger's clock is not synchronised
    /// with it).
    pub pre_trigger_samples: usize,
    /// Noise on the analog channels.
    pub noise: NoiseSpec,
    /// The speed sensor.
    pub speed_sensor: SpeedSensor,
}

/// Conditioning ranges of one record's analog channels (SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelRanges {
    /// Armature voltage range \[V\].
    pub voltage: Range,
    /// Current range \[A\].
    pub current: Range,
    /// Tachometer range \[rad/s\] (unused with an encoder).
    pub speed: Range,
}

/// The noise floor of each compared channel: the RMS error a perfect model would still show.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NoiseFloors {
    /// Current \[A\]: `√(σ² + q²/12)`, q one LSB.
    pub current_a: f64,
    /// Speed \[rad/s\]: tachometer `√(σ² + q²/12)`; encoder `Δθ/(Δt √24)` (the central
    /// difference of two independent uniform quantisation errors of one count Δθ).
    pub speed_rad_s: f64,
}

/// The negative part of a range kept for a signal that never goes negative, as a fraction of
/// its span \[-\]: noise around 0 is not clipped.
const RANGE_FOOT: f64 = 0.05;

/// A range covering `values` ([`Range::covering`]: 20 % headroom, as an engineer sets a gain)
/// that also reaches a little below zero.
pub(crate) fn range_for(values: &[f64]) -> Range {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((0.0_f64, 0.0_f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    Range::covering(&[lo.min(-RANGE_FOOT * (hi - lo)), hi])
}

impl ChannelRanges {
    /// Ranges covering a plant trace's voltage, current and speed.
    pub fn covering(trace: &Trace) -> Self {
        ChannelRanges {
            voltage: range_for(&trace.voltage),
            current: range_for(&trace.current),
            speed: range_for(&trace.speed),
        }
    }
}

/// One AR(1) noise sequence (see [`NoiseSpec`]).
#[derive(Debug, Clone)]
pub struct ColouredNoise {
    pole: f64,
    std: f64,
    last: Option<f64>,
}

impl ColouredNoise {
    /// A process of pole `pole` ∈ \[0, 1) and stationary standard deviation `std` ≥ 0.
    pub fn new(pole: f64, std: f64) -> Result<Self, ModelError> {
        if !(pole.is_finite() && (0.0..1.0).contains(&pole)) {
            return Err(ModelError::InvalidSetting {
                name: "AR(1) pole".into(),
                value: pole,
                expected: "a pole in [0, 1)",
            });
        }
        crate::error::non_negative("noise standard deviation", std)?;
        Ok(ColouredNoise {
            pole,
            std,
            last: None,
        })
    }

    /// The next value, started in the stationary distribution.
    pub fn next(&mut self, rng: &mut NoiseRng) -> f64 {
        let w = self.std * rng.normal();
        let e = match self.last {
            None => w,
            Some(prev) => self.pole * prev + (1.0 - self.pole * self.pole).sqrt() * w,
        };
        self.last = Some(e);
        e
    }
}

impl MeasurementSpec {
    /// The noise floors of a record measured through `ranges`.
    pub fn floors(&self, ranges: &ChannelRanges) -> NoiseFloors {
        let adc = Adc {
            bits: self.adc_bits,
        };
        let analog = |lsb_noise: f64, range: Range| {
            let q = adc.lsb(range);
            ((lsb_noise * q).powi(2) + q * q / 12.0).sqrt()
        };
        let speed_rad_s = match self.speed_sensor {
            SpeedSensor::Encoder { counts_per_rev } => {
                std::f64::consts::TAU / f64::from(counts_per_rev.max(1)) * self.rate_hz
                    / 24f64.sqrt()
            }
            SpeedSensor::Tachometer { noise_lsb } => analog(noise_lsb, ranges.speed),
        };
        NoiseFloors {
            current_a: analog(self.noise.lsb, ranges.current),
            speed_rad_s,
        }
    }

    /// Measures `trace` through `ranges`: AR(1) noise on voltage, current (and the tachometer),
    /// then [`MeasurementModel::apply`] for the ADC and the encoder. `seed` fixes the noise.
    pub fn measure(
        &self,
        trace: &Trace,
        ranges: &ChannelRanges,
        seed: u64,
    ) -> Result<Record, ModelError> {
        let adc = Adc {
            bits: self.adc_bits,
        };
        let mut rng = NoiseRng::new(seed);
        let mut noisy = trace.clone();
        let mut add = |values: &mut Vec<f64>, lsb_noise: f64, range: Range| {
            let mut noise = ColouredNoise::new(self.noise.ar1_pole, lsb_noise * adc.lsb(range))?;
            for v in values.iter_mut() {
                *v += noise.next(&mut rng);
            }
            Ok::<(), ModelError>(())
        };
        add(&mut noisy.voltage, self.noise.lsb, ranges.voltage)?;
        add(&mut noisy.current, self.noise.lsb, ranges.current)?;
        let (encoder, speed_source) = match self.speed_sensor {
            SpeedSensor::Encoder { counts_per_rev } => (Some(counts_per_rev), SpeedSource::Encoder),
            SpeedSensor::Tachometer { noise_lsb } => {
                add(&mut noisy.speed, noise_lsb, ranges.speed)?;
                (None, SpeedSource::Tacho)
            }
        };
        let chain = MeasurementModel {
            adc: Some(adc),
            ranges: [
                Some(ranges.voltage),
                Some(ranges.current),
                Some(ranges.speed),
            ],
            noise_std: [0.0; 3],
            encoder_counts_per_rev: encoder,
            speed_source,
            seed,
        };
        let mut record = chain.apply(&noisy)?;
        if encoder.is_none() {
            record.position = None;
        }
        Ok(record)
    }
}
