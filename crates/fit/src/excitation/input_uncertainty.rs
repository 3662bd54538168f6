//! What a record leaves unknown about the voltage it applied, and how that enters the intervals.
//!
//! The fits take each record's voltage levels and step instants as inputs, but those are
//! themselves measured: a level is estimated from its quantised, noisy (or noise-free: then
//! quantisation is a bias, not noise) voltage samples, and a step falls anywhere within the
//! sample period before the first sample that shows it. Each such input `u_j` is a nuisance with
//! an estimate `ū_j` and a variance `V_j` ([`LevelEstimate`], [`StepInputs`], [`LevelPrior`]).
//!
//! After the fit of `θ = ln p` at `u = ū`, the inputs are treated as parameters with a Gaussian
//! prior: one joint Gauss–Newton step on `(θ, u)` with the prior rows `(u − ū)/√V` moves `u`
//! where the records say it is (a sub-sample step instant is seen in the current's rise), `θ` is
//! refitted there, and the covariance is the `θ` block of the joint sandwich
//! `H⁻¹ (S + diag(0, V⁻¹)) H⁻¹ · n/(n − p)`, where `H = [[J_θᵀJ_θ, J_θᵀJ_u], [J_uᵀJ_θ,
//! J_uᵀJ_u + V⁻¹]]` is the joint normal matrix, `S` the Newey–West covariance of the joint score
//! `[J_θ J_u]ᵀ r` (the problem's own series and runs of equal readings) and `V⁻¹` that of the
//! prior's score (`ū − u` has covariance `V`). With white residuals `S = [J_θ J_u]ᵀ[J_θ J_u]`
//! and this is `H⁻¹`, the `Cov(θ | u) + G S_u Gᵀ` of the matrix inversion lemma; with
//! correlated ones (quantisation without noise holds one error for seconds) the residuals
//! inform `u` far less than `J_uᵀJ_u` says, and only the sandwich counts that. `J_u` is by
//! central differences of the weighted residuals.

use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::estimation::fitted::FullFit;
use crate::estimation::lm::LmSettings;
use crate::estimation::stats::{fitted_residual_bias, scaled_inverse};
use crate::estimation::weighted::{
    attach_intervals, fit_weighted_point, set_intervals, WeightedProblem,
};

/// Fraction of a level's samples at the column's extreme code above which that code is taken as
/// an ADC rail (a Gaussian level away from a rail puts a vanishing fraction, about `1/n`, in its
/// most extreme code).
const RAIL_FRACTION: f64 = 0.01;
/// A column is taken as quantised when it has at most this fraction of distinct values.
const QUANTISED_DISTINCT_FRACTION: f64 = 0.25;
/// Relative tolerance of "a multiple of the quantum" (values printed with finite digits).
const QUANTUM_TOLERANCE: f64 = 1e-3;
/// Joint Gauss–Newton passes on `(θ, u)` before the final covariance.
const REFINE_PASSES: usize = 8;

/// What a voltage column says about its ADC: the quantum (one LSB) and the extreme values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageScale {
    /// One ADC step \[V\], if the column is quantised (given, or found from the column).
    pub quantum_v: Option<f64>,
    /// Smallest value of the column \[V\] (a rail, if samples pile up there).
    pub min_v: f64,
    /// Largest value of the column \[V\].
    pub max_v: f64,
}

impl VoltageScale {
    /// The scale of `voltage`: `quantum_v` if given (e.g. from a record's metadata; `Some(0.0)`
    /// for a column known to be read without an ADC, whose values are then taken as they are),
    /// otherwise the smallest gap between distinct values when at most a quarter of the samples
    /// are distinct, there are at least three of them and every gap is a multiple of that
    /// smallest one (a noise-free column with two values cannot show its quantum: give it). An
    /// exact staircase of 0, 40, −20 and 2.5 V shows a "quantum" of 2.5 V that way: its levels
    /// were fitted as inputs of a 2.5 V ADC, and the exact record of the paper's motor gave
    /// R 0.2999941 [0.2999867, 0.3000015]; told there is no ADC, 0.3000000.
    pub fn of(voltage: &[f64], quantum_v: Option<f64>) -> Self {
        let (min_v, max_v) = voltage
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let exact = quantum_v == Some(0.0);
        let quantum_v = quantum_v
            .filter(|q| q.is_finite() && *q > 0.0)
            .or_else(|| (!exact).then(|| detect_quantum(voltage)).flatten());
        VoltageScale {
            quantum_v,
            min_v,
            max_v,
        }
    }
}

/// The quantum (one step) of a quantised column: see [`VoltageScale::of`]; `None` when the column
/// does not show one.
pub(crate) fn detect_quantum(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 3 || v.len() as f64 > QUANTISED_DISTINCT_FRACTION * values.len() as f64 {
        return None;
    }
    let gaps: Vec<f64> = v.windows(2).map(|w| w[1] - w[0]).collect();
    let q = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    (q > 0.0
        && gaps
            .iter()
            .all(|g| ((g / q) - (g / q).round()).abs() < QUANTUM_TOLERANCE * (g / q).max(1.0)))
    .then_some(q)
}

