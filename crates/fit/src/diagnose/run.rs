//! The whole diagnosis: the nominal identification, where its residual stands above the noise,
//! each candidate effect refitted jointly with the motor by output error, the candidates ranked
//! on held-out data, and the same again on top of the chosen effect (a second effect present is
//! named too).
//!
//! **Held-out data.** Every training record is cut into blocks of
//! [`DiagnoseSettings::block_samples`] samples (shorter on a record too short to lend two such
//! blocks) and every [`DiagnoseSettings::holdout_every`]-th block is left out of every fit
//! (its samples excluded, as clipped samples are) and judged on the model's prediction there
//! (the voltage jumps' instants, a nuisance of every model alike, are located on whole
//! records: see below). Records given as validation are held out whole, in addition
//! to those blocks (unless [`DiagnoseSettings::split_with_validation`] is off): an effect the
//! validation records do not excite (a cogging torque averaged out at speed, a Stribeck dip the
//! records never dwell in) is still judged on held-out samples of the records that show it. A
//! physical effect of a few parameters cannot learn the noise of the blocks it does not see, so
//! a fall of the held-out error is evidence; a fall on the training blocks alone is not (SPEC
//! section 7).
//!
//! **Voltage jumps.** The voltage column says only between which two samples a jump fell.
//! After the nominal fit each jump is moved to the instant within that sample period where the
//! nominal model fits its record best, the nominal model is refitted there, and its jumps are
//! located again beside the refit, in turn until no jump moves by more than 0.02 of a period
//! or for 6 rounds (the training records' jumps each next refit is made on moved by the
//! Gauss–Newton step of the motor and the instants together, which settles in a few rounds
//! where alternating moves a few per cent a round; by the located instants alone where that
//! step cannot be taken); the screening projects the jumps' instants out with the motor's
//! parameters: otherwise a step modelled up to a period late leaves a residual at every
//! jump that an effect acting there (a sensor lag, a saturating inductance) is credited with.
//! Every refitted candidate's jumps are located the same way beside its own model before it is
//! judged, so that each model is compared at its own best instants (a lag's lie earlier than
//! the nominal model's, which put them late to mimic it).
//!
//! **Candidates** start from the nominal motor and a small size of each effect, its shape
//! parameters from the records (the cogging period count from the residual's ripple per
//! revolution, time constants from the record span and sample period, speeds and currents from
//! their peaks). Each stage first *screens* every candidate by its score statistic at the base
//! model ([`crate::diagnose::screen`]: one linearisation, no fit); only the best
//! [`DiagnoseSettings::refits`] are refitted with the motor and judged by the verdict's tests,
//! then (up to [`DiagnoseSettings::refit_rounds`] times as many) the next ones by score in
//! place of a refit that stopped or left its effect unresolved, and any whose score promises
//! more than the refits' verdict delivered (its likelihood ratio, penalised alike): the
//! linearised score at zero size ranks effects that grow nonlinearly only roughly.
//! A refit starts where the screening's linear step points (`stepped_start`): a cogging
//! torque at the phase and amplitude of the ripple the residual holds, a drag, brush drop or
//! Stribeck excess at the size it asks for; from the start before the step when the stepped
//! one is too fast for the records' sample rate to simulate, fails, or ends above the base
//! model's training error (`RefitStart`). An effect the nominal fit absorbed into a motor
//! parameter (a sensor lag or a saturating inductance into L, a heating winding into R, a
//! Stribeck friction's static level into Ts) is also refitted from a start that splits the
//! two (`absorbed_start`), and the lower cost kept.
//! A refit whose effect's own part of the prediction is below a noise variance (its size gone
//! to zero) gives no training statistic and is not named: its fall is the motor's.
//! Every refit weights each channel by the noise level the nominal fit found for it, in one
//! stage (not reweighted by its own residuals): the refit then minimises the very cost its
//! likelihood-ratio statistic and held-out blocks measure, and cannot trade a channel the
//! effect does not touch for one it does.
//! A candidate is *not testable from these records* when its signature is lost in the base
//! model's (screening); one that is testable but whose refit leaves its parameters undetermined
//! (no interval, or one wider than a hundred times its value) reads *tested, no evidence* when
//! its screening score is below the level, *unresolved* otherwise.

