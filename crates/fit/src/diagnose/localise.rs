//! Where the model disagrees with the records: the residual `r = y − ŷ` of every record and
//! channel against a noise floor estimated from the records themselves (SPEC section 7), located
//! in time, in operating region, in frequency and shaft angle, with the whiteness and input
//! cross-correlation that MATLAB's `resid` reports.
//!
//! # The floor model
//!
//! Every test compares the residual with what a perfect model would still leave: per sample `i`
//! a floor variance `vᵢ` (the expected `rᵢ²`) and the variance `wᵢ` of `rᵢ²` under that floor.
//!
//! - An analog channel (current, tachometer speed): `vᵢ = σ²` with `σ` the largest of
//!   the steady-state scatter (pooled line-fit scatter of the flat 32-sample blocks of the
//!   measured signal), the second-difference noise ([`crate::noise_std`]) and the ADC step
//!   `q/√12` (the quantum found from the values); `wᵢ = 2σ⁴` (Gaussian; conservative for the
//!   uniform error of a quantiser, whose `Var r² = 0.8 σ⁴`). The largest, so that a floor is
//!   never below what any of the three shows.
//! - An encoder speed (central difference of the counts, [`Channel::EncoderSpeed`]): the speed
//!   step `q_s = Δθ/(2 dt)` is found from the values (or from the angle). With the model moving
//!   `mᵢ = |ŷᵢ|/q_s` speed steps, the measured difference is one of the two codes around `mᵢ`,
//!   so with `g = frac(m)(1 − frac(m))`: `vᵢ = q_s² g`, `wᵢ = q_s⁴ g (1 − 4g)` (exact for a
//!   smooth motion; `Δθ²/(24 dt²)` on average, 0 at rest). `g` is floored at 0.01 and `w` at
//!   `v²/2`.
//! - An analog channel's `σ` is at least [`PRECISION_FLOOR`] (1e-6) of its signal's RMS about
//!   its mean, the accuracy of the simulations and of six written digits
//!   ([`FloorSource::Precision`]); a channel at that floor (a record simulated without noise)
//!   has its pattern tests untested, as its error is the integrator's, not noise.
//!
//! The reported `σ_floor` is `√(mean vᵢ)` and the NRMSE floor `√(Σ vᵢ)/‖y − ȳ‖` (=
//! `σ_floor √n/‖y − ȳ‖`); the gap is NRMSE − floor.
//!
//! Samples that the model puts within `3σ` of an ADC rail of a quantised channel (an extreme
//! value held by at least 1 % of the samples: a current at rest on a unipolar channel) are left
//! out of the tests (not of the NRMSE): the rail clips half of the noise there.
//!
//! # The excess test
//!
//! Over a set `S` of samples (a phase, a window, a band, the whole channel), `A = Σ rᵢ²` is
//! compared with `B = Σ vᵢ`. Residual samples are correlated (the noise may be coloured, and a
//! gap itself is), so the variance of `A` is `c Σ wᵢ` with `c = 1 + 2 Σₖ ρₖ²` (`ρₖ` the
//! residual's autocorrelation at lags `1..=max_lag`: `Var Σ r² = 2 Σᵢⱼ Cov(rᵢ, rⱼ)²` for
//! Gaussian residuals). `A` is then a scaled chi-square (Satterthwaite): `A ~ s χ²_ν` with
//! `s = c W/(2B)`, `ν = 2B²/(c W)`; the p-value is `P(χ²_ν > A/s)`. With white noise and a
//! constant floor, `ν = n/c` is the effective sample size and `A/s = Σ r²/σ²`.
//!
//! # Where
//!
//! - Phases ([`PhaseKind`]) from the voltage levels ([`crate::voltage_input`]) and the measured
//!   speed and current; the windows of `n/50` samples (half-overlapping) with the largest mean
//!   excess `rᵢ² − vᵢ`.
//! - Bands of |Ω| (a near-zero band, |Ω| ≤ 10 % of the largest, then equal-width bands) and of
//!   |I|; the operating variable is the model's prediction for the channel itself and the
//!   other sensor's measurement otherwise (a channel's own measurement would select its own
//!   noise). Trends: the least-squares slope of `rᵢ² − vᵢ` on |x| with its t under the floor
//!   model.
//! - Welch spectrum of the residual against the floor's white density; harmonic regression on
//!   the shaft angle.
//! - Whiteness (autocorrelation with 99 % bounds, Ljung–Box) and cross-correlation with the
//!   input's first difference, as MATLAB's `resid`.
//!
//! # False alarms
//!
//! Each channel has eleven families of tests (whole channel, phases, windows, speed bands,
//! speed trend, current bands, current trend, spectrum, angle ripple, whiteness, input
//! cross-correlation). A test is *significant* when its p-value is below
//! `alpha / (11 × channels × tests in its family)` (Bonferroni), so that under the floor model
//! the probability of any significant finding in one call of [`localise`] is at most
//! [`LocaliseSettings::alpha`] (default 1 %). The tests are approximations (Satterthwaite,
//! Bartlett, Newey–West), checked on simulated records in `tests/localise.rs`.
//!
//! Tests whose null hypothesis the encoder's quantisation breaks are reported but not used as
//! evidence (`tested: false`): at constant speed the counts make a deterministic, periodic
//! error, neither white nor flat in spectrum, whose sidebands put a speed ripple at other N per
//! revolution. An encoder speed is judged on magnitudes only (whiteness, cross-correlation,
//! spectrum and angle ripple are reported untested). With
//! [`LocaliseSettings::dithered_steps`] so is an ADC channel whose noise is below that many of
//! its steps, and its floor is at least half a step: without noise a quantiser's error is a
//! deterministic sawtooth of the signal, held for as many samples as the signal stays within
//! one code (up to ±q/2 for seconds on a settled signal), neither white nor flat in spectrum,
//! and noise below a step or so dithers it only in part. On the paper's noise-free 10-bit step
//! pair the correct model's residual had Ljung–Box Q = 4·10⁵ and spectral peaks 15 times the
//! floor; at 0.3–0.5 LSB of noise the correct model of the small servo or of the paper's motor
//! was "not white" in every seed tried, at 1 LSB in 3 of 20 seeds of an 8-bit record. The
//! step is found from the values, or from their differences where the values are too many
//! to show it (a 14-bit record).

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::{Serialize, Serializer};

use motor_model::Input;

use crate::error::FitError;
use crate::full_model::{noise_std, second_difference, Channel};
use crate::input_uncertainty::detect_quantum;
use crate::output_error::voltage_input;
use crate::stats::{chi_square_sf, f_sf, normal_sf, NeweyWest};

/// Test families per channel (for the Bonferroni split of [`LocaliseSettings::alpha`]).
const FAMILIES: f64 = 11.0;
/// Samples of a block of the steady-state scatter.
const SCATTER_BLOCK: usize = 32;
/// Flat blocks needed for a steady-state scatter.
const MIN_FLAT_BLOCKS: usize = 3;
/// A flat block whose scatter is more than this many times the median flat block's holds a
/// transient, not noise, and is left out of the steady-state scatter \[-\]. The scatter of
/// 30 degrees of freedom exceeds twice its median with a probability below 1e-7.
const SCATTER_OUTLIER: f64 = 2.0;
/// Floor of `g = frac(m)(1 − frac(m))` of an encoder speed.
const ENCODER_G_MIN: f64 = 0.01;
/// Two-sided 99 % point of the standard normal (the bounds of MATLAB's `resid`).
const Z_99: f64 = 2.575_829_303_548_901;
/// Fraction of the largest |speed| under which the motor is taken as stopped.
const STOPPED_FRACTION: f64 = 0.02;
/// Fraction of a column's samples at its extreme value that makes that value an ADC rail.
const RAIL_FRACTION: f64 = 0.01;
/// Fraction of the largest |Ω| of the near-zero speed band.
const NEAR_ZERO_FRACTION: f64 = 0.1;
/// Fraction of the largest |voltage| under which the voltage is taken as off.
const VOLTAGE_OFF_FRACTION: f64 = 0.02;
/// Relative tolerance of "settled" on the final value.
const SETTLED_FRACTION: f64 = 0.02;
/// Fraction of unsettled samples a steady state may hold.
const UNSETTLED_FRACTION: f64 = 0.01;
/// The peak neighbourhood: current above this fraction of the way from final to peak value.
const PEAK_LEVEL: f64 = 0.8;
/// Overshoot (relative to the final current) that makes a current peak.
const PEAK_FRACTION: f64 = 0.1;
/// Largest harmonic frequency, in cycles per sample, at which a sample enters the angle-ripple
/// regression of that harmonic (0.4: below Nyquist with a margin; above it a ripple in
/// the angle cannot be told from the aliased pattern of the encoder's counts).
const RIPPLE_NYQUIST: f64 = 0.4;
/// Revolutions its samples must travel for a harmonic to be fitted (ripple locked to the
/// rotation repeats; a transient gap over part of a turn does not).
const MIN_RIPPLE_REVOLUTIONS: f64 = 8.0;
/// Samples needed for the regression of one harmonic.
const MIN_RIPPLE_SAMPLES: usize = 64;
/// Half-width of the moving average of speed and current for the phases \[samples\].
const PHASE_SMOOTHING: usize = 2;
/// Samples needed in a channel.
const MIN_SAMPLES: usize = 32;

/// One channel of a record: the measured samples and the model's prediction of them.
#[derive(Debug, Clone, Copy)]
pub struct ResidualChannel<'a> {
    /// Which channel (sets its unit and its floor model).
    pub kind: Channel,
    /// Measured samples (unit of the channel: A or rad/s).
    pub measured: &'a [f64],
    /// The model's prediction, same length (for [`Channel::EncoderSpeed`]: the central
    /// difference of the model's angle).
    pub model: &'a [f64],
}

/// One record: its signals on a uniform grid and the channels to localise the residual of.
#[derive(Debug, Clone)]
pub struct ResidualRecord<'a> {
    /// Name for reports (e.g. the file name).
    pub name: &'a str,
    /// Sample period \[s\].
    pub dt: f64,
    /// Armature voltage \[V\] (the input: phases and cross-correlation).
    pub voltage: &'a [f64],
    /// Armature current \[A\] (phases, |I| bands), if recorded.
    pub current: Option<&'a [f64]>,
    /// Speed \[rad/s\] (phases, |Ω| bands), if recorded.
    pub speed: Option<&'a [f64]>,
    /// Shaft angle \[rad\] (ripple per revolution), if an encoder is fitted.
    pub angle: Option<&'a [f64]>,
    /// The channels whose residual is localised.
    pub channels: Vec<ResidualChannel<'a>>,
}

