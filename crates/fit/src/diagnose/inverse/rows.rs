//! The stacked torque rows of a current-driven axis' records and the least-squares fits on
//! them: a candidate's regressor columns fitted with the motor's, the share of a column the
//! base model already explains, and the held-out statistics of a residual.

use nalgebra::{DMatrix, DVector};

use crate::current_driven::mechanical::Rows;
use crate::diagnose::localise::floor::correlation_factor;
use crate::diagnose::screen::CORRELATION_LAGS;

/// All rows of all records, stacked.
pub(crate) struct Stack {
    /// Regressor columns of the base model: q̈, q̇, sign q̇ (and 1 when the offset is fitted).
    pub(crate) base: Vec<Vec<f64>>,
    pub(crate) speed: Vec<f64>,
    pub(crate) sign: Vec<f64>,
    pub(crate) position: Vec<f64>,
    pub(crate) torque: Vec<f64>,
    /// −dτ/dt where both neighbours are adjacent rows, else 0.
    pub(crate) torque_rate: Vec<f64>,
    /// Row period \[s\].
    pub(crate) dt_row: f64,
    /// Per row: record index.
    pub(crate) record: Vec<usize>,
    /// Per row: held out.
    pub(crate) held: Vec<bool>,
    /// Start of each record's rows.
    pub(crate) starts: Vec<usize>,
}

impl Stack {
    pub(crate) fn len(&self) -> usize {
        self.torque.len()
    }
}

pub(crate) fn stack(
    rows: &[Rows],
    n_train: usize,
    fit_offset: bool,
    dt_row: f64,
    block: usize,
    every: usize,
) -> Stack {
    let mut s = Stack {
        base: vec![Vec::new(); if fit_offset { 4 } else { 3 }],
        speed: Vec::new(),
        sign: Vec::new(),
        position: Vec::new(),
        torque: Vec::new(),
        torque_rate: Vec::new(),
        dt_row,
        record: Vec::new(),
        held: Vec::new(),
        starts: Vec::new(),
    };
    for (k, r) in rows.iter().enumerate() {
        s.starts.push(s.torque.len());
        let n = r.torque.len();
        for i in 0..n {
            for (j, col) in s.base.iter_mut().enumerate() {
                col.push(if j < 3 { r.columns[j][i] } else { 1.0 });
            }
            s.speed.push(r.columns[1][i]);
            s.sign.push(r.columns[2][i]);
            s.position.push(r.position[i]);
            s.torque.push(r.torque[i]);
            let adjacent = |a: usize, b: usize| {
                (r.t_s[b] - r.t_s[a] - (b - a) as f64 * dt_row).abs() < 0.25 * dt_row
            };
            let rate = if i > 0 && i + 1 < n && adjacent(i - 1, i + 1) {
                -(r.torque[i + 1] - r.torque[i - 1]) / (2.0 * dt_row)
            } else {
                0.0
            };
            s.torque_rate.push(rate);
            s.record.push(k);
            s.held
                .push(k >= n_train || (i / block) % every == every - 1);
        }
    }
    s
}

/// A least-squares fit of the torque on `columns` over the training rows.
pub(crate) struct LsFit {
    pub(crate) theta: DVector<f64>,
    /// Residual `τ − Xθ` on every row.
    pub(crate) residual: Vec<f64>,
    /// `(XᵀX)⁻¹` of the training rows.
    pub(crate) inverse: DMatrix<f64>,
    /// Training sum of squares.
    pub(crate) sse: f64,
    /// Training rows.
    pub(crate) rows: usize,
}

pub(crate) fn least_squares(s: &Stack, columns: &[&[f64]]) -> Option<LsFit> {
    let train: Vec<usize> = (0..s.len()).filter(|&i| !s.held[i]).collect();
    let p = columns.len();
    if train.len() <= p + 1 {
        return None;
    }
    let x = DMatrix::from_fn(train.len(), p, |i, j| columns[j][train[i]]);
    let y = DVector::from_iterator(train.len(), train.iter().map(|&i| s.torque[i]));
    // Columns scaled to unit length, so that units of very different size count alike.
    let scale: Vec<f64> = (0..p)
        .map(|j| {
            let n = x.column(j).norm();
            if n > 0.0 {
                n
            } else {
                1.0
            }
        })
        .collect();
    let xs = DMatrix::from_fn(x.nrows(), p, |i, j| x[(i, j)] / scale[j]);
    let gram = xs.tr_mul(&xs);
    let inv_s = gram.clone().cholesky()?.inverse();
    let theta_s = &inv_s * xs.tr_mul(&y);
    let theta = DVector::from_fn(p, |j, _| theta_s[j] / scale[j]);
    let inverse = DMatrix::from_fn(p, p, |a, b| inv_s[(a, b)] / (scale[a] * scale[b]));
    let residual: Vec<f64> = (0..s.len())
        .map(|i| s.torque[i] - (0..p).map(|j| columns[j][i] * theta[j]).sum::<f64>())
        .collect();
    let sse = train.iter().map(|&i| residual[i] * residual[i]).sum();
    theta.iter().all(|v| v.is_finite()).then_some(LsFit {
        theta,
        residual,
        inverse,
        sse,
        rows: train.len(),
    })
}

