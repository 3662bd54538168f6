//! The voltage waveform a measured column describes: its levels and jumps where it is
//! piecewise constant (a step, staircase, PRBS), the samples themselves otherwise.

use motor_model::Input;

use crate::error::FitError;
use crate::estimation::records::{
    noise_of_second_differences, noise_std, squared_second_difference, uniform_period,
};
use crate::excitation::input_uncertainty::{
    estimate_level, LevelEstimate, LevelPrior, VoltageScale,
};

/// A voltage is piecewise constant when it has at most one jump per this many samples.
pub(crate) const MIN_SAMPLES_PER_LEVEL: usize = 20;

pub(crate) fn bad(series: impl Into<String>, reason: String) -> FitError {
    FitError::BadData {
        series: series.into(),
        reason,
    }
}

/// The waveform a measured voltage column describes, time measured from `t[0]`.
///
/// When the voltage is piecewise constant (a step, staircase, PRBS or reversal: jumps larger
/// than 10 noise levels and 0.1 % of the range, at most one per 20 samples, flat in between to
/// within 4 noise levels; where jumps many beside the record's length swell the noise level
/// found first, the noise is taken again without the changes above three of it, and each jump
/// must then span four of the record's smallest change, when that is under 5 % of the range) each level is estimated from its samples ([`crate::estimate_level`]:
/// the mean — the ADC noise averages out — or the censored fit at an ADC rail) and starts at
/// its first sample ([`voltage_levels`] puts it where it is expected, half a period earlier).
/// Otherwise the samples themselves are replayed, linearly interpolated. `t` must be uniform
/// (0.1 %).
pub fn voltage_input(t: &[f64], voltage: &[f64]) -> Result<Input, FitError> {
    rebuild_voltage(t, voltage, None, false).map(|(input, _)| input)
}

/// [`voltage_input`] with what the record leaves unknown about each level of a
/// piecewise-constant voltage (empty for a replayed waveform): the level is estimated by
/// [`crate::estimate_level`] (the mean, or the censored fit at an ADC rail; `quantum_v` \[V\]
/// is the voltage's ADC step if known) with its variance, and a level after the first starts
/// half a sample period before its first sample (the change fell anywhere in that period,
/// variance `dt²/12`). Pass both to [`OutputError::level_priors`](crate::OutputError::level_priors).
pub fn voltage_levels(
    t: &[f64],
    voltage: &[f64],
    quantum_v: Option<f64>,
) -> Result<(Input, Vec<LevelPrior>), FitError> {
    rebuild_voltage(t, voltage, quantum_v, true)
}

