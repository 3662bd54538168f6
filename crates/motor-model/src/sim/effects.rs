//! Unmodelled effects of SPEC section 5, each a typed set of parameters with its equation.
//!
//! Effects are switched on in an [`Effects`] set handed to the [`crate::Simulator`]; the nominal
//! model of the paper is the empty set (the effect `none`). Each kind of effect has one table of
//! its parameters ([`EffectKind::params`]: key, symbol, unit, default, domain, whether a fit
//! estimates it); parsing (`name:key=value,...`, keys not given take the table's default),
//! printing, the list of names [`EFFECT_NAMES`] and the conversion to and from a vector of
//! values ([`Effect::to_values`], [`Effect::from_values`]) all read that table. The dynamics
//! each effect adds to the plant are in the simulator (`Dynamics`, one implementation per
//! effect).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::params::MotorParams;

/// Copper's temperature coefficient of resistance at 20 °C \[1/K\] (IEC 60028 annealed copper).
pub const COPPER_ALPHA_PER_K: f64 = 0.00393;

/// `stribeck_friction`: the dry friction falls from a static level `Tst > Ts` to `Ts` with speed,
/// `T_c(Ω) = Ts + (Tst − Ts) exp(−(Ω/Ωs)²)` \[N·m\]; breakaway needs `|k I| > Tst`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StribeckFriction {
    /// Static (breakaway) torque Tst \[N·m\], key `tst`; must exceed the motor's Ts.
    pub static_torque_nm: f64,
    /// Stribeck speed Ωs \[rad/s\], key `ws` (default 1).
    pub stribeck_speed_rad_s: f64,
}

/// `cogging_torque`: a load torque periodic in the angle, `T_cog(θ) = A sin(N θ + φ)` \[N·m\].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CoggingTorque {
    /// Amplitude A \[N·m\], key `amp`.
    pub amplitude_nm: f64,
    /// Periods per revolution N \[-\], key `n` (default 6).
    pub periods_per_rev: u32,
    /// Phase φ \[rad\], key `phase` (default 0).
    pub phase_rad: f64,
}

/// `current_sensor_lag`: the current channel sees `I_f` with `τf dI_f/dt = I − I_f` \[A\]
/// (first-order low-pass of time constant τf); the plant itself is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurrentSensorLag {
    /// Filter time constant τf \[s\], key `tau`.
    pub tau_f_s: f64,
}

/// `thermal_drift`: `R = R0 (1 + α ΔT)`, with the winding temperature rise driven by the copper
/// loss through a first-order thermal network, `Cth dΔT/dt = I² R − ΔT/Rth` \[K\].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalDrift {
    /// Thermal resistance winding→ambient Rth \[K/W\], key `rth`.
    pub thermal_resistance_k_per_w: f64,
    /// Thermal capacity of the winding Cth \[J/K\], key `cth`.
    pub thermal_capacity_j_per_k: f64,
    /// Temperature coefficient α \[1/K\], key `alpha` (default [`COPPER_ALPHA_PER_K`]).
    pub alpha_per_k: f64,
}

/// `quadratic_drag`: an extra load torque `c Ω|Ω|` \[N·m\] (fan, fluid).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct QuadraticDrag {
    /// Coefficient c \[N·m·s²/rad²\], key `c`.
    pub c_nms2_per_rad2: f64,
}

/// `brush_drop`: a voltage drop across the brushes, `Vb sign(I)` \[V\], regularised linearly
/// below a knee current (`Vb · clamp(I/I_knee, −1, 1)`: a brush film conducts ohmically at
/// low current, and a true sign function would chatter).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BrushDrop {
    /// Drop Vb at full conduction \[V\], key `vb`.
    pub drop_v: f64,
    /// Knee current I_knee \[A\] below which the drop is proportional, key `knee` (default 0.05).
    pub knee_current_a: f64,
}

/// `inductance_saturation`: the incremental inductance falls as `|I|` grows,
/// `L(I) = L0 (r + (1 − r)/(1 + (I/I_sat)²))` \[H\], from L0 at rest towards `r L0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct InductanceSaturation {
    /// Saturation current I_sat \[A\] where L has fallen half-way, key `isat`.
    pub saturation_current_a: f64,
    /// Ratio r = L(∞)/L0 \[-\], key `ratio` (default 0.5), in (0, 1].
    pub min_ratio: f64,
}

