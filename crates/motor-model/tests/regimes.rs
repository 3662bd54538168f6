//! The exact response against the ODE simulator and against the paper's closed forms, in all
//! three damping regimes and across their boundaries.

use motor_model::paper::{current_components, speed_c4};
use motor_model::{
    breakaway_time, Derived, Effects, Input, MotorParams, Regime, Simulator, StepResponse,
};
use proptest::prelude::*;

/// A motor with the requested damping ratio, built from `a = R/L`, `κ = k²/(LJ)` (as a multiple
/// `m` of `a²`) and solving ζ² = ((a+b)/2)² / (ab + κ) for `b = f/J` (the larger root).
fn motor_with_zeta(
    zeta: f64,
    r: f64,
    a: f64,
    m: f64,
    j: f64,
    rho: f64,
) -> Option<(MotorParams, f64)> {
    let l = r / a;
    let kappa = m * a * a;
    let k = (kappa * l * j).sqrt();
    let disc = a * a * (zeta * zeta - 1.0) + kappa;
    if disc < 0.0 {
        return None;
    }
    let b = (2.0 * zeta * zeta - 1.0) * a + 2.0 * zeta * disc.sqrt();
    if b <= 0.0 {
        return None;
    }
    let f = b * j;
    // Step voltage so that R Ts/(k E) = rho: the motor breaks away at t0 of Eq. (11).
    let e = 10.0;
    let ts = rho * k * e / r;
    Some((MotorParams::new(r, l, k, f, j, ts).ok()?, e))
}

/// Compares the exact response with the ODE simulation over ~8 slow time constants.
/// Tolerance: 1e-6 of the final current and speed (acceptance 1 of the model issue); the RK4
/// step of 1/40 of the fastest time constant is good to ~1e-9.
fn check_against_ode(p: MotorParams, e: f64) -> Result<(), TestCaseError> {
    let d = Derived::new(&p);
    let q = d.sigma * d.sigma - d.omega_n * d.omega_n;
    let slow_rate = if q > 0.0 {
        d.omega_n * d.omega_n / (d.sigma + q.sqrt())
    } else {
        d.sigma
    };
    let t0 = breakaway_time(&p, e).unwrap();
    let t_end = t0 + 8.0 / slow_rate;
    let rate = 2000.0 / t_end;
    let exact = StepResponse::new(&p, e);
    let (i_r, w_r) = exact.steady();
    let trace = Simulator::new(p, Effects::none(), Input::step(e, 0.0).unwrap())
        .unwrap()
        .run(t_end, rate)
        .unwrap();
    let mut grid = vec![Default::default(); trace.t.len()];
    exact.fill(0.0, 1.0 / rate, &mut grid);
    // The analytic form assumes the rotor keeps turning forwards after breakaway.
    prop_assume!(grid
        .iter()
        .zip(&trace.t)
        .all(|(s, &t)| t <= t0 || s.speed_rad_s > 0.0));
    for (i, s) in grid.iter().enumerate() {
        let t = trace.t[i];
        prop_assert!(
            (s.current_a - trace.current[i]).abs() <= 1e-6 * i_r.abs(),
            "current at t = {t}: exact {} vs ODE {} (ζ = {})",
            s.current_a,
            trace.current[i],
            d.zeta
        );
        prop_assert!(
            (s.speed_rad_s - trace.speed[i]).abs() <= 1e-6 * w_r.abs(),
            "speed at t = {t}: exact {} vs ODE {} (ζ = {})",
            s.speed_rad_s,
            trace.speed[i],
            d.zeta
        );
        // The grid walk and the pointwise evaluation are the same function.
        let pointwise = exact.at(t);
        prop_assert!((pointwise.current_a - s.current_a).abs() <= 1e-9 * i_r.abs());
        prop_assert!(
            (pointwise.position_rad - s.position_rad).abs() <= 1e-9 * (1.0 + s.position_rad.abs())
        );
    }
    Ok(())
}

