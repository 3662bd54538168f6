//! Covariance, confidence intervals and correlations of a least-squares fit.
//!
//! As MATLAB's `nlparci`: with `n` residuals, `p` parameters and `s² = ‖r‖²/(n − p)`, the
//! covariance is `s² (JᵀJ)⁻¹` and the 95 % interval is `p̂ ± t_{0.975, n−p} √Cᵢᵢ`.

use nalgebra::DMatrix;

use crate::estimation::lm::NormalEquations;

/// Uncertainty of fitted parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Covariance matrix `s² (JᵀJ)⁻¹` in the fit's parameter units.
    pub covariance: DMatrix<f64>,
    /// Standard errors `√Cᵢᵢ`.
    pub std_error: Vec<f64>,
    /// Half-width of the 95 % interval, `t_{0.975, n−p} σᵢ`.
    pub ci95_half_width: Vec<f64>,
    /// Correlation matrix `Cᵢⱼ/(σᵢσⱼ)`.
    pub correlation: DMatrix<f64>,
    /// Residual variance `s²`.
    pub residual_variance: f64,
    /// Degrees of freedom `n − p`.
    pub dof: usize,
}

/// Uncertainty from the normal equations at the solution; `None` when `JᵀJ` is singular or
/// there are no degrees of freedom.
pub fn uncertainty(normal: &NormalEquations) -> Option<Uncertainty> {
    let dof = degrees_of_freedom(normal)?;
    let s2 = 2.0 * normal.cost / dof as f64;
    let covariance = inverse_jtj(normal)? * s2;
    from_covariance(covariance, dof, s2)
}

/// Uncertainty from the sandwich `(JᵀJ)⁻¹ S (JᵀJ)⁻¹ · n/(n − p)`, where `S` is a
/// heteroskedasticity- and autocorrelation-consistent estimate of the covariance of the score
/// `Jᵀr` (Newey–West). Unlike [`uncertainty`] it stays honest when the residuals are correlated
/// in time (noise that is not white: quantisation of a slowly moving signal, differentiated
/// encoder counts, filtering). `normal` gives `JᵀJ` and the residual count; `None` when `S` is
/// not of the shape of `JᵀJ`.
pub fn sandwich_uncertainty(
    normal: &NormalEquations,
    score_cov: &DMatrix<f64>,
) -> Option<Uncertainty> {
    if score_cov.shape() != normal.jtj.shape() {
        return None;
    }
    let dof = degrees_of_freedom(normal)?;
    let h_inv = inverse_jtj(normal)?;
    let small_sample = normal.n_residuals as f64 / dof as f64;
    let covariance = (&h_inv * score_cov * &h_inv) * small_sample;
    from_covariance(covariance, dof, 2.0 * normal.cost / dof as f64)
}

/// `hac` with every standard error raised to at least `floor`'s (the covariance scaled as
/// `D C D`, `D = diag(max(1, σ_floor/σ_hac))`, so that its correlations and positive
/// definiteness are kept), the intervals recomputed. A Newey–West estimate of the score's
/// covariance is itself noisy where few samples carry a parameter (the transients that fix an
/// inertia: its standard error varied by 22 % from one noise draw to the next on a servo's
/// staircase, and the narrow draws missed), while the model-based one, `s² JᵀJ`, does not
/// count correlated errors: the larger of the two is honest on white and on correlated noise.
/// `None` if the shapes differ.
pub(crate) fn at_least(hac: Uncertainty, floor: &Uncertainty) -> Option<Uncertainty> {
    let p = hac.std_error.len();
    if floor.std_error.len() != p {
        return None;
    }
    let d: Vec<f64> = (0..p)
        .map(|i| {
            let (a, b) = (hac.std_error[i], floor.std_error[i]);
            if a > 0.0 && b > a {
                b / a
            } else {
                1.0
            }
        })
        .collect();
    let covariance = DMatrix::from_fn(p, p, |i, j| hac.covariance[(i, j)] * d[i] * d[j]);
    from_covariance(covariance, hac.dof, hac.residual_variance)
}

/// `n − p`, if positive.
fn degrees_of_freedom(normal: &NormalEquations) -> Option<usize> {
    normal
        .n_residuals
        .checked_sub(normal.jtj.nrows())
        .filter(|&d| d > 0)
}

/// `(JᵀJ)⁻¹`, inverted with column scaling `D (D JᵀJ D)⁻¹ D`, `D = diag(JᵀJ)^{-1/2}`, so that
/// parameters of very different magnitudes do not ruin the conditioning.
fn inverse_jtj(normal: &NormalEquations) -> Option<DMatrix<f64>> {
    scaled_inverse(&normal.jtj)
}

