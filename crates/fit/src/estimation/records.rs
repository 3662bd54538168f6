//! The types every route's records and results are made of: a step test ([`StepTest`]) and a
//! record of any excitation ([`ExcitedRecord`]), the fitted channels ([`Channel`],
//! [`FittedChannel`], [`ChannelQuality`]), the initial state of a record's simulation
//! ([`InitialState`], [`FittedInitialState`]), the names and units of the six motor parameters,
//! the noise level of a channel from its second differences ([`noise_std`]) and the sample
//! period of a uniform grid ([`uniform_period`]).

use motor_model::Input;

use crate::error::FitError;

/// Names of the six parameters, in the order of every array here.
pub const PARAM_NAMES: [&str; 6] = ["R", "L", "k", "f", "J", "Ts"];
/// Their SI units.
pub const PARAM_UNITS: [&str; 6] = ["ohm", "H", "N·m/A", "N·m·s/rad", "kg·m²", "N·m"];

/// One step test as the identification sees it: a uniform grid starting at the step.
#[derive(Debug, Clone, Copy)]
pub struct StepTest<'a> {
    /// Step voltage E \[V\] (measured, after the step).
    pub volts: f64,
    /// Time of the first sample after the step instant \[s\] (≥ 0).
    pub t_first: f64,
    /// Sample period \[s\].
    pub dt: f64,
    /// Armature current \[A\].
    pub current: &'a [f64],
    /// Speed \[rad/s\] measured directly (tachometer), if any. Not used when `position` is given.
    pub speed: Option<&'a [f64]>,
    /// Encoder angle \[rad\] (any offset), if measured. Fitted through its central difference,
    /// with the same difference applied to the model's angle ([`Channel::EncoderSpeed`]).
    pub position: Option<&'a [f64]>,
    /// Samples of the current to leave out of the fit (clipped at an ADC rail), if any.
    pub exclude_current: Option<&'a [bool]>,
    /// Samples of the speed (or encoder speed) to leave out of the fit, if any.
    pub exclude_speed: Option<&'a [bool]>,
}

/// The fitted channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// Current \[A\].
    Current,
    /// Speed \[rad/s\] as measured (instantaneous: a tachometer).
    Speed,
    /// Speed \[rad/s\] as the central difference of the encoder angle, compared with the same
    /// central difference of the model's angle: exact however fast the motor, and blind to the
    /// encoder's unknown count offset.
    EncoderSpeed,
}

impl Channel {
    /// Lower-case name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Current => "current",
            Channel::Speed => "speed",
            Channel::EncoderSpeed => "encoder speed",
        }
    }
}

/// Fit quality of one channel of one test.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelQuality {
    /// Index of the test in the input.
    pub test: usize,
    /// Which channel.
    pub channel: Channel,
    /// Noise standard deviation used as the channel's weight (unit of the channel): estimated
    /// from the record, then the residual RMS of a first fit.
    pub noise_std: f64,
    /// RMS of the residual at the solution (unit of the channel).
    pub rms_residual: f64,
    /// Normalised-RMSE fit, `100 (1 − ‖y − ŷ‖/‖y − ȳ‖)` \[%\] (100 = perfect).
    pub nrmse_fit_percent: f64,
}

/// One fitted channel of one record: the samples fitted, as measured and as the fitted model
/// gives them (unit of the channel).
#[derive(Debug, Clone, PartialEq)]
pub struct FittedChannel {
    /// Index of the record (test) in the input.
    pub record: usize,
    /// Which channel.
    pub channel: Channel,
    /// Indices of the samples fitted in the record (those not left out as clipped).
    pub samples: Vec<usize>,
    /// The measured values at `samples` (for [`Channel::EncoderSpeed`], the central difference
    /// of the measured angle).
    pub measured: Vec<f64>,
    /// The fitted model at `samples`.
    pub model: Vec<f64>,
}

impl FittedChannel {
    /// The RMS of the residual, measured − model, over the samples both hold (the channel's
    /// unit: A, rad/s); 0 for an empty channel.
    pub fn residual_rms(&self) -> f64 {
        let n = self.measured.len().min(self.model.len());
        let sse: f64 = self
            .measured
            .iter()
            .zip(&self.model)
            .map(|(y, m)| (y - m).powi(2))
            .sum();
        (sse / n.max(1) as f64).sqrt()
    }
}

/// Fraction of the largest second differences ignored by [`noise_std`] (isolated glitches).
const NOISE_TRIM: f64 = 0.005;

/// Noise level of a sampled signal: the RMS of its second differences `Δ²y`, largest 0.5 %
/// dropped, over `√6` (the second difference of white noise has variance 6σ²; a smooth signal
/// contributes `y'' dt²`, negligible at logger rates). An RMS rather than a median, because
/// quantisation (ADC, encoder) shows as sparse jumps of one step whose median is 0. Floored at
/// 1e-7 of the signal's range, so that exact data still gives finite weights. Unit of `y`.
pub fn noise_std(y: &[f64]) -> f64 {
    noise_of_second_differences(y.windows(3).map(squared_second_difference).collect(), y)
}

/// `y[i+2] − 2 y[i+1] + y[i]` of a window of three samples.
pub(crate) fn second_difference(w: &[f64]) -> f64 {
    w[2] - 2.0 * w[1] + w[0]
}

/// [`second_difference`] squared.
pub(crate) fn squared_second_difference(w: &[f64]) -> f64 {
    second_difference(w).powi(2)
}

