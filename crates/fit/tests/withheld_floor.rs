//! A small, seeded version of the withheld-effect benchmark (issue 9, acceptance 1): cases of
//! `fit::diagnose::benchmark::calibrated_case` diagnosed without being told their effect,
//! scored by `fit::diagnose::benchmark`, with a floor on the top-1 accuracy and no false alarm
//! on `none`.
//!
//! The cases are all 16 of seed 1 (two `none`, two with two effects, twelve with one; about a
//! minute and a half on two cores); the full benchmark is the `withheld_benchmark` example.
//! The diagnosis names the right effect first on all 16. Case 1's thermal drift (5 floors)
//! was named after a `stribeck_friction` until the nominal model's steps and L were fitted
//! together; case 0's sensor lag (a sample period, 57 noise floors beside the best nominal
//! model) was named `inductance_saturation` until each candidate was judged at its own jump
//! instants. The floor, 0.9375, allows one miss.
//!
//! Two more tests diagnose one case each of the 160 that a screening or refit rule used to miss,
//! as they were found: sized against the true nominal motor (`motor_model::withheld::
//! benchmark_case`), before the benchmark's cases were sized on the gap; more, one case each
//! sized on the gap, that the held-out blocks, the jump instants, the nominal fit's start and
//! the thermal drift's start used to miss, one whose equation-error start failed, and two
//! two-effect cases whose second effect a Stribeck friction's start and the order of the
//! refits used to miss.
//!
//! The three slowest of those (30–55 s each on two cores) are `#[ignore]`d: the heavy checks
//! run them (`cargo test --release -p fit --test withheld_floor -- --ignored`).

use fit::diagnose::benchmark::{calibrated_case, run_case, CaseOutcome, Summary};
use fit::diagnose::DiagnoseSettings;
use motor_model::withheld::benchmark_case;

/// Seed of the cases.
const SEED: u64 = 1;
/// Cases of the seed.
const OF: usize = 16;
/// Top-1 accuracy the diagnosis must reach on them \[-\].
const TOP1_FLOOR: f64 = 0.9375;

#[test]
fn withheld_effects_are_named_above_the_floor_and_none_raises_no_alarm() {
    let settings = DiagnoseSettings {
        threads: 2,
        ..DiagnoseSettings::default()
    };
    let outcomes: Vec<CaseOutcome> = (0..OF)
        .map(|i| {
            let case = calibrated_case(SEED, i, OF, &settings).expect("a case of the benchmark");
            run_case(&case, &settings)
        })
        .collect();
    let table: Vec<String> = outcomes
        .iter()
        .map(|o| format!("case {}: {:?} named {:?}", o.index, o.truth, o.named))
        .collect();
    let s = Summary::of(&outcomes);
    assert!(
        s.false_alarms.1 > 0,
        "the cases must hold a `none` case: {table:#?}"
    );
    assert_eq!(s.false_alarms.0, 0, "false alarm on none: {table:#?}");
    assert!(
        s.top1_accuracy >= TOP1_FLOOR,
        "top-1 accuracy {:.2} below {TOP1_FLOOR}: {table:#?}",
        s.top1_accuracy
    );
}

#[test]
fn a_refit_whose_stepped_start_the_sample_rate_cannot_simulate_starts_unstepped() {
    // Case 100 of seed 1's 160: a brush drop (its logarithmic form) 15 noise floors from the
    // nominal motor. The screening's step grows the drop until its knee puts a resistance
    // `Vb/I_knee` in series that makes L/R shorter than the records can simulate; the refit
    // was refused ("start parameters: a time constant … below the sample period") and the
    // verdict was `none`. From the start before the step it names the drop.
    assert_named(100, "brush_drop");
}

#[test]
fn a_drag_the_residual_asks_to_push_does_not_take_the_refit_of_a_cogging_torque() {
    // Case 19 of seed 1's 160: a cogging torque 18 noise floors from the nominal refit. The
    // drag's two-sided screening score (χ² 18) took one of the two refits from it, though its
    // linear step asked for a negative drag; the refit ran c to 6e-33 and the verdict was
    // `none`. Screened one-sided, the drag scores 0 and the cogging torque is refitted.
    assert_named(19, "cogging_torque");
}

