//! Output-error identification of R, L, k, f, J and Ts from records of any voltage waveform.
//!
//! The model is the stick-slip simulator of Appendix D (`motor_model::Simulator`, nominal model:
//! Eq. (2) with Coulomb friction, stuck while `|k I| ≤ Ts`) driven by each record's own voltage
//! ([`voltage_input`]): staircases, PRBS, sines, reversals, several steps in one record. The
//! residuals are `(simulated − measured)/σ_channel` over the channels given (current, and the
//! tachometer speed or the encoder angle through its central difference, as in
//! [`crate::identify_full`]); samples flagged as clipped are left out. Parameters are fitted as
//! `θ = ln p`; the Jacobian is by forward differences in θ (step 1e-6) on a simulation whose
//! RK4 step is fixed for the whole fit, so that the simulated output is a smooth function of θ.
//!
//! Each record's simulation starts at its first sample from the state the record shows
//! ([`crate::InitialState`], [`crate::detect_initial_state`]): at rest (pre-trigger samples, or
//! the first change of voltage at the first sample), in the steady state of its first level
//! (Eqs. (4), (5) of the fitted motor: no parameter of its own), or free (a slice of a longer
//! run: its initial current and speed are fitted with the motor, appended to θ as they are,
//! and the motor's intervals are the marginal ones).

use std::sync::atomic::{AtomicU64, Ordering};

use motor_model::{central_difference, steady_state, Effects, Input, MotorParams, Simulator};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::error::{FitError, START_SERIES};
use crate::full_model::{
    noise_floor, noise_of_second_differences, noise_std, quality_from_sums,
    squared_second_difference, Channel, ChannelQuality, FittedChannel, FullFit, WeightedProblem,
};
use crate::initial_state::{FittedInitialState, InitialState};
use crate::input_uncertainty::{
    bias_group_sizes, detect_quantum, estimate_level, fit_with_inputs, grid_phase_score_covariance,
    noise_free_quantum, pooled_level_variance, settled_current, LevelEstimate, LevelPrior,
    Nuisance, NuisanceProblem, VoltageScale,
};
use crate::lm::{half_squared_norm, LeastSquares, LmSettings, NormalEquations};
use crate::mechanical::{
    identify_inverse_model_pooled, motor_torque, AxisRecord, InverseModelSettings,
};
use crate::parameters::Parameters;
use crate::plausibility::RecordFacts;
use crate::signal::Butterworth;
use crate::stats::{
    equal_runs, newey_west_lags, newey_west_run_covariance, scaled_inverse, SeriesLayout,
};
use crate::step_location::uniform_period;

/// Step of the forward-difference Jacobian in `θ = ln p` (relative step of each parameter).
const FD_STEP: f64 = 1e-6;
/// Step of the central-difference Jacobian behind the intervals
/// ([`OeProblem::jacobian_for_intervals`]), and relative step of the central difference in a
/// level. The simulation is smooth in θ only down to its rounding and the bisection of its
/// switching instants, about 1e-12 of the response; divided by a step of 1e-6 that noise was
/// 2e-6 of a column, information enough on records weighted at the noise floor (an exact
/// angle) to pin the voltage scale the levels' priors alone determine (R ±0.01 %, truth 0.06 %
/// off). At 1e-4 the noise is a hundredth of that and the truncation error of the central
/// difference, `h²/6` of the third derivative, 2e-9.
const INTERVAL_FD_STEP: f64 = 1e-4;
/// Fraction of the start's own RK4 step used for the whole fit (room for faster parameters).
const STEP_MARGIN: f64 = 0.5;
/// Most RK4 steps per record sample a simulation may take on average over the records (a time
/// constant 2.5 times below the sample period: 1/40 of it per step, with [`STEP_MARGIN`]);
/// faster time constants are outside what the records show.
// A record sampled fifty times slower than τe took minutes a fit at 1000 steps a sample, for
// an L that its current, settled at every sample, cannot show.
const MAX_STEPS_PER_SAMPLE: f64 = 200.0;
/// Speed bound of the simulations over the largest measured |speed| (room for the fitted
/// motor to run faster than the records while the step stays fixed).
const SPEED_BOUND_MARGIN: f64 = 1.5;
/// Share of the records' noise floor the integration error an effect causes at speed (the
/// cogging ripple) may reach ([`Simulator::with_speed_bound_and_tolerance`]).
const SPEED_ERROR_SHARE: f64 = 0.01;
/// Mean run of equal readings, in rows, beyond which [`OeProblem`]'s series layout takes no
/// longer lag windows for the fitted residuals' correction.
const MAX_LAG_RUN_LENGTH: f64 = 8.0;
/// A voltage is piecewise constant when it has at most one jump per this many samples.
const MIN_SAMPLES_PER_LEVEL: usize = 20;

/// One record of any excitation, on a uniform grid starting at the record's first sample.
#[derive(Debug, Clone, Copy)]
pub struct ExcitedRecord<'a> {
    /// The armature voltage applied, with time measured from the record's first sample
    /// ([`voltage_input`] builds it from a measured voltage column).
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