/// Settings of [`localise`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LocaliseSettings {
    /// Family-wise false-alarm probability of one call (0 < alpha < 1; default 0.01).
    pub alpha: f64,
    /// Largest lag of the autocorrelations (whiteness, effective sample size) and of the
    /// input cross-correlation \[samples\] (default 25, as `resid`).
    pub max_lag: usize,
    /// Length of the sliding windows \[samples\]; 0 = `n/50` within 16..=1000 (default 0).
    pub window_samples: usize,
    /// Windows of largest excess reported per channel (default 3).
    pub top_windows: usize,
    /// Equal-width bands of |Ω| above the near-zero band and of |I| (default 5).
    pub bands: usize,
    /// Welch segment length \[samples\] (default 256; shortened to the record).
    pub welch_segment: usize,
    /// Spectral peaks reported per channel (default 5).
    pub spectrum_peaks: usize,
    /// Largest harmonic N per revolution searched for angle ripple (default 64).
    pub max_harmonic: u32,
    /// Noise, in steps of a channel's ADC, below which its quantisation error is taken as not
    /// yet noise (module docs): the channel's pattern tests (spectrum, ripple, whiteness, input
    /// correlation) are then reported untested and its floor is at least half a step, the
    /// largest error of a quantiser without noise. 0 (default) takes every quantiser's error
    /// as noise, as the diagnosis's screening of candidates reads it;
    /// [`LocaliseSettings::model_check`] uses 1.5.
    pub dithered_steps: f64,
}

impl Default for LocaliseSettings {
    fn default() -> Self {
        LocaliseSettings {
            alpha: 0.01,
            max_lag: 25,
            window_samples: 0,
            top_windows: 3,
            bands: 5,
            welch_segment: 256,
            spectrum_peaks: 5,
            max_harmonic: 64,
            dithered_steps: 0.0,
        }
    }
}

impl LocaliseSettings {
    /// The settings of the model check `motorid identify` makes on every accepted fit
    /// ([`crate::StepPairIdentification::localise`]): the defaults at a family-wise
    /// false-alarm probability `alpha` of 1e-6, and quantisers with less than 1.5 steps of
    /// noise judged on the size of their residual only (`dithered_steps`: a channel read
    /// without noise, or with a third of a step, made the correct model "not white" and its
    /// settled stretches "above the floor"). At the default 0.01 the check flagged 10 of 94
    /// accepted fits of records without any effect (the heavy property run of
    /// `crates/cli/tests/property_identify.rs`): small misfits of a correct model (a slow
    /// rise over a few hundred samples, an encoder speed a few counts per sample) are
    /// significant at that level on long records, and a warning that often cries wolf is
    /// ignored. The unmodelled effects that bias a fit by several half-widths of its intervals
    /// (cogging, Stribeck friction, a current-sensor lag, inductance saturation at the paper's
    /// scale) stand out at p < 1e-12.
    pub fn model_check() -> Self {
        LocaliseSettings {
            alpha: 1e-6,
            dithered_steps: 1.5,
            ..LocaliseSettings::default()
        }
    }
}

/// Where a noise floor comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FloorSource {
    /// Scatter of the measured signal about a line on its flat stretches.
    SteadyScatter,
    /// Second differences of the measured signal: the smaller of their RMS
    /// ([`crate::noise_std`]) and their median magnitude's noise (a transient of a few
    /// samples inflates the one, whole ADC steps round the other).
    SecondDifference,
    /// The ADC step, `q/√12`.
    AdcStep,
    /// The encoder count of an encoder-derived speed.
    EncoderCount,
    /// Given by the caller ([`localise_with_floors`]): e.g. the noise an inverse model's
    /// regressors and torque carry through its filters.
    Given,
    /// [`PRECISION_FLOOR`] of the signal's RMS about its mean: a record without noise or
    /// quantiser (a simulation written out exactly) differs from its exact model only by the
    /// simulator's integration error and the digits written, which are neither noise nor a gap;
    /// the channel's pattern tests are then untested.
    Precision,
}

/// The smallest floor of a channel, as a share of its signal's RMS about its mean \[-\]: the
/// accuracy of the diagnosis's simulations (about 1e-6 of the response,
/// [`crate::diagnose::DiagnoseSettings::step_factor`]) and of values written to six
/// significant digits.
pub const PRECISION_FLOOR: f64 = 1e-6;

/// The noise floor of one channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseFloor {
    /// `σ_floor = √(mean vᵢ)` (unit of the channel).
    pub sigma: f64,
    /// The estimate that set it.
    pub source: FloorSource,
    /// Steady-state scatter (unit of the channel), if the signal has flat stretches.
    pub steady_scatter: Option<f64>,
    /// RMS second-difference noise (unit of the channel).
    pub second_difference: f64,
    /// ADC step found from the values (unit of the channel), if quantised.
    pub adc_step: Option<f64>,
    /// Encoder step Δθ \[rad\] of an encoder speed.
    pub encoder_step_rad: Option<f64>,
    /// The NRMSE a perfect model would still show, `σ_floor √n/‖y − ȳ‖`.
    pub nrmse_floor: f64,
    /// Samples left out of the tests because the model puts them within three floor
    /// deviations of an ADC rail of the channel (an extreme value held by at least 1 % of
    /// its samples: a current at rest on a unipolar channel), where the rail clips the noise.
    pub rail_samples: usize,
    /// Whether the channel is an ADC's whose noise does not dither it
    /// ([`LocaliseSettings::dithered_steps`]): its floor is then at least half a step and its
    /// pattern tests are untested.
    pub undithered: bool,
}

impl NoiseFloor {
    /// Whether the channel's error is noise that its pattern tests (spectrum, ripple,
    /// whiteness, input correlation, trends) can judge: not an ADC the noise does not dither,
    /// nor a record at [`FloorSource::Precision`].
    pub fn patterns_testable(&self) -> bool {
        !self.undithered && self.source != FloorSource::Precision
    }
}

/// An excess test over a set of samples (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ExcessTest {
    /// Samples in the set.
    pub samples: usize,
    /// Mean square residual over the mean floor variance, `Σ r²/Σ v` (1 = at the floor).
    pub ratio: f64,
    /// The chi-square statistic `A/s` (`Σ r²/σ²` for white noise and a constant floor).
    pub chi_square: f64,
    /// Effective degrees of freedom `ν`.
    pub dof: f64,
    /// `P(χ²_ν > A/s)`: the probability of so large a residual from the floor alone.
    pub p_value: f64,
    /// Whether `p_value` is below the test's share of `alpha`.
    pub significant: bool,
}

/// Kinds of phases of a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PhaseKind {
    /// Voltage off, motor stopped (pre-trigger samples included).
    Rest,
    /// Voltage on, speed ≈ 0: the current builds up to breakaway.
    BeforeBreakaway,
    /// After breakaway, the current rising towards its peak (or the speed to 90 % of its
    /// final value when the current does not overshoot).
    Rise,
    /// The neighbourhood of the current's peak (above 80 % of the way from final to peak).
    Peak,
    /// After the peak (or rise), until speed and current are within 2 % of their final values;
    /// also a coast with the voltage off.
    Settling,
    /// Speed and current within 2 % of their final values (plus three standard deviations of
    /// their noise) to the end of the level, but for at most 1 % of the samples.
    Steady,
    /// Voltage against the motion: from the new level until the speed reaches 20 % of its new
    /// final value in the new direction.
    Reversal,
    /// Speed ≈ 0 during a reversal with the voltage on.
    Sticking,
    /// Moving, in a record whose voltage is not piecewise constant (no step to phase against).
    Moving,
}

impl PhaseKind {
    /// Lower-case words for reports.
    pub fn words(self) -> &'static str {
        match self {
            PhaseKind::Rest => "rest",
            PhaseKind::BeforeBreakaway => "before breakaway",
            PhaseKind::Rise => "rise",
            PhaseKind::Peak => "current peak",
            PhaseKind::Settling => "settling",
            PhaseKind::Steady => "steady state",
            PhaseKind::Reversal => "reversal",
            PhaseKind::Sticking => "sticking",
            PhaseKind::Moving => "moving",
        }
    }
}

/// A phase of a record: samples `start..end`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Phase {
    /// Which phase.
    pub kind: PhaseKind,
    /// First sample.
    pub start: usize,
    /// One past the last sample.
    pub end: usize,
    /// Time of the first sample from the record's first \[s\].
    pub t_start_s: f64,
    /// Time one past the last sample \[s\].
    pub t_end_s: f64,
}

/// The excess of one channel over one phase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhaseExcess {
    /// The phase.
    pub phase: Phase,
    /// RMS residual over the phase (unit of the channel).
    pub rms_residual: f64,
    /// Mean residual over the phase (unit of the channel): a bias, or a ripple averaging out.
    pub mean_residual: f64,
    /// The test.
    pub test: ExcessTest,
}

/// A time window of large excess.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WindowExcess {
    /// First sample.
    pub start: usize,
    /// One past the last sample.
    pub end: usize,
    /// Time of the first sample \[s\].
    pub t_start_s: f64,
    /// Time one past the last sample \[s\].
    pub t_end_s: f64,
    /// Mean `rᵢ² − vᵢ` over the window (unit of the channel, squared).
    pub excess: f64,
    /// The test (Bonferroni over all the channel's windows).
    pub test: ExcessTest,
}

/// One band of an operating variable.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    /// Lowest |x| in the band (unit of the variable).
    pub lo: f64,
    /// Highest |x| in the band.
    pub hi: f64,
    /// The test over the band's samples.
    pub test: ExcessTest,
}

/// A trend of the excess `rᵢ² − vᵢ` with an operating variable |x|: the least-squares slope
/// with its standard error under the floor model (`c Σ (xᵢ − x̄)² wᵢ / Sxx²`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Trend {
    /// Slope of the excess per unit of |x| (channel unit² per unit of x).
    pub slope: f64,
    /// Its t statistic.
    pub t: f64,
    /// Two-sided p-value (normal).
    pub p_value: f64,
    /// Whether the test applies: not to an ADC channel whose noise does not dither its
    /// quantiser, whose floor is then a bound, not each sample's expected square (a settled
    /// current holds one code's error, a moving one sweeps the codes: a trend with |I| the
    /// model does not cause).
    pub tested: bool,
    /// Whether tested and `p_value` is below the family's share of `alpha`.
    pub significant: bool,
}