/// The inverse of a symmetric matrix `M` with a positive diagonal, as `D (D M D)⁻¹ D`,
/// `D = diag(M)^{-1/2}` (quantities of very different magnitudes keep the conditioning).
pub(crate) fn scaled_inverse(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if !m.is_square() {
        return None;
    }
    let p = m.nrows();
    let d: Vec<f64> = (0..p)
        .map(|i| {
            let v = m[(i, i)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let scaled = DMatrix::from_fn(p, p, |i, j| m[(i, j)] * d[i] * d[j]);
    let inv = scaled.try_inverse()?;
    Some(DMatrix::from_fn(p, p, |i, j| inv[(i, j)] * d[i] * d[j]))
}

/// Standard errors, Student-t 95 % half-widths and correlations of a covariance matrix.
pub(crate) fn from_covariance(
    covariance: DMatrix<f64>,
    dof: usize,
    residual_variance: f64,
) -> Option<Uncertainty> {
    let p = covariance.nrows();
    let std_error: Vec<f64> = (0..p).map(|i| covariance[(i, i)].max(0.0).sqrt()).collect();
    if std_error.iter().any(|s| !s.is_finite()) {
        return None;
    }
    let t = student_t_quantile(0.975, dof as f64);
    let correlation = DMatrix::from_fn(p, p, |i, j| {
        let den = std_error[i] * std_error[j];
        if den > 0.0 {
            covariance[(i, j)] / den
        } else if i == j {
            1.0
        } else {
            0.0
        }
    });
    Some(Uncertainty {
        ci95_half_width: std_error.iter().map(|s| t * s).collect(),
        std_error,
        covariance,
        correlation,
        residual_variance,
        dof,
    })
}

/// Newey–West lag for `n` samples, `⌊4 (n/100)^{2/9}⌋` (Newey & West 1994's rule of thumb).
pub fn newey_west_lags(n: usize) -> usize {
    (4.0 * (n as f64 / 100.0).powf(2.0 / 9.0)).floor() as usize
}

/// The Newey–West covariance of the score `Jᵀr` of any number of parameters (the same
/// estimate as [`NeweyWest`], from the whole residual vector `r` and Jacobian `J` at once):
/// the rows are cut into independent series of the lengths in `series` (in order, summing to
/// the row count), each with [`newey_west_lags`] of its length; a series of one row (a prior
/// on a parameter) is its own. `None` if the lengths do not add up or an entry is not finite.
pub fn newey_west_score_covariance(
    r: &[f64],
    jac: &DMatrix<f64>,
    series: &[usize],
) -> Option<DMatrix<f64>> {
    newey_west_run_covariance(r, jac, series, &vec![1; r.len()])
}

/// [`newey_west_score_covariance`] of rows grouped into runs whose errors move together:
/// `runs` are the run lengths in row order (each series a whole number of runs). The scores
/// `rᵢ ∂rᵢ/∂θ` are summed within each run and Newey–West is taken over the run sums, with
/// [`newey_west_lags`] of the number of runs of each series. A quantiser without noise
/// holds one code while the signal moves less than a step, so its error is one-signed for
/// as long as the code lasts — seconds on a slow settling tail, far beyond any fixed lag —
/// and runs of equal readings ([`equal_runs`]) are then the unit of independent error;
/// with noise of a step or more the runs are a sample or two and this is the plain
/// estimate. `None` if the lengths do not add up or an entry is not finite.
pub fn newey_west_run_covariance(
    r: &[f64],
    jac: &DMatrix<f64>,
    series: &[usize],
    runs: &[usize],
) -> Option<DMatrix<f64>> {
    let (n, p) = jac.shape();
    if r.len() != n || series.iter().sum::<usize>() != n || runs.iter().sum::<usize>() != n {
        return None;
    }
    // Run sums of the scores, and each series' length in runs.
    let mut g = DMatrix::zeros(runs.len(), p);
    let mut run_series = Vec::with_capacity(series.len());
    let (mut row, mut run) = (0, 0);
    for &len in series {
        let (end, first) = (row + len, run);
        while row < end {
            let width = *runs.get(run)?;
            if width == 0 || row + width > end {
                return None;
            }
            for i in row..row + width {
                for j in 0..p {
                    g[(run, j)] += r[i] * jac[(i, j)];
                }
            }
            row += width;
            run += 1;
        }
        run_series.push(run - first);
    }
    let mut total = DMatrix::zeros(p, p);
    let mut at = 0;
    for &len in &run_series {
        let block = g.rows(at, len);
        total += block.transpose() * block;
        let lags = newey_west_lags(len).max(1).min(len.saturating_sub(1));
        for l in 1..=lags {
            let weight = 1.0 - l as f64 / (newey_west_lags(len).max(1) as f64 + 1.0);
            let later = block.rows(l, len - l);
            let earlier = block.rows(0, len - l);
            let cross = later.transpose() * earlier;
            total += (&cross + cross.transpose()) * weight;
        }
        at += len;
    }
    total.iter().all(|v| v.is_finite()).then_some(total)
}

/// The lengths of the runs of exactly equal consecutive values of `data` (a quantised
/// reading), in order; they sum to `data.len()`.
pub fn equal_runs(data: &[f64]) -> Vec<usize> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < data.len() {
        let j = data[i..]
            .iter()
            .position(|v| v.to_bits() != data[i].to_bits())
            .map_or(data.len(), |d| i + d);
        runs.push(j - i);
        i = j;
    }
    runs
}

/// How the rows of a weighted residual vector fall into the independent series (a channel of
/// a record) that a Newey–West estimate of the score covariance takes one at a time.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct SeriesLayout {
    /// The series of each row, `None` for a row the estimate does not take from its residual
    /// (a channel read without noise, whose covariance comes from its quantiser instead).
    /// The rows of one series are in time order.
    pub series: Vec<Option<usize>>,
    /// The Newey–West lag of each series, in rows (Bartlett weights `1 − l/(L + 1)`).
    pub lags: Vec<usize>,
}

/// Row `i` of a row-major matrix of `q` columns.
fn row(m: &[f64], i: usize, q: usize) -> &[f64] {
    &m[i * q..(i + 1) * q]
}

/// The part of the score covariance that a Newey–West estimate from the fitted residuals
/// misses (p × p, in the units of `jac`'s columns).
///
/// The residuals at the solution are not the errors: the fit removes from them their
/// projection on the Jacobian's columns, so that with errors of variance `v`
/// `E[r rᵀ] = v (𝟙 − P)`, `P = J H⁻¹ Jᵀ` (`h_inv` = `H⁻¹`, the inverse of the normal matrix the
/// fit solved, a prior on some columns included), and the Newey–West estimate
/// `Σ_{|i−j|≤L} wᵢⱼ rᵢ rⱼ JᵢJⱼᵀ` has the expectation `v Σ JᵢJᵢᵀ − v Σ_{|i−j|≤L} wᵢⱼ Pᵢⱼ JᵢJⱼᵀ`.
/// The missing term is small for a parameter that every part of a long record informs, but
/// not for one that a few samples determine — the inductance from a current rise a few samples
/// long, whose samples all fall within one lag window: there the normal equations hold the
/// residuals' score near zero, and the estimate with them. This returns that term,
/// `Σ_series v_s Σ_{|i−j|≤L_s} wᵢⱼ Pᵢⱼ JᵢJⱼᵀ`, each series' `v_s` estimated as
/// `Σ rᵢ²/Σ (1 − Pᵢᵢ)` (its diagonal is the leverage correction of HC2-type estimates).
/// `None` if the shapes do not agree or an entry is not finite.
pub(crate) fn fitted_residual_bias(
    r: &[f64],
    jac: &DMatrix<f64>,
    h_inv: &DMatrix<f64>,
    layout: &SeriesLayout,
) -> Option<DMatrix<f64>> {
    let (n, q) = jac.shape();
    if r.len() != n || layout.series.len() != n || h_inv.shape() != (q, q) {
        return None;
    }
    let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
    // J's rows as contiguous slices (row-major); the rows of K = J H⁻¹ (H⁻¹ symmetric) are
    // formed as they are needed: on a long record a second n × q matrix is hundreds of MB.
    let jr: Vec<f64> = jac.transpose().as_slice().to_vec();
    let hr: Vec<f64> = h_inv.transpose().as_slice().to_vec();
    let k_row = |i: usize, out: &mut [f64]| {
        let ji = row(&jr, i, q);
        for (o, h) in out.iter_mut().zip(hr.chunks_exact(q)) {
            *o = dot(h, ji);
        }
    };
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); layout.lags.len()];
    for (i, s) in layout.series.iter().enumerate() {
        if let Some(s) = s {
            rows.get_mut(*s)?.push(i);
        }
    }
    let mut total = vec![0.0; q * q];
    let mut u = vec![0.0; q];
    let mut ki = vec![0.0; q];
    for (idx, &lags) in rows.iter().zip(&layout.lags) {
        let m = idx.len();
        if m == 0 {
            continue;
        }
        let leverage: f64 = idx
            .iter()
            .map(|&i| {
                k_row(i, &mut ki);
                dot(&ki, row(&jr, i, q))
            })
            .sum();
        let free = m as f64 - leverage;
        if free <= 0.0 {
            continue;
        }
        let v = idx.iter().map(|&i| r[i] * r[i]).sum::<f64>() / free;
        // Σ_b w_ab Pᵢⱼ Jⱼᵀ = Kᵢᵀ M_a, M_a = Σ_b w_ab JⱼJⱼᵀ; the Bartlett weight is the share of
        // the W = L + 1 row windows holding a that also hold b (see [`NeweyWest`]), so
        // M_a = C_a / W with C_a the sum of the windows' B_k = Σ_{b ∈ k} JⱼJⱼᵀ over the W
        // windows holding a: running sums, one window and one row at a time.
        let lags = lags.max(1);
        let w = lags + 1;
        let jj = |b: usize| row(&jr, idx[b], q);
        let mut window = vec![0.0; q * q];
        let mut c = WindowSum::new(w, q * q);
        let scale = v / w as f64;
        // Window kk − L holds rows kk − L … kk.
        for kk in 0..m + lags {
            if kk < m {
                add_outer(&mut window, jj(kk), 1.0);
            }
            if kk >= w && kk - w < m {
                add_outer(&mut window, jj(kk - w), -1.0);
            }
            if (kk + 1) % w == 0 {
                // Afresh every W windows, so that rounding does not build up.
                window.fill(0.0);
                for b in kk.saturating_sub(lags)..(kk + 1).min(m) {
                    add_outer(&mut window, jj(b), 1.0);
                }
            }
            c.push(&window);
            let Some(a) = kk.checked_sub(lags) else {
                continue;
            };
            let i = idx[a];
            k_row(i, &mut ki);
            for (ua, crow) in u.iter_mut().zip(c.sum().chunks_exact(q)) {
                *ua = dot(crow, &ki);
            }
            for (ja, out) in row(&jr, i, q).iter().zip(total.chunks_exact_mut(q)) {
                for (cell, ub) in out.iter_mut().zip(&u) {
                    *cell += scale * ja * ub;
                }
            }
        }
    }
    let m = DMatrix::from_row_slice(q, q, &total);
    let sym = (&m + m.transpose()) * 0.5;
    sym.iter().all(|x| x.is_finite()).then_some(sym)
}

