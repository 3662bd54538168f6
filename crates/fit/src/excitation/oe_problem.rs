//! The output-error least-squares problem: every record simulated from its voltage by the
//! stick-slip simulator, each channel weighted by its noise, the motor's parameters, the fitted
//! effects' and the records' initial states and current offsets as unknowns.

use std::sync::atomic::{AtomicU64, Ordering};

use motor_model::{central_difference, steady_state, Effects, Input, MotorParams, Simulator};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::error::FitError;
use crate::estimation::lm::{half_squared_norm, LeastSquares, NormalEquations};
use crate::estimation::parameters::Parameters;
use crate::estimation::plausibility::RecordFacts;
use crate::estimation::records::{
    noise_floor, noise_std, Channel, ChannelQuality, ExcitedRecord, FittedChannel,
    FittedInitialState, InitialState,
};
use crate::estimation::stats::{
    equal_runs, newey_west_lags, newey_west_run_covariance, scaled_inverse, SeriesLayout,
};
use crate::estimation::weighted::{quality_from_sums, WeightedProblem};
use crate::excitation::input_uncertainty::{
    bias_group_sizes, detect_quantum, grid_phase_score_covariance, noise_free_quantum,
    pooled_level_variance, settled_current, LevelPrior, Nuisance, NuisanceProblem,
};
use crate::excitation::voltage::bad;

/// Step of the forward-difference Jacobian in `θ = ln p` (relative step of each parameter).
pub(crate) const FD_STEP: f64 = 1e-6;

/// Step of the central-difference Jacobian behind the intervals
/// ([`OeProblem::jacobian_for_intervals`]), and relative step of the central difference in a
/// level. The simulation is smooth in θ only down to its rounding and the bisection of its
/// switching instants, about 1e-12 of the response; divided by a step of 1e-6 that noise was
/// 2e-6 of a column, information enough on records weighted at the noise floor (an exact
/// angle) to pin the voltage scale the levels' priors alone determine (R ±0.01 %, truth 0.06 %
/// off). At 1e-4 the noise is a hundredth of that and the truncation error of the central
/// difference, `h²/6` of the third derivative, 2e-9.
pub(crate) const INTERVAL_FD_STEP: f64 = 1e-4;

/// Fraction of the start's own RK4 step used for the whole fit (room for faster parameters).
pub(crate) const STEP_MARGIN: f64 = 0.5;

/// Most RK4 steps per record sample a simulation may take on average over the records (a time
/// constant 2.5 times below the sample period: 1/40 of it per step, with [`STEP_MARGIN`]);
/// faster time constants are outside what the records show.
// A record sampled fifty times slower than τe took minutes a fit at 1000 steps a sample, for
// an L that its current, settled at every sample, cannot show.
pub(crate) const MAX_STEPS_PER_SAMPLE: f64 = 200.0;

/// Speed bound of the simulations over the largest measured |speed| (room for the fitted
/// motor to run faster than the records while the step stays fixed).
pub(crate) const SPEED_BOUND_MARGIN: f64 = 1.5;

/// Share of the records' noise floor the integration error an effect causes at speed (the
/// cogging ripple) may reach ([`Simulator::with_speed_bound_and_tolerance`]).
pub(crate) const SPEED_ERROR_SHARE: f64 = 0.01;

/// Mean run of equal readings, in rows, beyond which [`OeProblem`]'s series layout takes no
/// longer lag windows for the fitted residuals' correction.
pub(crate) const MAX_LAG_RUN_LENGTH: f64 = 8.0;

/// A channel of one record: its data at the kept samples and its weight.
pub(crate) struct OeChannel {
    pub(crate) kind: Channel,
    /// Indices of the samples fitted.
    pub(crate) keep: Vec<usize>,
    /// Measured values at `keep`.
    pub(crate) data: Vec<f64>,
    pub(crate) sigma: f64,
    /// The smallest `sigma` may become ([`crate::estimation::records::noise_floor`] of `data`).
    pub(crate) floor: f64,
    /// One ADC step \[unit\] of a channel read without noise
    /// ([`crate::excitation::input_uncertainty::noise_free_quantum`]); `None` for a noisy or unquantised
    /// channel and for an encoder's speed (its errors are the encoder's, not an ADC's).
    pub(crate) noise_free_quantum: Option<f64>,
    /// Runs `[from, to)` of `data` (a quantised current's) over which the current has settled
    /// at one level, each with the index of its offset in [`OeProblem::current_offsets`].
    pub(crate) settled: Vec<(usize, usize, usize)>,
}