/// The residual against bands of an operating variable (|Ω| or |I|).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bands {
    /// The variable: `"speed"` (rad/s) or `"current"` (A).
    pub variable: &'static str,
    /// |Ω| ≤ 10 % of its largest value (speed only).
    pub near_zero: Option<Band>,
    /// Equal-width bands of |x| above the near-zero band up to its largest value, by
    /// increasing |x| (empty bands left out).
    pub bands: Vec<Band>,
    /// Trend of the excess with |x| over the samples above the near-zero band.
    pub trend: Option<Trend>,
}

/// A peak of the residual's spectrum.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SpectralPeak {
    /// Frequency \[Hz\].
    pub frequency_hz: f64,
    /// One-sided power spectral density (unit² / Hz).
    pub psd: f64,
    /// Over the floor's white density `2σ²dt`.
    pub ratio: f64,
    /// `P(χ²_ν > ν·ratio)`.
    pub p_value: f64,
    /// Whether below the family's share of `alpha` (Bonferroni over the bins).
    pub significant: bool,
}

/// The residual spectrum (Welch: Hann window, 50 % overlap, segment means removed).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spectrum {
    /// Segment length \[samples\].
    pub segment: usize,
    /// Equivalent degrees of freedom of each bin.
    pub dof: f64,
    /// The floor's one-sided density `2σ²dt` (unit² / Hz).
    pub floor_psd: f64,
    /// Whether the peaks were tested (not for an encoder speed or an ADC channel whose noise
    /// does not dither its quantiser: module docs).
    pub tested: bool,
    /// The largest local maxima, by decreasing ratio.
    pub peaks: Vec<SpectralPeak>,
}

/// Ripple locked to the shaft angle: the best of the harmonic regressions
/// `r = a + b sin(Nθ) + c cos(Nθ)`, N = 1..=max_harmonic, each over the samples where harmonic
/// N turns at most 0.4 cycles per sample; selected by F, judged by the Wald test of (b, c) on
/// a Newey–West covariance, Bonferroni over the N searched.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AngleRipple {
    /// The best N \[periods per revolution\] (largest F).
    pub periods_per_rev: u32,
    /// Samples in its regression: those where N turns at most 0.4 cycles per sample (below
    /// the Nyquist frequency with a margin); they must travel eight revolutions.
    pub samples: usize,
    /// Amplitude `√(b² + c²)` (unit of the channel).
    pub amplitude: f64,
    /// Phase φ of `A sin(Nθ + φ)` \[rad\].
    pub phase_rad: f64,
    /// Its F statistic (2 and n − 3 degrees of freedom, white errors).
    pub f_statistic: f64,
    /// p-value of the F test, not adjusted.
    pub f_p_value: f64,
    /// Wald statistic of (b, c) on a Newey–West covariance (χ²₂ under no ripple).
    pub wald: f64,
    /// Its p-value times the number of N searched (Bonferroni), at most 1.
    pub p_value: f64,
    /// Whether the test applies (not to an encoder speed: a speed ripple modulates the
    /// counts' periodic pattern, whose sidebands land at other N; nor to an ADC channel whose
    /// noise does not dither its quantiser).
    pub tested: bool,
    /// Whether tested and `p_value` is below the family's share of `alpha`.
    pub significant: bool,
}

/// The residual's autocorrelation, as MATLAB's `resid`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Whiteness {
    /// Autocorrelation at lags 1..=max_lag.
    pub autocorrelation: Vec<f64>,
    /// The 99 % bound `2.576/√n`.
    pub bound99: f64,
    /// Lags outside the bound.
    pub outside: Vec<usize>,
    /// Ljung–Box `Q = n(n + 2) Σ ρₖ²/(n − k)`.
    pub ljung_box_q: f64,
    /// Its degrees of freedom (max_lag).
    pub dof: usize,
    /// `P(χ²_dof > Q)`.
    pub p_value: f64,
    /// Whether the test applies (not to an encoder speed or an ADC channel whose noise does
    /// not dither its quantiser).
    pub tested: bool,
    /// Whether tested and `p_value` is below the family's share of `alpha`.
    pub significant: bool,
}

/// Cross-correlation of the residual with the input voltage, as MATLAB's `resid` but with the
/// input prewhitened by its first difference `Δu` (a step becomes an impulse): the test of
/// Box and Jenkins needs one of the two series white, and a step input correlates with any
/// constant offset of the residual (e.g. noise clipped at a rail at rest) at every lag.
/// For a step record the correlation at lag τ is then the residual τ samples after the step,
/// over its standard deviation and `√n`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrossCorrelation {
    /// Lags `−max_lag..=max_lag` \[samples\] (residual after the input for positive lags).
    pub lags: Vec<i64>,
    /// Correlation at each lag.
    pub values: Vec<f64>,
    /// The 99 % bound `2.576 √(1 + 2 Σ ρ_r(k) ρ_u(k))/√n` (residual white and independent of
    /// the input; the sum over lags 1..=max_lag, floored at 1).
    pub bound99: f64,
    /// Lags outside the bound.
    pub outside: Vec<i64>,
    /// Largest |value| over its standard error.
    pub max_ratio: f64,
    /// Two-sided p-value of that largest ratio times the number of lags, at most 1.
    pub p_value: f64,
    /// Whether the test applies (not to an encoder speed or an ADC channel whose noise does
    /// not dither its quantiser).
    pub tested: bool,
    /// Whether tested and `p_value` is below the family's share of `alpha`.
    pub significant: bool,
}

/// The localisation of one channel of one record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelLocalisation {
    /// Which channel.
    #[serde(serialize_with = "channel_key")]
    pub channel: Channel,
    /// Samples.
    pub samples: usize,
    /// `‖y − ŷ‖/‖y − ȳ‖` (SPEC section 7).
    pub nrmse: f64,
    /// The noise floor.
    pub floor: NoiseFloor,
    /// `nrmse − floor.nrmse_floor`.
    pub gap: f64,
    /// The excess test over the whole channel.
    pub overall: ExcessTest,
    /// Effective-sample-size factor `c = 1 + 2 Σ ρₖ²`.
    pub correlation_factor: f64,
    /// Excess per phase of the record.
    pub phases: Vec<PhaseExcess>,
    /// The windows of largest excess (non-overlapping, by decreasing excess).
    pub windows: Vec<WindowExcess>,
    /// Against |Ω| (if the record has a speed).
    pub speed_bands: Option<Bands>,
    /// Against |I| (if the record has a current).
    pub current_bands: Option<Bands>,
    /// The residual spectrum.
    pub spectrum: Spectrum,
    /// Ripple locked to the angle (if the record has an angle covering a revolution).
    pub angle_ripple: Option<AngleRipple>,
    /// Whiteness.
    pub whiteness: Whiteness,
    /// Cross-correlation with the voltage's first difference (if the voltage varies).
    pub cross_correlation: Option<CrossCorrelation>,
}

/// The localisation of one record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordLocalisation {
    /// The record's name.
    pub name: String,
    /// Its phases.
    pub phases: Vec<Phase>,
    /// Its channels.
    pub channels: Vec<ChannelLocalisation>,
}

/// What the localisation found, for every record and channel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Localisation {
    /// The settings used.
    pub settings: LocaliseSettings,
    /// Significance level of each family of tests of a channel,
    /// `alpha/(11 × channels)` (then split within the family).
    pub family_alpha: f64,
    /// Per record.
    pub records: Vec<RecordLocalisation>,
}

/// What a significant finding is about.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FindingKind {
    /// The channel as a whole is above its floor.
    Gap,
    /// A phase is above the floor.
    Phase {
        /// Which phase.
        phase: PhaseKind,
        /// Its start \[s\].
        t_start_s: f64,
        /// Its end \[s\].
        t_end_s: f64,
    },
    /// A time window is above the floor.
    Window {
        /// Its start \[s\].
        t_start_s: f64,
        /// Its end \[s\].
        t_end_s: f64,
    },
    /// The band |Ω| ≈ 0 is above the floor.
    NearZeroSpeed {
        /// Whether no moving band is.
        only: bool,
    },
    /// A band of |Ω| (not near zero) is above the floor.
    SpeedBand {
        /// Lowest |Ω| \[rad/s\].
        lo: f64,
        /// Highest |Ω| \[rad/s\].
        hi: f64,
    },
    /// A band of |I| is above the floor.
    CurrentBand {
        /// Lowest |I| \[A\].
        lo: f64,
        /// Highest |I| \[A\].
        hi: f64,
    },
    /// The excess trends with |Ω|.
    SpeedTrend {
        /// Grows (true) or falls with |Ω|.
        grows: bool,
    },
    /// The excess trends with |I|.
    CurrentTrend {
        /// Grows (true) or falls with |I|.
        grows: bool,
    },
    /// A spectral peak above the floor.
    SpectralPeak {
        /// Its frequency \[Hz\].
        frequency_hz: f64,
    },
    /// Ripple at N per revolution.
    AngleRipple {
        /// N.
        periods_per_rev: u32,
    },
    /// The residual is not white.
    NotWhite,
    /// The residual correlates with the input.
    InputCorrelation,
}

/// One significant finding.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// The record's name.
    pub record: String,
    /// The channel.
    #[serde(serialize_with = "channel_key")]
    pub channel: Channel,
    /// What.
    pub what: FindingKind,
    /// The test's number: the mean square over the floor (gap, phase, window, band), t
    /// (trend), the PSD over the floor (peak), the Wald statistic (ripple), Q (whiteness) or
    /// the largest correlation in standard errors (input).
    pub statistic: f64,
    /// Its p-value (adjusted where the test says so).
    pub p_value: f64,
    /// In words, e.g. "gap grows with |Ω| (t = 7.2)".
    pub text: String,
}

fn channel_key<S: Serializer>(c: &Channel, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(match c {
        Channel::Current => "current",
        Channel::Speed => "speed",
        Channel::EncoderSpeed => "encoder_speed",
    })
}

