//! Finding the step in a record: the instant, the height and the uniform grid after it.

use crate::error::FitError;
use crate::estimation::records::uniform_period;
use crate::excitation::input_uncertainty::{estimate_level, StepInputs, VoltageScale};

/// Where a voltage step sits in a record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLocation {
    /// Index of the first sample at the new level.
    pub index: usize,
    /// Step height E \[V\]: the level of the voltage after the step ([`crate::estimate_level`]:
    /// the mean, or the censored fit where the level sits at an ADC rail).
    pub volts: f64,
    /// Variance of `volts` \[V²\] (noise, quantisation, rail).
    pub volts_variance_v2: f64,
    /// Its quantiser-bias part \[V²\] ([`crate::LevelEstimate::bias_variance_v2`]).
    pub volts_bias_variance_v2: f64,
    /// The code the step height reads ([`crate::LevelEstimate::bias_code`]).
    pub volts_bias_code: i64,
    /// Sample period \[s\].
    pub dt: f64,
    /// Time of the step \[s\] (the first sample at the new level).
    pub t_step: f64,
    /// Index of the first sample after the step's level, when the voltage comes back down
    /// (below half the step) and stays there to the record's end — a return to 0 V; `None`
    /// when the record ends at the step's level. The step is the samples `index..fall`.
    pub fall: Option<usize>,
}

impl StepLocation {
    /// What the location leaves unknown about the step: its height's variance, and its instant
    /// anywhere in the sample period before the first sample at the new level — when a sample
    /// at the old level precedes it. A record whose first sample is already at the new level
    /// starts at its step (as `motorid simulate --step-at 0` writes it, and as
    /// [`crate::voltage_levels`] takes a level at the first sample): nothing brackets the
    /// instant from before, so it is the first sample's. Taken half a period earlier with the
    /// uniform period's variance, such records put the truth at the edge of that period,
    /// where its Gaussian approximation has no room left for the noise: in the heavy property
    /// run, L's and R's intervals missed on 7 and 8 of 35 accepted step pairs stepping at the
    /// first sample, against 3 and 1 of 36 stepping later.
    pub fn inputs(&self) -> StepInputs {
        let level = crate::LevelEstimate {
            volts: self.volts,
            variance_v2: self.volts_variance_v2,
            bias_variance_v2: self.volts_bias_variance_v2,
            bias_code: self.volts_bias_code,
        };
        if self.index == 0 {
            StepInputs {
                volts_variance_v2: level.variance_v2,
                volts_bias_variance_v2: level.bias_variance_v2,
                volts_bias_code: level.bias_code,
                ..StepInputs::default()
            }
        } else {
            StepInputs::sampled(level, self.dt)
        }
    }
}

/// Locates the voltage step: the first sample whose voltage passes half the median of the
/// record's last half (pre-trigger samples at 0 V are allowed before it), and checks that the
/// time column is strictly increasing and uniform. A record that ends below half its step
/// (the voltage returned to 0 V) is measured on its peak level instead (the median of the
/// samples beyond half its largest |voltage|), and the return is located
/// ([`StepLocation::fall`]); the step must hold in between. The voltage's ADC step is found from the
/// column if it can be ([`VoltageScale::of`]); [`locate_step_with`] takes it from elsewhere.
pub fn locate_step(t: &[f64], voltage: &[f64]) -> Result<StepLocation, FitError> {
    locate_step_with(t, voltage, None)
}

/// [`locate_step`] with the voltage's ADC step `quantum_v` \[V\] if known (e.g. from the
/// record's metadata): a noise-free quantised level is known only to ±½ step.
pub fn locate_step_with(
    t: &[f64],
    voltage: &[f64],
    quantum_v: Option<f64>,
) -> Result<StepLocation, FitError> {
    let bad = |series: &str, reason: String| FitError::BadData {
        series: series.into(),
        reason,
    };
    if t.len() != voltage.len() || t.len() < 8 {
        return Err(bad(
            "record",
            format!(
                "{} samples: at least 8 are needed",
                t.len().min(voltage.len())
            ),
        ));
    }
    let mut tail: Vec<f64> = voltage[voltage.len() / 2..].to_vec();
    let mid = tail.len() / 2;
    let end = *tail.select_nth_unstable_by(mid, f64::total_cmp).1;
    let level = if end.is_finite() && end.abs() >= 0.5 * peak_level(voltage).abs() {
        end
    } else {
        // The record ends below half its step: the voltage came back down (a return to 0 V).
        peak_level(voltage)
    };
    if !(level.abs() > 0.0 && level.is_finite()) {
        return Err(bad(
            "voltage",
            format!("the voltage settles at {end} V: no step found (is the voltage column right?)"),
        ));
    }
    let high = |v: f64| v * level.signum() >= 0.5 * level.abs();
    let index = voltage.iter().position(|&v| high(v)).unwrap_or(0);
    let fall = voltage
        .iter()
        .rposition(|&v| high(v))
        .map(|last| last + 1)
        .filter(|&f| f < voltage.len());
    let step_end = fall.unwrap_or(voltage.len());
    // No step but the noise of a voltage at 0, whose peaks were taken for one: the "step" is
    // within ten times the noise of the samples off it, or mostly below half of it between its
    // first and last samples above it.
    let above = voltage[index..step_end]
        .iter()
        .filter(|&&v| high(v))
        .count();
    let noise = crate::estimation::records::noise_std;
    let within_noise = match fall {
        Some(_) => {
            let off: Vec<f64> = voltage[..index]
                .iter()
                .chain(&voltage[step_end..])
                .copied()
                .collect();
            level.abs() < 10.0 * noise(&off) || 2 * above < step_end - index
        }
        // A record that holds its "step" to the end has one jump, which the trimmed noise
        // estimate of the whole record hardly sees (beyond 34 samples, ten times it stays below
        // the jump).
        None => level.abs() < 10.0 * noise(voltage),
    };
    if within_noise {
        return Err(bad(
            "voltage",
            format!(
                "no step: the voltage stays within its noise ({:.2e} V RMS; largest reading {level:.4} V, above half of it in {above} of the {} samples from the first such reading to the last) — a step test needs a step well above the noise (is the voltage column right, or was the supply off?)",
                noise(voltage),
                step_end - index
            ),
        ));
    }
    // A step that comes back down is one step only if it holds in between.
    let dip = fall.and_then(|_| voltage[index..step_end].iter().position(|&v| !high(v)));
    if let Some(dip) = dip {
        return Err(bad(
            "voltage",
            format!(
                "sample {} ({} V) falls below half the step of {level:.4} V between the step at sample {index} and the return at sample {step_end}: the voltage steps more than once — fit the record with identify --record (output error)",
                index + dip,
                voltage[index + dip]
            ),
        ));
    }
    // The mean, not the median: noise dithers the ADC's quantisation, so the mean of many
    // samples is unbiased (up to the bias estimate_level accounts for) while the median
    // sticks to one code (half an LSB off at worst).
    let after = &voltage[index..step_end];
    let scale = VoltageScale::of(voltage, quantum_v);
    let level = estimate_level(after, &scale).ok_or_else(|| {
        bad(
            "voltage",
            format!(
                "{} samples after the step at sample {index}: too few, or not finite",
                after.len()
            ),
        )
    })?;
    let dt = uniform_period(t, index, "a step test")?;
    Ok(StepLocation {
        index,
        volts: level.volts,
        volts_variance_v2: level.variance_v2,
        volts_bias_variance_v2: level.bias_variance_v2,
        volts_bias_code: level.bias_code,
        dt,
        t_step: t[index],
        fall,
    })
}

