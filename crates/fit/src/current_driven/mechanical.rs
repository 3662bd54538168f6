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
use crate::estimation::lm::NormalEquations;
use crate::estimation::signal::{decimate, Butterworth};
use crate::estimation::stats::{sandwich_uncertainty, NeweyWest};

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
    /// The identified axis: J (or M), f, Ts and the offset, in the units of the torque (force)
    /// column and the position (kg or kg·m², N·s/m or N·m·s/rad, N or N·m); the offset is
    /// exactly 0 when it is not fitted.
    pub axis: motor_model::AxisParams,
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
    /// Whether the offset was fitted, or fixed at 0 and why.
    pub offset_status: OffsetStatus,
    /// The fitted samples of each record, in the order given: torque as measured and as the
    /// model gives it, both low-passed and decimated as in the fit (torque unit); samples at
    /// rest are left out.
    pub fitted: Vec<FittedTorque>,
    /// The parameters corrected for the position's quantisation minus [`MechanicalFit::axis`]
    /// (each in its unit, linear or rotary as `axis`): the
    /// position step, differentiated once and twice behind the filters, is noise in the q̇ and
    /// q̈ columns and biases the least-squares solution towards 0 (errors in the regressors).
    /// The correction is the bias-compensated solution `(ΦᵀΦ − Σ) θ = Φᵀτ`, with `Σ` the
    /// quantisation noise's covariance in the columns; the 95 % intervals are widened by it on
    /// its side.
    pub quantisation_bias: motor_model::AxisParams,
}

/// Units of J, f, Ts and the offset of a rotary axis (torque in N·m, angle in rad).
pub const MECHANICAL_UNITS_ROTARY: [&str; 4] = ["kg·m²", "N·m·s/rad", "N·m", "N·m"];
/// Units of M, Fv, Fc and the offset of a linear axis (force in N, position in m).
pub const MECHANICAL_UNITS_LINEAR: [&str; 4] = ["kg", "N·s/m", "N", "N"];

impl MechanicalFit {
    /// J, f, Ts and the offset with their names ([`MECHANICAL_NAMES`]), `units`
    /// ([`MECHANICAL_UNITS_ROTARY`] or [`MECHANICAL_UNITS_LINEAR`], as the records are) and
    /// 95 % intervals, in that order.
    pub fn estimates(
        &self,
        units: [&'static str; 4],
    ) -> [crate::estimation::parameters::ParameterEstimate; 4] {
        let a = &self.axis;
        let values = [a.mass_kg, a.viscous_ns_per_m, a.coulomb_n, a.offset_n];
        std::array::from_fn(|i| crate::estimation::parameters::ParameterEstimate {
            name: MECHANICAL_NAMES[i],
            unit: units[i],
            value: values[i],
            ci95: self.ci95.map(|c| c[i]),
        })
    }
}

/// The torque the inverse model was fitted to, and its model, on the decimated grid (the
/// samples in motion only: where the axis rests the grid has gaps).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FittedTorque {
    /// Time of each fitted sample from the record's first sample \[s\].
    pub t_s: Vec<f64>,
    /// Measured (filtered) torque.
    pub measured: Vec<f64>,
    /// `Φθ`: the model's torque.
    pub model: Vec<f64>,
}

/// One record of a current- or force-driven axis for [`identify_inverse_model_pooled`].
#[derive(Debug, Clone, Copy)]
pub struct AxisRecord<'a> {
    /// Sample period \[s\].
    pub dt: f64,
    /// Motor torque (or force) `k I` at each sample (axis torque unit).
    pub torque: &'a [f64],
    /// Position (rad or m) at each sample, any offset.
    pub position: &'a [f64],
}

/// What became of the constant offset of an inverse-model fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum OffsetStatus {
    /// Fitted with the other parameters (the axis moved both ways).
    Fitted,
    /// Fixed at 0 because the settings say so ([`InverseModelSettings::fit_offset`] false).
    FixedBySettings,
    /// Fixed at 0 because the axis moved in one direction only: `sign(q̇)` is then constant
    /// while it moves, so a constant load cannot be told from Ts, and Ts carries it.
    FixedOneDirection,
}