#[test]
fn an_effect_only_a_short_training_step_shows_is_judged_on_its_held_out_blocks() {
    // Case 128 of seed 1's 160, sized on the gap: a cogging torque 12 noise floors from the
    // nominal model on the low step alone, a record of 112 samples. With blocks of 50 held
    // out one in four, that step lent no sample to the held-out data: the refit found the
    // amplitude to 2 % but no held-out gain, and the verdict was `none`.
    assert_named_calibrated(128, "cogging_torque");
}

#[test]
fn a_sensor_lag_the_nominal_fit_took_into_l_is_named_at_its_own_jump_instants() {
    // Case 11 of seed 1's 160, sized on the gap: a second-order current sensor 7.7 floors
    // from the nominal model, which took it into L and put the steps late. Refitted from the
    // nominal model at those instants, τf ran to 1e-109 s and the verdict was `none`; from a
    // start splitting L/R between L and τf, judged at its own instants, the lag is named.
    assert_named_calibrated(11, "current_sensor_lag");
}

#[test]
fn a_saturation_behind_a_step_the_nominal_fit_put_late_is_named_once_l_and_the_step_are_fitted_together(
) {
    // Case 79 of seed 1's 160, sized on the gap: an inductance saturating to 93 % above
    // 2.2 A, 10 floors from the nominal model, on a motor whose L/R (0.74 ms) is shorter than
    // the 1 ms sample period. Located beside the nominal model and refitted once, the steps
    // stayed late (0.89 ms, truth 0.63 ms) and L short (1.07 mH, truth 1.88 mH); their
    // residual at the steps' first samples set the current's weight a hundred floors high and
    // the verdict was `none`. The reversal record, six jumps in 150 samples read without noise,
    // was replayed as samples. The joint step puts the steps at 0.63 ms and L at 1.83 mH.
    assert_named_calibrated(79, "inductance_saturation");
}

#[test]
fn a_thermal_drift_refit_no_worse_than_the_nominal_model_on_a_channel_neither_explains_is_judged() {
    // Case 16 of seed 1's 160, sized on the gap: the low step's encoder speed is mostly its
    // counts, and the nominal model explains it no better than its mean. The thermal drift's
    // refit, at an NRMSE of 1.001 there, was refused as a wrong minimum, and a Stribeck
    // friction was named. Judged by its tests, the drift halves the held-out NRMSE.
    assert_named_calibrated(16, "thermal_drift");
}

#[test]
#[ignore = "heavy (30–55 s): cargo test --release -p fit --test withheld_floor -- --ignored"]
fn a_thermal_drift_the_nominal_fit_took_into_r_is_named_from_a_start_with_r_lowered() {
    // Case 102 of seed 1's 160, sized on the gap: the nominal fit took a winding that heats
    // for one at its mean temperature, and the drift's refit from the nominal R ran its
    // heating to zero (NRMSE 0.467 → 0.462, not significant: `none`). From a start heating
    // ten times more, R lowered so that the mean heated R is the nominal one, the training
    // NRMSE falls to 0.09.
    assert_named_calibrated(102, "thermal_drift");
}

#[test]
fn a_cogging_torque_behind_a_nominal_fit_that_lost_l_is_named_once_the_fit_restarts_from_a_slower_l(
) {
    // Case 25 of seed 1's 160, sized on the gap: the nominal fit ran L/R below the sample
    // period and stopped in a wrong minimum (training NRMSE 0.74, held out 1.18); no candidate
    // showed anything beside it and the verdict was `none`. Refitted from L/R at half a
    // sample period, the nominal model's NRMSE is 0.12 and the cogging torque is named.
    assert_named_calibrated(25, "cogging_torque");
}

#[test]
fn a_stribeck_friction_whose_refit_needs_more_than_60_iterations_is_named() {
    // Case 139 of seed 1's 160, sized on the gap: a Gaussian Stribeck friction with Tst twice
    // Ts, 188 noise floors on a low step that sticks and slips. Its refit stopped unresolved at
    // 60 iterations, and a cogging torque (then a sensor lag) took the gap; within 200 it
    // converges to Tst within 0.1 % of the truth and is named.
    assert_named_calibrated(139, "stribeck_friction");
}

