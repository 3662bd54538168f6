//! The exact propagation of the nominal model (matrix exponential of each mode) against the
//! RK4 integration of the same simulator ([`Simulator::integrated`]) and the closed-form step
//! response: staircases that stick, reverse and break away again, a sample period far above
//! the electrical time constant, and one longer than an underdamped motor's half period.

use motor_model::{Effects, Input, MotorParams, Simulator, StepResponse, Trace};

/// Largest difference between two traces per channel, over the channel's peak.
fn worst(a: &Trace, b: &Trace) -> [f64; 3] {
    let rel = |x: &[f64], y: &[f64]| {
        let peak = x.iter().fold(0.0_f64, |m, v| m.max(v.abs())).max(1e-300);
        x.iter()
            .zip(y)
            .fold(0.0_f64, |m, (p, q)| m.max((p - q).abs()))
            / peak
    };
    [
        rel(&a.current, &b.current),
        rel(&a.speed, &b.speed),
        rel(&a.position, &b.position),
    ]
}

/// Samples whose stuck flags differ (a switch within a sample may land either side of it
/// only where both integrations put it at that sample's edge).
fn flag_mismatches(a: &Trace, b: &Trace) -> usize {
    a.stuck.iter().zip(&b.stuck).filter(|(x, y)| x != y).count()
}

#[test]
fn staircase_with_reversals_agrees_with_rk4() {
    let motor = MotorParams::paper();
    // Breakaway, a reversal at speed, a stop at 0 V, a low level that breaks away again.
    let input = Input::piecewise(&[
        (0.5004, 40.0),
        (40.5007, -20.0),
        (80.5001, 0.0),
        (130.5003, 2.5),
    ])
    .unwrap();
    let sim = Simulator::new(motor, Effects::none(), input).unwrap();
    let exact = sim.run(170.0, 1000.0).unwrap();
    let rk4 = sim.clone().integrated().run(170.0, 1000.0).unwrap();
    let w = worst(&exact, &rk4);
    assert!(w.iter().all(|&e| e < 1e-7), "largest differences {w:?}");
    assert!(flag_mismatches(&exact, &rk4) <= 4);
    // It stuck at 0 V and moved on both sides of the reversal.
    assert!(exact.stuck[130_400] && !exact.stuck[20_000] && !exact.stuck[60_000]);
    assert!(!exact.stuck[160_000] && exact.speed[160_000] > 0.0);
    assert!(exact.speed[20_000] > 0.0 && exact.speed[60_000] < 0.0);
}

#[test]
fn sample_period_far_above_the_electrical_time_constant_is_exact() {
    // τe = 10 µs sampled every 10 ms: a thousand time constants a sample.
    let motor = MotorParams::new(2.0, 2e-5, 0.05, 1e-4, 2e-5, 2e-3).unwrap();
    let input = Input::step(12.0, 0.0).unwrap();
    let trace = Simulator::new(motor, Effects::none(), input)
        .unwrap()
        .run(2.0, 100.0)
        .unwrap();
    let reference = StepResponse::new(&motor, 12.0)
        .trace(0.0, 2.0, 100.0)
        .unwrap();
    let w = worst(&trace, &reference);
    assert!(w.iter().all(|&e| e < 1e-9), "largest differences {w:?}");
}

#[test]
fn underdamped_motor_sampled_slower_than_its_half_period_agrees_with_rk4() {
    // ω_d ≈ 313 rad/s (half period 10 ms), sampled every 25 ms; reversals under a ±PRBS.
    let motor = MotorParams::new(1.0, 0.01, 0.1, 1e-4, 1e-5, 2e-3).unwrap();
    let input = Input::prbs(3.0, 0.1, 0.0125, 3.0, 5).unwrap();
    let sim = Simulator::new(motor, Effects::none(), input).unwrap();
    let exact = sim.run(3.0, 40.0).unwrap();
    let rk4 = sim.clone().integrated().run(3.0, 40.0).unwrap();
    let w = worst(&exact, &rk4);
    assert!(w.iter().all(|&e| e < 1e-6), "largest differences {w:?}");
    assert_eq!(flag_mismatches(&exact, &rk4), 0);
    let reversals = exact.speed.windows(2).filter(|p| p[0] * p[1] < 0.0).count();
    assert!(reversals >= 5, "{reversals} reversals");
}

#[test]
fn a_started_state_and_a_step_agree_with_rk4() {
    // Coasting down from 100 rad/s with the voltage off: it sticks once, and stays.
    let motor = MotorParams::paper();
    let input = Input::piecewise(&[(0.0, 0.0), (30.0, 5.0)]).unwrap();
    let sim = Simulator::new(motor, Effects::none(), input)
        .unwrap()
        .with_initial_state(5.0, 100.0)
        .unwrap();
    let exact = sim.run(40.0, 200.0).unwrap();
    let rk4 = sim.clone().integrated().run(40.0, 200.0).unwrap();
    let w = worst(&exact, &rk4);
    assert!(w.iter().all(|&e| e < 1e-7), "largest differences {w:?}");
    assert!(flag_mismatches(&exact, &rk4) <= 2);
}
