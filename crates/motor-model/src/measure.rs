//! Measurement models: what the data logger does to the plant's signals.
//!
//! Separate from the plant on purpose: the same [`crate::Trace`] can be seen through an ideal
//! instrument or through the paper's logger (10-bit ADC over 0–5 V conditioned ranges, a
//! noisy tachometer, a quadrature encoder).

use serde::{Deserialize, Serialize};

use crate::error::{positive, ModelError};
use crate::rng::NoiseRng;
use crate::sim::trace::Trace;

/// Physical range \[lo, hi\] (SI units) mapped by a channel's signal conditioning onto the
/// ADC's 0–5 V input; values outside clip at the rails.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Range {
    /// Value at 0 V (ADC count 0).
    pub lo: f64,
    /// Value at full scale (ADC count 2^bits − 1).
    pub hi: f64,
}

impl Range {
    /// A validated range: finite, `lo < hi`.
    pub fn new(lo: f64, hi: f64) -> Result<Self, ModelError> {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(ModelError::InvalidSetting {
                name: format!("range [{lo}, {hi}]"),
                value: hi - lo,
                expected: "finite bounds with lo < hi",
            });
        }
        Ok(Range { lo, hi })
    }

    /// A range covering `[min, max]` of `values` with 20 % headroom each side.
    pub fn covering(values: &[f64]) -> Self {
        let (mut lo, mut hi) = values
            .iter()
            .filter(|v| v.is_finite())
            .fold((0.0_f64, 0.0_f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        if hi - lo <= 0.0 {
            hi = lo + 1.0;
        }
        let pad = 0.2 * (hi - lo);
        if lo < 0.0 {
            lo -= pad;
        }
        Range { lo, hi: hi + pad }
    }
}

/// An ADC of `bits` resolution \[-\] shared by all analog channels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Adc {
    /// Resolution in bits (the PIC 16F877: 10).
    pub bits: u8,
}

impl Adc {
    /// The largest count, `2^bits − 1`.
    pub fn full_scale_counts(&self) -> u32 {
        (1u32 << self.bits.min(31)) - 1
    }

    /// Converts a physical value to ADC counts through `range`, clipping at the rails.
    pub fn to_counts(&self, range: Range, value: f64) -> u32 {
        let fs = f64::from(self.full_scale_counts());
        let c = ((value - range.lo) / (range.hi - range.lo) * fs).round();
        if c.is_nan() {
            0
        } else {
            c.clamp(0.0, fs) as u32
        }
    }

    /// Converts ADC counts back to the physical value through `range`.
    pub fn to_value(&self, range: Range, counts: u32) -> f64 {
        let fs = f64::from(self.full_scale_counts());
        range.lo + f64::from(counts) / fs * (range.hi - range.lo)
    }

    /// One least significant bit of `range` in its physical unit.
    pub fn lsb(&self, range: Range) -> f64 {
        (range.hi - range.lo) / f64::from(self.full_scale_counts())
    }
}

/// Where the record's speed column comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpeedSource {
    /// The plant's speed, through the analog chain (tachometer: noise, ADC).
    Tacho,
    /// Central difference of the quantised encoder angle, as the paper did.
    Encoder,
    /// No speed column.
    Omit,
}

/// A measurement chain applied to a simulated [`Trace`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasurementModel {
    /// ADC resolution, or `None` for unquantised values.
    pub adc: Option<Adc>,
    /// Conditioning ranges of voltage \[V\], current \[A\], tacho speed \[rad/s\]; `None` = chosen
    /// from the signal with [`Range::covering`].
    pub ranges: [Option<Range>; 3],
    /// Standard deviation of additive white noise on voltage \[V\], current \[A\] and tacho speed
    /// \[rad/s\], before quantisation.
    pub noise_std: [f64; 3],
    /// Encoder counts per revolution after quadrature decoding, or `None` for no encoder: an
    /// ideal chain ([`MeasurementModel::is_ideal`]) then records the exact angle, any other no
    /// angle at all. A record read through an ADC or with noise that carried the exact angle
    /// beside its channels is no bench's record, and the fits would weight that angle far above
    /// every measured channel: with a noise-free 10-bit ADC, `identify --record` put Ts 10 of
    /// its half-widths from the truth on such a record, and was right once the angle came from
    /// an encoder or the speed from the tachometer.
    pub encoder_counts_per_rev: Option<u32>,
    /// Source of the speed column.
    pub speed_source: SpeedSource,
    /// Seed of the noise generator: the same seed gives the same record, sample for sample.
    pub seed: u64,
}

