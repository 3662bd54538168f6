//! One stage of the diagnosis on top of a base model: every candidate screened, the best
//! refitted from their starts, and the verdict's ranking of the refits on held-out data.

use motor_model::{
    BrushDrop, CoggingTorque, Effect, EffectKind, Effects, MotorParams, QuadraticDrag,
    StribeckFriction,
};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::diagnose::base::Base;
use crate::diagnose::heldout::{
    block_sse, channel_nrmse, nrmse_summary, train_fall, train_statistic,
};
use crate::diagnose::jumps::{located_inputs, with_inputs, with_jump_columns};
use crate::diagnose::localise::Localisation;
use crate::diagnose::nominal::{determined, diagnosable, UNEXPLAINED_CHANNEL};
use crate::diagnose::report::{
    Assessment, CandidateReport, DiagnoseProgress, DiagnoseSettings, EffectParam, ParamShift, Stage,
};
use crate::diagnose::screen::{BaseProjection, Screening};
use crate::diagnose::starts::{
    absorbed_start, candidate_start, candidate_starts, cogging_screened, shapes_searched,
    stribeck_within_records, weighted_difference, EFFECT_PART_MIN,
};
use crate::diagnose::verdict::{rank_candidates, training_support, CandidateScore};
use crate::error::{FitError, START_SERIES};
use crate::estimation::fitted::FullFit;
use crate::estimation::parameters::EffectEstimate;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel, PARAM_NAMES};
use crate::excitation::output_error::{
    fit_output_error, output_error_sensitivity, predict_with_step_factor,
};

/// A candidate's report, its held-out block errors and its training likelihood-ratio
/// statistic (empty and `None` when it was not refitted, or its refit failed).
pub(crate) type Refit = (CandidateReport, Vec<f64>, Option<f64>);

/// A candidate's [`Refit`] as [`rank_candidates`] scores it, against the held-out blocks'
/// squared errors before (`sse_before`); `searched` as [`CandidateScore::searched`].
pub(crate) fn refit_score<'a>(
    (report, sse, statistic): &'a Refit,
    searched: usize,
    sse_before: &'a [f64],
) -> CandidateScore<'a> {
    CandidateScore {
        name: report.name,
        extra_params: report.params.len(),
        testable: report.testable,
        train_statistic: *statistic,
        searched,
        heldout_sse_before: sse_before,
        heldout_sse_after: sse,
    }
}

/// The screening of `kinds` on top of `base` (see [`crate::diagnose::screen`]), in their
/// order, each with the start its refit begins from (of [`candidate_starts`], the testable one
/// of largest statistic): `None` for a candidate whose signature could not be simulated, and
/// for every one when the base model cannot be linearised (those are refitted unscreened, from
/// [`candidate_start`]).
pub(crate) fn screen_stage(
    kinds: &[EffectKind],
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    localisation: &Localisation,
    settings: &DiagnoseSettings,
) -> Vec<(Option<Screening>, RefitStart)> {
    let factor = settings.step_factor;
    let projection =
        output_error_sensitivity(base.train, &base.motor, &base.effects, sigmas, None, factor)
            .ok()
            .and_then(|lin| {
                let jacobian =
                    with_jump_columns(lin.jacobian.clone(), &lin.residuals, base, sigmas, factor);
                BaseProjection::new(&lin.residuals, &jacobian, &lin.series)
            });
    let Some(projection) = projection else {
        return kinds
            .iter()
            .map(|&kind| {
                (
                    None,
                    RefitStart::plain(candidate_start(kind, &base.motor, base.train, localisation)),
                )
            })
            .collect();
    };
    let cogging = if kinds.contains(&EffectKind::CoggingTorque) {
        cogging_screened(base, sigmas, &projection, localisation, settings)
    } else {
        Vec::new()
    };
    // Every candidate's starts at once on rayon's pool (a kind of one start alone would
    // leave a core idle).
    kinds
        .par_iter()
        .map(|&kind| {
            let starts = candidate_starts(kind, &base.motor, base.train, localisation, &cogging);
            let scored: Vec<(Option<Screening>, RefitStart)> = starts
                .par_iter()
                .map(|&effect| {
                    let effects = base.effects.with(effect);
                    let sig = output_error_sensitivity(
                        base.train,
                        &base.motor,
                        &effects,
                        sigmas,
                        Some(kind),
                        factor,
                    )
                    .ok();
                    let start = RefitStart {
                        stepped: sig.as_ref().map_or(effect, |sig| {
                            stepped_start(effect, base.motor.ts_nm, &sig.jacobian, &projection)
                        }),
                        plain: effect,
                    };
                    let score = sig.map(|sig| {
                        let score = projection.score(&sig.jacobian);
                        if asks_for_negative_size(kind, &sig.jacobian, &projection) {
                            Screening {
                                statistic: 0.0,
                                p_value: 1.0,
                                ..score
                            }
                        } else {
                            score
                        }
                    });
                    (score, start)
                })
                .collect();
            // The first start unless another is testable with a larger statistic.
            let rank = |x: &Option<Screening>| {
                x.filter(|s| s.testable)
                    .map_or(f64::NEG_INFINITY, |s| s.statistic)
            };
            let (score, start) = scored
                .iter()
                .copied()
                .reduce(|best, next| {
                    if rank(&next.0) > rank(&best.0) {
                        next
                    } else {
                        best
                    }
                })
                .unwrap_or((None, RefitStart::plain(starts[0])));
            // A fixed shape picked as the best of several (a cogging torque's period count)
            // has its screening p-value multiplied by their number (Bonferroni), so that the
            // best of the noise does not take a refit from an effect present.
            let searched = shapes_searched(kind, localisation, &settings.localise, base.train);
            let score = score.map(|s| Screening {
                p_value: (s.p_value * searched as f64).min(1.0),
                ..s
            });
            (score, start)
        })
        .collect()
}