fn shape() -> impl Strategy<Value = (f64, f64, f64, f64)> {
    // R [Ω], a = R/L [1/s], J [kg m²], rho = R Ts/(k E)
    (0.1f64..10.0, 1.0f64..1000.0, 1e-5f64..1.0, 0.01f64..0.9)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn overdamped_matches_ode((r, a, j, rho) in shape(), zeta in 1.05f64..8.0, m in 0.01f64..3.0) {
        let (p, e) = motor_with_zeta(zeta, r, a, m, j, rho).unwrap();
        prop_assert_eq!(Derived::new(&p).regime, Regime::Overdamped);
        check_against_ode(p, e)?;
    }

    #[test]
    fn underdamped_matches_ode((r, a, j, rho) in shape(), zeta in 0.2f64..0.95, u in 0.05f64..3.0) {
        let m = (1.0 - zeta * zeta) * (1.0 + u);
        let made = motor_with_zeta(zeta, r, a, m, j, rho);
        prop_assume!(made.is_some());
        let (p, e) = made.unwrap();
        prop_assert_eq!(Derived::new(&p).regime, Regime::Underdamped);
        check_against_ode(p, e)?;
    }

    #[test]
    fn near_critical_matches_ode((r, a, j, rho) in shape(), delta in -1e-6f64..1e-6, m in 0.01f64..3.0) {
        let (p, e) = motor_with_zeta(1.0 + delta, r, a, m, j, rho).unwrap();
        prop_assert!((Derived::new(&p).zeta - 1.0).abs() < 2e-6);
        check_against_ode(p, e)?;
    }

    /// Continuity across ζ = 1: motors at 1 − ε, 1 and 1 + ε respond alike to O(ε).
    #[test]
    fn exact_form_is_continuous_across_critical((r, a, j, rho) in shape(), m in 0.01f64..3.0, eps_exp in -12i32..-3) {
        let eps = 10f64.powi(eps_exp);
        let (lo, e) = motor_with_zeta(1.0 - eps, r, a, m, j, rho).unwrap();
        let (mid, _) = motor_with_zeta(1.0, r, a, m, j, rho).unwrap();
        let (hi, _) = motor_with_zeta(1.0 + eps, r, a, m, j, rho).unwrap();
        let d = Derived::new(&mid);
        let t0 = breakaway_time(&mid, e).unwrap();
        let (i_r, w_r) = StepResponse::new(&mid, e).steady();
        for n in 0..50 {
            let t = t0 + n as f64 * 0.2 / d.sigma;
            let s = StepResponse::new(&mid, e).at(t);
            for other in [&lo, &hi] {
                let o = StepResponse::new(other, e).at(t);
                // Responses move by O(ε) when ζ does; 50ε of the final values bounds it.
                prop_assert!((o.current_a - s.current_a).abs() <= 50.0 * eps * i_r.abs() + 1e-12 * i_r.abs());
                prop_assert!((o.speed_rad_s - s.speed_rad_s).abs() <= 50.0 * eps * w_r.abs() + 1e-12 * w_r.abs());
            }
        }
    }

    /// The paper's forms (13)–(15) (ζ > 1) and corrected (B.11)–(B.13) (ζ < 1) against the
    /// exact response, to rounding (1e-9 of the final value).
    #[test]
    fn paper_current_forms_match_exact((r, a, j, rho) in shape(), zeta in prop_oneof![0.2f64..0.95, 1.05f64..8.0], m in 0.3f64..3.0) {
        let made = motor_with_zeta(zeta, r, a, m, j, rho);
        prop_assume!(made.is_some());
        let (p, e) = made.unwrap();
        let d = Derived::new(&p);
        prop_assume!(d.tau_m > d.tau_e);
        let exact = StepResponse::new(&p, e);
        let t0 = exact.breakaway_time().unwrap();
        let (i_r, w_r) = exact.steady();
        for n in 0..40 {
            let tau = n as f64 * 0.25 / d.sigma;
            let s = exact.at(t0 + tau);
            let c = current_components(&p, e, tau).unwrap();
            prop_assert!((c.total() - s.current_a).abs() <= 1e-9 * i_r.abs(), "ζ = {}, τ = {tau}: paper {} exact {}", d.zeta, c.total(), s.current_a);
            if d.regime == Regime::Overdamped {
                let w = speed_c4(&p, e, tau).unwrap();
                prop_assert!((w - s.speed_rad_s).abs() <= 1e-9 * w_r.abs(), "C.4 at ζ = {}", d.zeta);
            }
        }
    }
}

