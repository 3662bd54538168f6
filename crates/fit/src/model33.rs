//! The fit of Eq. (33) to a normalised high-voltage current record (the paper's Sec. 2.4).
//!
//! Model: `Ī(t) = 1 + α e^{−σt} sinh(ωa t − φ)`, `φ = sinh⁻¹(1/α)`. With `u = ωa t − φ`,
//! `S = e^{−σt} sinh u`, `C = e^{−σt} cosh u`, the Jacobian rows are
//!
//! ```text
//! ∂Ī/∂α  = S + C/√(α² + 1)      (dφ/dα = −1/(α√(α²+1)))
//! ∂Ī/∂σ  = −t α S
//! ∂Ī/∂ωa =  t α C
//! ```
//!
//! On a uniform grid `S = (A − B)/2`, `C = (A + B)/2` with `A = e^{−φ} e^{(ωa−σ)t}` and
//! `B = e^{φ} e^{−(ωa+σ)t}`, each advanced by one multiplication per sample (re-anchored every
//! [`REANCHOR`] samples). Cost, `JᵀJ` and `Jᵀr` are accumulated in one pass, no allocation.

use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::lm::{solve, LeastSquares, LmReport, LmSettings, NormalEquations};

/// Samples between exact re-evaluations of the exponentials.
const REANCHOR: usize = 1024;

/// Parameters of Eq. (33).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params33 {
    /// α [-], Eq. (24).
    pub alpha: f64,
    /// σ \[1/s\], Eq. (23).
    pub sigma: f64,
    /// ωa \[rad/s\], Eq. (22).
    pub omega_a: f64,
}

/// A normalised current record on a uniform grid `t_i = t_first + i·dt`.
#[derive(Debug, Clone)]
pub struct Record33<'a> {
    /// Time of the first sample since the step \[s\].
    pub t_first: f64,
    /// Sample period \[s\].
    pub dt: f64,
    /// `I(t_i)/I_rm` [-].
    pub normalized_current: &'a [f64],
}

impl Record33<'_> {
    fn check(&self) -> Result<(), FitError> {
        let bad = |reason: String| FitError::BadData {
            series: "normalised high-voltage current".into(),
            reason,
        };
        if !(self.dt.is_finite() && self.dt > 0.0 && self.t_first.is_finite()) {
            return Err(bad(format!(
                "sample period {} s / first time {} s: expected a positive period",
                self.dt, self.t_first
            )));
        }
        if self.normalized_current.len() < 4 {
            return Err(bad(format!(
                "{} samples: at least 4 are needed to fit 3 parameters",
                self.normalized_current.len()
            )));
        }
        if let Some((i, v)) = self
            .normalized_current
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            return Err(bad(format!("sample {i} is {v}: remove or repair it")));
        }
        Ok(())
    }

    /// Walks the grid with the model at `p`, calling `visit(t, y, S, C)`.
    #[inline(always)]
    fn walk(&self, p: &Params33, mut visit: impl FnMut(f64, f64, f64, f64, f64)) -> bool {
        let Params33 {
            alpha,
            sigma,
            omega_a,
        } = *p;
        if !(alpha > 0.0 && sigma > 0.0 && omega_a > 0.0) {
            return false;
        }
        let phi = (1.0 / alpha).asinh();
        let g_a = ((omega_a - sigma) * self.dt).exp();
        let g_b = (-(omega_a + sigma) * self.dt).exp();
        let (mut a, mut b) = (0.0, 0.0);
        for (i, &y) in self.normalized_current.iter().enumerate() {
            let t = self.t_first + i as f64 * self.dt;
            if i % REANCHOR == 0 {
                a = (-phi + (omega_a - sigma) * t).exp();
                b = (phi - (omega_a + sigma) * t).exp();
            } else {
                a *= g_a;
                b *= g_b;
            }
            visit(t, y, 0.5 * (a - b), 0.5 * (a + b), alpha);
        }
        true
    }
}

impl LeastSquares for Record33<'_> {
    fn n_params(&self) -> usize {
        3
    }

    fn cost(&self, p: &[f64]) -> Option<f64> {
        let p = to_params(p)?;
        let mut cost = 0.0;
        let ok = self.walk(&p, |_, y, s, _, alpha| {
            let r = 1.0 + alpha * s - y;
            cost += r * r;
        });
        (ok && cost.is_finite()).then_some(0.5 * cost)
    }

    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations> {
        let p = to_params(p)?;
        let inv_root = 1.0 / (p.alpha * p.alpha + 1.0).sqrt();
        let mut jtj = [0.0; 6];
        let mut jtr = [0.0; 3];
        let mut cost = 0.0;
        let ok = self.walk(&p, |t, y, s, c, alpha| {
            let r = 1.0 + alpha * s - y;
            let j = [s + c * inv_root, -t * alpha * s, t * alpha * c];
            cost += r * r;
            jtr[0] += j[0] * r;
            jtr[1] += j[1] * r;
            jtr[2] += j[2] * r;
            jtj[0] += j[0] * j[0];
            jtj[1] += j[0] * j[1];
            jtj[2] += j[0] * j[2];
            jtj[3] += j[1] * j[1];
            jtj[4] += j[1] * j[2];
            jtj[5] += j[2] * j[2];
        });
        if !ok {
            return None;
        }
        let m = DMatrix::from_row_slice(
            3,
            3,
            &[
                jtj[0], jtj[1], jtj[2], jtj[1], jtj[3], jtj[4], jtj[2], jtj[4], jtj[5],
            ],
        );
        Some(NormalEquations {
            jtj: m,
            jtr: DVector::from_row_slice(&jtr),
            cost: 0.5 * cost,
            n_residuals: self.normalized_current.len(),
        })
    }
}

fn to_params(p: &[f64]) -> Option<Params33> {
    match *p {
        [alpha, sigma, omega_a] => Some(Params33 {
            alpha,
            sigma,
            omega_a,
        }),
        _ => None,
    }
}

/// Result of the (33) fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit33 {
    /// Fitted α, σ, ωa.
    pub params: Params33,
    /// Solver report (termination, iterations, normal equations at the solution).
    pub report: LmReport,
}

/// Samples of the decimated record used for the coarse stage of [`fit_33`].
const COARSE_SAMPLES: usize = 2000;

/// Fits Eq. (33) to `record` from `start`.
///
/// Coarse to fine: a record longer than 4 × [`COARSE_SAMPLES`] is first fitted decimated (every
/// k-th sample), which converges in a few cheap iterations, then polished on the full record.
pub fn fit_33(
    record: &Record33<'_>,
    start: Params33,
    settings: LmSettings,
) -> Result<Fit33, FitError> {
    record.check()?;
    let mut p0 = vec![start.alpha, start.sigma, start.omega_a];
    let n = record.normalized_current.len();
    if n > 4 * COARSE_SAMPLES {
        let k = n / COARSE_SAMPLES;
        let decimated: Vec<f64> = record
            .normalized_current
            .iter()
            .step_by(k)
            .copied()
            .collect();
        let coarse = Record33 {
            t_first: record.t_first,
            dt: record.dt * k as f64,
            normalized_current: &decimated,
        };
        let report = solve(
            &coarse,
            &p0,
            LmSettings {
                ftol: 1e-8,
                xtol: 1e-6,
                ..settings
            },
        )?;
        if report.termination.converged() {
            p0 = report.params;
        }
    }
    let report = solve(record, &p0, settings)?;
    let params = to_params(&report.params).ok_or_else(|| FitError::Solver("wrong size".into()))?;
    Ok(Fit33 { params, report })
}