impl InductanceSaturation {
    /// The factor `L(I)/L0 = r + (1 − r)/(1 + (I/I_sat)²)` \[-\] at current `i` \[A\].
    pub fn factor(&self, i: f64) -> f64 {
        let u = i / self.saturation_current_a;
        self.min_ratio + (1.0 - self.min_ratio) / (1.0 + u * u)
    }
}

/// The set of effects switched on in a simulation; the empty set is the paper's model.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Effects {
    /// See [`StribeckFriction`].
    pub stribeck_friction: Option<StribeckFriction>,
    /// See [`CoggingTorque`].
    pub cogging_torque: Option<CoggingTorque>,
    /// See [`CurrentSensorLag`].
    pub current_sensor_lag: Option<CurrentSensorLag>,
    /// See [`ThermalDrift`].
    pub thermal_drift: Option<ThermalDrift>,
    /// See [`QuadraticDrag`].
    pub quadratic_drag: Option<QuadraticDrag>,
    /// See [`BrushDrop`].
    pub brush_drop: Option<BrushDrop>,
    /// See [`InductanceSaturation`].
    pub inductance_saturation: Option<InductanceSaturation>,
}

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

/// The kinds of effect of SPEC section 5 (the nominal model, `none`, is no kind: it is the
/// empty [`Effects`] set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    /// [`StribeckFriction`].
    StribeckFriction,
    /// [`CoggingTorque`].
    CoggingTorque,
    /// [`CurrentSensorLag`].
    CurrentSensorLag,
    /// [`ThermalDrift`].
    ThermalDrift,
    /// [`QuadraticDrag`].
    QuadraticDrag,
    /// [`BrushDrop`].
    BrushDrop,
    /// [`InductanceSaturation`].
    InductanceSaturation,
}

const STRIBECK_PARAMS: [ParamSpec; 2] = [
    ParamSpec {
        key: "tst",
        symbol: "Tst",
        unit: "N·m",
        description: "static friction torque",
        default: None,
        domain: Domain::AboveCoulomb,
        fitted: true,
    },
    ParamSpec {
        key: "ws",
        symbol: "Ωs",
        unit: "rad/s",
        description: "Stribeck speed",
        default: Some(1.0),
        domain: Domain::Positive,
        fitted: true,
    },
];

const COGGING_PARAMS: [ParamSpec; 3] = [
    ParamSpec {
        key: "amp",
        symbol: "A",
        unit: "N·m",
        description: "amplitude",
        default: None,
        domain: Domain::NonNegative,
        fitted: true,
    },
    ParamSpec {
        key: "n",
        symbol: "N",
        unit: "-",
        description: "periods per revolution",
        default: Some(6.0),
        domain: Domain::WholeNumber,
        fitted: false,
    },
    ParamSpec {
        key: "phase",
        symbol: "φ",
        unit: "rad",
        description: "phase",
        default: Some(0.0),
        domain: Domain::Finite,
        fitted: true,
    },
];

const SENSOR_LAG_PARAMS: [ParamSpec; 1] = [ParamSpec {
    key: "tau",
    symbol: "τf",
    unit: "s",
    description: "filter time constant",
    default: None,
    domain: Domain::Positive,
    fitted: true,
}];

const THERMAL_PARAMS: [ParamSpec; 3] = [
    ParamSpec {
        key: "rth",
        symbol: "Rth",
        unit: "K/W",
        description: "thermal resistance",
        default: None,
        domain: Domain::Positive,
        fitted: true,
    },
    ParamSpec {
        key: "cth",
        symbol: "Cth",
        unit: "J/K",
        description: "thermal capacity",
        default: None,
        domain: Domain::Positive,
        fitted: true,
    },
    ParamSpec {
        key: "alpha",
        symbol: "α",
        unit: "1/K",
        description: "temperature coefficient of resistance",
        default: Some(COPPER_ALPHA_PER_K),
        domain: Domain::NonNegative,
        fitted: false,
    },
];

const DRAG_PARAMS: [ParamSpec; 1] = [ParamSpec {
    key: "c",
    symbol: "c",
    unit: "N·m·s²/rad²",
    description: "coefficient",
    default: None,
    domain: Domain::NonNegative,
    fitted: true,
}];

const BRUSH_PARAMS: [ParamSpec; 2] = [
    ParamSpec {
        key: "vb",
        symbol: "Vb",
        unit: "V",
        description: "drop",
        default: None,
        domain: Domain::NonNegative,
        fitted: true,
    },
    ParamSpec {
        key: "knee",
        symbol: "I_knee",
        unit: "A",
        description: "knee current",
        default: Some(0.05),
        domain: Domain::Positive,
        fitted: false,
    },
];

