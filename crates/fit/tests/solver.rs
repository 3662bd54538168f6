//! The (33) Jacobian against finite differences, and the solver's termination reasons.

use fit::{
    fit_33, solve, LeastSquares, LmSettings, NormalEquations, Params33, Record33, Termination,
};
use motor_model::paper::normalized_current_33;
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

/// The model (33) evaluated directly (no recurrence), for finite differences.
fn model(p: &Params33, t_first: f64, dt: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| normalized_current_33(p.alpha, p.sigma, p.omega_a, t_first + i as f64 * dt))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// JᵀJ and Jᵀr from the streaming analytic Jacobian equal those of a central-difference
    /// Jacobian of the directly evaluated model. Tolerance 1e-6 relative: central differences
    /// with h = 1e-6·|p| are accurate to ~h² ≈ 1e-12 relative in J, rounding ~1e-10.
    #[test]
    fn jacobian_33_matches_finite_differences(
        alpha in 0.5f64..20.0, sigma in 0.1f64..5.0, ratio in 0.2f64..0.95,
        dt in 1e-3f64..0.05, n in 10usize..3000, noise_seed in 0u64..1000,
    ) {
        let p = Params33 { alpha, sigma, omega_a: ratio * sigma };
        let mut rng = motor_model::NoiseRng::new(noise_seed);
        let y: Vec<f64> = (0..n).map(|i| normalized_current_33(alpha * 1.1, sigma * 0.9, ratio * sigma, i as f64 * dt) + 0.01 * rng.normal()).collect();
        let record = Record33 { t_first: 0.0, dt, normalized_current: &y };
        let analytic = record.normal_equations(&[p.alpha, p.sigma, p.omega_a]).unwrap();
        let r: Vec<f64> = model(&p, 0.0, dt, n).iter().zip(&y).map(|(m, yi)| m - yi).collect();
        let mut jac = DMatrix::zeros(n, 3);
        for k in 0..3 {
            let mut up = [p.alpha, p.sigma, p.omega_a];
            let mut down = up;
            let h = 1e-6 * up[k].abs();
            up[k] += h;
            down[k] -= h;
            let pu = Params33 { alpha: up[0], sigma: up[1], omega_a: up[2] };
            let pd = Params33 { alpha: down[0], sigma: down[1], omega_a: down[2] };
            // Difference the model, not the residuals: the data may be far larger than the
            // model (here up to ~1e7), and r(p+h) − r(p−h) would cancel away every digit.
            let (mu, md) = (model(&pu, 0.0, dt, n), model(&pd, 0.0, dt, n));
            for i in 0..n {
                jac[(i, k)] = (mu[i] - md[i]) / (2.0 * h);
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * DVector::from_vec(r.clone());
        let cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
        prop_assert!((analytic.cost - cost).abs() <= 1e-9 * cost.max(1e-12));
        let scale = jtj.amax();
        for (a, b) in analytic.jtj.iter().zip(jtj.iter()) {
            prop_assert!((a - b).abs() <= 1e-6 * scale, "JᵀJ {a} vs {b}");
        }
        let scale_r = jtr.amax().max(1e-12);
        for (a, b) in analytic.jtr.iter().zip(jtr.iter()) {
            prop_assert!((a - b).abs() <= 1e-6 * scale_r.max(scale.sqrt() * cost.sqrt()), "Jᵀr {a} vs {b}");
        }
    }
}

/// A problem whose cost is NaN everywhere.
struct Broken;
impl LeastSquares for Broken {
    fn n_params(&self) -> usize {
        1
    }
    fn cost(&self, _: &[f64]) -> Option<f64> {
        Some(f64::NAN)
    }
    fn normal_equations(&self, _: &[f64]) -> Option<NormalEquations> {
        Some(NormalEquations {
            jtj: DMatrix::from_element(1, 1, f64::NAN),
            jtr: DVector::from_element(1, f64::NAN),
            cost: f64::NAN,
            n_residuals: 3,
        })
    }
}

/// Rosenbrock as residuals r = [10(y − x²), 1 − x]: a slow valley.
struct Rosenbrock;
impl LeastSquares for Rosenbrock {
    fn n_params(&self) -> usize {
        2
    }
    fn cost(&self, p: &[f64]) -> Option<f64> {
        let r = [10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        Some(0.5 * (r[0] * r[0] + r[1] * r[1]))
    }
    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations> {
        let r = DVector::from_vec(vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]]);
        let j = DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0]);
        Some(NormalEquations {
            jtj: j.transpose() * &j,
            jtr: j.transpose() * &r,
            cost: 0.5 * r.norm_squared(),
            n_residuals: 2,
        })
    }
}

#[test]
fn termination_reasons_are_reported_not_raised() {
    let nan = solve(&Broken, &[1.0], LmSettings::default()).unwrap();
    assert_eq!(nan.termination, Termination::NonFinite);
    assert!(!nan.termination.converged());

    let short = solve(
        &Rosenbrock,
        &[-1.2, 1.0],
        LmSettings {
            max_iters: 3,
            ..LmSettings::default()
        },
    )
    .unwrap();
    assert_eq!(short.termination, Termination::MaxIterations);
    assert_eq!(short.iterations, 3);

    // The evaluation budget bounds a fit whatever its iteration budget.
    let starved = solve(
        &Rosenbrock,
        &[-1.2, 1.0],
        LmSettings {
            max_evaluations: 4,
            ..LmSettings::default()
        },
    )
    .unwrap();
    assert_eq!(starved.termination, Termination::MaxEvaluations);
    assert!(!starved.termination.converged());
    assert!(LmSettings {
        max_evaluations: 0,
        ..LmSettings::default()
    }
    .validated()
    .is_err());

    let full = solve(&Rosenbrock, &[-1.2, 1.0], LmSettings::default()).unwrap();
    assert!(full.termination.converged(), "{:?}", full.termination);
    assert!((full.params[0] - 1.0).abs() < 1e-6 && (full.params[1] - 1.0).abs() < 1e-6);

    assert!(LmSettings {
        ftol: -1.0,
        ..LmSettings::default()
    }
    .validated()
    .is_err());
    assert!(solve(&Rosenbrock, &[1.0], LmSettings::default()).is_err());
}

#[test]
fn bad_records_are_typed_errors() {
    let start = Params33 {
        alpha: 1.0,
        sigma: 1.0,
        omega_a: 0.5,
    };
    let cases: [(&[f64], f64, &str); 3] = [
        (&[1.0, 2.0], 0.01, "at least 4"),
        (&[0.0, 0.5, f64::NAN, 1.0, 1.0], 0.01, "sample 2 is NaN"),
        (&[0.0, 0.5, 1.0, 1.0, 1.0], 0.0, "positive period"),
    ];
    for (y, dt, needle) in cases {
        let record = Record33 {
            t_first: 0.0,
            dt,
            normalized_current: y,
        };
        let err = fit_33(&record, start, LmSettings::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains(needle), "{err}");
    }
}