/// Newey–West accumulator of the covariance of a score `Σᵢ gᵢ` over one time series of
/// per-sample scores `gᵢ = rᵢ ∂rᵢ/∂θ` (`p` parameters):
/// `Σᵢ gᵢgᵢᵀ + Σₗ wₗ Σᵢ (gᵢgᵢ₋ₗᵀ + gᵢ₋ₗgᵢᵀ)` with Bartlett weights `wₗ = 1 − l/(L+1)`.
/// Feed one series (a channel of a record) with [`NeweyWest::push`], then call
/// [`NeweyWest::new_series`] before the next; series are taken as independent of each other.
///
/// The Bartlett weight `1 − |i−j|/(L+1)` is the share of the `L+1`-sample windows holding
/// sample `i` that also hold `j`, so the sum is `1/(L+1) Σₖ SₖSₖᵀ` over every window `k`
/// (those that run past either end of the series clipped to it), `Sₖ` the window's sum of
/// scores: one outer product per sample instead of `2L+1`, and positive semi-definite by
/// construction.
#[derive(Debug, Clone)]
pub struct NeweyWest {
    p: usize,
    /// The finished series' covariance, `p × p`, row-major.
    done: Vec<f64>,
    /// `Σₖ SₖSₖᵀ` over the current series' windows so far, `p × p`, row-major.
    sum: Vec<f64>,
    /// The last `L + 1` scores and their sum (the newest window).
    window: WindowSum,
    lags: usize,
}

