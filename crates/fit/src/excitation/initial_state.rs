//! The state a record's simulation starts from in an output-error fit, and how a record shows
//! it.
//!
//! A record either starts at rest (pre-trigger samples, or the first change of voltage at the
//! first sample), in the steady state of its first voltage level (a step from one level to
//! another on a running motor: Eqs. (4), (5) give `Ω0`, `I0` from the parameters, so that it
//! costs no parameter; below breakaway that state is rest with `I0 = E/R`, Eq. (1)), or
//! anywhere (a slice cut from a long log: the initial current and speed are fitted with the
//! motor, and their uncertainty enters the motor's intervals).

use motor_model::{central_difference, Input};

use crate::error::FitError;
use crate::estimation::records::{noise_std, ExcitedRecord, InitialState};

/// The initial state a record shows, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectedInitialState {
    /// The state detected.
    pub state: InitialState,
    /// What the first samples show, in words (values with units).
    pub reason: String,
}

/// Fewest samples of the first level over which a record is judged flat (steady).
const MIN_WINDOW: usize = 16;
/// Largest share of the record the flatness is judged on.
const WINDOW_FRACTION: usize = 10;
/// Noise levels a first sample may lie from 0 and still be at rest.
const REST_SIGMAS: f64 = 5.0;
/// Standard errors the two halves of the window may differ by and still be flat.
const FLAT_SIGMAS: f64 = 4.0;
/// Share of a channel's largest |value| within which it counts as 0 (at rest) or as not
/// changing (flat): sensor offsets, ripple, a motor within 0.5 % of its steady state.
const FLOOR_FRACTION: f64 = 5e-3;

/// Angles fitted by [`speed_at_start`].
const START_ANGLES: usize = 6;

/// The speed \[rad/s\] at the first sample of an encoder angle sampled every `dt` \[s\], and
/// its standard error: the slope at t = 0 of `θ0 + Ω0 t + a t²/2` fitted by least squares to
/// the first [`START_ANGLES`] angles, their scatter the larger of the angle's own noise
/// ([`noise_std`]: about a third of a count for a quantised one) and the parabola's residual
/// scatter. A motor started from rest at its step within a few samples of its time constants
/// turns as `θ ∝ t³` at first and then bends: no parabola follows it, and its slope at 0 is not
/// the speed (a fast motor stepped at the first sample read as moving at 59 rad/s, with a
/// standard error of 0.4 rad/s from the count alone, and its fit from a free initial state was
/// biased by a half-width in L and J).
fn speed_at_start(angle: &[f64], dt: f64) -> Option<(f64, f64)> {
    let first = angle.get(..START_ANGLES)?;
    let mut xtx = nalgebra::Matrix3::<f64>::zeros();
    let mut xty = nalgebra::Vector3::<f64>::zeros();
    let row = |k: usize| {
        let t = k as f64 * dt;
        nalgebra::Vector3::new(1.0, t, 0.5 * t * t)
    };
    for (k, th) in first.iter().enumerate() {
        let x = row(k);
        xtx += x * x.transpose();
        xty += x * (th - first[0]);
    }
    let inv = xtx.try_inverse()?;
    let beta = inv * xty;
    let rss: f64 = first
        .iter()
        .enumerate()
        .map(|(k, th)| (th - first[0] - row(k).dot(&beta)).powi(2))
        .sum();
    let misfit = (rss / (START_ANGLES - 3) as f64).sqrt();
    let sigma = noise_std(angle).max(misfit);
    Some((beta[1], sigma * inv[(1, 1)].sqrt())).filter(|(w, s)| w.is_finite() && s.is_finite())
}

/// The channels of a record that tell whether it starts at rest ([`detect_rest`]): no input
/// is needed for that.
#[derive(Debug, Clone, Copy)]
pub struct StartChannels<'a> {
    /// Sample period \[s\].
    pub dt: f64,
    /// Armature current \[A\].
    pub current: &'a [f64],
    /// Speed \[rad/s\] measured directly (tachometer), if any. Not used when `position` is given.
    pub speed: Option<&'a [f64]>,
    /// Encoder angle \[rad\] (any offset), if measured.
    pub position: Option<&'a [f64]>,
}

