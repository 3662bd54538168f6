//! Identification from the voltage and the speed alone (no current sensor): the
//! voltage-to-speed model of a DC motor whose electrical time constant is negligible.
//!
//! With `L dI/dt` neglected in Eq. (2a), `I = (E − kΩ)/R`, and Eq. (2b) times `R/k` reads
//!
//! `E = kS sign(Ω) + kV Ω + kA dΩ/dt`, with `kS = R Ts/k` \[V\], `kV = k + R f/k` \[V·s/rad\],
//! `kA = R J/k` \[V·s²/rad\]
//!
//! (WPILib SysId's feedforward constants); the rotor is stuck while `|E| ≤ kS`. Only these three
//! combinations reach the speed: J, f and Ts follow when R and k are known
//! ([`FeedforwardParams::mechanical`]). The reduced model holds while `τe = L/R` is small
//! against `τm = kA/kV`; when it is not, the speed's rise is rounded over about τe and kA
//! absorbs it (kA is then too large by about `kV τe`).
//!
//! The fit is by output error on the measured speed (the tachometer, or the central difference
//! of the encoder angle, as the simulated angle is differentiated alike): the model is solved
//! exactly between the instants where the voltage changes (a relaxation of time constant
//! `kA/kV` towards `(E − kS d)/kV`, zero crossings of the speed found in closed form), so the
//! cost is smooth in the parameters. A record that does not start at rest gets its initial
//! speed as a fitted parameter. The start is the inverse model
//! ([`crate::identify_inverse_model_pooled`] with the voltage as the "torque").

use motor_model::{central_difference, Input};

use crate::current_driven::mechanical::{
    identify_inverse_model_pooled, AxisRecord, InverseModelSettings,
};
use crate::error::FitError;
use crate::estimation::lm::{solve, LeastSquares, LmReport, LmSettings, Termination};
use crate::estimation::records::{
    noise_floor, noise_std, reweighted_sigma, Channel, ChannelQuality,
};
use crate::estimation::stats::{
    at_least, equal_runs, newey_west_run_covariance, sandwich_uncertainty, Uncertainty,
};
use crate::excitation::input_uncertainty::{bias_group_sizes, pooled_level_variance};
use crate::voltage_speed::ff_problem::{ks_collapsed, FfProblem, FfRecord, Level};
use crate::voltage_speed::model::{FeedforwardFit, FeedforwardSettings, SpeedRecord, TauE};

/// Decimation of the start's inverse model.
const START_DECIMATION: usize = 5;
/// Cut-offs of the start's position filter, as fractions of the sample rate, tried in turn.
const START_CUTOFFS: [f64; 3] = [0.02, 0.005, 0.00125];

fn bad(series: impl Into<String>, reason: String) -> FitError {
    FitError::BadData {
        series: series.into(),
        reason,
    }
}