/// A p-value in words: `p = 3.1e-4`, or `p < 1e-12`.
fn p_words(p: f64) -> String {
    if p < 1e-12 {
        "p < 1e-12".to_string()
    } else {
        format!("p = {p:.1e}")
    }
}

impl Localisation {
    /// Every significant finding, by increasing p-value, in words for the ranking and the
    /// report (e.g. "gap grows with |Ω| (t = 7.2)", "ripple at 6 per revolution (p < 1e-12)").
    pub fn significant_findings(&self) -> Vec<Finding> {
        let mut out = Vec::new();
        for rec in &self.records {
            for ch in &rec.channels {
                channel_findings(&rec.name, ch, &mut out);
            }
        }
        out.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
        out
    }

    /// Whether anything is significant.
    pub fn any_significant(&self) -> bool {
        !self.significant_findings().is_empty()
    }

    /// The localisation of `channel` of the record named `record`, if present.
    pub fn channel(&self, record: &str, channel: Channel) -> Option<&ChannelLocalisation> {
        self.records
            .iter()
            .find(|r| r.name == record)?
            .channels
            .iter()
            .find(|c| c.channel == channel)
    }
}

fn channel_findings(record: &str, ch: &ChannelLocalisation, out: &mut Vec<Finding>) {
    let mut push = |what: FindingKind, statistic: f64, p_value: f64, text: String| {
        out.push(Finding {
            record: record.to_string(),
            channel: ch.channel,
            what,
            statistic,
            p_value,
            text: format!("{record}, {}: {text}", ch.channel.name()),
        });
    };
    if ch.overall.significant {
        push(
            FindingKind::Gap,
            ch.overall.ratio,
            ch.overall.p_value,
            format!(
                "NRMSE {:.4} over a floor of {:.4} (gap {:.4}; mean square {:.3}× the floor, {})",
                ch.nrmse,
                ch.floor.nrmse_floor,
                ch.gap,
                ch.overall.ratio,
                p_words(ch.overall.p_value)
            ),
        );
    }
    for ph in ch.phases.iter().filter(|p| p.test.significant) {
        push(
            FindingKind::Phase {
                phase: ph.phase.kind,
                t_start_s: ph.phase.t_start_s,
                t_end_s: ph.phase.t_end_s,
            },
            ph.test.ratio,
            ph.test.p_value,
            format!(
                "gap in the {} phase, {:.4}–{:.4} s ({:.3}× the floor, {})",
                ph.phase.kind.words(),
                ph.phase.t_start_s,
                ph.phase.t_end_s,
                ph.test.ratio,
                p_words(ph.test.p_value)
            ),
        );
    }
    for w in ch.windows.iter().filter(|w| w.test.significant) {
        push(
            FindingKind::Window {
                t_start_s: w.t_start_s,
                t_end_s: w.t_end_s,
            },
            w.test.ratio,
            w.test.p_value,
            format!(
                "gap in the window {:.4}–{:.4} s ({:.3}× the floor, {})",
                w.t_start_s,
                w.t_end_s,
                w.test.ratio,
                p_words(w.test.p_value)
            ),
        );
    }
    for bands in [&ch.speed_bands, &ch.current_bands].into_iter().flatten() {
        let (sym, unit) = if bands.variable == "speed" {
            ("|Ω|", "rad/s")
        } else {
            ("|I|", "A")
        };
        let any_moving = bands.bands.iter().any(|b| b.test.significant);
        if let Some(z) = bands.near_zero.filter(|z| z.test.significant) {
            push(
                FindingKind::NearZeroSpeed { only: !any_moving },
                z.test.ratio,
                z.test.p_value,
                format!(
                    "gap {}near Ω = 0 (|Ω| ≤ {:.3} rad/s: {:.3}× the floor, {})",
                    if any_moving { "also " } else { "only " },
                    z.hi,
                    z.test.ratio,
                    p_words(z.test.p_value)
                ),
            );
        }
        for b in bands.bands.iter().filter(|b| b.test.significant) {
            let what = if bands.variable == "speed" {
                FindingKind::SpeedBand { lo: b.lo, hi: b.hi }
            } else {
                FindingKind::CurrentBand { lo: b.lo, hi: b.hi }
            };
            push(
                what,
                b.test.ratio,
                b.test.p_value,
                format!(
                    "gap at {sym} {:.3}–{:.3} {unit} ({:.3}× the floor, {})",
                    b.lo,
                    b.hi,
                    b.test.ratio,
                    p_words(b.test.p_value)
                ),
            );
        }
        if let Some(t) = bands.trend.filter(|t| t.significant) {
            let grows = t.t > 0.0;
            let what = if bands.variable == "speed" {
                FindingKind::SpeedTrend { grows }
            } else {
                FindingKind::CurrentTrend { grows }
            };
            push(
                what,
                t.t,
                t.p_value,
                format!(
                    "gap {} with {sym} (t = {:.1})",
                    if grows { "grows" } else { "falls" },
                    t.t
                ),
            );
        }
    }
    for pk in ch.spectrum.peaks.iter().filter(|p| p.significant) {
        push(
            FindingKind::SpectralPeak {
                frequency_hz: pk.frequency_hz,
            },
            pk.ratio,
            pk.p_value,
            format!(
                "spectral peak at {:.3} Hz ({:.1}× the floor, {})",
                pk.frequency_hz,
                pk.ratio,
                p_words(pk.p_value)
            ),
        );
    }
    if let Some(a) = ch.angle_ripple.filter(|a| a.significant) {
        push(
            FindingKind::AngleRipple {
                periods_per_rev: a.periods_per_rev,
            },
            a.wald,
            a.p_value,
            format!(
                "ripple at {} per revolution (amplitude {:.3e}, {})",
                a.periods_per_rev,
                a.amplitude,
                p_words(a.p_value)
            ),
        );
    }
    if ch.whiteness.significant {
        push(
            FindingKind::NotWhite,
            ch.whiteness.ljung_box_q,
            ch.whiteness.p_value,
            format!(
                "residual not white (Ljung–Box Q = {:.1} on {} lags, {})",
                ch.whiteness.ljung_box_q,
                ch.whiteness.dof,
                p_words(ch.whiteness.p_value)
            ),
        );
    }
    if let Some(x) = ch.cross_correlation.as_ref().filter(|x| x.significant) {
        push(
            FindingKind::InputCorrelation,
            x.max_ratio,
            x.p_value,
            format!(
                "residual correlates with the voltage ({:.1} standard errors, {})",
                x.max_ratio,
                p_words(x.p_value)
            ),
        );
    }
}

/// Localises the residual of every record and channel (see the module documentation for the
/// floor model, the tests and their false-alarm rate).
///
/// Errors: a setting out of range ([`FitError::InvalidSetting`]); a record whose period is not
/// positive, whose signals differ in length from its voltage, with non-finite samples or fewer
/// than 32 samples ([`FitError::BadData`]).
pub fn localise(
    records: &[ResidualRecord],
    settings: &LocaliseSettings,
) -> Result<Localisation, FitError> {
    localise_with_floors(records, &[], settings)
}

/// [`localise`] with the noise floor of some channels given: `floors[k][j]`, when present and
/// positive, is the floor deviation `σ` of channel `j` of record `k` (unit of the channel;
/// white, `vᵢ = σ²`, `wᵢ = 2σ⁴`, [`FloorSource::Given`]), for a residual whose floor the
/// measured signal cannot show (a filtered, decimated torque); the others are estimated as
/// [`localise`] does.
pub fn localise_with_floors(
    records: &[ResidualRecord],
    floors: &[Vec<f64>],
    settings: &LocaliseSettings,
) -> Result<Localisation, FitError> {
    check_settings(settings)?;
    for rec in records {
        check_record(rec)?;
    }
    let n_channels: usize = records.iter().map(|r| r.channels.len()).sum();
    let family_alpha = settings.alpha / (FAMILIES * n_channels.max(1) as f64);
    let mut planner = FftPlanner::new();
    let out = records
        .iter()
        .enumerate()
        .map(|(k, rec)| {
            let n = rec.voltage.len();
            let phases = detect_phases(rec, n);
            let channels = rec
                .channels
                .iter()
                .enumerate()
                .map(|(j, ch)| {
                    let given = floors
                        .get(k)
                        .and_then(|f| f.get(j))
                        .copied()
                        .filter(|s| s.is_finite() && *s > 0.0);
                    localise_channel(
                        rec,
                        ch,
                        given,
                        &phases,
                        settings,
                        family_alpha,
                        &mut planner,
                    )
                })
                .collect();
            RecordLocalisation {
                name: rec.name.to_string(),
                phases,
                channels,
            }
        })
        .collect();
    Ok(Localisation {
        settings: *settings,
        family_alpha,
        records: out,
    })
}

fn check_settings(s: &LocaliseSettings) -> Result<(), FitError> {
    let bad = |name: &'static str, value: f64, expected: &'static str| {
        Err(FitError::InvalidSetting {
            name,
            value,
            expected,
        })
    };
    if !(s.alpha > 0.0 && s.alpha < 1.0) {
        return bad("alpha", s.alpha, "a probability strictly between 0 and 1");
    }
    if s.max_lag == 0 {
        return bad("max_lag", 0.0, "at least 1 sample");
    }
    if s.bands == 0 {
        return bad("bands", 0.0, "at least 1 band");
    }
    if s.welch_segment < 8 {
        return bad(
            "welch_segment",
            s.welch_segment as f64,
            "at least 8 samples",
        );
    }
    if s.max_harmonic == 0 {
        return bad("max_harmonic", 0.0, "at least 1 period per revolution");
    }
    Ok(())
}