const SATURATION_PARAMS: [ParamSpec; 2] = [
    ParamSpec {
        key: "isat",
        symbol: "I_sat",
        unit: "A",
        description: "saturation current",
        default: None,
        domain: Domain::Positive,
        fitted: true,
    },
    ParamSpec {
        key: "ratio",
        symbol: "r",
        unit: "-",
        description: "ratio L(∞)/L0",
        default: Some(0.5),
        domain: Domain::UnitInterval,
        fitted: true,
    },
];

impl EffectKind {
    /// Every kind, in the order of [`EFFECT_NAMES`].
    pub const ALL: [EffectKind; 7] = [
        EffectKind::StribeckFriction,
        EffectKind::CoggingTorque,
        EffectKind::CurrentSensorLag,
        EffectKind::ThermalDrift,
        EffectKind::QuadraticDrag,
        EffectKind::BrushDrop,
        EffectKind::InductanceSaturation,
    ];

    /// The SPEC section 5 name.
    pub const fn name(self) -> &'static str {
        match self {
            EffectKind::StribeckFriction => "stribeck_friction",
            EffectKind::CoggingTorque => "cogging_torque",
            EffectKind::CurrentSensorLag => "current_sensor_lag",
            EffectKind::ThermalDrift => "thermal_drift",
            EffectKind::QuadraticDrag => "quadratic_drag",
            EffectKind::BrushDrop => "brush_drop",
            EffectKind::InductanceSaturation => "inductance_saturation",
        }
    }

    /// The table of its parameters, in the order of [`Effect::to_values`].
    pub const fn params(self) -> &'static [ParamSpec] {
        match self {
            EffectKind::StribeckFriction => &STRIBECK_PARAMS,
            EffectKind::CoggingTorque => &COGGING_PARAMS,
            EffectKind::CurrentSensorLag => &SENSOR_LAG_PARAMS,
            EffectKind::ThermalDrift => &THERMAL_PARAMS,
            EffectKind::QuadraticDrag => &DRAG_PARAMS,
            EffectKind::BrushDrop => &BRUSH_PARAMS,
            EffectKind::InductanceSaturation => &SATURATION_PARAMS,
        }
    }

    /// The parameter of key `key`, if it has one.
    pub fn param(self, key: &str) -> Option<&'static ParamSpec> {
        self.params().iter().find(|p| p.key == key)
    }
}

impl fmt::Display for EffectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for EffectKind {
    type Err = ModelError;

    /// A kind by its SPEC section 5 name (`none` is not a kind).
    fn from_str(name: &str) -> Result<Self, ModelError> {
        EffectKind::ALL
            .into_iter()
            .find(|k| k.name() == name.trim())
            .ok_or_else(|| ModelError::EffectSpec {
                spec: name.to_string(),
                reason: format!(
                    "unknown effect `{}`; known: {}",
                    name.trim(),
                    EFFECT_NAMES.join(", ")
                ),
            })
    }
}

/// The names of SPEC section 5, in the order the diagnoser reports them: every
/// [`EffectKind::name`], then `none`.
pub const EFFECT_NAMES: [&str; 8] = {
    let mut out = ["none"; 8];
    let mut i = 0;
    while i < EffectKind::ALL.len() {
        out[i] = EffectKind::ALL[i].name();
        i += 1;
    }
    out
};

/// One effect with its parameters, as parsed from `name:key=value,...`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "name", rename_all = "snake_case")]
pub enum Effect {
    /// See [`StribeckFriction`].
    StribeckFriction(StribeckFriction),
    /// See [`CoggingTorque`].
    CoggingTorque(CoggingTorque),
    /// See [`CurrentSensorLag`].
    CurrentSensorLag(CurrentSensorLag),
    /// See [`ThermalDrift`].
    ThermalDrift(ThermalDrift),
    /// See [`QuadraticDrag`].
    QuadraticDrag(QuadraticDrag),
    /// See [`BrushDrop`].
    BrushDrop(BrushDrop),
    /// See [`InductanceSaturation`].
    InductanceSaturation(InductanceSaturation),
    /// The nominal model: no effect.
    None,
}

