//! The parameter vector of a fit of the motor and a set of effects.
//!
//! `θ = [ln R, ln L, ln k, ln f, ln J, ln Ts, θ_e…]`: the motor's six parameters as logarithms
//! (all stay positive), then the fitted parameters of the effects that are on
//! ([`Effects::fitted_slots`]) in each parameter's unconstrained coordinate
//! ([`ParamSpec::to_unconstrained`]: `ln v` for a positive or non-negative size, the logit for a
//! ratio in (0, 1], `v` itself for a phase). Stribeck's static torque is carried as its excess
//! over the motor's Coulomb torque, `θ = ln(Tst − Ts)`, so that every θ gives `Tst > Ts` however
//! the fit moves Ts. Intervals go back to SI units by the delta method through these transforms
//! ([`Parameters::value_jacobian`]).

use motor_model::{Domain, EffectKind, Effects, MotorParams, ParamSpec};
use nalgebra::DMatrix;

use crate::error::{FitError, START_SERIES};
use crate::estimation::intervals::MotorIntervals;
use crate::estimation::records::{PARAM_NAMES, PARAM_UNITS};
use crate::estimation::stats::from_covariance;

/// Number of motor parameters at the head of θ.
pub(crate) const MOTOR: usize = 6;
/// Index of `ln Ts` in θ.
const LN_TS: usize = 5;

/// One fitted effect parameter in SI units, with its uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectEstimate {
    /// The effect it belongs to.
    pub effect: EffectKind,
    /// Its key in the effect's table ([`ParamSpec::key`]), e.g. `tst`.
    pub key: &'static str,
    /// Its symbol, e.g. `Tst`.
    pub symbol: &'static str,
    /// Its SI unit, e.g. `N·m`.
    pub unit: &'static str,
    /// The fitted value (unit above).
    pub value: f64,
    /// Standard error (unit above), by the delta method through the parameter's transform;
    /// `None` when the fit has no intervals.
    pub std_error: Option<f64>,
    /// 95 % interval `[lo, hi]` (unit above), `value ± t σ`; `None` when the fit has no
    /// intervals.
    pub ci95: Option<[f64; 2]>,
}

/// How θ maps to a motor and its effects (module docs).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Parameters {
    /// The effects fitted, with the values of their parameters that are not fitted.
    effects: Effects,
    slots: Vec<(EffectKind, &'static ParamSpec)>,
    /// Number of free initial-state coordinates at the end of θ (not motor nor effect).
    free_states: usize,
}

/// Intervals of every parameter in SI units, in θ order.
pub(crate) struct Intervals {
    pub std_error: Vec<f64>,
    pub ci95: Vec<[f64; 2]>,
    pub correlation: DMatrix<f64>,
}

impl Parameters {
    /// The motor alone: θ of six logarithms.
    pub fn nominal() -> Self {
        Parameters::new(&Effects::none())
    }

    /// The motor and the fitted parameters of `effects`.
    pub fn new(effects: &Effects) -> Self {
        Parameters {
            effects: *effects,
            slots: effects.fitted_slots(),
            free_states: 0,
        }
    }

    /// The same parameters with `n` free initial-state coordinates appended to θ.
    pub fn with_free_states(mut self, n: usize) -> Self {
        self.free_states = n;
        self
    }

    /// Length of θ.
    pub fn len(&self) -> usize {
        self.named() + self.free_states
    }

    /// Number of named parameters (the motor's and the effects'), at the head of θ.
    pub fn named(&self) -> usize {
        MOTOR + self.slots.len()
    }

