//! The diagnosis of a current- (or force-) driven axis: where the inverse model
//! `τ = J q̈ + f q̇ + Ts sign(q̇) + offset` ([`crate::identify_inverse_model_pooled`], IDIM-LS)
//! still disagrees with the measured torque, and which mechanical effect of SPEC section 5
//! explains the disagreement on held-out data.
//!
//! The drive imposes the current, so the residual lives on the torque channel: the measured
//! `k I` against the torque the model needs for the measured motion, on the filtered,
//! decimated rows of the inverse model (samples at rest left out). It is localised in units of
//! the current column (the residual divided by the torque constant, as the current channel of
//! [`crate::diagnose::localise`]): noise floor, phases, time windows of largest excess, speed
//! and current bands, spectrum, shaft-angle ripple (rotary axes), whiteness.
//!
//! **Candidates.** The inverse model is linear in its parameters, and so is every mechanical
//! effect once its shape is fixed; each candidate adds regressor columns and is refitted by
//! least squares on the training rows:
//! - `stribeck_friction`: `sign(q̇) exp(−(q̇/Ωs)²)`, its coefficient `Tst − Ts`; `Ωs` from a
//!   grid of fractions of the largest |q̇| (the best training fit);
//! - `quadratic_drag`: `q̇ |q̇|`, coefficient `c`;
//! - `cogging_torque` (rotary axes only): `sin(Nθ)`, `cos(Nθ)`, `N` from 1 to
//!   [`LocaliseSettings::max_harmonic`] (the best training fit), each row only while the
//!   harmonic turns at most 0.4 cycles per row;
//! - `current_sensor_lag`: `−dτ/dt` (a sensor lagging by `τf` reads `I` with
//!   `I_true ≈ I + τf dI/dt`), coefficient `τf`.
//!
//! The electrical effects (`thermal_drift`, `brush_drop`, `inductance_saturation`) change how
//! the voltage makes the current; a drive that imposes the current hides them: they are *not
//! testable from these records*, as is an effect whose columns the base columns already span.
//!
//! **Held-out data and the verdict.** As in [`crate::diagnose::run`]: validation records are
//! held out whole, else every [`InverseDiagnoseSettings::holdout_every`]-th block of
//! [`InverseDiagnoseSettings::block_rows`] rows (not shortened on short records, unlike
//! there). The squared errors are counted in units of the
//! base model's training residual variance (the inverse model's residual is mostly model error,
//! not sensor noise, and an improvement is judged against what the base model leaves), the
//! training statistic divided by the residual's correlation factor. Candidates are ranked by
//! [`crate::diagnose::verdict::rank_candidates`]; a candidate is named only if in addition its
//! paired held-out test is significant at the same level, so that no effect is named that the
//! held-out rows do not back.

mod rows;

use serde::Serialize;

use motor_model::{EffectKind, Effects};

use crate::current_driven::mechanical::{
    identify_inverse_model_pooled, regressor_rows, AxisRecord, InverseModelSettings, MechanicalFit,
    OffsetStatus, Rows, MECHANICAL_NAMES, MECHANICAL_UNITS_LINEAR, MECHANICAL_UNITS_ROTARY,
};
use crate::diagnose::inverse::rows::block_sse;
use crate::diagnose::inverse::rows::least_squares;
use crate::diagnose::inverse::rows::model_of;
use crate::diagnose::inverse::rows::nrmse_summary;
use crate::diagnose::inverse::rows::projected_fraction;
use crate::diagnose::inverse::rows::residual_factor;
use crate::diagnose::inverse::rows::slices;
use crate::diagnose::inverse::rows::stack;
use crate::diagnose::inverse::rows::LsFit;
use crate::diagnose::inverse::rows::Stack;
use crate::diagnose::localise::{
    localise_with_floors, Localisation, LocaliseSettings, ResidualChannel, ResidualRecord,
};
use crate::diagnose::report::{
    Assessment, CandidateReport, DiagnoseError, EffectParam, ParamShift,
};
use crate::diagnose::verdict::{rank_candidates, CandidateScore, VerdictSettings};
use crate::diagnose::Stage;
use crate::error::FitError;
use crate::estimation::records::{noise_std, Channel};
use crate::estimation::stats::student_t_quantile;

