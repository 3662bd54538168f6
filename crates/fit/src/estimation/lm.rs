//! Levenberg–Marquardt as an `argmin` solver.
//!
//! Minimises `C(p) = ½ Σ rᵢ(p)²`. Each iteration solves the damped normal equations
//!
//! ```text
//! (JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr
//! ```
//!
//! (Marquardt's scaling: the damping acts on each parameter in its own units, so parameters of
//! very different magnitudes — ohms and kg·m² — are handled alike). A step that lowers the cost
//! is accepted and λ shrinks; one that does not is rejected, λ grows and the step is retried
//! within the same iteration, so the `argmin` state (parameter, cost) only ever changes on
//! accepted steps. The problem supplies `JᵀJ` and `Jᵀr` directly ([`NormalEquations`]), which
//! it can accumulate in one pass over the data without storing `J`.
//!
//! The stop that is not success is reported, not raised: [`Termination`].

use argmin::core::{
    CostFunction, Error as ArgminError, Executor, Gradient, IterState, Problem, Solver, State,
    TerminationReason, TerminationStatus, KV,
};
use nalgebra::{DMatrix, DVector};

use crate::error::FitError;

/// Steps accepted by every [`LevenbergMarquardt`] of this process so far.
static ACCEPTED_STEPS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many Levenberg–Marquardt steps every fit of this process has accepted so far: a sign of
/// life for a long identification that a program can show while it waits (`motorid identify`
/// prints it with its phase once a second). It only grows; fits running at once share it.
pub fn accepted_steps() -> u64 {
    ACCEPTED_STEPS.load(std::sync::atomic::Ordering::Relaxed)
}

/// `JᵀJ`, `Jᵀr` and the cost `½‖r‖²` at one parameter vector.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    /// `JᵀJ` (p × p).
    pub jtj: DMatrix<f64>,
    /// `Jᵀr` (p).
    pub jtr: DVector<f64>,
    /// `½‖r‖²`.
    pub cost: f64,
    /// Number of residuals.
    pub n_residuals: usize,
}

impl NormalEquations {
    /// The normal equations of the residuals `r` and their dense Jacobian `jac` (a row per
    /// residual, a column per parameter): `JᵀJ`, `Jᵀr` and `½‖r‖²`.
    pub(crate) fn from_jacobian(r: Vec<f64>, jac: &DMatrix<f64>) -> NormalEquations {
        let n_residuals = r.len();
        let r = DVector::from_vec(r);
        NormalEquations {
            jtj: jac.tr_mul(jac),
            jtr: jac.tr_mul(&r),
            cost: 0.5 * r.norm_squared(),
            n_residuals,
        }
    }
}

/// `½‖r‖²` of the residuals `r`, the cost [`LeastSquares::cost`] returns.
pub(crate) fn half_squared_norm(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|v| v * v).sum::<f64>()
}

/// A nonlinear least-squares problem as the solver sees it.
pub trait LeastSquares {
    /// Number of parameters.
    fn n_params(&self) -> usize;
    /// `½‖r(p)‖²`, or `None` where `p` is outside the model's domain (the step is rejected).
    fn cost(&self, p: &[f64]) -> Option<f64>;
    /// Normal equations at `p`, or `None` outside the domain.
    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations>;
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Termination {
    /// Relative cost reduction (achieved by the last step, or predicted for the next one) below
    /// `ftol`, or relative step (the last one taken, or the next Gauss–Newton one) below `xtol`.
    Converged,
    /// Gradient `‖Jᵀr‖∞` below `gtol` (an exact fit).
    ZeroGradient,
    /// No step lowered the cost even with the largest damping, and the local model promised a
    /// gain below √ε of the cost: rounding in the summed cost is what stops progress, so the fit
    /// is at its optimum to working precision (MINPACK's `info = 6`/`7`; rust-cv's
    /// `NoImprovementPossible`).
    NoImprovementPossible,
    /// No step lowered the cost even with the largest damping, although the local model
    /// promised a gain larger than √ε of the cost: the model and the data disagree there.
    Stalled,
    /// The iteration budget ran out before convergence.
    MaxIterations,
    /// The budget of model evaluations (accepted and rejected trial steps together,
    /// [`LmSettings::max_evaluations`]) ran out before convergence.
    MaxEvaluations,
    /// The residuals or Jacobian became non-finite at the start.
    NonFinite,
}

impl Termination {
    /// Whether this counts as a converged fit.
    pub fn converged(self) -> bool {
        matches!(
            self,
            Termination::Converged | Termination::ZeroGradient | Termination::NoImprovementPossible
        )
    }