use motor_model::{EffectKind, Effects, Input, MotorParams};

use crate::diagnose::base::Base;
use crate::diagnose::heldout::{nrmse_summary, split};
use crate::diagnose::jumps::{
    filled_from_grid, jump_gauss_newton, largest_jump_move, locate_every_jump, located_inputs,
    with_inputs, NOMINAL_LOCATE_ROUNDS, NOMINAL_LOCATE_SETTLED,
};
use crate::diagnose::nominal::{fit_nominal, localise_fit, usable_nominal};
use crate::diagnose::report::{
    DiagnoseError, DiagnoseProgress, DiagnoseSettings, Diagnosis, Stage,
};
use crate::diagnose::stage::run_stage;
use crate::diagnose::starts::{channel_scales, slower_electrical};
use crate::error::FitError;
use crate::estimation::records::{Channel, ExcitedRecord};
use crate::excitation::output_error::predict_with_step_factor;

/// Identifies the motor on `records`, localises its residual and looks for the unmodelled
/// effects among [`DiagnoseSettings::candidates`] (module docs). `validation` records, if any,
/// are held out whole; otherwise blocks of `records` are. `start` is the start of the nominal
/// fit (e.g. [`crate::equation_error_start`]). `names` label the records in the localisation
/// (training first, then validation). `progress` is called as the work advances.
pub fn diagnose(
    records: &[ExcitedRecord<'_>],
    validation: &[ExcitedRecord<'_>],
    names: &[&str],
    start: &MotorParams,
    settings: &DiagnoseSettings,
    progress: &(dyn Fn(DiagnoseProgress) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    if records.is_empty() {
        return Err(FitError::BadData {
            series: "records".into(),
            reason: "no record given".into(),
        }
        .into());
    }
    // The channels and masks must align before the held-out blocks are merged into the masks.
    let shown = super::record_names(names, records.len() + validation.len());
    for (r, name) in records.iter().chain(validation).zip(&shown) {
        crate::estimation::checks::check_aligned(name, r.channels())?;
        crate::estimation::checks::check_current_varies(name, r.current)?;
    }
    // The training records: whole, or with their held-out blocks excluded.
    let masks =
        (validation.is_empty() || settings.split_with_validation).then(|| split(records, settings));
    let train: Vec<ExcitedRecord<'_>> = match &masks {
        Some(m) => records
            .iter()
            .enumerate()
            .map(|(k, r)| ExcitedRecord {
                exclude_current: Some(&m.current_masks[k]),
                exclude_speed: Some(&m.speed_masks[k]),
                ..*r
            })
            .collect(),
        None => records.to_vec(),
    };
    // Every record the held-out error is judged on, and which samples of each are held out.
    let all: Vec<ExcitedRecord<'_>> = records.iter().chain(validation).copied().collect();
    let held: Vec<Vec<bool>> = match &masks {
        Some(m) => m.held.clone(),
        None => records
            .iter()
            .map(|r| vec![false; r.current.len()])
            .collect(),
    }
    .into_iter()
    .chain(validation.iter().map(|r| vec![true; r.current.len()]))
    .collect();
    let blocks = || {
        format!(
            "every {}th block of {} samples of each record held out ({} %; shorter blocks on \
             a record under {} samples, so that it lends two)",
            settings.holdout_every.max(2),
            settings.block_samples.max(1),
            100 / settings.holdout_every.max(2),
            2 * settings.holdout_every.max(2) * settings.block_samples.max(1)
        )
    };
    let heldout = match (&masks, validation.len()) {
        (Some(_), 0) => format!("no validation record: {}", blocks()),
        (Some(_), n) => format!("{n} validation record(s) held out whole, and {}", blocks()),
        (None, n) => format!("{n} validation record(s) held out whole"),
    };

    progress(DiagnoseProgress::Nominal);
    let predict_nominal = |records: &[ExcitedRecord<'_>], motor: &MotorParams| {
        predict_with_step_factor(records, motor, &Effects::none(), settings.step_factor)
    };
    let nominal = fit_nominal(&train, start, settings, None)?;
    // A nominal fit that ran L/R below what the records show may have stopped in a wrong
    // minimum there (the current's rise lost, the rest bent to match): refitted from L/R at
    // [`SLOWEST_START_L_OVER_R`] sample periods, the one with the lower training NRMSE kept.
    let nominal = match slower_electrical(&nominal.params, &train) {
        Some(slower) => match fit_nominal(&train, &slower, settings, None) {
            Ok(second)
                if usable_nominal(&second)
                    && (!usable_nominal(&nominal)
                        || nrmse_summary(&second.fitted, |_, _| true)
                            < nrmse_summary(&nominal.fitted, |_, _| true)) =>
            {
                second
            }
            _ => nominal,
        },
        None => nominal,
    };
    // A channel the nominal model explains worse than its mean is what an unmodelled effect
    // can do, and a motor parameter the records do not determine leaves the prediction the
    // diagnosis works on as good as any value of it would: diagnosed, and said
    // (`nominal_note`). Any other failure stops here.
    let nominal_note = match nominal.failure() {
        None => None,
        Some(why) if !usable_nominal(&nominal) => return Err(DiagnoseError::NominalFailed(why)),
        Some(_) => nominal.refusal.as_ref().map(ToString::to_string),
    };
    let nominal_all = predict_nominal(&all, &nominal.params)?;
    // Each voltage jump moved to where, within its sample period, the nominal model puts it
    // (the voltage column says only between which two samples it fell), then the nominal
    // model refitted on those instants: from here on every fit and test uses them.
    let sigmas = channel_scales(&nominal, &nominal_all);
    let grid = all.clone();
    let located = locate_every_jump(
        &all,
        0..all.len(),
        &nominal.params,
        &Effects::none(),
        &sigmas,
        settings.step_factor,
    );
    let train_grid = train;
    // The nominal model refitted on the located instants and its jumps located again, in
    // turn, until they stop moving. The early samples of a step tie L to the step's instant:
    // located beside a fixed model, a step comes out late and L short, and each round moves
    // them only a little, so the training records' jumps the refit is made on next are moved
    // by the joint Gauss–Newton step ([`jump_gauss_newton`]) instead; the instants kept are
    // those located beside the last refit, as every candidate's are beside its own.
    // A record whose jumps could not move keeps its own.
    let any_moved = located.iter().any(Option::is_some);
    let mut inputs = filled_from_grid(located, &grid);
    let mut fit_at = inputs.clone();
    let mut nominal = nominal;
    let n_train = train_grid.len();
    // The last accepted round's noise scales, its validation records' located jumps, and its
    // training records' when it located them (not when the joint step moved them): the
    // training jumps are located once, beside the model the rounds end on.
    struct RoundEnd {
        sigmas: Vec<(usize, Channel, f64)>,
        valid: Vec<Option<Input>>,
        train_located: Option<Vec<Option<Input>>>,
    }
    let mut last_round: Option<RoundEnd> = None;
    if any_moved {
        for round in 0..NOMINAL_LOCATE_ROUNDS {
            let train_now = with_inputs(&train_grid, &fit_at);
            // A refit that fails after the first keeps the model of the round before.
            let refit = match fit_nominal(&train_now, &nominal.params, settings, None) {
                Ok(refit) => refit,
                Err(e) if round == 0 => return Err(e.into()),
                Err(_) => break,
            };
            // The refit on the located instants replaces the model only when it is a result
            // too.
            nominal = match (refit.failure(), refit.termination.converged()) {
                (None, _) => refit,
                (Some(_), true) if nominal_note.is_some() => refit,
                _ => break,
            };
            let all_now = with_inputs(&grid, &fit_at);
            let sigmas = channel_scales(&nominal, &predict_nominal(&all_now, &nominal.params)?);
            let none = Effects::none();
            let valid = located_inputs(
                &grid,
                n_train..grid.len(),
                &nominal.params,
                &none,
                &sigmas,
                settings,
            );
            let (train_next, train_located) = match jump_gauss_newton(
                &train_now,
                &grid[..n_train],
                &nominal.params,
                &sigmas,
                settings.step_factor,
            ) {
                Some(stepped) => (stepped, None),
                None => {
                    let located = located_inputs(
                        &grid,
                        0..n_train,
                        &nominal.params,
                        &none,
                        &sigmas,
                        settings,
                    );
                    (located.clone(), Some(located))
                }
            };
            let next: Vec<Option<Input>> = train_next
                .into_iter()
                .chain(valid.iter().cloned())
                .collect();
            let moved = largest_jump_move(&fit_at, &next, &grid);
            fit_at = next;
            last_round = Some(RoundEnd {
                sigmas,
                valid,
                train_located,
            });
            if moved < NOMINAL_LOCATE_SETTLED {
                break;
            }
        }
    }
    if let Some(RoundEnd {
        sigmas,
        valid,
        train_located,
    }) = last_round
    {
        let train_located = train_located.unwrap_or_else(|| {
            located_inputs(
                &grid,
                0..n_train,
                &nominal.params,
                &Effects::none(),
                &sigmas,
                settings,
            )
        });
        inputs = train_located.into_iter().chain(valid).collect();
    }
    let train: Vec<ExcitedRecord<'_>> = with_inputs(&train_grid, &inputs);
    let all: Vec<ExcitedRecord<'_>> = with_inputs(&grid, &inputs);
    let nominal_all = predict_nominal(&all, &nominal.params)?;
    // The noise level of each channel, as the nominal fit weighted it: the same for every
    // candidate, so that their held-out errors compare.
    let sigmas = channel_scales(&nominal, &nominal_all);
    let localisation = localise_fit(&all, &nominal_all, names, &settings.localise)?;

    // A stage's records carry the jump instants of the model it starts from: the nominal
    // model's for the first, the chosen refit's for the next (one slot per stage, filled once).
    let stage_inputs: Vec<std::cell::OnceCell<Vec<Option<Input>>>> =
        (0..settings.max_effects.max(1))
            .map(|_| Default::default())
            .collect();
    let stage_records: Vec<std::cell::OnceCell<(Vec<ExcitedRecord<'_>>, Vec<ExcitedRecord<'_>>)>> =
        (0..settings.max_effects.max(1))
            .map(|_| Default::default())
            .collect();
    let mut stages: Vec<Stage> = Vec::new();
    let mut base = Base {
        motor: nominal.params,
        effects: Effects::none(),
        fitted: nominal_all,
        train: &train,
        all: &all,
        grid: &grid,
    };
    for stage_no in 1..=settings.max_effects.max(1) {
        let kinds: Vec<EffectKind> = settings
            .candidates
            .iter()
            .copied()
            .filter(|k| base.effects.get(*k).is_none())
            .collect();
        if kinds.is_empty() {
            break;
        }
        let stage = run_stage(
            stage_no,
            &kinds,
            &base,
            &held,
            &sigmas,
            &localisation,
            settings,
            progress,
        );
        let chosen = stage.verdict.verdict.clone();
        let next = chosen.as_ref().and_then(|name| {
            stage
                .candidates
                .iter()
                .find(|c| c.name == name.as_str())
                .and_then(|c| c.motor.map(|m| (m, c.effects, c.inputs.clone())))
        });
        stages.push(stage);
        let Some((motor, effects, inputs)) = next else {
            break;
        };
        // The next stage starts from the model with the chosen effect, on its jump instants.
        let (Some(slot), Some(records)) = (
            stage_inputs.get(stage_no - 1),
            stage_records.get(stage_no - 1),
        ) else {
            break;
        };
        let inputs = slot.get_or_init(|| inputs);
        let (train_now, all_now) =
            records.get_or_init(|| (with_inputs(&train, inputs), with_inputs(&all, inputs)));
        let fitted = predict_with_step_factor(all_now, &motor, &effects, settings.step_factor)?;
        base = Base {
            motor,
            effects,
            fitted,
            train: train_now,
            all: all_now,
            grid: &grid,
        };
    }
    Ok(Diagnosis {
        nominal,
        nominal_note,
        heldout,
        held,
        localisation,
        stages,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::heldout::block_sse;
    use crate::diagnose::heldout::record_block;
    use crate::diagnose::heldout::train_fall;
    use crate::diagnose::jumps::jump_bracket;
    use crate::diagnose::jumps::FIRST_JUMP_MARGIN;
    use crate::diagnose::screen::BaseProjection;
    use crate::diagnose::stage::asks_for_negative_size;
    use crate::diagnose::stage::stepped_start;
    use crate::diagnose::starts::brush_knee_scales;
    use crate::diagnose::starts::cogging_prefilter;
    use crate::diagnose::starts::COGGING_SCREENED;
    use crate::estimation::records::FittedChannel;
    use crate::excitation::output_error::output_error_sensitivity;
    use crate::excitation::voltage::voltage_input;
    use motor_model::CoggingTorque;
    use motor_model::Effect;
    use motor_model::{MeasurementModel, Record};
    use nalgebra::DMatrix;

    #[test]
    fn a_first_jump_after_the_starting_level_is_searched_down_to_the_records_start() {
        let dt = 1e-3;
        // A record's voltage as its column reads it: 0 V from its start, the step on sample 1,
        // a reversal on sample 30.
        let levels = [(0.0, 0.0), (dt, 6.0), (30.0 * dt, -6.0)];
        // The step can have fallen anywhere in the first sample period (it was searched only
        // in its second half: half a period after the level at 0 s, taken for a jump).
        let (lo, hi) = jump_bracket(&levels, 1, dt);
        assert!((lo - FIRST_JUMP_MARGIN * dt).abs() < 1e-15, "{lo}");
        assert_eq!(hi, dt);
        // A later jump: within the period before its sample, half a period after the one
        // before.
        let (lo, hi) = jump_bracket(&levels, 2, dt);
        assert!(
            (lo - 29.0 * dt).abs() < 1e-15 && hi == 30.0 * dt,
            "{lo} {hi}"
        );
        let close = [(0.0, 0.0), (dt, 6.0), (1.2 * dt, -6.0)];
        let (lo, _) = jump_bracket(&close, 2, dt);
        assert!((lo - 1.5 * dt).abs() < 1e-15, "{lo}");
    }

    #[test]
    fn a_brush_knee_is_started_at_every_distinct_current_scale() {
        let input = Input::step(1.0, 0.0).expect("a step");
        let currents = [vec![0.0, 20.0, 10.0], vec![0.1, -0.2, 0.15], vec![0.3, 0.1]];
        let records: Vec<ExcitedRecord<'_>> = currents
            .iter()
            .map(|current| ExcitedRecord {
                input: &input,
                dt: 1e-3,
                current,
                speed: None,
                position: None,
                exclude_current: None,
                exclude_speed: None,
            })
            .collect();
        // 20 A, then 0.3 A (0.2 A is within a factor 3 of it).
        assert_eq!(brush_knee_scales(&records), vec![20.0, 0.3]);
        assert_eq!(brush_knee_scales(&records[..1]), vec![20.0]);
    }

    /// The servo of the diagnosis examples (R 2 Ω, L 2 mH, k 0.05, f 4e-4, J 2e-5, Ts 4 mN·m)
    /// under 12 V, 3 V and 0.6 V steps of 1 s at 5 kHz through the paper's logger, with
    /// `effects`.
    fn servo_records(effects: Effects) -> (MotorParams, Vec<(Input, Record)>) {
        let motor = MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3).unwrap();
        let records = [12.0, 3.0, 0.6]
            .iter()
            .enumerate()
            .map(|(k, &volts)| {
                let input = Input::step(volts, 0.05).unwrap();
                let trace = motor_model::simulate(&motor, effects, &input, 1.0, 5e3).unwrap();
                let record = MeasurementModel::paper_logger(&trace, 30 + k as u64)
                    .apply(&trace)
                    .unwrap();
                (voltage_input(&record.t, &record.voltage).unwrap(), record)
            })
            .collect();
        (motor, records)
    }

    /// The records of [`servo_records`] as the diagnosis takes them (encoder angle, 5 kHz).
    fn excited_of(records: &[(Input, Record)]) -> Vec<ExcitedRecord<'_>> {
        records
            .iter()
            .map(|(input, r)| ExcitedRecord {
                input,
                dt: 2e-4,
                current: &r.current,
                speed: None,
                position: r.position.as_deref(),
                exclude_current: None,
                exclude_speed: None,
            })
            .collect()
    }

    /// The nominal `motor`'s prediction of `excited` and each channel's residual level.
    fn nominal_of(
        excited: &[ExcitedRecord<'_>],
        motor: &MotorParams,
    ) -> (Vec<FittedChannel>, Vec<(usize, Channel, f64)>) {
        let fitted = predict_with_step_factor(excited, motor, &Effects::none(), 8.0).unwrap();
        let sigmas = fitted
            .iter()
            .map(|ch| (ch.record, ch.channel, ch.residual_rms()))
            .collect();
        (fitted, sigmas)
    }

    #[test]
    fn the_screening_step_turns_a_cogging_start_to_the_phase_present() {
        // A 20-per-revolution ripple at φ = 2.5 rad, screened from the start's φ = 0.3 rad
        // (more than a quarter period away, where a refit collapses to A → 0): the stepped
        // start has the phase present to within 0.3 rad and the amplitude within a factor 2.
        let present = CoggingTorque {
            amplitude_nm: 2e-3,
            periods_per_rev: 20,
            phase_rad: 2.5,
        };
        let (motor, records) = servo_records(Effects::none().with(Effect::CoggingTorque(present)));
        let excited = excited_of(&records);
        let (_, sigmas) = nominal_of(&excited, &motor);
        let lin = output_error_sensitivity(&excited, &motor, &Effects::none(), &sigmas, None, 8.0)
            .unwrap();
        let projection = BaseProjection::new(&lin.residuals, &lin.jacobian, &lin.series).unwrap();
        let start = Effect::CoggingTorque(CoggingTorque {
            amplitude_nm: 2e-4,
            phase_rad: 0.3,
            ..present
        });
        let sig = output_error_sensitivity(
            &excited,
            &motor,
            &Effects::none().with(start),
            &sigmas,
            Some(EffectKind::CoggingTorque),
            8.0,
        )
        .unwrap();
        let Effect::CoggingTorque(moved) =
            stepped_start(start, motor.ts_nm, &sig.jacobian, &projection)
        else {
            panic!("not a cogging torque");
        };
        let off = (moved.phase_rad - present.phase_rad + std::f64::consts::PI)
            .rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!(off.abs() < 0.3, "{moved:?}");
        let ratio = moved.amplitude_nm / present.amplitude_nm;
        assert!((0.5..2.0).contains(&ratio), "{moved:?}");
    }

    #[test]
    fn the_cogging_prefilter_ranks_the_period_count_present_among_those_screened() {
        // A cogging torque of 20 periods per revolution at half the Coulomb torque, the
        // nominal motor as the base: its signature at N = 20 must be among the few the
        // screening refits in full.
        for n in [7u32, 20] {
            let cogging = Effect::CoggingTorque(CoggingTorque {
                amplitude_nm: 2e-3,
                periods_per_rev: n,
                phase_rad: 0.4,
            });
            let (motor, records) = servo_records(Effects::none().with(cogging));
            let excited = excited_of(&records);
            let (fitted, sigmas) = nominal_of(&excited, &motor);
            let base = Base {
                motor,
                effects: Effects::none(),
                fitted,
                train: &excited,
                all: &excited,
                grid: &excited,
            };
            let lin =
                output_error_sensitivity(&excited, &motor, &Effects::none(), &sigmas, None, 8.0)
                    .unwrap();
            let projection = BaseProjection::new(&lin.residuals, &lin.jacobian, &lin.series)
                .expect("a linearisation");
            let ranked = cogging_prefilter(&base, &sigmas, &projection, 64, 8.0)
                .expect("a ranking of the period counts");
            assert_eq!(ranked.len(), 64);
            let at = ranked.iter().position(|&m| m == n);
            assert!(
                at.is_some_and(|at| at < COGGING_SCREENED),
                "N = {n} ranked {at:?}: {:?}",
                &ranked[..8]
            );
        }
    }

    #[test]
    fn a_size_only_effect_asked_for_a_negative_size_screens_at_zero() {
        // A base of a line, a residual `± 3 x²` beside it, and the signature `x²` of one
        // parameter: the residual `simulated − measured` asks for the size `∓ 3`.
        let n = 200;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let base = DMatrix::from_fn(n, 2, |i, j| if j == 0 { x[i] } else { 1.0 });
        let signature = DMatrix::from_fn(n, 1, |i, _| x[i] * x[i]);
        for (sign, negative) in [(1.0, true), (-1.0, false)] {
            // The part of `sign · 3 x²` a line cannot explain.
            let y = DMatrix::from_fn(n, 1, |i, _| sign * 3.0 * x[i] * x[i]);
            let fit = base.clone().svd(true, true).solve(&y, 1e-12).unwrap();
            let r = (y - &base * fit).as_slice().to_vec();
            let projection = BaseProjection::new(&r, &base, &[n]).unwrap();
            for kind in [
                EffectKind::CurrentSensorLag,
                EffectKind::QuadraticDrag,
                EffectKind::BrushDrop,
            ] {
                assert_eq!(
                    asks_for_negative_size(kind, &signature, &projection),
                    negative,
                    "{kind:?}, residual {sign} · 3 x²"
                );
            }
            // A cogging torque's phase turns its sign: never one-sided.
            assert!(!asks_for_negative_size(
                EffectKind::CoggingTorque,
                &signature,
                &projection
            ));
        }
    }

    #[test]
    fn a_short_training_record_lends_two_held_out_blocks_and_each_run_is_a_block() {
        let settings = DiagnoseSettings::default();
        // 4 blocks of 50 held out one in four: a record under 400 samples gets shorter ones.
        assert_eq!(record_block(5000, &settings), 50);
        assert_eq!(record_block(400, &settings), 50);
        assert_eq!(record_block(112, &settings), 14);
        let n = 112;
        let block = record_block(n, &settings);
        let held: Vec<bool> = (0..n).map(|i| (i / block) % 4 == 3).collect();
        assert_eq!(held.iter().filter(|&&h| h).count(), 28);
        // A training record's held-out runs are its blocks; a validation record, held out
        // whole, is cut every `block_samples`.
        let channel = |record: usize, n: usize| FittedChannel {
            record,
            channel: Channel::Current,
            samples: (0..n).collect(),
            measured: vec![1.0; n],
            model: vec![0.0; n],
        };
        let sigmas = [(0, Channel::Current, 1.0), (1, Channel::Current, 1.0)];
        let sse = block_sse(
            &[channel(0, n), channel(1, 120)],
            &sigmas,
            &[held, vec![true; 120]],
            settings.block_samples,
        );
        assert_eq!(sse, vec![14.0, 14.0, 50.0, 50.0, 20.0]);
    }

    #[test]
    fn a_channel_shorter_than_the_correlation_lags_still_gives_a_training_statistic() {
        // 20 training samples, fewer than the 25 lags + 1: the fall is counted, with a
        // quarter of the length in lags, not dropped (which read p = 1 on records of a few
        // dozen samples).
        let channel = |model: f64| FittedChannel {
            record: 0,
            channel: Channel::Current,
            samples: (0..20).collect(),
            measured: (0..20)
                .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
                .collect(),
            model: vec![model; 20],
        };
        let sigmas = [(0, Channel::Current, 1.0)];
        let (fall, factor) = train_fall(
            &[channel(1.0)],
            &[channel(0.0)],
            &sigmas,
            &[vec![false; 20]],
        )
        .expect("a statistic");
        // Before: residuals 0 and -2 (sum of squares 40); after: ±1 (20).
        assert_eq!(fall, 20.0);
        assert!(factor >= 1.0);
    }
}
