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
        delay_s: 0.5e-3,
        delay_variance_s2: 1e-6 / 12.0,
        ..Default::default()
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

/// Without noise a quantiser's error is fixed by the signal and by where its grid sits; only
/// the grid's place varies from one record to the next. The paper's step pair (40 V and
/// 2.5 V, 50 s at 1 kHz, current on a 10-bit ADC without noise, 2000-count encoder) read
/// with the current's grid at 16 places over one step: over those places each parameter's
/// r.m.s. error must match its reported standard error (ratio 0.6 to 1.5), and its mean error
/// must stay within half of it. With the settled current taken up by an offset whose start
/// the readings choose (where they last changed code) and the residuals' Newey–West score
/// covariance, R's r.m.s. error was 2.9e-5 against a standard error of 1.4e-5.
#[test]
fn noise_free_current_intervals_hold_the_error_over_the_grids_place() {
    let truth = MotorParams::paper();
    let (rate, n, places) = (1000.0, 50_001, 16);
    let count = std::f64::consts::TAU / 2000.0;
    let runs: Vec<_> = [40.0, 2.5]
        .map(|volts| {
            let mut s = vec![MotorState::default(); n];
            StepResponse::new(&truth, volts).fill(0.0, 1.0 / rate, &mut s);
            // One step of a 10-bit ADC over the current's range with 20 % headroom.
            let peak = s.iter().map(|x| x.current_a).fold(0.0, f64::max);
            let q = 1.2 * peak / 1023.0;
            let angle: Vec<f64> = s
                .iter()
                .map(|x| count * (x.position_rad / count).floor())
                .collect();
            (volts, s, q, angle)
        })
        .into();
    let mut errors = vec![[0.0; 6]; places];
    let mut std_errors = vec![[0.0; 6]; places];
    for k in 0..places {
        // The two records' grids at unrelated places: evenly spaced, and a golden-ratio walk.
        let fraction = [
            (k as f64 + 0.37) / places as f64,
            (k as f64 * 0.618_034 + 0.11).fract(),
        ];
        let currents: Vec<Vec<f64>> = runs
            .iter()
            .zip(fraction)
            .map(|((_, s, q, _), f)| {
                let phase = f * q;
                s.iter()
                    .map(|x| phase + q * ((x.current_a - phase) / q).round())
                    .collect()
            })
            .collect();
        let tests: Vec<StepTest> = runs
            .iter()
            .zip(&currents)
            .map(|((volts, _, _, angle), current)| StepTest {
                volts: *volts,
                t_first: 0.0,
                dt: 1.0 / rate,
                current,
                speed: None,
                position: Some(angle),
                exclude_current: None,
                exclude_speed: None,
            })
            .collect();
        let inputs: Vec<fit::StepInputs> = runs
            .iter()
            .map(|(_, _, q, _)| fit::StepInputs {
                current_lsb_a: *q,
                ..Default::default()
            })
            .collect();
        let fit =
            fit::identify_full_with_inputs(&tests, &inputs, &truth, LmSettings::default()).unwrap();
        assert!(fit.accepted(), "{:?}", fit.failure());
        let se = fit.std_error.expect("standard errors").values();
        for (j, (v, t)) in fit.params.values().iter().zip(truth.values()).enumerate() {
            errors[k][j] = v / t - 1.0;
            std_errors[k][j] = se[j] / t;
        }
    }
    for (j, name) in fit::PARAM_NAMES.iter().enumerate() {
        let mean = errors.iter().map(|e| e[j]).sum::<f64>() / places as f64;
        let rms = (errors.iter().map(|e| e[j] * e[j]).sum::<f64>() / places as f64).sqrt();
        let se = (std_errors.iter().map(|s| s[j] * s[j]).sum::<f64>() / places as f64).sqrt();
        assert!(
            (0.6..1.5).contains(&(rms / se)),
            "{name}: r.m.s. error {rms:.2e}, standard error {se:.2e}"
        );
        assert!(
            mean.abs() < 0.5 * se,
            "{name}: mean error {mean:+.2e}, standard error {se:.2e}"
        );
    }
}