impl NeweyWest {
    /// An empty accumulator of scores of `p` parameters for series of about `n` samples
    /// ([`newey_west_lags`]).
    pub fn new(p: usize, n: usize) -> Self {
        let lags = newey_west_lags(n).max(1);
        NeweyWest {
            p,
            done: vec![0.0; p * p],
            sum: vec![0.0; p * p],
            window: WindowSum::new(lags + 1, p),
            lags,
        }
    }

    /// Starts a new independent series of about `n` samples.
    pub fn new_series(&mut self, n: usize) {
        let finished = self.series_covariance();
        for (d, f) in self.done.iter_mut().zip(finished) {
            *d += f;
        }
        self.lags = newey_west_lags(n).max(1);
        self.sum.fill(0.0);
        self.window = WindowSum::new(self.lags + 1, self.p);
    }

    /// Adds the next score of the current series (`p` values; extra ones are ignored, missing
    /// ones count as 0).
    pub fn push(&mut self, g: &[f64]) {
        self.window.push(g);
        add_outer(&mut self.sum, self.window.sum(), 1.0);
    }

    /// The current series' covariance: its windows so far, the windows that run past its
    /// last sample, and the `1/(L+1)` of the Bartlett weights.
    fn series_covariance(&self) -> Vec<f64> {
        let seen = self.window.seen;
        let mut total = self.sum.clone();
        // Windows starting at n−L … n−1: sums of the last L, L−1, …, 1 scores (all of the
        // series once it is shorter).
        let mut tail = vec![0.0; self.p];
        for back in 1..=self.lags.min(seen) {
            for (t, x) in tail.iter_mut().zip(self.window.past(back)) {
                *t += x;
            }
            add_outer(&mut total, &tail, 1.0);
        }
        if seen > 0 {
            for _ in seen..self.lags {
                add_outer(&mut total, &tail, 1.0);
            }
        }
        let scale = 1.0 / (self.lags + 1) as f64;
        total.iter_mut().for_each(|x| *x *= scale);
        total
    }