/// The common quantisation offset of a settled current: its value \[A\] (a nuisance input,
/// 0 a priori) and prior variance \[A²\].
#[derive(Debug, Clone, Copy)]
pub(crate) struct CurrentOffset {
    pub(crate) value: f64,
    pub(crate) variance: f64,
    /// ADC step \[A\] and the code the settled readings' mean rounds to: runs that read alike
    /// share one offset.
    pub(crate) key: (u64, i64),
}

pub(crate) struct OeRecord {
    pub(crate) input: Input,
    /// Per level of a piecewise input: its value and start as estimated, and their uncertainty.
    pub(crate) priors: Vec<(f64, f64, LevelPrior)>,
    pub(crate) dt: f64,
    pub(crate) n: usize,
    pub(crate) channels: Vec<OeChannel>,
    /// How its simulation starts.
    pub(crate) initial: InitialState,
    /// Index in θ of its free initial current (the speed follows), for [`InitialState::Free`].
    pub(crate) free_at: Option<usize>,
}

pub(crate) struct OeProblem {
    /// How θ maps to the motor and the effects simulated with it.
    pub(crate) parameters: Parameters,
    pub(crate) records: Vec<OeRecord>,
    pub(crate) n_residuals: usize,
    /// RK4 step \[s\] of every simulation (bits of an `f64`): fixed within an iteration of the
    /// solver — set at each Jacobian from the parameters there, so that the base simulation,
    /// its perturbations and the trial steps that follow share one discretisation — and
    /// following the parameters from one iteration to the next (a start with a tiny L would
    /// otherwise keep a tiny step, and a slow fit, to the end).
    pub(crate) max_step_bits: AtomicU64,
    /// Largest |speed| \[rad/s\] the simulations take their state-dependent steps (cogging)
    /// at: [`SPEED_BOUND_MARGIN`] times the largest measured, so that the step count does not
    /// follow the simulated speed ([`Simulator::with_speed_bound`]); `None` without a speed
    /// channel.
    pub(crate) speed_bound: Option<f64>,
    /// The smallest noise floor \[A\] and \[rad/s\] of the records' current and speed
    /// channels, from their own scatter ([`noise_std`]): the integration error at speed is
    /// held to [`SPEED_ERROR_SHARE`] of it.
    pub(crate) noise_floor: (f64, f64),
    /// RK4 steps this many times the simulator's default ([`Simulator::with_step_factor`]; 1
    /// for every fit but the diagnosis's).
    pub(crate) step_factor: f64,
    /// Whether the channels' noise levels were given ([`OeProblem::set_sigmas`]) and are
    /// kept: the fit is then one stage in those weights, not reweighted by its own residuals
    /// ([`crate::estimation::weighted::WeightedProblem::reweights`]).
    pub(crate) fixed_sigmas: bool,
    /// Offsets of the settled runs of quantised currents ([`settle_currents`]).
    pub(crate) current_offsets: Vec<CurrentOffset>,
}