impl Default for MeasurementModel {
    /// An ideal instrument: no ADC, no noise, exact angle, true speed.
    fn default() -> Self {
        MeasurementModel {
            adc: None,
            ranges: [None; 3],
            noise_std: [0.0; 3],
            encoder_counts_per_rev: None,
            speed_source: SpeedSource::Tacho,
            seed: 1,
        }
    }
}

/// A measured record in the units of SPEC section 4, ready to be written as CSV.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Record {
    /// Sample times \[s\], strictly increasing.
    pub t: Vec<f64>,
    /// Armature voltage \[V\].
    pub voltage: Vec<f64>,
    /// Armature current \[A\].
    pub current: Vec<f64>,
    /// Speed \[rad/s\], if recorded.
    pub speed: Option<Vec<f64>>,
    /// Angle \[rad\], if recorded.
    pub position: Option<Vec<f64>>,
    /// Samples of each analog channel (voltage, current, speed) that sat on an ADC rail.
    pub clipped: [usize; 3],
}

impl MeasurementModel {
    /// Whether the chain measures exactly: no ADC, no noise, no encoder (the exact angle).
    pub fn is_ideal(&self) -> bool {
        self.adc.is_none()
            && self.noise_std.iter().all(|&s| s == 0.0)
            && self.encoder_counts_per_rev.is_none()
    }

    /// A data logger: a `bits`-bit ADC over `ranges` (voltage \[V\], current \[A\], tachometer
    /// \[rad/s\]) with `noise_lsb` LSB of white noise on each analog channel, an encoder of
    /// `counts_per_rev` counts, and the speed from the encoder (as the paper's logger, whose
    /// tachometer was too noisy).
    pub fn logger(
        bits: u8,
        ranges: [Range; 3],
        noise_lsb: f64,
        counts_per_rev: u32,
        seed: u64,
    ) -> Self {
        let adc = Adc { bits };
        MeasurementModel {
            adc: Some(adc),
            ranges: ranges.map(Some),
            noise_std: ranges.map(|r| noise_lsb * adc.lsb(r)),
            encoder_counts_per_rev: Some(counts_per_rev),
            speed_source: SpeedSource::Encoder,
            seed,
        }
    }

    /// The paper's logger on `trace`: [`MeasurementModel::logger`] with a 10-bit ADC over ranges
    /// covering the trace's signals ([`Range::covering`]), 1 LSB of noise and a 2000-count
    /// encoder.
    pub fn paper_logger(trace: &Trace, seed: u64) -> Self {
        let ranges = [&trace.voltage, &trace.current, &trace.speed].map(|s| Range::covering(s));
        Self::logger(10, ranges, 1.0, 2000, seed)
    }

    /// Measures `trace` through this chain.
    pub fn apply(&self, trace: &Trace) -> Result<Record, ModelError> {
        for (name, s) in ["voltage", "current", "speed"].iter().zip(self.noise_std) {
            if !(s.is_finite() && s >= 0.0) {
                return Err(ModelError::InvalidSetting {
                    name: format!("{name} noise"),
                    value: s,
                    expected: "a finite standard deviation of zero or more",
                });
            }
        }
        if let Some(cpr) = self.encoder_counts_per_rev {
            positive("encoder counts per revolution", f64::from(cpr))?;
        }
        let mut rng = NoiseRng::new(self.seed);
        let mut clipped = [0usize; 3];
        let position = match self.encoder_counts_per_rev {
            Some(cpr) => {
                let quantum = std::f64::consts::TAU / f64::from(cpr);
                trace
                    .position
                    .iter()
                    .map(|th| (th / quantum).floor() * quantum)
                    .collect()
            }
            None => trace.position.clone(),
        };
        let mut channel = |idx: usize, values: &[f64]| -> Vec<f64> {
            let range = self.ranges[idx].unwrap_or_else(|| Range::covering(values));
            values
                .iter()
                .map(|&v| {
                    let noisy = v + self.noise_std[idx] * rng.normal();
                    match self.adc {
                        Some(adc) => {
                            let c = adc.to_counts(range, noisy);
                            if c == 0 || c == adc.full_scale_counts() {
                                clipped[idx] += 1;
                            }
                            adc.to_value(range, c)
                        }
                        None => noisy,
                    }
                })
                .collect()
        };
        let voltage = channel(0, &trace.voltage);
        let current = channel(1, &trace.current);
        let speed = match self.speed_source {
            SpeedSource::Tacho => Some(channel(2, &trace.speed)),
            SpeedSource::Encoder => Some(central_difference(&trace.t, &position)),
            SpeedSource::Omit => None,
        };
        Ok(Record {
            t: trace.t.clone(),
            voltage,
            current,
            speed,
            position: (self.encoder_counts_per_rev.is_some() || self.is_ideal())
                .then_some(position),
            clipped,
        })
    }
}