fn check_record(rec: &ResidualRecord) -> Result<(), FitError> {
    let n = rec.voltage.len();
    let bad = |series: String, reason: String| Err(FitError::BadData { series, reason });
    if !(rec.dt.is_finite() && rec.dt > 0.0) {
        return bad(
            format!("record {}", rec.name),
            format!("sample period {} s: expected a positive period", rec.dt),
        );
    }
    if n < MIN_SAMPLES {
        return bad(
            format!("record {}", rec.name),
            format!("{n} samples: at least {MIN_SAMPLES} are needed to localise a residual"),
        );
    }
    let mut series: Vec<(String, &[f64])> = vec![("voltage".to_string(), rec.voltage)];
    for (name, s) in [
        ("current", rec.current),
        ("speed", rec.speed),
        ("angle", rec.angle),
    ] {
        if let Some(s) = s {
            series.push((name.to_string(), s));
        }
    }
    for ch in &rec.channels {
        series.push((format!("measured {}", ch.kind.name()), ch.measured));
        series.push((format!("model {}", ch.kind.name()), ch.model));
    }
    for (name, s) in series {
        if s.len() != n {
            return bad(
                format!("record {}, {name}", rec.name),
                format!(
                    "{} samples where the voltage has {n}: the channels must align",
                    s.len()
                ),
            );
        }
        if let Some((i, v)) = s.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return bad(
                format!("record {}, {name}", rec.name),
                format!("sample {i} is {v}"),
            );
        }
    }
    Ok(())
}

/// The quantum of values that are multiples of one step up to rounding (differences of
/// quantised angles, central differences of counts): [`detect_quantum`] of the values rounded to
/// 1e-9 of their largest magnitude.
fn quantum_of(x: &[f64]) -> Option<f64> {
    let grid = 1e-9 * x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if grid.is_nan() || grid <= 0.0 {
        return None;
    }
    let rounded: Vec<f64> = x.iter().map(|v| (v / grid).round() * grid).collect();
    detect_quantum(&rounded)
}

/// The noise of `y` from the median of its second differences' magnitudes: `median|Δ²y|`
/// over `0.6745 √6` (Gaussian noise σ gives second differences of deviation `√6 σ`, whose
/// median magnitude is 0.6745 of it). 0 for a signal that holds its value in most windows
/// of three samples (a quantiser without noise).
fn median_noise(y: &[f64]) -> f64 {
    let mut d2: Vec<f64> = y.windows(3).map(|w| second_difference(w).abs()).collect();
    if d2.is_empty() {
        return 0.0;
    }
    let mid = d2.len() / 2;
    let (_, median, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    *median / (0.6745 * 6f64.sqrt())
}

/// Per-sample floor: expected `r²` and the variance of `r²`, zero at the samples left out.
struct FloorModel {
    v: Vec<f64>,
    w: Vec<f64>,
    /// Samples in the tests (not at an ADC rail).
    keep: Vec<bool>,
    report: NoiseFloor,
}

/// Samples whose model value is within three floor deviations of an ADC rail of the measured
/// column `y` (an extreme value held by at least [`RAIL_FRACTION`] of its samples): the rail
/// clips the noise there (half of it reads the rail), so neither the floor nor the residual's
/// mean hold. `false` marks a sample left out.
fn off_rails(y: &[f64], model: &[f64], sigma: f64) -> Vec<bool> {
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let held = |rail: f64| {
        y.iter().filter(|&&v| v == rail).count() as f64 >= RAIL_FRACTION * y.len() as f64
    };
    let (low, high) = (held(lo), held(hi));
    model
        .iter()
        .map(|&m| !((low && m <= lo + 3.0 * sigma) || (high && m >= hi - 3.0 * sigma)))
        .collect()
}

/// Pooled scatter about a line of the flat blocks of `y` (a block is flat when its fitted
/// trend across the block is within two residual standard deviations), leaving out blocks
/// whose scatter is more than [`SCATTER_OUTLIER`] times the median block's: a block holding a
/// transient shorter than itself (a current spike a few samples long when L/R is below the
/// sample period, at each switch of a square wave) has almost no trend and a scatter set by
/// the spike, and a few of them pooled with the quiet blocks made the floor of a 0.6 mA noise
/// 0.11 A.
fn steady_scatter(y: &[f64]) -> Option<f64> {
    let b = SCATTER_BLOCK;
    let xm = (b as f64 - 1.0) / 2.0;
    let sxx: f64 = (0..b).map(|i| (i as f64 - xm).powi(2)).sum();
    let mut flat: Vec<f64> = Vec::new();
    for block in y.chunks_exact(b) {
        let ym = block.iter().sum::<f64>() / b as f64;
        let (syy, sxy) = block
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(syy, sxy), (i, &v)| {
                (syy + (v - ym).powi(2), sxy + (i as f64 - xm) * (v - ym))
            });
        let slope = sxy / sxx;
        let rss = (syy - slope * sxy).max(0.0);
        let s = (rss / (b - 2) as f64).sqrt();
        if s > 0.0 && slope.abs() * b as f64 <= 2.0 * s {
            flat.push(rss);
        }
    }
    if flat.len() < MIN_FLAT_BLOCKS {
        return None;
    }
    flat.sort_by(f64::total_cmp);
    let median = flat[flat.len() / 2];
    let kept: Vec<f64> = flat
        .into_iter()
        .filter(|&rss| rss <= SCATTER_OUTLIER * SCATTER_OUTLIER * median)
        .collect();
    (kept.len() >= MIN_FLAT_BLOCKS)
        .then(|| (kept.iter().sum::<f64>() / (kept.len() * (b - 2)) as f64).sqrt())
}

/// A white floor of deviation `sigma` given by the caller.
fn given_floor_model(ch: &ResidualChannel, sigma: f64, y_ss: f64) -> FloorModel {
    let n = ch.measured.len();
    let v = vec![sigma * sigma; n];
    let report = NoiseFloor {
        sigma,
        source: FloorSource::Given,
        steady_scatter: steady_scatter(ch.measured),
        second_difference: noise_std(ch.measured),
        adc_step: detect_quantum(ch.measured),
        encoder_step_rad: None,
        nrmse_floor: if y_ss > 0.0 {
            sigma * (n as f64).sqrt() / y_ss.sqrt()
        } else {
            f64::INFINITY
        },
        rail_samples: 0,
        undithered: false,
    };
    FloorModel {
        w: vec![2.0 * sigma.powi(4); n],
        v,
        keep: vec![true; n],
        report,
    }
}

fn floor_model(
    rec: &ResidualRecord,
    ch: &ResidualChannel,
    y_ss: f64,
    dithered_steps: f64,
) -> FloorModel {
    let y = ch.measured;
    let n = y.len();
    let second_difference = noise_std(y);
    let median_difference = median_noise(y);
    let steady = steady_scatter(y);
    // Where the values are too many to show the step, their differences can (a 14-bit
    // record): looked for only where it matters, for `dithered_steps`.
    let adc_step = detect_quantum(y).or_else(|| {
        (dithered_steps > 0.0)
            .then(|| {
                let differences: Vec<f64> = y.windows(2).map(|w| w[1] - w[0]).collect();
                quantum_of(&differences)
            })
            .flatten()
    });
    let nrmse_floor = |v: &[f64]| {
        let s = v.iter().sum::<f64>().sqrt();
        if y_ss > 0.0 {
            s / y_ss.sqrt()
        } else {
            f64::INFINITY
        }
    };
    if ch.kind == Channel::EncoderSpeed {
        let from_angle = rec.angle.and_then(|th| {
            let steps: Vec<f64> = th.windows(2).map(|w| w[1] - w[0]).collect();
            quantum_of(&steps)
        });
        let q_s = from_angle
            .map(|q| q / (2.0 * rec.dt))
            .or_else(|| quantum_of(y));
        if let Some(q) = q_s {
            let (v, w): (Vec<f64>, Vec<f64>) = ch
                .model
                .iter()
                .map(|m| {
                    let m = m.abs() / q;
                    let f = m - m.floor();
                    let g = (f * (1.0 - f)).max(ENCODER_G_MIN);
                    let v = q * q * g;
                    (v, (q.powi(4) * g * (1.0 - 4.0 * g)).max(0.5 * v * v))
                })
                .unzip();
            let sigma = (v.iter().sum::<f64>() / n as f64).sqrt();
            let report = NoiseFloor {
                sigma,
                source: FloorSource::EncoderCount,
                steady_scatter: steady,
                second_difference,
                adc_step: None,
                encoder_step_rad: Some(2.0 * rec.dt * q),
                nrmse_floor: nrmse_floor(&v),
                rail_samples: 0,
                undithered: false,
            };
            return FloorModel {
                v,
                w,
                keep: vec![true; n],
                report,
            };
        }
    }
    // Each noise estimate can only take some signal for noise, never the reverse: the RMS
    // second difference a fast signal's curvature (a noise-free 14-bit current of a 1 ms τe
    // at 6 kHz read several steps of "noise"), the flat stretches a staircase's transients
    // (9 steps on a noise-free 10-bit one), the median second difference (robust to the
    // few samples of a PRBS's switches) the least. The smallest is the noise.
    let undithered = dithered_steps > 0.0
        && adc_step.is_some_and(|q| {
            let measured_noise = steady
                .unwrap_or(f64::INFINITY)
                .min(second_difference)
                .min(median_difference);
            measured_noise < dithered_steps * q
        });
    // A quantiser the noise does not dither errs by up to half a step, held as long as the
    // signal stays within one code: its floor is that bound.
    let adc = adc_step.map(|q| {
        if undithered {
            0.5 * q
        } else {
            q / 12f64.sqrt()
        }
    });
    // The floor: the smaller of the RMS and the median second difference's noise, raised to
    // the steady-state scatter (which sees the low frequencies of coloured noise that
    // differences remove) and to the ADC step's. A current spike of a few samples at each
    // switch (L/R below the sample period) makes the RMS second difference many times the
    // noise, while the median of a quantised record's second differences, which are whole
    // steps, rounds to a step (1.2 times the noise at one step of noise): each errs where
    // the other does not.
    let mut sigma = second_difference.min(median_difference);
    let mut source = FloorSource::SecondDifference;
    for (s, src) in [
        (steady, FloorSource::SteadyScatter),
        (adc, FloorSource::AdcStep),
    ] {
        if let Some(s) = s.filter(|&s| s > sigma) {
            sigma = s;
            source = src;
        }
    }
    let precision = PRECISION_FLOOR * (y_ss / n as f64).sqrt();
    if precision > sigma {
        sigma = precision;
        source = FloorSource::Precision;
    }
    let mut v = vec![sigma * sigma; n];
    let mut w = vec![2.0 * sigma.powi(4); n];
    let floor_of_all = nrmse_floor(&v);
    let keep = if adc_step.is_some() {
        off_rails(y, ch.model, sigma)
    } else {
        vec![true; n]
    };
    for ((v, w), &k) in v.iter_mut().zip(w.iter_mut()).zip(&keep) {
        if !k {
            (*v, *w) = (0.0, 0.0);
        }
    }
    let report = NoiseFloor {
        sigma,
        source,
        steady_scatter: steady,
        second_difference,
        adc_step,
        encoder_step_rad: None,
        nrmse_floor: floor_of_all,
        rail_samples: keep.iter().filter(|k| !**k).count(),
        undithered,
    };
    FloorModel { v, w, keep, report }
}

