//! Finding the step in a record: the instant, the height and the uniform grid after it.

use crate::error::FitError;

/// Relative deviation from the median sample period tolerated before a record counts as not
/// uniformly sampled.
const GRID_TOLERANCE: f64 = 1e-3;

/// Where a voltage step sits in a record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLocation {
    /// Index of the first sample at the new level.
    pub index: usize,
    /// Step height E \[V\]: the mean voltage after the step.
    pub volts: f64,
    /// Sample period \[s\].
    pub dt: f64,
    /// Time of the step \[s\] (the first sample at the new level).
    pub t_step: f64,
}

/// Locates the voltage step: the first sample whose voltage passes half the median of the
/// record's last half (pre-trigger samples at 0 V are allowed before it), and checks that the
/// time column is strictly increasing and uniform.
pub fn locate_step(t: &[f64], voltage: &[f64]) -> Result<StepLocation, FitError> {
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
    // samples is unbiased while the median sticks to one code (half an LSB off at worst).
    let after = &voltage[index..];
    let volts = after.iter().sum::<f64>() / after.len() as f64;
    let dt = uniform_period(t, index, "a step test")?;
    Ok(StepLocation {
        index,
        volts,
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