/// A voltage level estimated from its samples, with the variance of the estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelEstimate {
    /// The level \[V\].
    pub volts: f64,
    /// Variance of `volts` \[V²\]: from the noise (`s²/n`), the quantisation bias, or the
    /// censored fit at a rail.
    pub variance_v2: f64,
    /// The part of `variance_v2` that is the quantiser's bias \[V²\]: fixed by where the level
    /// sits between codes, not by the noise, so it need not average out over several levels
    /// (the fits count it once per level reading the same code, [`Self::bias_code`]); 0 for an
    /// unquantised level and one fitted at a rail.
    pub bias_variance_v2: f64,
    /// The ADC code the level reads, counted from the scale's lowest value (0 where there is
    /// no bias part): levels of one fit that read the same code sit alike between codes.
    pub bias_code: i64,
}

/// The level of `samples` (one constant voltage) recorded on `scale`.
///
/// - Unquantised: the mean, variance `s²/n` (white noise).
/// - Quantised with quantum `Δ`: the mean, whose error is the noise's `s²/n` plus the
///   quantiser's bias `e(μ) = E[Q(μ + n)] − μ`. For Gaussian noise σ, `e` is periodic in the
///   level μ, `e(μ) = Σₖ (−1)^{k+1} Δ/(πk) exp(−2π²k²σ²/Δ²) sin(2πkμ/Δ)`; with the level's
///   place between codes unknown (uniform), its variance is
///   `Σₖ Δ²/(2π²k²) exp(−4π²k²σ²/Δ²)` — `Δ²/12` without noise, negligible beyond σ ≈ Δ.
///   σ is estimated as `√max(s² − Δ²/12, 0)` (too small, hence a larger bias term, when σ < Δ/2).
/// - At a rail (the level's lowest or highest code is the column's extreme and holds more than
///   1 % of its samples, with at least three codes seen): noise is clipped there, so the mean
///   is biased; the level and σ are the maximum-likelihood fit of a Gaussian quantised into
///   the codes seen, the rail code standing for everything beyond it; the variance is the
///   inverse observed information.
///
/// `None` for fewer than two samples or non-finite values.
pub fn estimate_level(samples: &[f64], scale: &VoltageScale) -> Option<LevelEstimate> {
    let n = samples.len();
    if n < 2 || samples.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let nf = n as f64;
    let mean = samples.iter().sum::<f64>() / nf;
    let s2 = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    let Some(q) = scale.quantum_v else {
        return Some(LevelEstimate {
            volts: mean,
            variance_v2: s2 / nf,
            bias_variance_v2: 0.0,
            bias_code: 0,
        });
    };
    let (lo, hi, counts) = code_counts(samples, q);
    let at = |v: f64, rail: f64| (v - rail).abs() < 0.25 * q;
    let seen = counts.iter().filter(|&&c| c > 0.0).count();
    let first = counts.first().copied().unwrap_or(0.0);
    let last = counts.last().copied().unwrap_or(0.0);
    let low_rail = at(lo, scale.min_v) && first > RAIL_FRACTION * nf;
    let high_rail = at(hi, scale.max_v) && last > RAIL_FRACTION * nf;
    if (low_rail || high_rail) && seen >= 3 {
        if let Some((mu, var, _)) = censored_fit(&counts, low_rail, high_rail) {
            return Some(LevelEstimate {
                volts: lo + mu * q,
                variance_v2: var * q * q,
                bias_variance_v2: 0.0,
                bias_code: 0,
            });
        }
    }
    let bias = quantisation_bias_variance(noise_sigma_of_counts(&counts, s2, q), q);
    Some(LevelEstimate {
        volts: mean,
        variance_v2: s2 / nf + bias,
        bias_variance_v2: bias,
        bias_code: ((mean - scale.min_v) / q).round() as i64,
    })
}

/// Prior variance \[V²\] given to an uncertain level of a fit whose variance is `variance` with
/// quantiser-bias part `bias` ([`LevelEstimate::bias_variance_v2`]), one of `m` levels of the
/// fit that read the same code ([`LevelEstimate::bias_code`], [`bias_group_sizes`]): the bias
/// counted `m` times.
///
/// The noise in the levels is independent; their quantiser biases need not be: without noise
/// the bias is a function of where each level sits between codes, and levels that sit alike
/// read alike. Levels that read the same code do — the same level read twice (the segments of
/// a two-level PRBS, a return to 0 V after starting there), or levels on ranges in proportion
/// to them: the paper's pair, 40 V on 0–48 V and 2.5 V on 0–3 V, both read code 853, ½ step
/// high, and the common voltage scale, exactly degenerate with scaling all six parameters, was
/// off by √3 standard deviations of each level while the two taken as independent claimed √2
/// less: `R 0.30018 [0.30004, 0.30032]`, truth 0.3. Whatever the correlation of the `m` biases
/// of a group, `Var(Σ aₖbₖ) ≤ (Σ|aₖ|σₖ)² ≤ m Σ aₖ²σₖ²` (Cauchy–Schwarz): taken as independent
/// with `m` times their variance they bound every combination the fit can use, exactly so for
/// equal weights. Levels at different codes are taken as independent: counting every level of
/// a fit in one group made the noise-free `montecarlo` study (each record's range stretched at
/// random, so its levels sit anywhere between codes) cover R, L, k, f and J in 200 of 200 runs.
pub(crate) fn pooled_level_variance(variance: f64, bias: f64, m: usize) -> f64 {
    variance + m.saturating_sub(1) as f64 * bias.clamp(0.0, variance.max(0.0))
}