impl<'a> ExcitedRecord<'a> {
    /// The record's channels without its input, for [`detect_rest`].
    pub fn start_channels(&self) -> StartChannels<'a> {
        StartChannels {
            dt: self.dt,
            current: self.current,
            speed: self.speed,
            position: self.position,
        }
    }
}

/// What the rest test and the flatness test of [`detect_initial_state`] read off a record's
/// channels.
struct StartLevels<'a> {
    current: &'a [f64],
    /// The tachometer's speed, or the encoder angle's central difference \[rad/s\].
    speed: Vec<f64>,
    /// Noise levels of the current \[A\] and the speed \[rad/s\] ([`noise_std`]).
    noise: (f64, f64),
    /// Floors of the current \[A\] and the speed \[rad/s\]: [`FLOOR_FRACTION`] of the largest
    /// |value|.
    floor: (f64, f64),
    /// The speed at the first sample \[rad/s\] and its standard error ([`speed_at_start`] with
    /// an encoder).
    start_speed: (f64, f64),
    /// With an encoder, whether its first two angle differences show a rotor that was at rest
    /// at the first sample and is speeding up ([`starts_speeding_up`]).
    speeding_up: bool,
}

/// Whether the angles `θ0, θ1, θ2` show a rotor at rest at the first sample that speeds up:
/// the first difference at most half the second, both of one sign, the second not zero. From
/// rest at `t = 0` a speed `ω` that rises convex over the first period (a current that grows
/// from 0 through L) has `θ1 − θ0 = ∫ω ≤ ω(dt) dt/2`, and the second period at least
/// `ω(dt) dt`; a rotor already turning at `Ω0` covers `Ω0 dt` in the first period and could
/// not double its mean speed in one more — not while its current, as [`detect_rest`] also
/// asks, is still 0. The parabola of [`speed_at_start`] cannot follow that start when the
/// time constants are a sample or two: a 2 ms motor stepped at the first sample of a 1 kHz
/// record read as turning at −20.7 rad/s and was fitted as a slice of a longer run.
fn starts_speeding_up(angle: &[f64]) -> bool {
    let [a, b, c] = match angle.get(..3) {
        Some(&[a, b, c]) => [a, b, c],
        _ => return false,
    };
    let (d1, d2) = (b - a, c - b);
    d2 != 0.0 && d1 * d2 >= 0.0 && 2.0 * d1.abs() <= d2.abs()
}

impl<'a> StartLevels<'a> {
    /// The levels of `record`; an error for fewer than 3 samples, no speed nor position, or
    /// channels not finite or not of one length.
    fn of(record: &StartChannels<'a>) -> Result<Self, FitError> {
        let current = record.current;
        let n = current.len();
        let bad = |reason: String| FitError::BadData {
            series: "record".into(),
            reason,
        };
        if n < 3 {
            return Err(bad(format!("{n} samples: too few to tell how it starts")));
        }
        let speed: Vec<f64> = match (record.position, record.speed) {
            (Some(angle), _) => {
                let times: Vec<f64> = (0..angle.len()).map(|i| i as f64 * record.dt).collect();
                central_difference(&times, angle)
            }
            (None, Some(w)) => w.to_vec(),
            (None, None) => {
                return Err(bad(
                    "neither speed nor position: the initial speed cannot be seen".into(),
                ))
            }
        };
        if speed.len() != n || current.iter().chain(&speed).any(|v| !v.is_finite()) {
            return Err(bad(
                "the current and speed must be finite and of one length".into(),
            ));
        }
        let peak = |y: &[f64]| y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let noise = (noise_std(current), noise_std(&speed));
        let floor = (
            FLOOR_FRACTION * peak(current),
            FLOOR_FRACTION * peak(&speed),
        );
        let w0 = speed[0];
        let start_speed = match record.position {
            Some(angle) => speed_at_start(angle, record.dt).unwrap_or((w0, noise.1)),
            None => (w0, noise.1),
        };
        Ok(StartLevels {
            current,
            speed,
            noise,
            floor,
            start_speed,
            speeding_up: record.position.is_some_and(starts_speeding_up),
        })
    }

