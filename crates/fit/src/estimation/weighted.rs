//! The weighted two-stage fit every simulation-based route shares: a least-squares problem
//! whose residuals are channels of records, each divided by its noise level
//! ([`WeightedProblem`]), fitted, reweighted by each channel's own residual and fitted again
//! ([`fit_weighted_point`]), then given its intervals and judged ([`attach_intervals`]).

use motor_model::MotorParams;
use nalgebra::DMatrix;

use crate::error::FitError;
use crate::estimation::fitted::FullFit;
use crate::estimation::lm::{solve, LeastSquares, LmSettings, NormalEquations};
use crate::estimation::parameters::Parameters;
use crate::estimation::plausibility::{judge, RecordFacts};
use crate::estimation::records::{reweighted_sigma, Channel, ChannelQuality, FittedChannel};
use crate::estimation::stats::{sandwich_uncertainty, SeriesLayout};

/// A least-squares problem in θ (the motor's six logarithms, then the unconstrained
/// coordinates of the fitted effect parameters: [`Parameters`]) whose residuals are channels
/// of records, each divided by its channel's noise level.
pub(crate) trait WeightedProblem: LeastSquares {
    /// How θ maps to the motor and its effects.
    fn parameters(&self) -> &Parameters;
    /// The noise level of every channel, in a fixed order, with the smallest it may become
    /// ([`noise_floor`]).
    fn sigmas_mut(&mut self) -> Vec<(&mut f64, f64)>;
    /// Whether [`fit_weighted_point`] reweights each channel by its own residual at the first
    /// solution (the default); `false` when the noise levels were given and are kept.
    fn reweights(&self) -> bool {
        true
    }
    /// Fit quality of every channel at `theta`, in the order of [`Self::sigmas_mut`].
    fn channel_quality(&self, theta: &[f64]) -> Vec<ChannelQuality>;
    /// Newey–West covariance of the score `Jᵀr` at `theta` (channels independent), with what
    /// the fitted residuals miss of it ([`crate::estimation::stats::fitted_residual_bias`]).
    fn score_covariance(&self, theta: &[f64]) -> Option<DMatrix<f64>>;
    /// Which series (channel of a record) each weighted residual belongs to, in residual
    /// order, and each series' Newey–West lag.
    fn series_layout(&self) -> SeriesLayout;
    /// What the records show, for the plausibility of the result.
    fn facts(&self) -> RecordFacts;
    /// Every fitted channel at `theta`, measured and modelled.
    fn fitted_channels(&self, theta: &[f64]) -> Vec<FittedChannel>;
}

/// Fits `problem` from `theta0` in two stages (one when it keeps given weights,
/// [`WeightedProblem::reweights`]), still without intervals: the estimate, its quality and
/// the normal equations at it for [`attach_intervals`], which a caller that may refit at once
/// (with moved inputs) calls only on the fit it keeps. The Newey–West score covariance behind
/// the intervals costs as much as several iterations on a long record.
pub(crate) fn fit_weighted_point<P: WeightedProblem>(
    problem: &mut P,
    theta0: &[f64],
    settings: LmSettings,
) -> Result<(FullFit, NormalEquations), FitError> {
    let first = solve(&*problem, theta0, settings)?;
    // Second stage: weight each channel by its own residual RMS at the first solution, so that
    // every channel's weighted residuals have unit variance and the pooled variance behind the
    // intervals describes each of them (feasible generalised least squares). Skipped when the
    // problem keeps given weights, the first stage did not converge or a channel fits exactly
    // (noise-free data).
    let first_iterations = first.iterations;
    let (report, iterations) = if problem.reweights()
        && first.termination.converged()
        && problem.parameters().decode(&first.params).is_some()
    {
        let rms = problem.channel_quality(&first.params);
        let mut changed = false;
        for ((sigma, floor), q) in problem.sigmas_mut().into_iter().zip(&rms) {
            if let Some(s) = reweighted_sigma(*sigma, floor, q.rms_residual) {
                *sigma = s;
                changed = true;
            }
        }
        if changed {
            let second = solve(&*problem, &first.params, settings)?;
            let total = first_iterations + second.iterations;
            (second, total)
        } else {
            (first, first_iterations)
        }
    } else {
        (first, first_iterations)
    };
    let theta = report.params.clone();
    let (params, effects) = problem
        .parameters()
        .decode(&theta)
        .ok_or_else(|| FitError::Solver("parameters left the representable range".into()))?;
    let fit = FullFit {
        params,
        effects,
        effect_estimates: Vec::new(),
        fitted: problem.fitted_channels(&theta),
        std_error: None,
        ci95: None,
        correlation: None,
        quality: problem.channel_quality(&theta),
        iterations,
        termination: report.termination,
        refusal: None,
        refusal_beside_channels: None,
        cost: report.normal.cost,
        initial_states: Vec::new(),
        theta,
        theta_covariance: None,
    };
    Ok((fit, report.normal))
}

/// Sets the intervals of a fit by [`fit_weighted_point`] from `normal`, its normal equations,
/// and judges it ([`judge`]): the Newey–West sandwich (residuals of logged signals are rarely
/// white), then the delta method through each parameter's transform back to SI units.
pub(crate) fn attach_intervals<P: WeightedProblem>(
    problem: &P,
    fit: &mut FullFit,
    normal: &NormalEquations,
) {
    let unc = problem
        .score_covariance(&fit.theta)
        .and_then(|s| sandwich_uncertainty(normal, &s));
    let dof = unc.as_ref().map_or(0, |u| u.dof);
    set_intervals(fit, problem.parameters(), unc.map(|u| u.covariance), dof);
    judge(fit, &problem.facts());
}

/// Sets the intervals of `fit` (motor and effects, SI units) from the covariance of its θ
/// with `dof` degrees of freedom; without a covariance (or with one that has no finite
/// intervals) the intervals are left as they are, the effect estimates without intervals.
pub(crate) fn set_intervals(
    fit: &mut FullFit,
    parameters: &Parameters,
    cov_theta: Option<DMatrix<f64>>,
    dof: usize,
) {
    let intervals = cov_theta
        .as_ref()
        .and_then(|c| parameters.intervals(&fit.theta, c, dof));
    if let (Some(iv), Some(cov)) = (&intervals, cov_theta) {
        fit.std_error = match iv.std_error[..] {
            [r_ohm, l_henry, k_nm_per_a, f_nms_per_rad, j_kgm2, ts_nm, ..] => Some(MotorParams {
                r_ohm,
                l_henry,
                k_nm_per_a,
                f_nms_per_rad,
                j_kgm2,
                ts_nm,
            }),
            _ => None,
        };
        fit.ci95 = crate::MotorIntervals::from_solver_order(&iv.ci95);
        fit.correlation = Some(iv.correlation.clone());
        fit.theta_covariance = Some(cov);
    }
    if intervals.is_some() || fit.effect_estimates.is_empty() {
        fit.effect_estimates = parameters.estimates(&fit.theta, intervals.as_ref());
    }
}

/// Quality of one channel from its sums: `sse = Σ(ŷ − y)²`, `sst = Σ(y − ȳ)²`, `n` samples.
pub(crate) fn quality_from_sums(
    test: usize,
    channel: Channel,
    noise_std: f64,
    sse: f64,
    sst: f64,
    n: usize,
) -> ChannelQuality {
    ChannelQuality {
        test,
        channel,
        noise_std,
        rms_residual: (sse / n.max(1) as f64).sqrt(),
        nrmse_fit_percent: if sst > 0.0 {
            100.0 * (1.0 - (sse / sst).sqrt())
        } else {
            f64::NAN
        },
    }
}
