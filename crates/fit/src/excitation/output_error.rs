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

use std::sync::atomic::Ordering;

use motor_model::{Effects, Input, MotorParams};
use nalgebra::DMatrix;

use crate::error::{FitError, START_SERIES};
use crate::estimation::fitted::FullFit;
use crate::estimation::lm::LmSettings;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel, InitialState};
use crate::estimation::weighted::WeightedProblem;
use crate::excitation::input_uncertainty::{fit_with_inputs, LevelPrior};
use crate::excitation::oe_problem::OeProblem;
use crate::excitation::voltage::bad;

/// The model's channels on every sample of `records` — the samples an exclusion mask leaves out
/// of a fit too — for `motor` with `effects`: what a fit is judged against on data it did not
/// see (held-out records or blocks). Channels as in [`OutputError`]; each
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
        crate::estimation::checks::check_aligned(&format!("record {}", k + 1), r.channels())?;
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
/// coordinates of [`OutputError::effects`]): every column, or with `of` only the
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
            .map(|(j, _)| crate::estimation::parameters::MOTOR + j)
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

/// An output-error identification: R, L, k, f, J, Ts (and the fitted parameters of any
/// effects switched on) from records of any voltage waveform, each simulated from its voltage
/// by the stick-slip simulator and fitted on every channel it measured. One way in, set up by
/// what is known of the records:
///
/// ```no_run
/// # fn demo(records: &[fit::ExcitedRecord<'_>]) -> Result<(), fit::FitError> {
/// let start = fit::equation_error_start(records)?;
/// let fit = fit::OutputError::new(records, start).fit()?;
/// # Ok(()) }
/// ```
///
/// - [`OutputError::effects`]: the motor fitted jointly with a set of effects: one fit of
///   `θ = [ln R, ln L, ln k, ln f, ln J, ln Ts, θ_e…]`, the effects' fitted parameters
///   ([`Effects::fitted_slots`]) each in its unconstrained coordinate
///   ([`motor_model::ParamSpec::to_unconstrained`]; Stribeck's Tst as `ln(Tst − Ts)`), started
///   from the values given. The simulation runs on a fixed RK4 step and (with cogging) a speed
///   bound 1.5 times the largest measured speed, so that it is smooth in θ. The results name
///   every parameter: [`FullFit::effects`], [`FullFit::effect_estimates`] (value, standard
///   error and 95 % interval in SI units by the delta method through each transform),
///   [`FullFit::parameter_names`] for the rows of [`FullFit::correlation`].
/// - [`OutputError::level_priors`]: what each record leaves unknown about its voltage levels
///   (one list per record, from [`voltage_levels`](crate::voltage_levels), a prior per level of
///   its piecewise input): the fit moves the levels and their start instants where the records
///   put them and widens the intervals by what remains unknown (see [`crate::StepInputs`]).
/// - [`OutputError::initial_states`]: record `k`'s simulation started from `initial[k]` (all
///   at rest by default; [`crate::detect_initial_state`] tells which a record shows): at rest,
///   in the steady state of its first level (Eqs. (4), (5) of the motor being fitted; nominal
///   model only), or free (its initial current \[A\] and speed \[rad/s\] fitted with the
///   motor, from its first samples; the motor's intervals are the marginal ones, with that
///   uncertainty in them). [`FullFit::initial_states`] gives each record's state as fitted.
/// - [`OutputError::solver`]: the Levenberg–Marquardt settings.
///
/// [`OutputError::fit`] fits from the start given;
/// [`OutputError::fit_with_friction_restart`] tries once more from another start where the
/// friction vanished.
#[derive(Debug, Clone)]
pub struct OutputError<'a> {
    records: &'a [ExcitedRecord<'a>],
    start: MotorParams,
    priors: &'a [Vec<LevelPrior>],
    initial: &'a [InitialState],
    effects: Effects,
    settings: LmSettings,
}

impl<'a> OutputError<'a> {
    /// The identification of `records` from `start` (e.g. [`equation_error_start`](crate::equation_error_start)):
    /// the nominal motor, every record at rest at its first sample, its voltage levels as
    /// measured, the solver's default settings.
    pub fn new(records: &'a [ExcitedRecord<'a>], start: MotorParams) -> Self {
        OutputError {
            records,
            start,
            priors: &[],
            initial: &[],
            effects: Effects::none(),
            settings: LmSettings::default(),
        }
    }

    /// The motor with `effects` switched on, their fitted parameters started from the values
    /// in `effects`.
    pub fn effects(mut self, effects: Effects) -> Self {
        self.effects = effects;
        self
    }

    /// What each record leaves unknown about its voltage levels: `priors[k]` for record `k`
    /// (or none at all).
    pub fn level_priors(mut self, priors: &'a [Vec<LevelPrior>]) -> Self {
        self.priors = priors;
        self
    }

    /// Each record's initial state: `initial[k]` for record `k` (or none: all at rest).
    pub fn initial_states(mut self, initial: &'a [InitialState]) -> Self {
        self.initial = initial;
        self
    }

    /// The solver's settings.
    pub fn solver(mut self, settings: LmSettings) -> Self {
        self.settings = settings;
        self
    }

    /// The fit from the start given.
    pub fn fit(&self) -> Result<FullFit, FitError> {
        fit_output_error(
            self.records,
            self.priors,
            self.initial,
            &self.start,
            &self.effects,
            self.settings,
            1.0,
            None,
        )
    }

    /// [`OutputError::fit`], tried again from another start where that fit is refused because
    /// a friction parameter went to nothing ([`crate::Refusal::Vanished`]), or so near it that
    /// the records no longer determine it ([`crate::Refusal::Undetermined`] of f or Ts): a
    /// start that splits the friction wrongly between f and Ts can lead the fit into the
    /// minimum without one of them. The equation-error start of a ±12 V PRBS of the small servo
    /// (`fixtures/motors/small_servo.json`, 1 s at 2 kHz through the logger) put f at 2.3 times
    /// its value and Ts at a ninth of it, and the fit drove Ts to 1e-15 N·m on 5 of 6 seeds;
    /// from f halved, or from Ts tenfold, it found the motor. The restart moves the friction
    /// towards the vanished parameter: that parameter ten times its start (at least 1 % and at
    /// most half of its scale: the largest motor torque `k·|I|` of the records for Ts, the
    /// electrical damping `k²/R` for f), the other halved. An accepted fit from there is kept,
    /// else the first fit with its refusal. Returns the start of the fit returned, and the fit;
    /// the restart costs one bounded fit.
    pub fn fit_with_friction_restart(&self) -> Result<(MotorParams, FullFit), FitError> {
        let (records, start) = (self.records, &self.start);
        let first = self.fit()?;
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
        match (OutputError {
            start: restart,
            ..self.clone()
        })
        .fit()
        {
            Ok(fit) if fit.accepted() => Ok((restart, fit)),
            _ => Ok((*start, first)),
        }
    }
}

/// [`OutputError::fit`] on RK4 steps `step_factor` times the
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::voltage::voltage_input;
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