/// Fraction of the length of `col` (over the training rows) left once projected off `base`.
pub(crate) fn projected_fraction(s: &Stack, base: &[&[f64]], col: &[f64]) -> f64 {
    let train: Vec<usize> = (0..s.len()).filter(|&i| !s.held[i]).collect();
    let x = DMatrix::from_fn(train.len(), base.len(), |i, j| base[j][train[i]]);
    let y = DVector::from_iterator(train.len(), train.iter().map(|&i| col[i]));
    let norm = y.norm();
    if norm.is_nan() || norm <= 0.0 {
        return 0.0;
    }
    let svd = x.clone().svd(true, true);
    match svd.solve(&y, 1e-12) {
        Ok(b) => (&y - &x * b).norm() / norm,
        Err(_) => 0.0,
    }
}

/// The correlation factor of the training residual, weighted over the records' runs.
pub(crate) fn residual_factor(s: &Stack, residual: &[f64]) -> f64 {
    let (mut weighted, mut count) = (0.0, 0usize);
    for (k, &start) in s.starts.iter().enumerate() {
        let end = s.starts.get(k + 1).copied().unwrap_or(s.len());
        let part: Vec<f64> = (start..end)
            .filter(|&i| !s.held[i])
            .map(|i| residual[i])
            .collect();
        if part.len() > CORRELATION_LAGS + 1 {
            weighted += correlation_factor(&part, CORRELATION_LAGS) * part.len() as f64;
            count += part.len();
        }
    }
    if count > 0 {
        weighted / count as f64
    } else {
        1.0
    }
}

/// Held-out squared error per block \[units of `variance`\].
pub(crate) fn block_sse(s: &Stack, residual: &[f64], variance: f64, block: usize) -> Vec<f64> {
    let mut out = Vec::new();
    let mut current: Option<(usize, usize)> = None;
    for (i, r) in residual.iter().enumerate().take(s.len()) {
        if !s.held[i] {
            continue;
        }
        let local = i - s.starts[s.record[i]];
        let key = (s.record[i], local / block);
        if current != Some(key) {
            out.push(0.0);
            current = Some(key);
        }
        if let Some(last) = out.last_mut() {
            *last += r * r / variance;
        }
    }
    out
}

/// NRMSE (SPEC section 7) of the rows `keep` selects: each record's, weighted by its rows.
pub(crate) fn nrmse_summary(s: &Stack, residual: &[f64], keep: impl Fn(usize) -> bool) -> f64 {
    let (mut weighted, mut count) = (0.0, 0usize);
    for (k, &start) in s.starts.iter().enumerate() {
        let end = s.starts.get(k + 1).copied().unwrap_or(s.len());
        let idx: Vec<usize> = (start..end).filter(|&i| keep(i)).collect();
        if idx.len() < 2 {
            continue;
        }
        let mean = idx.iter().map(|&i| s.torque[i]).sum::<f64>() / idx.len() as f64;
        let sst: f64 = idx.iter().map(|&i| (s.torque[i] - mean).powi(2)).sum();
        let sse: f64 = idx.iter().map(|&i| residual[i].powi(2)).sum();
        if sst > 0.0 {
            weighted += (sse / sst).sqrt() * idx.len() as f64;
            count += idx.len();
        }
    }
    if count > 0 {
        weighted / count as f64
    } else {
        f64::NAN
    }
}

/// The columns as slices.
pub(crate) fn slices(cols: &[Vec<f64>]) -> Vec<&[f64]> {
    cols.iter().map(Vec::as_slice).collect()
}

pub(crate) fn model_of(s: &Stack, residual: &[f64]) -> Vec<f64> {
    s.torque.iter().zip(residual).map(|(y, r)| y - r).collect()
}