/// The correlation factor `1 + 2 Σₖ ρₖ²` of `x` over lags 1..=max_lag ([`autocorrelation`]):
/// how much correlation in time inflates the variance of a sum of squares of `x`.
pub(crate) fn correlation_factor(x: &[f64], max_lag: usize) -> f64 {
    factor_of(&autocorrelation(x, max_lag))
}

/// `1 + 2 Σₖ ρₖ²` of the autocorrelations `rho`.
fn factor_of(rho: &[f64]) -> f64 {
    1.0 + 2.0 * rho.iter().map(|p| p * p).sum::<f64>()
}

/// Autocorrelation of `x` (mean removed) at lags 1..=max_lag (biased estimator, as `resid`).
fn autocorrelation(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    let m = x.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = x.iter().map(|v| v - m).collect();
    let c0: f64 = d.iter().map(|v| v * v).sum();
    (1..=max_lag)
        .map(|k| {
            if k >= n || c0 <= 0.0 {
                return 0.0;
            }
            d[k..]
                .iter()
                .zip(&d[..n - k])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / c0
        })
        .collect()
}

/// Prefix sums of `r²`, `v`, `w`.
struct Prefix {
    a: Vec<f64>,
    b: Vec<f64>,
    w: Vec<f64>,
}

impl Prefix {
    fn new(r: &[f64], floor: &FloorModel) -> Self {
        let scan = |it: &mut dyn Iterator<Item = f64>| {
            let mut acc = 0.0;
            std::iter::once(0.0)
                .chain(it.map(|x| {
                    acc += x;
                    acc
                }))
                .collect::<Vec<f64>>()
        };
        Prefix {
            a: scan(&mut r.iter().map(|x| x * x)),
            b: scan(&mut floor.v.iter().copied()),
            w: scan(&mut floor.w.iter().copied()),
        }
    }

    fn sums(&self, start: usize, end: usize) -> (f64, f64, f64) {
        (
            self.a[end] - self.a[start],
            self.b[end] - self.b[start],
            self.w[end] - self.w[start],
        )
    }
}

/// The excess test of sums `A = Σ r²`, `B = Σ v`, `W = Σ w` over `samples` samples.
fn excess_test((a, b, w): (f64, f64, f64), samples: usize, c: f64, alpha_test: f64) -> ExcessTest {
    if samples == 0 || b <= 0.0 || w <= 0.0 {
        return ExcessTest {
            samples,
            ratio: f64::NAN,
            chi_square: f64::NAN,
            dof: 0.0,
            p_value: 1.0,
            significant: false,
        };
    }
    let nu = 2.0 * b * b / (c * w);
    let scale = c * w / (2.0 * b);
    let chi_square = a / scale;
    let p_value = chi_square_sf(chi_square, nu);
    ExcessTest {
        samples,
        ratio: a / b,
        chi_square,
        dof: nu,
        p_value,
        significant: p_value < alpha_test,
    }
}

fn localise_channel(
    rec: &ResidualRecord,
    ch: &ResidualChannel,
    given_floor: Option<f64>,
    phases: &[Phase],
    settings: &LocaliseSettings,
    family_alpha: f64,
    planner: &mut FftPlanner<f64>,
) -> ChannelLocalisation {
    let y = ch.measured;
    let n = y.len();
    let r: Vec<f64> = y.iter().zip(ch.model).map(|(a, b)| a - b).collect();
    let y_mean = y.iter().sum::<f64>() / n as f64;
    let y_ss: f64 = y.iter().map(|v| (v - y_mean).powi(2)).sum();
    let r_ss: f64 = r.iter().map(|v| v * v).sum();
    let nrmse = if y_ss > 0.0 {
        (r_ss / y_ss).sqrt()
    } else {
        f64::INFINITY
    };
    let floor = match given_floor {
        Some(sigma) => given_floor_model(ch, sigma, y_ss),
        None => floor_model(rec, ch, y_ss, settings.dithered_steps),
    };
    let full_residual = r;
    // The residual of the tests: zero at the samples left out.
    let r: Vec<f64> = full_residual
        .iter()
        .zip(&floor.keep)
        .map(|(&r, &k)| if k { r } else { 0.0 })
        .collect();
    let rho = autocorrelation(&r, settings.max_lag.min(n - 1));
    let c = factor_of(&rho);
    let prefix = Prefix::new(&r, &floor);
    let overall = excess_test(prefix.sums(0, n), n, c, family_alpha);
    // Tests of the residual's pattern (spectrum, whiteness, input correlation, ripple) need an
    // error that is noise: not an encoder's counts, nor a quantiser whose noise does not yet
    // dither it (module docs).
    let pattern_tested = ch.kind != Channel::EncoderSpeed && floor.report.patterns_testable();

    let phase_alpha = family_alpha / phases.len().max(1) as f64;
    let phase_stats = phases
        .iter()
        .map(|ph| {
            let seg = &full_residual[ph.start..ph.end];
            let len = seg.len().max(1) as f64;
            PhaseExcess {
                phase: *ph,
                rms_residual: (seg.iter().map(|v| v * v).sum::<f64>() / len).sqrt(),
                mean_residual: seg.iter().sum::<f64>() / len,
                test: excess_test(prefix.sums(ph.start, ph.end), seg.len(), c, phase_alpha),
            }
        })
        .collect();

    let windows = top_windows(&prefix, n, rec.dt, c, settings, family_alpha);
    let speed_bands =
        operating_variable(rec, ch, &[Channel::Speed, Channel::EncoderSpeed], rec.speed)
            .map(|s| bands(&r, &floor, s, "speed", true, c, settings, family_alpha));
    let current_bands = operating_variable(rec, ch, &[Channel::Current], rec.current)
        .map(|s| bands(&r, &floor, s, "current", false, c, settings, family_alpha));
    let sigma2 = floor.report.sigma.powi(2);
    let spectrum = welch(
        &r,
        rec.dt,
        sigma2,
        pattern_tested,
        settings,
        family_alpha,
        planner,
    );
    let angle_ripple = rec
        .angle
        .and_then(|th| angle_ripple(&r, th, settings.max_harmonic, pattern_tested, family_alpha));
    let whiteness = whiteness(&rho, n, pattern_tested, family_alpha);
    let cross_correlation = cross_correlation(
        &r,
        &rho,
        rec.voltage,
        settings.max_lag,
        pattern_tested,
        family_alpha,
    );
    ChannelLocalisation {
        channel: ch.kind,
        samples: n,
        nrmse,
        gap: nrmse - floor.report.nrmse_floor,
        floor: floor.report,
        overall,
        correlation_factor: c,
        phases: phase_stats,
        windows,
        speed_bands,
        current_bands,
        spectrum,
        angle_ripple,
        whiteness,
        cross_correlation,
    }
}

/// The operating variable of the bands of channel `ch`: the measured signal of another sensor
/// (its noise is independent of the channel's), but the model's prediction of the channel
/// itself (a channel's own measured value would select its own noise: the samples in the top
/// band of a measured current are those with positive noise); the model of a channel of
/// `kinds` when the record has no such signal.
fn operating_variable<'a>(
    rec: &ResidualRecord<'a>,
    ch: &ResidualChannel<'a>,
    kinds: &[Channel],
    measured: Option<&'a [f64]>,
) -> Option<&'a [f64]> {
    if kinds.contains(&ch.kind) {
        return Some(ch.model);
    }
    measured.or_else(|| {
        rec.channels
            .iter()
            .find(|c| kinds.contains(&c.kind))
            .map(|c| c.model)
    })
}

fn top_windows(
    prefix: &Prefix,
    n: usize,
    dt: f64,
    c: f64,
    settings: &LocaliseSettings,
    family_alpha: f64,
) -> Vec<WindowExcess> {
    let len = if settings.window_samples > 0 {
        settings.window_samples.min(n)
    } else {
        (n / 50).clamp(16, 1000).min(n)
    };
    let step = (len / 2).max(1);
    let starts: Vec<usize> = (0..=(n - len)).step_by(step).collect();
    let alpha_test = family_alpha / starts.len().max(1) as f64;
    let mut all: Vec<(usize, f64)> = starts
        .iter()
        .map(|&s| {
            let (a, b, _) = prefix.sums(s, s + len);
            (s, (a - b) / len as f64)
        })
        .collect();
    all.sort_by(|x, y| y.1.total_cmp(&x.1));
    let mut chosen: Vec<WindowExcess> = Vec::new();
    for (s, excess) in all {
        if chosen.len() >= settings.top_windows {
            break;
        }
        if chosen.iter().any(|w| s < w.end && w.start < s + len) {
            continue;
        }
        chosen.push(WindowExcess {
            start: s,
            end: s + len,
            t_start_s: s as f64 * dt,
            t_end_s: (s + len) as f64 * dt,
            excess,
            test: excess_test(prefix.sums(s, s + len), len, c, alpha_test),
        });
    }
    chosen
}

/// Sums of `r²`, `v`, `w` over `idx`.
fn sums_over(r: &[f64], floor: &FloorModel, idx: &[usize]) -> (f64, f64, f64) {
    idx.iter().fold((0.0, 0.0, 0.0), |(a, b, w), &i| {
        (a + r[i] * r[i], b + floor.v[i], w + floor.w[i])
    })
}

