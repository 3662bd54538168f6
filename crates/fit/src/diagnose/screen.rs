//! *Screening*: which candidate effects deserve a full refit, from one linearisation of the
//! model the stage starts from.
//!
//! At the base model's optimum the score (Lagrange-multiplier) test of an effect needs no fit
//! of that effect: with `r` the base model's weighted training residuals (units of the noise),
//! `J` their Jacobian in the base model's parameters (and in the instant of every voltage jump
//! within its sample period, which the voltage column leaves unknown) and `S` the effect's
//! *signatures* — the
//! derivatives of the residuals in the effect's parameters at a small start size, by forward
//! differences of the simulation — the statistic is
//!
//! ```text
//! LM = (Sᵀ P r)ᵀ (Sᵀ P S)⁺ (Sᵀ P r) / c,        P = 1 − J (JᵀJ)⁺ Jᵀ,
//! ```
//!
//! the part of the residual the effect could explain that the base parameters cannot,
//! divided by the correlation factor `c = 1 + 2 Σ ρₖ²` of the base residuals (as the
//! likelihood-ratio test of [`crate::diagnose::verdict`] divides its fall). Without the effect
//! it is χ² with as many degrees of freedom as the effect adds; it approximates the fall of
//! the weighted cost a refit would achieve. Only the best-scoring candidates are refitted; the
//! verdict still rests on the refit's likelihood-ratio test and its held-out improvement.
//!
//! An effect is **not testable from these records** when its signatures, projected off the
//! base parameters' columns (and each off the effect's other parameters), keep less than a
//! thousandth of their length: no size of the effect would change the records in a way the
//! base model cannot mimic, or two of its parameters act alike. An effect that is testable
//! but absent gets a small statistic: *tested, no evidence*.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::diagnose::localise::floor::correlation_factor;
use crate::estimation::stats::chi_square_sf;

/// Lags of the residual autocorrelation behind the correlation factor.
pub(crate) const CORRELATION_LAGS: usize = 25;
/// Smallest eigenvalue of the Gram matrix of the projected signatures, each scaled to unit
/// length before projection, for an effect to be testable (a thousandth of the length, squared).
const MIN_TESTABLE_EIGENVALUE: f64 = 1e-6;
/// Relative singular value below which a column direction of the base Jacobian is dropped.
const RANK_TOLERANCE: f64 = 1e-10;

/// One candidate's screening result.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Screening {
    /// The score statistic `LM` (module docs) \[χ² units\].
    pub statistic: f64,
    /// Its degrees of freedom (the effect's fitted parameters the records determine).
    pub dof: usize,
    /// Its upper-tail χ² probability.
    pub p_value: f64,
    /// Whether the records can determine the effect (module docs).
    pub testable: bool,
}

