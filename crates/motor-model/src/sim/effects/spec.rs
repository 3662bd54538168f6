//! The table of an effect parameter ([`ParamSpec`]: key, symbol, unit, default, domain, whether
//! a fit estimates it) and the domains a value is checked against ([`Domain`]).
use crate::error::ModelError;
use crate::params::MotorParams;

/// The set a parameter's value must lie in, with the transform to an unconstrained real that
/// an optimiser can move freely ([`ParamSpec::to_unconstrained`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Domain {
    /// Finite and `> 0`; unconstrained `θ = ln v`.
    Positive,
    /// Finite and `≥ 0`; unconstrained `θ = ln v` (a fit moves a size that is not zero: a
    /// start of exactly 0 is refused by [`ParamSpec::to_unconstrained`]).
    NonNegative,
    /// Any finite value; unconstrained `θ = v`.
    Finite,
    /// Finite in `(0, 1]`; unconstrained `θ = ln(v/(1 − v))` (logit; a start of exactly 1 is
    /// refused by [`ParamSpec::to_unconstrained`]).
    UnitInterval,
    /// A whole number from 1 to 65535 (a count, never fitted); unconstrained `θ = v`.
    WholeNumber,
    /// A torque \[N·m\] at least the motor's Coulomb torque Ts (checked when the simulator is
    /// built, `> 0` alone when parsed); unconstrained `θ = ln(v − Ts)`, so that a fit moving
    /// Ts keeps `v > Ts`: the value depends on `ln Ts` too, `∂v/∂(ln Ts) = Ts`.
    AboveCoulomb,
}

impl Domain {
    /// What the domain expects, in words.
    pub fn expected(self) -> &'static str {
        match self {
            Domain::Positive | Domain::AboveCoulomb => "a finite value greater than zero",
            Domain::NonNegative => "a finite value of zero or more",
            Domain::Finite => "a finite number",
            Domain::UnitInterval => "a finite value in (0, 1]",
            Domain::WholeNumber => "a whole number from 1 to 65535",
        }
    }

    /// Whether `value` lies in the domain (for [`Domain::AboveCoulomb`], the part that does
    /// not need the motor: `> 0`).
    pub fn contains(self, value: f64) -> bool {
        value.is_finite()
            && match self {
                Domain::Positive | Domain::AboveCoulomb => value > 0.0,
                Domain::NonNegative => value >= 0.0,
                Domain::Finite => true,
                Domain::UnitInterval => value > 0.0 && value <= 1.0,
                Domain::WholeNumber => {
                    value >= 1.0 && value.fract() == 0.0 && value <= f64::from(u16::MAX)
                }
            }
    }

    /// `value` if it lies in the domain, else the error naming the setting `name`.
    pub fn check(self, name: &str, value: f64) -> Result<f64, ModelError> {
        if self.contains(value) {
            Ok(value)
        } else {
            Err(ModelError::InvalidSetting {
                name: name.to_string(),
                value,
                expected: self.expected(),
            })
        }
    }
}

/// One parameter of an effect: how it is written, its unit, its default and its domain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Key in the command-line form `name:key=value`, e.g. `tst`.
    pub key: &'static str,
    /// Symbol in reports, e.g. `Tst`.
    pub symbol: &'static str,
    /// SI unit, e.g. `N·m` (`-` for a pure number).
    pub unit: &'static str,
    /// What it is, in words (for messages: "missing `tst=` (static friction torque in N·m)").
    pub description: &'static str,
    /// Value when the key is not given; `None` for a required key.
    pub default: Option<f64>,
    /// The values it may take.
    pub domain: Domain,
    /// Whether a fit estimates it; `false` for counts and material constants (a cogging
    /// period count, copper's temperature coefficient) and numerical regularisations (the
    /// brush knee).
    pub fitted: bool,
}

impl ParamSpec {
    /// The unconstrained coordinate of `value` ([`Domain`]); `motor` gives Ts for
    /// [`Domain::AboveCoulomb`]. Refuses a value outside the domain or on a boundary the
    /// transform cannot reach (0 for [`Domain::NonNegative`], 1 for [`Domain::UnitInterval`],
    /// Ts for [`Domain::AboveCoulomb`]).
    pub fn to_unconstrained(&self, value: f64, motor: &MotorParams) -> Result<f64, ModelError> {
        self.domain.check(self.key, value)?;
        let boundary = |expected| ModelError::InvalidSetting {
            name: self.key.to_string(),
            value,
            expected,
        };
        match self.domain {
            Domain::Positive => Ok(value.ln()),
            Domain::NonNegative if value > 0.0 => Ok(value.ln()),
            Domain::NonNegative => Err(boundary(
                "a size greater than zero to start a fit from (it is fitted as ln v)",
            )),
            Domain::Finite | Domain::WholeNumber => Ok(value),
            Domain::UnitInterval if value < 1.0 => Ok((value / (1.0 - value)).ln()),
            Domain::UnitInterval => Err(boundary(
                "a value below 1 to start a fit from (it is fitted as ln(v/(1 − v)))",
            )),
            Domain::AboveCoulomb if value > motor.ts_nm => Ok((value - motor.ts_nm).ln()),
            Domain::AboveCoulomb => Err(boundary(
                "a torque above the motor's Coulomb torque Ts to start a fit from (it is fitted as ln(v − Ts))",
            )),
        }
    }

