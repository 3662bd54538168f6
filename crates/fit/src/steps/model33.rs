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

// Lane loops index several arrays in step (`a[k]`, `t[k]`, `s[k]`…): an index is the clearest
// form, and the one the vectoriser reads best.
#![allow(clippy::needless_range_loop)]

use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::estimation::lm::{solve, LeastSquares, LmReport, LmSettings, NormalEquations};

/// Samples between exact re-evaluations of the exponentials (a multiple of [`LANES`]).
const REANCHOR: usize = 1024;
/// Lanes of the portable kernel: one SSE2 register of two `f64` (more spill the ten
/// accumulators of the normal equations out of the sixteen registers).
const LANES_SSE2: usize = 2;
/// Lanes of the AVX2 kernel: one 256-bit register of four `f64`.
#[cfg(target_arch = "x86_64")]
const LANES_AVX2: usize = 4;

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

    /// The model at `p` on the grid, `LANES` interleaved samples at a time: `None` outside the
    /// model's domain (α, σ, ωa must be positive).
    fn lanes<const LANES: usize>(&self, p: &Params33) -> Option<Lanes<'_, LANES>> {
        let (phi, rate_a, rate_b) = phase_and_rates(p)?;
        let chunk_span = LANES as f64 * self.dt;
        Some(Lanes {
            y: self.normalized_current,
            t_first: self.t_first,
            dt: self.dt,
            phi,
            rate_a,
            rate_b,
            g_a: (rate_a * chunk_span).exp(),
            g_b: (rate_b * chunk_span).exp(),
            a: [0.0; LANES],
            b: [0.0; LANES],
            next: 0,
        })
    }
}

/// The phase `φ = asinh(1/α)` and the two exponential rates `ωa − σ` and `−(ωa + σ)` \[1/s\]
/// of Eq. (33) at `p`: `None` outside the model's domain (α, σ, ωa must be positive).
fn phase_and_rates(p: &Params33) -> Option<(f64, f64, f64)> {
    let Params33 {
        alpha,
        sigma,
        omega_a,
    } = *p;
    if !(alpha > 0.0 && sigma > 0.0 && omega_a > 0.0) {
        return None;
    }
    Some(((1.0 / alpha).asinh(), omega_a - sigma, -(omega_a + sigma)))
}

/// One chunk of [`Lanes`]: times `t`, data `y`, `S = e^{−σt} sinh u`, `C = e^{−σt} cosh u`.
type Chunk<const LANES: usize> = ([f64; LANES], [f64; LANES], [f64; LANES], [f64; LANES]);

/// Iterator over the grid, `LANES` interleaved samples per item. Each lane advances its
/// exponentials by `g^LANES`; lanes past the end of the data carry `S = C = 0`, `y = 1` (zero
/// residual, zero Jacobian), so kernels need no tail code.
struct Lanes<'a, const LANES: usize> {
    y: &'a [f64],
    t_first: f64,
    dt: f64,
    phi: f64,
    rate_a: f64,
    rate_b: f64,
    g_a: f64,
    g_b: f64,
    a: [f64; LANES],
    b: [f64; LANES],
    next: usize,
}

impl<const LANES: usize> Iterator for Lanes<'_, LANES> {
    type Item = Chunk<LANES>;

    #[inline(always)]
    fn next(&mut self) -> Option<Chunk<LANES>> {
        let i0 = self.next;
        if i0 >= self.y.len() {
            return None;
        }
        self.next += LANES;
        // Through i64: x86 converts signed 64-bit integers in one instruction, unsigned ones in
        // a sequence (the index is far below 2⁶³).
        let t: [f64; LANES] =
            std::array::from_fn(|k| self.t_first + (i0 + k) as i64 as f64 * self.dt);
        let full = i0 + LANES <= self.y.len();
        if i0.is_multiple_of(REANCHOR) || !full {
            for k in 0..LANES {
                self.a[k] = (-self.phi + self.rate_a * t[k]).exp();
                self.b[k] = (self.phi + self.rate_b * t[k]).exp();
            }
        } else {
            for k in 0..LANES {
                self.a[k] *= self.g_a;
                self.b[k] *= self.g_b;
            }
        }
        let mut y = [1.0; LANES];
        let mut s = [0.0; LANES];
        let mut c = [0.0; LANES];
        if full {
            y.copy_from_slice(&self.y[i0..i0 + LANES]);
            for k in 0..LANES {
                s[k] = 0.5 * (self.a[k] - self.b[k]);
                c[k] = 0.5 * (self.a[k] + self.b[k]);
            }
        } else {
            for (k, &v) in self.y[i0..].iter().enumerate() {
                y[k] = v;
                s[k] = 0.5 * (self.a[k] - self.b[k]);
                c[k] = 0.5 * (self.a[k] + self.b[k]);
            }
        }
        Some((t, y, s, c))
    }
}

