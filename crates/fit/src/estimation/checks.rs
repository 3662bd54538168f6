//! Checks of step records shared by both identification methods: each failure says what is
//! wrong with the record and what to do.

use crate::error::FitError;
use crate::estimation::records::StepTest;

/// Fewest samples a step record may have.
pub const MIN_SAMPLES: usize = 8;
/// A record has settled when its last tenth moves by less than this fraction of its final
/// value (the paper's own 40 V record, at 2.5 τm, moves by 0.2 %).
pub const SETTLED_FRACTION: f64 = 0.02;

fn bad(label: &str, reason: String) -> FitError {
    FitError::BadData {
        series: label.to_string(),
        reason,
    }
}

/// The measured channels of one record and the samples left out of the fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Channels<'a> {
    pub current: &'a [f64],
    pub speed: Option<&'a [f64]>,
    pub position: Option<&'a [f64]>,
    pub exclude_current: Option<&'a [bool]>,
    pub exclude_speed: Option<&'a [bool]>,
}

/// The measured channels and exclusion masks of a record, for the checks.
macro_rules! channels_of {
    ($($record:ty),*) => {
        $(
            impl<'a> $record {
                /// The measured channels and exclusion masks, for the checks.
                pub(crate) fn channels(&self) -> Channels<'a> {
                    Channels {
                        current: self.current,
                        speed: self.speed,
                        position: self.position,
                        exclude_current: self.exclude_current,
                        exclude_speed: self.exclude_speed,
                    }
                }
            }
        )*
    };
}
channels_of!(StepTest<'a>, crate::estimation::records::ExcitedRecord<'a>);

/// Channels of one record: enough samples, aligned and finite, exclusion masks of the same
/// length leaving at least [`MIN_SAMPLES`] samples.
pub(crate) fn check_channels(label: &str, c: Channels<'_>) -> Result<(), FitError> {
    let n = c.current.len();
    if n < MIN_SAMPLES {
        return Err(bad(
            label,
            format!("{n} samples: at least {MIN_SAMPLES} are needed"),
        ));
    }
    check_aligned(label, c)?;
    for (name, data) in [
        ("current", Some(c.current)),
        ("speed", c.speed),
        ("position", c.position),
    ] {
        let Some(y) = data else { continue };
        if let Some((i, v)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(bad(
                label,
                format!("{name} sample {i} is {v}: remove or repair it"),
            ));
        }
    }
    for (name, mask) in [("current", c.exclude_current), ("speed", c.exclude_speed)] {
        if let Some(m) = mask {
            let kept = m.iter().filter(|&&x| !x).count();
            if kept < MIN_SAMPLES {
                return Err(bad(label, format!("only {kept} {name} samples are left once the clipped ones are excluded: widen the ADC range")));
            }
        }
    }
    Ok(())
}

/// Channels of one record aligned: the speed, the angle and both exclusion masks, where
/// given, as long as the current.
pub(crate) fn check_aligned(label: &str, c: Channels<'_>) -> Result<(), FitError> {
    let n = c.current.len();
    let align = ": the channels must align";
    let lengths = [
        ("speed", c.speed.map(<[f64]>::len), align),
        ("position", c.position.map(<[f64]>::len), align),
        (
            "the current exclusion mask",
            c.exclude_current.map(<[bool]>::len),
            "",
        ),
        (
            "the speed exclusion mask",
            c.exclude_speed.map(<[bool]>::len),
            "",
        ),
    ];
    for (what, len, tail) in lengths {
        if let Some(len) = len.filter(|&len| len != n) {
            return Err(bad(
                label,
                format!("{what} has {len} samples where the current has {n}{tail}"),
            ));
        }
    }
    Ok(())
}

/// The spread of `y`, max − min (its unit).
fn span(y: &[f64]) -> f64 {
    y.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v))
        - y.iter().fold(f64::INFINITY, |m, &v| m.min(v))
}