/// A motor that is critically damped in exact binary arithmetic: R/L = 6, k²/(LJ) = 1,
/// f/J = 4, so σ = ωn = 5 and σ² − ωn² = 0; τm = 0.25 s > τe = 1/6 s, inside the domain of
/// the ζ > 1 forms.
fn exactly_critical(f_scale: f64) -> MotorParams {
    MotorParams::new(6.0, 1.0, 1.0, 4.0 * f_scale, 1.0, 0.5).unwrap()
}

#[test]
fn critical_forms_b14_b16_match_exact_and_neighbours() {
    let p = exactly_critical(1.0);
    assert_eq!(Derived::new(&p).regime, Regime::Critical);
    let e = 10.0;
    let exact = StepResponse::new(&p, e);
    let t0 = exact.breakaway_time().unwrap();
    let (i_r, _) = exact.steady();
    for n in 0..60 {
        let tau = n as f64 * 0.02;
        let c = current_components(&p, e, tau).unwrap();
        assert!(
            (c.total() - exact.at(t0 + tau).current_a).abs() < 1e-12 * i_r,
            "τ = {tau}"
        );
    }
    // Regime boundaries: the ζ > 1 and ζ < 1 forms of slightly perturbed motors tend to the
    // critical form. Their error grows like 1/√|ζ²−1| times rounding, so ε = 1e-6 is used and
    // the tolerance is 1e-4 of the final current (the motor moves by ~ε, rounding costs
    // ~1e-16/√ε ≈ 1e-13, and α, γ ≈ 700 amplify the rest).
    for f_scale in [1.0 - 1e-6, 1.0 + 1e-6] {
        let near = exactly_critical(f_scale);
        let regime = Derived::new(&near).regime;
        assert_ne!(regime, Regime::Critical);
        for n in 0..60 {
            let tau = n as f64 * 0.02;
            let a = current_components(&near, e, tau).unwrap().total();
            let b = current_components(&p, e, tau).unwrap().total();
            assert!(
                (a - b).abs() < 1e-4 * i_r,
                "{regime:?} at τ = {tau}: {a} vs {b}"
            );
        }
    }
}

/// Erratum E4: (B.16) as printed, `1 − e^{−ωn τ}[1 + ωn(τm − 1)τ]`, is not the critical
/// response; the corrected `1 + ωn(1 − ωn τm)τ` is (see docs/errata.md).
#[test]
fn erratum_b16_printed_form_is_wrong() {
    let p = exactly_critical(1.0);
    let d = Derived::new(&p);
    let e = 10.0;
    let i_e_printed = |tau: f64| {
        d.k_e * e * (1.0 - (-d.omega_n * tau).exp() * (1.0 + d.omega_n * (d.tau_m - 1.0) * tau))
    };
    let tau = 0.3;
    let corrected = current_components(&p, e, tau).unwrap().i_e;
    let err = (i_e_printed(tau) - corrected).abs() / (d.k_e * e);
    assert!(
        err > 0.05,
        "printed (B.16) differs from the corrected form by {err}"
    );
}