#[allow(clippy::too_many_arguments)]
fn bands(
    r: &[f64],
    floor: &FloorModel,
    x: &[f64],
    variable: &'static str,
    near_zero_band: bool,
    c: f64,
    settings: &LocaliseSettings,
    family_alpha: f64,
) -> Bands {
    let ax: Vec<f64> = x.iter().map(|v| v.abs()).collect();
    let max = ax.iter().copied().fold(0.0, f64::max);
    let zero_limit = if near_zero_band {
        NEAR_ZERO_FRACTION * max
    } else {
        0.0
    };
    let width = (max - zero_limit) / settings.bands as f64;
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); settings.bands + 1];
    for (i, &v) in ax.iter().enumerate() {
        let slot = if near_zero_band && v <= zero_limit {
            0
        } else if width > 0.0 {
            1 + (((v - zero_limit) / width) as usize).min(settings.bands - 1)
        } else {
            1
        };
        members[slot].push(i);
    }
    let tests = members.iter().filter(|m| !m.is_empty()).count();
    let alpha_test = family_alpha / tests.max(1) as f64;
    let band = |k: usize, idx: &[usize]| Band {
        lo: if k == 0 {
            0.0
        } else {
            zero_limit + (k - 1) as f64 * width
        },
        hi: if k == 0 {
            zero_limit
        } else {
            zero_limit + k as f64 * width
        },
        test: excess_test(sums_over(r, floor, idx), idx.len(), c, alpha_test),
    };
    let near_zero = (near_zero_band && !members[0].is_empty()).then(|| band(0, &members[0]));
    let bands = (1..=settings.bands)
        .filter(|&k| !members[k].is_empty())
        .map(|k| band(k, &members[k]))
        .collect();
    // The trend over the samples in the tests, above the near-zero band (tested apart).
    let used: Vec<usize> = (0..r.len())
        .filter(|&i| floor.keep[i] && !(near_zero_band && ax[i] <= zero_limit))
        .collect();
    let excess: Vec<f64> = used.iter().map(|&i| r[i] * r[i] - floor.v[i]).collect();
    let at: Vec<f64> = used.iter().map(|&i| ax[i]).collect();
    let wt: Vec<f64> = used.iter().map(|&i| floor.w[i]).collect();
    let tested = floor.report.patterns_testable();
    let trend = floor_slope(&excess, &at, &wt, c).map(|(slope, t)| {
        let p_value = (2.0 * normal_sf(t.abs())).min(1.0);
        Trend {
            slope,
            t,
            p_value,
            tested,
            significant: tested && p_value < family_alpha,
        }
    });
    Bands {
        variable,
        near_zero,
        bands,
        trend,
    }
}

/// Least-squares slope of the excess `y` on `x` and its t statistic under the floor model:
/// `Var(slope) = c Σ (xᵢ − x̄)² wᵢ / Sxx²` with `wᵢ` the floor variance of `rᵢ²` and `c` the
/// effective-sample-size factor. The variance is the floor's, not estimated from the residuals:
/// a sandwich estimate is biased low exactly when a few high-leverage samples (a transient
/// among thousands of steady-state ones) happen to lie low, and then overstates |t|.
/// `None` when `x` is constant.
fn floor_slope(y: &[f64], x: &[f64], w: &[f64], c: f64) -> Option<(f64, f64)> {
    if y.len() < 2 {
        return None;
    }
    let n = y.len() as f64;
    let xm = x.iter().sum::<f64>() / n;
    let ym = y.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|v| (v - xm).powi(2)).sum();
    if sxx.is_nan() || sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - xm) * (b - ym)).sum();
    let slope = sxy / sxx;
    let var: f64 = c * x
        .iter()
        .zip(w)
        .map(|(a, w)| (a - xm).powi(2) * w)
        .sum::<f64>()
        / (sxx * sxx);
    (var > 0.0).then(|| (slope, slope / var.sqrt()))
}

#[allow(clippy::too_many_arguments)]
fn welch(
    r: &[f64],
    dt: f64,
    sigma2: f64,
    tested: bool,
    settings: &LocaliseSettings,
    family_alpha: f64,
    planner: &mut FftPlanner<f64>,
) -> Spectrum {
    let n = r.len();
    let len = (settings.welch_segment.min(n / 2).max(8) / 2) * 2;
    let hop = len / 2;
    let window: Vec<f64> = (0..len)
        .map(|j| 0.5 * (1.0 - (std::f64::consts::TAU * j as f64 / len as f64).cos()))
        .collect();
    let w2: f64 = window.iter().map(|w| w * w).sum();
    let rho_w: f64 = window[hop..]
        .iter()
        .zip(&window[..len - hop])
        .map(|(a, b)| a * b)
        .sum::<f64>()
        / w2;
    let fft = planner.plan_fft_forward(len);
    let mut power = vec![0.0; len / 2 + 1];
    let mut segments = 0usize;
    let mut buf = vec![Complex::new(0.0, 0.0); len];
    let mut start = 0;
    while start + len <= n {
        let seg = &r[start..start + len];
        let m = seg.iter().sum::<f64>() / len as f64;
        for ((b, x), w) in buf.iter_mut().zip(seg).zip(&window) {
            *b = Complex::new((x - m) * w, 0.0);
        }
        fft.process(&mut buf);
        for (p, b) in power.iter_mut().zip(&buf) {
            *p += b.norm_sqr();
        }
        segments += 1;
        start += hop;
    }
    let k = segments.max(1) as f64;
    let scale = 2.0 * dt / (w2 * k);
    let psd: Vec<f64> = power.iter().map(|p| p * scale).collect();
    let dof = 2.0 * k / (1.0 + 2.0 * (1.0 - 1.0 / k) * rho_w * rho_w);
    let floor_psd = 2.0 * sigma2 * dt;
    let bins = len / 2 - 1;
    let alpha_test = family_alpha / bins.max(1) as f64;
    let mut peaks: Vec<SpectralPeak> = (1..len / 2)
        .filter(|&i| psd[i] >= psd[i - 1] && psd[i] >= psd[i + 1])
        .map(|i| {
            let ratio = if floor_psd > 0.0 {
                psd[i] / floor_psd
            } else {
                f64::INFINITY
            };
            let p_value = chi_square_sf(dof * ratio, dof);
            SpectralPeak {
                frequency_hz: i as f64 / (len as f64 * dt),
                psd: psd[i],
                ratio,
                p_value,
                significant: tested && p_value < alpha_test,
            }
        })
        .collect();
    peaks.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    peaks.truncate(settings.spectrum_peaks);
    Spectrum {
        segment: len,
        dof,
        floor_psd,
        tested,
        peaks,
    }
}

/// Whether harmonic `N` at angle step `step` \[rad per sample\] is below [`RIPPLE_NYQUIST`].
fn below_nyquist(order: usize, step: f64) -> bool {
    order as f64 * step <= RIPPLE_NYQUIST * std::f64::consts::TAU
}

fn angle_ripple(
    r: &[f64],
    theta: &[f64],
    max_n: u32,
    tested: bool,
    family_alpha: f64,
) -> Option<AngleRipple> {
    let n = r.len();
    let (lo, hi) = theta
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    if hi - lo < std::f64::consts::TAU || n < MIN_RIPPLE_SAMPLES {
        return None;
    }
    // Angle step per sample at each sample (central difference).
    let step: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (theta[b] - theta[a]).abs() / (b - a) as f64
        })
        .collect();
    let m = max_n as usize;
    // Per N: count, Σr, Σr², Σs, Σc, Σss, Σcc, Σsc, Σrs, Σrc and the angle travelled over the
    // samples where N is below the Nyquist limit.
    let mut acc = vec![[0.0f64; 11]; m];
    for ((&ri, &th), &st) in r.iter().zip(theta).zip(&step) {
        let (s1, c1) = th.sin_cos();
        let (mut s, mut c) = (s1, c1);
        for (k, a) in acc.iter_mut().enumerate() {
            if !below_nyquist(k + 1, st) {
                break;
            }
            a[0] += 1.0;
            a[1] += ri;
            a[2] += ri * ri;
            a[3] += s;
            a[4] += c;
            a[5] += s * s;
            a[6] += c * c;
            a[7] += s * c;
            a[8] += ri * s;
            a[9] += ri * c;
            a[10] += st;
            (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
        }
    }
    let normal = |a: &[f64; 11]| Matrix3::new(a[0], a[3], a[4], a[3], a[5], a[7], a[4], a[7], a[6]);
    let mut best: Option<(usize, f64, Vector3<f64>)> = None;
    for (k, a) in acc.iter().enumerate() {
        let nk = a[0];
        if nk < MIN_RIPPLE_SAMPLES as f64 || a[10] < MIN_RIPPLE_REVOLUTIONS * std::f64::consts::TAU
        {
            continue;
        }
        let rhs = Vector3::new(a[1], a[8], a[9]);
        let Some(beta) = normal(a).try_inverse().map(|h| h * rhs) else {
            continue;
        };
        let rss0 = a[2] - a[1] * a[1] / nk;
        let rss1 = (a[2] - beta.dot(&rhs)).max(0.0);
        let f = if rss1 > 0.0 {
            ((rss0 - rss1) / 2.0) / (rss1 / (nk - 3.0))
        } else {
            f64::INFINITY
        };
        if best.as_ref().is_none_or(|b| f > b.1) {
            best = Some((k + 1, f, beta));
        }
    }
    let (order, f, beta) = best?;
    let a = &acc[order - 1];
    let h_inv = normal(a).try_inverse()?;
    let mut nw = NeweyWest::new(3, a[0] as usize);
    for ((&ri, &th), &st) in r.iter().zip(theta).zip(&step) {
        if !below_nyquist(order, st) {
            continue;
        }
        let (s, c) = (order as f64 * th).sin_cos();
        let e = ri - beta[0] - beta[1] * s - beta[2] * c;
        nw.push(&[e, s * e, c * e]);
    }
    let score = nw.finish()?;
    let score = Matrix3::from_iterator(score.iter().copied());
    let cov = h_inv * score * h_inv;
    let cov2 = Matrix2::new(cov[(1, 1)], cov[(1, 2)], cov[(2, 1)], cov[(2, 2)]);
    let b2 = Vector2::new(beta[1], beta[2]);
    let wald = cov2
        .try_inverse()
        .map_or(f64::INFINITY, |ci| b2.dot(&(ci * b2)));
    let p_value = (chi_square_sf(wald, 2.0) * f64::from(max_n)).min(1.0);
    Some(AngleRipple {
        periods_per_rev: order as u32,
        samples: a[0] as usize,
        amplitude: b2.norm(),
        phase_rad: beta[2].atan2(beta[1]),
        f_statistic: f,
        f_p_value: f_sf(f, 2.0, a[0] - 3.0),
        wald,
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    })
}