/// Where a candidate's refit begins: the screening's linear step from a start of
/// [`candidate_starts`] ([`stepped_start`]), and that start itself, which the refit falls
/// back to when the step lands where the records' sample rate cannot simulate (a brush drop
/// grown a hundredfold puts a resistance `Vb/I_knee` in series that makes `L/R` far shorter
/// than a sample period).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RefitStart {
    /// The stepped start.
    pub(crate) stepped: Effect,
    /// The start before the step.
    pub(crate) plain: Effect,
}

impl RefitStart {
    /// A start without a step.
    fn plain(effect: Effect) -> Self {
        RefitStart {
            stepped: effect,
            plain: effect,
        }
    }
}

/// Whether the residual asks `kind`, an effect of one parameter whose response is
/// proportional to it at small sizes (a sensor lag's `τf`, a drag's `c`, a brush drop's `Vb`),
/// for a size below zero: the screening's linear step from zero size ([`BaseProjection::step`]
/// of its signature) is negative. No size of such an effect explains that residual (a current
/// read *ahead* of the model is no lag, a drag that pushes is no drag), so its screening is
/// one-sided: statistic 0, and the refit goes to a candidate that could explain the residual.
pub(crate) fn asks_for_negative_size(
    kind: EffectKind,
    signatures: &DMatrix<f64>,
    projection: &BaseProjection,
) -> bool {
    let one_sided = matches!(
        kind,
        EffectKind::CurrentSensorLag | EffectKind::QuadraticDrag | EffectKind::BrushDrop
    );
    one_sided
        && signatures.ncols() == 1
        && size_step(signatures, projection).is_some_and(|d| d < 0.0)
}

/// The screening's linear step ([`BaseProjection::step`]) of an effect's first parameter, its
/// size, on that parameter's signature column alone; `None` without columns or when that
/// column is not testable.
pub(crate) fn size_step(signatures: &DMatrix<f64>, projection: &BaseProjection) -> Option<f64> {
    if signatures.ncols() == 0 {
        return None;
    }
    projection
        .step(&signatures.columns(0, 1).into_owned())
        .map(|step| step[0])
}

/// Largest factor by which [`stepped_start`] grows or shrinks an effect's size \[-\]: the
/// linear step of a size far from the start's is a guide, not a value.
pub(crate) const SIZE_STEP_LIMIT: f64 = 1e3;