/// For levels given as `(bias variance, code)` ([`LevelEstimate`]), how many of them with a
/// bias part read each one's code (1 for a level without one).
pub(crate) fn bias_group_sizes(levels: &[(f64, i64)]) -> Vec<usize> {
    levels
        .iter()
        .map(|&(bias, code)| {
            if bias > 0.0 {
                levels
                    .iter()
                    .filter(|&&(b, c)| b > 0.0 && c == code)
                    .count()
            } else {
                1
            }
        })
        .collect()
}

/// Variance over the level's unknown place between codes of a quantiser's bias with Gaussian
/// noise `sigma` and quantum `q` (same unit): `Σₖ q²/(2π²k²) exp(−4π²k²σ²/q²)`, `q²/12` at σ = 0.
pub fn quantisation_bias_variance(sigma: f64, q: f64) -> f64 {
    use std::f64::consts::PI;
    if sigma <= 0.0 {
        return q * q / 12.0;
    }
    let a = 4.0 * PI * PI * sigma * sigma / (q * q);
    let mut total = 0.0;
    for k in 1..=10_000u32 {
        let k2 = f64::from(k) * f64::from(k);
        let term = q * q / (2.0 * PI * PI * k2) * (-a * k2).exp();
        total += term;
        if term < 1e-14 * total {
            break;
        }
    }
    total
}

/// Largest noise, as a fraction of one ADC step, below which a channel is taken as
/// noise-free: its bias variance ([`quantisation_bias_variance`]) is then above 86 % of
/// `Δ²/12`, the quantiser's error a function of where its grid sits and not of the noise.
const NOISE_FREE_FRACTION: f64 = 0.1;
/// Grid phases over one step at which [`grid_phase_score_covariance`] quantises the model.
const GRID_PHASES: usize = 64;

/// The ADC step of a channel whose readings `values` are quantised without noise: the
/// quantum of [`VoltageScale::of`]'s test, when the noise behind the readings (their
/// second differences, [`crate::noise_std`], less the quantiser's own `Δ²/12`) is below
/// a tenth of it. `None` for an unquantised or a noisy channel.
pub(crate) fn noise_free_quantum(values: &[f64]) -> Option<f64> {
    let q = detect_quantum(values)?;
    let s = crate::estimation::records::noise_std(values);
    let sigma = (s * s - q * q / 12.0).max(0.0).sqrt();
    (sigma <= NOISE_FREE_FRACTION * q).then_some(q)
}

/// Covariance of the score `Jᵀr` that the quantisation of one noise-free channel puts there,
/// over the unknown place of its grid: `E_φ[g(φ) g(φ)ᵀ]`, `g(φ) = −Jᵀ e(φ)/σ`, where
/// `e_i(φ) = Q_φ(m_i) − m_i` is the error of a quantiser of step `q` whose codes sit at
/// `φ + kq` on the model's values `m` (unit of the channel), `jac` the rows of the weighted
/// residuals `(m − y)/σ` of the channel, and φ taken at [`GRID_PHASES`] places evenly over
/// one step.
///
/// Without noise a quantiser's error is no noise: it is fixed by the signal and where the
/// grid sits, held for as long as a code lasts (seconds on a settling tail), one-signed over
/// a decelerating tail (the signal lingers near each code's far edge), and largely absorbed by
/// the parameters on a settled level (the fit moves Ts to its held code). Residuals show only
/// what the fit leaves of it; the grid's place, unknown and uniform over a step, is what
/// varies from one record to the next, and its mean square (bias included) is what an
/// interval must hold.
pub(crate) fn grid_phase_score_covariance(
    model: &[f64],
    q: f64,
    jac: nalgebra::DMatrixView<'_, f64>,
    sigma: f64,
) -> DMatrix<f64> {
    let p = jac.ncols();
    let mut total = DMatrix::zeros(p, p);
    if !(q > 0.0 && sigma > 0.0) || model.len() != jac.nrows() {
        return total;
    }
    for k in 0..GRID_PHASES {
        let phase = (k as f64 + 0.5) / GRID_PHASES as f64 * q;
        let e = DVector::from_iterator(
            model.len(),
            model
                .iter()
                .map(|&m| phase + q * ((m - phase) / q).round() - m),
        );
        let g = jac.tr_mul(&e) / sigma;
        total += &g * g.transpose();
    }
    total / GRID_PHASES as f64
}