/// [`noise_std`] from the squared second differences `d2` of (parts of) the signal `y`: their
/// RMS, largest 0.5 % dropped, over `√6`, floored at [`noise_floor`] of `y`.
pub(crate) fn noise_of_second_differences(mut d2: Vec<f64>, y: &[f64]) -> f64 {
    let floor = noise_floor(y);
    if d2.is_empty() {
        return floor;
    }
    let keep = d2.len() - ((d2.len() as f64 * NOISE_TRIM) as usize).min(d2.len() - 1);
    d2.select_nth_unstable_by(keep - 1, f64::total_cmp);
    let mean_sq = d2[..keep].iter().sum::<f64>() / keep as f64;
    (mean_sq.sqrt() / 6f64.sqrt()).max(floor)
}

/// Smallest noise level a channel is given, as a fraction of the channel's range: finer than a
/// 23-bit reading of the signal's own span, so no real sensor is weighted above its worth.
/// Exact columns (an encoder angle written at full double precision, an ideal record) show a
/// scatter of 1e-12 of their range or less; weighted by it, the information on a direction the
/// other channels leave nearly free (the voltage scale, exactly degenerate with scaling all six
/// parameters) reaches 1e23 and the joint covariance loses the prior that bounds it below double
/// precision: `R 0.3001839 [0.3001832, 0.3001846]` on a noise-free 10-bit pair whose truth is 0.3.
/// With the floor at 1e-9 of the range that pair still claimed ±5e-6; from 1e-7 to 1e-4 its
/// intervals no longer depend on the floor (±1.4e-4, set by the voltage levels and then widened
/// by [`crate::excitation::input_uncertainty::pooled_level_variance`] to ±2.0e-4).
const NOISE_FLOOR_FRACTION: f64 = 1e-7;

/// [`NOISE_FLOOR_FRACTION`] of the range of `y` (unit of `y`; the smallest positive number for a
/// constant signal).
pub(crate) fn noise_floor(y: &[f64]) -> f64 {
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    NOISE_FLOOR_FRACTION * (hi - lo).abs().max(f64::MIN_POSITIVE)
}

/// The noise level a channel of level `sigma` and floor `floor` ([`noise_floor`]) is given in
/// the second stage of a fit, from its residual RMS `rms` at the first solution: `rms`, not
/// below the floor; `None` (kept) when `rms` is not finite or the channel fits to rounding.
pub(crate) fn reweighted_sigma(sigma: f64, floor: f64, rms: f64) -> Option<f64> {
    (rms.is_finite() && rms > 1e3 * sigma * f64::EPSILON.sqrt()).then(|| rms.max(floor))
}

/// One record of any excitation, on a uniform grid starting at the record's first sample.
#[derive(Debug, Clone, Copy)]
pub struct ExcitedRecord<'a> {
    /// The armature voltage applied, with time measured from the record's first sample
    /// ([`crate::voltage_input`] builds it from a measured voltage column).
    pub input: &'a Input,
    /// Sample period \[s\].
    pub dt: f64,
    /// Armature current \[A\].
    pub current: &'a [f64],
    /// Speed \[rad/s\] measured directly (tachometer), if any. Not used when `position` is given.
    pub speed: Option<&'a [f64]>,
    /// Encoder angle \[rad\] (any offset), if measured.
    pub position: Option<&'a [f64]>,
    /// Samples of the current to leave out (clipped at an ADC rail), if any.
    pub exclude_current: Option<&'a [bool]>,
    /// Samples of the speed or angle to leave out, if any.
    pub exclude_speed: Option<&'a [bool]>,
}

/// How a record's simulation starts at its first sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum InitialState {
    /// At rest: no current, no speed.
    #[default]
    Rest,
    /// In the steady state of the first voltage level, Eqs. (4), (5) (rest with `I = E/R`
    /// below breakaway): a function of the parameters, no parameter of its own.
    Steady,
    /// Anywhere: the initial current \[A\] and speed \[rad/s\] are fitted with the motor.
    Free,
}

impl InitialState {
    /// Its name in reports and on the command line: `rest`, `steady` or `free`.
    pub fn name(self) -> &'static str {
        match self {
            InitialState::Rest => "rest",
            InitialState::Steady => "steady",
            InitialState::Free => "free",
        }
    }
}

/// A record's initial state as fitted (no interval of its own: a free initial current rests
/// on the first few samples, where the sandwich covariance understates its spread — on
/// simulated slices it missed the true current by 3 standard errors — while the motor's
/// intervals, marginal over it, held).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedInitialState {
    /// How the record's simulation started.
    pub state: InitialState,
    /// Armature current at the first sample \[A\].
    pub current_a: f64,
    /// Speed at the first sample \[rad/s\].
    pub speed_rad_s: f64,
}

/// Relative deviation from the median sample period tolerated before a record counts as not
/// uniformly sampled.
const GRID_TOLERANCE: f64 = 1e-3;

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
    let mut dt = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    // Stamps far from zero (Unix time: 1.7e9 s) are held by a double to 2.4e-7 s, a sizeable
    // part of a fast logger's period: each step is off by up to that spacing, and so is their
    // median (0.017 % at 5 kHz). The grid is then judged with that spacing allowed, and its
    // period taken over the whole span, exact to the spacing over the sample count.
    let spacing = 2.0 * t[0].abs().max(t[t.len() - 1].abs()) * f64::EPSILON;
    let tolerance = if spacing > 1e-3 * GRID_TOLERANCE * dt {
        let last = t.len() - 1;
        if last > from {
            dt = (t[last] - t[from]) / (last - from) as f64;
        }
        GRID_TOLERANCE * dt + spacing
    } else {
        GRID_TOLERANCE * dt
    };
    for (i, w) in t.windows(2).enumerate().skip(from) {
        if ((w[1] - w[0]) - dt).abs() > tolerance {
            return Err(bad(format!("sample {} (t = {} s) breaks the uniform {dt} s grid: {purpose} needs uniform sampling", i + 1, w[1])));
        }
    }
    Ok(dt)
}
