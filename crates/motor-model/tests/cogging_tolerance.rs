//! The cogging step a fit takes at its speed bound ([`Simulator::with_speed_bound_and_tolerance`])
//! is far longer than 1/40 of a cogging period, and still moves the simulated speed by less than
//! the tolerance it was given and the current by less than that tolerance through the back-EMF
//! (`k/R` of it), against the 1/40-period integration: from rest through breakaway, the rise,
//! the cogging ripple at full speed and a reversal through zero.

use motor_model::{Effect, Effects, Input, MotorParams, Simulator, Trace};

const RATE_HZ: f64 = 4000.0;

/// A fast small servo (a cogging ripple at about a sample rate at full speed, its steps bound
/// by the ripple rather than by its time constants) under a step, a reversal and a low step, and
/// the paper's motor under a reversal: each with cogging, and the record's length \[s\].
fn cases() -> Vec<(MotorParams, Effect, Input, f64)> {
    let servo = MotorParams::new(4.0, 1e-2, 0.03, 5e-6, 6e-6, 1e-3).unwrap();
    let servo_cogging: Effect = "cogging_torque:amp=8e-4,n=20,phase=0.4".parse().unwrap();
    let paper = MotorParams::paper();
    let paper_cogging: Effect = "cogging_torque:amp=0.02,n=12,phase=1.1".parse().unwrap();
    let reversal = |v: f64, s: f64| Input::piecewise(&[(0.0, v), (0.5 * s, -v)]).unwrap();
    vec![
        (servo, servo_cogging, Input::step(24.0, 0.0).unwrap(), 0.3),
        (servo, servo_cogging, reversal(24.0, 0.3), 0.3),
        (servo, servo_cogging, Input::step(0.5, 0.0).unwrap(), 0.3),
        (paper, paper_cogging, reversal(40.0, 20.0), 20.0),
    ]
}

fn run(sim: Simulator, seconds: f64) -> Trace {
    sim.run(seconds, RATE_HZ).unwrap()
}

fn largest_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn a_tolerance_lengthens_the_cogging_step_and_keeps_the_error_below_it() {
    for (case, (motor, effect, input, seconds)) in cases().into_iter().enumerate() {
        let sim = || Simulator::new(motor, Effects::none().with(effect), input.clone()).unwrap();
        let free = run(sim(), seconds);
        let peak = free.speed.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        assert!(peak > 0.0, "case {case}: the rotor never moved");
        let bound = 1.5 * peak;
        let fine = sim().with_speed_bound(bound).unwrap();
        let reference = run(fine.clone(), seconds);
        for tolerance in [1e-3, 1e-5, 1e-7, 1e-9, 1e-11] {
            let coarse = sim()
                .with_speed_bound_and_tolerance(bound, tolerance)
                .unwrap();
            assert!(coarse.max_step_s() >= fine.max_step_s());
            let trace = run(coarse.clone(), seconds);
            // What the longer step costs the nominal model alone (the plant's time constants,
            // the step factor's error): the tolerance is on what cogging adds to it.
            let nominal = |h: f64| {
                let sim = Simulator::new(motor, Effects::none(), input.clone())
                    .and_then(|s| s.with_max_step(h))
                    .unwrap()
                    .integrated();
                run(sim, seconds)
            };
            let (nominal_coarse, nominal_fine) =
                (nominal(coarse.max_step_s()), nominal(fine.max_step_s()));
            let nominal_speed = largest_difference(&nominal_coarse.speed, &nominal_fine.speed);
            let nominal_current =
                largest_difference(&nominal_coarse.current, &nominal_fine.current);
            let speed_error = largest_difference(&trace.speed, &reference.speed);
            let current_error = largest_difference(&trace.current, &reference.current);
            let through_emf = tolerance * motor.k_nm_per_a / motor.r_ohm;
            eprintln!(
                "case {case}, tolerance {tolerance:e} rad/s: step {:.2} times longer, speed off by \
                 {speed_error:.2e} rad/s, current by {current_error:.2e} A (the nominal model \
                 alone {nominal_speed:.2e} rad/s, {nominal_current:.2e} A)",
                coarse.max_step_s() / fine.max_step_s()
            );
            assert!(
                speed_error <= tolerance + nominal_speed,
                "case {case}, tolerance {tolerance:e} rad/s: speed off by {speed_error:.3e} rad/s"
            );
            assert!(
                current_error <= through_emf + nominal_current,
                "case {case}, tolerance {tolerance:e} rad/s: current off by {current_error:.3e} A, \
                 above {through_emf:.3e} A"
            );
        }
    }
}

#[test]
fn at_the_tolerance_of_a_noisy_record_the_cogging_step_is_a_quarter_period() {
    // The servo of the first case: a speed noise floor of 0.1 rad/s, 1 % of it.
    let (motor, effect, input, _) = cases().remove(0);
    let sim = Simulator::new(motor, Effects::none().with(effect), input).unwrap();
    let bound = 1200.0;
    let fine = sim.clone().with_speed_bound(bound).unwrap().max_step_s();
    let coarse = sim
        .with_speed_bound_and_tolerance(bound, 1e-3)
        .unwrap()
        .max_step_s();
    // 1/40 of a period and a quarter of one at the bound, unless the plant's own time
    // constants bound the step first.
    let period = std::f64::consts::TAU / (20.0 * bound);
    assert!((fine - period / 40.0).abs() < 1e-9 * period, "{fine:e}");
    assert!(coarse > 5.0 * fine, "{coarse:e} against {fine:e}");
    assert!(coarse <= period / 4.0 * (1.0 + 1e-12), "{coarse:e}");
}