/// Fractions of the largest |q̇| tried as the Stribeck speed `Ωs`.
const STRIBECK_SPEED_FRACTIONS: [f64; 6] = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2];
/// A candidate column keeps less than this fraction of its length once projected off the
/// base columns: the records cannot tell it from the base model (as in
/// [`crate::diagnose::screen`], a thousandth).
const MIN_PROJECTED_FRACTION: f64 = 1e-3;
/// Largest harmonic turn per row for a cogging column, in cycles (as the localisation's angle
/// ripple: below Nyquist with a margin).
const RIPPLE_NYQUIST: f64 = 0.4;
/// Rows of the localisation's time windows (16: 0.16 s of a 1 kHz record decimated by 10,
/// short enough to pin a disturbance of a fraction of a second).
const WINDOW_ROWS: usize = 16;
/// Windows of largest excess reported per record.
const TOP_WINDOWS: usize = 5;
/// Fraction of the decimated band the decimation's low-pass passes ([`crate::decimate`]: an
/// order-8 Butterworth at 0.8 of the new Nyquist frequency).
const DECIMATION_PASSBAND: f64 = 0.8;

/// Whether the axis turns (angles in rad) or slides (positions in m): sets the units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AxisGeometry {
    /// Angles in rad, torque in N·m.
    Rotary,
    /// Positions in m, force in N.
    Linear,
}

impl AxisGeometry {
    /// Units of J, f, Ts and the offset.
    pub fn units(self) -> [&'static str; 4] {
        match self {
            AxisGeometry::Rotary => MECHANICAL_UNITS_ROTARY,
            AxisGeometry::Linear => MECHANICAL_UNITS_LINEAR,
        }
    }

    /// Unit of the speed q̇.
    fn speed_unit(self) -> &'static str {
        match self {
            AxisGeometry::Rotary => "rad/s",
            AxisGeometry::Linear => "m/s",
        }
    }

    /// Unit of the drag coefficient `c` of `c q̇ |q̇|`.
    fn drag_unit(self) -> &'static str {
        match self {
            AxisGeometry::Rotary => "N·m·s²/rad²",
            AxisGeometry::Linear => "N·s²/m²",
        }
    }
}

/// Settings of [`diagnose_inverse`].
#[derive(Debug, Clone, PartialEq)]
pub struct InverseDiagnoseSettings {
    /// The inverse model's filters and decimation.
    pub inverse: InverseModelSettings,
    /// Rotary or linear (units; cogging is a candidate of a rotary axis only).
    pub geometry: AxisGeometry,
    /// Torque (force) per unit of the current column (> 0): the residual is localised in the
    /// current column's unit.
    pub torque_constant: f64,
    /// The candidate effects (default: all seven of SPEC section 5).
    pub candidates: Vec<EffectKind>,
    /// Effects named at most, one on top of the other (default 2).
    pub max_effects: usize,
    /// Block length of the split into training and held-out rows \[decimated rows\] (default
    /// 25).
    pub block_rows: usize,
    /// Every this many blocks one is held out (default 4: a quarter).
    pub holdout_every: usize,
    /// The ranking's settings.
    pub verdict: VerdictSettings,
    /// The localisation's settings (default: windows of 16 rows, the top 5 reported).
    pub localise: LocaliseSettings,
}

impl Default for InverseDiagnoseSettings {
    fn default() -> Self {
        InverseDiagnoseSettings {
            inverse: InverseModelSettings::default(),
            geometry: AxisGeometry::Rotary,
            torque_constant: 1.0,
            candidates: EffectKind::ALL.to_vec(),
            max_effects: 2,
            block_rows: 25,
            holdout_every: 4,
            verdict: VerdictSettings::default(),
            localise: LocaliseSettings {
                window_samples: WINDOW_ROWS,
                top_windows: TOP_WINDOWS,
                ..LocaliseSettings::default()
            },
        }
    }
}