impl Effect {
    /// Its kind; `None` for the nominal model.
    pub fn kind(&self) -> Option<EffectKind> {
        Some(match self {
            Effect::StribeckFriction(_) => EffectKind::StribeckFriction,
            Effect::CoggingTorque(_) => EffectKind::CoggingTorque,
            Effect::CurrentSensorLag(_) => EffectKind::CurrentSensorLag,
            Effect::ThermalDrift(_) => EffectKind::ThermalDrift,
            Effect::QuadraticDrag(_) => EffectKind::QuadraticDrag,
            Effect::BrushDrop(_) => EffectKind::BrushDrop,
            Effect::InductanceSaturation(_) => EffectKind::InductanceSaturation,
            Effect::None => return None,
        })
    }

    /// The SPEC section 5 name of this effect.
    pub fn name(&self) -> &'static str {
        self.kind().map_or("none", EffectKind::name)
    }

    /// Its parameter values in the order of its table ([`EffectKind::params`]), SI units
    /// (a count as a whole `f64`); empty for `none`.
    pub fn to_values(&self) -> Vec<f64> {
        match *self {
            Effect::StribeckFriction(e) => vec![e.static_torque_nm, e.stribeck_speed_rad_s],
            Effect::CoggingTorque(e) => {
                vec![e.amplitude_nm, f64::from(e.periods_per_rev), e.phase_rad]
            }
            Effect::CurrentSensorLag(e) => vec![e.tau_f_s],
            Effect::ThermalDrift(e) => vec![
                e.thermal_resistance_k_per_w,
                e.thermal_capacity_j_per_k,
                e.alpha_per_k,
            ],
            Effect::QuadraticDrag(e) => vec![e.c_nms2_per_rad2],
            Effect::BrushDrop(e) => vec![e.drop_v, e.knee_current_a],
            Effect::InductanceSaturation(e) => vec![e.saturation_current_a, e.min_ratio],
            Effect::None => Vec::new(),
        }
    }

    /// The effect of `kind` with `values` in the order of its table, each checked against
    /// its domain (the error names the effect and the parameter, e.g.
    /// `current_sensor_lag tau = -1: expected a finite value greater than zero`).
    pub fn from_values(kind: EffectKind, values: &[f64]) -> Result<Effect, ModelError> {
        let table = kind.params();
        if values.len() != table.len() {
            return Err(ModelError::InvalidSetting {
                name: format!("{} parameter count", kind.name()),
                value: values.len() as f64,
                expected: "one value per parameter of the effect's table",
            });
        }
        let v = table
            .iter()
            .zip(values)
            .map(|(spec, &value)| {
                spec.domain
                    .check(&format!("{} {}", kind.name(), spec.key), value)
            })
            .collect::<Result<Vec<f64>, _>>()?;
        Ok(match kind {
            EffectKind::StribeckFriction => Effect::StribeckFriction(StribeckFriction {
                static_torque_nm: v[0],
                stribeck_speed_rad_s: v[1],
            }),
            EffectKind::CoggingTorque => Effect::CoggingTorque(CoggingTorque {
                amplitude_nm: v[0],
                // A whole number from 1 to 65535 (checked above).
                periods_per_rev: v[1] as u32,
                phase_rad: v[2],
            }),
            EffectKind::CurrentSensorLag => {
                Effect::CurrentSensorLag(CurrentSensorLag { tau_f_s: v[0] })
            }
            EffectKind::ThermalDrift => Effect::ThermalDrift(ThermalDrift {
                thermal_resistance_k_per_w: v[0],
                thermal_capacity_j_per_k: v[1],
                alpha_per_k: v[2],
            }),
            EffectKind::QuadraticDrag => Effect::QuadraticDrag(QuadraticDrag {
                c_nms2_per_rad2: v[0],
            }),
            EffectKind::BrushDrop => Effect::BrushDrop(BrushDrop {
                drop_v: v[0],
                knee_current_a: v[1],
            }),
            EffectKind::InductanceSaturation => {
                Effect::InductanceSaturation(InductanceSaturation {
                    saturation_current_a: v[0],
                    min_ratio: v[1],
                })
            }
        })
    }
}

impl fmt::Display for Effect {
    /// `name:key=value,...` in the order of the effect's table (parses back to the same
    /// effect); `none` for the nominal model.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(kind) = self.kind() else {
            return f.write_str("none");
        };
        write!(f, "{}", kind.name())?;
        for (j, (spec, value)) in kind.params().iter().zip(self.to_values()).enumerate() {
            let sep = if j == 0 { ':' } else { ',' };
            write!(f, "{sep}{}={value}", spec.key)?;
        }
        Ok(())
    }
}