    /// The accumulated covariance (`p × p`), `None` if any entry is not finite.
    pub fn finish(&self) -> Option<DMatrix<f64>> {
        let current = self.series_covariance();
        let sum: Vec<f64> = self.done.iter().zip(&current).map(|(d, c)| d + c).collect();
        let m = DMatrix::from_row_slice(self.p, self.p, &sum);
        m.iter().all(|v| v.is_finite()).then_some(m)
    }
}

/// The running sum of the last `w` vectors of `d` values pushed (zeros before the first),
/// summed afresh from its ring every `w` pushes so that rounding does not build up over a
/// long series.
#[derive(Debug, Clone)]
struct WindowSum {
    d: usize,
    /// The last `w` vectors, `d` each, as a ring.
    ring: Vec<f64>,
    sum: Vec<f64>,
    seen: usize,
}

impl WindowSum {
    fn new(w: usize, d: usize) -> Self {
        WindowSum {
            d,
            ring: vec![0.0; w * d],
            sum: vec![0.0; d],
            seen: 0,
        }
    }

    /// Adds `x` (missing values count as 0, extra ones are ignored) and drops the vector `w`
    /// pushes old.
    fn push(&mut self, x: &[f64]) {
        let (d, w) = (self.d, self.ring.len() / self.d.max(1));
        let slot = self.seen % w;
        let held = &mut self.ring[slot * d..(slot + 1) * d];
        for (j, (old, s)) in held.iter_mut().zip(self.sum.iter_mut()).enumerate() {
            let new = x.get(j).copied().unwrap_or(0.0);
            *s += new - *old;
            *old = new;
        }
        self.seen += 1;
        if slot + 1 == w {
            self.sum.fill(0.0);
            for past in self.ring.chunks_exact(d) {
                for (s, v) in self.sum.iter_mut().zip(past) {
                    *s += v;
                }
            }
        }
    }

    /// The sum of the last `w` vectors pushed.
    fn sum(&self) -> &[f64] {
        &self.sum
    }

    /// The vector pushed `back` pushes ago (1: the last; `back` from 1 to `w`).
    fn past(&self, back: usize) -> &[f64] {
        let w = self.ring.len() / self.d.max(1);
        let slot = (self.seen - back) % w;
        &self.ring[slot * self.d..(slot + 1) * self.d]
    }
}

/// `m += scale · x xᵀ` for a row-major `x.len()²` matrix `m`.
fn add_outer(m: &mut [f64], x: &[f64], scale: f64) {
    for (row, xa) in m.chunks_exact_mut(x.len()).zip(x) {
        let a = scale * xa;
        for (cell, xb) in row.iter_mut().zip(x) {
            *cell += a * xb;
        }
    }
}