/// Identifies kS, kV and kA (and τe where the records resolve it) from records of voltage and
/// speed (module docs), by output error from the inverse-model start: the reduced model first,
/// each record weighted by its noise and then by its residual RMS; then, if asked, with τe, kept
/// when its interval is narrower than its value. Intervals from the Newey–West sandwich.
pub fn identify_feedforward(
    records: &[SpeedRecord<'_>],
    settings: FeedforwardSettings,
) -> Result<FeedforwardFit, FitError> {
    if records.is_empty() {
        return Err(bad("records", "no record given".into()));
    }
    let mut prepared = Vec::with_capacity(records.len());
    let mut positions = Vec::with_capacity(records.len());
    let mut free = 0usize;
    let mut nuisances = 0usize;
    // Every record's levels in order, with how many read the same code.
    let groups = bias_group_sizes(
        &records
            .iter()
            .flat_map(|r| r.priors)
            .map(|q| {
                let uncertain = q.volts_variance_v2 > 0.0;
                let bias = if uncertain {
                    q.volts_bias_variance_v2
                } else {
                    0.0
                };
                (bias, q.volts_bias_code)
            })
            .collect::<Vec<_>>(),
    );
    let mut group = groups.into_iter();
    for (k, rec) in records.iter().enumerate() {
        let label = format!("record {}", k + 1);
        if !(rec.dt.is_finite() && rec.dt > 0.0) {
            return Err(bad(
                label,
                format!("sample period {} s: expected a positive period", rec.dt),
            ));
        }
        let t_of = |n: usize| -> Vec<f64> { (0..n).map(|i| i as f64 * rec.dt).collect() };
        let (kind, full, position) = match (rec.position, rec.speed) {
            (Some(angle), _) => (
                Channel::EncoderSpeed,
                central_difference(&t_of(angle.len()), angle),
                angle.to_vec(),
            ),
            (None, Some(speed)) => {
                // The angle as the running trapezoid of the speed, for the start only.
                let mut theta = Vec::with_capacity(speed.len());
                let mut acc = 0.0;
                for (i, w) in speed.iter().enumerate() {
                    if i > 0 {
                        acc += 0.5 * (w + speed[i - 1]) * rec.dt;
                    }
                    theta.push(acc);
                }
                (Channel::Speed, speed.to_vec(), theta)
            }
            (None, None) => {
                return Err(bad(
                    label,
                    "no speed or angle: the speed is what is fitted".into(),
                ))
            }
        };
        let n = full.len();
        if n < crate::MIN_SAMPLES {
            return Err(bad(
                label,
                format!("{n} samples: at least {} are needed", crate::MIN_SAMPLES),
            ));
        }
        if let Some((i, v)) = full.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(bad(
                label,
                format!("speed sample {i} is {v}: remove or repair it"),
            ));
        }
        if rec.exclude.is_some_and(|m| m.len() != n) {
            return Err(bad(
                label,
                "the exclusion mask does not align with the speed".into(),
            ));
        }
        let keep: Vec<usize> = (0..n)
            .filter(|&i| !rec.exclude.is_some_and(|m| m[i]))
            .collect();
        let data: Vec<f64> = keep.iter().map(|&i| full[i]).collect();
        let sigma = noise_std(&data);
        // At rest: the speed at the first sample within the noise of zero, or the mean of the
        // first five (and an encoder that has not moved). The first sample alone decides for a
        // motor that a voltage applied at that sample speeds up within five samples (a servo's
        // PRBS at 2 kHz: its head mean said "running", and the fitted start drove kS to 0).
        let head = &full[..n.min(5)];
        let head_mean = head.iter().sum::<f64>() / head.len() as f64;
        let at_rest = rec
            .at_rest
            .unwrap_or(full[0].abs() <= 3.0 * sigma || head_mean.abs() <= 3.0 * sigma);
        let free_start = if at_rest {
            None
        } else {
            free += 1;
            Some(free - 1)
        };
        let levels = match (rec.input, rec.priors.is_empty()) {
            (_, true) => Vec::new(),
            (Input::Piecewise { times_s, volts }, false) if volts.len() == rec.priors.len() => {
                times_s
                    .iter()
                    .zip(volts)
                    .zip(rec.priors)
                    .map(|((t, v), q)| {
                        let mut slot = |variance: f64| {
                            (variance > 0.0).then(|| {
                                nuisances += 1;
                                nuisances - 1
                            })
                        };
                        let volts_slot = slot(q.volts_variance_v2);
                        let start_slot = slot(q.start_variance_s2);
                        Level {
                            volts: *v,
                            start_s: *t,
                            volts_sd: pooled_level_variance(
                                q.volts_variance_v2,
                                q.volts_bias_variance_v2,
                                group.next().unwrap_or(1),
                            )
                            .max(0.0)
                            .sqrt(),
                            start_sd: q.start_variance_s2.max(0.0).sqrt(),
                            volts_slot,
                            start_slot,
                        }
                    })
                    .collect()
            }
            _ => {
                return Err(bad(
                    label,
                    "level priors given for a voltage that is not piecewise constant with as many levels".into(),
                ))
            }
        };
        if rec.priors.iter().any(|q| {
            !(q.volts_variance_v2.is_finite()
                && q.volts_variance_v2 >= 0.0
                && q.start_variance_s2.is_finite()
                && q.start_variance_s2 >= 0.0)
        }) {
            return Err(bad(label, "level variances must be finite and ≥ 0".into()));
        }
        // Each instant's error is one common to the record plus one of its own, each with the
        // variance of a change within its sample period: the prior holds for an excitation
        // clocked with the logger (every change at the same point of its period) and for one
        // that is not (each change anywhere in its period).
        let common_start_slot = levels.iter().any(|l| l.start_slot.is_some()).then(|| {
            nuisances += 1;
            nuisances - 1
        });
        prepared.push(FfRecord {
            input: rec.input.clone(),
            dt: rec.dt,
            n,
            kind,
            keep,
            floor: noise_floor(&data),
            data,
            sigma,
            free_start,
            levels,
            common_start_slot,
        });
        positions.push(position);
    }
    // Start: the inverse model E = kA Ω̇ + kV Ω + kS sign Ω on every record, the voltage as
    // the "torque" (no offset: the model has none), decimated by START_DECIMATION: a record
    // too short for it is refused here, in the fit's own terms.
    let min = crate::current_driven::mechanical::min_samples(START_DECIMATION);
    if let Some(r) = prepared.iter().find(|r| r.n < min) {
        return Err(bad(
            "record",
            format!(
                "{} samples: the voltage-and-speed fit needs at least {min} (record for longer, or at a higher rate)",
                r.n
            ),
        ));
    }
    let voltages: Vec<Vec<f64>> = prepared
        .iter()
        .map(|r| {
            (0..r.n)
                .map(|i| r.input.volts_at(i as f64 * r.dt))
                .collect()
        })
        .collect();
    let axis: Vec<AxisRecord<'_>> = prepared
        .iter()
        .zip(&voltages)
        .zip(&positions)
        .map(|((r, v), q)| AxisRecord {
            dt: r.dt,
            torque: v,
            position: q,
        })
        .collect();
    let dt_min = prepared.iter().map(|r| r.dt).fold(f64::INFINITY, f64::min);
    // At a fiftieth of the sample rate, else lower where the angle's resolution does not
    // support that cut-off (a slow motor read through an encoder: the quantisation,
    // differentiated twice, would bias the start's kA).
    let mut inverse = Err(FitError::Solver("no start tried".into()));
    for fraction in START_CUTOFFS {
        inverse = identify_inverse_model_pooled(
            &axis,
            InverseModelSettings {
                position_cutoff_hz: fraction / dt_min,
                position_filter_order: 4,
                decimation: START_DECIMATION,
                fit_offset: false,
            },
        );
        if inverse.is_ok() {
            break;
        }
    }
    let inverse = inverse.map_err(|e| FitError::MethodDomain {
        equation: "voltage-to-speed start (E = kS sign Ω + kV Ω + kA dΩ/dt)",
        reason: e.to_string(),
    })?;
    let motor_model::AxisParams {
        mass_kg: ka0,
        viscous_ns_per_m: kv0,
        coulomb_n: ks0,
        ..
    } = inverse.axis;
    let peak_e = voltages
        .iter()
        .flatten()
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    let peak_w = prepared
        .iter()
        .flat_map(|r| r.data.iter())
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    if !(peak_w > 0.0 && peak_e > 0.0) {
        return Err(bad(
            "records",
            "the motor never moves: nothing to identify — record it with a voltage that breaks the friction, Eq. (11)".into(),
        ));
    }
    let kv0 = if kv0 > 0.0 { kv0 } else { peak_e / peak_w };
    let ka0 = if ka0 > 0.0 { ka0 } else { kv0 * 10.0 * dt_min };
    let ks0 = if ks0 > 0.0 { ks0 } else { 1e-3 * peak_e };
    let n_data = prepared.iter().map(|r| r.data.len()).sum::<usize>();
    let mut problem = FfProblem {
        records: prepared,
        electrical: false,
        back_emf: settings.torque_constant,
        share_at_zero: false,
        free_starts: free,
        level_nuisances: nuisances,
        n_data,
        speed_scale: peak_w,
    };
    // Each record's noise as its samples show it, before any weighting by residuals.
    let noise: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
    let mut theta0 = vec![ks0.ln(), kv0.ln(), ka0.ln()];
    for r in &problem.records {
        if r.free_start.is_some() {
            theta0.push(r.data.first().copied().unwrap_or(0.0) / peak_w);
        }
    }
    theta0.extend(std::iter::repeat_n(0.0, nuisances));
    let mut iterations = 0;
    let reduced = fit_stages(&mut problem, &theta0, settings.lm, &mut iterations)?;
    // The kept fit, what it says of τe, and its uncertainty where already computed.
    let mut result = (reduced.clone(), TauE::Neglected, None);
    // The reduced fit is only a start for the model with τe: one that stalled (the reduced
    // model disagreeing with a record whose τe is not small) starts it as well.
    let usable = reduced.termination.converged() || reduced.termination == Termination::Stalled;
    if settings.electrical && usable {
        let p = problem
            .params_of(&reduced.params)
            .ok_or_else(|| FitError::Solver("parameters left the representable range".into()))?;
        // τe from several starts about the sample period and up to a tenth of τm (the cost
        // has a local minimum where τe trades against kS at every reversal); the lowest wins.
        // Where none explains the records down to their noise, τe is not small against τm (an
        // underdamped motor: τe = 0.1 s against τm = 0.04 s), and starts about the reduced τm
        // follow.
        problem.electrical = true;
        let sigmas: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
        let tau_m = p.constants.tau_m_s();
        let near_sample = [0.1, 0.3, 1.0, 3.0].map(|x| x * dt_min);
        let near_tau_m = [0.3, 1.0, 3.0].map(|x| x * tau_m);
        let mut best: Option<(LmReport, Vec<f64>, f64)> = None;
        for (i, tau0) in near_sample.into_iter().chain(near_tau_m).enumerate() {
            let about_tau_m = i >= near_sample.len();
            if about_tau_m {
                let explained = best
                    .as_ref()
                    .is_some_and(|(fit, _, _)| explains(&problem, &fit.params, &noise));
                if explained {
                    break;
                }
            } else if tau0 >= 0.1 * tau_m && best.is_some() {
                continue;
            }
            for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                r.sigma = *s;
            }
            let mut theta = reduced.params[..3].to_vec();
            // Where τe's lag at the reversals looks like a smaller kS, the reduced fit can
            // drive kS to 0 (its logarithm far below the start's): kS restarts there from the
            // start's value, or its gradient in the logarithm vanishes.
            if ks_collapsed(theta[0], ks0) {
                theta[0] = ks0.ln();
            }
            theta.push(
                if about_tau_m {
                    tau0
                } else {
                    tau0.min(0.1 * tau_m)
                }
                .ln(),
            );
            theta.extend_from_slice(&reduced.params[3..]);
            if settings.torque_constant.is_none() {
                theta.push(0.0); // the viscous share of kV at its prior mean
            }
            let fit = fit_stages(&mut problem, &theta, settings.lm, &mut iterations)?;
            // A fit that drove kS to 0 (its logarithm far below the start's) leaves kS no
            // interval, so it is no result; the next starts are tried instead (with R and k
            // given, a PRBS of the paper's motor read by an encoder converged there from every
            // start about the sample period, and fitted kS from those about τm).
            if !fit.termination.converged() || ks_collapsed(fit.params[0], ks0) {
                continue;
            }
            // Starts compared at the records' own noise levels (the second stage's weights
            // differ from one start to the next).
            let weights: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
            for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                r.sigma = *s;
            }
            let cost = problem.cost(&fit.params).unwrap_or(f64::INFINITY);
            if best.as_ref().is_none_or(|(_, _, c)| cost < *c) {
                best = Some((fit, weights, cost));
            }
        }
        // Kept whenever it converged: its intervals carry what τe leaves unknown.
        let mut kept = None;
        if let Some((fit, weights, _)) = best {
            for (r, s) in problem.records.iter_mut().zip(&weights) {
                r.sigma = *s;
            }
            let unc = fit_uncertainty(&problem, &fit);
            let ci = unc.as_ref().map(|u| intervals_of(&problem, &fit, u));
            // Without k, kA can trade against τe and the viscous share of kV (no interval, or
            // kA's reaching 0): then the two coefficients the records fix are fitted instead.
            let undetermined = ci.as_ref().is_none_or(|(_, c)| c[2][0] <= 0.0);
            let unc = unc.filter(|_| !undetermined);
            kept = if settings.torque_constant.is_none() && undetermined {
                traded(&mut problem, &fit, ks0, settings.lm, &mut iterations)?
            } else {
                ci.map(|(_, c)| {
                    let ci = c[3];
                    // τe is reported where it is significantly above 0 (its interval
                    // excludes 0).
                    let t = if ci[0] > 0.0 {
                        TauE::Fitted {
                            value_s: fit.params[3].exp(),
                            ci95_s: ci,
                        }
                    } else {
                        TauE::NotResolved { upper_s: ci[1] }
                    };
                    (fit, t, unc)
                })
            };
        }
        match kept {
            Some(r) => result = r,
            None => {
                problem.electrical = false;
                for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                    r.sigma = *s;
                }
                result.1 = TauE::Unfitted;
                result.2 = None;
            }
        }
    }
    let (report, tau_e, unc) = result;
    let model = problem
        .params_of(&report.params)
        .ok_or_else(|| FitError::Solver("parameters left the representable range".into()))?;
    let ci95 = unc
        .or_else(|| fit_uncertainty(&problem, &report))
        .map(|u| intervals_of(&problem, &report, &u))
        .map(|(_, ci)| {
            let ka = match tau_e {
                TauE::Traded { lead_ci95, .. } => [0.0, lead_ci95[1]],
                _ => ci[2],
            };
            [ci[0], ci[1], ka]
        });
    let initial_speed_rad_s = problem
        .records
        .iter()
        .map(|r| problem.initial_speed(r, &report.params))
        .collect();
    let quality = problem.quality(&report.params);
    let residual_over_noise = residual_over_noise(&quality, &noise);
    Ok(FeedforwardFit {
        residual_over_noise,
        params: model.constants,
        ci95,
        tau_e,
        initial_speed_rad_s,
        quality,
        iterations,
        termination: report.termination,
    })
}

