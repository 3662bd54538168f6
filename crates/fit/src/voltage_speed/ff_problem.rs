//! The least-squares problem of the voltage-to-speed fit: each record's speed simulated from
//! its voltage levels, the parameters as logarithms, the initial speeds where records do not
//! start at rest.

use motor_model::{central_difference, Input};
use nalgebra::DMatrix;

use crate::estimation::lm::{half_squared_norm, LeastSquares, NormalEquations};
use crate::estimation::records::{Channel, ChannelQuality};
use crate::estimation::weighted::quality_from_sums;
use crate::voltage_speed::model::{FeedforwardParams, VoltageSpeedModel};
use crate::voltage_speed::simulation::simulate_voltage_speed;

/// Step of the forward-difference Jacobian (in ln k and, scaled, in the initial speeds).
pub(crate) const FD_STEP: f64 = 1e-6;

/// How far \[ln\] below its start the reduced fit may take kS before the τe stage restarts
/// it from the start (a factor of 1000).
pub(crate) const KS_COLLAPSE_LN: f64 = 6.907755278982137;

/// Whether a fit took kS, `ln_ks` its logarithm, [`KS_COLLAPSE_LN`] below the start's `ks0`
/// \[V\]: driven to 0, where its gradient in the logarithm vanishes and it has no interval.
pub(crate) fn ks_collapsed(ln_ks: f64, ks0: f64) -> bool {
    ln_ks < ks0.ln() - KS_COLLAPSE_LN
}

/// One record prepared for the fit.
pub(crate) struct FfRecord {
    pub(crate) input: Input,
    pub(crate) dt: f64,
    pub(crate) n: usize,
    pub(crate) kind: Channel,
    pub(crate) keep: Vec<usize>,
    pub(crate) data: Vec<f64>,
    pub(crate) sigma: f64,
    /// The smallest `sigma` may become ([`noise_floor`] of `data`).
    pub(crate) floor: f64,
    /// Which of the fitted initial speeds is this record's (0 for the first such record), if
    /// it does not start at rest.
    pub(crate) free_start: Option<usize>,
    /// The levels of a piecewise-constant voltage with what is unknown of them, if given.
    pub(crate) levels: Vec<Level>,
    /// Where the shift common to every level change's instant sits among the nuisances (in
    /// units of a change's standard deviation), if any change has an uncertain instant: an
    /// excitation clocked with the logger changes at the same point of every sample period
    /// (a PRBS whose bits fall on samples), so the instants' errors are not independent.
    pub(crate) common_start_slot: Option<usize>,
}

/// One level of a record's voltage as measured: its value and start with their standard
/// deviations, and where their corrections sit among the fit's nuisance parameters (each
/// nuisance is the correction in units of its standard deviation, with a unit normal prior).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Level {
    pub(crate) volts: f64,
    pub(crate) start_s: f64,
    pub(crate) volts_sd: f64,
    pub(crate) start_sd: f64,
    pub(crate) volts_slot: Option<usize>,
    pub(crate) start_slot: Option<usize>,
}

pub(crate) struct FfProblem {
    pub(crate) records: Vec<FfRecord>,
    /// Whether τe is fitted (the fourth parameter, as ln τe).
    pub(crate) electrical: bool,
    /// The back-EMF constant k \[V·s/rad\] if given; else taken as kV.
    pub(crate) back_emf: Option<f64>,
    /// With τe and no k given: k taken as kV (the viscous share of kV fixed at 0, not a
    /// nuisance), the fit of [`TauE::Traded`]'s two coefficients.
    pub(crate) share_at_zero: bool,
    pub(crate) free_starts: usize,
    /// Nuisance parameters of the levels (values and instants), after the initial speeds;
    /// with τe and no k given, one more follows: the viscous share of kV (module docs).
    pub(crate) level_nuisances: usize,
    /// Data residuals.
    pub(crate) n_data: usize,
    /// Scale of the initial speeds in the parameter vector \[rad/s\] (so that every parameter
    /// moves by similar amounts).
    pub(crate) speed_scale: f64,
}

impl FfProblem {
    /// Nuisance parameters: the levels', and the viscous share of kV when τe is fitted without
    /// a given k (its prior uniform over `[0, kV]`: the share is Φ(z) of a nuisance z with a unit
    /// normal prior, so that a share near 0 or 1 is as likely as one about ½).
    pub(crate) fn nuisances(&self) -> usize {
        self.level_nuisances
            + usize::from(self.electrical && self.back_emf.is_none() && !self.share_at_zero)
    }

    /// Residuals: the data and one prior per nuisance.
    pub(crate) fn n_residuals(&self) -> usize {
        self.n_data + self.nuisances()
    }

    /// Parameters of the model itself (before the initial speeds).
    pub(crate) fn n_model(&self) -> usize {
        if self.electrical {
            4
        } else {
            3
        }
    }

