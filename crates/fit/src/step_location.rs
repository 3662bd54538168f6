//! Finding the step in a record: the instant, the height and the uniform grid after it.

use crate::error::FitError;
use crate::input_uncertainty::{estimate_level, StepInputs, VoltageScale};

/// Relative deviation from the median sample period tolerated before a record counts as not
/// uniformly sampled.
const GRID_TOLERANCE: f64 = 1e-3;

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
    /// Sample period \[s\].
    pub dt: f64,
    /// Time of the step \[s\] (the first sample at the new level).
    pub t_step: f64,
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
        };
        if self.index == 0 {
            StepInputs {
                volts_variance_v2: level.variance_v2,
                ..StepInputs::default()
            }
        } else {
            StepInputs::sampled(level, self.dt)
        }
    }
}

/// Locates the voltage step: the first sample whose voltage passes half the median of the
/// record's last half (pre-trigger samples at 0 V are allowed before it), and checks that the
/// time column is strictly increasing and uniform. The voltage's ADC step is found from the
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
    let level = *tail.select_nth_unstable_by(mid, f64::total_cmp).1;
    if !(level.abs() > 0.0 && level.is_finite()) {
        return Err(bad(
            "voltage",
            format!(
                "the voltage settles at {level} V: no step found (is the voltage column right?)"
            ),
        ));
    }
    let index = voltage
        .iter()
        .position(|&v| v * level.signum() >= 0.5 * level.abs())
        .unwrap_or(0);
    // The mean, not the median: noise dithers the ADC's quantisation, so the mean of many
    // samples is unbiased (up to the bias estimate_level accounts for) while the median
    // sticks to one code (half an LSB off at worst).
    let after = &voltage[index..];
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
        dt,
        t_step: t[index],
    })
}

/// The sample period \[s\] of `t`: strictly increasing, and uniform (to 0.1 %) from sample
/// `from` on; `purpose` names what needs the uniform grid in the error.
pub(crate) fn uniform_period(t: &[f64], from: usize, purpose: &str) -> Result<f64, FitError> {
    let bad = |reason: String| FitError::BadData {
        series: "time".into(),
        reason,
    };
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.is_empty() {
        return Err(bad(format!("{} samples: no sample period", t.len())));
    }
    if let Some(i) = steps.iter().position(|d| d.is_nan() || *d <= 0.0) {
        return Err(bad(format!("sample {} (t = {} s) does not come after the one before it (t = {} s): time must increase strictly", i + 1, t[i + 1], t[i])));
    }
    let mid = steps.len() / 2;
    let dt = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    for (i, w) in t.windows(2).enumerate().skip(from) {
        if ((w[1] - w[0]) - dt).abs() > GRID_TOLERANCE * dt {
            return Err(bad(format!("sample {} (t = {} s) breaks the uniform {dt} s grid: {purpose} needs uniform sampling", i + 1, w[1])));
        }
    }
    Ok(dt)
}
