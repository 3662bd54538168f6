//! The result of a fit of the motor (and its effects) to records: [`FullFit`], shared by the
//! full-model fit of step tests and the output-error fit of records of any excitation.

use motor_model::{Effects, MotorParams};
use nalgebra::DMatrix;

use crate::estimation::lm::Termination;
use crate::estimation::parameters::{names_of, units_of, EffectEstimate};
use crate::estimation::records::{ChannelQuality, FittedChannel, FittedInitialState};
use crate::estimation::refusal::Refusal;

/// Result of the full-model identification.
#[derive(Debug, Clone, PartialEq)]
pub struct FullFit {
    /// The identified motor.
    pub params: MotorParams,
    /// The effects of the model at the solution (fitted parameters at their estimates, the
    /// others as given); empty for the nominal model.
    pub effects: Effects,
    /// The fitted effect parameters with units and intervals, in the order of
    /// [`Effects::fitted_slots`] (empty for the nominal model).
    pub effect_estimates: Vec<EffectEstimate>,
    /// The fitted channels at the solution, measured and modelled.
    pub fitted: Vec<FittedChannel>,
    /// Standard error of each parameter, by name and in its unit (the standard error of R
    /// in `std_error.r_ohm` \[Ω\], …); `None` if the fit has no degrees of freedom or a
    /// singular Jacobian (a parameter the data cannot determine).
    pub std_error: Option<MotorParams>,
    /// 95 % intervals `[lo, hi]` of R, L, k, f, J, Ts by name (t distribution, as `nlparci`,
    /// on a Newey–West covariance), each in its parameter's SI unit.
    pub ci95: Option<crate::MotorIntervals>,
    /// Correlation matrix of all fitted parameters ((6 + n) × (6 + n), in the order of
    /// [`FullFit::parameter_names`]).
    pub correlation: Option<DMatrix<f64>>,
    /// Per-channel fit quality.
    pub quality: Vec<ChannelQuality>,
    /// Accepted iterations (both stages).
    pub iterations: u64,
    /// Why the solver stopped.
    pub termination: Termination,
    /// Why a fit whose solver converged is still not a result (a model worse than the
    /// records' mean, parameters impossible for the records, no intervals); `None` for an
    /// accepted fit. See [`FullFit::accepted`].
    pub refusal: Option<Refusal>,
    /// The refusal its motor, intervals and effect estimates alone give, no channel's NRMSE
    /// looked at ([`crate::estimation::plausibility::judge`]): what still refuses a fit whose channel
    /// worse than a constant a caller has reason to pass over.
    pub(crate) refusal_beside_channels: Option<Refusal>,
    /// Final weighted cost `½ Σ r²`.
    pub cost: f64,
    /// Each record's initial state as fitted, in record order, for an output-error fit
    /// ([`crate::OutputError::initial_states`]); empty for the step fits (every
    /// step starts at rest).
    pub initial_states: Vec<FittedInitialState>,
    /// The solution in the fit's coordinates (`θ`, see `parameters.rs`).
    pub(crate) theta: Vec<f64>,
    /// Covariance of `θ` behind the intervals, if any.
    pub(crate) theta_covariance: Option<DMatrix<f64>>,
}

impl FullFit {
    /// Names of the fitted parameters in the order of [`FullFit::correlation`]: `R`, `L`, `k`,
    /// `f`, `J`, `Ts`, then `effect_name.key` of each effect estimate (e.g.
    /// `quadratic_drag.c`).
    pub fn parameter_names(&self) -> Vec<String> {
        names_of(&self.effects.fitted_slots())
    }

    /// SI units of the fitted parameters, in the order of [`FullFit::parameter_names`].
    pub fn parameter_units(&self) -> Vec<&'static str> {
        units_of(&self.effects.fitted_slots())
    }

    /// Whether the fit is a result: its solver converged and nothing refuses it.
    pub fn accepted(&self) -> bool {
        self.termination.converged() && self.refusal.is_none()
    }

    /// Why the fit is not a result, in words; `None` when [`FullFit::accepted`].
    pub fn failure(&self) -> Option<String> {
        if !self.termination.converged() {
            Some(format!(
                "the fit did not converge ({} after {} iterations; weighted cost {:.3e})",
                self.termination.text(),
                self.iterations,
                self.cost
            ))
        } else {
            self.refusal
                .as_ref()
                .map(|r| format!("the fit is refused: {r}"))
        }
    }
}