/// Standard normal distribution function.
pub(crate) fn phi(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// Maximum-likelihood level `μ`, its variance and the noise σ (all in codes, code 0 = the
/// lowest seen) of a Gaussian quantised into `counts`, the lowest (highest) code censored when
/// it is a rail.
fn censored_fit(counts: &[f64], low_rail: bool, high_rail: bool) -> Option<(f64, f64, f64)> {
    let top = counts.len() - 1;
    let nll = |mu: f64, ln_sigma: f64| -> f64 {
        let s = ln_sigma.exp();
        let mut total = 0.0;
        for (k, &c) in counts.iter().enumerate() {
            if c == 0.0 {
                continue;
            }
            let kf = k as f64;
            let upper = if high_rail && k == top {
                1.0
            } else {
                phi((kf + 0.5 - mu) / s)
            };
            let lower = if low_rail && k == 0 {
                0.0
            } else {
                phi((kf - 0.5 - mu) / s)
            };
            let p = (upper - lower).max(1e-300);
            total -= c * p.ln();
        }
        total
    };
    let n: f64 = counts.iter().sum();
    let mean = counts
        .iter()
        .enumerate()
        .map(|(k, c)| k as f64 * c)
        .sum::<f64>()
        / n;
    let var = counts
        .iter()
        .enumerate()
        .map(|(k, c)| (k as f64 - mean).powi(2) * c)
        .sum::<f64>()
        / n;
    let mut x = [mean, var.sqrt().max(0.3).ln()];
    let h = 1e-4;
    let hessian_at = |x: [f64; 2]| -> ([f64; 2], [[f64; 2]; 2]) {
        let f = |a: f64, b: f64| nll(a, b);
        let f0 = f(x[0], x[1]);
        let g = [
            (f(x[0] + h, x[1]) - f(x[0] - h, x[1])) / (2.0 * h),
            (f(x[0], x[1] + h) - f(x[0], x[1] - h)) / (2.0 * h),
        ];
        let haa = (f(x[0] + h, x[1]) - 2.0 * f0 + f(x[0] - h, x[1])) / (h * h);
        let hbb = (f(x[0], x[1] + h) - 2.0 * f0 + f(x[0], x[1] - h)) / (h * h);
        let hab = (f(x[0] + h, x[1] + h) - f(x[0] + h, x[1] - h) - f(x[0] - h, x[1] + h)
            + f(x[0] - h, x[1] - h))
            / (4.0 * h * h);
        (g, [[haa, hab], [hab, hbb]])
    };
    for _ in 0..200 {
        let (g, hm) = hessian_at(x);
        let det = hm[0][0] * hm[1][1] - hm[0][1] * hm[0][1];
        let mut step = if hm[0][0] > 0.0 && det > 0.0 {
            [
                -(hm[1][1] * g[0] - hm[0][1] * g[1]) / det,
                -(hm[0][0] * g[1] - hm[0][1] * g[0]) / det,
            ]
        } else {
            [-0.01 * g[0] / n, -0.01 * g[1] / n]
        };
        let f0 = nll(x[0], x[1]);
        let mut accepted = false;
        for _ in 0..40 {
            let trial = [x[0] + step[0], (x[1] + step[1]).clamp(-6.0, 6.0)];
            if nll(trial[0], trial[1]) <= f0 {
                x = trial;
                accepted = true;
                break;
            }
            step = [0.5 * step[0], 0.5 * step[1]];
        }
        if !accepted || step[0].abs().max(step[1].abs()) < 1e-10 {
            break;
        }
    }
    let (_, hm) = hessian_at(x);
    let det = hm[0][0] * hm[1][1] - hm[0][1] * hm[0][1];
    let var_mu = hm[1][1] / det;
    (x[0].is_finite() && var_mu.is_finite() && var_mu > 0.0 && det > 0.0).then_some((
        x[0],
        var_mu,
        x[1].exp(),
    ))
}

/// The readings `samples` of one constant level quantised with step `q`: their lowest and
/// highest values and their count per code from the lowest.
fn code_counts(samples: &[f64], q: f64) -> (f64, f64, Vec<f64>) {
    let (lo, hi) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let top = ((hi - lo) / q).round().clamp(0.0, 1e6) as usize;
    let mut counts = vec![0.0; top + 1];
    for v in samples {
        let code = ((v - lo) / q).round() as i64;
        if let Some(slot) = usize::try_from(code).ok().and_then(|c| counts.get_mut(c)) {
            *slot += 1.0;
        }
    }
    (lo, hi, counts)
}

/// The noise σ (unit of `samples`) behind the readings `samples` of one constant level
/// quantised with step `q`: the maximum-likelihood σ of a Gaussian quantised into the codes
/// seen, 0 when they are one code. Sheppard's `√max(s² − q²/12, 0)` is exact only averaged
/// over the level's place between codes: at a third of a step it read 0.23 steps for 0.3 on a
/// level near a code's centre, and the bias variance it implies
/// ([`quantisation_bias_variance`]) is then four times too large. Sheppard's value where
/// the likelihood has no maximum.
fn quantised_noise_sigma(samples: &[f64], q: f64) -> f64 {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    let s2 = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    noise_sigma_of_counts(&code_counts(samples, q).2, s2, q)
}

/// [`quantised_noise_sigma`] of readings already counted per code (`counts`, their sample
/// variance `s2`).
fn noise_sigma_of_counts(counts: &[f64], s2: f64, q: f64) -> f64 {
    let sheppard = (s2 - q * q / 12.0).max(0.0).sqrt();
    match counts.iter().filter(|&&c| c > 0.0).count() {
        0 | 1 => 0.0,
        _ => censored_fit(counts, false, false).map_or(sheppard, |(_, _, sigma)| sigma * q),
    }
}

/// What one step test leaves unknown about its input (see [`crate::identify_full_with_inputs`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepInputs {
    /// Variance of the step height \[V²\] ([`LevelEstimate::variance_v2`]).
    pub volts_variance_v2: f64,
    /// Its quantiser-bias part \[V²\] ([`LevelEstimate::bias_variance_v2`]).
    pub volts_bias_variance_v2: f64,
    /// The code the step height reads ([`LevelEstimate::bias_code`]).
    pub volts_bias_code: i64,
    /// Expected time from the step instant to the test's first sample \[s\], added to its
    /// `t_first`: `dt/2` for a step that falls anywhere in the sample period before the first
    /// sample at the new level.
    pub delay_s: f64,
    /// Variance of that time \[s²\]: `dt²/12` for a uniform place in the period.
    pub delay_variance_s2: f64,
    /// One ADC step of the current channel \[A\], or 0 if unknown or unquantised. A current
    /// that settles within one step reads one code (or a few, with little noise) for the rest
    /// of the record: its quantisation error is then a constant offset the parameters absorb
    /// and the residuals cannot show, so it enters as an input of variance
    /// [`quantisation_bias_variance`]. A current read without noise (below a tenth of a step)
    /// instead enters the intervals whole, by its quantiser on the fitted model averaged over
    /// the unknown place of its ADC's grid, with no such offset.
    pub current_lsb_a: f64,
}

