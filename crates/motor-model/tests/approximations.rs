//! The paper's approximations (31)–(33), (C.6), (C.8) and the apparent-resistance law (6)–(9),
//! checked against the exact response with the paper's own claims as tolerances.

use motor_model::paper::{
    approximate_speed_c6, high_voltage_current_32, high_voltage_threshold_31,
    normalized_current_33, normalized_speed_c8,
};
use motor_model::{steady_state, ApparentResistance, Derived, MotorParams, StepResponse};

/// Fig. C-2: normalised by its final value, the speed after breakaway *is* (C.8) when the time
/// origin is t0 (the Coulomb and initial-current components only rescale it). Tolerance:
/// rounding, 1e-12.
#[test]
fn c8_is_the_normalised_speed_exactly_when_t0_is_known() {
    let p = MotorParams::paper();
    let d = Derived::new(&p);
    let gamma = d.gamma.unwrap();
    let mut eps3 = Vec::new();
    for e in [0.36, 2.5, 15.0, 40.0] {
        let step = StepResponse::new(&p, e);
        let t0 = step.breakaway_time().unwrap();
        let (_, w_r) = step.steady();
        let mut worst_t = 0.0_f64;
        for n in 0..2000 {
            let tau = n as f64 * 0.025;
            let w_n = step.at(t0 + tau).speed_rad_s / w_r;
            let c8 = normalized_speed_c8(gamma, d.sigma, d.omega_a, tau);
            assert!(
                (c8 - w_n).abs() < 1e-12,
                "E = {e}, τ = {tau}: {c8} vs {w_n}"
            );
            worst_t =
                worst_t.max((normalized_speed_c8(gamma, d.sigma, d.omega_a, t0 + tau) - w_n).abs());
        }
        eps3.push(worst_t);
    }
    // ε3 of Fig. C-2/C-3 (t used for τ, t0 ignored) shrinks as E grows.
    assert!(
        eps3.windows(2).all(|w| w[1] < w[0]),
        "ε3 by voltage: {eps3:?}"
    );
    assert!(eps3[0] > 1e-3 && *eps3.last().unwrap() < 1e-3, "{eps3:?}");
}

/// Fig. C-1: (C.6) enters and stays within ±5 % of (C.4) from 3.5 s on, for E ≥ 0.36 V.
#[test]
fn c6_is_within_five_percent_after_3_5_s() {
    let p = MotorParams::paper();
    for e in [0.36, 1.0, 2.5, 40.0] {
        let step = StepResponse::new(&p, e);
        let t0 = step.breakaway_time().unwrap();
        for n in 0..1000 {
            let tau = 3.5 + n as f64 * 0.1;
            let exact = step.at(t0 + tau).speed_rad_s;
            let approx = approximate_speed_c6(&p, e, tau).unwrap();
            assert!(
                ((approx - exact) / exact).abs() < 0.05,
                "E = {e}, τ = {tau}"
            );
        }
    }
}

/// (31)–(33): above the voltage of (31) the normalised current follows (33) to within 5 % of
/// its final value; well below it, it does not.
#[test]
fn high_voltage_approximation_32_33_holds_above_the_threshold_31() {
    let p = MotorParams::paper();
    let d = Derived::new(&p);
    let threshold = high_voltage_threshold_31(&p);
    assert!(
        (threshold - 3.0).abs() < 1e-12,
        "20 Ts (R/k + k/f) = 3 V for the paper's motor"
    );
    let worst = |e: f64| {
        let step = StepResponse::new(&p, e);
        let (i_r, _) = step.steady();
        (0..5000)
            .map(|n| {
                let t = n as f64 * 0.01;
                let i = step.at(t).current_a;
                let approx = high_voltage_current_32(&p, e, t).unwrap();
                assert_eq!(
                    approx,
                    d.k_e * e * normalized_current_33(d.alpha.unwrap(), d.sigma, d.omega_a, t)
                );
                (i / i_r - normalized_current_33(d.alpha.unwrap(), d.sigma, d.omega_a, t)).abs()
            })
            .fold(0.0_f64, f64::max)
    };
    for e in [1.2 * threshold, 15.0, 40.0] {
        assert!(worst(e) < 0.05, "E = {e}: {}", worst(e));
    }
    assert!(worst(0.5) > 0.05);
}

/// (6)–(9): E/Ir − R = a − b/Ir at every steady state, and Ts = k b/a.
#[test]
fn apparent_resistance_law_and_coulomb_torque() {
    let p = MotorParams::paper();
    let law = ApparentResistance::of_motor(&p);
    for e in [0.5, 1.0, 2.5, 10.0, 40.0] {
        let ss = steady_state(&p, e);
        assert!(ss.moving);
        let delta_r = e / ss.current_a - p.r_ohm;
        assert!(
            (delta_r - law.delta_r(ss.current_a)).abs() < 1e-12,
            "E = {e}"
        );
        // (4), (5) themselves.
        let w = (e * p.k_nm_per_a - p.ts_nm * p.r_ohm) / p.rf_plus_k2();
        assert!((ss.speed_rad_s - w).abs() < 1e-12);
        assert!((ss.current_a - (e - p.k_nm_per_a * w) / p.r_ohm).abs() < 1e-12);
    }
    assert!((law.coulomb_torque(p.k_nm_per_a).unwrap() - p.ts_nm).abs() < 1e-15);
    // The paper's remark on Fig. 3: ΔR varies by a few per cent over its three test voltages.
    let (lo, hi) = (
        law.delta_r(steady_state(&p, 1.0).current_a),
        law.delta_r(steady_state(&p, 40.0).current_a),
    );
    assert!((hi - lo) / hi > 0.01 && (hi - lo) / hi < 0.2);
}