/// The `p`-quantile of Student's t distribution with `nu` degrees of freedom (`0 < p < 1`).
///
/// Bisection on the CDF, `F(t) = 1 − ½ I_{ν/(ν+t²)}(ν/2, ½)` for `t > 0`, with the regularised
/// incomplete beta function by its continued fraction (Numerical Recipes §6.4); good to 1e-10.
pub fn student_t_quantile(p: f64, nu: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && nu > 0.0) {
        return f64::NAN;
    }
    if p < 0.5 {
        return -student_t_quantile(1.0 - p, nu);
    }
    let cdf = |t: f64| 1.0 - 0.5 * incomplete_beta(nu / (nu + t * t), 0.5 * nu, 0.5);
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    while cdf(hi) < p {
        hi *= 2.0;
        if hi > 1e12 {
            return f64::INFINITY;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-13 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Upper tail `P(X > x)` of the chi-square distribution with `nu` degrees of freedom (`nu > 0`,
/// not necessarily an integer): the regularised upper incomplete gamma `Q(ν/2, x/2)`.
/// 1 for `x ≤ 0`; NaN for a non-positive or non-finite `nu`.
pub(crate) fn chi_square_sf(x: f64, nu: f64) -> f64 {
    if !(nu > 0.0 && nu.is_finite()) || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    upper_incomplete_gamma(0.5 * nu, 0.5 * x)
}

/// Upper tail `P(Z > z)` of the standard normal distribution, `½ erfc(z/√2)`.
pub(crate) fn normal_sf(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// Upper tail `P(F > f)` of Fisher's F distribution with `d1`, `d2` degrees of freedom:
/// `I_{d2/(d2 + d1 f)}(d2/2, d1/2)`. 1 for `f ≤ 0`.
pub(crate) fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if !(d1 > 0.0 && d2 > 0.0) || f.is_nan() {
        return f64::NAN;
    }
    if f <= 0.0 {
        return 1.0;
    }
    incomplete_beta(d2 / (d2 + d1 * f), 0.5 * d2, 0.5 * d1)
}

/// Regularised upper incomplete gamma `Q(a, x) = Γ(a, x)/Γ(a)` for `a > 0`, `x > 0`: the series
/// of `P = 1 − Q` below `x = a + 1`, Lentz's continued fraction of `Q` above (Numerical
/// Recipes §6.2), each to 1e-15 within 1000 terms.
fn upper_incomplete_gamma(a: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let ln_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_front.exp()).clamp(0.0, 1.0)
    } else {
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..=1000 {
            let an = -f64::from(i) * (f64::from(i) - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < TINY {
                d = TINY;
            }
            c = b + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_front.exp() * h).clamp(0.0, 1.0)
    }
}

/// `ln Γ(x)` for `x > 0` (Lanczos, g = 7, n = 9; relative error < 1e-15).
fn ln_gamma(x: f64) -> f64 {
    const COEF: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = COEF[0];
    let t = x + 7.5;
    for (i, c) in COEF.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularised incomplete beta `I_x(a, b)`.
fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_continued_fraction(x, a, b) / a
    } else {
        1.0 - front * beta_continued_fraction(1.0 - x, b, a) / b
    }
}

/// Lentz's evaluation of the continued fraction of `I_x(a, b)`.
fn beta_continued_fraction(x: f64, a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let guard = |v: f64| if v.abs() < TINY { TINY } else { v };
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 / guard(1.0 - qab * x / qap);
    let mut h = d;
    // One Lentz update with coefficient `aa`: returns the factor applied to h.
    let update = |aa: f64, c: &mut f64, d: &mut f64| {
        *d = 1.0 / guard(1.0 + aa * *d);
        *c = guard(1.0 + aa / *c);
        *d * *c
    };
    for m in 1..=300 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        h *= update(m * (b - m) * x / ((qam + m2) * (a + m2)), &mut c, &mut d);
        let del = update(
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
            &mut c,
            &mut d,
        );
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_floor_raises_only_the_smaller_standard_errors_and_keeps_the_correlation() {
        let hac = from_covariance(
            DMatrix::from_row_slice(2, 2, &[4.0, 1.2, 1.2, 1.0]),
            50,
            1.0,
        )
        .unwrap();
        let floor = from_covariance(
            DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 9.0]),
            50,
            1.0,
        )
        .unwrap();
        let out = at_least(hac.clone(), &floor).unwrap();
        assert_eq!(out.std_error[0], 2.0);
        assert!((out.std_error[1] - 3.0).abs() < 1e-12);
        assert!((out.correlation[(0, 1)] - hac.correlation[(0, 1)]).abs() < 1e-12);
        assert!((out.ci95_half_width[1] / hac.ci95_half_width[1] - 3.0).abs() < 1e-12);
    }

    #[test]
    fn equal_runs_split_repeated_readings() {
        assert_eq!(equal_runs(&[1.0, 1.0, 2.0, 2.0, 2.0, 1.0]), vec![2, 3, 1]);
        assert_eq!(equal_runs(&[]), Vec::<usize>::new());
        assert_eq!(equal_runs(&[0.5]), vec![1]);
    }

    /// A run of `m` rows sharing one error counts once, with `m²` times one row's score
    /// variance (rows of equal score), where rows taken apart count `m` times; runs of one row
    /// give back the plain estimate; lengths that do not add up are refused.
    #[test]
    fn runs_are_one_error_each() {
        let n = 400;
        let jac = DMatrix::from_fn(n, 1, |_, _| 1.0);
        // An error held for four samples at a time, sign alternating from run to run.
        let r: Vec<f64> = (0..n)
            .map(|i| if (i / 4) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let plain = newey_west_score_covariance(&r, &jac, &[n]).unwrap();
        let ones = newey_west_run_covariance(&r, &jac, &[n], &vec![1; n]).unwrap();
        assert_eq!(plain, ones);
        let runs = newey_west_run_covariance(&r, &jac, &[n], &vec![4; n / 4]).unwrap();
        // Run sums ±4, alternating: lag-0 term 100 · 16; the Bartlett lags of the alternating
        // series take some of it back, never all.
        assert!(runs[(0, 0)] > 0.0 && runs[(0, 0)] < 1600.0 + 1e-9);
        let same = vec![1.0; n];
        let held = newey_west_run_covariance(&same, &jac, &[n], &vec![4; n / 4]).unwrap();
        let apart = newey_west_run_covariance(&same, &jac, &[n], &vec![1; n]).unwrap();
        assert!(held[(0, 0)] > apart[(0, 0)]);
        assert!(newey_west_run_covariance(&r, &jac, &[n], &[3; 100]).is_none());
        assert!(newey_west_run_covariance(&r, &jac, &[200, 200], &[3, 397]).is_none());
    }

    /// Reference quantiles t_{0.975, ν} from standard tables (e.g. NIST/SEMATECH e-Handbook,
    /// Table 1.3.6.7.2), printed to 3 decimals; tolerance 5e-4.
    /// Chi-square, normal and F tails against tabled values (NIST/SEMATECH e-Handbook,
    /// Tables 1.3.6.7.1, 1.3.6.7.3, 1.3.6.7.4): the 5 % and 1 % critical values give back
    /// their tail probabilities.
    #[test]
    fn tail_probabilities_match_tables() {
        for (x, nu, p) in [
            (3.841, 1.0, 0.05),
            (6.635, 1.0, 0.01),
            (11.070, 5.0, 0.05),
            (37.566, 20.0, 0.01),
            (124.342, 100.0, 0.05),
        ] {
            let got = chi_square_sf(x, nu);
            assert!((got - p).abs() < 5e-3 * p, "χ²({nu}) at {x}: {got}");
        }
        assert!((chi_square_sf(2.0, 2.0) - (-1.0f64).exp()).abs() < 1e-14);
        assert!((normal_sf(1.959_964) - 0.025).abs() < 1e-7);
        assert!((normal_sf(-1.0) - 0.841_344_746).abs() < 1e-8);
        for (f, d1, d2, p) in [
            (4.103, 2.0, 10.0, 0.05),
            (2.696, 3.0, 100.0, 0.05),
            (3.984, 3.0, 100.0, 0.01),
        ] {
            let got = f_sf(f, d1, d2);
            assert!((got - p).abs() < 1e-2 * p, "F({d1}, {d2}) at {f}: {got}");
        }
    }

    #[test]
    fn t_quantiles_match_tables() {
        let table = [
            (1.0, 12.706),
            (2.0, 4.303),
            (3.0, 3.182),
            (5.0, 2.571),
            (10.0, 2.228),
            (30.0, 2.042),
            (100.0, 1.984),
            (1e6, 1.960),
        ];
        for (nu, t) in table {
            let q = student_t_quantile(0.975, nu);
            assert!((q - t).abs() < 5e-4, "ν = {nu}: {q} vs {t}");
        }
        assert!((student_t_quantile(0.5, 7.0)).abs() < 1e-12);
        assert!((student_t_quantile(0.025, 10.0) + 2.228).abs() < 5e-4);
    }

    /// A parameter that three samples determine (a rise a few samples long) beside one the
    /// whole series informs: over many draws of white noise the Newey–West estimate from the
    /// fitted residuals falls well short of the true score variance `JᵀJ` for the first,
    /// while with [`fitted_residual_bias`] added it is right for both.
    #[test]
    fn fitted_residual_bias_restores_the_score_variance_of_a_local_parameter() {
        let n = 400;
        let jac = DMatrix::from_fn(n, 2, |i, j| match j {
            0 => 1.0,
            _ => [3.0, 2.0, 1.0]
                .get(i.wrapping_sub(10))
                .copied()
                .unwrap_or(0.0),
        });
        let h_inv = scaled_inverse(&jac.tr_mul(&jac)).unwrap();
        let projector = &jac * &h_inv * jac.transpose();
        let layout = SeriesLayout {
            series: vec![Some(0); n],
            lags: vec![newey_west_lags(n)],
        };
        let truth = jac.tr_mul(&jac);
        let mut rng = motor_model::NoiseRng::new(5);
        let draws = 4000;
        let (mut plain, mut corrected) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 2));
        for _ in 0..draws {
            let e = nalgebra::DVector::from_fn(n, |_, _| rng.normal());
            let r: Vec<f64> = (&e - &projector * &e).iter().copied().collect();
            let nw = newey_west_score_covariance(&r, &jac, &[n]).unwrap();
            corrected += &nw + fitted_residual_bias(&r, &jac, &h_inv, &layout).unwrap();
            plain += nw;
        }
        let (plain, corrected) = (plain / draws as f64, corrected / draws as f64);
        for k in 0..2 {
            let ratio = corrected[(k, k)] / truth[(k, k)];
            assert!((ratio - 1.0).abs() < 0.05, "parameter {k}: {ratio}");
        }
        assert!(plain[(1, 1)] < 0.5 * truth[(1, 1)], "{}", plain[(1, 1)]);
    }

    /// [`fitted_residual_bias`] by its definition, `Σ_series v_s Σ_{|a−b|≤L} w_ab Pᵢⱼ JᵢJⱼᵀ`,
    /// term by term.
    fn bias_by_definition(
        r: &[f64],
        jac: &DMatrix<f64>,
        h_inv: &DMatrix<f64>,
        layout: &SeriesLayout,
    ) -> DMatrix<f64> {
        let q = jac.ncols();
        let projector = jac * h_inv * jac.transpose();
        let mut total = DMatrix::zeros(q, q);
        for (s, &lags) in layout.lags.iter().enumerate() {
            let idx: Vec<usize> = (0..r.len())
                .filter(|&i| layout.series[i] == Some(s))
                .collect();
            let free = idx.len() as f64 - idx.iter().map(|&i| projector[(i, i)]).sum::<f64>();
            let v = idx.iter().map(|&i| r[i] * r[i]).sum::<f64>() / free;
            let lags = lags.max(1);
            for (a, &i) in idx.iter().enumerate() {
                for (b, &j) in idx.iter().enumerate() {
                    let d = a.abs_diff(b);
                    if d <= lags {
                        let weight = 1.0 - d as f64 / (lags as f64 + 1.0);
                        total +=
                            v * weight * projector[(i, j)] * jac.row(i).transpose() * jac.row(j);
                    }
                }
            }
        }
        (&total + total.transpose()) * 0.5
    }

    /// The running-window [`fitted_residual_bias`] equals its definition: series of many
    /// windows, of fewer rows than a window, of one row, interleaved, and rows in none.
    #[test]
    fn fitted_residual_bias_matches_its_definition() {
        let mut rng = motor_model::NoiseRng::new(9);
        let n = 260;
        let q = 5;
        let jac = DMatrix::from_fn(n, q, |_, _| rng.normal());
        let r: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let h_inv = scaled_inverse(&jac.tr_mul(&jac)).unwrap();
        let series: Vec<Option<usize>> = (0..n)
            .map(|i| match i {
                0..=199 => Some(i % 2),
                200..=205 => Some(2),
                206 => Some(3),
                207..=209 => None,
                _ => Some(i % 2),
            })
            .collect();
        let layout = SeriesLayout {
            series,
            lags: vec![5, 3, 9, 2],
        };
        let fast = fitted_residual_bias(&r, &jac, &h_inv, &layout).unwrap();
        let slow = bias_by_definition(&r, &jac, &h_inv, &layout);
        assert!(
            (&fast - &slow).norm() < 1e-12 * slow.norm(),
            "{fast} {slow}"
        );
    }

    /// The whole-vector Newey–West covariance equals the accumulator's, series by series.
    #[test]
    fn score_covariance_of_the_whole_vector_matches_the_accumulator() {
        let n = [300usize, 1, 120, 3, 7];
        let rows: usize = n.iter().sum();
        let mut x = 0.3_f64;
        let mut next = || {
            x = (x * 3.7 + 0.11).fract();
            x - 0.5
        };
        let r: Vec<f64> = (0..rows).map(|_| next()).collect();
        let jac = DMatrix::from_fn(rows, 3, |_, _| next());
        let whole = newey_west_score_covariance(&r, &jac, &n).unwrap();
        let mut acc = NeweyWest::new(3, n[0]);
        let mut at = 0;
        for (k, len) in n.iter().enumerate() {
            if k > 0 {
                acc.new_series(*len);
            }
            for i in at..at + len {
                let g: Vec<f64> = (0..3).map(|j| r[i] * jac[(i, j)]).collect();
                acc.push(&g);
            }
            at += len;
        }
        let series = acc.finish().unwrap();
        assert!(
            (&whole - &series).norm() < 1e-12 * series.norm(),
            "{whole} {series}"
        );
        assert!(newey_west_score_covariance(&r, &jac, &[rows - 1]).is_none());
    }
}
