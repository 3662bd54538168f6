//! Appendix D: E(t) = 0.1 sin(πt/10) V on the paper's motor shows stick-slip.

use motor_model::{Effects, Input, MotorParams, Simulator, Trace};

const AMPLITUDE_V: f64 = 0.1;
const FREQUENCY_HZ: f64 = 0.05; // πt/10 = 2π·0.05·t
const RATE_HZ: f64 = 1000.0;

fn appendix_d() -> Trace {
    let input = Input::sine(AMPLITUDE_V, FREQUENCY_HZ).unwrap();
    Simulator::new(MotorParams::paper(), Effects::none(), input)
        .unwrap()
        .run(60.0, RATE_HZ)
        .unwrap()
}

/// Maximal runs of equal `stuck` flags: (first index, last index, stuck).
fn runs(stuck: &[bool]) -> Vec<(usize, usize, bool)> {
    let mut out: Vec<(usize, usize, bool)> = Vec::new();
    for (i, &s) in stuck.iter().enumerate() {
        match out.last_mut() {
            Some(run) if run.2 == s => run.1 = i,
            _ => out.push((i, i, s)),
        }
    }
    out
}

/// Current while stuck, from (t_s, i_s), solving L dI/dt = A sin(ωt) − R I exactly.
fn stuck_current(p: &MotorParams, t_s: f64, i_s: f64, t: f64) -> f64 {
    let w = std::f64::consts::TAU * FREQUENCY_HZ;
    let (r, l) = (p.r_ohm, p.l_henry);
    let particular = |t: f64| {
        AMPLITUDE_V / (r * r + (w * l).powi(2)) * (r * (w * t).sin() - w * l * (w * t).cos())
    };
    particular(t) + (i_s - particular(t_s)) * (-(t - t_s) * r / l).exp()
}

#[test]
fn speed_is_exactly_zero_while_stuck_and_the_motor_moves_in_between() {
    let trace = appendix_d();
    let mut stuck_samples = 0;
    for (i, &s) in trace.stuck.iter().enumerate() {
        if s {
            stuck_samples += 1;
            assert_eq!(
                trace.speed[i], 0.0,
                "speed at t = {} while stuck",
                trace.t[i]
            );
        }
    }
    let moving = trace.stuck.len() - stuck_samples;
    assert!(
        stuck_samples > 1000 && moving > 1000,
        "{stuck_samples} stuck, {moving} moving"
    );
}

#[test]
fn motor_sticks_again_after_each_reversal() {
    let trace = appendix_d();
    let moving_runs: Vec<(usize, usize)> = runs(&trace.stuck)
        .into_iter()
        .filter(|r| !r.2)
        .map(|r| (r.0, r.1))
        .collect();
    // One moving interval per half period of the 20 s sine over 60 s: 6.
    assert_eq!(moving_runs.len(), 6, "moving intervals: {moving_runs:?}");
    // Directions alternate: each reversal of E passes through a stuck interval.
    let dirs: Vec<f64> = moving_runs
        .iter()
        .map(|&(a, b)| trace.speed[(a + b) / 2].signum())
        .collect();
    for pair in dirs.windows(2) {
        assert_eq!(pair[0], -pair[1], "directions {dirs:?}");
    }
    // Speed never changes sign inside a moving interval.
    for &(a, b) in &moving_runs {
        let d = trace.speed[(a + b) / 2].signum();
        assert!(trace.speed[a..=b].iter().all(|w| w * d >= 0.0));
    }
}