impl Record33<'_> {
    /// `½‖r‖²` with `LANES` interleaved samples.
    #[inline(always)]
    fn cost_kernel<const LANES: usize>(&self, p: &Params33) -> Option<f64> {
        let alpha = p.alpha;
        let mut cost = [0.0; LANES];
        for (_, y, s, _) in self.lanes::<LANES>(p)? {
            for k in 0..LANES {
                let r = 1.0 + alpha * s[k] - y[k];
                cost[k] += r * r;
            }
        }
        let cost: f64 = cost.iter().sum();
        cost.is_finite().then_some(0.5 * cost)
    }

    /// `JᵀJ` (6 unique), `Jᵀr` (3) and `‖r‖²`, with `LANES` interleaved samples.
    #[inline(always)]
    fn normal_kernel<const LANES: usize>(&self, p: &Params33) -> Option<[f64; 10]> {
        let alpha = p.alpha;
        let inv_root = 1.0 / (alpha * alpha + 1.0).sqrt();
        let (mut a00, mut a01, mut a02, mut a11, mut a12) = (
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
        );
        let (mut a22, mut b0, mut b1, mut b2, mut rr) = (
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
            [0.0; LANES],
        );
        for (t, y, s, c) in self.lanes::<LANES>(p)? {
            for k in 0..LANES {
                let r = 1.0 + alpha * s[k] - y[k];
                let j0 = s[k] + c[k] * inv_root;
                let j1 = -t[k] * alpha * s[k];
                let j2 = t[k] * alpha * c[k];
                a00[k] += j0 * j0;
                a01[k] += j0 * j1;
                a02[k] += j0 * j2;
                a11[k] += j1 * j1;
                a12[k] += j1 * j2;
                a22[k] += j2 * j2;
                b0[k] += j0 * r;
                b1[k] += j1 * r;
                b2[k] += j2 * r;
                rr[k] += r * r;
            }
        }
        Some([a00, a01, a02, a11, a12, a22, b0, b1, b2, rr].map(|lanes| lanes.iter().sum::<f64>()))
    }

    /// The kernels compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA (checked by the caller with `is_x86_feature_detected!`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn cost_avx2(&self, p: &Params33) -> Option<f64> {
        self.cost_kernel::<LANES_AVX2>(p)
    }

    /// The normal equations with AVX2/FMA intrinsics: four samples per step, the exponentials
    /// `A`, `B` and the times advanced by one multiply or add per step (re-anchored exactly every
    /// [`REANCHOR`] samples), ten fused multiply-add accumulators in registers. The same
    /// arithmetic as [`Record33::normal_kernel`] (tested equal to 1e-12), which the compiler
    /// does not vectorise by itself.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn normal_avx2(&self, p: &Params33) -> Option<[f64; 10]> {
        use std::arch::x86_64::*;
        let (phi, rate_a, rate_b) = phase_and_rates(p)?;
        let alpha = p.alpha;
        let inv_root = 1.0 / (alpha * alpha + 1.0).sqrt();
        let (t_first, dt) = (self.t_first, self.dt);
        let y = self.normalized_current;
        let whole = y.len() / LANES_AVX2 * LANES_AVX2;
        let span = LANES_AVX2 as f64 * dt;
        let g_a = _mm256_set1_pd((rate_a * span).exp());
        let g_b = _mm256_set1_pd((rate_b * span).exp());
        let span_v = _mm256_set1_pd(span);
        let half = _mm256_set1_pd(0.5);
        let one = _mm256_set1_pd(1.0);
        let alpha_v = _mm256_set1_pd(alpha);
        let inv_root_v = _mm256_set1_pd(inv_root);
        let zero = _mm256_setzero_pd();
        let mut acc = [zero; 10];
        let (mut a, mut b, mut t) = (zero, zero, zero);
        let mut i0 = 0;
        while i0 < whole {
            if i0.is_multiple_of(REANCHOR) {
                let tt: [f64; LANES_AVX2] =
                    std::array::from_fn(|k| t_first + (i0 + k) as i64 as f64 * dt);
                let aa = tt.map(|t| (-phi + rate_a * t).exp());
                let bb = tt.map(|t| (phi + rate_b * t).exp());
                t = _mm256_loadu_pd(tt.as_ptr());
                a = _mm256_loadu_pd(aa.as_ptr());
                b = _mm256_loadu_pd(bb.as_ptr());
            } else {
                a = _mm256_mul_pd(a, g_a);
                b = _mm256_mul_pd(b, g_b);
                t = _mm256_add_pd(t, span_v);
            }
            let yv = _mm256_loadu_pd(y[i0..i0 + LANES_AVX2].as_ptr());
            let s = _mm256_mul_pd(half, _mm256_sub_pd(a, b));
            let c = _mm256_mul_pd(half, _mm256_add_pd(a, b));
            let r = _mm256_fmadd_pd(alpha_v, s, _mm256_sub_pd(one, yv));
            let j0 = _mm256_fmadd_pd(c, inv_root_v, s);
            let ta = _mm256_mul_pd(t, alpha_v);
            let j1 = _mm256_sub_pd(zero, _mm256_mul_pd(ta, s));
            let j2 = _mm256_mul_pd(ta, c);
            acc[0] = _mm256_fmadd_pd(j0, j0, acc[0]);
            acc[1] = _mm256_fmadd_pd(j0, j1, acc[1]);
            acc[2] = _mm256_fmadd_pd(j0, j2, acc[2]);
            acc[3] = _mm256_fmadd_pd(j1, j1, acc[3]);
            acc[4] = _mm256_fmadd_pd(j1, j2, acc[4]);
            acc[5] = _mm256_fmadd_pd(j2, j2, acc[5]);
            acc[6] = _mm256_fmadd_pd(j0, r, acc[6]);
            acc[7] = _mm256_fmadd_pd(j1, r, acc[7]);
            acc[8] = _mm256_fmadd_pd(j2, r, acc[8]);
            acc[9] = _mm256_fmadd_pd(r, r, acc[9]);
            i0 += LANES_AVX2;
        }
        let mut sums = acc.map(|v| {
            let mut lanes = [0.0; LANES_AVX2];
            _mm256_storeu_pd(lanes.as_mut_ptr(), v);
            lanes.iter().sum::<f64>()
        });
        for (i, &yi) in y.iter().enumerate().skip(whole) {
            let t = t_first + i as i64 as f64 * dt;
            let (ai, bi) = ((-phi + rate_a * t).exp(), (phi + rate_b * t).exp());
            let (s, c) = (0.5 * (ai - bi), 0.5 * (ai + bi));
            let r = 1.0 + alpha * s - yi;
            let j = [s + c * inv_root, -t * alpha * s, t * alpha * c];
            let terms = [
                j[0] * j[0],
                j[0] * j[1],
                j[0] * j[2],
                j[1] * j[1],
                j[1] * j[2],
                j[2] * j[2],
                j[0] * r,
                j[1] * r,
                j[2] * r,
                r * r,
            ];
            for (sum, term) in sums.iter_mut().zip(terms) {
                *sum += term;
            }
        }
        Some(sums)
    }
}