/// The raw readings a data logger stores for a measured trace: ADC codes of voltage, current
/// and tachometer speed, and the encoder count (not wrapped: a logger's counter keeps its low
/// bits).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Readings {
    /// ADC codes of voltage, current and tachometer speed.
    pub adc: [Vec<u32>; 3],
    /// Encoder counts, `⌊θ/(2π/cpr)⌋`.
    pub encoder: Vec<i64>,
}

impl MeasurementModel {
    /// The readings behind [`MeasurementModel::apply`]: the same noise draws in the same
    /// order (all voltage samples, then current, then the tachometer), the same quantisation,
    /// so that converting them back (`Adc::to_value`, `count · 2π/cpr`) gives `apply`'s record
    /// bit for bit. Needs an ADC, ranges for the three channels and an encoder.
    pub fn readings(&self, trace: &Trace) -> Result<Readings, ModelError> {
        let missing = |what: &str| ModelError::InvalidSetting {
            name: what.into(),
            value: 0.0,
            expected: "an ADC, the three conditioning ranges and an encoder for logger readings",
        };
        let adc = self.adc.ok_or_else(|| missing("adc"))?;
        let cpr = self
            .encoder_counts_per_rev
            .ok_or_else(|| missing("encoder"))?;
        positive("encoder counts per revolution", f64::from(cpr))?;
        let mut rng = NoiseRng::new(self.seed);
        let mut channel = |idx: usize, values: &[f64]| -> Result<Vec<u32>, ModelError> {
            let range = self.ranges[idx].ok_or_else(|| missing("range"))?;
            Ok(values
                .iter()
                .map(|&v| adc.to_counts(range, v + self.noise_std[idx] * rng.normal()))
                .collect())
        };
        let voltage = channel(0, &trace.voltage)?;
        let current = channel(1, &trace.current)?;
        let speed = channel(2, &trace.speed)?;
        let quantum = std::f64::consts::TAU / f64::from(cpr);
        Ok(Readings {
            adc: [voltage, current, speed],
            encoder: trace
                .position
                .iter()
                .map(|th| (th / quantum).floor() as i64)
                .collect(),
        })
    }
}

/// Mean sample period of `t` \[s\]: `(t_last − t_first)/(n − 1)`; NaN with fewer than two
/// samples.
pub fn mean_period(t: &[f64]) -> f64 {
    match (t.first(), t.last()) {
        (Some(first), Some(last)) if t.len() > 1 => (last - first) / (t.len() - 1) as f64,
        _ => f64::NAN,
    }
}

/// Derivative of `y` over `t` by central differences (one-sided at the ends) \[unit of y / s\].
pub fn central_difference(t: &[f64], y: &[f64]) -> Vec<f64> {
    difference_over(t, y, 1)
}