    /// Text for reports.
    pub fn text(self) -> &'static str {
        match self {
            Termination::Converged => "converged",
            Termination::ZeroGradient => "converged (zero gradient)",
            Termination::NoImprovementPossible => {
                "converged to working precision (no step lowers the cost further)"
            }
            Termination::Stalled => "stalled (no step lowers the cost)",
            Termination::MaxIterations => "maximum iterations reached",
            Termination::MaxEvaluations => "maximum model evaluations reached",
            Termination::NonFinite => "non-finite residuals",
        }
    }
}

/// Tolerances and limits of the solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSettings {
    /// Relative cost reduction below which the fit has converged.
    pub ftol: f64,
    /// Relative step size below which the fit has converged.
    pub xtol: f64,
    /// Gradient infinity norm below which the fit has converged.
    pub gtol: f64,
    /// Maximum accepted iterations.
    pub max_iters: u64,
    /// Maximum evaluations of the model (each trial step, accepted or rejected, and each
    /// Jacobian count one): bounds the work of a fit whose steps keep being rejected.
    pub max_evaluations: u64,
    /// Initial damping λ.
    pub lambda_start: f64,
    /// Evaluate the first trial step with its normal equations at once (one pass over the data
    /// instead of two), as after an accepted step: for a start known to be close to the
    /// solution, such as a polish after a coarse fit.
    pub optimistic_start: bool,
}

impl Default for LmSettings {
    fn default() -> Self {
        LmSettings {
            // 100 times stricter than SciPy's and MINPACK's defaults (1e-8); the statistical
            // precision of a fit of n samples is ~p/n of the cost, far coarser.
            ftol: 1e-10,
            xtol: 1e-10,
            gtol: 0.0,
            max_iters: 200,
            // 200 iterations of about five evaluations each: a fit that needs more is not
            // converging.
            max_evaluations: 1000,
            lambda_start: 1e-3,
            optimistic_start: false,
        }
    }
}

impl LmSettings {
    /// Checks every tolerance is finite and non-negative and the iteration budget positive.
    pub fn validated(self) -> Result<Self, FitError> {
        for (name, v) in [
            ("ftol", self.ftol),
            ("xtol", self.xtol),
            ("gtol", self.gtol),
            ("lambda_start", self.lambda_start),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(FitError::InvalidSetting {
                    name,
                    value: v,
                    expected: "a finite value of zero or more",
                });
            }
        }
        if self.max_evaluations == 0 {
            return Err(FitError::InvalidSetting {
                name: "max_evaluations",
                value: 0.0,
                expected: "at least one evaluation",
            });
        }
        if self.max_iters == 0 {
            return Err(FitError::InvalidSetting {
                name: "max_iters",
                value: 0.0,
                expected: "at least one iteration",
            });
        }
        Ok(self)
    }
}

/// Largest damping tried before the solver declares itself stalled.
const LAMBDA_MAX: f64 = 1e16;
/// Relative predicted gain below which a solver that can no longer lower the cost counts as
/// converged: `√ε`, MINPACK's default `ftol`.
const STALL_PRECISION: f64 = 1.4901161193847656e-8;
/// Damping floor on `diag(JᵀJ)` relative to its largest entry (keeps the scaling invertible
/// when a parameter has no influence at the current point).
const DIAG_FLOOR: f64 = 1e-12;

/// The outcome of a solve.
#[derive(Debug, Clone, PartialEq)]
pub struct LmReport {
    /// Parameters at the end.
    pub params: Vec<f64>,
    /// Normal equations at `params` (for covariance).
    pub normal: NormalEquations,
    /// Accepted iterations.
    pub iterations: u64,
    /// Why it stopped.
    pub termination: Termination,
}

/// Adapter from [`LeastSquares`] to argmin's operator traits.
struct ArgminProblem<'a, P: LeastSquares>(&'a P);

impl<P: LeastSquares> CostFunction for ArgminProblem<'_, P> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, ArgminError> {
        Ok(self.0.cost(p).unwrap_or(f64::INFINITY))
    }
}