fn bad(series: impl Into<String>, reason: String) -> FitError {
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
/// variance `dt²/12`). Pass both to [`identify_output_error_with_inputs`].
pub fn voltage_levels(
    t: &[f64],
    voltage: &[f64],
    quantum_v: Option<f64>,
) -> Result<(Input, Vec<LevelPrior>), FitError> {
    rebuild_voltage(t, voltage, quantum_v, true)
}

/// The waveform of a voltage column and its level priors; with `expected_starts` each change
/// starts half a period before its first sample, otherwise at it.
fn rebuild_voltage(
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
const RETRY_MIN_CODES: f64 = 4.0;
/// Largest share of the range the smallest change of a voltage may be for [`RETRY_MIN_CODES`]
/// to apply (a change larger than this is a jump, not a code).
const RETRY_CODE_SHARE: f64 = 0.05;

/// [`noise_std`] of `voltage` from the second differences of the windows of three samples
/// whose two changes are both at most `above` in size.
fn noise_without_changes(voltage: &[f64], above: f64) -> f64 {
    let d2: Vec<f64> = voltage
        .windows(3)
        .filter(|w| (w[1] - w[0]).abs() <= above && (w[2] - w[1]).abs() <= above)
        .map(squared_second_difference)
        .collect();
    noise_of_second_differences(d2, voltage)
}

/// Passes of [`rebuild_voltage`]'s jump search on the noise between the jumps found.
const JUMP_PASSES: usize = 3;

/// The first sample and the sample of every change of `voltage` larger than `threshold`.
fn jumps(voltage: &[f64], threshold: f64) -> Vec<usize> {
    std::iter::once(0)
        .chain((1..voltage.len()).filter(|&i| (voltage[i] - voltage[i - 1]).abs() > threshold))
        .collect()
}

/// [`noise_std`] of `voltage` over its stretches between the changes at `starts` (each from
/// its start to the next): the second differences that straddle a change left out.
fn noise_between(voltage: &[f64], starts: &[usize]) -> f64 {
    let ends = starts.iter().skip(1).copied().chain([voltage.len()]);
    let d2: Vec<f64> = starts
        .iter()
        .zip(ends)
        .flat_map(|(&s, e)| voltage[s..e].windows(3).map(squared_second_difference))
        .collect();
    noise_of_second_differences(d2, voltage)
}

/// A channel of one record: its data at the kept samples and its weight.
struct OeChannel {
    kind: Channel,
    /// Indices of the samples fitted.
    keep: Vec<usize>,
    /// Measured values at `keep`.
    data: Vec<f64>,
    sigma: f64,
    /// The smallest `sigma` may become ([`crate::full_model::noise_floor`] of `data`).
    floor: f64,
    /// One ADC step \[unit\] of a channel read without noise
    /// ([`crate::input_uncertainty::noise_free_quantum`]); `None` for a noisy or unquantised
    /// channel and for an encoder's speed (its errors are the encoder's, not an ADC's).
    noise_free_quantum: Option<f64>,
    /// Runs `[from, to)` of `data` (a quantised current's) over which the current has settled
    /// at one level, each with the index of its offset in [`OeProblem::current_offsets`].
    settled: Vec<(usize, usize, usize)>,
}

/// The common quantisation offset of a settled current: its value \[A\] (a nuisance input,
/// 0 a priori) and prior variance \[A²\].
#[derive(Debug, Clone, Copy)]
struct CurrentOffset {
    value: f64,
    variance: f64,
    /// ADC step \[A\] and the code the settled readings' mean rounds to: runs that read alike
    /// share one offset.
    key: (u64, i64),
}

struct OeRecord {
    input: Input,
    /// Per level of a piecewise input: its value and start as estimated, and their uncertainty.
    priors: Vec<(f64, f64, LevelPrior)>,
    dt: f64,
    n: usize,
    channels: Vec<OeChannel>,
    /// How its simulation starts.
    initial: InitialState,
    /// Index in θ of its free initial current (the speed follows), for [`InitialState::Free`].
    free_at: Option<usize>,
}

struct OeProblem {
    /// How θ maps to the motor and the effects simulated with it.
    parameters: Parameters,
    records: Vec<OeRecord>,
    n_residuals: usize,
    /// RK4 step \[s\] of every simulation (bits of an `f64`): fixed within an iteration of the
    /// solver — set at each Jacobian from the parameters there, so that the base simulation,
    /// its perturbations and the trial steps that follow share one discretisation — and
    /// following the parameters from one iteration to the next (a start with a tiny L would
    /// otherwise keep a tiny step, and a slow fit, to the end).
    max_step_bits: AtomicU64,
    /// Largest |speed| \[rad/s\] the simulations take their state-dependent steps (cogging)
    /// at: [`SPEED_BOUND_MARGIN`] times the largest measured, so that the step count does not
    /// follow the simulated speed ([`Simulator::with_speed_bound`]); `None` without a speed
    /// channel.
    speed_bound: Option<f64>,
    /// The smallest noise floor \[A\] and \[rad/s\] of the records' current and speed
    /// channels, from their own scatter ([`noise_std`]): the integration error at speed is
    /// held to [`SPEED_ERROR_SHARE`] of it.
    noise_floor: (f64, f64),
    /// RK4 steps this many times the simulator's default ([`Simulator::with_step_factor`]; 1
    /// for every fit but the diagnosis's).
    step_factor: f64,
    /// Whether the channels' noise levels were given ([`OeProblem::set_sigmas`]) and are
    /// kept: the fit is then one stage in those weights, not reweighted by its own residuals
    /// ([`crate::full_model::WeightedProblem::reweights`]).
    fixed_sigmas: bool,
    /// Offsets of the settled runs of quantised currents ([`settle_currents`]).
    current_offsets: Vec<CurrentOffset>,
}

impl OeProblem {
    /// The problem of `records` (checked) for the motor and `effects`, simulated with RK4
    /// steps of at most `max_step_s`.
    fn new(
        records: &[ExcitedRecord<'_>],
        effects: &Effects,
        max_step_s: f64,
    ) -> Result<Self, FitError> {
        let max_step_bits = AtomicU64::new(max_step_s.to_bits());
        let mut records = records
            .iter()
            .enumerate()
            .map(|(k, r)| prepare(k, r))
            .collect::<Result<Vec<_>, _>>()?;
        let current_offsets = settle_currents(&mut records);
        let n_residuals = records
            .iter()
            .flat_map(|r| &r.channels)
            .map(|c| c.data.len())
            .sum();
        let peak_speed = records
            .iter()
            .flat_map(|r| &r.channels)
            .filter(|c| c.kind != Channel::Current)
            .flat_map(|c| c.data.iter())
            .fold(0.0f64, |m, w| m.max(w.abs()));
        let speed_bound =
            (peak_speed > 0.0 && peak_speed.is_finite()).then_some(SPEED_BOUND_MARGIN * peak_speed);
        let floor = |current: bool| {
            records
                .iter()
                .flat_map(|r| &r.channels)
                .filter(|c| (c.kind == Channel::Current) == current)
                .map(|c| c.sigma)
                .fold(f64::INFINITY, f64::min)
        };
        Ok(OeProblem {
            parameters: Parameters::new(effects),
            noise_floor: (floor(true), floor(false)),
            records,
            n_residuals,
            max_step_bits,
            speed_bound,
            step_factor: 1.0,
            fixed_sigmas: false,
            current_offsets,
        })
    }

    /// Weights each channel by the noise level `sigmas` gives it (`(record, channel, σ)`;
    /// channels it does not list, or lists with a σ that is not positive and finite, keep their
    /// own scatter) and keeps those weights through the fit.
    fn set_sigmas(&mut self, sigmas: &[(usize, Channel, f64)]) {
        for (k, rec) in self.records.iter_mut().enumerate() {
            for ch in &mut rec.channels {
                if let Some(s) = sigmas
                    .iter()
                    .find(|(r, c, s)| *r == k && *c == ch.kind && *s > 0.0 && s.is_finite())
                {
                    ch.sigma = s.2;
                }
            }
        }
        self.fixed_sigmas = true;
    }

    /// Starts record `k`'s simulation from `initial[k]` (all at rest when `initial` is empty),
    /// appending the free initial states to θ. A steady start is the nominal model's
    /// (Eqs. (4), (5)): refused with `effects` on.
    fn set_initial_states(
        &mut self,
        initial: &[InitialState],
        effects: &Effects,
    ) -> Result<(), FitError> {
        if initial.is_empty() {
            return Ok(());
        }
        if initial.len() != self.records.len() {
            return Err(bad(
                "initial states",
                format!(
                    "{} for {} records: give one per record, or none",
                    initial.len(),
                    self.records.len()
                ),
            ));
        }
        let mut next = self.parameters.named();
        for (k, (rec, &state)) in self.records.iter_mut().zip(initial).enumerate() {
            if state == InitialState::Steady && !effects.is_nominal() {
                return Err(bad(
                    format!("record {}", k + 1),
                    "a steady initial state is the nominal motor's (Eqs. (4), (5)); with effects on, \
                     start it free"
                        .into(),
                ));
            }
            rec.initial = state;
            if state == InitialState::Free {
                rec.free_at = Some(next);
                next += 2;
            }
        }
        let free = next - self.parameters.named();
        self.parameters = self.parameters.clone().with_free_states(free);
        Ok(())
    }

    /// θ of the named parameters `named` with the free initial states appended, each at the
    /// record's first measured current and speed.
    fn with_state_guesses(&self, mut named: Vec<f64>) -> Vec<f64> {
        for rec in self.records.iter().filter(|r| r.free_at.is_some()) {
            let first = |current: bool| {
                rec.channels
                    .iter()
                    .filter(|c| (c.kind == Channel::Current) == current)
                    .find_map(|c| c.data.first().copied())
                    .unwrap_or(0.0)
            };
            named.push(first(true));
            named.push(first(false));
        }
        named
    }

    /// The current \[A\] and speed \[rad/s\] record `rec` starts at for `motor` and θ.
    fn start_of(rec: &OeRecord, motor: &MotorParams, theta: &[f64]) -> Option<(f64, f64)> {
        match rec.initial {
            InitialState::Steady => {
                let s = steady_state(motor, rec.input.volts_at(0.0));
                Some((s.current_a, s.speed_rad_s))
            }
            InitialState::Free => {
                let k = rec.free_at?;
                Some((*theta.get(k)?, *theta.get(k + 1)?))
            }
            _ => Some((0.0, 0.0)),
        }
    }

    /// Each record's initial state at the solution θ.
    fn fitted_initial_states(&self, theta: &[f64]) -> Vec<FittedInitialState> {
        let Some((motor, _)) = self.parameters.decode(theta) else {
            return Vec::new();
        };
        self.records
            .iter()
            .map(|rec| {
                let (current_a, speed_rad_s) =
                    Self::start_of(rec, &motor, theta).unwrap_or((f64::NAN, f64::NAN));
                FittedInitialState {
                    state: rec.initial,
                    current_a,
                    speed_rad_s,
                }
            })
            .collect()
    }

    /// The RK4 step \[s\] in use.
    fn max_step_s(&self) -> f64 {
        f64::from_bits(self.max_step_bits.load(Ordering::Relaxed))
    }

    /// A simulator of `motor` and `effects` driven by `input`, with the speed bound.
    fn simulator(
        &self,
        motor: MotorParams,
        effects: Effects,
        input: Input,
    ) -> Result<Simulator, motor_model::ModelError> {
        let mut sim = Simulator::new(motor, effects, input)?;
        if self.step_factor != 1.0 {
            sim = sim.with_step_factor(self.step_factor)?;
        }
        match (self.speed_bound, self.speed_tolerance(&motor)) {
            (Some(w), Some(tol)) => sim.with_speed_bound_and_tolerance(w, tol),
            (Some(w), None) => sim.with_speed_bound(w),
            (None, _) => Ok(sim),
        }
    }

    /// The speed error \[rad/s\] the integration at speed may cause on `motor`:
    /// [`SPEED_ERROR_SHARE`] of the speed channels' noise floor, and of the current's through
    /// the back-EMF (a speed error `e` moves the current by at most `k e/R`); `None` without
    /// a positive floor.
    fn speed_tolerance(&self, motor: &MotorParams) -> Option<f64> {
        let (current_a, speed_rad_s) = self.noise_floor;
        let via_current = current_a * motor.r_ohm / motor.k_nm_per_a;
        let tol = SPEED_ERROR_SHARE * speed_rad_s.min(via_current);
        (tol > 0.0 && tol.is_finite()).then_some(tol)
    }

    /// The RK4 step \[s\] for `motor` and `effects`: the simulator's own (1/40 of the fastest
    /// time constant, and the cogging step at the speed bound that keeps the ripple's error
    /// within [`OeProblem::speed_tolerance`]) with a margin.
    fn step_for(&self, motor: &MotorParams, effects: &Effects) -> Option<f64> {
        let step = Input::Step {
            volts: 1.0,
            at_s: 0.0,
        };
        self.simulator(*motor, *effects, step)
            .ok()
            .map(|s| s.max_step_s() * STEP_MARGIN)
    }

    /// Uses the step that suits `motor` and `effects` from now on; `None` (and no change)
    /// where that step would cost more than [`MAX_STEPS_PER_SAMPLE`] RK4 steps per sample
    /// ([`OeProblem::within_work_bound`]): a time constant that far below the sample period is outside what
    /// the records show, and simulating it would take without bound.
    fn set_step_for(&self, motor: &MotorParams, effects: &Effects) -> Option<()> {
        let h = self.within_work_bound(motor, effects)?;
        self.max_step_bits.store(h.to_bits(), Ordering::Relaxed);
        Some(())
    }

    /// The RK4 step for `motor` and `effects`, `None` where simulating every record would take
    /// more than [`MAX_STEPS_PER_SAMPLE`] steps per sample of the records together (each
    /// sample at least one step). Records at one rate: the step is at least 1/200 of their
    /// period. Records at rates far apart (one whose times are in another unit than its header
    /// says): the slow records' steps count too — bounded by the fastest record's period alone,
    /// a record sampled a thousand times slower took 1000 × 200 steps a sample, and `diagnose`
    /// ran for hours.
    fn within_work_bound(&self, motor: &MotorParams, effects: &Effects) -> Option<f64> {
        let h = self.step_for(motor, effects)?;
        let (steps, samples) = self.records.iter().fold((0.0, 0.0), |(steps, samples), r| {
            let n = r.n as f64;
            (steps + n * (r.dt / h).ceil().max(1.0), samples + n)
        });
        (steps <= MAX_STEPS_PER_SAMPLE * samples).then_some(h)
    }

    /// The simulated channels of every record at `theta`: `[record][channel][kept sample]`.
    fn simulate(&self, theta: &[f64]) -> Option<Vec<Vec<Vec<f64>>>> {
        let (motor, effects) = self.parameters.decode(theta)?;
        // Every evaluation within the work bound, trial steps included: the simulator's own
        // step follows the parameters' fastest time constant whatever the fixed step says.
        self.within_work_bound(&motor, &effects)?;
        let mut out = Vec::with_capacity(self.records.len());
        for rec in &self.records {
            let (i0, w0) = Self::start_of(rec, &motor, theta)?;
            let sim = self
                .simulator(motor, effects, rec.input.clone())
                .and_then(|s| s.with_max_step(self.max_step_s()))
                .and_then(|s| s.with_initial_state(i0, w0))
                .ok()?;
            let rate = 1.0 / rec.dt;
            // n samples: t = 0 … (n − 1) dt, half a period of slack against rounding.
            let trace = sim.run((rec.n as f64 - 0.5) / rate, rate).ok()?;
            if trace.t.len() != rec.n {
                return None;
            }
            let mut encoder: Option<Vec<f64>> = None;
            let channels = rec
                .channels
                .iter()
                .map(|ch| {
                    let full: &[f64] = match ch.kind {
                        Channel::Current => &trace.current,
                        Channel::Speed => &trace.speed,
                        Channel::EncoderSpeed => encoder
                            .get_or_insert_with(|| central_difference(&trace.t, &trace.position)),
                    };
                    let mut model: Vec<f64> = ch.keep.iter().map(|&i| full[i]).collect();
                    for &(from, to, g) in &ch.settled {
                        let offset = self.current_offsets[g].value;
                        model[from..to].iter_mut().for_each(|m| *m += offset);
                    }
                    model
                })
                .collect();
            out.push(channels);
        }
        out.iter()
            .flatten()
            .flatten()
            .all(|v: &f64| v.is_finite())
            .then_some(out)
    }

    /// Weighted residuals at `theta`, in record/channel/sample order.
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let sim = self.simulate(theta)?;
        let mut r = Vec::with_capacity(self.n_residuals);
        for (rec, simulated) in self.records.iter().zip(&sim) {
            for (ch, model) in rec.channels.iter().zip(simulated) {
                r.extend(ch.data.iter().zip(model).map(|(y, m)| (m - y) / ch.sigma));
            }
        }
        Some(r)
    }

    /// Residuals and their Jacobian in θ (forward differences, the perturbed simulations run
    /// in parallel).
    fn jacobian(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let (motor, effects) = self.parameters.decode(theta)?;
        self.set_step_for(&motor, &effects)?;
        let all: Vec<usize> = (0..self.parameters.len()).collect();
        self.jacobian_columns(theta, &all, false)
    }

    /// [`OeProblem::jacobian`] by central differences, for the intervals. A forward difference
    /// errs by `h/2` of each column's curvature; on records whose weights reach the noise floor
    /// (an exact angle) that error is information: it broke the exact degeneracy of scaling the
    /// voltage and all six parameters together, which only the levels' priors may resolve, and
    /// a noise-free pair read half a step high claimed R to ±0.002 % while 0.06 % off.
    fn jacobian_for_intervals(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let (motor, effects) = self.parameters.decode(theta)?;
        self.set_step_for(&motor, &effects)?;
        let all: Vec<usize> = (0..self.parameters.len()).collect();
        self.jacobian_columns(theta, &all, true)
    }

    /// Residuals at `theta` and the columns `which` of their Jacobian in θ (forward
    /// differences, or central ones with `central`; the perturbed simulations run in parallel
    /// on rayon's pool, so that a fit already running on that pool shares its threads), on the
    /// RK4 step in use.
    fn jacobian_columns(
        &self,
        theta: &[f64],
        which: &[usize],
        central: bool,
    ) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let r0 = self.residuals(theta)?;
        let p = which.len();
        let at = |j: usize, step: f64| {
            let mut th = theta.to_vec();
            th[j] += step;
            self.residuals(&th)
        };
        let columns: Vec<Option<Vec<f64>>> = which
            .par_iter()
            .map(|&j| {
                Some(if central {
                    let plus = at(j, INTERVAL_FD_STEP)?;
                    let minus = at(j, -INTERVAL_FD_STEP)?;
                    plus.iter()
                        .zip(&minus)
                        .map(|(a, b)| (a - b) / (2.0 * INTERVAL_FD_STEP))
                        .collect()
                } else {
                    let plus = at(j, FD_STEP)?;
                    plus.iter()
                        .zip(&r0)
                        .map(|(a, b)| (a - b) / FD_STEP)
                        .collect()
                })
            })
            .collect();
        let mut jac = DMatrix::zeros(r0.len(), p);
        for (j, col) in columns.into_iter().enumerate() {
            let col = col?;
            jac.column_mut(j).copy_from_slice(&col);
        }
        Some((r0, jac))
    }
}

impl LeastSquares for OeProblem {
    fn n_params(&self) -> usize {
        self.parameters.len()
    }

    fn cost(&self, theta: &[f64]) -> Option<f64> {
        Some(half_squared_norm(&self.residuals(theta)?))
    }

    fn normal_equations(&self, theta: &[f64]) -> Option<NormalEquations> {
        let (r, jac) = self.jacobian(theta)?;
        Some(NormalEquations::from_jacobian(r, &jac))
    }
}

impl WeightedProblem for OeProblem {
    fn parameters(&self) -> &Parameters {
        &self.parameters
    }

    fn reweights(&self) -> bool {
        !self.fixed_sigmas
    }

    fn facts(&self) -> RecordFacts {
        let mut facts = RecordFacts::default();
        for r in &self.records {
            facts.add(
                r.dt,
                r.n,
                r.channels.iter().map(|c| (c.kind, c.data.as_slice())),
            );
        }
        facts
    }

    fn sigmas_mut(&mut self) -> Vec<(&mut f64, f64)> {
        self.records
            .iter_mut()
            .flat_map(|r| r.channels.iter_mut().map(|c| (&mut c.sigma, c.floor)))
            .collect()
    }

    fn channel_quality(&self, theta: &[f64]) -> Vec<ChannelQuality> {
        let sim = self.simulate(theta);
        let mut out = Vec::new();
        for (k, rec) in self.records.iter().enumerate() {
            for (c, ch) in rec.channels.iter().enumerate() {
                let n = ch.data.len();
                let mean = ch.data.iter().sum::<f64>() / n.max(1) as f64;
                let sst = ch.data.iter().map(|y| (y - mean).powi(2)).sum::<f64>();
                let sse = sim.as_ref().map_or(f64::NAN, |s| {
                    s[k][c]
                        .iter()
                        .zip(&ch.data)
                        .map(|(m, y)| (m - y).powi(2))
                        .sum()
                });
                out.push(quality_from_sums(k, ch.kind, ch.sigma, sse, sst, n));
            }
        }
        out
    }

    fn score_covariance(&self, theta: &[f64]) -> Option<DMatrix<f64>> {
        let (r, jac) = self.jacobian_for_intervals(theta)?;
        self.fitted_score_covariance(&r, &jac, &scaled_inverse(&jac.tr_mul(&jac))?)
    }

    /// One series per channel of each record, in order; a channel read without noise is left
    /// out (its covariance is its quantiser's). The lag is the run covariance's, in runs of
    /// equal readings, taken as rows at the channel's mean run length (at most
    /// [`MAX_LAG_RUN_LENGTH`] rows a run, so that a channel that barely changes costs no more
    /// than a few passes).
    fn series_layout(&self) -> SeriesLayout {
        let mut layout = SeriesLayout::default();
        for (s, ch) in self
            .records
            .iter()
            .flat_map(|rec| &rec.channels)
            .enumerate()
        {
            let len = ch.data.len();
            let runs = equal_runs(&ch.data).len().max(1);
            let run_length = (len as f64 / runs as f64).min(MAX_LAG_RUN_LENGTH);
            let lags = newey_west_lags(runs).max(1) as f64 * run_length;
            layout.lags.push(lags.round().max(1.0) as usize);
            let id = ch.noise_free_quantum.is_none().then_some(s);
            layout.series.extend(std::iter::repeat_n(id, len));
        }
        layout
    }

    fn fitted_channels(&self, theta: &[f64]) -> Vec<FittedChannel> {
        let Some(sim) = self.simulate(theta) else {
            return Vec::new();
        };
        self.records
            .iter()
            .zip(sim)
            .enumerate()
            .flat_map(|(k, (rec, simulated))| {
                rec.channels
                    .iter()
                    .zip(simulated)
                    .map(move |(ch, model)| FittedChannel {
                        record: k,
                        channel: ch.kind,
                        samples: ch.keep.clone(),
                        measured: ch.data.clone(),
                        model,
                    })
            })
            .collect()
    }
}

/// The model's channels on every sample of `records` — the samples an exclusion mask leaves out
/// of a fit too — for `motor` with `effects`: what a fit is judged against on data it did not
/// see (held-out records or blocks). Channels as in [`identify_output_error`]; each
/// [`FittedChannel::samples`] lists every sample.
pub fn predict_output_error(
    records: &[ExcitedRecord<'_>],
    motor: &MotorParams,
    effects: &Effects,
) -> Result<Vec<FittedChannel>, FitError> {
    predict_with_step_factor(records, motor, effects, 1.0)
}

/// [`predict_output_error`] on RK4 steps `step_factor` times the simulator's default
/// ([`Simulator::with_step_factor`]).
pub(crate) fn predict_with_step_factor(
    records: &[ExcitedRecord<'_>],
    motor: &MotorParams,
    effects: &Effects,
    step_factor: f64,
) -> Result<Vec<FittedChannel>, FitError> {
    // Every sample is predicted, the masks set aside; still, they must align.
    for (k, r) in records.iter().enumerate() {
        crate::checks::check_aligned(&format!("record {}", k + 1), r.channels())?;
    }
    let all: Vec<ExcitedRecord<'_>> = records
        .iter()
        .map(|r| ExcitedRecord {
            exclude_current: None,
            exclude_speed: None,
            ..*r
        })
        .collect();
    let mut problem = OeProblem::new(&all, effects, f64::INFINITY)?;
    problem.step_factor = step_factor;
    problem.set_step_for(motor, effects).ok_or_else(|| {
        bad(
            "motor",
            "a time constant far below the sample period: the records cannot show it".into(),
        )
    })?;
    let theta = problem.parameters.encode(motor, effects)?;
    let fitted = problem.fitted_channels(&theta);
    if fitted.is_empty() {
        return Err(bad(
            "motor",
            "the model cannot be simulated on these records".into(),
        ));
    }
    Ok(fitted)
}

/// The output-error model of some records linearised at one point (see
/// [`output_error_sensitivity`]).
pub(crate) struct Sensitivity {
    /// Weighted residuals `(simulated − measured)/σ` at the fitted samples, in record, channel,
    /// sample order.
    pub residuals: Vec<f64>,
    /// Their derivatives in θ (forward differences), one column per parameter asked for.
    pub jacobian: DMatrix<f64>,
    /// Length of each channel's run of residuals, in order (for correlation factors).
    pub series: Vec<usize>,
}

/// The residuals of `records` for `motor` with `effects` and their Jacobian in θ (the
/// coordinates of [`identify_output_error_with_effects`]): every column, or with `of` only the
/// columns of that effect's fitted parameters. Each channel is weighted by its σ in `sigmas`
/// (`(record, channel, σ)`, the channel's own scatter where missing). The RK4 step is the one
/// a fit from this point with `step_factor` would take ([`Simulator::with_step_factor`]).
/// What a score test needs: the residual and the
/// signatures of parameters at a point, without a fit.
pub(crate) fn output_error_sensitivity(
    records: &[ExcitedRecord<'_>],
    motor: &MotorParams,
    effects: &Effects,
    sigmas: &[(usize, Channel, f64)],
    of: Option<motor_model::EffectKind>,
    step_factor: f64,
) -> Result<Sensitivity, FitError> {
    let mut problem = OeProblem::new(records, effects, f64::INFINITY)?;
    problem.set_sigmas(sigmas);
    let theta = problem.parameters.encode(motor, effects)?;
    let not_simulable = || {
        bad(
            "motor",
            "a time constant far below the sample period: the records cannot show it".into(),
        )
    };
    problem.step_factor = step_factor;
    problem
        .set_step_for(motor, effects)
        .ok_or_else(not_simulable)?;
    let which: Vec<usize> = match of {
        None => (0..problem.parameters.len()).collect(),
        Some(kind) => problem
            .parameters
            .slot_kinds()
            .enumerate()
            .filter(|(_, k)| *k == kind)
            .map(|(j, _)| crate::parameters::MOTOR + j)
            .collect(),
    };
    let (residuals, jacobian) = problem
        .jacobian_columns(&theta, &which, false)
        .ok_or_else(not_simulable)?;
    let series = problem
        .records
        .iter()
        .flat_map(|r| r.channels.iter().map(|c| c.data.len()))
        .collect();
    Ok(Sensitivity {
        residuals,
        jacobian,
        series,
    })
}

/// Checks record `k` (0-based): aligned, finite channels of enough samples, a positive period.
fn check_record(k: usize, rec: &ExcitedRecord<'_>) -> Result<(), FitError> {
    let label = format!("record {}", k + 1);
    crate::checks::check_channels(&label, rec.channels())?;
    if !(rec.dt.is_finite() && rec.dt > 0.0) {
        return Err(bad(
            label,
            format!("sample period {} s: expected a positive period", rec.dt),
        ));
    }
    Ok(())
}

/// Finds where each record's quantised current settles at one voltage level and gives each
/// such run an offset ([`CurrentOffset`], the step fit's settled offset,
/// `crate::input_uncertainty::settled_current`): a current that settles within a few ADC steps
/// reads the same few codes for the rest of the level, its quantisation error a constant the
/// parameters absorb (into f and Ts) and the residuals cannot show, so it enters the intervals
/// as an input. Runs whose readings average to the same code of the same ADC step share one
/// offset — a level a PRBS or staircase comes back to reads alike each time — and so do not
/// average out. A current read without noise gets none: its quantiser enters the intervals
/// whole ([`grid_phase_score_covariance`]). Levels are the piecewise input's, or the step's.
fn settle_currents(records: &mut [OeRecord]) -> Vec<CurrentOffset> {
    let mut offsets: Vec<CurrentOffset> = Vec::new();
    for rec in records.iter_mut() {
        let starts: Vec<f64> = match &rec.input {
            Input::Piecewise { times_s, .. } => times_s.clone(),
            Input::Step { at_s, .. } => vec![0.0, *at_s],
            _ => continue,
        };
        let dt = rec.dt;
        let Some(ch) = rec
            .channels
            .iter_mut()
            .find(|c| c.kind == Channel::Current && c.noise_free_quantum.is_none())
        else {
            continue;
        };
        let Some(q) = detect_quantum(&ch.data) else {
            continue;
        };
        // Level j covers the samples at or after its start and before the next one's.
        let first_kept = |t: f64| {
            let i = (t / dt - 1e-9).ceil().max(0.0) as usize;
            ch.keep.partition_point(|&k| k < i)
        };
        let bounds: Vec<usize> = starts
            .iter()
            .map(|&t| first_kept(t))
            .chain(std::iter::once(ch.data.len()))
            .collect();
        for w in bounds.windows(2) {
            let (a, b) = (w[0], w[1]);
            let Some((from, variance)) = ch.data.get(a..b).and_then(|seg| settled_current(seg, q))
            else {
                continue;
            };
            let run = &ch.data[a + from..b];
            let mean = run.iter().sum::<f64>() / run.len() as f64;
            let key = (q.to_bits(), (mean / q).round() as i64);
            let g = match offsets.iter().position(|o| o.key == key) {
                Some(g) => {
                    offsets[g].variance = offsets[g].variance.max(variance);
                    g
                }
                None => {
                    offsets.push(CurrentOffset {
                        value: 0.0,
                        variance,
                        key,
                    });
                    offsets.len() - 1
                }
            };
            ch.settled.push((a + from, b, g));
        }
    }
    offsets
}

/// Checks one record's channels and builds its fitted channels.
fn prepare(k: usize, rec: &ExcitedRecord<'_>) -> Result<OeRecord, FitError> {
    check_record(k, rec)?;
    let n = rec.current.len();
    let channel = |kind: Channel, full: Vec<f64>, mask: Option<&[bool]>| {
        let keep: Vec<usize> = (0..n).filter(|&i| !mask.is_some_and(|m| m[i])).collect();
        let data: Vec<f64> = keep.iter().map(|&i| full[i]).collect();
        let noise_free_quantum = match kind {
            Channel::EncoderSpeed => None,
            Channel::Current | Channel::Speed => noise_free_quantum(&data),
        };
        OeChannel {
            kind,
            sigma: noise_std(&data),
            floor: noise_floor(&data),
            noise_free_quantum,
            settled: Vec::new(),
            keep,
            data,
        }
    };
    let mut channels = vec![channel(
        Channel::Current,
        rec.current.to_vec(),
        rec.exclude_current,
    )];
    match (rec.position, rec.speed) {
        (Some(angle), _) => {
            let times: Vec<f64> = (0..n).map(|i| i as f64 * rec.dt).collect();
            channels.push(channel(
                Channel::EncoderSpeed,
                central_difference(&times, angle),
                rec.exclude_speed,
            ));
        }
        (None, Some(speed)) => {
            channels.push(channel(Channel::Speed, speed.to_vec(), rec.exclude_speed))
        }
        (None, None) => {}
    }
    Ok(OeRecord {
        initial: InitialState::Rest,
        free_at: None,
        priors: Vec::new(),
        input: rec.input.clone(),
        dt: rec.dt,
        n,
        channels,
    })
}

/// Identifies R, L, k, f, J, Ts from records of any voltage waveform (output error through
/// the stick-slip simulator), starting from `start` (e.g. [`equation_error_start`]).
pub fn identify_output_error(
    records: &[ExcitedRecord<'_>],
    start: &MotorParams,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    identify_output_error_with_inputs_and_effects(records, &[], start, &Effects::none(), settings)
}

/// [`identify_output_error`] of the motor with `effects` switched on: one fit of
/// `θ = [ln R, ln L, ln k, ln f, ln J, ln Ts, θ_e…]`, the six motor parameters and the fitted
/// parameters of the effects ([`Effects::fitted_slots`], each in its unconstrained coordinate,
/// [`motor_model::ParamSpec::to_unconstrained`]; Stribeck's Tst as `ln(Tst − Ts)`), started
/// from `start` and the values in `effects`. The simulation is the stick-slip simulator with
/// those effects, on a fixed RK4 step and (with cogging) a speed bound 1.5 times the largest
/// measured speed, so that it is smooth in θ. The results name every parameter:
/// [`FullFit::effects`], [`FullFit::effect_estimates`] (value, standard error and 95 %
/// interval in SI units by the delta method through each transform),
/// [`FullFit::parameter_names`] for the rows of [`FullFit::correlation`].
pub fn identify_output_error_with_effects(
    records: &[ExcitedRecord<'_>],
    start: &MotorParams,
    effects: &Effects,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    identify_output_error_with_inputs_and_effects(records, &[], start, effects, settings)
}

/// [`identify_output_error`] with what each record leaves unknown about its voltage levels
/// (`priors[k]` for record `k`, from [`voltage_levels`], one per level of its piecewise input;
/// or no priors at all): the fit moves the levels and their start instants where the records
/// put them and widens the intervals by what remains unknown (see [`crate::StepInputs`]).
pub fn identify_output_error_with_inputs(
    records: &[ExcitedRecord<'_>],
    priors: &[Vec<LevelPrior>],
    start: &MotorParams,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    identify_output_error_with_inputs_and_effects(
        records,
        priors,
        start,
        &Effects::none(),
        settings,
    )
}

/// [`identify_output_error_with_inputs`] of the motor with `effects`
/// (see [`identify_output_error_with_effects`]).
pub fn identify_output_error_with_inputs_and_effects(
    records: &[ExcitedRecord<'_>],
    priors: &[Vec<LevelPrior>],
    start: &MotorParams,
    effects: &Effects,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    identify_output_error_with_initial_states(records, priors, &[], start, effects, settings)
}

/// [`identify_output_error_with_inputs_and_effects`] with record `k`'s simulation started from
/// `initial[k]` (all at rest when `initial` is empty; [`crate::detect_initial_state`] tells
/// which a record shows): at rest, in the steady state of its first level (Eqs. (4), (5) of
/// the motor being fitted; nominal model only), or free (its initial current \[A\] and speed
/// \[rad/s\] fitted with the motor, from its first samples; the motor's intervals are the
/// marginal ones, with that uncertainty in them). [`FullFit::initial_states`] gives each
/// record's initial state as fitted.
pub fn identify_output_error_with_initial_states(
    records: &[ExcitedRecord<'_>],
    priors: &[Vec<LevelPrior>],
    initial: &[InitialState],
    start: &MotorParams,
    effects: &Effects,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    fit_output_error(
        records, priors, initial, start, effects, settings, 1.0, None,
    )
}

/// [`identify_output_error_with_initial_states`] from `start`, tried again from another start
/// where that fit is refused because a friction parameter went to nothing
/// ([`crate::Refusal::Vanished`]), or so near it that the records no longer determine it
/// ([`crate::Refusal::Undetermined`] of f or Ts): a start that splits the friction wrongly
/// between f and Ts can lead the fit into the minimum without one of them. The equation-error
/// start of a ±12 V PRBS of the small servo (`fixtures/motors/small_servo.json`, 1 s at 2 kHz
/// through the logger) put f at 2.3 times its value and Ts at a ninth of it, and the fit drove Ts to
/// 1e-15 N·m on 5 of 6 seeds; from f halved, or from Ts tenfold, it found the motor. The
/// restart moves the friction towards the vanished parameter: that parameter ten times its
/// start (at least 1 % and at most half of its scale: the largest motor torque `k·|I|` of the
/// records for Ts, the electrical damping `k²/R` for f), the other halved. An accepted fit
/// from there is kept, else the first fit with its refusal. Returns the start of the fit
/// returned, and the fit; the restart costs one bounded fit.
pub fn identify_output_error_with_friction_restarts(
    records: &[ExcitedRecord<'_>],
    priors: &[Vec<LevelPrior>],
    initial: &[InitialState],
    start: &MotorParams,
    effects: &Effects,
    settings: LmSettings,
) -> Result<(MotorParams, FullFit), FitError> {
    let first = identify_output_error_with_initial_states(
        records, priors, initial, start, effects, settings,
    )?;
    let parameter = match first.refusal {
        Some(
            crate::Refusal::Vanished { parameter, .. }
            | crate::Refusal::Undetermined { parameter, .. },
        ) if parameter == "Ts" || parameter == "f" => parameter,
        _ => return Ok((*start, first)),
    };
    let peak_current = records
        .iter()
        .flat_map(|r| r.current.iter())
        .fold(0.0_f64, |m, i| m.max(i.abs()));
    let torque_scale = start.k_nm_per_a * peak_current;
    let damping_scale = start.k_nm_per_a.powi(2) / start.r_ohm;
    // One restart: each costs a whole fit, and a second (a hundredfold, quartered) found no
    // motor the first had missed on the records tried, while it tripled the time of a fit
    // that is refused anyway (an 85,000-sample record at 100 kHz: 7.6 s → 27.6 s).
    let tenfold = |value: f64, scale: f64| (10.0 * value).clamp(0.01 * scale, 0.5 * scale);
    let restart = match parameter {
        "Ts" if torque_scale > 0.0 => MotorParams {
            ts_nm: tenfold(start.ts_nm, torque_scale),
            f_nms_per_rad: 0.5 * start.f_nms_per_rad,
            ..*start
        },
        "f" if damping_scale > 0.0 => MotorParams {
            f_nms_per_rad: tenfold(start.f_nms_per_rad, damping_scale),
            ts_nm: 0.5 * start.ts_nm,
            ..*start
        },
        _ => return Ok((*start, first)),
    };
    match identify_output_error_with_initial_states(
        records, priors, initial, &restart, effects, settings,
    ) {
        Ok(fit) if fit.accepted() => Ok((restart, fit)),
        _ => Ok((*start, first)),
    }
}

/// [`identify_output_error_with_initial_states`] on RK4 steps `step_factor` times the
/// simulator's default ([`Simulator::with_step_factor`]), every channel weighted by the noise
/// level `sigmas` gives it (`(record, channel, σ)`, as [`output_error_sensitivity`] takes
/// them) in one stage when given; without, by its own scatter and then by its own residual at
/// the first solution. Models fitted in the same given weights are nested: the fall of their
/// weighted cost is a likelihood ratio.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_output_error(
    records: &[ExcitedRecord<'_>],
    priors: &[Vec<LevelPrior>],
    initial: &[InitialState],
    start: &MotorParams,
    effects: &Effects,
    settings: LmSettings,
    step_factor: f64,
    sigmas: Option<&[(usize, Channel, f64)]>,
) -> Result<FullFit, FitError> {
    if !priors.is_empty() && priors.len() != records.len() {
        return Err(bad(
            "level priors",
            format!(
                "{} lists for {} records: give one per record, or none",
                priors.len(),
                records.len()
            ),
        ));
    }
    if records.is_empty() {
        return Err(bad("records", "no record given".into()));
    }
    let mut problem = OeProblem::new(records, effects, f64::INFINITY)?;
    problem.step_factor = step_factor;
    if let Some(sigmas) = sigmas {
        problem.set_sigmas(sigmas);
    }
    problem.set_initial_states(initial, effects)?;
    let theta0 = problem.with_state_guesses(problem.parameters.encode(start, effects)?);
    let h = problem
        .step_for(start, effects)
        .ok_or_else(|| bad(START_SERIES, "not simulable".into()))?;
    problem.max_step_bits.store(h.to_bits(), Ordering::Relaxed);
    if priors.is_empty() {
        problem.set_step_for(start, effects).ok_or_else(|| {
            bad(
                START_SERIES,
                "a time constant (L/R or the mechanical one) more than 2.5 times below the sample period: \
                 the records cannot show it; give a start that matches them"
                    .into(),
            )
        })?;
    }
    for (k, (rec, p)) in problem.records.iter_mut().zip(priors).enumerate() {
        if p.is_empty() {
            continue;
        }
        let Input::Piecewise { times_s, volts } = &rec.input else {
            return Err(bad(
                format!("record {}", k + 1),
                "level priors given for a voltage that is not piecewise constant".into(),
            ));
        };
        if p.len() != volts.len() {
            return Err(bad(
                format!("record {}", k + 1),
                format!("{} level priors for {} levels", p.len(), volts.len()),
            ));
        }
        if p.iter().any(|q| {
            !(q.volts_variance_v2.is_finite()
                && q.volts_variance_v2 >= 0.0
                && q.start_variance_s2.is_finite()
                && q.start_variance_s2 >= 0.0)
        }) {
            return Err(bad(
                format!("record {}", k + 1),
                "level variances must be finite and ≥ 0".into(),
            ));
        }
        rec.priors = volts
            .iter()
            .zip(times_s)
            .zip(p)
            .map(|((v, t), q)| (*v, *t, *q))
            .collect();
    }
    let mut fit = fit_with_inputs(&mut problem, &theta0, settings)?;
    fit.initial_states = problem.fitted_initial_states(&fit.theta);
    Ok(fit)
}

/// Relative step of the central difference in a level ([`INTERVAL_FD_STEP`]'s reasons).
const LEVEL_DIFF_STEP: f64 = INTERVAL_FD_STEP;
/// Step of the central difference in a level's start, as a fraction of the sample period.
const START_DIFF_STEP: f64 = 1e-2;

impl OeProblem {
    /// `(record, level, 0: value / 1: start)` of every uncertain input, then `(0, g, 2)` for
    /// each settled-current offset `g`.
    fn nuisance_slots(&self) -> Vec<(usize, usize, usize)> {
        let mut out = Vec::new();
        for (k, rec) in self.records.iter().enumerate() {
            for (j, (_, _, p)) in rec.priors.iter().enumerate() {
                if p.volts_variance_v2 > 0.0 {
                    out.push((k, j, 0));
                }
                if p.start_variance_s2 > 0.0 {
                    out.push((k, j, 1));
                }
            }
        }
        out.extend((0..self.current_offsets.len()).map(|g| (0, g, 2)));
        out
    }
}

impl NuisanceProblem for OeProblem {
    fn nuisances(&self) -> Vec<Nuisance> {
        let slots = self.nuisance_slots();
        let level_slots: Vec<(usize, usize)> = slots
            .iter()
            .filter(|(_, _, slot)| *slot == 0)
            .map(|&(k, j, _)| (k, j))
            .collect();
        let groups = bias_group_sizes(
            &level_slots
                .iter()
                .map(|&(k, j)| {
                    let p = self.records[k].priors[j].2;
                    (p.volts_bias_variance_v2, p.volts_bias_code)
                })
                .collect::<Vec<_>>(),
        );
        let group_of = |k: usize, j: usize| {
            level_slots
                .iter()
                .position(|&s| s == (k, j))
                .map_or(1, |i| groups[i])
        };
        slots
            .into_iter()
            .filter_map(|(k, j, slot)| {
                if slot == 2 {
                    let o = self.current_offsets[j];
                    return Some(Nuisance {
                        value: o.value,
                        prior_mean: 0.0,
                        prior_variance: o.variance,
                        step: 1e-3 * o.variance.sqrt(),
                    });
                }
                let rec = &self.records[k];
                let Input::Piecewise { times_s, volts } = &rec.input else {
                    return None;
                };
                let (v0, t0, p) = rec.priors[j];
                Some(if slot == 0 {
                    Nuisance {
                        value: volts[j],
                        prior_mean: v0,
                        prior_variance: pooled_level_variance(
                            p.volts_variance_v2,
                            p.volts_bias_variance_v2,
                            group_of(k, j),
                        ),
                        step: LEVEL_DIFF_STEP * v0.abs().max(1e-3),
                    }
                } else {
                    Nuisance {
                        value: times_s[j],
                        prior_mean: t0,
                        prior_variance: p.start_variance_s2,
                        step: START_DIFF_STEP * rec.dt,
                    }
                })
            })
            .collect()
    }

    fn set_nuisance(&mut self, j: usize, value: f64) {
        if let Some(&(k, level, slot)) = self.nuisance_slots().get(j) {
            if slot == 2 {
                self.current_offsets[level].value = value;
                return;
            }
            let rec = &mut self.records[k];
            let gap = 1e-9 * rec.dt;
            let (_, start, prior) = rec.priors.get(level).copied().unwrap_or_default();
            let half = (3.0 * prior.start_variance_s2).sqrt();
            if let Input::Piecewise { times_s, volts } = &mut rec.input {
                match slot {
                    0 => volts[level] = value,
                    // A start stays in the period its uniform prior spans (±√(3V)), and
                    // may not pass its neighbours (nor 0).
                    _ => {
                        let lo = if level == 0 { 0.0 } else { times_s[level - 1] };
                        let hi = times_s.get(level + 1).copied().unwrap_or(f64::INFINITY);
                        times_s[level] = value
                            .min(start + half)
                            .max(start - half)
                            .min(hi - gap)
                            .max(lo + gap);
                    }
                }
            }
        }
    }

    fn linear_parts(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        self.jacobian_for_intervals(theta)
    }

    fn residual_vector(&self, theta: &[f64]) -> Option<Vec<f64>> {
        self.residuals(theta)
    }

    /// The score covariance of the residuals' errors: Newey–West over runs of equal readings
    /// ([`newey_west_run_covariance`]: readings that repeat exactly share one quantisation
    /// error), except for a channel read without noise: there the error of every reading is
    /// fixed by the signal and by where the ADC's grid sits, and the fit absorbs much of it
    /// (a settled level's held code into Ts), so the residuals cannot show it; that channel
    /// enters instead as its quantiser on the model's values averaged over the grid's place
    /// ([`crate::input_uncertainty::grid_phase_score_covariance`]).
    fn score_covariance_of(&self, r: &[f64], jac: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let channels = || self.records.iter().flat_map(|rec| &rec.channels);
        let series: Vec<usize> = channels().map(|ch| ch.data.len()).collect();
        let runs: Vec<usize> = channels().flat_map(|ch| equal_runs(&ch.data)).collect();
        let mut rest = r.to_vec();
        let mut grid = DMatrix::zeros(jac.ncols(), jac.ncols());
        let mut row = 0;
        for ch in channels() {
            let len = ch.data.len();
            if let Some(q) = ch.noise_free_quantum {
                let rows = rest.get_mut(row..row + len)?;
                let model: Vec<f64> = ch
                    .data
                    .iter()
                    .zip(rows.iter())
                    .map(|(y, r)| y + ch.sigma * r)
                    .collect();
                rows.fill(0.0);
                grid += grid_phase_score_covariance(&model, q, jac.rows(row, len), ch.sigma);
            }
            row += len;
        }
        newey_west_run_covariance(&rest, jac, &series, &runs).map(|c| c + grid)
    }
}

/// Samples per row of the equation-error start's torque equation (2b), at most \[-\].
const START_DECIMATION: usize = 5;

/// RK4 steps of [`equation_error_start`]'s simulations, as a multiple of the simulator's
/// default ([`Simulator::with_step_factor`]).
const START_STEP_FACTOR: f64 = 8.0;
/// Cut-offs tried by [`equation_error_start`], as fractions of the sample rate.
const START_CUTOFFS: [f64; 4] = [0.1, 0.02, 0.004, 0.0008];

/// A start for [`identify_output_error`] by equation error: the measured signals, low-passed
/// forward and backward (zero phase, 4th-order Butterworth), are put into the model's
/// equations, which are linear in the parameters: Eq. (2a) `E = R I + L dI/dt + k Ω` gives R, L,
/// k by least squares over every sample, and Eq. (2b) `k I = J dΩ/dt + f Ω + Ts sign Ω` the
/// rest (the inverse model of [`crate::identify_inverse_model`] on the motor torque `k I`, the
/// angle filtered five times harder). Derivatives of noisy signals bias such estimates towards
/// zero unless the filter is narrow, and a narrow filter distorts fast motors: so the estimate
/// is made at cut-offs of 1/10, 1/50, 1/250 and 1/1250 of the sample rate and the one whose
/// simulation fits the records best (output-error cost) is returned. Values the records cannot
/// resolve (an L below one sample, no friction seen) are replaced by small positive ones; a J
/// the torque equation gives as ≤ 0 (a torque ripple the regression does not hold, or too
/// little acceleration) by the best, by the same cost, of mechanical time constants
/// J / (f + k²/R) of 1/1000 to 1 times the longest record.
pub fn equation_error_start(records: &[ExcitedRecord<'_>]) -> Result<MotorParams, FitError> {
    equation_error_start_with_initial_states(records, &[])
}

/// [`equation_error_start`] for records whose simulations start from `initial` (as in
/// [`identify_output_error_with_initial_states`]): the cut-off is chosen on the output-error
/// cost of those simulations, free states at the records' first samples.
pub fn equation_error_start_with_initial_states(
    records: &[ExcitedRecord<'_>],
    initial: &[InitialState],
) -> Result<MotorParams, FitError> {
    let mut problem = OeProblem::new(records, &Effects::none(), f64::INFINITY)?;
    problem.set_initial_states(initial, &Effects::none())?;
    // Telling four starts apart by their cost needs no more than noise-level accuracy.
    problem.step_factor = START_STEP_FACTOR;
    let mut best: Option<(f64, MotorParams)> = None;
    let mut first_error = None;
    for fraction in START_CUTOFFS {
        let starts = match equation_error_estimate(records, fraction) {
            Ok(starts) => starts,
            Err(e) => {
                first_error.get_or_insert(e);
                continue;
            }
        };
        for start in starts {
            if problem.set_step_for(&start, &Effects::none()).is_none() {
                first_error.get_or_insert(bad(
                    "records",
                    format!(
                        "the equation-error estimate (R {:.3e} Ω, L {:.3e} H) has a time constant far below the sample period",
                        start.r_ohm, start.l_henry
                    ),
                ));
                continue;
            }
            let theta = problem.with_state_guesses(start.values().iter().map(|v| v.ln()).collect());
            debug_assert_eq!(theta.len(), problem.parameters.len());
            let cost = problem.cost(&theta).unwrap_or(f64::INFINITY);
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                best = Some((cost, start));
            }
        }
    }
    match (best, first_error) {
        (Some((_, start)), _) => Ok(start),
        (None, Some(e)) => Err(e),
        (None, None) => Err(bad("records", "no start could be estimated".into())),
    }
}

/// R \[Ω\], L \[H\] and k \[N·m/A\] from Eq. (2a) `E = R I + L dI/dt + k Ω` by least squares
/// over every sample of `records`, the current and angle low-passed forward and backward (zero
/// phase, 4th-order Butterworth) at `fraction` of the sample rate and differentiated by central
/// differences. The torque constant of a drive that closes its own current loop follows from
/// its armature voltage this way (`motorid identify --input current` without
/// `--torque-constant`). An L the records cannot resolve (≤ 0) is replaced by half a sample's
/// worth, `R dt/2`.
pub fn electrical_equation(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<[f64; 3], FitError> {
    electrical_estimate(records, fraction).map(|(x, _)| x)
}

/// [`electrical_equation`], also returning each record's sample period and angle.
#[allow(clippy::type_complexity)]
fn electrical_estimate(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<([f64; 3], Vec<(f64, Vec<f64>)>), FitError> {
    let domain = |reason: String| FitError::MethodDomain {
        equation: "voltage equation (2a)",
        reason,
    };
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    let mut per_record = Vec::new();
    for (k, rec) in records.iter().enumerate() {
        check_record(k, rec)?;
        let n = rec.current.len();
        let dt = rec.dt;
        if n < crate::checks::MIN_SAMPLES || dt.is_nan() || dt <= 0.0 {
            return Err(bad(
                format!("record {}", k + 1),
                format!("{n} samples, period {dt} s: too short for a start"),
            ));
        }
        let times: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let position: Vec<f64> = match (rec.position, rec.speed) {
            (Some(p), _) => p.to_vec(),
            (None, Some(w)) => {
                // The angle as the running trapezoid integral of the tachometer speed.
                let mut theta = Vec::with_capacity(n);
                let mut acc = 0.0;
                theta.push(0.0);
                for i in 1..n {
                    acc += 0.5 * (w[i] + w[i - 1]) * dt;
                    theta.push(acc);
                }
                theta
            }
            (None, None) => {
                return Err(domain(format!(
                    "record {} has neither speed nor position: k, f and J need one of them",
                    k + 1
                )))
            }
        };
        let filter = Butterworth::low_pass(4, fraction / dt, 1.0 / dt)?;
        let i_f = filter.filtfilt(rec.current);
        let th_f = filter.filtfilt(&position);
        let w_f = central_difference(&times, &th_f);
        let di = central_difference(&times, &i_f);
        for j in 0..n {
            let e = rec.input.volts_at(times[j]);
            let row = nalgebra::Vector3::new(i_f[j], di[j], w_f[j]);
            ata += row * row.transpose();
            atb += row * e;
        }
        per_record.push((dt, position));
    }
    let x = ata.cholesky().map(|c| c.solve(&atb)).ok_or_else(|| {
        domain(
            "the voltage equation is singular: does the motor move, and does the voltage vary?"
                .into(),
        )
    })?;
    let (r, mut l, k) = (x[0], x[1], x[2]);
    let span = records
        .iter()
        .map(|r| r.dt * r.current.len() as f64)
        .fold(0.0, f64::max);
    if !(r > 0.0 && k > 0.0 && r.is_finite() && k.is_finite()) {
        return Err(domain(format!(
            "R = {r:.4e} Ω, k = {k:.4e} N·m/A from the voltage equation: either the records show too little \
             motion to tell R I from k Ω (the longest lasts {span:.4e} s: record until the speed settles), or the \
             current or speed sign is reversed"
        )));
    }
    let dt_min = per_record.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    if !(l > 0.0 && l.is_finite()) {
        l = 0.5 * r * dt_min;
    }
    Ok(([r, l, k], per_record))
}

/// One equation-error estimate with the electrical signals low-passed at `fraction` of the
/// sample rate (the angle at a fifth of that, with decimation by 5, or less on records too
/// short for twenty rows at 5): one start, or several differing only in J when the torque
/// equation leaves J unresolved.
fn equation_error_estimate(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<Vec<MotorParams>, FitError> {
    let domain = |reason: String| FitError::MethodDomain {
        equation: "equation-error start (Eq. (2))",
        reason,
    };
    let ([r, l, k], per_record) = electrical_estimate(records, fraction)?;
    // The mechanical side on the motor torque k I: one inverse model over every record (each
    // filtered on its own, samples at rest left out), so that its error is the real one.
    let torques: Vec<Vec<f64>> = records
        .iter()
        .map(|rec| motor_torque(k, rec.current))
        .collect();
    let axis: Vec<AxisRecord<'_>> = per_record
        .iter()
        .zip(&torques)
        .map(|((dt, position), torque)| AxisRecord {
            dt: *dt,
            torque,
            position,
        })
        .collect();
    let dt_max = per_record.iter().map(|(dt, _)| *dt).fold(0.0_f64, f64::max);
    // Accelerations are second differences of a quantised angle: filter harder than the
    // electrical side and average by decimation, or the noise in the acceleration regressor
    // biases J towards zero. Every START_DECIMATION-th sample, or as many as the shortest
    // record leaves twenty rows at (a 0.1 s step at 1 kHz has 101 samples); a record too
    // short even for every sample is refused with the count every sample would need.
    let shortest = per_record
        .iter()
        .map(|(_, position)| position.len())
        .min()
        .unwrap_or(0);
    let decimation = (1..=START_DECIMATION)
        .rev()
        .find(|&d| shortest >= crate::mechanical::min_samples(d))
        .unwrap_or(1);
    let settings = InverseModelSettings {
        position_cutoff_hz: 0.2 * fraction / dt_max,
        position_filter_order: 4,
        decimation,
        // Eq. (2b) has no offset; with one, a record that never reverses cannot tell it from
        // Ts (a 40 V step gave Ts = 2443 N·m against an offset of −2443 N·m).
        fit_offset: false,
    };
    let mechanical = identify_inverse_model_pooled(&axis, settings)
        .map_err(|e| domain(format!("the torque equation (2b): {e}")))?;
    let motor_model::AxisParams {
        mass_kg: j,
        viscous_ns_per_m: f,
        coulomb_n: ts,
        ..
    } = mechanical.axis;
    let f = if f > 0.0 { f } else { 1e-3 * k * k / r };
    let peak_torque = records
        .iter()
        .flat_map(|r| r.current.iter())
        .fold(0.0f64, |m, i| m.max((k * i).abs()));
    let ts = if ts > 0.0 { ts } else { 1e-3 * peak_torque };
    let motor = |j: f64| {
        MotorParams::new(r, l, k, f, j, ts)
            .map_err(FitError::model("equation-error start (Eq. (2))"))
    };
    if j > 0.0 && j.is_finite() {
        return Ok(vec![motor(j)?]);
    }
    // A J the torque equation cannot resolve (a torque ripple or a load the regression does
    // not hold, against too little acceleration): one J per mechanical time constant
    // J / (f + k²/R) of UNRESOLVED_J_SPANS times the longest record, for the caller's costs.
    let span = records
        .iter()
        .map(|r| r.dt * r.current.len().saturating_sub(1) as f64)
        .fold(0.0, f64::max);
    let damping = f + k * k / r;
    let starts: Vec<MotorParams> = UNRESOLVED_J_SPANS
        .iter()
        .filter_map(|share| motor(share * span * damping).ok())
        .collect();
    if starts.is_empty() {
        return Err(domain(format!(
            "J = {j:.4e} kg·m² from the torque equation: the records show too little acceleration"
        )));
    }
    Ok(starts)
}

/// Mechanical time constants tried by [`equation_error_start`] when the torque equation
/// gives no positive J, as shares of the longest record \[-\].
const UNRESOLVED_J_SPANS: [f64; 4] = [1e-3, 1e-2, 1e-1, 1.0];

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::MeasurementModel;

    #[test]
    fn given_channel_weights_are_kept_through_the_fit() {
        let motor = MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3).expect("valid motor");
        let step = Input::step(6.0, 0.05).expect("a step");
        let trace =
            motor_model::simulate(&motor, Effects::none(), &step, 0.3, 5000.0).expect("a trace");
        let record = MeasurementModel::paper_logger(&trace, 3)
            .apply(&trace)
            .expect("a record");
        let input = voltage_input(&record.t, &record.voltage).expect("a waveform");
        let records = [ExcitedRecord {
            input: &input,
            dt: 2e-4,
            current: &record.current,
            speed: None,
            position: record.position.as_deref(),
            exclude_current: None,
            exclude_speed: None,
        }];
        let start = MotorParams::new(2.2, 1.8e-3, 0.048, 5e-4, 2.2e-5, 3.5e-3).expect("a start");
        let settings = LmSettings::default();
        let own = fit_output_error(
            &records,
            &[],
            &[],
            &start,
            &Effects::none(),
            settings,
            1.0,
            None,
        )
        .expect("a fit");
        // Weights three times the fit's own: kept, not replaced by the residual's level.
        let given: Vec<(usize, Channel, f64)> = own
            .quality
            .iter()
            .map(|q| (q.test, q.channel, 3.0 * q.noise_std))
            .collect();
        let kept = fit_output_error(
            &records,
            &[],
            &[],
            &own.params,
            &Effects::none(),
            settings,
            1.0,
            Some(&given),
        )
        .expect("a fit");
        assert!(kept.termination.converged(), "{:?}", kept.termination);
        for (q, (_, _, sigma)) in kept.quality.iter().zip(&given) {
            assert_eq!(q.noise_std, *sigma, "{q:?}");
            assert!(q.rms_residual < 0.5 * sigma, "{q:?}");
        }
    }
}