impl OeProblem {
    /// The problem of `records` (checked) for the motor and `effects`, simulated with RK4
    /// steps of at most `max_step_s`.
    pub(crate) fn new(
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
    pub(crate) fn set_sigmas(&mut self, sigmas: &[(usize, Channel, f64)]) {
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
    pub(crate) fn set_initial_states(
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
    pub(crate) fn with_state_guesses(&self, mut named: Vec<f64>) -> Vec<f64> {
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
    pub(crate) fn start_of(
        rec: &OeRecord,
        motor: &MotorParams,
        theta: &[f64],
    ) -> Option<(f64, f64)> {
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
    pub(crate) fn fitted_initial_states(&self, theta: &[f64]) -> Vec<FittedInitialState> {
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
    pub(crate) fn max_step_s(&self) -> f64 {
        f64::from_bits(self.max_step_bits.load(Ordering::Relaxed))
    }

    /// A simulator of `motor` and `effects` driven by `input`, with the speed bound.
    pub(crate) fn simulator(
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
    pub(crate) fn speed_tolerance(&self, motor: &MotorParams) -> Option<f64> {
        let (current_a, speed_rad_s) = self.noise_floor;
        let via_current = current_a * motor.r_ohm / motor.k_nm_per_a;
        let tol = SPEED_ERROR_SHARE * speed_rad_s.min(via_current);
        (tol > 0.0 && tol.is_finite()).then_some(tol)
    }

    /// The RK4 step \[s\] for `motor` and `effects`: the simulator's own (1/40 of the fastest
    /// time constant, and the cogging step at the speed bound that keeps the ripple's error
    /// within [`OeProblem::speed_tolerance`]) with a margin.
    pub(crate) fn step_for(&self, motor: &MotorParams, effects: &Effects) -> Option<f64> {
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
    pub(crate) fn set_step_for(&self, motor: &MotorParams, effects: &Effects) -> Option<()> {
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
    pub(crate) fn within_work_bound(&self, motor: &MotorParams, effects: &Effects) -> Option<f64> {
        let h = self.step_for(motor, effects)?;
        let (steps, samples) = self.records.iter().fold((0.0, 0.0), |(steps, samples), r| {
            let n = r.n as f64;
            (steps + n * (r.dt / h).ceil().max(1.0), samples + n)
        });
        (steps <= MAX_STEPS_PER_SAMPLE * samples).then_some(h)
    }

    /// The simulated channels of every record at `theta`: `[record][channel][kept sample]`.
    pub(crate) fn simulate(&self, theta: &[f64]) -> Option<Vec<Vec<Vec<f64>>>> {
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
    pub(crate) fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
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
    pub(crate) fn jacobian(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
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
    pub(crate) fn jacobian_for_intervals(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let (motor, effects) = self.parameters.decode(theta)?;
        self.set_step_for(&motor, &effects)?;
        let all: Vec<usize> = (0..self.parameters.len()).collect();
        self.jacobian_columns(theta, &all, true)
    }

    /// Residuals at `theta` and the columns `which` of their Jacobian in θ (forward
    /// differences, or central ones with `central`; the perturbed simulations run in parallel
    /// on rayon's pool, so that a fit already running on that pool shares its threads), on the
    /// RK4 step in use.
    pub(crate) fn jacobian_columns(
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

/// Relative step of the central difference in a level ([`INTERVAL_FD_STEP`]'s reasons).
pub(crate) const LEVEL_DIFF_STEP: f64 = INTERVAL_FD_STEP;

/// Step of the central difference in a level's start, as a fraction of the sample period.
pub(crate) const START_DIFF_STEP: f64 = 1e-2;

impl OeProblem {
    /// `(record, level, 0: value / 1: start)` of every uncertain input, then `(0, g, 2)` for
    /// each settled-current offset `g`.
    pub(crate) fn nuisance_slots(&self) -> Vec<(usize, usize, usize)> {
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
    /// ([`crate::excitation::input_uncertainty::grid_phase_score_covariance`]).
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

/// Checks record `k` (0-based): aligned, finite channels of enough samples, a positive period.
pub(crate) fn check_record(k: usize, rec: &ExcitedRecord<'_>) -> Result<(), FitError> {
    let label = format!("record {}", k + 1);
    crate::estimation::checks::check_channels(&label, rec.channels())?;
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
/// `crate::excitation::input_uncertainty::settled_current`): a current that settles within a few ADC steps
/// reads the same few codes for the rest of the level, its quantisation error a constant the
/// parameters absorb (into f and Ts) and the residuals cannot show, so it enters the intervals
/// as an input. Runs whose readings average to the same code of the same ADC step share one
/// offset — a level a PRBS or staircase comes back to reads alike each time — and so do not
/// average out. A current read without noise gets none: its quantiser enters the intervals
/// whole ([`grid_phase_score_covariance`]). Levels are the piecewise input's, or the step's.
pub(crate) fn settle_currents(records: &mut [OeRecord]) -> Vec<CurrentOffset> {
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
pub(crate) fn prepare(k: usize, rec: &ExcitedRecord<'_>) -> Result<OeRecord, FitError> {
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
