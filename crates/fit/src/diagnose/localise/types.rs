//! What a localisation is given (the residual records and channels, [`LocaliseSettings`]) and
//! what it answers: floors, excess tests, phases, windows, bands, spectra, angle ripples and
//! the whiteness and cross-correlation of each channel.

use serde::{Serialize, Serializer};

use crate::estimation::records::Channel;

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

/// Settings of [`localise`](super::localise).
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
    /// Given by the caller ([`localise_with_floors`](super::localise_with_floors)): e.g. the noise an inverse model's
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

pub(crate) fn channel_key<S: Serializer>(c: &Channel, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(match c {
        Channel::Current => "current",
        Channel::Speed => "speed",
        Channel::EncoderSpeed => "encoder_speed",
    })
}
