//! A small, seeded version of the withheld-effect benchmark (issue 9, acceptance 1): cases of
//! `fit::diagnose::benchmark::calibrated_case` diagnosed without being told their effect,
//! scored by `fit::diagnose::benchmark`, with a floor on the top-1 accuracy and no false alarm
//! on `none`.
//!
//! The cases are all 16 of seed 1 (two `none`, two with two effects, twelve with one; about a
//! minute on two cores); the full benchmark is the `withheld_benchmark` example. The diagnosis
//! names the right effect first on 14 of the 16: case 0's sensor lag (a sample period, 57
//! noise floors beside the best nominal model) is named `inductance_saturation` (its refit
//! runs τf to 0 from the nominal fit, whose L/R has taken the lag), and case 1's thermal drift
//! (5 floors) `stribeck_friction`. The floor, 0.8, allows three misses.
//!
//! Two more tests diagnose one case each of the 160 that a screening or refit rule used to miss,
//! as they were found: sized against the true nominal motor (`motor_model::withheld::
//! benchmark_case`), before the benchmark's cases were sized on the gap.

use fit::diagnose::benchmark::{calibrated_case, run_case, CaseOutcome, Summary};
use fit::diagnose::DiagnoseSettings;
use motor_model::withheld::benchmark_case;

/// Seed of the cases.
const SEED: u64 = 1;
/// Cases of the seed.
const OF: usize = 16;
/// Top-1 accuracy the diagnosis must reach on them \[-\].
const TOP1_FLOOR: f64 = 0.8;

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

/// Diagnoses case `index` of seed 1's 160 (sized against the true nominal motor), which holds
/// `effect` alone, and checks that
/// `effect` is named first.
fn assert_named(index: usize, effect: &str) {
    let case = benchmark_case(SEED, index, 160).expect("a case of the benchmark");
    let outcome = run_case(&case, &DiagnoseSettings::default());
    assert_eq!(outcome.truth, [effect]);
    assert_eq!(outcome.verdict(), effect, "{outcome:?}");
}