/// `key=value` pairs of one effect spec (each key once), consumed as they are read so that
/// unknown keys are reported.
struct SpecArgs<'a> {
    spec: &'a str,
    pairs: Vec<(&'a str, f64)>,
}

impl<'a> SpecArgs<'a> {
    fn parse(spec: &'a str, body: &'a str) -> Result<Self, ModelError> {
        let mut pairs = Vec::new();
        for item in body.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item.split_once('=').ok_or_else(|| ModelError::EffectSpec {
                spec: spec.to_string(),
                reason: format!("`{item}` is not of the form key=value"),
            })?;
            let value: f64 = value.trim().parse().map_err(|_| ModelError::EffectSpec {
                spec: spec.to_string(),
                reason: format!(
                    "value of `{}` is not a number: `{}`",
                    key.trim(),
                    value.trim()
                ),
            })?;
            let key = key.trim();
            if pairs.iter().any(|(k, _)| *k == key) {
                return Err(ModelError::EffectSpec {
                    spec: spec.to_string(),
                    reason: format!("key `{key}` given twice; give each key once"),
                });
            }
            pairs.push((key, value));
        }
        Ok(SpecArgs { spec, pairs })
    }

    /// The values of `table`'s keys, defaults for those not given; refuses a missing required
    /// key and any key the table does not have.
    fn values(mut self, table: &[ParamSpec]) -> Result<Vec<f64>, ModelError> {
        // An unknown key first: `vb` misspelt is a typo to name, not a missing `vb=`.
        if let Some((key, _)) = self
            .pairs
            .iter()
            .find(|(k, _)| table.iter().all(|p| p.key != *k))
        {
            let known: Vec<&str> = table.iter().map(|p| p.key).collect();
            return Err(ModelError::EffectSpec {
                spec: self.spec.to_string(),
                reason: if known.is_empty() {
                    format!("unknown key `{key}`; this effect takes no parameters")
                } else {
                    format!(
                        "unknown key `{key}`; this effect takes {}",
                        known.join(", ")
                    )
                },
            });
        }
        let mut out = Vec::with_capacity(table.len());
        for p in table {
            let given = self
                .pairs
                .iter()
                .position(|(k, _)| *k == p.key)
                .map(|pos| self.pairs.remove(pos).1);
            let value = given.or(p.default).ok_or_else(|| ModelError::EffectSpec {
                spec: self.spec.to_string(),
                reason: format!("missing `{}=` ({} in {})", p.key, p.description, p.unit),
            })?;
            out.push(value);
        }
        Ok(out)
    }
}

impl FromStr for Effect {
    type Err = ModelError;

    /// Parses `name:key=value,...`, e.g. `cogging_torque:amp=0.01,n=6`, by the effect's table.
    fn from_str(spec: &str) -> Result<Self, ModelError> {
        let spec = spec.trim();
        let (name, body) = spec.split_once(':').unwrap_or((spec, ""));
        let args = SpecArgs::parse(spec, body)?;
        if name.trim() == "none" {
            args.values(&[])?;
            return Ok(Effect::None);
        }
        let kind: EffectKind = name.parse().map_err(|e| match e {
            ModelError::EffectSpec { reason, .. } => ModelError::EffectSpec {
                spec: spec.to_string(),
                reason,
            },
            other => other,
        })?;
        Effect::from_values(kind, &args.values(kind.params())?)
    }
}

impl Effects {
    /// The nominal model (effect `none`).
    pub fn none() -> Self {
        Effects::default()
    }

    /// Switches one effect on (replacing an earlier one of the same name).
    pub fn with(mut self, effect: Effect) -> Self {
        match effect {
            Effect::StribeckFriction(e) => self.stribeck_friction = Some(e),
            Effect::CoggingTorque(e) => self.cogging_torque = Some(e),
            Effect::CurrentSensorLag(e) => self.current_sensor_lag = Some(e),
            Effect::ThermalDrift(e) => self.thermal_drift = Some(e),
            Effect::QuadraticDrag(e) => self.quadratic_drag = Some(e),
            Effect::BrushDrop(e) => self.brush_drop = Some(e),
            Effect::InductanceSaturation(e) => self.inductance_saturation = Some(e),
            Effect::None => {}
        }
        self
    }