    /// The effect each fitted effect parameter belongs to, in θ order after the motor's six.
    pub fn slot_kinds(&self) -> impl Iterator<Item = EffectKind> + '_ {
        self.slots.iter().map(|(k, _)| *k)
    }

    /// θ of `motor` with the fitted values of `effects` (the same effects as these
    /// parameters'), refusing values the transforms cannot carry.
    pub fn encode(&self, motor: &MotorParams, effects: &Effects) -> Result<Vec<f64>, FitError> {
        motor.validate().map_err(FitError::model(START_SERIES))?;
        if motor.ts_nm <= 0.0 {
            return Err(FitError::BadData {
                series: START_SERIES.into(),
                reason: "Ts = 0: the fit works on ln Ts and needs a positive start".into(),
            });
        }
        effects
            .validate(motor)
            .map_err(FitError::model("start effects"))?;
        let values = effects.fitted_values();
        if effects.fitted_slots() != self.slots {
            return Err(FitError::BadData {
                series: "start effects".into(),
                reason: "not the effects of the fit".into(),
            });
        }
        let mut theta: Vec<f64> = motor.values().iter().map(|v| v.ln()).collect();
        for ((kind, spec), v) in self.slots.iter().zip(values) {
            let t = spec
                .to_unconstrained(v, motor)
                .map_err(|e| FitError::BadData {
                    series: format!("start of {} {}", kind.name(), spec.key),
                    reason: e.to_string(),
                })?;
            theta.push(t);
        }
        Ok(theta)
    }

    /// The motor and effects at θ, if θ is representable and inside every domain.
    pub fn decode(&self, theta: &[f64]) -> Option<(MotorParams, Effects)> {
        if theta.len() != self.len() || theta.iter().any(|t| !t.is_finite()) {
            return None;
        }
        if theta[..MOTOR].iter().any(|t| t.abs() >= 700.0) {
            return None;
        }
        let motor = MotorParams::from_values(std::array::from_fn(|i| theta[i].exp())).ok()?;
        if self.slots.is_empty() {
            return Some((motor, self.effects));
        }
        let values: Vec<f64> = self
            .slots
            .iter()
            .zip(&theta[MOTOR..self.named()])
            .map(|((_, spec), &t)| spec.from_unconstrained(t, &motor))
            .collect();
        // A coordinate whose value rounds onto a boundary its transform cannot reach (a ratio
        // of exactly 1 from a logit past 37, a size of 0 from ln v below −745) is not
        // representable: it could not be encoded again to predict or linearise the fitted
        // model, so a fit must not step there.
        if self
            .slots
            .iter()
            .zip(&values)
            .any(|((_, spec), &v)| spec.to_unconstrained(v, &motor).is_err())
        {
            return None;
        }
        let effects = self.effects.with_fitted_values(&values).ok()?;
        effects.validate(&motor).ok()?;
        Some((motor, effects))
    }

    /// The named values in SI units at θ, in θ order (the free initial states left out).
    pub fn values(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let (motor, effects) = self.decode(theta)?;
        let mut v = motor.values().to_vec();
        v.extend(effects.fitted_values());
        Some(v)
    }

    /// `∂values/∂θ` at θ (named values by the named head of θ): the diagonal `dv/dθ` of each
    /// transform, and for a parameter carried as an excess over Ts ([`Domain::AboveCoulomb`])
    /// `∂v/∂(ln Ts) = Ts`.
    pub fn value_jacobian(&self, theta: &[f64]) -> Option<DMatrix<f64>> {
        let v = self.values(theta)?;
        let p = self.named();
        let mut d = DMatrix::zeros(p, p);
        for i in 0..MOTOR {
            d[(i, i)] = v[i];
        }
        for (j, (_, spec)) in self.slots.iter().enumerate() {
            let i = MOTOR + j;
            d[(i, i)] = spec.slope(theta[i]);
            if spec.domain == Domain::AboveCoulomb {
                d[(i, LN_TS)] = v[LN_TS];
            }
        }
        Some(d)
    }

    /// Standard errors, Student-t 95 % intervals (`dof` degrees of freedom) and correlations
    /// in SI units of the named parameters from the covariance of θ, by the delta method
    /// `D Cov(θ) Dᵀ` on its named block (the marginal covariance: free initial states profiled
    /// out).
    pub fn intervals(
        &self,
        theta: &[f64],
        cov_theta: &DMatrix<f64>,
        dof: usize,
    ) -> Option<Intervals> {
        let v = self.values(theta)?;
        let d = self.value_jacobian(theta)?;
        let q = self.named();
        if cov_theta.nrows() < q || cov_theta.ncols() < q {
            return None;
        }
        let cov = &d * cov_theta.view((0, 0), (q, q)) * d.transpose();
        // Standard errors and correlations as every other fit here reports them.
        let u = from_covariance(cov, dof.max(1), f64::NAN)?;
        let ci95 = v
            .iter()
            .zip(&u.ci95_half_width)
            .map(|(x, half)| [x - half, x + half])
            .collect();
        Some(Intervals {
            std_error: u.std_error,
            ci95,
            correlation: u.correlation,
        })
    }

    /// The effect estimates at θ with their intervals, if any.
    pub fn estimates(&self, theta: &[f64], intervals: Option<&Intervals>) -> Vec<EffectEstimate> {
        let values = self.values(theta).unwrap_or_default();
        self.slots
            .iter()
            .enumerate()
            .map(|(j, (kind, spec))| EffectEstimate {
                effect: *kind,
                key: spec.key,
                symbol: spec.symbol,
                unit: spec.unit,
                value: values.get(MOTOR + j).copied().unwrap_or(f64::NAN),
                std_error: intervals.map(|iv| iv.std_error[MOTOR + j]),
                ci95: intervals.map(|iv| iv.ci95[MOTOR + j]),
            })
            .collect()
    }
}

/// Names of a fit's parameters: the motor's, then `effect_name.key` of each fitted slot.
pub(crate) fn names_of(slots: &[(EffectKind, &'static ParamSpec)]) -> Vec<String> {
    PARAM_NAMES
        .iter()
        .map(|s| s.to_string())
        .chain(slots.iter().map(|(k, p)| format!("{}.{}", k.name(), p.key)))
        .collect()
}

/// Units of a fit's parameters in the order of [`names_of`].
pub(crate) fn units_of(slots: &[(EffectKind, &'static ParamSpec)]) -> Vec<&'static str> {
    PARAM_UNITS
        .iter()
        .copied()
        .chain(slots.iter().map(|(_, p)| p.unit))
        .collect()
}

/// A parameter as identified: name, unit, value and 95 % interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParameterEstimate {
    /// Name as in [`PARAM_NAMES`] (`R`, `L`, `k`, `f`, `J`, `Ts`), or [`crate::FEEDFORWARD_NAMES`].
    pub name: &'static str,
    /// SI unit (as in [`PARAM_UNITS`] for the six motor parameters).
    pub unit: &'static str,
    /// The value (SI units).
    pub value: f64,
    /// The 95 % interval `[lo, hi]` (SI units), if the method gives one.
    pub ci95: Option<[f64; 2]>,
}

/// The six parameters of `params` with names, units and, if given, the 95 % intervals `ci95`
/// (in the order of [`PARAM_NAMES`]).
pub fn parameter_estimates(
    params: &MotorParams,
    ci95: Option<&MotorIntervals>,
) -> Vec<ParameterEstimate> {
    PARAM_NAMES
        .into_iter()
        .zip(PARAM_UNITS)
        .zip(params.values())
        .map(|((name, unit), value)| ParameterEstimate {
            name,
            unit,
            value,
            ci95: ci95.and_then(|c| c.get(name)),
        })
        .collect()
}
