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