#[test]
fn records_whose_torque_equation_gives_no_positive_j_are_still_diagnosed() {
    // Case 88 of seed 1's 160, sized on the gap: a cogging torque of three harmonics, 8 noise
    // floors on the low step. The equation-error start's torque equation gave J = -2.6e-7
    // kg·m², and the diagnosis failed before it began. The start now takes J from the
    // mechanical time constant whose simulation fits the records best.
    let settings = DiagnoseSettings::default();
    let case = calibrated_case(SEED, 88, 160, &settings).expect("a case of the benchmark");
    let outcome = run_case(&case, &settings);
    assert!(outcome.named.is_ok(), "{outcome:?}");
}

#[test]
#[ignore = "heavy (30–55 s): cargo test --release -p fit --test withheld_floor -- --ignored"]
fn a_stribeck_friction_the_nominal_fit_took_into_ts_is_named_from_a_start_with_ts_split() {
    // Case 129 of seed 1's 160, sized on the gap: an inductance saturating to 43 % and a
    // Gaussian Stribeck friction (Tst 0.0296 N·m, twice Ts, Ωs 0.32 rad/s) on a motor whose
    // low step crawls near 2 Ωs for seconds. The nominal fit put its Ts at 0.0274 N·m, near
    // Tst; refitted from there, the friction ran Ωs to 0 or to infinity (a step in friction,
    // or a constant one), and a cogging torque was named after the saturation. From Ts halved
    // and Tst at the nominal Ts, the refit finds Tst 0.0297 N·m and Ωs 0.33 rad/s.
    assert_both_named_calibrated(129, ["inductance_saturation", "stribeck_friction"]);
}

#[test]
#[ignore = "heavy (30–55 s): cargo test --release -p fit --test withheld_floor -- --ignored"]
fn a_candidate_screened_below_one_that_delivered_less_than_it_promises_is_refitted() {
    // Case 83 of seed 1's 160, sized on the gap: an exact quadratic drag and an inductance
    // saturation. The drag's screening score (χ² 502) was fourth, behind a Stribeck friction
    // (880) whose refit delivered a likelihood ratio of 354 and was named; refitted, the drag
    // delivers 484 and takes the held-out NRMSE from 0.248 to 0.242 (the Stribeck friction's
    // 0.246), and both effects present are named.
    assert_both_named_calibrated(83, ["quadratic_drag", "inductance_saturation"]);
}

/// [`assert_named`] on case `index` of seed 1's 160 sized on the gap the nominal model leaves
/// (`calibrated_case`).
fn assert_named_calibrated(index: usize, effect: &str) {
    let settings = DiagnoseSettings::default();
    let case = calibrated_case(SEED, index, 160, &settings).expect("a case of the benchmark");
    let outcome = run_case(&case, &settings);
    assert_eq!(outcome.truth, [effect]);
    assert_eq!(outcome.verdict(), effect, "{outcome:?}");
}

/// Diagnoses case `index` of seed 1's 160 sized on the gap (`calibrated_case`), which holds
/// the two `effects`, and checks that both are named.
fn assert_both_named_calibrated(index: usize, effects: [&str; 2]) {
    let settings = DiagnoseSettings::default();
    let case = calibrated_case(SEED, index, 160, &settings).expect("a case of the benchmark");
    let outcome = run_case(&case, &settings);
    let mut truth = outcome.truth.clone();
    truth.sort_unstable();
    let mut expected = effects.to_vec();
    expected.sort_unstable();
    assert_eq!(truth, expected);
    let named = outcome.named.as_ref().expect("a diagnosis");
    assert!(
        effects.iter().all(|e| named.iter().any(|n| n == e)),
        "{outcome:?}"
    );
}

/// Diagnoses case `index` of seed 1's 160 (sized against the true nominal motor), which holds
/// `effect` alone, and checks that
/// `effect` is named first.
fn assert_named(index: usize, effect: &str) {
    let case = benchmark_case(SEED, index, 160).expect("a case of the benchmark");
    let outcome = run_case(&case, &DiagnoseSettings::default());
    assert_eq!(outcome.truth, [effect]);
    assert_eq!(outcome.verdict(), effect, "{outcome:?}");
}