/// The refit start of `effect` moved by the screening's Gauss–Newton step
/// ([`BaseProjection::step`], in the fit's coordinates of its parameters, from `signatures`,
/// their Jacobian columns at the start) where the step is exact in the effect's signature
/// space, which its response spans to first order in its size:
/// - a cogging torque `A sin(Nθ + φ)`, `θ = (ln A, φ)`: its columns `A s(φ)` and `A c(φ)`
///   span the ripple at every phase, so the stepped signature `A (1 + δ₁) s + A δ₂ c` is the
///   ripple `A' sin(Nθ + φ + ψ)` with `A' = A hypot(1 + δ₁, δ₂)` and `ψ = atan2(δ₂, 1 + δ₁)`.
///   A refit from the start's phase collapses to `A → 0` when the ripple present is more
///   than a quarter period away (its first steps shrink `A` before they turn φ);
/// - an effect whose load or drop is proportional to its first parameter (the drag's `c`,
///   the brush drop's `Vb`, the Stribeck excess `Tst − Ts`), `θ₁` its logarithm: the step
///   of that column alone gives the size `v (1 + δ)` the residual asks for (kept when `1 + δ`
///   is not positive: the residual asks for the opposite sign), within a factor
///   [`SIZE_STEP_LIMIT`]. The fit's own first step moves `ln v` by `δ`, which overshoots
///   `e^δ/(1 + δ)` times, and is refused and damped over several iterations.
///
/// Other effects keep their start.
pub(crate) fn stepped_start(
    effect: Effect,
    motor_ts: f64,
    signatures: &DMatrix<f64>,
    projection: &BaseProjection,
) -> Effect {
    let grow = |delta: f64| -> Option<f64> {
        let m = 1.0 + delta;
        (m.is_finite() && m > 0.0).then(|| m.clamp(1.0 / SIZE_STEP_LIMIT, SIZE_STEP_LIMIT))
    };
    let size_factor = || size_step(signatures, projection).and_then(grow);
    match effect {
        Effect::CoggingTorque(c) => {
            let Some(step) = projection.step(signatures) else {
                return effect;
            };
            let &[d_ln_a, d_phase] = step.as_slice() else {
                return effect;
            };
            let (along, across) = (1.0 + d_ln_a, d_phase);
            let gain = along.hypot(across);
            if gain > 0.0 && gain.is_finite() {
                Effect::CoggingTorque(CoggingTorque {
                    amplitude_nm: c.amplitude_nm * gain.min(SIZE_STEP_LIMIT),
                    phase_rad: (c.phase_rad + across.atan2(along))
                        .rem_euclid(std::f64::consts::TAU),
                    ..c
                })
            } else {
                effect
            }
        }
        Effect::QuadraticDrag(d) => size_factor().map_or(effect, |m| {
            Effect::QuadraticDrag(QuadraticDrag {
                c_nms2_per_rad2: d.c_nms2_per_rad2 * m,
            })
        }),
        Effect::StribeckFriction(f) if f.static_torque_nm > motor_ts => {
            size_factor().map_or(effect, |m| {
                Effect::StribeckFriction(StribeckFriction {
                    static_torque_nm: motor_ts + (f.static_torque_nm - motor_ts) * m,
                    ..f
                })
            })
        }
        Effect::BrushDrop(b) => size_factor().map_or(effect, |m| {
            Effect::BrushDrop(BrushDrop {
                drop_v: b.drop_v * m,
                ..b
            })
        }),
        _ => effect,
    }
}