    /// Switches the effect of `kind` off.
    pub fn without(mut self, kind: EffectKind) -> Self {
        match kind {
            EffectKind::StribeckFriction => self.stribeck_friction = None,
            EffectKind::CoggingTorque => self.cogging_torque = None,
            EffectKind::CurrentSensorLag => self.current_sensor_lag = None,
            EffectKind::ThermalDrift => self.thermal_drift = None,
            EffectKind::QuadraticDrag => self.quadratic_drag = None,
            EffectKind::BrushDrop => self.brush_drop = None,
            EffectKind::InductanceSaturation => self.inductance_saturation = None,
        }
        self
    }

    /// The effect of `kind`, if it is on.
    pub fn get(&self, kind: EffectKind) -> Option<Effect> {
        match kind {
            EffectKind::StribeckFriction => self.stribeck_friction.map(Effect::StribeckFriction),
            EffectKind::CoggingTorque => self.cogging_torque.map(Effect::CoggingTorque),
            EffectKind::CurrentSensorLag => self.current_sensor_lag.map(Effect::CurrentSensorLag),
            EffectKind::ThermalDrift => self.thermal_drift.map(Effect::ThermalDrift),
            EffectKind::QuadraticDrag => self.quadratic_drag.map(Effect::QuadraticDrag),
            EffectKind::BrushDrop => self.brush_drop.map(Effect::BrushDrop),
            EffectKind::InductanceSaturation => {
                self.inductance_saturation.map(Effect::InductanceSaturation)
            }
        }
    }

    /// The effects switched on, in the order of [`EFFECT_NAMES`].
    pub fn list(&self) -> Vec<Effect> {
        EffectKind::ALL
            .into_iter()
            .filter_map(|k| self.get(k))
            .collect()
    }

    /// Whether no effect is on: the paper's model.
    pub fn is_nominal(&self) -> bool {
        self.list().is_empty()
    }

    /// The parameters a fit estimates ([`ParamSpec::fitted`]) of the effects that are on, in
    /// the order of [`EFFECT_NAMES`] and then of each effect's table: the order of
    /// [`Effects::fitted_values`] and [`Effects::with_fitted_values`].
    pub fn fitted_slots(&self) -> Vec<(EffectKind, &'static ParamSpec)> {
        self.list()
            .iter()
            .filter_map(Effect::kind)
            .flat_map(|k| k.params().iter().filter(|p| p.fitted).map(move |p| (k, p)))
            .collect()
    }

    /// The values of [`Effects::fitted_slots`], SI units.
    pub fn fitted_values(&self) -> Vec<f64> {
        self.list()
            .iter()
            .flat_map(|e| {
                let table = e.kind().map_or(&[][..], EffectKind::params);
                e.to_values()
                    .into_iter()
                    .zip(table)
                    .filter(|(_, p)| p.fitted)
                    .map(|(v, _)| v)
            })
            .collect()
    }

    /// The same effects with their fitted parameters set to `values` (in the order of
    /// [`Effects::fitted_slots`]; the others kept), each checked against its domain.
    pub fn with_fitted_values(&self, values: &[f64]) -> Result<Effects, ModelError> {
        let slots = self.fitted_slots().len();
        if values.len() != slots {
            return Err(ModelError::InvalidSetting {
                name: "fitted effect parameter count".into(),
                value: values.len() as f64,
                expected: "one value per fitted parameter of the effects that are on",
            });
        }
        let mut next = values.iter();
        let mut out = *self;
        for effect in self.list() {
            let Some(kind) = effect.kind() else { continue };
            let mut v = effect.to_values();
            for (slot, spec) in v.iter_mut().zip(kind.params()) {
                if spec.fitted {
                    if let Some(&x) = next.next() {
                        *slot = x;
                    }
                }
            }
            out = out.with(Effect::from_values(kind, &v)?);
        }
        Ok(out)
    }

    /// Checks every value of every effect that is on against its domain, and those that
    /// depend on the motor (Stribeck's Tst ≥ Ts) against `motor`.
    pub fn validate(&self, motor: &MotorParams) -> Result<(), ModelError> {
        for effect in self.list() {
            if let Some(kind) = effect.kind() {
                for (spec, value) in kind.params().iter().zip(effect.to_values()) {
                    let name = format!("{} {}", kind.name(), spec.key);
                    spec.domain.check(&name, value)?;
                    if spec.domain == Domain::AboveCoulomb && value < motor.ts_nm {
                        return Err(ModelError::InvalidSetting {
                            name,
                            value,
                            expected: "a static torque at least the motor's Coulomb torque Ts",
                        });
                    }
                }
            }
        }
        Ok(())
    }
}