/// Residual RMS over noise below which a fit explains a record (the noise estimate of
/// [`noise_std`] is itself rough by tens of per cent; fits that explain their records gave
/// 0.99–1.15 on the fixtures' motors, the reduced model of an underdamped one 11–65).
pub const EXPLAINED_RATIO: f64 = 2.0;

/// Each record's residual RMS in `quality` over that record's `noise`.
fn residual_over_noise(quality: &[ChannelQuality], noise: &[f64]) -> Vec<f64> {
    quality
        .iter()
        .zip(noise)
        .map(|(q, s)| q.rms_residual / s)
        .collect()
}

/// Whether the model at `theta` leaves on every record a residual within
/// [`EXPLAINED_RATIO`] of that record's `noise`.
fn explains(problem: &FfProblem, theta: &[f64], noise: &[f64]) -> bool {
    residual_over_noise(&problem.quality(theta), noise)
        .iter()
        .all(|&x| x <= EXPLAINED_RATIO)
}

/// Two stages from `theta0`: the records weighted by their noise, then (if the first
/// converged) by their residual RMS. Counts the iterations into `iterations`.
fn fit_stages(
    problem: &mut FfProblem,
    theta0: &[f64],
    lm: LmSettings,
    iterations: &mut u64,
) -> Result<LmReport, FitError> {
    let first = solve(&*problem, theta0, lm)?;
    *iterations += first.iterations;
    if !first.termination.converged() {
        return Ok(first);
    }
    let quality = problem.quality(&first.params);
    let mut changed = false;
    for (r, q) in problem.records.iter_mut().zip(&quality) {
        if let Some(s) = reweighted_sigma(r.sigma, r.floor, q.rms_residual) {
            r.sigma = s;
            changed = true;
        }
    }
    if !changed {
        return Ok(first);
    }
    let second = solve(&*problem, &first.params, lm)?;
    *iterations += second.iterations;
    Ok(second)
}