impl<P: LeastSquares> Gradient for ArgminProblem<'_, P> {
    type Param = Vec<f64>;
    type Gradient = Option<NormalEquations>;
    fn gradient(&self, p: &Vec<f64>) -> Result<Option<NormalEquations>, ArgminError> {
        Ok(self.0.normal_equations(p))
    }
}

/// The Levenberg–Marquardt solver (an argmin [`Solver`]).
#[derive(Debug, Clone)]
pub struct LevenbergMarquardt {
    settings: LmSettings,
    lambda: f64,
    normal: Option<NormalEquations>,
    last_step_rel: f64,
    last_cost_rel: f64,
    /// Whether the last trial step was accepted: then the next trial is evaluated with its
    /// normal equations at once (one pass over the data instead of two when it is accepted
    /// again, the usual case near the solution).
    last_accepted: bool,
    /// Model evaluations so far (cost or normal equations).
    evaluations: u64,
    stop: Option<Termination>,
}

impl LevenbergMarquardt {
    /// A solver with the given settings.
    pub fn new(settings: LmSettings) -> Result<Self, FitError> {
        let settings = settings.validated()?;
        Ok(LevenbergMarquardt {
            settings,
            lambda: settings.lambda_start,
            normal: None,
            last_step_rel: f64::INFINITY,
            last_cost_rel: f64::INFINITY,
            last_accepted: settings.optimistic_start,
            evaluations: 0,
            stop: None,
        })
    }
}

type LmState = IterState<Vec<f64>, (), (), (), (), f64>;

fn finite_normal(n: &NormalEquations) -> bool {
    n.cost.is_finite() && n.jtj.iter().all(|v| v.is_finite()) && n.jtr.iter().all(|v| v.is_finite())
}