/// Fewest decimated rows in each direction of motion for the offset to be told from Ts.
pub(crate) const MIN_ROWS_EACH_WAY: usize = 20;

/// Identifies `[J, f, Ts, offset]` from the motor torque (or force) `torque` and the position
/// `position`, sampled every `dt` \[s\] ([`identify_inverse_model_pooled`] of one record).
pub fn identify_inverse_model(
    dt: f64,
    torque: &[f64],
    position: &[f64],
    settings: InverseModelSettings,
) -> Result<MechanicalFit, FitError> {
    identify_inverse_model_pooled(
        &[AxisRecord {
            dt,
            torque,
            position,
        }],
        settings,
    )
}

/// The regressor rows of one record: its observation matrix columns (`q̈`, `q̇`, `sign q̇`)
/// and torque, filtered and decimated, ends dropped, samples at rest left out.
pub(crate) struct Rows {
    /// `q̈`, `q̇` and `sign q̇` at each row (position unit per s², per s; sign).
    pub(crate) columns: [Vec<f64>; 3],
    /// The filtered position at each row (rad or m).
    pub(crate) position: Vec<f64>,
    /// The position quantisation's share of the q̈ and q̇ columns: the quantisation error of a
    /// smoothed position ([`quantisation_probe`]), filtered, differentiated and decimated like
    /// the position.
    pub(crate) quantisation: [Vec<f64>; 2],
    /// The torque (or force) at each row, low-passed and decimated like the columns.
    pub(crate) torque: Vec<f64>,
    /// Time of each row from the record's first sample \[s\].
    pub(crate) t_s: Vec<f64>,
}

