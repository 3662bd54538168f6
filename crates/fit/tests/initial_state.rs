//! Output error on records that do not start at rest: a step from a steady 5 V to 15 V, and a
//! slice cut from the middle of a staircase, against a step from rest to 15 V.

mod common;

use common::excited;

use fit::{
    detect_initial_state, equation_error_start_with_initial_states, voltage_levels, FullFit,
    InitialState, OutputError, PARAM_NAMES,
};
use motor_model::{Effects, Input, MeasurementModel, MotorParams, Record, Simulator, Trace};

/// `fixtures/motors/small_servo.json`: τe = 1 ms, τm = 12 ms.
fn servo() -> MotorParams {
    MotorParams::new(2.0, 0.002, 0.05, 4e-4, 2e-5, 0.004).unwrap()
}

const RATE_HZ: f64 = 5000.0;
/// Seeds of the logger's noise, chosen before the first run (not after).
const SEEDS: [u64; 3] = [1, 2, 3];

/// The samples of `trace` from `from_s` on (time from the first kept sample), as a logger that
/// started recording then would have seen them.
fn slice(trace: &Trace, from_s: f64) -> Trace {
    let k = trace.t.iter().position(|&t| t >= from_s - 1e-12).unwrap();
    let cut = |v: &[f64]| v[k..].to_vec();
    Trace {
        t: trace.t[k..].iter().map(|t| t - trace.t[k]).collect(),
        voltage: cut(&trace.voltage),
        current: cut(&trace.current),
        armature_current: cut(&trace.armature_current),
        speed: cut(&trace.speed),
        position: cut(&trace.position),
        stuck: trace.stuck[k..].to_vec(),
    }
}

/// `input` on the servo for `duration_s` from rest, recorded from `from_s` on by the paper's
/// logger (10-bit ADC, 1 LSB of noise, 2000-count encoder) with `seed`.
fn recorded(input: Input, duration_s: f64, from_s: f64, seed: u64) -> Record {
    let trace = Simulator::new(servo(), Effects::none(), input)
        .unwrap()
        .run(duration_s, RATE_HZ)
        .unwrap();
    let kept = slice(&trace, from_s);
    MeasurementModel::paper_logger(&kept, seed)
        .apply(&kept)
        .unwrap()
}

/// Where within its sample period a voltage change falls (a logger's clock knows nothing of
/// the drive's): a third of the period after a sample, not on one (where the truth would sit
/// at the edge of the uniform prior the fit gives a change's instant).
const BETWEEN_SAMPLES_S: f64 = 0.33 / RATE_HZ;

/// The same levels from rest: 20 ms at 0 V, 0.1 s at 5 V, then 15 V for 0.2 s. (A single step
/// from rest to 15 V does not tell this servo's Ts, 4 % of its friction torque at speed, from
/// f: its fit ends at Ts → 0 and is refused, seeds 1 to 3.)
fn from_rest(seed: u64) -> Record {
    let d = BETWEEN_SAMPLES_S;
    let input = Input::piecewise(&[(0.02 + d, 5.0), (0.12 + d, 15.0)]).unwrap();
    recorded(input, 0.32, 0.0, seed)
}

/// 5 V for 0.3 s (25 mechanical time constants: settled), then 15 V; recorded from 0.28 s:
/// 20 ms in the 5 V steady state, then 0.2 s after the step.
fn from_steady(seed: u64) -> Record {
    let input = Input::piecewise(&[(0.0, 5.0), (0.3 + BETWEEN_SAMPLES_S, 15.0)]).unwrap();
    recorded(input, 0.5, 0.28, seed)
}

/// A staircase (6, 12, −8, 3, 10 V, 50 ms each) recorded from 5 ms after the 12 V step, while
/// the motor accelerates, for 0.2 s.
fn staircase_slice(seed: u64) -> Record {
    let input = Input::piecewise(&[
        (0.01, 6.0),
        (0.06, 12.0),
        (0.11, -8.0),
        (0.16, 3.0),
        (0.21, 10.0),
    ])
    .unwrap();
    recorded(input, 0.265, 0.065, seed)
}

/// The output-error fit of `rec` with its simulation started from `state`, from the
/// equation-error start.
fn fit_from(rec: &Record, state: InitialState) -> Result<FullFit, fit::FitError> {
    let (input, priors) = voltage_levels(&rec.t, &rec.voltage, None)?;
    let records = [excited(rec, &input)];
    let initial = [state];
    let start = equation_error_start_with_initial_states(&records, &initial)?;
    OutputError::new(&records, start)
        .level_priors(&[priors])
        .initial_states(&initial)
        .fit()
}

