//! A simulation a fit differentiates must be smooth in the parameters: with the step fixed
//! ([`Simulator::with_max_step`]) and the speed bounded up front
//! ([`Simulator::with_speed_bound`]), no step instant depends on the state.

use motor_model::{Effect, Effects, Input, MotorParams, Simulator};

const RATE: f64 = 50.0;
const SECONDS: f64 = 10.0;

fn speed(amp: f64, fit_mode: Option<(f64, f64)>) -> Vec<f64> {
    let effect: Effect = format!("cogging_torque:amp={amp},n=6,phase=0.3")
        .parse()
        .unwrap();
    let mut sim = Simulator::new(
        MotorParams::paper(),
        Effects::none().with(effect),
        Input::step(10.0, 0.0).unwrap(),
    )
    .unwrap();
    if let Some((h, bound)) = fit_mode {
        sim = sim
            .with_max_step(h)
            .unwrap()
            .with_speed_bound(bound)
            .unwrap();
    }
    sim.run(SECONDS, RATE).unwrap().speed
}

/// Second differences of the cost over a scan of the cogging amplitude in steps of `delta`
/// \[N·m\]: for a cost smooth in the parameter they are `c'' δ²` (nearly constant over a
/// narrow scan); a jump ε of the cost anywhere shows as a second difference of order ε.
fn second_differences(fit_mode: (f64, f64), delta: f64) -> Vec<f64> {
    let reference = speed(0.02, Some(fit_mode));
    let costs: Vec<f64> = (0..41)
        .map(|i| {
            let amp = 0.021 + delta * i as f64;
            speed(amp, Some(fit_mode))
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).powi(2))
                .sum()
        })
        .collect();
    costs.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect()
}

#[test]
fn cost_is_smooth_in_the_cogging_amplitude_with_a_fixed_step_and_a_speed_bound() {
    let default_step = Simulator::new(
        MotorParams::paper(),
        Effects::none(),
        Input::step(10.0, 0.0).unwrap(),
    )
    .unwrap()
    .max_step_s();
    let peak = speed(0.02, None).iter().fold(0.0f64, |m, w| m.max(w.abs()));
    // Steps of 1e-7 N·m: c'' δ² ≈ 7e-13, far above the rounding of the cost (≈ 1e-16).
    let d2 = second_differences((0.5 * default_step, 1.2 * peak), 1e-7);
    let mut mags: Vec<f64> = d2.iter().map(|v| v.abs()).collect();
    mags.sort_by(f64::total_cmp);
    let median = mags[mags.len() / 2];
    assert!(median > 0.0);
    for (i, v) in d2.iter().enumerate() {
        assert!(
            *v > 0.0,
            "second difference {i} is {v:.3e}: the cost is not convex here"
        );
        assert!(
            *v < 1.5 * median,
            "second difference {i} is {v:.3e}, {:.2} times the median {median:.3e}: the cost jumps",
            v / median
        );
    }
}