    /// At rest (with the reason) when the current and the speed at the first sample are 0
    /// within [`REST_SIGMAS`] noise levels and the floors; `None` otherwise.
    fn rest(&self) -> Option<DetectedInitialState> {
        let (c0, w0) = (self.current[0], self.speed[0]);
        let (w_start, sw_start) = self.start_speed;
        (c0.abs() <= REST_SIGMAS * self.noise.0 + self.floor.0
            && (self.speeding_up || w_start.abs() <= REST_SIGMAS * sw_start + self.floor.1))
            .then(|| DetectedInitialState {
                state: InitialState::Rest,
                reason: format!(
                    "current {c0:.4e} A and speed {w0:.4e} rad/s at the first sample: at rest"
                ),
            })
    }
}

/// The rest test of [`detect_initial_state`] alone, which needs no input: `Some` (at rest)
/// when the current and the speed at the first sample are 0 within 5 noise levels and 0.5 % of
/// their largest |value|, `None` when the record starts moving (then [`detect_initial_state`]
/// tells steady from free, the same way). Errors as [`detect_initial_state`]'s.
pub fn detect_rest(record: &StartChannels<'_>) -> Result<Option<DetectedInitialState>, FitError> {
    Ok(StartLevels::of(record)?.rest())
}

/// The initial state `record` shows: at rest when the current and the speed at the first
/// sample are 0 within 5 noise levels ([`noise_std`]) and 0.5 % of their largest |value| (with
/// an encoder, the speed at the first sample is the slope at t = 0 of a parabola fitted to the
/// first 6 angles, within 5 of its standard errors: a difference of angles is the mean speed
/// over a period in which a motor started at that sample already moves, and one count per
/// sample can exceed the noise level of the speed; or the first angle difference at most half
/// the second and the current 0, for a motor too fast for that parabola);
/// otherwise steady when both stay flat over the first level (the samples before the first
/// change of voltage, at most a tenth of the record, at least 16: the means of its two halves
/// within 4 standard errors and 0.5 % of the largest |value|), else free. The speed is the
/// tachometer's, or the encoder angle's central difference.
pub fn detect_initial_state(record: &ExcitedRecord<'_>) -> Result<DetectedInitialState, FitError> {
    crate::estimation::checks::check_aligned("record", record.channels())?;
    let levels = StartLevels::of(&record.start_channels())?;
    if let Some(rest) = levels.rest() {
        return Ok(rest);
    }
    let StartLevels {
        current,
        speed,
        noise: (sc, sw),
        floor: (fc, fw),
        ..
    } = levels;
    let n = current.len();
    let (c0, w0) = (current[0], speed[0]);
    let e0 = record.input.volts_at(0.0);
    let first_change = match record.input {
        Input::Piecewise { times_s, .. } => times_s
            .iter()
            .find(|&&t| t > 0.0)
            .map_or(n, |t| ((t / record.dt).floor() as usize).min(n)),
        _ => n,
    };
    let m = first_change
        .min((n / WINDOW_FRACTION).max(MIN_WINDOW))
        .min(n);
    let moving = format!("current {c0:.4} A, speed {w0:.4} rad/s at the first sample ({e0:.4} V)");
    if m < MIN_WINDOW {
        return Ok(DetectedInitialState {
            state: InitialState::Free,
            reason: format!(
                "{moving}; the first voltage level lasts {m} samples, too few to show a steady state: \
                 the initial current and speed are fitted"
            ),
        });
    }
    // Change between the two halves of the window, against its standard error.
    let half = m / 2;
    let mean = |y: &[f64]| y.iter().sum::<f64>() / y.len() as f64;
    let change = |y: &[f64]| mean(&y[half..m]) - mean(&y[..half]);
    let (dc, dw) = (change(current), change(&speed));
    let se = |s: f64| s * (2.0 / half as f64).sqrt();
    let flat = dc.abs() <= FLAT_SIGMAS * se(sc) + fc && dw.abs() <= FLAT_SIGMAS * se(sw) + fw;
    Ok(if flat {
        DetectedInitialState {
            state: InitialState::Steady,
            reason: format!(
                "{moving}, flat over the first {m} samples: the steady state of {e0:.4} V"
            ),
        }
    } else {
        DetectedInitialState {
            state: InitialState::Free,
            reason: format!(
                "{moving}, changing over the first {m} samples (current by {dc:.3e} A, speed by {dw:.3e} rad/s): \
                 a slice of a longer run, the initial current and speed are fitted"
            ),
        }
    })
}