/// [`fit_from`] the initial state `rec` shows, which must be `want`.
fn identify(rec: &Record, want: InitialState) -> FullFit {
    let (input, _) = voltage_levels(&rec.t, &rec.voltage, None).unwrap();
    let detected = detect_initial_state(&excited(rec, &input)).unwrap();
    assert_eq!(detected.state, want, "{}", detected.reason);
    fit_from(rec, detected.state).unwrap()
}

/// Per-parameter 95 % misses allowed over the 18 intervals of three seeds: honest intervals
/// exceed 3 with probability 1.1 % (binomial, p = 0.05), intervals half as wide as they should
/// be with probability 76 %.
const MAX_MISSES_OF_18: usize = 3;

/// Checks one accepted fit against the truth: every error within 4 standard errors (a wrong
/// answer, not chance), and counts the 95 % intervals that miss the truth; prints each
/// parameter. Returns the misses, the largest relative error and the largest relative
/// half-width.
fn judge(fit: &FullFit, what: &str) -> (usize, f64, f64) {
    assert!(
        fit.accepted(),
        "{what}: {:?} at {:?}",
        fit.failure(),
        fit.params
    );
    let ci = fit.ci95.expect("intervals").named().map(|(_, c)| c);
    let se = fit.std_error.expect("standard errors").values();
    let (mut misses, mut worst_error, mut widest) = (0, 0.0f64, 0.0f64);
    for (k, (&got, want)) in fit.params.values().iter().zip(servo().values()).enumerate() {
        let [lo, hi] = ci[k];
        let inside = lo <= want && want <= hi;
        let z = (got - want) / se[k];
        eprintln!(
            "{what}: {:<2} {got:.6e} [{lo:.6e}, {hi:.6e}] error {:+.3} % ({z:+.2} se), {}",
            PARAM_NAMES[k],
            100.0 * (got - want) / want,
            if inside { "inside" } else { "MISSED" }
        );
        assert!(
            z.abs() < 4.0,
            "{what}: {} = {got} is {z:.1} se from {want}",
            PARAM_NAMES[k]
        );
        misses += usize::from(!inside);
        worst_error = worst_error.max((got - want).abs() / want);
        widest = widest.max(0.5 * (hi - lo) / want);
    }
    (misses, worst_error, widest)
}

/// Acceptance 2 of the real-world-records issue: a step from the 5 V steady state to 15 V
/// identifies as well as the same levels from rest, on seeds 1, 2, 3 (chosen before the first
/// run): every fit accepted, every error within 4 standard errors, at most 3 of the 18
/// per-parameter 95 % intervals missing the truth for each kind, and intervals of the same size
/// (within a factor of 3 of the rest record's on the same seed: the steady record lacks the
/// 5 V transient). The steady start costs no parameter of its own.
#[test]
fn a_step_from_a_steady_level_identifies_as_well_as_one_from_rest() {
    let (mut rest_misses, mut steady_misses) = (0, 0);
    for seed in SEEDS {
        let rest = identify(&from_rest(seed), InitialState::Rest);
        let (m, rest_error, rest_width) = judge(&rest, &format!("rest seed {seed}"));
        rest_misses += m;
        let steady = identify(&from_steady(seed), InitialState::Steady);
        let (m, steady_error, steady_width) = judge(&steady, &format!("steady 5 V seed {seed}"));
        steady_misses += m;
        eprintln!(
            "seed {seed}: largest error {:.3} % (rest) vs {:.3} % (steady), largest half-width {:.3} % vs {:.3} %",
            100.0 * rest_error,
            100.0 * steady_error,
            100.0 * rest_width,
            100.0 * steady_width
        );
        assert!(steady_width < 3.0 * rest_width, "seed {seed}");
        // The steady start is the fitted motor's own steady state at 5 V, Eqs. (4), (5).
        let s = &steady.initial_states[0];
        assert_eq!(s.state, InitialState::Steady);
        let own = motor_model::steady_state(&steady.params, 5.0);
        assert!((s.speed_rad_s - own.speed_rad_s).abs() < 0.01 * own.speed_rad_s);
        assert_eq!(rest.initial_states[0].state, InitialState::Rest);
        assert_eq!(rest.initial_states[0].speed_rad_s, 0.0);
    }
    eprintln!("95 % intervals missing the truth: {rest_misses} of 18 (rest), {steady_misses} of 18 (steady)");
    assert!(rest_misses <= MAX_MISSES_OF_18 && steady_misses <= MAX_MISSES_OF_18);
}

