//! Sec. 2.2: Ts from steady-state tests through the apparent resistance, Eqs. (6)–(9).
//!
//! With R and k known, each test at voltage E with steady current Ir gives
//! `ΔR = E/Ir − R = a − b/Ir` (8); fitting a and b over the tests gives `Ts = k b/a` (9).
//! The paper fits (8) by Gauss–Newton (`nlinfit`, Appendix A); this uses the same
//! Levenberg–Marquardt as everything else (the model is linear in a, b: it converges at once).

use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::estimation::lm::{solve, LeastSquares, LmSettings, NormalEquations, Termination};
use crate::estimation::stats::uncertainty;

/// Result of the apparent-resistance fit.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyFit {
    /// `a = k²/f` \[Ω\].
    pub a_ohm: f64,
    /// `b = Ts k/f` \[Ω·A\].
    pub b_ohm_a: f64,
    /// Eq. (9) `Ts = k b/a` \[N·m\].
    pub ts_nm: f64,
    /// 95 % intervals of a and b (None with fewer than 3 tests: no degrees of freedom).
    pub ci95: Option<[[f64; 2]; 2]>,
    /// `(Ir, ΔR)` of each test \[A, Ω\].
    pub points: Vec<(f64, f64)>,
    /// Why the solver stopped.
    pub termination: Termination,
}

struct DeltaR<'a>(&'a [(f64, f64)]);

impl LeastSquares for DeltaR<'_> {
    fn n_params(&self) -> usize {
        2
    }
    fn cost(&self, p: &[f64]) -> Option<f64> {
        let (a, b) = (*p.first()?, *p.get(1)?);
        Some(
            0.5 * self
                .0
                .iter()
                .map(|(i, dr)| (a - b / i - dr).powi(2))
                .sum::<f64>(),
        )
    }
    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations> {
        let (a, b) = (*p.first()?, *p.get(1)?);
        let mut jtj = DMatrix::zeros(2, 2);
        let mut jtr = DVector::zeros(2);
        let mut cost = 0.0;
        for (i, dr) in self.0 {
            let r = a - b / i - dr;
            let j = [1.0, -1.0 / i];
            cost += r * r;
            for x in 0..2 {
                jtr[x] += j[x] * r;
                for y in 0..2 {
                    jtj[(x, y)] += j[x] * j[y];
                }
            }
        }
        Some(NormalEquations {
            jtj,
            jtr,
            cost: 0.5 * cost,
            n_residuals: self.0.len(),
        })
    }
}

/// Fits `ΔR = a − b/Ir` (8) to steady states `(E [V], Ir [A])` with known `R` \[Ω\] and `k`
/// \[N·m/A\], and returns Ts by (9). Needs at least two tests at different currents.
pub fn fit_apparent_resistance(
    tests: &[(f64, f64)],
    r_ohm: f64,
    k_nm_per_a: f64,
) -> Result<SteadyFit, FitError> {
    for (name, v) in [("R", r_ohm), ("k", k_nm_per_a)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(FitError::InvalidSetting {
                name,
                value: v,
                expected: "a known positive value (Sec. 2.2 assumes R and k known)",
            });
        }
    }
    let mut points = Vec::new();
    for (n, &(e, ir)) in tests.iter().enumerate() {
        if !(e.is_finite() && ir.is_finite() && ir.abs() > 0.0) {
            return Err(FitError::BadData {
                series: format!("steady test {}", n + 1),
                reason: format!(
                    "E = {e} V, Ir = {ir} A: both must be finite and the current non-zero"
                ),
            });
        }
        points.push((ir, e / ir - r_ohm));
    }
    let distinct = points
        .iter()
        .any(|(i, _)| (i - points[0].0).abs() > 1e-9 * i.abs());
    if points.len() < 2 || !distinct {
        return Err(FitError::BadData {
            series: "steady tests".into(),
            reason: format!(
                "{} test(s) at distinct currents: Eq. (8) needs at least two",
                if distinct { points.len() } else { 1 }
            ),
        });
    }
    let report = solve(&DeltaR(&points), &[1.0, 1.0], LmSettings::default())?;
    let (a, b) = (report.params[0], report.params[1]);
    let ci95 = uncertainty(&report.normal).map(|u| {
        [
            [a - u.ci95_half_width[0], a + u.ci95_half_width[0]],
            [b - u.ci95_half_width[1], b + u.ci95_half_width[1]],
        ]
    });
    Ok(SteadyFit {
        a_ohm: a,
        b_ohm_a: b,
        ts_nm: k_nm_per_a * b / a,
        ci95,
        points,
        termination: report.termination,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::{steady_state, MotorParams};

    /// Fig. 3's motor: exact steady states at three voltages give Ts = 0.03 N·m back.
    #[test]
    fn recovers_ts_from_exact_steady_states() {
        let p = MotorParams::paper();
        let tests: Vec<(f64, f64)> = [0.5, 1.0, 2.0]
            .iter()
            .map(|&e| (e, steady_state(&p, e).current_a))
            .collect();
        let fit = fit_apparent_resistance(&tests, p.r_ohm, p.k_nm_per_a).unwrap();
        assert!((fit.ts_nm - 0.03).abs() < 1e-10, "{}", fit.ts_nm);
        assert!((fit.a_ohm - 0.45).abs() < 1e-10);
        assert!(fit_apparent_resistance(&tests[..1], 0.3, 0.15).is_err());
    }
}