impl StepInputs {
    /// A step of `level` sampled every `dt_s` \[s\], its instant anywhere in the period before
    /// its first sample.
    pub fn sampled(level: LevelEstimate, dt_s: f64) -> Self {
        StepInputs {
            volts_variance_v2: level.variance_v2,
            volts_bias_variance_v2: level.bias_variance_v2,
            volts_bias_code: level.bias_code,
            delay_s: 0.5 * dt_s,
            delay_variance_s2: dt_s * dt_s / 12.0,
            current_lsb_a: 0.0,
        }
    }
}

/// Standard deviations of the tail's scatter that a settled current may stray from its final
/// level by ([`settled_current`]): four, so that a noise excursion of a settled reading is not
/// taken for motion (one such in 30 000 samples).
const SETTLED_SPREAD_SDS: f64 = 4.0;

/// The samples at the end of `current` that stay near its final level (the mean of the last
/// 5 %): within one ADC step `lsb`, or [`SETTLED_SPREAD_SDS`] standard deviations of the last
/// 5 % where its noise is larger; as the index of the first, with the variance of their common
/// quantisation offset. `None` when that variance is negligible (noise of a step or more
/// dithers the quantiser) or nothing settles.
///
/// Noise of a third of a step leaves the mean of a settled current a few hundredths of a step
/// off ([`quantisation_bias_variance`]) while its readings reach the codes either side of the
/// level, more than one step from the mean: a bound of one step found a 10 s record settled for
/// its last 60 samples only, and the offset of the other 9 800 went into f and Ts (f 6.5
/// half-widths off its interval).
pub(crate) fn settled_current(current: &[f64], lsb: f64) -> Option<(usize, f64)> {
    if !(lsb > 0.0 && lsb.is_finite()) || current.len() < 20 {
        return None;
    }
    let tail = &current[current.len() - current.len() / 20..];
    let end = tail.iter().sum::<f64>() / tail.len() as f64;
    let tail_sd =
        (tail.iter().map(|y| (y - end).powi(2)).sum::<f64>() / (tail.len() - 1) as f64).sqrt();
    let bound = lsb.max(SETTLED_SPREAD_SDS * tail_sd);
    let from = current
        .iter()
        .rposition(|y| (y - end).abs() > bound)
        .map_or(0, |i| i + 1);
    let settled = current.get(from..).filter(|s| s.len() >= 2)?;
    let sigma = quantised_noise_sigma(settled, lsb);
    let variance = quantisation_bias_variance(sigma, lsb);
    (variance > 1e-6 * lsb * lsb).then_some((from, variance))
}

/// What a record leaves unknown about one level of its piecewise-constant voltage
/// (see [`crate::voltage_levels`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LevelPrior {
    /// Variance of the level \[V²\].
    pub volts_variance_v2: f64,
    /// Its quantiser-bias part \[V²\] ([`LevelEstimate::bias_variance_v2`]).
    pub volts_bias_variance_v2: f64,
    /// The code the level reads ([`LevelEstimate::bias_code`]).
    pub volts_bias_code: i64,
    /// Variance of the instant the level starts \[s²\] (0 for a level that starts the record).
    pub start_variance_s2: f64,
}

/// One nuisance input of a problem: where it is now, its prior, and a difference step.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Nuisance {
    /// Current value (unit of the input).
    pub value: f64,
    /// Prior estimate.
    pub prior_mean: f64,
    /// Prior variance (> 0).
    pub prior_variance: f64,
    /// Step of the central difference.
    pub step: f64,
}