/// Fraction of a record's samples above the quantile [`peak_level`] reads (isolated glitches
/// beyond it are ignored).
const PEAK_QUANTILE_TRIM: f64 = 0.005;

/// The level of a step that may come back down before the record ends \[V\]: the median of the
/// samples beyond half the record's largest |voltage| (its 99.5th percentile, so that a glitch
/// does not count), signed; 0 for an all-zero (or non-finite) column.
fn peak_level(voltage: &[f64]) -> f64 {
    let mut magnitudes: Vec<f64> = voltage
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.abs())
        .collect();
    if magnitudes.is_empty() {
        return 0.0;
    }
    let keep = magnitudes.len() - 1 - (magnitudes.len() as f64 * PEAK_QUANTILE_TRIM) as usize;
    let peak = *magnitudes.select_nth_unstable_by(keep, f64::total_cmp).1;
    let mut beyond: Vec<f64> = voltage
        .iter()
        .copied()
        .filter(|v| v.is_finite() && v.abs() >= 0.5 * peak && peak > 0.0)
        .collect();
    if beyond.is_empty() {
        return 0.0;
    }
    let mid = beyond.len() / 2;
    *beyond.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<f64> {
        (0..n).map(|i| i as f64 * 0.01).collect()
    }

    #[test]
    fn a_held_step_has_no_fall() {
        let v: Vec<f64> = (0..100).map(|i| if i < 10 { 0.0 } else { 40.0 }).collect();
        let loc = locate_step(&grid(100), &v).unwrap();
        assert_eq!((loc.index, loc.fall), (10, None));
        assert_eq!(loc.volts, 40.0);
    }

    #[test]
    fn a_return_to_zero_is_located_and_left_out_of_the_step_height() {
        // 40 V from sample 10 to 39, then 0 V for 60 samples: the last half's median is 0.
        let v: Vec<f64> = (0..100)
            .map(|i| if (10..40).contains(&i) { -40.0 } else { 0.0 })
            .collect();
        let loc = locate_step(&grid(100), &v).unwrap();
        assert_eq!((loc.index, loc.fall), (10, Some(40)));
        assert_eq!(loc.volts, -40.0);
    }

    #[test]
    fn a_noise_spike_on_a_voltage_at_zero_is_no_step() {
        // 0 V read with noise, one reading well above the rest: once taken for a step of one
        // sample, then for a record too coarse to fit.
        let mut rng = motor_model::NoiseRng::new(5);
        let mut v: Vec<f64> = (0..2000).map(|_| (1e-3 * rng.normal()).max(0.0)).collect();
        v[700] = 5e-3;
        let err = locate_step(&grid(2000), &v).unwrap_err().to_string();
        assert!(
            err.contains("no step: the voltage stays within its noise"),
            "{err}"
        );
    }

    #[test]
    fn a_step_that_drops_out_and_comes_back_is_refused() {
        let v: Vec<f64> = (0..100)
            .map(|i| {
                if (10..40).contains(&i) && i != 25 {
                    40.0
                } else {
                    0.0
                }
            })
            .collect();
        let err = locate_step(&grid(100), &v).unwrap_err().to_string();
        assert!(
            err.contains("sample 25") && err.contains("identify --record"),
            "{err}"
        );
    }

    #[test]
    fn an_all_zero_record_has_no_step() {
        let err = locate_step(&grid(100), &[0.0; 100])
            .unwrap_err()
            .to_string();
        assert!(err.contains("settles at 0 V: no step found"), "{err}");
    }
}