/// Refuses a record whose current \[A\] never changes: a motor driven by a voltage draws a
/// current that moves at least by its noise or an ADC step, so the column is not a current
/// (or the motor was not connected); fitted, its noise floor of 0 makes every weight infinite.
pub(crate) fn check_current_varies(label: &str, current: &[f64]) -> Result<(), FitError> {
    if span(current) <= 0.0 {
        return Err(bad(label, format!("the current is constant ({} A): is the current column right, and was the motor connected?", current.first().copied().unwrap_or(0.0))));
    }
    Ok(())
}

/// Basic soundness of one step test: enough samples, aligned finite channels, a real step,
/// a current that varies, and (where speed or angle is measured) a rotor that moves.
pub fn check_step_test(label: &str, t: &StepTest<'_>) -> Result<(), FitError> {
    check_channels(label, t.channels())?;
    if !(t.dt.is_finite() && t.dt > 0.0 && t.t_first.is_finite() && t.t_first >= 0.0) {
        return Err(bad(label, format!("first sample {} s after the step, period {} s: expected t_first ≥ 0 and a positive period", t.t_first, t.dt)));
    }
    if !(t.volts.is_finite() && t.volts != 0.0) {
        return Err(bad(
            label,
            format!("step of {} V: expected a non-zero finite step", t.volts),
        ));
    }
    check_current_varies(label, t.current)?;
    let moved = match (t.position, t.speed) {
        (Some(angle), _) => span(angle) > 0.0,
        // A tachometer's noise is no motion.
        (None, Some(speed)) => crate::estimation::plausibility::shows_motion(speed),
        (None, None) => true,
    };
    if !moved {
        // A current still rising means the record ended too early to tell: the rotor may
        // only start later. Only a settled current at rest shows the friction holds.
        if check_settled_for(label, "current", t.current, t.dt, "").is_err() {
            return Err(bad(label, record_too_short(t.current, t.dt)));
        }
        return Err(bad(label, format!("the rotor never moves: the {:.4} V step does not break the Coulomb friction (|E| ≤ R Ts/k, Eq. (11)); raise the step voltage", t.volts)));
    }
    check_signs(label, t)
}

/// A motor stepped from rest draws current, and turns, in the direction of its voltage: at
/// the end of the record `R I = E − k Ω` (Eq. (5)) with `0 ≤ k Ω < E`, so `I` has the sign of
/// `E`, and so has `Ω` (the model's k > 0). A channel whose end reads clearly (beyond five
/// times its noise) the other way is wired or counted in reverse; fitted as it is, the
/// parameters come out negative ("R = −0.314 must be greater than zero") without a word on
/// why.
fn check_signs(label: &str, t: &StepTest<'_>) -> Result<(), FitError> {
    let end = tail_mean;
    let against = |y: &[f64]| {
        let e = end(y);
        e * t.volts < 0.0 && e.abs() > 5.0 * crate::estimation::records::noise_std(y)
    };
    if against(t.current) {
        return Err(bad(label, format!("the current ends at {:.4} A against a {:.4} V step: its sign is reversed (negate the current column, or swap the current sensor's leads)", end(t.current), t.volts)));
    }
    let speed = match (t.position, t.speed) {
        (Some(angle), _) => {
            let moved = angle[angle.len() - 1] - angle[0];
            (moved * t.volts < 0.0).then(|| format!("the angle runs {moved:.4} rad"))
        }
        (None, Some(speed)) => {
            against(speed).then(|| format!("the speed ends at {:.4} rad/s", end(speed)))
        }
        (None, None) => None,
    };
    match speed {
        Some(what) => Err(bad(label, format!("{what} against a {:.4} V step: its sign is reversed (negate the speed or position column, or count the encoder the other way)", t.volts))),
        None => Ok(()),
    }
}