/// A weighted problem whose residuals also depend on uncertain inputs.
pub(crate) trait NuisanceProblem: WeightedProblem {
    /// The uncertain inputs (those with a positive variance), in a fixed order.
    fn nuisances(&self) -> Vec<Nuisance>;
    /// Sets input `j` (in the order of [`Self::nuisances`]) to `value`.
    fn set_nuisance(&mut self, j: usize, value: f64);
    /// The weighted residuals at `theta` and their Jacobian in θ (n × p); fixes whatever
    /// discretisation the residuals at other inputs must share.
    fn linear_parts(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)>;
    /// The weighted residuals at `theta`, on the discretisation of the last
    /// [`Self::linear_parts`].
    fn residual_vector(&self, theta: &[f64]) -> Option<Vec<f64>>;
    /// Newey–West covariance of the score `Jᵀr` of the weighted residuals `r` (in the order of
    /// [`Self::residual_vector`]) for any Jacobian columns `jac` (θ and inputs alike), with the
    /// problem's own independent series and runs of errors that move together.
    fn score_covariance_of(&self, r: &[f64], jac: &DMatrix<f64>) -> Option<DMatrix<f64>>;
    /// [`Self::score_covariance_of`] with what the fitted residuals miss of it
    /// ([`fitted_residual_bias`]), `h_inv` being the inverse of the normal matrix the fit
    /// solved for `jac`'s columns (a prior on some of them included).
    fn fitted_score_covariance(
        &self,
        r: &[f64],
        jac: &DMatrix<f64>,
        h_inv: &DMatrix<f64>,
    ) -> Option<DMatrix<f64>> {
        Some(
            self.score_covariance_of(r, jac)?
                + fitted_residual_bias(r, jac, h_inv, &self.series_layout())?,
        )
    }
}

/// The joint linearisation at one point.
struct Joint {
    /// Weighted residuals.
    r: Vec<f64>,
    /// Their Jacobian in `(θ, u)`, `[J_θ J_u]` (n × (p + m)).
    jac: DMatrix<f64>,
    /// Inverse of the joint normal matrix `H` (prior included).
    h_inv: DMatrix<f64>,
    /// Prior information `V⁻¹` of each input.
    prior_info: Vec<f64>,
    /// Joint Gauss–Newton step on `(θ, u)`.
    step: DVector<f64>,
}

impl Joint {
    /// The `θ` block (`p` parameters) of the joint sandwich covariance (module documentation),
    /// with the residuals' score covariance `score_cov` of `[J_θ J_u]`.
    fn theta_covariance(&self, score_cov: &DMatrix<f64>, p: usize) -> Option<DMatrix<f64>> {
        let n = self.r.len();
        let dof = n.checked_sub(p).filter(|&d| d > 0)?;
        let mut meat = score_cov.clone();
        for (j, info) in self.prior_info.iter().enumerate() {
            meat[(p + j, p + j)] += info;
        }
        let cov = &self.h_inv * meat * &self.h_inv * (n as f64 / dof as f64);
        let theta = cov.view((0, 0), (p, p)).into_owned();
        theta.iter().all(|v| v.is_finite()).then_some(theta)
    }
}

fn linearise<P: NuisanceProblem>(problem: &mut P, theta: &[f64]) -> Option<Joint> {
    let nuisances = problem.nuisances();
    let m = nuisances.len();
    let (r0, jt) = problem.linear_parts(theta)?;
    let n = r0.len();
    let p = jt.ncols();
    let mut ju = DMatrix::zeros(n, m);
    for (j, u) in nuisances.iter().enumerate() {
        problem.set_nuisance(j, u.value + u.step);
        let plus = problem.residual_vector(theta);
        problem.set_nuisance(j, u.value - u.step);
        let minus = problem.residual_vector(theta);
        problem.set_nuisance(j, u.value);
        let (plus, minus) = (plus?, minus?);
        if plus.len() != n || minus.len() != n {
            return None;
        }
        for i in 0..n {
            ju[(i, j)] = (plus[i] - minus[i]) / (2.0 * u.step);
        }
    }
    let r = DVector::from_vec(r0);
    let a = jt.tr_mul(&jt);
    let b = jt.tr_mul(&ju);
    let prior_info = DMatrix::from_fn(m, m, |i, j| {
        if i == j {
            1.0 / nuisances[i].prior_variance
        } else {
            0.0
        }
    });
    let d = ju.tr_mul(&ju) + &prior_info;
    // The joint normal equations [[A, B], [Bᵀ, D]] (δθ, δu) = −(J_θᵀr, J_uᵀr + V⁻¹(u − ū)).
    let mut h = DMatrix::zeros(p + m, p + m);
    h.view_mut((0, 0), (p, p)).copy_from(&a);
    h.view_mut((0, p), (p, m)).copy_from(&b);
    h.view_mut((p, 0), (m, p)).copy_from(&b.transpose());
    h.view_mut((p, p), (m, m)).copy_from(&d);
    let mut grad = DVector::zeros(p + m);
    grad.rows_mut(0, p).copy_from(&jt.tr_mul(&r));
    let offset = DVector::from_fn(m, |j, _| {
        (nuisances[j].value - nuisances[j].prior_mean) / nuisances[j].prior_variance
    });
    grad.rows_mut(p, m).copy_from(&(ju.tr_mul(&r) + offset));
    let h_inv = scaled_inverse(&h)?;
    let step = -(&h_inv * grad);
    let mut jac = DMatrix::zeros(n, p + m);
    jac.view_mut((0, 0), (n, p)).copy_from(&jt);
    jac.view_mut((0, p), (n, m)).copy_from(&ju);
    step.iter().all(|v| v.is_finite()).then_some(Joint {
        r: r.iter().copied().collect(),
        jac,
        h_inv,
        prior_info: nuisances.iter().map(|u| 1.0 / u.prior_variance).collect(),
        step,
    })
}