fn whiteness(rho: &[f64], n: usize, tested: bool, family_alpha: f64) -> Whiteness {
    let nf = n as f64;
    let bound99 = Z_99 / nf.sqrt();
    let q: f64 = rho
        .iter()
        .enumerate()
        .map(|(k, p)| p * p / (nf - (k + 1) as f64))
        .sum::<f64>()
        * nf
        * (nf + 2.0);
    let p_value = chi_square_sf(q, rho.len() as f64);
    Whiteness {
        autocorrelation: rho.to_vec(),
        bound99,
        outside: (1..=rho.len())
            .filter(|&k| rho[k - 1].abs() > bound99)
            .collect(),
        ljung_box_q: q,
        dof: rho.len(),
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    }
}

fn cross_correlation(
    r: &[f64],
    rho_r: &[f64],
    u: &[f64],
    max_lag: usize,
    tested: bool,
    family_alpha: f64,
) -> Option<CrossCorrelation> {
    // The input prewhitened by its first difference, aligned with the residual.
    let du: Vec<f64> = u.windows(2).map(|w| w[1] - w[0]).collect();
    let r = &r[1..];
    let u = &du[..];
    let n = r.len();
    let nf = n as f64;
    let mean = |x: &[f64]| x.iter().sum::<f64>() / nf;
    let (mr, mu) = (mean(r), mean(u));
    let e: Vec<f64> = r.iter().map(|v| v - mr).collect();
    let d: Vec<f64> = u.iter().map(|v| v - mu).collect();
    let se = e.iter().map(|v| v * v).sum::<f64>().sqrt();
    let su = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(se > 0.0 && su > 0.0) {
        return None;
    }
    let max_lag = max_lag.min(n - 1);
    let rho_u = autocorrelation(u, max_lag);
    let factor = (1.0 + 2.0 * rho_r.iter().zip(&rho_u).map(|(a, b)| a * b).sum::<f64>()).max(1.0);
    let sd = (factor / nf).sqrt();
    let lags: Vec<i64> = (-(max_lag as i64)..=max_lag as i64).collect();
    let values: Vec<f64> = lags
        .iter()
        .map(|&lag| {
            let k = lag.unsigned_abs() as usize;
            let s: f64 = if lag >= 0 {
                e[k..].iter().zip(&d[..n - k]).map(|(a, b)| a * b).sum()
            } else {
                d[k..].iter().zip(&e[..n - k]).map(|(a, b)| a * b).sum()
            };
            s / (se * su)
        })
        .collect();
    let max_ratio = values.iter().fold(0.0f64, |m, v| m.max(v.abs())) / sd;
    let p_value = (2.0 * normal_sf(max_ratio) * lags.len() as f64).min(1.0);
    let bound99 = Z_99 * sd;
    Some(CrossCorrelation {
        outside: lags
            .iter()
            .zip(&values)
            .filter(|(_, v)| v.abs() > bound99)
            .map(|(l, _)| *l)
            .collect(),
        lags,
        values,
        bound99,
        max_ratio,
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    })
}

/// Centred moving average of half-width `h`.
fn smooth(x: &[f64], h: usize) -> Vec<f64> {
    let n = x.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    let mut acc = 0.0;
    for v in x {
        acc += v;
        prefix.push(acc);
    }
    (0..n)
        .map(|i| {
            let lo = i.saturating_sub(h);
            let hi = (i + h + 1).min(n);
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

fn mean_of(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

/// Intervals collected in order, merging neighbours of one kind and dropping empty ones.
struct PhaseList {
    dt: f64,
    phases: Vec<Phase>,
}

impl PhaseList {
    fn push(&mut self, kind: PhaseKind, start: usize, end: usize) {
        if end <= start {
            return;
        }
        if let Some(last) = self.phases.last_mut() {
            if last.kind == kind && last.end == start {
                last.end = end;
                last.t_end_s = end as f64 * self.dt;
                return;
            }
        }
        self.phases.push(Phase {
            kind,
            start,
            end,
            t_start_s: start as f64 * self.dt,
            t_end_s: end as f64 * self.dt,
        });
    }

    /// Runs of `a..e` labelled by `label`.
    fn runs(&mut self, a: usize, e: usize, label: impl Fn(usize) -> PhaseKind) {
        let mut s = a;
        while s < e {
            let kind = label(s);
            let mut t = s + 1;
            while t < e && label(t) == kind {
                t += 1;
            }
            self.push(kind, s, t);
            s = t;
        }
    }
}

/// The phases of a record, from its voltage levels and its measured speed and current
/// (moving averages over five samples).
fn detect_phases(rec: &ResidualRecord, n: usize) -> Vec<Phase> {
    let dt = rec.dt;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let starts: Option<Vec<usize>> = match voltage_input(&t, rec.voltage) {
        Ok(Input::Piecewise { times_s, .. }) => Some(
            times_s
                .iter()
                .map(|ts| ((ts / dt).round() as usize).min(n))
                .collect(),
        ),
        _ => None,
    };
    let h = PHASE_SMOOTHING;
    let w = rec.speed.map(|s| smooth(s, h));
    let cur = rec.current.map(|c| smooth(c, h));
    let v_max = rec.voltage.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let w_max = w
        .as_deref()
        .map_or(0.0, |w| w.iter().fold(0.0f64, |m, v| m.max(v.abs())));
    let w_thr = STOPPED_FRACTION * w_max;
    let stopped = |i: usize| w.as_deref().is_some_and(|w| w[i].abs() <= w_thr);
    let mut list = PhaseList {
        dt,
        phases: Vec::new(),
    };
    let Some(starts) = starts else {
        // No levels: label by motion only.
        list.runs(0, n, |i| {
            let on = rec.voltage[i].abs() > VOLTAGE_OFF_FRACTION * v_max;
            match (w.is_some(), stopped(i), on) {
                (true, true, true) => PhaseKind::Sticking,
                (true, true, false) => PhaseKind::Rest,
                _ => PhaseKind::Moving,
            }
        });
        return list.phases;
    };
    // Noise of the smoothed signals, for the settled tolerance.
    let noise =
        |x: Option<&[f64]>| x.map_or(0.0, |x| 3.0 * noise_std(x) / ((2 * h + 1) as f64).sqrt());
    let (w_noise, i_noise) = (noise(rec.speed), noise(rec.current));
    for (j, &a) in starts.iter().enumerate() {
        let e = starts.get(j + 1).copied().unwrap_or(n).min(n);
        if e <= a {
            continue;
        }
        let level = mean_of(&rec.voltage[a..e]);
        if level.abs() <= VOLTAGE_OFF_FRACTION * v_max {
            list.runs(a, e, |i| {
                if w.is_none() || stopped(i) {
                    PhaseKind::Rest
                } else {
                    PhaseKind::Settling
                }
            });
            continue;
        }
        let tail = |x: &[f64], from: usize| mean_of(&x[from + (e - from) * 9 / 10..e]);
        let mut i = a;
        if let Some(w) = w.as_deref() {
            if stopped(a) {
                let b = (a..e).find(|&k| !stopped(k)).unwrap_or(e);
                list.push(PhaseKind::BeforeBreakaway, a, b);
                i = b;
            } else {
                let w_ss = tail(w, a);
                if w[a] * w_ss < 0.0 && w_ss.abs() > w_thr {
                    let z = (a..e)
                        .find(|&k| w[k] * w_ss > 0.0 && w[k].abs() >= 0.2 * w_ss.abs())
                        .unwrap_or(e);
                    list.runs(a, z, |k| {
                        if stopped(k) {
                            PhaseKind::Sticking
                        } else {
                            PhaseKind::Reversal
                        }
                    });
                    i = z;
                }
            }
        }
        if i >= e {
            continue;
        }
        let w_ss = w.as_deref().map(|w| tail(w, i));
        let i_ss = cur.as_deref().map(|c| tail(c, i));
        let settled = |k: usize| {
            let ok_w = match (w.as_deref(), w_ss) {
                (Some(w), Some(ss)) => (w[k] - ss).abs() <= SETTLED_FRACTION * ss.abs() + w_noise,
                _ => true,
            };
            let ok_i = match (cur.as_deref(), i_ss) {
                (Some(c), Some(ss)) => (c[k] - ss).abs() <= SETTLED_FRACTION * ss.abs() + i_noise,
                _ => true,
            };
            ok_w && ok_i
        };
        // The earliest start of a suffix with at most 1 % of its samples unsettled (a noise
        // spike alone does not end a steady state).
        let (mut s, mut unsettled) = (e, 0usize);
        for k in (i..e).rev() {
            if !settled(k) {
                unsettled += 1;
            }
            if unsettled as f64 <= UNSETTLED_FRACTION * (e - k) as f64 {
                s = k;
            }
        }
        let sgn = level.signum();
        let peak = cur.as_deref().zip(i_ss).and_then(|(c, ss)| {
            let (p, top) = (i..e)
                .map(|k| (k, sgn * c[k]))
                .fold((i, f64::NEG_INFINITY), |b, x| if x.1 > b.1 { x } else { b });
            let base = sgn * ss;
            let notable = top - base > PEAK_FRACTION * base.abs() + i_noise;
            (notable && p < e - (e - i) / 10).then(|| {
                let half = base + PEAK_LEVEL * (top - base);
                let mut lo = p;
                while lo > i && sgn * c[lo - 1] >= half {
                    lo -= 1;
                }
                let mut hi = p + 1;
                while hi < e && sgn * c[hi] >= half {
                    hi += 1;
                }
                (lo, hi)
            })
        });
        let rise_end = match peak {
            Some((lo, _)) => lo,
            None => match (w.as_deref(), w_ss, cur.as_deref(), i_ss) {
                (Some(w), Some(ss), _, _) => {
                    (i..e).find(|&k| w[k].abs() >= 0.9 * ss.abs()).unwrap_or(e)
                }
                (_, _, Some(c), Some(ss)) => {
                    (i..e).find(|&k| sgn * c[k] >= 0.9 * sgn * ss).unwrap_or(e)
                }
                _ => i,
            },
        };
        list.push(PhaseKind::Rise, i, rise_end);
        let after = match peak {
            Some((lo, hi)) => {
                list.push(PhaseKind::Peak, lo, hi);
                hi
            }
            None => rise_end,
        };
        let steady_from = s.max(after);
        list.push(PhaseKind::Settling, after, steady_from);
        list.push(PhaseKind::Steady, steady_from, e);
    }
    list.phases
}
