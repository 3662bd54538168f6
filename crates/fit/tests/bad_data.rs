//! Bad data gives a typed error that says what is wrong — never a panic.

use fit::{identify_full, identify_paper, FitError, LmSettings, StepTest};
use motor_model::{MotorParams, MotorState, StepResponse};

struct Rec {
    volts: f64,
    current: Vec<f64>,
    speed: Vec<f64>,
}

fn exact(volts: f64, seconds: f64) -> Rec {
    let n = (seconds * 1000.0) as usize + 1;
    let mut s = vec![MotorState::default(); n];
    StepResponse::new(&MotorParams::paper(), volts).fill(0.0, 1e-3, &mut s);
    Rec {
        volts,
        current: s.iter().map(|x| x.current_a).collect(),
        speed: s.iter().map(|x| x.speed_rad_s).collect(),
    }
}

fn test_of(r: &Rec) -> StepTest<'_> {
    StepTest {
        volts: r.volts,
        t_first: 0.0,
        dt: 1e-3,
        current: &r.current,
        speed: Some(&r.speed),
        position: None,
        exclude_current: None,
        exclude_speed: None,
    }
}

fn both_fail(high: &StepTest<'_>, low: &StepTest<'_>, needle: &str) {
    let paper = identify_paper(high, low, LmSettings::default()).unwrap_err();
    let full =
        identify_full(&[*high, *low], &MotorParams::paper(), LmSettings::default()).unwrap_err();
    for err in [paper, full] {
        assert!(matches!(err, FitError::BadData { .. }), "{err:?}");
        assert!(
            err.to_string().contains(needle),
            "`{err}` should mention `{needle}`"
        );
    }
}

#[test]
fn nan_empty_short_constant_and_misaligned_records_are_refused() {
    let (hv, lv) = (exact(40.0, 50.0), exact(2.5, 50.0));
    let good_low = test_of(&lv);

    let mut nan = exact(40.0, 50.0);
    nan.current[1234] = f64::NAN;
    both_fail(&test_of(&nan), &good_low, "current sample 1234 is NaN");

    let empty = Rec {
        volts: 40.0,
        current: vec![],
        speed: vec![],
    };
    both_fail(&test_of(&empty), &good_low, "0 samples");

    let short = Rec {
        volts: 40.0,
        current: hv.current[..5].to_vec(),
        speed: hv.speed[..5].to_vec(),
    };
    both_fail(&test_of(&short), &good_low, "5 samples: at least 8");

    let constant = Rec {
        volts: 40.0,
        current: vec![2.0; 1000],
        speed: hv.speed[..1000].to_vec(),
    };
    both_fail(&test_of(&constant), &good_low, "the current is constant");

    let misaligned = StepTest {
        speed: Some(&hv.speed[..100]),
        ..test_of(&hv)
    };
    both_fail(
        &misaligned,
        &good_low,
        "speed has 100 samples where the current has 50001",
    );

    let zero_volts = StepTest {
        volts: 0.0,
        ..test_of(&hv)
    };
    both_fail(&zero_volts, &good_low, "step of 0 V");
}

/// The paper's motor breaks away only above R Ts/k = 0.06 V.
#[test]
fn a_low_voltage_step_that_never_breaks_away_is_named() {
    let hv = exact(40.0, 50.0);
    let stuck = exact(0.05, 50.0);
    assert!(stuck.speed.iter().all(|&w| w == 0.0));
    both_fail(&test_of(&hv), &test_of(&stuck), "never moves");
}

/// The paper's method reads the steady state off the record's end: a 5 s record of a motor
/// with τm = 20 s has not settled. The full model does not need a steady state.
#[test]
fn a_step_that_never_settles_is_refused_by_the_paper_method_only() {
    let (hv, lv) = (exact(40.0, 5.0), exact(2.5, 50.0));
    let err = identify_paper(&test_of(&hv), &test_of(&lv), LmSettings::default()).unwrap_err();
    assert!(err.to_string().contains("has not settled"), "{err}");
    let full = identify_full(
        &[test_of(&hv), test_of(&lv)],
        &MotorParams::paper(),
        LmSettings::default(),
    )
    .unwrap();
    assert!(
        full.termination.converged(),
        "{:?} after {} iterations, cost {:e}, {:?}",
        full.termination,
        full.iterations,
        full.cost,
        full.params
    );
    assert!((full.params.j_kgm2 - 1.0).abs() < 1e-6);
    // The paper's own 50 s record (2.5 τm) counts as settled.
    assert!(identify_paper(
        &test_of(&exact(40.0, 50.0)),
        &test_of(&lv),
        LmSettings::default()
    )
    .is_ok());
}