/// Whether this CPU runs the AVX2 kernels (detected once; `is_x86_feature_detected!` caches).
#[cfg(target_arch = "x86_64")]
fn has_avx2_fma() -> bool {
    std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
}

impl LeastSquares for Record33<'_> {
    fn n_params(&self) -> usize {
        3
    }

    fn cost(&self, p: &[f64]) -> Option<f64> {
        let p = to_params(p)?;
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA, just checked.
            return unsafe { self.cost_avx2(&p) };
        }
        self.cost_kernel::<LANES_SSE2>(&p)
    }

    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations> {
        let p = to_params(p)?;
        #[cfg(target_arch = "x86_64")]
        let sums = if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA, just checked.
            unsafe { self.normal_avx2(&p) }
        } else {
            self.normal_kernel::<LANES_SSE2>(&p)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let sums = self.normal_kernel::<LANES_SSE2>(&p);
        let v = sums?;
        let m = DMatrix::from_row_slice(
            3,
            3,
            &[v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5]],
        );
        Some(NormalEquations {
            jtj: m,
            jtr: DVector::from_row_slice(&[v[6], v[7], v[8]]),
            cost: 0.5 * v[9],
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
/// Coarse to fine: a record longer than 8,000 samples is first fitted decimated to about 2,000 (every
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
    // Polish: from the coarse solution a full Gauss–Newton step is the right first move.
    let polish = if n > 4 * COARSE_SAMPLES {
        LmSettings {
            lambda_start: settings.lambda_start.min(1e-9),
            optimistic_start: true,
            ..settings
        }
    } else {
        settings
    };
    let report = solve(record, &p0, polish)?;
    let params = to_params(&report.params).ok_or_else(|| FitError::Solver("wrong size".into()))?;
    Ok(Fit33 { params, report })
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::paper::normalized_current_33;

    /// The AVX2 kernel and the portable kernel compute the same sums (1e-12 relative: they
    /// differ only in summation order, fused multiply-adds and time stepping).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_kernel_matches_portable_kernel() {
        if !has_avx2_fma() {
            return;
        }
        for n in [3usize, 4, 5, 1023, 1024, 1025, 5003] {
            let y: Vec<f64> = (0..n)
                .map(|i| {
                    normalized_current_33(5.0, 0.5, 0.39, i as f64 * 0.01) + 1e-3 * (i as f64).sin()
                })
                .collect();
            let record = Record33 {
                t_first: 0.002,
                dt: 0.01,
                normalized_current: &y,
            };
            let p = Params33 {
                alpha: 4.9,
                sigma: 0.52,
                omega_a: 0.38,
            };
            let portable = record.normal_kernel::<LANES_SSE2>(&p).unwrap();
            // SAFETY: AVX2 and FMA are present, checked above.
            let fast = unsafe { record.normal_avx2(&p) }.unwrap();
            for (a, b) in portable.iter().zip(fast) {
                assert!(
                    (a - b).abs() <= 1e-12 * a.abs().max(1e-300),
                    "n = {n}: {a} vs {b}"
                );
            }
        }
    }
}
