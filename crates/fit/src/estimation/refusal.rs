//! Why a fit whose solver converged is still not a result ([`Refusal`]); the rules that
//! decide it are in [`crate::estimation::plausibility`].

use std::fmt;

use crate::estimation::records::Channel;

/// Why a converged fit is still not a result.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Refusal {
    /// A channel the model explains less well than the channel's own mean does: NRMSE above 1
    /// (SPEC section 7), a negative fit percentage.
    WorseThanConstant {
        /// Index of the record.
        test: usize,
        /// Which channel.
        channel: Channel,
        /// Its NRMSE `‖y − ŷ‖/‖y − ȳ‖`.
        nrmse: f64,
    },
    /// Parameters no motor could have and still produce these records.
    Implausible {
        /// What is impossible, with the values.
        reason: String,
    },
    /// The parameter covariance could not be computed (a singular Jacobian: some parameter
    /// does not change the model's output), so there are no intervals.
    NoIntervals,
    /// No intervals, because a friction parameter went to a vanishing share of its scale
    /// (Ts of the largest motor torque k·|I|, f of the electrical damping k²/R), where it no
    /// longer acts on the records: the fit ran into a wrong minimum or the records show no
    /// such friction.
    Vanished {
        /// `f` or `Ts`.
        parameter: &'static str,
        /// Its value (SI unit).
        value: f64,
        /// Its SI unit.
        unit: &'static str,
        /// The value over its scale.
        share: f64,
    },
    /// A parameter's 95 % interval is wider than the value itself (it reaches zero): the
    /// records do not determine it, and a linearised interval that wide is no longer honest.
    Undetermined {
        /// The parameter (`R`, `L`, `k`, `f`, `J`, `Ts`, or an effect parameter's symbol,
        /// e.g. `τf`).
        parameter: &'static str,
        /// Half-width of its interval over its value.
        relative_half_width: f64,
    },
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Refusal::WorseThanConstant {
                test,
                channel,
                nrmse,
            } => write!(
                f,
                "the model explains the {} of record {} worse than its mean does (NRMSE {nrmse:.3} > 1): \
                 the fit found a wrong minimum (a start nearer the truth may help: identify --record … --start FILE.json) or the records do not fit the model",
                channel.name(),
                test + 1
            ),
            Refusal::Implausible { reason } => write!(f, "physically impossible for these records: {reason}"),
            Refusal::NoIntervals => f.write_str(
                "the 95 % intervals cannot be computed (singular Jacobian: some parameter does not act on the records)",
            ),
            Refusal::Vanished {
                parameter,
                value,
                unit,
                share,
            } => write!(
                f,
                "{parameter} went to {value:.3e} {unit} ({share:.1e} of its scale), where it no longer acts on the \
                 records, so no interval can be computed: the fit found a wrong minimum (a start nearer the truth \
                 may help: identify --record … --start FILE.json), or the records show no such friction",
            ),
            Refusal::Undetermined {
                parameter,
                relative_half_width,
            } => write!(
                f,
                "{parameter} is not determined by these records: its 95 % interval spans ±{:.0} % of the value \
                 (record longer, or with more excitation)",
                100.0 * relative_half_width
            ),
        }
    }
}