/// The waveform of a voltage column and its level priors; with `expected_starts` each change
/// starts half a period before its first sample, otherwise at it.
pub(crate) fn rebuild_voltage(
    t: &[f64],
    voltage: &[f64],
    quantum_v: Option<f64>,
    expected_starts: bool,
) -> Result<(Input, Vec<LevelPrior>), FitError> {
    if t.len() != voltage.len() {
        return Err(bad(
            "voltage",
            format!(
                "{} samples where the time has {}: the channels must align",
                voltage.len(),
                t.len()
            ),
        ));
    }
    let dt = uniform_period(t, 0, "an output-error fit")?;
    if let Some((i, v)) = voltage.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(bad("voltage", format!("sample {i} is {v}")));
    }
    let (lo, hi) = voltage
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    // The jumps are the changes above ten noise levels; the noise is that of the flat
    // stretches between the jumps found, found again until they hold (the jumps' own second
    // differences in the noise made 0 → −12 V at the head of a ±12 V PRBS of 50 bits a
    // second at 2 kHz look like noise: a 24 V reversal every 40 samples set the level at 15 V).
    let threshold = |sigma: f64| (10.0 * sigma).max(1e-3 * (hi - lo));
    let sampled = || {
        Input::sampled(0.0, dt, voltage.to_vec())
            .map(|i| (i, Vec::new()))
            .map_err(FitError::model("voltage"))
    };
    // The levels from a first noise level `sigma0`, every jump at least `min_jump`; `None`
    // when the voltage is not piecewise constant at that level.
    let levels_from =
        |sigma0: f64, min_jump: f64| -> Option<Result<(Input, Vec<LevelPrior>), FitError>> {
            let mut sigma = sigma0;
            let mut starts = jumps(voltage, threshold(sigma));
            for _ in 0..JUMP_PASSES {
                let flat = noise_between(voltage, &starts);
                if flat >= sigma {
                    break;
                }
                sigma = flat;
                let again = jumps(voltage, threshold(sigma));
                if again == starts {
                    break;
                }
                starts = again;
            }
            if (starts.len() - 1) * MIN_SAMPLES_PER_LEVEL > voltage.len()
                || starts
                    .iter()
                    .skip(1)
                    .any(|&s| (voltage[s] - voltage[s - 1]).abs() < min_jump)
            {
                return None;
            }
            let scale = VoltageScale::of(voltage, quantum_v);
            let mut steps = Vec::with_capacity(starts.len());
            let mut priors = Vec::with_capacity(starts.len());
            for (j, &s) in starts.iter().enumerate() {
                let e = starts.get(j + 1).copied().unwrap_or(voltage.len());
                let seg = &voltage[s..e];
                let mean = seg.iter().sum::<f64>() / seg.len() as f64;
                let rms =
                    (seg.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / seg.len() as f64).sqrt();
                // The rounding of the mean is no scatter: a record that holds one code throughout
                // (a step at its first sample read without noise) has an RMS of 1e-15 about its
                // mean, and replayed as samples it lost its level's prior (R, L, k, f, J 20–80
                // half-widths off the truth of a half-step quantisation bias).
                let rounding = 1e-12 * hi.abs().max(lo.abs());
                if rms > 4.0 * sigma + 1e-3 * (hi - lo) + rounding {
                    // Not flat between jumps (a sine, a ramp): replay the samples.
                    return None;
                }
                let level = estimate_level(seg, &scale).unwrap_or(LevelEstimate {
                    volts: mean,
                    variance_v2: 0.0,
                    bias_variance_v2: 0.0,
                    bias_code: 0,
                });
                let (start, start_variance_s2) = if s == 0 {
                    (0.0, 0.0)
                } else {
                    let lead = if expected_starts { 0.5 * dt } else { 0.0 };
                    (t[s] - t[0] - lead, dt * dt / 12.0)
                };
                steps.push((start, level.volts));
                priors.push(LevelPrior {
                    volts_variance_v2: level.variance_v2,
                    volts_bias_variance_v2: level.bias_variance_v2,
                    volts_bias_code: level.bias_code,
                    start_variance_s2,
                });
            }
            Some(
                Input::piecewise(&steps)
                    .map(|input| (input, priors))
                    .map_err(FitError::model("voltage")),
            )
        };
    let sigma = noise_std(voltage);
    if let Some(levels) = levels_from(sigma, 0.0) {
        return levels;
    }
    // Jumps many beside the record's length set the first noise level from their own second
    // differences, above themselves (six ±6.4 V reversals in 150 samples read 1.5 V, and no
    // jump passed ten of it): the noise again without the windows that straddle a change
    // larger than three of that level. Without them a slow ramp read without noise (one ADC
    // code every few dozen samples) has no noise left, and each code would be a level: the
    // jumps so found must each span [`RETRY_MIN_CODES`] of the smallest change the record
    // shows.
    let quiet = noise_without_changes(voltage, 3.0 * sigma);
    // The smallest change, when it is small beside the range (a record without noise whose
    // only changes are its jumps has no code to read).
    let code = voltage
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let min_jump = if code < RETRY_CODE_SHARE * (hi - lo) {
        RETRY_MIN_CODES * code
    } else {
        0.0
    };
    match (quiet < sigma)
        .then(|| levels_from(quiet, min_jump))
        .flatten()
    {
        Some(levels) => levels,
        None => sampled(),
    }
}

/// Smallest jump of a voltage whose levels [`rebuild_voltage`] finds on its second noise level,
/// in the smallest change the record shows (its ADC code, read without noise).
pub(crate) const RETRY_MIN_CODES: f64 = 4.0;

/// Largest share of the range the smallest change of a voltage may be for [`RETRY_MIN_CODES`]
/// to apply (a change larger than this is a jump, not a code).
pub(crate) const RETRY_CODE_SHARE: f64 = 0.05;

/// [`noise_std`] of `voltage` from the second differences of the windows of three samples
/// whose two changes are both at most `above` in size.
pub(crate) fn noise_without_changes(voltage: &[f64], above: f64) -> f64 {
    let d2: Vec<f64> = voltage
        .windows(3)
        .filter(|w| (w[1] - w[0]).abs() <= above && (w[2] - w[1]).abs() <= above)
        .map(squared_second_difference)
        .collect();
    noise_of_second_differences(d2, voltage)
}

/// Passes of [`rebuild_voltage`]'s jump search on the noise between the jumps found.
pub(crate) const JUMP_PASSES: usize = 3;

/// The first sample and the sample of every change of `voltage` larger than `threshold`.
pub(crate) fn jumps(voltage: &[f64], threshold: f64) -> Vec<usize> {
    std::iter::once(0)
        .chain((1..voltage.len()).filter(|&i| (voltage[i] - voltage[i - 1]).abs() > threshold))
        .collect()
}

/// [`noise_std`] of `voltage` over its stretches between the changes at `starts` (each from
/// its start to the next): the second differences that straddle a change left out.
pub(crate) fn noise_between(voltage: &[f64], starts: &[usize]) -> f64 {
    let ends = starts.iter().skip(1).copied().chain([voltage.len()]);
    let d2: Vec<f64> = starts
        .iter()
        .zip(ends)
        .flat_map(|(&s, e)| voltage[s..e].windows(3).map(squared_second_difference))
        .collect();
    noise_of_second_differences(d2, voltage)
}