/// Why a record whose current is still rising is too short, with the time the current needs
/// to settle where its rise shows it: at rest it follows Eq. (10), `I = E/R (1 − e^(−t/τe))`,
/// so the rise over the second half of the record is `e^(−T/(2τe))` times that over the first
/// half, and the current is within 1 % of E/R after about 5 τe.
fn record_too_short(current: &[f64], dt: f64) -> String {
    let n = current.len();
    let span_s = dt * (n - 1) as f64;
    let half = (n - 1) / 2;
    let (first, mid, last) = (current[0], current[half], current[2 * half]);
    let ratio = (last - mid) / (mid - first);
    let tau_e = -(dt * half as f64) / ratio.ln();
    let needs = if ratio > 0.0 && ratio < 1.0 && tau_e.is_finite() {
        let seconds = |x: f64| {
            if x >= 1e-3 {
                format!("{x:.3}")
            } else {
                format!("{x:.2e}")
            }
        };
        format!(
            ", the current needs about {} s to settle (5 τe, τe ≈ {} s from its rise, Eq. (10))",
            seconds(5.0 * tau_e),
            seconds(tau_e)
        )
    } else {
        String::new()
    };
    format!("record too short: {n} samples ({span_s:.3} s) end before the current settles{needs}; record until current and speed are steady")
}

/// Whether the record's end is a steady state, as the paper's method assumes (it reads Irm,
/// Ωrm, Irb off the last samples): over the last tenth of `y`, the mean of its last fifth
/// differs from the mean of its first fifth by less than [`SETTLED_FRACTION`] of the former.
pub fn check_settled(label: &str, name: &str, y: &[f64], dt: f64) -> Result<(), FitError> {
    check_settled_for(
        label,
        name,
        y,
        dt,
        "the paper's method reads the steady state off the record's end — record longer (several mechanical time constants) or use --method full",
    )
}

/// Mean of the last tenth of a series (at least its last sample): the steady value of a
/// settled record. Unit of `y`; `y` must not be empty.
pub(crate) fn tail_mean(y: &[f64]) -> f64 {
    let n = (y.len() / 10).max(1);
    y[y.len() - n..].iter().sum::<f64>() / n as f64
}

/// Standard deviations of the noise in the difference of [`check_settled_for`]'s two means
/// beyond which their difference counts as motion.
const SETTLED_NOISE_SDS: f64 = 4.0;

/// [`check_settled`] with the caller's `advice` (why a steady end is needed, what to do) at the
/// end of the error.
pub fn check_settled_for(
    label: &str,
    name: &str,
    y: &[f64],
    dt: f64,
    advice: &str,
) -> Result<(), FitError> {
    let n = y.len();
    let tail = (n / 10).max(5);
    let window = &y[n.saturating_sub(tail)..];
    // Means of the first and last fifths of the tail, so that noise does not count as motion.
    let fifth = (window.len() / 5).max(1);
    let mean = |w: &[f64]| w.iter().sum::<f64>() / w.len() as f64;
    let (first, last) = (
        mean(&window[..fifth]),
        mean(&window[window.len() - fifth..]),
    );
    let moved = (last - first).abs();
    // Nor a difference the noise alone makes: two means of `fifth` samples of white noise σ
    // differ with standard deviation σ √(2/fifth). On a 200 Hz record whose exact current was
    // flat to all its digits over its last 0.5 s, the two means (8 samples each, 0.019 A of
    // noise) differed by 0.0076 A and the record was called unsettled ("moves by 2.2 %").
    let noise = crate::estimation::records::noise_std(window) * (2.0 / fifth as f64).sqrt();
    if moved > SETTLED_FRACTION * last.abs() && moved > SETTLED_NOISE_SDS * noise {
        return Err(bad(
            label,
            format!(
            "the {name} has not settled: it still moves by {:.1} % over the last {:.3} s; {advice}",
            100.0 * moved / last.abs().max(f64::MIN_POSITIVE),
            tail as f64 * dt
        ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_about_a_settled_value_is_not_motion_but_a_drift_is() {
        // 400 samples at 200 Hz, the last 40 judged: means of 8 samples each.
        let mut rng = motor_model::NoiseRng::new(1);
        let flat: Vec<f64> = (0..400).map(|_| 0.32 + 0.019 * rng.normal()).collect();
        assert!(check_settled("test", "current", &flat, 5e-3).is_ok());
        // The same noise on a current still rising by 10 % over the judged tail.
        let rising: Vec<f64> = flat
            .iter()
            .enumerate()
            .map(|(i, y)| y + 0.32 * 0.1 * (i as f64 - 360.0).max(0.0) / 40.0)
            .collect();
        let err = check_settled("test", "current", &rising, 5e-3).unwrap_err();
        assert!(err.to_string().contains("has not settled"), "{err}");
    }
}