/// A diagnosis of a current-driven axis (module docs).
#[derive(Debug, Clone)]
pub struct InverseDiagnosis {
    /// The inverse-model identification on the training records (all their rows).
    pub nominal: MechanicalFit,
    /// How the held-out data were made, in words.
    pub heldout: String,
    /// Where the base model (fitted on the training rows) misses, on every record; times are
    /// those of the rows (gaps where the axis rests).
    pub localisation: Localisation,
    /// The stages of the search, as [`crate::diagnose::Diagnosis::stages`]; a candidate's
    /// `motor_shift` lists J, f, Ts and the offset.
    pub stages: Vec<Stage>,
    /// Per record (training, then validation), the row times \[s\], the measured torque, and
    /// the torque of the model before and after each stage's chosen effect (torque unit):
    /// `models[0]` is the base model, `models[s]` the model after stage `s`.
    pub traces: Vec<TorqueTrace>,
}

impl InverseDiagnosis {
    /// The effects named, in the order found (empty: `none`).
    pub fn named(&self) -> Vec<&str> {
        named_effects(&self.stages)
    }
}

/// The effects `stages` name, in the order found (empty: `none`).
pub fn named_effects(stages: &[Stage]) -> Vec<&str> {
    stages
        .iter()
        .filter_map(|s| s.verdict.verdict.as_deref())
        .collect()
}

/// The measured torque of one record and the models of the diagnosis, on its rows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TorqueTrace {
    /// Time of each row from the record's first sample \[s\].
    pub t_s: Vec<f64>,
    /// Measured torque (force), filtered and decimated (torque unit).
    pub measured: Vec<f64>,
    /// The model before any effect, then after each named effect (torque unit).
    pub models: Vec<Vec<f64>>,
}

/// One candidate's columns and how to read its coefficients.
struct CandidateColumns {
    columns: Vec<Vec<f64>>,
    /// Parameters the effect adds (its coefficients and its shape, chosen from a grid).
    extra_params: usize,
    /// The shape parameter chosen from the grid, if any: symbol, key, unit, value.
    shape: Option<(&'static str, &'static str, &'static str, f64)>,
}

/// Why a candidate cannot be tested on a current-driven axis, if it cannot.
fn untestable_reason(kind: EffectKind, geometry: AxisGeometry) -> Option<&'static str> {
    match kind {
        EffectKind::ThermalDrift | EffectKind::BrushDrop | EffectKind::InductanceSaturation => Some(
            "an electrical effect: the drive imposes the current, so the records cannot show it",
        ),
        EffectKind::CoggingTorque if geometry == AxisGeometry::Linear => {
            Some("a linear axis has no shaft angle in the records to lock a ripple to")
        }
        _ => None,
    }
}

/// The candidate's columns for each value of its shape grid.
fn candidate_grid(
    kind: EffectKind,
    s: &Stack,
    settings: &InverseDiagnoseSettings,
) -> Vec<CandidateColumns> {
    let peak = s.speed.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let unit = settings.geometry.speed_unit();
    match kind {
        EffectKind::StribeckFriction => STRIBECK_SPEED_FRACTIONS
            .iter()
            .map(|fr| {
                let ws = fr * peak;
                CandidateColumns {
                    columns: vec![s
                        .speed
                        .iter()
                        .zip(&s.sign)
                        .map(|(v, sg)| sg * (-(v / ws).powi(2)).exp())
                        .collect()],
                    extra_params: 2,
                    shape: Some(("Ωs", "ws", unit, ws)),
                }
            })
            .collect(),
        EffectKind::QuadraticDrag => vec![CandidateColumns {
            columns: vec![s.speed.iter().map(|v| v * v.abs()).collect()],
            extra_params: 1,
            shape: None,
        }],
        EffectKind::CurrentSensorLag => vec![CandidateColumns {
            columns: vec![s.torque_rate.clone()],
            extra_params: 1,
            shape: None,
        }],
        EffectKind::CoggingTorque => (1..=settings.localise.max_harmonic)
            .map(|n| {
                let nf = f64::from(n);
                let (mut sin, mut cos) = (Vec::with_capacity(s.len()), Vec::with_capacity(s.len()));
                for i in 0..s.len() {
                    let turn = nf * s.speed[i].abs() * s.dt_row / std::f64::consts::TAU;
                    let (a, b) = if turn <= RIPPLE_NYQUIST {
                        (nf * s.position[i]).sin_cos()
                    } else {
                        (0.0, 0.0)
                    };
                    sin.push(a);
                    cos.push(b);
                }
                CandidateColumns {
                    columns: vec![sin, cos],
                    extra_params: 3,
                    shape: Some(("N", "n", "-", nf)),
                }
            })
            .collect(),
        _ => Vec::new(),
    }
}