/// The stuck intervals end exactly where the analytic breakaway condition |k I| > Ts first
/// holds for the standstill current of Eq. (1) under the sine input: within one sample.
#[test]
fn stuck_intervals_match_the_analytic_breakaway_condition() {
    let p = MotorParams::paper();
    let trace = appendix_d();
    let dt = 1.0 / RATE_HZ;
    let mut checked = 0;
    for (first, last, stuck) in runs(&trace.stuck) {
        if !stuck || last + 1 >= trace.t.len() {
            continue;
        }
        // Every stuck sample satisfies the holding condition |k I| ≤ Ts.
        for i in first..=last {
            assert!(p.k_nm_per_a * trace.current[i].abs() <= p.ts_nm * (1.0 + 1e-12));
        }
        // Analytic breakaway from the first stuck sample on, by bisection on a 1 ms scan.
        let (t_s, i_s) = (trace.t[first], trace.current[first]);
        let holds = |t: f64| p.k_nm_per_a * stuck_current(&p, t_s, i_s, t).abs() <= p.ts_nm;
        let mut t = t_s;
        while holds(t + dt) {
            t += dt;
        }
        let (mut lo, mut hi) = (t, t + dt);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if holds(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let t_break = hi;
        // The simulator's last stuck sample is before t_break and its next sample after it.
        assert!(
            trace.t[last] <= t_break + 1e-9 && t_break <= trace.t[last + 1] + 1e-9,
            "analytic breakaway at {t_break} s, simulator between {} and {} s",
            trace.t[last],
            trace.t[last + 1]
        );
        checked += 1;
    }
    assert!(
        checked >= 5,
        "only {checked} stuck intervals ended inside the record"
    );
}

/// A staircase with a reversal and a hold at 0 V: each level settles to the steady state of
/// Eq. (2) at that level whatever came before, and the rotor sticks while the hold lasts.
#[test]
fn staircase_levels_reach_their_own_steady_states() {
    let p = MotorParams::paper();
    let levels = [(1.0, 20.0), (101.0, -10.0), (201.0, 0.0), (251.0, 40.0)];
    let input = Input::piecewise(&levels).unwrap();
    let trace = Simulator::new(p, Effects::none(), input)
        .unwrap()
        .run(350.0, 100.0)
        .unwrap();
    // Last sample before each change, and the end.
    for (k, &(_, volts)) in levels.iter().enumerate() {
        let t_end = levels.get(k + 1).map_or(350.0, |l| l.0 - 0.01);
        let i = (t_end * 100.0_f64).round() as usize;
        assert_eq!(trace.voltage[i], volts, "level {k}");
        let steady = motor_model::steady_state(&p, volts);
        assert!(
            (trace.speed[i] - steady.speed_rad_s).abs() < 1e-3 * (1.0 + steady.speed_rad_s.abs()),
            "level {k}: speed {} vs steady {}",
            trace.speed[i],
            steady.speed_rad_s
        );
        assert!(
            (trace.current[i] - steady.current_a).abs() < 1e-3 * (1.0 + steady.current_a.abs()),
            "level {k}: current {} vs steady {}",
            trace.current[i],
            steady.current_a
        );
    }
    // Stuck through the 0 V hold once the rotor has stopped.
    assert!(trace.stuck[240 * 100..251 * 100].iter().all(|&s| s));
    // A single level equals the step input sample for sample.
    let step = Simulator::new(p, Effects::none(), Input::step(20.0, 1.0).unwrap())
        .unwrap()
        .run(20.0, 100.0)
        .unwrap();
    let one = Simulator::new(
        p,
        Effects::none(),
        Input::piecewise(&[(1.0, 20.0)]).unwrap(),
    )
    .unwrap()
    .run(20.0, 100.0)
    .unwrap();
    assert_eq!(step, one);
}

/// A step that falls on a sample instant (a staircase level at 25 sample periods) is applied
/// from its instant on, not a sixth of an RK4 step early: the simulated current matches the
/// exact response to the integrator's accuracy (it was 0.35 % of the current step off).
#[test]
fn a_step_on_a_sample_instant_is_applied_at_its_instant() {
    let p = MotorParams::new(2.0, 2e-3, 0.05, 1e-5, 1e-5, 5e-3).unwrap();
    let (volts, at, rate) = (12.0, 0.005, 5000.0);
    let sim = Simulator::new(p, Effects::none(), Input::step(volts, at).unwrap())
        .unwrap()
        .run(0.05, rate)
        .unwrap();
    let exact = motor_model::StepResponse::new(&p, volts)
        .trace(at, 0.05, rate)
        .unwrap();
    let worst = sim
        .current
        .iter()
        .zip(&exact.current)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-6 * volts / p.r_ohm,
        "largest current error {worst:e} A"
    );
}

/// A simulation started at the steady state of its constant voltage (Eqs. (4), (5)) stays
/// there: moving above breakaway, stuck with `I = E/R` below it; a rotor started moving at 0 V
/// coasts and sticks for good.
#[test]
fn a_simulation_started_at_its_steady_state_stays_there() {
    let p = MotorParams::paper();
    for volts in [40.0, -20.0, 0.1] {
        let s = motor_model::steady_state(&p, volts);
        let trace = Simulator::new(
            p,
            Effects::none(),
            Input::piecewise(&[(0.0, volts)]).unwrap(),
        )
        .unwrap()
        .with_initial_state(s.current_a, s.speed_rad_s)
        .unwrap()
        .run(5.0, 100.0)
        .unwrap();
        for i in 0..trace.t.len() {
            assert!(
                (trace.current[i] - s.current_a).abs() < 1e-9 * s.current_a.abs().max(1.0),
                "{volts} V, sample {i}: {} A vs {} A",
                trace.current[i],
                s.current_a
            );
            assert!(
                (trace.speed[i] - s.speed_rad_s).abs() < 1e-9 * s.speed_rad_s.abs().max(1.0),
                "{volts} V, sample {i}: {} rad/s vs {} rad/s",
                trace.speed[i],
                s.speed_rad_s
            );
            assert_eq!(trace.stuck[i], !s.moving, "{volts} V, sample {i}");
        }
    }
    let coast = Simulator::new(p, Effects::none(), Input::piecewise(&[(0.0, 0.0)]).unwrap())
        .unwrap()
        .with_initial_state(0.0, 50.0)
        .unwrap()
        .run(60.0, 100.0)
        .unwrap();
    assert!(!coast.stuck[0] && coast.speed[1] < 50.0 && coast.speed[1] > 0.0);
    let last = coast.t.len() - 1;
    assert!(coast.stuck[last] && coast.speed[last] == 0.0);
    assert!(coast.speed.iter().all(|w| *w >= 0.0));
    assert!(
        Simulator::new(p, Effects::none(), Input::piecewise(&[(0.0, 0.0)]).unwrap())
            .unwrap()
            .with_initial_state(f64::NAN, 0.0)
            .is_err()
    );
}