impl Screening {
    /// The statistic less `penalty` per degree of freedom (Akaike's in χ² units with 2), by
    /// which candidates are ordered for the refit; −∞ for an untestable one.
    pub fn penalised(&self, penalty: f64) -> f64 {
        if self.testable && self.statistic.is_finite() {
            self.statistic - penalty * self.dof as f64
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// The base model linearised once for every candidate of a stage.
pub(crate) struct BaseProjection {
    /// Orthonormal basis of the base Jacobian's column space.
    basis: DMatrix<f64>,
    /// The residual with that space projected out.
    residual: DVector<f64>,
    /// The correlation factor of the residual.
    factor: f64,
}

impl BaseProjection {
    /// From the base model's residuals `r`, its Jacobian `jacobian` and the length of each
    /// channel's run of residuals (`series`); `None` when the residual is empty or not finite.
    pub fn new(r: &[f64], jacobian: &DMatrix<f64>, series: &[usize]) -> Option<Self> {
        if r.is_empty() || r.iter().any(|v| !v.is_finite()) || jacobian.nrows() != r.len() {
            return None;
        }
        let basis = orthonormal_basis(jacobian)?;
        let r = DVector::from_column_slice(r);
        let residual = &r - &basis * (basis.tr_mul(&r));
        let (mut weighted, mut count, mut at) = (0.0, 0usize, 0usize);
        for &len in series {
            let part = &r.as_slice()[at..(at + len).min(r.len())];
            at += len;
            if part.len() > CORRELATION_LAGS + 1 {
                weighted += correlation_factor(part, CORRELATION_LAGS) * part.len() as f64;
                count += part.len();
            }
        }
        let factor = if count > 0 {
            weighted / count as f64
        } else {
            1.0
        };
        Some(BaseProjection {
            basis,
            residual,
            factor,
        })
    }

    /// `signatures` with every column scaled to unit length and projected off the base
    /// columns: the columns' norms, the eigen-decomposition of the projected columns' Gram
    /// matrix and their products with the projected residual. `None` when the columns are
    /// empty, of another length than the residual, not finite, or not testable (a zero column,
    /// or a direction keeping less than [`MIN_TESTABLE_EIGENVALUE`] of its length).
    fn projected(&self, signatures: &DMatrix<f64>) -> Option<Projected> {
        if signatures.ncols() == 0
            || signatures.nrows() != self.residual.len()
            || signatures.iter().any(|v| !v.is_finite())
        {
            return None;
        }
        let norms: Vec<f64> = signatures.column_iter().map(|c| c.norm()).collect();
        if norms.iter().any(|&n| n <= 0.0) {
            return None;
        }
        let mut s = signatures.clone();
        for (mut col, n) in s.column_iter_mut().zip(&norms) {
            col /= *n;
        }
        let projected = &s - &self.basis * self.basis.tr_mul(&s);
        let eigen = projected.tr_mul(&projected).symmetric_eigen();
        let smallest = eigen
            .eigenvalues
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        if smallest.is_nan() || smallest < MIN_TESTABLE_EIGENVALUE {
            return None;
        }
        let b = projected.tr_mul(&self.residual);
        Some(Projected { norms, eigen, b })
    }

    /// The score test of an effect whose signatures are the columns of `signatures` (module
    /// docs).
    pub fn score(&self, signatures: &DMatrix<f64>) -> Screening {
        let Some(p) = self.projected(signatures) else {
            return Screening {
                statistic: 0.0,
                dof: 0,
                p_value: 1.0,
                testable: false,
            };
        };
        let along = p.eigen.eigenvectors.tr_mul(&p.b);
        let quadratic: f64 = along
            .iter()
            .zip(p.eigen.eigenvalues.iter())
            .map(|(a, l)| a * a / l)
            .sum();
        let dof = signatures.ncols();
        let statistic = quadratic / self.factor;
        Screening {
            statistic,
            dof,
            p_value: chi_square_sf(statistic, dof as f64),
            testable: true,
        }
    }

    /// The Gauss–Newton step `δ` of the candidate's parameters from the point its
    /// `signatures` (the Jacobian columns of the weighted residuals `simulated − measured`,
    /// one per parameter) were taken at: `δ = −(PᵀP)⁻¹ Pᵀ r⊥`, `P` the columns with the base
    /// model's space projected out and `r⊥` the residual that space leaves. `None` when the
    /// columns are not testable (see [`BaseProjection::score`]).
    pub fn step(&self, signatures: &DMatrix<f64>) -> Option<DVector<f64>> {
        let p = self.projected(signatures)?;
        // (PᵀP)⁻¹ Pᵀ r⊥ in the unit columns' coordinates, from the Gram matrix's eigenpairs.
        let along = p.eigen.eigenvectors.tr_mul(&p.b);
        let scaled = DVector::from_iterator(
            along.len(),
            along
                .iter()
                .zip(p.eigen.eigenvalues.iter())
                .map(|(a, l)| a / l),
        );
        let unit = &p.eigen.eigenvectors * scaled;
        Some(DVector::from_iterator(
            unit.len(),
            unit.iter().zip(&p.norms).map(|(d, n)| -d / n),
        ))
    }
}

/// Candidate columns as [`BaseProjection::projected`] leaves them.
struct Projected {
    /// The columns' norms before they were scaled to unit length.
    norms: Vec<f64>,
    /// Eigen-decomposition of the projected unit columns' Gram matrix.
    eigen: nalgebra::SymmetricEigen<f64, nalgebra::Dyn>,
    /// The projected unit columns' products with the projected residual.
    b: DVector<f64>,
}

/// Orthonormal basis of the column space of `m` (its columns scaled to unit length first, so
/// that parameters of very different units count alike), dropping directions below
/// [`RANK_TOLERANCE`] of the largest.
fn orthonormal_basis(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let mut scaled = m.clone();
    for mut col in scaled.column_iter_mut() {
        let norm = col.norm();
        if norm > 0.0 {
            col /= norm;
        }
    }
    if scaled.ncols() == 0 {
        return Some(DMatrix::zeros(m.nrows(), 0));
    }
    let svd = scaled.svd(true, false);
    let u = svd.u?;
    let top = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&j| svd.singular_values[j] > RANK_TOLERANCE * top)
        .collect();
    Some(u.select_columns(&keep))
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::NoiseRng;

    /// A linear model `y = a x + b + noise` as the base, and a candidate column `x²`.
    fn problem(curvature: f64, seed: u64) -> (Vec<f64>, DMatrix<f64>, DMatrix<f64>) {
        let n = 400;
        let mut rng = NoiseRng::new(seed);
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let base = DMatrix::from_fn(n, 2, |i, j| if j == 0 { x[i] } else { 1.0 });
        // The base fit of y = curvature x² + noise: its residual is the part of x² that a
        // line cannot explain, plus noise.
        let y = DVector::from_fn(n, |i, _| curvature * x[i] * x[i] + rng.normal());
        let fit = base.clone().svd(true, true).solve(&y, 1e-12).unwrap();
        let r = &base * fit - &y;
        let candidate = DMatrix::from_fn(n, 1, |i, _| x[i] * x[i]);
        (r.as_slice().to_vec(), base, candidate)
    }

    #[test]
    fn an_absent_effect_scores_like_chi_square_and_a_present_one_high() {
        // Absent: over 200 noise draws the statistic exceeds the χ²(1) 1 % point (6.63) about
        // 1 % of the time.
        let mut above = 0;
        for seed in 0..200 {
            let (r, j, s) = problem(0.0, seed);
            let base = BaseProjection::new(&r, &j, &[r.len()]).unwrap();
            let score = base.score(&s);
            assert!(score.testable);
            if score.statistic > 6.63 {
                above += 1;
            }
        }
        assert!(above <= 8, "{above} of 200 above the 1 % point");
        // x² of size 10 leaves a part a line cannot explain worth about 220 noise variances.
        let (r, j, s) = problem(10.0, 1);
        let base = BaseProjection::new(&r, &j, &[r.len()]).unwrap();
        let score = base.score(&s);
        assert!(score.p_value < 1e-6, "{score:?}");
    }

    #[test]
    fn the_step_recovers_the_size_of_an_effect_present() {
        // y = 10 x² + noise beside a line: the step from a zero curvature is the least-squares
        // curvature, 10 to within its standard error (about 0.7 here).
        let (r, j, s) = problem(10.0, 3);
        let base = BaseProjection::new(&r, &j, &[r.len()]).unwrap();
        let step = base.step(&s).expect("a step");
        assert!((step[0] - 10.0).abs() < 3.0, "{step}");
        // A column the base spans has none.
        let same = j.columns(0, 1).into_owned();
        assert!(base.step(&same).is_none());
    }

    #[test]
    fn a_signature_the_base_already_spans_is_not_testable() {
        let (r, j, _) = problem(1.0, 2);
        let base = BaseProjection::new(&r, &j, &[r.len()]).unwrap();
        let same = j.columns(0, 1).into_owned() * 3.0;
        assert!(!base.score(&same).testable);
        // Two parameters acting alike.
        let (_, _, s) = problem(1.0, 2);
        let twice = DMatrix::from_fn(s.nrows(), 2, |i, j| s[(i, 0)] * (1.0 + j as f64));
        assert!(!base.score(&twice).testable);
    }
}