/// Standard errors and 95 % intervals of the model's parameters (kS, kV, kA, and τe when
/// fitted; SI units) at `report`, from its uncertainty `unc` ([`fit_uncertainty`]: the
/// Newey–West sandwich record by record), computed once per kept fit.
fn intervals_of(
    problem: &FfProblem,
    report: &LmReport,
    unc: &Uncertainty,
) -> (Vec<f64>, Vec<[f64; 2]>) {
    let m = problem.n_model();
    let values: Vec<f64> = report.params[..m].iter().map(|t| t.exp()).collect();
    let std: Vec<f64> = (0..m).map(|i| values[i] * unc.std_error[i]).collect();
    let ci = (0..m)
        .map(|i| {
            let half = values[i] * unc.ci95_half_width[i];
            [values[i] - half, values[i] + half]
        })
        .collect();
    (std, ci)
}

/// The sandwich uncertainty of every fitted parameter (in the fit's own coordinates: the
/// logarithms of the constants and of τe, then the initial speeds and the nuisances), each
/// standard error at least the model-based one ([`at_least`]: the small servo's staircase
/// with a tachometer, R and k given, missed kA in 30 of 200 noise seeds with the Newey–West
/// one alone, 10 with the floor).
fn fit_uncertainty(problem: &FfProblem, report: &LmReport) -> Option<Uncertainty> {
    let (mut r, jac) = problem.jacobian(&report.params)?;
    // A prior's row enters the score's covariance with its expected square, 1 (its variance),
    // not the realised one: at the prior mean that would be 0 and the prior's uncertainty lost.
    let priors = problem.nuisances();
    let n = r.len();
    r[n - priors..].iter_mut().for_each(|v| *v = 1.0);
    // Readings that repeat exactly share one quantisation error (an encoder's speed held at 0
    // while the rotor creeps through a reversal): see [`newey_west_run_covariance`].
    let mut runs: Vec<usize> = problem
        .records
        .iter()
        .flat_map(|rec| equal_runs(&rec.data))
        .collect();
    runs.extend(std::iter::repeat_n(1, priors));
    let score = newey_west_run_covariance(&r, &jac, &problem.series(), &runs)?;
    let hac = sandwich_uncertainty(&report.normal, &score)?;
    // The model-based score covariance, `s² J_dᵀJ_d` of the data rows (`s²` their mean square
    // over n − p) and the priors' own: a floor under the Newey–West one ([`at_least`]).
    let data = n - priors;
    let dof = data.checked_sub(jac.ncols()).filter(|&d| d > 0)?;
    let s2 = r[..data].iter().map(|v| v * v).sum::<f64>() / dof as f64;
    let jd = jac.rows(0, data);
    let jp = jac.rows(data, priors);
    let model = jd.transpose() * jd * s2 + jp.transpose() * jp;
    let based = sandwich_uncertainty(&report.normal, &model)?;
    at_least(hac, &based)
}

