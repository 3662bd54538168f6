//! The mechanical side of a current- or force-driven axis by inverse-model least squares
//! (IDIM-LS, as in the EMPS benchmark): `τ = J q̈ + f q̇ + Ts sign(q̇) + offset`.
//!
//! The drive closes a current loop, so the motor torque (or force) is known from the current
//! and the torque constant, and the model is linear in `θ = [J, f, Ts, offset]`. The position
//! is filtered forward and backward by a Butterworth low-pass (no lag), differentiated by
//! central differences; every column of the observation matrix and the torque are then
//! low-passed and decimated alike; θ is the least-squares solution. This works in open or
//! closed loop (the regressors are measured signals, not simulated ones).

use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::lm::NormalEquations;
use crate::signal::{decimate, Butterworth};
use crate::stats::uncertainty;

/// Names of the mechanical parameters, in the order of every array here.
pub const MECHANICAL_NAMES: [&str; 4] = ["J", "f", "Ts", "offset"];

/// Settings of the inverse-model identification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseModelSettings {
    /// Cut-off of the zero-phase Butterworth filter on the position \[Hz\] (the EMPS rule:
    /// at least 5 times the closed-loop bandwidth).
    pub position_cutoff_hz: f64,
    /// Order of that filter (even).
    pub position_filter_order: usize,
    /// Decimation factor of the parallel filtering (1 = none).
    pub decimation: usize,
    /// Whether the constant offset (a constant load torque, or a drive's current offset) is
    /// fitted. When the axis moves in one direction only, `sign(q̇)` is constant and the offset
    /// cannot be told from Ts: fixing it at 0 leaves Ts to carry any constant load. A
    /// voltage-driven motor's own torque `k I` has no offset (Eq. (2b)).
    pub fit_offset: bool,
}

impl Default for InverseModelSettings {
    /// 100 Hz order-4 position filter, decimation by 10 (1 kHz records; EMPS: 20 Hz loop).
    fn default() -> Self {
        InverseModelSettings {
            position_cutoff_hz: 100.0,
            position_filter_order: 4,
            decimation: 10,
            fit_offset: true,
        }
    }
}

/// Result of the inverse-model identification (units of the axis: for a rotary axis
/// kg·m², N·m·s/rad, N·m, N·m; for a linear one kg, N·s/m, N, N).
#[derive(Debug, Clone, PartialEq)]
pub struct MechanicalFit {
    /// `[J, f, Ts, offset]` (offset exactly 0 when it is not fitted).
    pub values: [f64; 4],
    /// 95 % intervals (Student t on the least-squares covariance, as `nlparci`).
    pub ci95: Option<[[f64; 2]; 4]>,
    /// Correlation matrix (4 × 4, or 3 × 3 of J, f, Ts when the offset is fixed).
    pub correlation: Option<DMatrix<f64>>,
    /// Samples used after decimation.
    pub samples: usize,
    /// RMS of the torque residual after filtering (torque unit).
    pub residual_rms: f64,
    /// `100 (1 − ‖τ − Φθ‖/‖τ − τ̄‖)` \[%\].
    pub nrmse_fit_percent: f64,
    /// The fitted samples: torque as measured and as the model gives it, both low-passed and
    /// decimated as in the fit (torque unit).
    pub fitted: FittedTorque,
}

impl MechanicalFit {
    /// The identified axis with named fields: J (or M), f, Ts and the offset, in the units of the
    /// torque (force) column and the position (kg or kg·m², N·s/m or N·m·s/rad, N or N·m).
    pub fn axis(&self) -> motor_model::AxisParams {
        let [mass_kg, viscous_ns_per_m, coulomb_n, offset_n] = self.values;
        motor_model::AxisParams {
            mass_kg,
            viscous_ns_per_m,
            coulomb_n,
            offset_n,
        }
    }
}

/// The torque the inverse model was fitted to, and its model, on the decimated grid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FittedTorque {
    /// Time of the first fitted sample from the record's first sample \[s\].
    pub t0_s: f64,
    /// Their spacing \[s\] (the sample period times the decimation).
    pub dt_s: f64,
    /// Measured (filtered) torque.
    pub measured: Vec<f64>,
    /// `Φθ`: the model's torque.
    pub model: Vec<f64>,
}