/// Derivative of `y` over `t` by differences over ±`m` samples (`m` = 1: the central
/// difference), one-sided within `m` samples of the ends \[unit of y / s\]; 0 where the time
/// span is not positive. As long as the shorter of `t` and `y`.
pub fn difference_over(t: &[f64], y: &[f64], m: usize) -> Vec<f64> {
    let n = t.len().min(y.len());
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(m), (i + m).min(n.saturating_sub(1)));
            let span = t[b] - t[a];
            if span > 0.0 {
                (y[b] - y[a]) / span
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod readings_tests {
    use super::*;
    use crate::{MotorParams, StepResponse};

    #[test]
    fn readings_convert_back_to_the_applied_record_bit_for_bit() {
        let trace = StepResponse::new(&MotorParams::paper(), 40.0)
            .trace(0.0, 2.0, 1000.0)
            .unwrap();
        let adc = Adc { bits: 10 };
        let ranges = [
            Range::new(-50.0, 50.0).unwrap(),
            Range::new(-200.0, 200.0).unwrap(),
            Range::new(-250.0, 250.0).unwrap(),
        ];
        let model = MeasurementModel::logger(10, ranges, 1.0, 2000, 7);
        let record = model.apply(&trace).unwrap();
        let readings = model.readings(&trace).unwrap();
        let back = |c: usize| -> Vec<f64> {
            readings.adc[c]
                .iter()
                .map(|&k| adc.to_value(ranges[c], k))
                .collect()
        };
        assert_eq!(back(0), record.voltage);
        assert_eq!(back(1), record.current);
        let quantum = std::f64::consts::TAU / 2000.0;
        let position: Vec<f64> = readings
            .encoder
            .iter()
            .map(|&k| k as f64 * quantum)
            .collect();
        assert_eq!(Some(&position), record.position.as_ref());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Effects, Input, MotorParams, Simulator};

    fn trace() -> Trace {
        Simulator::new(
            MotorParams::paper(),
            Effects::none(),
            Input::step(40.0, 0.0).unwrap(),
        )
        .unwrap()
        .run(5.0, 1000.0)
        .unwrap()
    }

    #[test]
    fn adc_round_trip_is_within_half_an_lsb_and_clips_at_the_rails() {
        let adc = Adc { bits: 10 };
        let range = Range::new(-10.0, 10.0).unwrap();
        assert_eq!(adc.full_scale_counts(), 1023);
        for v in [-9.99, -1.0, 0.0, 0.123, 9.9] {
            let back = adc.to_value(range, adc.to_counts(range, v));
            assert!((back - v).abs() <= 0.5 * adc.lsb(range) + 1e-12);
        }
        assert_eq!(adc.to_counts(range, 50.0), 1023);
        assert_eq!(adc.to_counts(range, -50.0), 0);
        assert_eq!(adc.to_counts(range, f64::NAN), 0);
    }

    #[test]
    fn same_seed_same_record_and_clipping_is_counted() {
        let tr = trace();
        let model = MeasurementModel {
            adc: Some(Adc { bits: 10 }),
            ranges: [None, Some(Range::new(0.0, 60.0).unwrap()), None],
            noise_std: [0.01, 0.05, 0.1],
            encoder_counts_per_rev: Some(2000),
            speed_source: SpeedSource::Encoder,
            seed: 7,
        };
        let a = model.apply(&tr).unwrap();
        let b = model.apply(&tr).unwrap();
        assert_eq!(a, b);
        let c = MeasurementModel {
            seed: 8,
            ..model.clone()
        }
        .apply(&tr)
        .unwrap();
        assert_ne!(a.current, c.current);
        // The current peaks at about 115 A: the 0-60 A channel clips.
        assert!(a.clipped[1] > 100, "{:?}", a.clipped);
        assert_eq!(a.clipped[0], 0);
        // Encoder angle is a whole number of counts.
        let quantum = std::f64::consts::TAU / 2000.0;
        for th in a.position.as_ref().unwrap() {
            assert!(((th / quantum) - (th / quantum).round()).abs() < 1e-6);
        }
    }

    #[test]
    fn ideal_measurement_is_the_trace() {
        let tr = trace();
        let r = MeasurementModel::default().apply(&tr).unwrap();
        assert_eq!(r.current, tr.current);
        assert_eq!(r.speed.as_ref().unwrap(), &tr.speed);
        assert_eq!(r.clipped, [0, 0, 0]);
    }

    #[test]
    fn noise_has_the_requested_spread() {
        let mut rng = NoiseRng::new(3);
        let n = 100_000;
        let xs: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        // 5 standard errors: mean ± 0.016, variance ± 0.022.
        assert!(
            mean.abs() < 0.016 && (var - 1.0).abs() < 0.022,
            "{mean} {var}"
        );
    }
}