/// [`TauE::Traded`] of `fit` (with τe, no torque constant given, kA undetermined): refitted
/// with the viscous share of kV fixed at 0, where the model's two coefficients are its own
/// parameters (`lead = kA`, `kA τe`), their intervals from that fit's sandwich covariance (the
/// product's by the delta method on `ln kA + ln τe`). `problem` is left in that mode when the
/// refit gives intervals (the returned report is in its coordinates), else restored; `None`
/// when the refit fails. kS restarts from `ks0` \[V\] (the start's) where `fit` drove it to 0,
/// as the stage with τe does.
fn traded(
    problem: &mut FfProblem,
    fit: &LmReport,
    ks0: f64,
    lm: LmSettings,
    iterations: &mut u64,
) -> Result<Option<(LmReport, TauE, Option<Uncertainty>)>, FitError> {
    let Some(p) = problem.params_of(&fit.params) else {
        return Ok(None);
    };
    // The start: the same two coefficients with the share at 0.
    let (ka, tau_e) = (p.constants.ka_v_s2_per_rad, p.tau_e_s);
    let lead = ka + tau_e * (p.constants.kv_v_s_per_rad - p.back_emf_v_s_per_rad);
    let mut theta: Vec<f64> = fit.params[..fit.params.len() - 1].to_vec();
    theta[2] = lead.ln();
    theta[3] = (ka * tau_e / lead).ln();
    if ks_collapsed(theta[0], ks0) {
        theta[0] = ks0.ln();
    }
    problem.share_at_zero = true;
    let refit = fit_stages(problem, &theta, lm, iterations)?;
    let traded = refit
        .termination
        .converged()
        .then(|| fit_uncertainty(problem, &refit))
        .flatten()
        .and_then(|unc| {
            let ratio = unc.ci95_half_width[2] / unc.std_error[2];
            let (ln_ka, ln_tau) = (refit.params[2], refit.params[3]);
            let lead = ln_ka.exp();
            let product = (ln_ka + ln_tau).exp();
            let c = &unc.covariance;
            let h_lead = lead * unc.ci95_half_width[2];
            let h_product =
                product * ratio * (c[(2, 2)] + 2.0 * c[(2, 3)] + c[(3, 3)]).max(0.0).sqrt();
            (h_lead < lead && h_product < product).then_some((
                TauE::Traded {
                    lead_v_s2_per_rad: lead,
                    lead_ci95: [lead - h_lead, lead + h_lead],
                    product_v_s3_per_rad: product,
                    product_ci95: [product - h_product, product + h_product],
                },
                unc,
            ))
        });
    match traded {
        Some((t, unc)) => Ok(Some((refit, t, Some(unc)))),
        None => {
            problem.share_at_zero = false;
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::voltage_speed::model::FeedforwardParams;
    use crate::voltage_speed::simulation::simulate_feedforward;

    /// The exact solution against a fine explicit integration of the same equation, through a
    /// stop and a restart the other way.
    #[test]
    fn the_closed_form_matches_a_fine_integration_through_reversals() {
        let p = FeedforwardParams {
            ks_v: 0.3,
            kv_v_s_per_rad: 0.05,
            ka_v_s2_per_rad: 0.01,
        };
        let input = Input::piecewise(&[(0.0105, 6.0), (0.4003, -4.0), (0.9, 0.2)]).unwrap();
        let (dt, n) = (1e-3, 1500);
        let (speed, angle) = simulate_feedforward(&p, &input, dt, n, 0.0);
        let (mut w, mut th) = (0.0_f64, 0.0_f64);
        let h = 1e-7;
        let per = (dt / h).round() as usize;
        for i in 0..n {
            assert!(
                (speed[i] - w).abs() < 1e-4 * 120.0,
                "speed at {i}: {} vs {w}",
                speed[i]
            );
            assert!(
                (angle[i] - th).abs() < 1e-4 * 50.0,
                "angle at {i}: {} vs {th}",
                angle[i]
            );
            for s in 0..per {
                let t = i as f64 * dt + (s as f64 + 0.5) * h;
                let e = input.volts_at(t);
                let d = if w != 0.0 {
                    w.signum()
                } else if e.abs() > p.ks_v {
                    e.signum()
                } else {
                    0.0
                };
                if d == 0.0 {
                    continue;
                }
                let wn = w + h * (e - p.ks_v * d - p.kv_v_s_per_rad * w) / p.ka_v_s2_per_rad;
                th += 0.5 * (w + wn) * h;
                w = if wn * d < 0.0 { 0.0 } else { wn };
            }
        }
        // It stopped after the reversal command and ran the other way.
        assert!(speed[600] < -10.0, "{}", speed[600]);
        // 0.2 V is inside the dead band: at rest at the end.
        assert_eq!(speed[n - 1], 0.0);
    }
}