/// A slice cut from the middle of a staircase, starting while the motor accelerates: its
/// initial current and speed are fitted with the motor; judged as the steps above (seeds 1, 2,
/// 3, at most 3 of 18 intervals missing); the fitted initial speed within 1 % of the true one.
#[test]
fn a_slice_from_the_middle_of_a_staircase_identifies_with_a_free_initial_state() {
    // The true state at the cut, from the same simulation.
    let input = Input::piecewise(&[(0.01, 6.0), (0.06, 12.0)]).unwrap();
    let truth = Simulator::new(servo(), Effects::none(), input)
        .unwrap()
        .run(0.065, RATE_HZ)
        .unwrap();
    let (i0, w0) = (*truth.current.last().unwrap(), *truth.speed.last().unwrap());
    let mut misses = 0;
    for seed in SEEDS {
        let fit = identify(&staircase_slice(seed), InitialState::Free);
        misses += judge(&fit, &format!("staircase slice seed {seed}")).0;
        let s = &fit.initial_states[0];
        assert_eq!(s.state, InitialState::Free);
        eprintln!(
            "seed {seed}: I0 {:.5} A (true {i0:.5}), Ω0 {:.4} rad/s (true {w0:.4})",
            s.current_a, s.speed_rad_s
        );
        assert!((s.speed_rad_s - w0).abs() < 0.01 * w0);
        assert!((s.current_a - i0).abs() < 0.02 * i0);
    }
    eprintln!("95 % intervals missing the truth: {misses} of 18 (slice)");
    assert!(misses <= MAX_MISSES_OF_18);
}

/// The same steady-start record fitted as if it started at rest cannot match it: the fit is
/// refused or its intervals miss the truth (what the detection prevents).
#[test]
fn a_steady_start_fitted_from_rest_is_not_a_result() {
    let Ok(fit) = fit_from(&from_steady(SEEDS[0]), InitialState::Rest) else {
        return;
    };
    let inside = fit.ci95.is_some_and(|ci| {
        ci.named()
            .iter()
            .map(|(_, c)| c)
            .zip(servo().values())
            .all(|([lo, hi], want)| *lo <= want && want <= *hi)
    });
    assert!(
        !(fit.accepted() && inside),
        "a steady start fitted from rest matched the truth: {:?}",
        fit.params
    );
}

/// A fast motor stepped at the first sample, its time constants a few samples long (τe = 3.2
/// and τm = 6.7 sample periods at 430 Hz, the motor of the heavy property run's case 136),
/// recorded by a 12-bit logger with a 500-count encoder: it starts at rest, and is seen so on
/// seeds 1, 2, 3. Its angle turns as t³ and then bends within the first six samples, so the
/// parabola through them has a slope of tens of rad/s at t = 0; read as the speed, that made
/// the record a slice of a longer run, fitted from a free initial state with L and J biased by
/// about one half-width of their intervals on every seed.
#[test]
fn a_fast_motor_stepped_at_the_first_sample_starts_at_rest() {
    let motor = MotorParams::new(1.847, 0.013_72, 0.015_51, 1.494e-5, 2.341e-7, 5.19e-4).unwrap();
    let rate_hz = 430.0;
    for seed in SEEDS {
        let trace = Simulator::new(motor, Effects::none(), Input::step(17.5, 0.0).unwrap())
            .unwrap()
            .run(1.0, rate_hz)
            .unwrap();
        let ranges =
            [&trace.voltage, &trace.current, &trace.speed].map(|s| motor_model::Range::covering(s));
        let rec = MeasurementModel::logger(12, ranges, 1.0, 500, seed)
            .apply(&trace)
            .unwrap();
        let (input, _) = voltage_levels(&rec.t, &rec.voltage, None).unwrap();
        let detected = detect_initial_state(&excited(&rec, &input)).unwrap();
        assert_eq!(
            detected.state,
            InitialState::Rest,
            "seed {seed}: {}",
            detected.reason
        );
    }
}