/// The report of a candidate that is not refitted.
fn unfitted(
    kind: EffectKind,
    assessment: Assessment,
    why: Option<String>,
    before: (f64, f64),
) -> CandidateReport {
    CandidateReport {
        name: kind.name(),
        assessment,
        testable: assessment != Assessment::NotTestable,
        significant: false,
        screening: None,
        p_value: 1.0,
        heldout_p_value: 1.0,
        params: Vec::new(),
        train_nrmse_before: before.0,
        train_nrmse_after: f64::NAN,
        heldout_nrmse_before: before.1,
        heldout_nrmse_after: f64::NAN,
        motor_shift: Vec::new(),
        motor: None,
        effects: Effects::none(),
        failure: why,
        inputs: Vec::new(),
        fitted: Vec::new(),
    }
}

/// A candidate's refit: its report, its held-out block errors, its training statistic, and its
/// columns (for the next stage).
struct Refit {
    report: CandidateReport,
    sse: Vec<f64>,
    statistic: Option<f64>,
    extra_params: usize,
    chosen: Option<Vec<Vec<f64>>>,
}

/// Localisation of the base model's residual on every record's rows.
fn localise_rows(
    s: &Stack,
    residual: &[f64],
    names: &[&str],
    floors: &[f64],
    settings: &InverseDiagnoseSettings,
) -> Result<Localisation, FitError> {
    let k = settings.torque_constant;
    let per_record: Vec<(usize, usize)> = (0..s.starts.len())
        .map(|r| (s.starts[r], s.starts.get(r + 1).copied().unwrap_or(s.len())))
        .collect();
    let currents: Vec<Vec<f64>> = per_record
        .iter()
        .map(|&(a, b)| s.torque[a..b].iter().map(|t| t / k).collect())
        .collect();
    let models: Vec<Vec<f64>> = per_record
        .iter()
        .map(|&(a, b)| (a..b).map(|i| (s.torque[i] - residual[i]) / k).collect())
        .collect();
    let shown = super::record_names(names, per_record.len());
    let records: Vec<ResidualRecord<'_>> = per_record
        .iter()
        .enumerate()
        .map(|(r, &(a, b))| ResidualRecord {
            name: &shown[r],
            dt: s.dt_row,
            // The current is the input of a current-driven axis.
            voltage: &currents[r],
            current: Some(&currents[r]),
            speed: Some(&s.speed[a..b]),
            angle: (settings.geometry == AxisGeometry::Rotary).then(|| &s.position[a..b]),
            channels: vec![ResidualChannel {
                kind: Channel::Current,
                measured: &currents[r],
                model: &models[r],
            }],
        })
        .collect();
    let floors: Vec<Vec<f64>> = floors.iter().map(|f| vec![f / k]).collect();
    localise_with_floors(&records, &floors, &settings.localise)
}

