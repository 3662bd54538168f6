//! Full-model identification on the paper's setup.

use fit::{identify_full, identify_paper, LmSettings, StepTest};
use motor_model::{MotorParams, MotorState, StepResponse};

struct Rec {
    volts: f64,
    current: Vec<f64>,
    speed: Vec<f64>,
}

fn exact_record(motor: &MotorParams, volts: f64, seconds: f64, rate: f64) -> Rec {
    let n = (seconds * rate) as usize + 1;
    let mut s = vec![MotorState::default(); n];
    StepResponse::new(motor, volts).fill(0.0, 1.0 / rate, &mut s);
    Rec {
        volts,
        current: s.iter().map(|x| x.current_a).collect(),
        speed: s.iter().map(|x| x.speed_rad_s).collect(),
    }
}

fn test_of(r: &Rec, rate: f64) -> StepTest<'_> {
    StepTest {
        volts: r.volts,
        t_first: 0.0,
        dt: 1.0 / rate,
        current: &r.current,
        speed: Some(&r.speed),
        position: None,
        exclude_current: None,
        exclude_speed: None,
    }
}

/// Acceptance 2 of the identification issue: on the paper's noise-free records (40 V and
/// 2.5 V, 50 s, 1 kHz) the full method recovers each parameter within 0.01 % of the truth,
/// starting from the paper method's result (itself about 1 % off).
#[test]
fn full_method_recovers_the_paper_motor_within_0_01_percent() {
    let truth = MotorParams::paper();
    let (hv, lv) = (
        exact_record(&truth, 40.0, 50.0, 1000.0),
        exact_record(&truth, 2.5, 50.0, 1000.0),
    );
    let tests = [test_of(&hv, 1000.0), test_of(&lv, 1000.0)];
    let paper = identify_paper(&tests[0], &tests[1], LmSettings::default()).unwrap();
    let full = identify_full(&tests, &paper.params, LmSettings::default()).unwrap();
    assert!(full.termination.converged(), "{:?}", full.termination);
    let pairs = [
        ("R", full.params.r_ohm, truth.r_ohm, paper.params.r_ohm),
        (
            "L",
            full.params.l_henry,
            truth.l_henry,
            paper.params.l_henry,
        ),
        (
            "k",
            full.params.k_nm_per_a,
            truth.k_nm_per_a,
            paper.params.k_nm_per_a,
        ),
        (
            "f",
            full.params.f_nms_per_rad,
            truth.f_nms_per_rad,
            paper.params.f_nms_per_rad,
        ),
        ("J", full.params.j_kgm2, truth.j_kgm2, paper.params.j_kgm2),
        ("Ts", full.params.ts_nm, truth.ts_nm, paper.params.ts_nm),
    ];
    for (name, got, want, paper_value) in pairs {
        let rel = (got - want).abs() / want;
        assert!(rel < 1e-4, "{name}: {got} vs {want} ({:.2e} relative)", rel);
        // And the paper's method was much farther off.
        assert!(
            (paper_value - want).abs() / want > 10.0 * rel,
            "{name}: paper {paper_value}"
        );
    }
    for q in &full.quality {
        assert!(q.nrmse_fit_percent > 99.99, "{q:?}");
    }
}

/// A step 0.7 ms before the first sample that shows it (the logger samples every 1 ms): the
/// step instant is an uncertain input (expected 0.5 ms, variance dt²/12) that the records
/// move to where they put it. On exact records the fit then recovers every parameter to
/// 1e-4 relative (measured: 2.3e-8), where fixing the instant at its expected 0.5 ms leaves a
/// worst error of 2.0e-4 (measured); the test asks for a factor 5 between them.
#[test]
fn sub_sample_step_instant_is_found_from_the_records() {
    let truth = MotorParams::paper();
    let rate = 1000.0;
    let delay = 0.7e-3;
    let record = |volts: f64| {
        let n = 50_001;
        let mut s = vec![MotorState::default(); n];
        StepResponse::new(&truth, volts).fill(delay, 1.0 / rate, &mut s);
        Rec {
            volts,
            current: s.iter().map(|x| x.current_a).collect(),
            speed: s.iter().map(|x| x.speed_rad_s).collect(),
        }
    };
    let (hv, lv) = (record(40.0), record(2.5));
    let tests = [test_of(&hv, rate), test_of(&lv, rate)];
    let paper = identify_paper(&tests[0], &tests[1], LmSettings::default()).unwrap();
    let inputs = fit::StepInputs {
        volts_variance_v2: 0.0,
        delay_s: 0.5e-3,
        delay_variance_s2: 1e-6 / 12.0,
        current_lsb_a: 0.0,
    };
    let worst = |fit: &fit::FullFit| {
        fit.params
            .values()
            .iter()
            .zip(truth.values())
            .map(|(v, w)| ((v - w) / w).abs())
            .fold(0.0, f64::max)
    };
    let moved = fit::identify_full_with_inputs(
        &tests,
        &[inputs, inputs],
        &paper.params,
        LmSettings::default(),
    )
    .unwrap();
    let fixed_tests = tests.map(|t| StepTest {
        t_first: 0.5e-3,
        ..t
    });
    let fixed = identify_full(&fixed_tests, &paper.params, LmSettings::default()).unwrap();
    assert!(moved.termination.converged(), "{:?}", moved.termination);
    assert!(worst(&moved) < 1e-4, "worst error {:.3e}", worst(&moved));
    assert!(
        worst(&fixed) > 5.0 * worst(&moved),
        "fixed {:.3e}, moved {:.3e}",
        worst(&fixed),
        worst(&moved)
    );
}