/// Identifies `[J, f, Ts, offset]` from the motor torque (or force) `torque` and the position
/// `position`, sampled every `dt` \[s\].
pub fn identify_inverse_model(
    dt: f64,
    torque: &[f64],
    position: &[f64],
    settings: InverseModelSettings,
) -> Result<MechanicalFit, FitError> {
    let bad = |series: &str, reason: String| FitError::BadData {
        series: series.into(),
        reason,
    };
    let n = torque.len();
    if position.len() != n {
        return Err(bad(
            "position",
            format!(
                "{} samples where the torque has {n}: the channels must align",
                position.len()
            ),
        ));
    }
    let min = 20 * settings.decimation.max(1) + 10;
    if n < min {
        return Err(bad(
            "record",
            format!(
                "{n} samples: at least {min} are needed with decimation {}",
                settings.decimation
            ),
        ));
    }
    for (name, y) in [("torque", torque), ("position", position)] {
        if let Some((i, v)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(bad(name, format!("sample {i} is {v}: remove or repair it")));
        }
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(FitError::InvalidSetting {
            name: "sample period",
            value: dt,
            expected: "a positive period",
        });
    }
    let filter = Butterworth::low_pass(
        settings.position_filter_order,
        settings.position_cutoff_hz,
        1.0 / dt,
    )?;
    let q = filter.filtfilt(position);
    let qd = central(&q, dt);
    let qdd = central(&qd, dt);
    if qd.iter().all(|v| *v == 0.0) {
        return Err(bad(
            "position",
            "the axis never moves: nothing to identify".into(),
        ));
    }
    let mut columns = vec![
        qdd,
        qd.clone(),
        qd.iter()
            .map(|v| {
                if *v > 0.0 {
                    1.0
                } else if *v < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            })
            .collect(),
    ];
    if settings.fit_offset {
        columns.push(vec![1.0; n]);
    }
    let p = columns.len();
    let k = settings.decimation.max(1);
    let y = decimate(torque, k)?;
    let phi: Vec<Vec<f64>> = columns
        .iter()
        .map(|c| decimate(c, k))
        .collect::<Result<_, _>>()?;
    // Drop the ends, where the filters' edge handling dominates (10 decimated samples each).
    let edge = 10.min(y.len() / 4);
    let rows = edge..y.len() - edge;
    let m = rows.len();
    let a = DMatrix::from_fn(m, p, |i, j| phi[j][rows.start + i]);
    let b = DVector::from_iterator(m, rows.clone().map(|i| y[i]));
    let jtj = a.transpose() * &a;
    let jtb = a.transpose() * &b;
    let theta = jtj
        .clone()
        .cholesky()
        .map(|c| c.solve(&jtb))
        .ok_or_else(|| bad("record", "the regressors are collinear: the motion does not excite J, f, Ts and the offset separately (use a richer trajectory)".into()))?;
    let model = &a * &theta;
    let fitted = FittedTorque {
        t0_s: rows.start as f64 * k as f64 * dt,
        dt_s: k as f64 * dt,
        measured: b.iter().copied().collect(),
        model: model.iter().copied().collect(),
    };
    let residual = model - &b;
    let sse = residual.norm_squared();
    let mean = b.mean();
    let sst = b.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    let normal = NormalEquations {
        jtj,
        jtr: a.transpose() * &residual,
        cost: 0.5 * sse,
        n_residuals: m,
    };
    let unc = uncertainty(&normal);
    // A fixed offset is exactly 0, its interval [0, 0].
    let values: [f64; 4] = std::array::from_fn(|i| theta.get(i).copied().unwrap_or(0.0));
    let half = |u: &crate::stats::Uncertainty, i: usize| u.ci95_half_width.get(i).copied();
    Ok(MechanicalFit {
        values,
        ci95: unc.as_ref().map(|u| {
            std::array::from_fn(|i| {
                let h = half(u, i).unwrap_or(0.0);
                [values[i] - h, values[i] + h]
            })
        }),
        correlation: unc.map(|u| u.correlation),
        samples: m,
        residual_rms: (sse / m as f64).sqrt(),
        nrmse_fit_percent: if sst > 0.0 {
            100.0 * (1.0 - (sse / sst).sqrt())
        } else {
            f64::NAN
        },
        fitted,
    })
}

/// Central differences on a uniform grid (one-sided at the ends).
fn central(y: &[f64], dt: f64) -> Vec<f64> {
    let n = y.len();
    (0..n)
        .map(|i| match (i, n) {
            (_, 0 | 1) => 0.0,
            (0, _) => (y[1] - y[0]) / dt,
            (i, n) if i + 1 == n => (y[i] - y[i - 1]) / dt,
            (i, _) => (y[i + 1] - y[i - 1]) / (2.0 * dt),
        })
        .collect()
}