    pub(crate) fn params_of(&self, theta: &[f64]) -> Option<VoltageSpeedModel> {
        let m = self.n_model();
        if theta.len() != m + self.free_starts + self.nuisances()
            || !theta.iter().all(|t| t.is_finite())
            || !theta[..m].iter().all(|t| t.abs() < 700.0)
        {
            return None;
        }
        let constants = FeedforwardParams {
            ks_v: theta[0].exp(),
            kv_v_s_per_rad: theta[1].exp(),
            ka_v_s2_per_rad: theta[2].exp(),
        };
        let kv = constants.kv_v_s_per_rad;
        let back_emf_v_s_per_rad = match (self.electrical, self.back_emf) {
            (_, Some(k)) => k.min(kv),
            (false, None) => kv,
            (true, None) if self.share_at_zero => kv,
            (true, None) => {
                let share = crate::excitation::input_uncertainty::phi(theta[theta.len() - 1]);
                kv * (1.0 - share)
            }
        };
        Some(VoltageSpeedModel {
            constants,
            tau_e_s: if self.electrical { theta[3].exp() } else { 0.0 },
            back_emf_v_s_per_rad,
        })
    }

    pub(crate) fn initial_speed(&self, r: &FfRecord, theta: &[f64]) -> f64 {
        r.free_start
            .map_or(0.0, |j| theta[self.n_model() + j] * self.speed_scale)
    }

    /// The voltage of record `r` with its levels corrected by the nuisances in `theta`;
    /// `None` where the corrected instants are out of order.
    pub(crate) fn input_of(&self, r: &FfRecord, theta: &[f64]) -> Option<Input> {
        if r.levels.is_empty() {
            return Some(r.input.clone());
        }
        let base = self.n_model() + self.free_starts;
        let shift = |slot: Option<usize>, sd: f64| slot.map_or(0.0, |j| theta[base + j] * sd);
        let steps: Vec<(f64, f64)> = r
            .levels
            .iter()
            .map(|l| {
                let common = if l.start_slot.is_some() {
                    shift(r.common_start_slot, l.start_sd)
                } else {
                    0.0
                };
                (
                    l.start_s + shift(l.start_slot, l.start_sd) + common,
                    l.volts + shift(l.volts_slot, l.volts_sd),
                )
            })
            .collect();
        Input::piecewise(&steps).ok()
    }

    /// The model of every record's fitted channel at `theta`.
    pub(crate) fn model(&self, theta: &[f64]) -> Option<Vec<Vec<f64>>> {
        let p = self.params_of(theta)?;
        let out: Vec<Vec<f64>> = self
            .records
            .iter()
            .map(|r| {
                let w0 = self.initial_speed(r, theta);
                let input = self.input_of(r, theta)?;
                let (speed, angle) = simulate_voltage_speed(&p, &input, r.dt, r.n, w0);
                let full = match r.kind {
                    Channel::EncoderSpeed => {
                        let t: Vec<f64> = (0..r.n).map(|i| i as f64 * r.dt).collect();
                        central_difference(&t, &angle)
                    }
                    _ => speed,
                };
                Some(r.keep.iter().map(|&i| full[i]).collect())
            })
            .collect::<Option<_>>()?;
        out.iter().flatten().all(|v| v.is_finite()).then_some(out)
    }

    pub(crate) fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let model = self.model(theta)?;
        let mut r = Vec::with_capacity(self.n_residuals());
        for (rec, m) in self.records.iter().zip(&model) {
            r.extend(rec.data.iter().zip(m).map(|(y, m)| (m - y) / rec.sigma));
        }
        // The nuisances' unit normal priors.
        r.extend_from_slice(&theta[theta.len() - self.nuisances()..]);
        Some(r)
    }

    /// Lengths of the independent series of the residual vector: each record's channel, then
    /// each prior on its own.
    pub(crate) fn series(&self) -> Vec<usize> {
        let mut s: Vec<usize> = self.records.iter().map(|r| r.data.len()).collect();
        s.extend(std::iter::repeat_n(1, self.nuisances()));
        s
    }

    pub(crate) fn jacobian(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let r0 = self.residuals(theta)?;
        let n_params = theta.len();
        let mut jac = DMatrix::zeros(r0.len(), n_params);
        for j in 0..n_params {
            let mut th = theta.to_vec();
            th[j] += FD_STEP;
            let r = self.residuals(&th)?;
            for (i, (a, b)) in r.iter().zip(&r0).enumerate() {
                jac[(i, j)] = (a - b) / FD_STEP;
            }
        }
        Some((r0, jac))
    }

    pub(crate) fn quality(&self, theta: &[f64]) -> Vec<ChannelQuality> {
        let model = self.model(theta);
        self.records
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let mean = r.data.iter().sum::<f64>() / r.data.len().max(1) as f64;
                let sst = r.data.iter().map(|y| (y - mean).powi(2)).sum::<f64>();
                let sse = model.as_ref().map_or(f64::NAN, |m| {
                    m[k].iter().zip(&r.data).map(|(a, b)| (a - b).powi(2)).sum()
                });
                quality_from_sums(k, r.kind, r.sigma, sse, sst, r.data.len())
            })
            .collect()
    }
}

impl LeastSquares for FfProblem {
    fn n_params(&self) -> usize {
        self.n_model() + self.free_starts + self.nuisances()
    }

    fn cost(&self, theta: &[f64]) -> Option<f64> {
        Some(half_squared_norm(&self.residuals(theta)?))
    }

    fn normal_equations(&self, theta: &[f64]) -> Option<NormalEquations> {
        let (r, jac) = self.jacobian(theta)?;
        Some(NormalEquations::from_jacobian(r, &jac))
    }
}
