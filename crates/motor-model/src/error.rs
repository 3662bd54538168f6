use std::fmt;

/// Every way the model can refuse its input.
///
/// Messages name the offending quantity and value and say what to fix.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum ModelError {
    /// A motor parameter is not finite or not strictly positive.
    InvalidParameter {
        /// Parameter name as in the paper (`R`, `L`, `k`, `f`, `J`, `Ts`).
        name: &'static str,
        /// The value given.
        value: f64,
        /// Why it is refused.
        reason: &'static str,
    },
    /// A setting (voltage, duration, rate, effect parameter, …) is out of range.
    InvalidSetting {
        /// Name of the setting.
        name: String,
        /// The value given.
        value: f64,
        /// What is expected instead.
        expected: &'static str,
    },
    /// An effect specification could not be parsed (`name:key=value,...`).
    EffectSpec {
        /// The text given.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A load, controller or model file could not be read (`name:key=value,...`).
    RigSpec {
        /// What it is (`load`, `controller`, `model file`).
        what: &'static str,
        /// The text given.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A simulation would take more RK4 steps than its bound
    /// ([`crate::MAX_RK4_STEPS_PER_SAMPLE`] a sample on average, 1e9 at most): a time constant
    /// of the model (a brush drop's knee, a deep saturation) or an effect's step limit (a fast
    /// cogging) far below the sample period.
    TooStiff {
        /// The bound \[RK4 steps\].
        budget: f64,
        /// Where the bound ran out \[s\] (0: refused before the start).
        at_s: f64,
        /// The longest step the model's fastest time constant allows \[s\] (1/40 of it).
        max_step_s: f64,
    },
    /// The simulated state left the finite numbers: the model's parameters make it blow up
    /// (an effect far outside a motor's range), or a step too long for its dynamics.
    Diverged {
        /// The first sample where it was found \[s\].
        at_s: f64,
    },
    /// An analytic formula was asked for outside its domain (wrong damping regime, no breakaway).
    OutOfDomain {
        /// Which formula.
        formula: &'static str,
        /// Why it does not apply.
        reason: String,
    },
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelError::InvalidParameter {
                name,
                value,
                reason,
            } => write!(f, "motor parameter {name} = {value}: {reason}"),
            ModelError::InvalidSetting {
                name,
                value,
                expected,
            } => write!(f, "{name} = {value}: expected {expected}"),
            ModelError::EffectSpec { spec, reason } => {
                write!(f, "effect `{spec}`: {reason}")
            }
            ModelError::RigSpec { what, spec, reason } => {
                write!(f, "{what} `{spec}`: {reason}")
            }
            ModelError::TooStiff {
                budget,
                at_s,
                max_step_s,
            } => {
                write!(
                    f,
                    "the simulation would take more than {budget:.1e} RK4 steps (its step is at most {max_step_s:.3e} s, 1/40 of the model's fastest time constant"
                )?;
                if *at_s > 0.0 {
                    write!(f, ", or shorter where an effect needs; it ran out at t = {at_s:.6} s")?;
                }
                write!(
                    f,
                    "): a time constant this far below the sample period (a brush drop's knee this sharp, an inductance saturating this deep, a cogging this fast) is out of the simulator's reach — make the effect smoother or sample faster"
                )
            }
            ModelError::Diverged { at_s } => write!(
                f,
                "the simulation diverged (a value no longer finite at t = {at_s:.6} s): the parameters make the model blow up — an effect far outside a motor's range"
            ),
            ModelError::OutOfDomain { formula, reason } => {
                write!(f, "{formula} does not apply: {reason}")
            }
        }
    }
}

impl std::error::Error for ModelError {}

/// Checks that a setting is finite and strictly positive.
pub(crate) fn positive(name: &str, value: f64) -> Result<f64, ModelError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(ModelError::InvalidSetting {
            name: name.to_string(),
            value,
            expected: "a finite value greater than zero",
        })
    }
}

/// Checks that a setting is finite and not negative.
pub(crate) fn non_negative(name: &str, value: f64) -> Result<f64, ModelError> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(ModelError::InvalidSetting {
            name: name.to_string(),
            value,
            expected: "a finite value of zero or more",
        })
    }
}

/// Checks that a setting is finite.
pub(crate) fn finite(name: &str, value: f64) -> Result<f64, ModelError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ModelError::InvalidSetting {
            name: name.to_string(),
            value,
            expected: "a finite number",
        })
    }
}