impl<P: LeastSquares> Solver<ArgminProblem<'_, P>, LmState> for LevenbergMarquardt {
    fn name(&self) -> &str {
        "Levenberg-Marquardt"
    }

    fn init(
        &mut self,
        problem: &mut Problem<ArgminProblem<'_, P>>,
        state: LmState,
    ) -> Result<(LmState, Option<KV>), ArgminError> {
        let p0 = state
            .get_param()
            .cloned()
            .ok_or_else(|| ArgminError::msg("Levenberg-Marquardt needs a start vector"))?;
        let normal = problem.gradient(&p0)?;
        let cost = match &normal {
            Some(n) if finite_normal(n) => n.cost,
            _ => {
                self.stop = Some(Termination::NonFinite);
                f64::INFINITY
            }
        };
        self.normal = normal;
        Ok((state.param(p0).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<ArgminProblem<'_, P>>,
        state: LmState,
    ) -> Result<(LmState, Option<KV>), ArgminError> {
        let p = state
            .get_param()
            .cloned()
            .ok_or_else(|| ArgminError::msg("Levenberg-Marquardt: no current parameter"))?;
        let Some(normal) = self.normal.clone() else {
            self.stop = Some(Termination::NonFinite);
            return Ok((state, None));
        };
        let n = p.len();
        let cost = normal.cost;
        if normal.jtr.amax() <= self.settings.gtol {
            self.stop = Some(Termination::ZeroGradient);
            return Ok((state, None));
        }
        // Predicted reduction of the undamped Gauss–Newton step, ½ Jᵀr·(JᵀJ)⁻¹Jᵀr: when the
        // local quadratic model says less than ftol·C is left to gain, the fit has converged
        // (MINPACK's test; the actual reduction alone stalls on rounding at a noisy optimum).
        // The undamped Gauss–Newton step and the reduction the local quadratic model predicts
        // for it, ½ Jᵀr·(JᵀJ)⁻¹Jᵀr. When that reduction is below ftol·C, or the step itself is
        // below xtol relative to the parameters, there is nothing left to gain: converged
        // (MINPACK's tests; the actual reduction alone stalls on rounding at an optimum).
        let p_norm = p.iter().map(|v| v * v).sum::<f64>().sqrt();
        let gauss_newton = normal
            .jtj
            .clone()
            .cholesky()
            .map(|chol| chol.solve(&(-&normal.jtr)));
        let predicted = gauss_newton
            .as_ref()
            .map(|step| -0.5 * normal.jtr.dot(step))
            .filter(|p| p.is_finite());
        let tiny_step = gauss_newton
            .as_ref()
            .is_some_and(|step| step.norm() <= self.settings.xtol * (p_norm + self.settings.xtol));
        if tiny_step || predicted.is_some_and(|p| p <= self.settings.ftol * cost) {
            self.stop = Some(Termination::Converged);
            return Ok((state, None));
        }
        let diag_max = (0..n).map(|i| normal.jtj[(i, i)]).fold(0.0_f64, f64::max);
        loop {
            if self.evaluations >= self.settings.max_evaluations {
                self.stop = Some(Termination::MaxEvaluations);
                return Ok((state, None));
            }
            let mut a = normal.jtj.clone();
            for i in 0..n {
                let d = normal.jtj[(i, i)]
                    .max(DIAG_FLOOR * diag_max)
                    .max(f64::MIN_POSITIVE);
                a[(i, i)] += self.lambda * d;
            }
            let step = a.cholesky().map(|c| c.solve(&(-&normal.jtr)));
            if let Some(delta) = step.filter(|d| d.iter().all(|v| v.is_finite())) {
                let trial: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
                // Optimistic: after an accepted step, evaluate the trial's normal equations
                // directly; otherwise screen it with the cheaper cost first.
                self.evaluations += 1;
                let trial_normal = if self.last_accepted {
                    problem
                        .gradient(&trial)?
                        .filter(|tn| finite_normal(tn) && tn.cost < cost)
                } else if problem.cost(&trial)? < cost {
                    self.evaluations += 1;
                    problem.gradient(&trial)?.filter(finite_normal)
                } else {
                    None
                };
                if let Some(tn) = trial_normal {
                    self.last_step_rel = delta.norm() / (p_norm + self.settings.xtol);
                    self.last_cost_rel = (cost - tn.cost) / cost.max(f64::MIN_POSITIVE);
                    self.lambda = (self.lambda / 3.0).max(1e-15);
                    self.last_accepted = true;
                    ACCEPTED_STEPS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let new_cost = tn.cost;
                    self.normal = Some(tn);
                    return Ok((state.param(trial).cost(new_cost), None));
                }
                self.last_accepted = false;
            }
            self.lambda *= 4.0;
            if self.lambda > LAMBDA_MAX {
                // No step lowers the cost. If the quadratic model promised less than √ε of it,
                // rounding in the summed cost is what stopped progress: converged to working
                // precision. Otherwise the model and the data disagree: a genuine stall.
                let at_precision = predicted.is_some_and(|p| p <= STALL_PRECISION * cost);
                self.stop = Some(if at_precision {
                    Termination::NoImprovementPossible
                } else {
                    Termination::Stalled
                });
                return Ok((state, None));
            }
        }
    }

    fn terminate(&mut self, state: &LmState) -> TerminationStatus {
        if let Some(stop) = self.stop {
            return TerminationStatus::Terminated(match stop {
                t if t.converged() => TerminationReason::SolverConverged,
                other => TerminationReason::SolverExit(other.text().to_string()),
            });
        }
        if state.get_iter() > 0
            && (self.last_cost_rel <= self.settings.ftol
                || self.last_step_rel <= self.settings.xtol)
        {
            self.stop = Some(Termination::Converged);
            return TerminationStatus::Terminated(TerminationReason::SolverConverged);
        }
        TerminationStatus::NotTerminated
    }
}

/// Solves `problem` from `start` with argmin's executor.
pub fn solve<P: LeastSquares>(
    problem: &P,
    start: &[f64],
    settings: LmSettings,
) -> Result<LmReport, FitError> {
    if start.len() != problem.n_params() {
        return Err(FitError::Solver(format!(
            "start vector has {} entries for {} parameters",
            start.len(),
            problem.n_params()
        )));
    }
    let solver = LevenbergMarquardt::new(settings)?;
    let result = Executor::new(ArgminProblem(problem), solver)
        .configure(|s| s.param(start.to_vec()).max_iters(settings.max_iters))
        .timer(false)
        .run()
        .map_err(|e| FitError::Solver(e.to_string()))?;
    let state = result.state();
    let iterations = state.get_iter();
    let solver = result.solver();
    let termination = match solver.stop {
        Some(t) => t,
        None => Termination::MaxIterations,
    };
    let params = state
        .get_param()
        .cloned()
        .ok_or_else(|| FitError::Solver("no final parameter".into()))?;
    let normal = solver
        .normal
        .clone()
        .ok_or_else(|| FitError::Solver("no normal equations at the end".into()))?;
    Ok(LmReport {
        params,
        normal,
        iterations,
        termination,
    })
}
