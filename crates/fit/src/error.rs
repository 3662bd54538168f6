use std::fmt;

use motor_model::ModelError;

/// The series a [`FitError`] about a fit's start motor parameters names: a start no motor can
/// have, or one the records' sample rate cannot simulate (the diagnosis refits a candidate
/// from its unstepped start on such an error).
pub(crate) const START_SERIES: &str = "start parameters";

/// Every way an identification can refuse its input.
///
/// A fit that runs but does not converge is *not* an error: it is a result whose
/// [`crate::Termination`] says so.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum FitError {
    /// A data series is unusable (empty, too short, non-finite, constant…).
    BadData {
        /// Which series (e.g. "high-voltage current").
        series: String,
        /// What is wrong and what to do.
        reason: String,
    },
    /// A setting is out of range.
    InvalidSetting {
        /// Name of the setting.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is expected.
        expected: &'static str,
    },
    /// An intermediate quantity of the paper's method left its domain (e.g. σ ≤ ωa, so the
    /// fitted response is not overdamped and (35)–(37) do not apply).
    MethodDomain {
        /// The equation that failed.
        equation: &'static str,
        /// Why.
        reason: String,
    },
    /// The motor model refused a value (parameters, an input waveform) that the identification
    /// derived or was given.
    Model {
        /// What was being built (e.g. "start parameters", "voltage").
        context: &'static str,
        /// The model's own error.
        source: ModelError,
    },
    /// The optimiser itself failed (not a non-convergence: an internal error).
    Solver(String),
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitError::BadData { series, reason } => write!(f, "{series}: {reason}"),
            FitError::InvalidSetting {
                name,
                value,
                expected,
            } => write!(f, "{name} = {value}: expected {expected}"),
            FitError::MethodDomain { equation, reason } => {
                write!(f, "{equation} does not apply: {reason}")
            }
            FitError::Model { context, source } => write!(f, "{context}: {source}"),
            FitError::Solver(msg) => write!(f, "optimiser failed: {msg}"),
        }
    }
}

impl std::error::Error for FitError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            FitError::Model { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl FitError {
    /// A [`FitError::Model`] in `context`, for `map_err`.
    pub(crate) fn model(context: &'static str) -> impl Fn(ModelError) -> FitError {
        move |source| FitError::Model { context, source }
    }
}