/// Fits `problem` from `theta0` as [`fit_weighted_point`] does, then moves its uncertain inputs
/// where the records put them (joint Gauss–Newton with their prior), refits, and widens the
/// intervals by the inputs' posterior uncertainty (see the module documentation).
pub(crate) fn fit_with_inputs<P: NuisanceProblem>(
    problem: &mut P,
    theta0: &[f64],
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    // Intervals only for the fit that is kept: each refit replaces the one before.
    let (mut fit, mut normal) = fit_weighted_point(problem, theta0, settings)?;
    if problem.nuisances().is_empty() {
        attach_intervals(problem, &mut fit, &normal);
        return Ok(fit);
    }
    let p = problem.parameters().len();
    let mut iterations = fit.iterations;
    for _ in 0..REFINE_PASSES {
        let theta = fit.theta.clone();
        let joint = if fit.termination.converged() {
            linearise(problem, &theta)
        } else {
            None
        };
        let Some(joint) = joint else {
            fit.iterations = iterations;
            attach_intervals(problem, &mut fit, &normal);
            return Ok(fit);
        };
        let nuisances = problem.nuisances();
        let m = nuisances.len();
        let du = joint.step.rows(p, m);
        let small = nuisances
            .iter()
            .zip(du.iter())
            .all(|(u, d)| d.abs() < 1e-3 * u.prior_variance.sqrt());
        if small {
            break;
        }
        for (j, u) in nuisances.iter().enumerate() {
            problem.set_nuisance(j, u.value + du[j]);
        }
        let moved: Vec<f64> = theta
            .iter()
            .zip(joint.step.rows(0, p).iter())
            .map(|(t, d)| t + d)
            .collect();
        let restart = if problem.parameters().decode(&moved).is_some() {
            moved
        } else {
            theta
        };
        let (refit, refit_normal) = fit_weighted_point(problem, &restart, settings)?;
        iterations += refit.iterations;
        (fit, normal) = (refit, refit_normal);
    }
    fit.iterations = iterations;
    let theta = fit.theta.clone();
    let joint = linearise(problem, &theta).map(|joint| {
        let cov = problem
            .fitted_score_covariance(&joint.r, &joint.jac, &joint.h_inv)
            .and_then(|score| joint.theta_covariance(&score, p));
        (cov, joint.r.len().saturating_sub(p))
    });
    let widened = joint.as_ref().is_some_and(|(cov, dof)| {
        cov.as_ref()
            .is_some_and(|c| problem.parameters().intervals(&theta, c, *dof).is_some())
    });
    if !widened {
        // The fit's own intervals stand where the joint ones cannot be computed.
        attach_intervals(problem, &mut fit, &normal);
    }
    if let Some((cov, dof)) = joint {
        set_intervals(&mut fit, problem.parameters(), cov, dof);
    }
    // The widened intervals are the ones reported: judge the result on them.
    crate::estimation::plausibility::judge(&mut fit, &problem.facts());
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quantise(x: f64, q: f64, lo: f64) -> f64 {
        lo + ((x - lo) / q).round().max(0.0) * q
    }

    /// A joint problem `n × (p + m)` with a fixed pseudo-random Jacobian and residuals.
    fn joint(n: usize, p: usize, prior_variance: &[f64]) -> Joint {
        let m = prior_variance.len();
        let mut rng = motor_model::NoiseRng::new(3);
        let jac = DMatrix::from_fn(n, p + m, |_, _| rng.normal());
        let r: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mut h = jac.tr_mul(&jac);
        for (j, v) in prior_variance.iter().enumerate() {
            h[(p + j, p + j)] += 1.0 / v;
        }
        Joint {
            r,
            jac,
            h_inv: scaled_inverse(&h).unwrap(),
            prior_info: prior_variance.iter().map(|v| 1.0 / v).collect(),
            step: DVector::zeros(p + m),
        }
    }

    #[test]
    fn joint_sandwich_with_white_scores_is_the_conditional_covariance_plus_the_inputs_share() {
        // With the score covariance JᵀJ (white residuals of unit variance) the θ block of the
        // sandwich is (J_θᵀJ_θ)⁻¹ + G S Gᵀ: the matrix inversion lemma.
        let (n, p, v) = (40, 3, [0.5, 2.0]);
        let j = joint(n, p, &v);
        let score = j.jac.tr_mul(&j.jac);
        let got = j.theta_covariance(&score, p).unwrap() * ((n - p) as f64 / n as f64);
        let jt = j.jac.columns(0, p).into_owned();
        let ju = j.jac.columns(p, v.len()).into_owned();
        let a_inv = scaled_inverse(&jt.tr_mul(&jt)).unwrap();
        let g = -(&a_inv * jt.tr_mul(&ju));
        let mut d = ju.tr_mul(&ju);
        for (k, var) in v.iter().enumerate() {
            d[(k, k)] += 1.0 / var;
        }
        let s_u = scaled_inverse(&(d + ju.tr_mul(&jt) * &g)).unwrap();
        let want = a_inv + &g * s_u * g.transpose();
        assert!(
            (&got - &want).norm() < 1e-10 * want.norm(),
            "{got} vs {want}"
        );
    }

    #[test]
    fn joint_sandwich_widens_with_the_score_covariance() {
        // Residuals that move together (a score covariance four times JᵀJ) inform θ and the
        // inputs less: the θ variances grow, though by less than four times (the prior's share
        // does not grow).
        let (p, v) = (3, [0.05, 0.2]);
        let j = joint(40, p, &v);
        let white = j.jac.tr_mul(&j.jac);
        let narrow = j.theta_covariance(&white, p).unwrap();
        let wide = j.theta_covariance(&(white * 4.0), p).unwrap();
        for k in 0..p {
            let ratio = wide[(k, k)] / narrow[(k, k)];
            assert!(ratio > 1.0 && ratio < 4.0, "parameter {k}: ratio {ratio}");
        }
    }

    #[test]
    fn noise_free_quantum_is_found_only_without_noise() {
        let q = 0.1;
        let slow: Vec<f64> = (0..4000)
            .map(|i| quantise(3.0 + 2.0 * (-(i as f64) / 800.0).exp(), q, 0.0))
            .collect();
        assert!((noise_free_quantum(&slow).unwrap() - q).abs() < 1e-12);
        let mut rng = motor_model::NoiseRng::new(11);
        let noisy: Vec<f64> = slow
            .iter()
            .map(|y| quantise(y + 0.5 * q * rng.normal(), q, 0.0))
            .collect();
        assert!(noise_free_quantum(&noisy).is_none());
        let smooth: Vec<f64> = (0..4000).map(|i| (i as f64 * 1e-3).sin()).collect();
        assert!(noise_free_quantum(&smooth).is_none());
    }

    #[test]
    fn grid_phase_covariance_of_a_held_level_is_q2_over_12() {
        // A constant signal read by one offset column: its error is uniform over ±q/2 as the
        // grid moves, so the score's variance is (n/σ)² q²/12.
        let (n, q, sigma) = (50, 0.2, 0.5);
        let jac = DMatrix::from_element(n, 1, 1.0);
        let c = grid_phase_score_covariance(&vec![1.234; n], q, jac.columns(0, 1), sigma);
        let want = (n as f64 / sigma).powi(2) * q * q / 12.0;
        assert!(
            (c[(0, 0)] - want).abs() < 1e-3 * want,
            "{} vs {want}",
            c[(0, 0)]
        );
        // A ramp over many steps averages its errors out: far less than held.
        let ramp: Vec<f64> = (0..n).map(|i| i as f64 * 0.37 * q).collect();
        let moving = grid_phase_score_covariance(&ramp, q, jac.columns(0, 1), sigma);
        assert!(moving[(0, 0)] < 0.1 * want, "{}", moving[(0, 0)]);
    }

    #[test]
    fn noise_free_level_gets_the_uniform_quantisation_variance() {
        let q = 0.05;
        let v = vec![quantise(40.012, q, 0.0); 1000];
        let scale = VoltageScale::of(&v, Some(q));
        let e = estimate_level(&v, &scale).unwrap();
        assert!((e.variance_v2 - q * q / 12.0).abs() < 1e-15);
        assert!((e.volts - 40.0).abs() < 1e-12);
    }

    #[test]
    fn bias_variance_falls_from_q2_over_12_with_noise() {
        let q = 1.0;
        assert!((quantisation_bias_variance(1e-9, q) - 1.0 / 12.0).abs() < 1e-4);
        assert!(quantisation_bias_variance(0.5, q) < 1e-5);
        assert!(quantisation_bias_variance(0.25, q) > 1e-3);
    }

    #[test]
    fn a_settled_current_a_third_of_a_step_noisy_is_settled_over_its_whole_tail() {
        // A level near a code's centre, σ = 0.3 steps: readings reach the codes either side,
        // more than one step from the mean.
        let q = 0.01;
        let mut rng = motor_model::NoiseRng::new(7);
        for centre in [17.1, 17.5, 17.9] {
            let current: Vec<f64> = (0..10_000)
                .map(|_| quantise(centre * q + 0.3 * q * rng.normal(), q, 0.0))
                .collect();
            let sigma = quantised_noise_sigma(&current, q);
            assert!((sigma / (0.3 * q) - 1.0).abs() < 0.1, "{centre}: σ {sigma}");
            let (from, variance) = settled_current(&current, q).expect("an offset");
            assert!(from < 100, "{centre}: settled from sample {from}");
            let expected = quantisation_bias_variance(0.3 * q, q);
            assert!(
                (variance / expected - 1.0).abs() < 0.5,
                "{centre}: {variance} against {expected}"
            );
        }
        // One code throughout: no noise to see, the whole q²/12.
        assert_eq!(quantised_noise_sigma(&[0.17; 50], q), 0.0);
    }

    #[test]
    fn level_at_a_rail_is_not_biased_by_the_clipped_noise() {
        // 0 V read on a 0-rail ADC with 1 LSB of noise: the mean reads about +0.29 LSB.
        let q = 0.05;
        let mut rng = motor_model::NoiseRng::new(7);
        let mut v: Vec<f64> = (0..20_000)
            .map(|_| quantise(q * rng.normal(), q, 0.0))
            .collect();
        v.push(40.0);
        let scale = VoltageScale::of(&v, None);
        assert!((scale.quantum_v.unwrap() - q).abs() < 1e-12);
        v.pop();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        assert!(mean > 0.2 * q, "mean {mean}");
        let e = estimate_level(&v, &scale).unwrap();
        let sd = e.variance_v2.sqrt();
        assert!(e.volts.abs() < 3.0 * sd, "{} ± {sd}", e.volts);
        assert!(sd < 0.05 * q);
    }
}