/// Filters, differentiates and decimates record `index` (0-based) into regressor rows.
fn record_rows(
    index: usize,
    rec: &AxisRecord<'_>,
    settings: &InverseModelSettings,
) -> Result<Rows, FitError> {
    let label = |series: &str| {
        if index == 0 {
            series.to_string()
        } else {
            format!("record {} {series}", index + 1)
        }
    };
    let bad = |series: &str, reason: String| FitError::BadData {
        series: label(series),
        reason,
    };
    let (dt, torque, position) = (rec.dt, rec.torque, rec.position);
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
    let min = min_samples(settings.decimation);
    if n < min {
        return Err(bad(
            "record",
            format!(
                "{n} samples: at least {min} are needed, the speed and acceleration being read \
                 {} (record for longer, or at a higher rate)",
                match settings.decimation {
                    0 | 1 => "at every sample".to_string(),
                    d => format!("every {d} samples"),
                }
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
    // At rest the filtered speed is rounding noise around 0 and the friction torque is anything
    // in [−Ts, Ts] (static friction holds the axis): such samples carry no equation. The axis
    // is at rest where the filtered speed stays below half a position step per filter time
    // constant (the step: the smallest change of the position record).
    let quantum = position
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let peak_speed = qd.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if peak_speed == 0.0 || !quantum.is_finite() {
        return Err(bad(
            "position",
            "the axis never moves: nothing to identify — record it with a voltage (or current command) that breaks the friction, Eq. (11)".into(),
        ));
    }
    let rest_speed = (0.5 * quantum * std::f64::consts::TAU * settings.position_cutoff_hz)
        .max(1e-9 * peak_speed);
    let moving: Vec<f64> = qd
        .iter()
        .map(|v| f64::from(u8::from(v.abs() > rest_speed)))
        .collect();
    let sign: Vec<f64> = qd
        .iter()
        .zip(&moving)
        .map(|(v, m)| m * v.signum())
        .collect();
    let k = settings.decimation.max(1);
    let y = decimate(torque, k)?;
    let cols = [decimate(&qdd, k)?, decimate(&qd, k)?, decimate(&sign, k)?];
    let q_rows = decimate(&q, k)?;
    // The true position is estimated at a quarter of the cut-off (still above the motion's
    // bandwidth by the EMPS rule), so that the position steps themselves are smoothed out.
    let smooth = Butterworth::low_pass(
        settings.position_filter_order,
        0.25 * settings.position_cutoff_hz,
        1.0 / dt,
    )?
    .filtfilt(position);
    let noise_q = filter.filtfilt(&quantisation_probe(
        &smooth,
        position[0],
        position_step(position),
    ));
    let noise_qd = central(&noise_q, dt);
    let noise_qdd = central(&noise_qd, dt);
    let noise = [decimate(&noise_qdd, k)?, decimate(&noise_qd, k)?];
    // A decimated row is at rest if any sample behind it is (the decimation filter's span).
    let span = 2 * k + 1;
    let moving_run: Vec<bool> = (0..y.len())
        .map(|r| {
            let c = r * k;
            let lo = c.saturating_sub(span);
            let hi = (c + span + 1).min(n);
            moving[lo..hi].iter().all(|m| *m == 1.0)
        })
        .collect();
    // Drop the ends, where the filters' edge handling dominates (10 decimated samples each).
    let edge = 10.min(y.len() / 4);
    let keep: Vec<usize> = (edge..y.len() - edge).filter(|&r| moving_run[r]).collect();
    Ok(Rows {
        columns: cols.map(|c| keep.iter().map(|&r| c[r]).collect()),
        position: keep.iter().map(|&r| q_rows[r]).collect(),
        quantisation: noise.map(|c| keep.iter().map(|&r| c[r]).collect()),
        torque: keep.iter().map(|&r| y[r]).collect(),
        t_s: keep.iter().map(|&r| (r * k) as f64 * dt).collect(),
    })
}

/// The motor torque `k I` of Eq. (2b) at each sample of `current` \[A\], with the torque
/// constant `k_nm_per_a` \[N·m/A\] (on a linear axis N/A, the force \[N\]): the `torque` of an
/// [`AxisRecord`] of a current-driven axis.
pub fn motor_torque(k_nm_per_a: f64, current: &[f64]) -> Vec<f64> {
    current.iter().map(|i| k_nm_per_a * i).collect()
}

/// The regressor rows of every record (see [`identify_inverse_model_pooled`]).
pub(crate) fn regressor_rows(
    records: &[AxisRecord<'_>],
    settings: &InverseModelSettings,
) -> Result<Vec<Rows>, FitError> {
    records
        .iter()
        .enumerate()
        .map(|(i, r)| record_rows(i, r, settings))
        .collect()
}

/// Identifies `[J, f, Ts, offset]` from several records of one axis, pooled into one least
/// squares problem: each record is filtered and differentiated on its own (its own filter
/// state, no jump where one record ends and the next begins), samples at rest are left out
/// (static friction holds any torque up to Ts there), and the rows are stacked. The offset is
/// fitted when [`InverseModelSettings::fit_offset`] asks for it and the records move both ways
/// for at least 20 decimated samples each; else it is fixed at 0 and Ts carries any constant
/// load ([`MechanicalFit::offset_status`] says which).
pub fn identify_inverse_model_pooled(
    records: &[AxisRecord<'_>],
    settings: InverseModelSettings,
) -> Result<MechanicalFit, FitError> {
    let bad = |series: &str, reason: String| FitError::BadData {
        series: series.into(),
        reason,
    };
    if records.is_empty() {
        return Err(bad("records", "no record given".into()));
    }
    let rows = regressor_rows(records, &settings)?;
    let m: usize = rows.iter().map(|r| r.torque.len()).sum();
    let (forward, backward) = rows
        .iter()
        .flat_map(|r| &r.columns[2])
        .fold((0, 0), |(f, b), s| {
            (f + usize::from(*s > 0.5), b + usize::from(*s < -0.5))
        });
    let offset_status = if !settings.fit_offset {
        OffsetStatus::FixedBySettings
    } else if forward.min(backward) < MIN_ROWS_EACH_WAY {
        OffsetStatus::FixedOneDirection
    } else {
        OffsetStatus::Fitted
    };
    let p = if offset_status == OffsetStatus::Fitted {
        4
    } else {
        3
    };
    if m < 2 * p {
        return Err(bad(
            "record",
            format!("{m} samples in motion after filtering and decimation: the axis must move for longer"),
        ));
    }
    let a = DMatrix::from_fn(m, p, |i, j| {
        let mut i = i;
        for r in &rows {
            if i < r.torque.len() {
                return if j < 3 { r.columns[j][i] } else { 1.0 };
            }
            i -= r.torque.len();
        }
        0.0
    });
    let b = DVector::from_iterator(m, rows.iter().flat_map(|r| r.torque.iter().copied()));
    let jtj = a.transpose() * &a;
    let jtb = a.transpose() * &b;
    let theta = jtj
        .clone()
        .cholesky()
        .map(|c| c.solve(&jtb))
        .ok_or_else(|| bad("record", "the regressors are collinear: the motion does not excite J, f and Ts separately (use a richer trajectory)".into()))?;
    // The quantisation noise's covariance in the q̈ and q̇ columns, summed over the rows.
    let mut sigma = DMatrix::zeros(p, p);
    for r in &rows {
        for i in 0..r.torque.len() {
            for j in 0..2 {
                for l in 0..2 {
                    sigma[(j, l)] += r.quantisation[j][i] * r.quantisation[l][i];
                }
            }
        }
    }
    let compensated = (&jtj - &sigma).cholesky().map(|c| c.solve(&jtb));
    let model = &a * &theta;
    let mut fitted = Vec::with_capacity(rows.len());
    let mut at = 0;
    for r in &rows {
        let len = r.torque.len();
        fitted.push(FittedTorque {
            t_s: r.t_s.clone(),
            measured: r.torque.clone(),
            model: model.rows(at, len).iter().copied().collect(),
        });
        at += len;
    }
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
    // Intervals from the Newey–West sandwich, record by record: the residuals of filtered,
    // decimated signals are correlated over several samples, and the plain least-squares
    // covariance would take them as independent.
    let mut nw = NeweyWest::new(p, rows.first().map_or(0, |r| r.torque.len()));
    let mut at = 0;
    let mut g = vec![0.0; p];
    for (k, r) in rows.iter().enumerate() {
        if k > 0 {
            nw.new_series(r.torque.len());
        }
        for i in at..at + r.torque.len() {
            for (j, gj) in g.iter_mut().enumerate() {
                *gj = residual[i] * a[(i, j)];
            }
            nw.push(&g);
        }
        at += r.torque.len();
    }
    let unc = nw.finish().and_then(|s| sandwich_uncertainty(&normal, &s));
    // A fixed offset is exactly 0, its interval [0, 0].
    let values: [f64; 4] = std::array::from_fn(|i| theta.get(i).copied().unwrap_or(0.0));
    let half =
        |u: &crate::estimation::stats::Uncertainty, i: usize| u.ci95_half_width.get(i).copied();
    let [mass_kg, viscous_ns_per_m, coulomb_n, offset_n] = values;
    let quantisation_bias =
        quantisation_bias(compensated.as_ref(), &values, unc.as_ref(), &settings)?;
    Ok(MechanicalFit {
        axis: motor_model::AxisParams {
            mass_kg,
            viscous_ns_per_m,
            coulomb_n,
            offset_n,
        },
        ci95: unc.as_ref().map(|u| {
            std::array::from_fn(|i| {
                let h = half(u, i).unwrap_or(0.0);
                let d = quantisation_bias[i];
                [values[i] - h + d.min(0.0), values[i] + h + d.max(0.0)]
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
        offset_status,
        fitted,
        quantisation_bias: motor_model::AxisParams {
            mass_kg: quantisation_bias[0],
            viscous_ns_per_m: quantisation_bias[1],
            coulomb_n: quantisation_bias[2],
            offset_n: quantisation_bias[3],
        },
    })
}

/// Largest quantisation bias of J, f or Ts the fit accepts, as a fraction of the parameter's
/// 95 % half-width: beyond it the first-order correction itself is no longer to be trusted.
const MAX_QUANTISATION_BIAS: f64 = 1.0;

/// The bias-compensated solution minus the least-squares one (see
/// [`MechanicalFit::quantisation_bias`]), or the refusal when the position's resolution does not
/// support the filter's cut-off: the bias of J, f or Ts exceeds its 95 % half-width, or the
/// quantisation noise in the columns is as large as the columns themselves.
fn quantisation_bias(
    compensated: Option<&DVector<f64>>,
    values: &[f64; 4],
    unc: Option<&crate::estimation::stats::Uncertainty>,
    settings: &InverseModelSettings,
) -> Result<[f64; 4], FitError> {
    let cutoff = settings.position_cutoff_hz;
    let refuse = |detail: String, lower_to: Option<f64>| {
        FitError::MethodDomain {
        equation: "the inverse model (IDIM-LS)",
        reason: format!(
            "the position cut-off {cutoff} Hz is above what the position's resolution supports: {detail}; {}",
            lower_to.map_or_else(
                || "lower the cut-off or record the position with a finer encoder".to_string(),
                |hz| format!("lower the cut-off to about {hz:.0} Hz or record the position with a finer encoder")
            )
        ),
    }
    };
    let Some(compensated) = compensated else {
        return Err(refuse(
            "the position step, differentiated twice, is as large as the acceleration itself"
                .into(),
            None,
        ));
    };
    let bias: [f64; 4] = std::array::from_fn(|i| compensated.get(i).map_or(0.0, |c| c - values[i]));
    let Some(u) = unc else {
        return Ok(bias);
    };
    let (worst, ratio) = (0..3)
        .map(|i| {
            let h = u.ci95_half_width.get(i).copied().unwrap_or(0.0);
            (i, bias[i].abs() / h)
        })
        .fold(
            (0, 0.0_f64),
            |w, c| if c.1 > w.1 || c.1.is_nan() { c } else { w },
        );
    if ratio > MAX_QUANTISATION_BIAS || ratio.is_nan() {
        // The q̈ noise power grows as the cut-off to the fifth power; aim at half the limit.
        let lower_to = cutoff * (0.5 * MAX_QUANTISATION_BIAS / ratio).powf(0.2);
        let name = MECHANICAL_NAMES[worst];
        return Err(refuse(
            format!(
                "the position step, differentiated twice, biases {name} by {:.1} % ({:.1} times its 95 % half-width)",
                100.0 * bias[worst] / values[worst].abs().max(f64::MIN_POSITIVE),
                ratio
            ),
            lower_to.is_finite().then_some(lower_to),
        ));
    }
    Ok(bias)
}

/// The position's resolution: the smallest change between samples, or between successive
/// changes (an axis that never moves slowly passes many steps per sample, but its changes
/// still differ by one step); changes below 1e-9 of the largest |position| are rounding.
fn position_step(position: &[f64]) -> f64 {
    let scale = position.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let floor = 1e-9 * scale;
    let first: Vec<f64> = position.windows(2).map(|w| w[1] - w[0]).collect();
    first
        .iter()
        .copied()
        .chain(first.windows(2).map(|w| w[1] - w[0]))
        .map(f64::abs)
        .filter(|d| *d > floor)
        .fold(f64::INFINITY, f64::min)
}

/// The quantisation error a position recorded in steps of `step` from `origin` would have if
/// the axis followed `smooth` (the position low-passed, an estimate of the true one): the
/// error keeps the record's own structure (a slow sawtooth at low speed, near-white noise when
/// several steps pass per sample).
fn quantisation_probe(smooth: &[f64], origin: f64, step: f64) -> Vec<f64> {
    smooth
        .iter()
        .map(|x| origin + ((x - origin) / step).round() * step - x)
        .collect()
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

/// Fewest samples a record needs for the inverse model at `decimation` (twenty decimated rows,
/// plus the filter's start).
pub(crate) fn min_samples(decimation: usize) -> usize {
    20 * decimation.max(1) + 10
}