/// One stage: every candidate screened, the best [`DiagnoseSettings::refits`] refitted on top
/// of `base` (in parallel), then ranked.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_stage(
    stage_no: usize,
    kinds: &[EffectKind],
    base: &Base<'_>,
    held: &[Vec<bool>],
    sigmas: &[(usize, Channel, f64)],
    localisation: &Localisation,
    settings: &DiagnoseSettings,
    progress: &(dyn Fn(DiagnoseProgress) + Sync),
) -> Stage {
    let block = settings.block_samples.max(1);
    let train_mask = |ch: &FittedChannel, i: usize| !held.get(ch.record).is_some_and(|h| h[i]);
    let held_mask = |ch: &FittedChannel, i: usize| held.get(ch.record).is_some_and(|h| h[i]);
    let train_before = nrmse_summary(&base.fitted, train_mask);
    let heldout_before = nrmse_summary(&base.fitted, held_mask);
    let sse_before = block_sse(&base.fitted, sigmas, held, block);
    progress(DiagnoseProgress::Screening { stage: stage_no });
    let (screens, starts): (Vec<Option<Screening>>, Vec<RefitStart>) =
        screen_stage(kinds, base, sigmas, localisation, settings)
            .into_iter()
            .unzip();
    // The level each candidate is judged at: α over every candidate the records can test
    // (the screened-out ones included: the screening looked at the same data).
    let family = screens
        .iter()
        .filter(|x| x.is_none_or(|s| s.testable))
        .count()
        .max(1);
    let level = settings.verdict.alpha / family as f64;
    // The candidates refitted: the best testable ones by their penalised score whose score
    // passes the screening level, and any the screening could not score.
    let penalty = settings.verdict.penalty_per_param;
    let searched: Vec<usize> = kinds
        .iter()
        .map(|&kind| shapes_searched(kind, localisation, &settings.localise, base.train))
        .collect();
    let mut passed: Vec<usize> = (0..kinds.len())
        .filter(|&k| screens[k].is_some_and(|s| s.testable && s.p_value < settings.screening_alpha))
        .collect();
    // A shape picked as the best of `s` (a cogging torque's period count) also pays `2 ln s`,
    // the Bonferroni factor on its p-value as a statistic of two degrees of freedom: the best
    // of many period counts scores above a single one's χ² on noise alone, and would take a
    // refit from the effect present.
    let promise = |k: usize| {
        screens[k].map_or(f64::NEG_INFINITY, |s| {
            s.penalised(penalty) - 2.0 * (searched[k] as f64).ln()
        })
    };
    passed.sort_by(|a, b| promise(*b).total_cmp(&promise(*a)));
    let per_round = settings.refits.max(1);
    passed.truncate(per_round * settings.refit_rounds.max(1));
    // The first round: the best `refits` by score, and any the screening could not score.
    let mut refit_set: Vec<usize> = (0..kinds.len())
        .filter(|&k| screens[k].is_none() || passed[..passed.len().min(per_round)].contains(&k))
        .collect();
    refit_set.sort_unstable();
    let screen_of = |k: usize| screens[k];
    // The report of a candidate not refitted, or whose refit failed.
    let unfitted =
        |k: usize, effects: Effects, assessment: Assessment, why: Option<String>| CandidateReport {
            name: kinds[k].name(),
            assessment,
            testable: assessment != Assessment::NotTestable,
            significant: false,
            screening: screen_of(k),
            p_value: 1.0,
            heldout_p_value: 1.0,
            params: Vec::new(),
            train_nrmse_before: train_before,
            train_nrmse_after: f64::NAN,
            heldout_nrmse_before: heldout_before,
            heldout_nrmse_after: f64::NAN,
            motor_shift: Vec::new(),
            motor: None,
            effects,
            failure: why,
            inputs: Vec::new(),
            fitted: Vec::new(),
        };
    // Without the evidence of a refit, the screening score speaks: no evidence below the
    // level, evidence the refit could not resolve above it.
    let by_score = |k: usize, otherwise: Assessment| match screen_of(k) {
        Some(s) if !s.testable => Assessment::NotTestable,
        Some(s) if s.p_value >= level => Assessment::NoEvidence,
        _ => otherwise,
    };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = std::sync::atomic::AtomicUsize::new(refit_set.len());
    progress(DiagnoseProgress::Candidates {
        stage: stage_no,
        done: 0,
        total: refit_set.len(),
    });
    // A refit worse than a constant on training channels the base model explains no better
    // ([`UNEXPLAINED_CHANNEL`]: a low step's encoder speed that is mostly its counts) has not
    // found a wrong minimum there: when every channel it is refused for is one of those and
    // nothing else refuses it (motor, intervals, effect), the tests judge it as any other.
    let base_as_bad = |fit: &FullFit, kind: EffectKind| {
        let unexplained = |q: &crate::ChannelQuality| {
            let before = base
                .fitted
                .iter()
                .find(|ch| ch.record == q.test && ch.channel == q.channel)
                .and_then(|ch| channel_nrmse(ch, train_mask))
                .map_or(f64::NAN, |(nrmse, _)| nrmse);
            let after = 1.0 - q.nrmse_fit_percent / 100.0;
            before >= UNEXPLAINED_CHANNEL && after <= before + (1.0 - UNEXPLAINED_CHANNEL)
        };
        matches!(fit.refusal, Some(crate::Refusal::WorseThanConstant { .. }))
            && fit
                .quality
                .iter()
                .filter(|q| q.nrmse_fit_percent < 0.0)
                .all(unexplained)
            && fit
                .refusal_beside_channels
                .as_ref()
                .is_none_or(|r| diagnosable(r, Some(kind)))
    };
    let refit = |k: usize| -> Refit {
        let kind = kinds[k];
        // In the weights the base model was fitted and every candidate is judged in (the
        // nominal fit's channel levels): a refit reweighted by its own residuals would
        // minimise another cost than the one its likelihood-ratio test and held-out blocks
        // measure, and could trade a channel the effect does not touch for one it does.
        let fit_on = |train: &[ExcitedRecord<'_>], motor: &MotorParams, start: Effect| {
            fit_output_error(
                train,
                &[],
                &[],
                motor,
                &base.effects.with(start),
                settings.lm,
                settings.step_factor,
                Some(sigmas),
            )
        };
        let accept = |fit: FullFit| match (&fit.refusal, fit.failure()) {
            (_, None) => Ok(fit),
            (Some(r), Some(_))
                if fit.termination.converged()
                    && (diagnosable(r, Some(kind)) || base_as_bad(&fit, kind)) =>
            {
                Ok(fit)
            }
            (_, Some(why)) => Err(why),
        };
        // The refit's prediction with every jump located beside the refitted model, as the
        // base model's are beside it: each model is judged at its own best instants.
        // With the effect's own part of that prediction, in noise variances.
        let judged = |fit: FullFit| {
            let inputs = located_inputs(
                base.grid,
                0..base.grid.len(),
                &fit.params,
                &fit.effects,
                sigmas,
                settings,
            );
            let all = with_inputs(base.all, &inputs);
            let predict = |effects: &Effects| {
                predict_with_step_factor(&all, &fit.params, effects, settings.step_factor)
                    .map_err(|e| e.to_string())
            };
            let pred = predict(&fit.effects)?;
            let part = weighted_difference(&pred, &predict(&fit.effects.without(kind))?, sigmas);
            drop(all);
            Ok((fit, pred, inputs, part))
        };
        let RefitStart { stepped, plain } = starts[k];
        let refit_from = |start: Effect| {
            fit_on(base.train, &base.motor, start)
                .map_err(|e| e.to_string())
                .and_then(accept)
                .and_then(judged)
        };
        // Whether the plain start has been fitted already (the stepped one cannot be, or is it).
        let (outcome, plain_tried) = match fit_on(base.train, &base.motor, stepped) {
            Err(FitError::BadData { series, .. }) if series == START_SERIES && stepped != plain => {
                (fit_on(base.train, &base.motor, plain), true)
            }
            other => (other, stepped == plain),
        };
        let outcome = outcome.map_err(|e| e.to_string()).and_then(accept);
        // An effect the base fit absorbed into a motor parameter (a sensor lag into L, its
        // jumps placed late to match a current rising at once; a saturation into a mean L; a
        // heating winding into a mean R) is a saddle there: the effect grown alone only adds
        // to what the parameter does. It is also refitted from a start that splits the two,
        // on the jumps located beside that start, and the lower cost kept.
        // A Stribeck friction refitted to a speed the records visit has split its levels
        // already: the split start is for one whose Ωs ran off to 0 or infinity.
        let split_needed = match (&outcome, kind) {
            (Ok(fit), EffectKind::StribeckFriction) => !stribeck_within_records(fit, base.train),
            _ => true,
        };
        let absorbed = split_needed
            .then(|| absorbed_start(kind, plain, &base.motor, base.train))
            .flatten();
        let outcome = match absorbed {
            Some((motor, start)) => {
                // The training records' alone: the split start's refit is made on them.
                let inputs = located_inputs(
                    base.grid,
                    0..base.train.len(),
                    &motor,
                    &base.effects.with(start),
                    sigmas,
                    settings,
                );
                let train = with_inputs(base.train, &inputs);
                let split = fit_on(&train, &motor, start)
                    .map_err(|e| e.to_string())
                    .and_then(accept);
                match (outcome, split) {
                    (Ok(a), Ok(b)) => Ok(if b.cost < a.cost { b } else { a }),
                    (Err(_), Ok(b)) => Ok(b),
                    (a, Err(_)) => a,
                }
            }
            None => outcome,
        }
        .and_then(judged);
        // A refit from the stepped start that fails, or ends above the base model's training
        // error (in a worse minimum than the one beside which it started), is retried from
        // the plain start, and the larger fall kept.
        let fall = |pred: &[FittedChannel]| {
            train_fall(&base.fitted, pred, sigmas, held).map_or(f64::NEG_INFINITY, |f| f.0)
        };
        let outcome = match outcome {
            Ok(first) if !plain_tried && fall(&first.1) < 0.0 => match refit_from(plain) {
                Ok(second) if fall(&second.1) > fall(&first.1) => Ok(second),
                _ => Ok(first),
            },
            Err(why) if !plain_tried => refit_from(plain).map_err(|_| why),
            other => other,
        };
        let report = match outcome {
            Ok((fit, pred, inputs, part)) => {
                let own: Vec<EffectEstimate> = fit
                    .effect_estimates
                    .iter()
                    .filter(|e| e.effect == kind)
                    .cloned()
                    .collect();
                let sse = block_sse(&pred, sigmas, held, block);
                // An effect whose own part of the prediction is below a noise variance (its
                // size gone to zero) gives no statistic: the fall is the motor's refit alone.
                let statistic = (part >= EFFECT_PART_MIN)
                    .then(|| train_statistic(&base.fitted, &pred, sigmas, held))
                    .flatten();
                let motor_shift = PARAM_NAMES
                    .iter()
                    .zip(base.motor.values())
                    .zip(fit.params.values())
                    .map(|((name, b), a)| ParamShift {
                        name,
                        before: b,
                        after: a,
                        relative: a / b - 1.0,
                    })
                    .collect();
                // A refit that leaves the effect's parameters undetermined cannot name it:
                // the screening score says whether that is for want of the effect.
                let assessment = if determined(&own) {
                    Assessment::NoEvidence
                } else {
                    by_score(k, Assessment::Unresolved)
                };
                (
                    CandidateReport {
                        params: own
                            .iter()
                            .map(|e| EffectParam {
                                symbol: e.symbol,
                                key: e.key,
                                unit: e.unit,
                                value: e.value,
                                ci95: e.ci95,
                            })
                            .collect(),
                        train_nrmse_after: nrmse_summary(&pred, train_mask),
                        heldout_nrmse_after: nrmse_summary(&pred, held_mask),
                        motor_shift,
                        motor: Some(fit.params),
                        inputs,
                        fitted: pred.clone(),
                        ..unfitted(k, fit.effects, assessment, None)
                    },
                    sse,
                    statistic,
                )
            }
            Err(why) => (
                unfitted(
                    k,
                    base.effects.with(starts[k].stepped),
                    by_score(k, Assessment::Unresolved),
                    Some(why),
                ),
                Vec::new(),
                None,
            ),
        };
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(DiagnoseProgress::Candidates {
            stage: stage_no,
            done: d,
            total: total.load(std::sync::atomic::Ordering::Relaxed),
        });
        report
    };
    // The refits in parallel on rayon's pool, which the output-error Jacobians inside them
    // share (one thread per core, no threads started within threads); one after the other
    // with `threads` ≤ 1. A refit that panics is reported as stopped, not propagated.
    let guarded = |k: usize| -> (usize, Refit) {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| refit(k)))
            .unwrap_or_else(|_| {
                (
                    unfitted(
                        k,
                        base.effects,
                        by_score(k, Assessment::Unresolved),
                        Some("the refit stopped unexpectedly".into()),
                    ),
                    Vec::new(),
                    None,
                )
            });
        (k, result)
    };
    let run_round = |set: &[usize]| -> Vec<(usize, Refit)> {
        if settings.threads > 1 {
            set.par_iter().map(|&k| guarded(k)).collect()
        } else {
            set.iter().map(|&k| guarded(k)).collect()
        }
    };
    let mut refitted: Vec<(usize, Refit)> = run_round(&refit_set);
    // Further rounds while a refit of the last one could not be judged (it stopped, or left
    // the effect's size undetermined although its screening score passed): the next passed
    // candidates by score take their place, so that a refit that fails from its start does
    // not hide an effect that scored a little lower.
    let mut next = per_round.min(passed.len());
    loop {
        let unjudged = refitted
            .iter()
            .filter(|(_, (c, _, _))| c.motor.is_none() || c.assessment == Assessment::Unresolved)
            .count();
        let judged = refitted.len() - unjudged;
        if judged >= per_round || next >= passed.len() || unjudged == 0 {
            break;
        }
        let take = (per_round - judged).min(passed.len() - next);
        let round: Vec<usize> = passed[next..next + take].to_vec();
        next += take;
        total.fetch_add(round.len(), std::sync::atomic::Ordering::Relaxed);
        refitted.extend(run_round(&round));
    }
    // Then, one at a time, a passed candidate not yet refitted whose screening score promises
    // more than the training data support the verdict of the refits so far (its penalised
    // likelihood ratio, the same χ² units): the linearised score ranks the candidates, and
    // once a refit shows what the top one delivers, one promising more may explain the gap
    // better (an exact drag screened below a Stribeck friction that, refitted, explained
    // less: benchmark case 83). Bounded by the refits the rounds allow.
    let bound = per_round * settings.refit_rounds.max(1);
    while refitted.len() < bound && next < passed.len() {
        // Every candidate, as the final ranking sees it (the same level `α / m`): those not
        // refitted without a statistic or held-out blocks, which names none of them.
        let scores: Vec<CandidateScore<'_>> = (0..kinds.len())
            .map(|k| match refitted.iter().find(|(j, _)| *j == k) {
                Some((_, r)) => refit_score(r, searched[k], &sse_before),
                None => CandidateScore {
                    name: kinds[k].name(),
                    extra_params: 0,
                    testable: screens[k].is_none_or(|s| s.testable),
                    train_statistic: None,
                    searched: searched[k],
                    heldout_sse_before: &sse_before,
                    heldout_sse_after: &[],
                },
            })
            .collect();
        let verdict = rank_candidates(&scores, &settings.verdict);
        let Some(delivered) = verdict.verdict.as_deref().and_then(|name| {
            scores
                .iter()
                .find(|c| c.name == name)
                .map(|c| training_support(c, penalty))
        }) else {
            break;
        };
        let k = passed[next];
        let promised = promise(k);
        if refitted.iter().any(|(j, _)| *j == k) {
            next += 1;
            continue;
        }
        if promised <= delivered {
            break;
        }
        next += 1;
        total.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        refitted.extend(run_round(&[k]));
    }
    // Every candidate in the order given: refitted, or reported with its screening score.
    let results: Vec<Refit> = (0..kinds.len())
        .map(|k| match refitted.iter().position(|(j, _)| *j == k) {
            Some(at) => refitted.swap_remove(at).1,
            None => (
                unfitted(
                    k,
                    base.effects.with(starts[k].stepped),
                    by_score(k, Assessment::ScreenedOut),
                    None,
                ),
                Vec::new(),
                None,
            ),
        })
        .collect();
    let scores: Vec<CandidateScore<'_>> = results
        .iter()
        .zip(&searched)
        .map(|(r, &searched)| refit_score(r, searched, &sse_before))
        .collect();
    let verdict = rank_candidates(&scores, &settings.verdict);
    let mut candidates: Vec<CandidateReport> = results.into_iter().map(|(c, _, _)| c).collect();
    for c in &mut candidates {
        c.take_rank(&verdict);
    }
    Stage {
        base: base.effects.list().iter().map(Effect::name).collect(),
        candidates,
        verdict,
        fitted_before: base.fitted.clone(),
    }
}