    /// The value at unconstrained coordinate `theta` (inverse of
    /// [`ParamSpec::to_unconstrained`]); `motor` gives Ts for [`Domain::AboveCoulomb`].
    pub fn from_unconstrained(&self, theta: f64, motor: &MotorParams) -> f64 {
        match self.domain {
            Domain::Positive | Domain::NonNegative => theta.exp(),
            Domain::Finite | Domain::WholeNumber => theta,
            Domain::UnitInterval => 1.0 / (1.0 + (-theta).exp()),
            Domain::AboveCoulomb => motor.ts_nm + theta.exp(),
        }
    }

    /// `dv/dθ` at unconstrained coordinate `theta` (the delta method's factor from an
    /// interval on θ to one on the value). For [`Domain::AboveCoulomb`] the value also moves
    /// with `ln Ts`, by `Ts`.
    pub fn slope(&self, theta: f64) -> f64 {
        match self.domain {
            Domain::Positive | Domain::NonNegative | Domain::AboveCoulomb => theta.exp(),
            Domain::Finite | Domain::WholeNumber => 1.0,
            Domain::UnitInterval => {
                let v = 1.0 / (1.0 + (-theta).exp());
                v * (1.0 - v)
            }
        }
    }
}

/// `key=value` pairs of one `name:key=value,...` spec (each key once), consumed as they are
/// read so that unknown keys are reported. Errors are the reason in words; the caller names
/// the spec (an effect, a load, a controller).
pub(crate) struct SpecArgs<'a> {
    pairs: Vec<(&'a str, f64)>,
}

impl<'a> SpecArgs<'a> {
    /// The pairs of `body` (the text after `name:`).
    pub(crate) fn parse(body: &'a str) -> Result<Self, String> {
        let mut pairs = Vec::new();
        for item in body.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| format!("`{item}` is not of the form key=value"))?;
            let value: f64 = value.trim().parse().map_err(|_| {
                format!(
                    "value of `{}` is not a number: `{}`",
                    key.trim(),
                    value.trim()
                )
            })?;
            let key = key.trim();
            if pairs.iter().any(|(k, _)| *k == key) {
                return Err(format!("key `{key}` given twice; give each key once"));
            }
            pairs.push((key, value));
        }
        Ok(SpecArgs { pairs })
    }

    /// The values of `table`'s keys, defaults for those not given, each checked against its
    /// domain (`what` names the thing in messages: "this effect"); refuses a missing required key and any key the table does not have.
    pub(crate) fn values(mut self, table: &[ParamSpec], what: &str) -> Result<Vec<f64>, String> {
        // An unknown key first: `vb` misspelt is a typo to name, not a missing `vb=`.
        if let Some((key, _)) = self
            .pairs
            .iter()
            .find(|(k, _)| table.iter().all(|p| p.key != *k))
        {
            let known: Vec<&str> = table.iter().map(|p| p.key).collect();
            return Err(if known.is_empty() {
                format!("unknown key `{key}`; {what} takes no parameters")
            } else {
                format!("unknown key `{key}`; {what} takes {}", known.join(", "))
            });
        }
        let mut out = Vec::with_capacity(table.len());
        for p in table {
            let given = self
                .pairs
                .iter()
                .position(|(k, _)| *k == p.key)
                .map(|pos| self.pairs.remove(pos).1);
            let value = given
                .or(p.default)
                .ok_or_else(|| format!("missing `{}=` ({} in {})", p.key, p.description, p.unit))?;
            out.push(value);
        }
        Ok(out)
    }
}

/// Parses `name:key=value,...` against `kinds` (each name with its table): the kind's name and
/// its values in table order, each checked against its domain. `what` names the family in
/// messages (`load`, `controller`).
pub(crate) fn parse_kind<'k>(
    text: &str,
    what: &'static str,
    kinds: &[(&'k str, &'static [ParamSpec])],
) -> Result<(&'k str, Vec<f64>), ModelError> {
    let text = text.trim();
    let failed = |reason| ModelError::RigSpec {
        what,
        spec: text.to_string(),
        reason,
    };
    let (name, body) = text.split_once(':').unwrap_or((text, ""));
    let name = name.trim();
    let (kind, table) = kinds.iter().find(|(n, _)| *n == name).ok_or_else(|| {
        let known: Vec<&str> = kinds.iter().map(|(n, _)| *n).collect();
        failed(format!(
            "unknown {what} `{name}`; known: {}",
            known.join(", ")
        ))
    })?;
    let v = SpecArgs::parse(body)
        .and_then(|a| a.values(table, &format!("this {what}")))
        .map_err(failed)?;
    for (p, value) in table.iter().zip(&v) {
        p.domain
            .check(p.key, *value)
            .map_err(|e| failed(e.to_string()))?;
    }
    Ok((kind, v))
}