/// The noise floor of each record's torque rows (torque unit): the torque's own noise (its
/// second-difference deviation at the full rate, band-limited by the decimation's low-pass to
/// `0.8/decimation` of the band) and the position's quantisation carried into the model's
/// torque through J and f (the probe of [`crate::identify_inverse_model_pooled`]'s
/// correction), added in quadrature.
fn torque_floors(
    records: &[AxisRecord<'_>],
    rows: &[Rows],
    nominal: &MechanicalFit,
    settings: &InverseModelSettings,
) -> Vec<f64> {
    let band = (DECIMATION_PASSBAND / settings.decimation.max(1) as f64).min(1.0);
    let (j, f) = (nominal.axis.mass_kg, nominal.axis.viscous_ns_per_m);
    records
        .iter()
        .zip(rows)
        .map(|(rec, r)| {
            let torque = noise_std(rec.torque).powi(2) * band;
            let n = r.torque.len().max(1) as f64;
            let carried = r.quantisation[0]
                .iter()
                .zip(&r.quantisation[1])
                .map(|(qdd, qd)| (j * qdd + f * qd).powi(2))
                .sum::<f64>()
                / n;
            (torque + carried).sqrt()
        })
        .collect()
}

/// Rewrites the localisation's times (computed as `row × period`) as the rows' own times,
/// which skip the stretches at rest.
fn retime(localisation: &mut Localisation, times: &[Vec<f64>], dt_row: f64) {
    let at = |t: &[f64], i: usize| -> f64 {
        match t.get(i) {
            Some(v) => *v,
            None => t.last().map_or(0.0, |v| v + dt_row),
        }
    };
    for (rec, t) in localisation.records.iter_mut().zip(times) {
        for p in &mut rec.phases {
            p.t_start_s = at(t, p.start);
            p.t_end_s = at(t, p.end.saturating_sub(1)) + dt_row;
        }
        for ch in &mut rec.channels {
            for p in &mut ch.phases {
                p.phase.t_start_s = at(t, p.phase.start);
                p.phase.t_end_s = at(t, p.phase.end.saturating_sub(1)) + dt_row;
            }
            for w in &mut ch.windows {
                w.t_start_s = at(t, w.start);
                w.t_end_s = at(t, w.end.saturating_sub(1)) + dt_row;
            }
        }
    }
}

/// Diagnoses a current-driven axis (module docs): `records` are fitted (and split into
/// training and held-out blocks when `validation` is empty), `validation` records are held out
/// whole; `names` name them in that order for the report.
///
/// Errors: unusable records or settings ([`DiagnoseError::Fit`]); an inverse model the records
/// cannot support ([`DiagnoseError::NominalFailed`]: no effect is named on top of it).
pub fn diagnose_inverse(
    records: &[AxisRecord<'_>],
    validation: &[AxisRecord<'_>],
    names: &[&str],
    settings: &InverseDiagnoseSettings,
) -> Result<InverseDiagnosis, DiagnoseError> {
    if !(settings.torque_constant.is_finite() && settings.torque_constant > 0.0) {
        return Err(FitError::InvalidSetting {
            name: "torque constant",
            value: settings.torque_constant,
            expected: "a positive torque (force) per unit of the current column",
        }
        .into());
    }
    let nominal =
        identify_inverse_model_pooled(records, settings.inverse).map_err(|e| match e {
            FitError::MethodDomain { .. } => DiagnoseError::NominalFailed(e.to_string()),
            e => DiagnoseError::Fit(e),
        })?;
    let all: Vec<AxisRecord<'_>> = records.iter().chain(validation).copied().collect();
    let rows = regressor_rows(&all, &settings.inverse)?;
    let dt_row = records.first().map_or(1.0, |r| r.dt) * settings.inverse.decimation.max(1) as f64;
    let block = settings.block_rows.max(1);
    let every = settings.holdout_every.max(2);
    let fit_offset = nominal.offset_status == OffsetStatus::Fitted;
    let s = stack(&rows, records.len(), fit_offset, dt_row, block, every);
    let heldout = if validation.is_empty() {
        format!(
            "every {every}th block of {block} rows ({:.3} s) of each record held out of every fit, judged on its prediction",
            block as f64 * dt_row
        )
    } else {
        format!("{} validation record(s) held out whole", validation.len())
    };
    let mut base_cols: Vec<Vec<f64>> = s.base.clone();
    let base_fit = least_squares(&s, &slices(&base_cols)).ok_or_else(|| {
        DiagnoseError::NominalFailed(
            "the training rows do not determine J, f and Ts (too few, or collinear)".into(),
        )
    })?;
    let floors = torque_floors(&all, &rows, &nominal, &settings.inverse);
    let mut localisation = localise_rows(&s, &base_fit.residual, names, &floors, settings)?;
    let times: Vec<Vec<f64>> = rows.iter().map(|r| r.t_s.clone()).collect();
    retime(&mut localisation, &times, dt_row);
    let mut models: Vec<Vec<f64>> = vec![model_of(&s, &base_fit.residual)];
    let mut base = base_fit;
    let mut found: Vec<EffectKind> = Vec::new();
    let mut stages = Vec::new();
    for _ in 0..settings.max_effects.max(1) {
        let kinds: Vec<EffectKind> = settings
            .candidates
            .iter()
            .copied()
            .filter(|k| !found.contains(k))
            .collect();
        if kinds.is_empty() {
            break;
        }
        let (stage, next) = run_stage(&s, &base_cols, &base, &kinds, &found, settings);
        let chosen = stage.verdict.verdict.clone();
        stages.push(stage);
        let Some((cols, name)) = next.zip(chosen) else {
            break;
        };
        let Some(kind) = kinds.iter().copied().find(|k| k.name() == name) else {
            break;
        };
        base_cols.extend(cols);
        let Some(refit) = least_squares(&s, &slices(&base_cols)) else {
            break;
        };
        models.push(model_of(&s, &refit.residual));
        base = refit;
        found.push(kind);
    }
    let traces = (0..s.starts.len())
        .map(|r| {
            let (a, b) = (s.starts[r], s.starts.get(r + 1).copied().unwrap_or(s.len()));
            TorqueTrace {
                t_s: times[r].clone(),
                measured: s.torque[a..b].to_vec(),
                models: models.iter().map(|m| m[a..b].to_vec()).collect(),
            }
        })
        .collect();
    Ok(InverseDiagnosis {
        nominal,
        heldout,
        localisation,
        stages,
        traces,
    })
}

/// One stage: every candidate refitted on top of `base_cols`, ranked, and the chosen one's
/// columns returned.
fn run_stage(
    s: &Stack,
    base_cols: &[Vec<f64>],
    base: &LsFit,
    kinds: &[EffectKind],
    found: &[EffectKind],
    settings: &InverseDiagnoseSettings,
) -> (Stage, Option<Vec<Vec<f64>>>) {
    let block = settings.block_rows.max(1);
    let dof = base.rows.saturating_sub(base.theta.len()).max(1) as f64;
    let variance = (base.sse / dof).max(f64::MIN_POSITIVE);
    let factor = residual_factor(s, &base.residual);
    let held = |i: usize| s.held[i];
    let before = (
        nrmse_summary(s, &base.residual, |i| !held(i)),
        nrmse_summary(s, &base.residual, held),
    );
    let sse_before = block_sse(s, &base.residual, variance, block);
    let units = settings.geometry.units();
    let refits: Vec<Refit> = kinds
        .iter()
        .map(|&kind| {
            let none = |assessment: Assessment, why: Option<String>| Refit {
                report: unfitted(kind, assessment, why, before),
                sse: Vec::new(),
                statistic: None,
                extra_params: 1,
                chosen: None,
            };
            if let Some(why) = untestable_reason(kind, settings.geometry) {
                return none(Assessment::NotTestable, Some(why.into()));
            }
            let base_refs: Vec<&[f64]> = base_cols.iter().map(Vec::as_slice).collect();
            // The best of the shape grid on the training rows, among the testable ones.
            let best = candidate_grid(kind, s, settings)
                .into_iter()
                .filter(|c| {
                    c.columns
                        .iter()
                        .all(|col| projected_fraction(s, &base_refs, col) > MIN_PROJECTED_FRACTION)
                })
                .filter_map(|c| {
                    let mut cols = base_refs.clone();
                    cols.extend(c.columns.iter().map(Vec::as_slice));
                    least_squares(s, &cols).map(|f| (c, f))
                })
                .min_by(|a, b| a.1.sse.total_cmp(&b.1.sse));
            let Some((cand, fit)) = best else {
                return none(
                    Assessment::NotTestable,
                    Some("its columns are lost in the base model's on these records".into()),
                );
            };
            let p0 = base_cols.len();
            let statistic = (base.sse - fit.sse) / variance / factor;
            let fit_dof = fit.rows.saturating_sub(fit.theta.len()).max(1) as f64;
            let fit_var = fit.sse / fit_dof * residual_factor(s, &fit.residual);
            let t = student_t_quantile(0.975, fit_dof);
            let half = |j: usize| t * (fit_var * fit.inverse[(j, j)]).max(0.0).sqrt();
            let coef = |j: usize| fit.theta[p0 + j];
            let ci = |value: f64, h: f64| (h.is_finite()).then_some([value - h, value + h]);
            let mut params = Vec::new();
            match kind {
                EffectKind::StribeckFriction => {
                    // Tst = Ts + the coefficient; its variance from the covariance of both.
                    let ts = fit.theta[2];
                    let var = fit_var
                        * (fit.inverse[(2, 2)]
                            + fit.inverse[(p0, p0)]
                            + 2.0 * fit.inverse[(2, p0)]);
                    let value = ts + coef(0);
                    params.push(EffectParam {
                        symbol: "Tst",
                        key: "tst",
                        unit: units[2],
                        value,
                        ci95: ci(value, t * var.max(0.0).sqrt()),
                    });
                }
                EffectKind::QuadraticDrag => params.push(EffectParam {
                    symbol: "c",
                    key: "c",
                    unit: settings.geometry.drag_unit(),
                    value: coef(0),
                    ci95: ci(coef(0), half(p0)),
                }),
                EffectKind::CurrentSensorLag => params.push(EffectParam {
                    symbol: "τf",
                    key: "tau",
                    unit: "s",
                    value: coef(0),
                    ci95: ci(coef(0), half(p0)),
                }),
                EffectKind::CoggingTorque => {
                    let (b, c) = (coef(0), coef(1));
                    let amp = b.hypot(c);
                    // Delta method: ∂A/∂b = b/A, ∂A/∂c = c/A.
                    let var = if amp > 0.0 {
                        fit_var
                            * (b * b * fit.inverse[(p0, p0)]
                                + c * c * fit.inverse[(p0 + 1, p0 + 1)]
                                + 2.0 * b * c * fit.inverse[(p0, p0 + 1)])
                            / (amp * amp)
                    } else {
                        f64::NAN
                    };
                    params.push(EffectParam {
                        symbol: "A",
                        key: "amp",
                        unit: units[2],
                        value: amp,
                        ci95: ci(amp, t * var.max(0.0).sqrt()),
                    });
                    params.push(EffectParam {
                        symbol: "φ",
                        key: "phase",
                        unit: "rad",
                        value: c.atan2(b),
                        ci95: None,
                    });
                }
                _ => {}
            }
            if let Some((symbol, key, unit, value)) = cand.shape {
                params.push(EffectParam {
                    symbol,
                    key,
                    unit,
                    value,
                    ci95: None,
                });
            }
            // An effect fitted against its physics (a sensor that leads, a drag that pushes,
            // static friction below the sliding one) is not that effect.
            let against = match kind {
                EffectKind::StribeckFriction => (coef(0) <= 0.0).then_some("Tst below Ts"),
                EffectKind::QuadraticDrag => (coef(0) <= 0.0).then_some("c not positive"),
                EffectKind::CurrentSensorLag => (coef(0) <= 0.0).then_some("τf not positive"),
                _ => None,
            };
            let motor_shift = MECHANICAL_NAMES
                .iter()
                .enumerate()
                .filter(|(j, _)| *j < p0.min(4))
                .map(|(j, name)| {
                    let (b, a) = (base.theta[j], fit.theta[j]);
                    ParamShift {
                        name,
                        before: b,
                        after: a,
                        relative: a / b - 1.0,
                    }
                })
                .collect();
            let sse = match against {
                Some(_) => Vec::new(),
                None => block_sse(s, &fit.residual, variance, block),
            };
            let why = against.map(|w| format!("fitted with {w}: not this effect"));
            let report = CandidateReport {
                params,
                train_nrmse_after: nrmse_summary(s, &fit.residual, |i| !held(i)),
                heldout_nrmse_after: nrmse_summary(s, &fit.residual, held),
                motor_shift,
                ..unfitted(kind, Assessment::NoEvidence, why, before)
            };
            let chosen_cols = cand.columns;
            Refit {
                report,
                sse,
                statistic: Some(statistic),
                extra_params: cand.extra_params,
                chosen: Some(chosen_cols),
            }
        })
        .collect();
    let scores: Vec<CandidateScore<'_>> = refits
        .iter()
        .map(|r| CandidateScore {
            name: r.report.name,
            extra_params: r.extra_params,
            testable: r.report.testable,
            train_statistic: r.statistic,
            searched: 1,
            heldout_sse_before: &sse_before,
            heldout_sse_after: &r.sse,
        })
        .collect();
    let mut verdict = rank_candidates(&scores, &settings.verdict);
    // Named only if the held-out rows back it too (module docs).
    for r in &mut verdict.ranked {
        r.significant &= r.heldout_p_value < verdict.level;
    }
    let significant: Vec<String> = verdict
        .ranked
        .iter()
        .filter(|r| r.significant)
        .map(|r| r.name.clone())
        .collect();
    verdict.verdict = significant.first().cloned();
    verdict.ambiguous_with.retain(|n| significant.contains(n));
    let mut candidates = Vec::with_capacity(refits.len());
    let mut next = None;
    for r in refits {
        let mut c = r.report;
        c.take_rank(&verdict);
        if verdict.verdict.as_deref() == Some(c.name) {
            next = r.chosen;
        }
        candidates.push(c);
    }
    (
        Stage {
            base: found.iter().map(|k| k.name()).collect(),
            candidates,
            verdict,
            fitted_before: Vec::new(),
        },
        next,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::NoiseRng;

    /// A linear axis (M 2 kg, Fv 10 N·s/m, Fc 3 N, offset 0.5 N) on two sines, 20 s at 1 kHz,
    /// its position in steps of 1 µm, its force with 0.5 N of white noise and a drag
    /// `c q̇|q̇|` on top.
    fn axis(c: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let dt = 1e-3;
        let mut rng = NoiseRng::new(seed);
        let w = [std::f64::consts::TAU * 0.5, std::f64::consts::TAU * 1.3];
        let amp = [0.1, 0.05];
        let (mut force, mut position) = (Vec::new(), Vec::new());
        for i in 0..20_000 {
            let t = i as f64 * dt;
            let q: f64 = (0..2).map(|j| amp[j] * (w[j] * t).sin()).sum();
            let qd: f64 = (0..2).map(|j| amp[j] * w[j] * (w[j] * t).cos()).sum();
            let qdd: f64 = (0..2)
                .map(|j| -amp[j] * w[j] * w[j] * (w[j] * t).sin())
                .sum();
            force.push(
                2.0 * qdd
                    + 10.0 * qd
                    + 3.0 * qd.signum()
                    + 0.5
                    + c * qd * qd.abs()
                    + 0.5 * rng.normal(),
            );
            position.push((q / 1e-6).round() * 1e-6);
        }
        (force, position)
    }

    fn run(c: f64) -> InverseDiagnosis {
        let (force, position) = axis(c, 5);
        let rec = AxisRecord {
            dt: 1e-3,
            torque: &force,
            position: &position,
        };
        let settings = InverseDiagnoseSettings {
            geometry: AxisGeometry::Linear,
            candidates: vec![EffectKind::QuadraticDrag, EffectKind::StribeckFriction],
            max_effects: 1,
            ..InverseDiagnoseSettings::default()
        };
        diagnose_inverse(&[rec], &[], &["axis"], &settings).expect("a diagnosis")
    }

    #[test]
    fn a_withheld_drag_is_named_with_its_size_and_none_without_it() {
        let d = run(20.0);
        assert_eq!(d.named(), ["quadratic_drag"]);
        let drag = d.stages[0]
            .candidates
            .iter()
            .find(|c| c.name == "quadratic_drag")
            .unwrap();
        let [lo, hi] = drag.params[0].ci95.unwrap();
        assert!(lo <= 20.0 && 20.0 <= hi, "c = {:?}", drag.params[0]);
        assert!(drag.heldout_nrmse_after < drag.heldout_nrmse_before);
        assert_eq!(d.traces[0].models.len(), 2);
        let d = run(0.0);
        assert!(d.named().is_empty(), "{:?}", d.stages[0].verdict);
    }
}