/// Errata E2, E3: (B.12) and (B.13) as printed (principal sin⁻¹, sign of (B.12)) violate the
/// initial conditions I_Ts'(0) = 0 and I_E'(0) = KE E τm ωn², for a usual motor (τm ωn > ζ).
#[test]
fn errata_b12_b13_printed_forms_are_wrong() {
    // Underdamped, τm ωn > ζ: R = 1, L = 0.1, k = 0.5, f = 0.01, J = 0.01.
    let p = MotorParams::new(1.0, 0.1, 0.5, 0.01, 0.01, 0.01).unwrap();
    let d = Derived::new(&p);
    assert_eq!(d.regime, Regime::Underdamped);
    assert!(d.tau_m * d.omega_n > d.zeta);
    let (alpha, gamma) = (d.alpha.unwrap(), d.gamma.unwrap());
    let h = 1e-6;
    let b12_printed =
        |t: f64| 1.0 + gamma * (-d.sigma * t).exp() * (d.omega_a * t + (-1.0 / gamma).asin()).sin();
    let b13_printed =
        |t: f64| 1.0 - alpha * (-d.sigma * t).exp() * (d.omega_a * t + (1.0 / alpha).asin()).sin();
    // Normalised derivatives at τ = 0 (both forms start at 0).
    let slope_b12 = (b12_printed(h) - b12_printed(0.0)) / h;
    let slope_b13 = (b13_printed(h) - b13_printed(0.0)) / h;
    assert!(b12_printed(0.0).abs() < 1e-12 && b13_printed(0.0).abs() < 1e-12);
    assert!(
        (slope_b12 - 0.0).abs() > 0.1 * d.sigma,
        "printed (B.12) slope {slope_b12}"
    );
    let wanted = d.tau_m * d.omega_n * d.omega_n;
    assert!(
        (slope_b13 - wanted).abs() > 0.1 * wanted,
        "printed (B.13) slope {slope_b13}"
    );
    // The corrected forms have the right slopes.
    let c = |tau: f64| current_components(&p, 1.0, tau).unwrap();
    let ts_slope = (c(h).i_ts - c(0.0).i_ts) / h / (d.k_s * p.ts_nm);
    let e_slope = (c(h).i_e - c(0.0).i_e) / h / d.k_e;
    assert!(
        ts_slope.abs() < 1e-4 * d.sigma,
        "corrected (B.12) slope {ts_slope}"
    );
    assert!(
        (e_slope - wanted).abs() < 1e-4 * wanted,
        "corrected (B.13) slope {e_slope}"
    );
}

#[test]
fn paper_forms_refuse_motors_outside_their_domain() {
    // τe > τm: α of (24) is not real.
    let p = MotorParams::new(1.0, 10.0, 0.1, 1.0, 0.1, 0.01).unwrap();
    assert_eq!(Derived::new(&p).regime, Regime::Overdamped);
    assert!(current_components(&p, 10.0, 1.0).is_err());
    assert!(speed_c4(&p, 10.0, 1.0).is_err());
    // But the exact form still agrees with the ODE there.
    check_against_ode(p, 10.0).unwrap();
}

#[test]
fn negative_step_mirrors_positive_and_weak_step_never_moves() {
    let p = MotorParams::paper();
    let pos = StepResponse::new(&p, 40.0);
    let neg = StepResponse::new(&p, -40.0);
    for t in [0.0, 0.001, 0.1, 3.0, 50.0] {
        let (a, b) = (pos.at(t), neg.at(t));
        assert_eq!(a.current_a, -b.current_a);
        assert_eq!(a.speed_rad_s, -b.speed_rad_s);
        assert_eq!(a.position_rad, -b.position_rad);
    }
    // |E| ≤ R Ts / k = 0.06 V: Eq. (1) for ever.
    let weak = StepResponse::new(&p, 0.05);
    assert_eq!(weak.breakaway_time(), None);
    let s = weak.at(100.0);
    assert_eq!(s.speed_rad_s, 0.0);
    assert!((s.current_a - 0.05 / 0.3).abs() < 1e-12);
}
