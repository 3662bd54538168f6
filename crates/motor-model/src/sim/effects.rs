//! Unmodelled effects of SPEC section 5, each a typed set of parameters with its equation.
//!
//! Effects are switched on in an [`Effects`] set handed to the [`crate::Simulator`]; the nominal
//! model of the paper is the empty set (the effect `none`). Each parses from the command-line
//! form `name:key=value,...`; keys not given take the documented default.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::{finite, non_negative, positive, ModelError};

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

/// The names of SPEC section 5, in the order the diagnoser reports them.
pub const EFFECT_NAMES: [&str; 8] = [
    "stribeck_friction",
    "cogging_torque",
    "current_sensor_lag",
    "thermal_drift",
    "quadratic_drag",
    "brush_drop",
    "inductance_saturation",
    "none",
];

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
    /// The SPEC section 5 name of this effect.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::StribeckFriction(_) => "stribeck_friction",
            Effect::CoggingTorque(_) => "cogging_torque",
            Effect::CurrentSensorLag(_) => "current_sensor_lag",
            Effect::ThermalDrift(_) => "thermal_drift",
            Effect::QuadraticDrag(_) => "quadratic_drag",
            Effect::BrushDrop(_) => "brush_drop",
            Effect::InductanceSaturation(_) => "inductance_saturation",
            Effect::None => "none",
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Effect::StribeckFriction(e) => write!(
                f,
                "stribeck_friction:tst={},ws={}",
                e.static_torque_nm, e.stribeck_speed_rad_s
            ),
            Effect::CoggingTorque(e) => write!(
                f,
                "cogging_torque:amp={},n={},phase={}",
                e.amplitude_nm, e.periods_per_rev, e.phase_rad
            ),
            Effect::CurrentSensorLag(e) => write!(f, "current_sensor_lag:tau={}", e.tau_f_s),
            Effect::ThermalDrift(e) => write!(
                f,
                "thermal_drift:rth={},cth={},alpha={}",
                e.thermal_resistance_k_per_w, e.thermal_capacity_j_per_k, e.alpha_per_k
            ),
            Effect::QuadraticDrag(e) => write!(f, "quadratic_drag:c={}", e.c_nms2_per_rad2),
            Effect::BrushDrop(e) => {
                write!(f, "brush_drop:vb={},knee={}", e.drop_v, e.knee_current_a)
            }
            Effect::InductanceSaturation(e) => write!(
                f,
                "inductance_saturation:isat={},ratio={}",
                e.saturation_current_a, e.min_ratio
            ),
            Effect::None => write!(f, "none"),
        }
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

    fn take(&mut self, key: &str) -> Option<f64> {
        let pos = self.pairs.iter().position(|(k, _)| *k == key)?;
        Some(self.pairs.remove(pos).1)
    }

    fn required(&mut self, key: &str, meaning: &str) -> Result<f64, ModelError> {
        self.take(key).ok_or_else(|| ModelError::EffectSpec {
            spec: self.spec.to_string(),
            reason: format!("missing `{key}=` ({meaning})"),
        })
    }

    fn finish(self, known: &[&str]) -> Result<(), ModelError> {
        match self.pairs.first() {
            None => Ok(()),
            Some((key, _)) => Err(ModelError::EffectSpec {
                spec: self.spec.to_string(),
                reason: format!(
                    "unknown key `{key}`; this effect takes {}",
                    known.join(", ")
                ),
            }),
        }
    }
}

impl FromStr for Effect {
    type Err = ModelError;

    /// Parses `name:key=value,...`, e.g. `cogging_torque:amp=0.01,n=6`.
    fn from_str(spec: &str) -> Result<Self, ModelError> {
        let spec = spec.trim();
        let (name, body) = spec.split_once(':').unwrap_or((spec, ""));
        let mut args = SpecArgs::parse(spec, body)?;
        let effect = match name.trim() {
            "none" => Effect::None,
            "stribeck_friction" => {
                let e = StribeckFriction {
                    static_torque_nm: positive(
                        "stribeck_friction tst",
                        args.required("tst", "static friction torque in N·m")?,
                    )?,
                    stribeck_speed_rad_s: positive(
                        "stribeck_friction ws",
                        args.take("ws").unwrap_or(1.0),
                    )?,
                };
                args.finish(&["tst", "ws"])?;
                Effect::StribeckFriction(e)
            }
            "cogging_torque" => {
                let amp = non_negative(
                    "cogging_torque amp",
                    args.required("amp", "amplitude in N·m")?,
                )?;
                let n = positive("cogging_torque n", args.take("n").unwrap_or(6.0))?;
                if n.fract() != 0.0 || n > f64::from(u16::MAX) {
                    return Err(ModelError::EffectSpec {
                        spec: spec.to_string(),
                        reason: format!("n = {n} must be a whole number of periods per revolution"),
                    });
                }
                let e = CoggingTorque {
                    amplitude_nm: amp,
                    periods_per_rev: n as u32,
                    phase_rad: finite("cogging_torque phase", args.take("phase").unwrap_or(0.0))?,
                };
                args.finish(&["amp", "n", "phase"])?;
                Effect::CoggingTorque(e)
            }
            "current_sensor_lag" => {
                let e = CurrentSensorLag {
                    tau_f_s: positive(
                        "current_sensor_lag tau",
                        args.required("tau", "filter time constant in s")?,
                    )?,
                };
                args.finish(&["tau"])?;
                Effect::CurrentSensorLag(e)
            }
            "thermal_drift" => {
                let e = ThermalDrift {
                    thermal_resistance_k_per_w: positive(
                        "thermal_drift rth",
                        args.required("rth", "thermal resistance in K/W")?,
                    )?,
                    thermal_capacity_j_per_k: positive(
                        "thermal_drift cth",
                        args.required("cth", "thermal capacity in J/K")?,
                    )?,
                    alpha_per_k: non_negative(
                        "thermal_drift alpha",
                        args.take("alpha").unwrap_or(COPPER_ALPHA_PER_K),
                    )?,
                };
                args.finish(&["rth", "cth", "alpha"])?;
                Effect::ThermalDrift(e)
            }
            "quadratic_drag" => {
                let e = QuadraticDrag {
                    c_nms2_per_rad2: non_negative(
                        "quadratic_drag c",
                        args.required("c", "coefficient in N·m·s²/rad²")?,
                    )?,
                };
                args.finish(&["c"])?;
                Effect::QuadraticDrag(e)
            }
            "brush_drop" => {
                let e = BrushDrop {
                    drop_v: non_negative("brush_drop vb", args.required("vb", "drop in V")?)?,
                    knee_current_a: positive("brush_drop knee", args.take("knee").unwrap_or(0.05))?,
                };
                args.finish(&["vb", "knee"])?;
                Effect::BrushDrop(e)
            }
            "inductance_saturation" => {
                let ratio = positive(
                    "inductance_saturation ratio",
                    args.take("ratio").unwrap_or(0.5),
                )?;
                if ratio > 1.0 {
                    return Err(ModelError::EffectSpec {
                        spec: spec.to_string(),
                        reason: format!("ratio = {ratio} must lie in (0, 1]"),
                    });
                }
                let e = InductanceSaturation {
                    saturation_current_a: positive(
                        "inductance_saturation isat",
                        args.required("isat", "saturation current in A")?,
                    )?,
                    min_ratio: ratio,
                };
                args.finish(&["isat", "ratio"])?;
                Effect::InductanceSaturation(e)
            }
            other => {
                return Err(ModelError::EffectSpec {
                    spec: spec.to_string(),
                    reason: format!(
                        "unknown effect `{other}`; known: {}",
                        EFFECT_NAMES.join(", ")
                    ),
                })
            }
        };
        Ok(effect)
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

    /// The effects switched on, in the order of [`EFFECT_NAMES`].
    pub fn list(&self) -> Vec<Effect> {
        let mut out = Vec::new();
        out.extend(self.stribeck_friction.map(Effect::StribeckFriction));
        out.extend(self.cogging_torque.map(Effect::CoggingTorque));
        out.extend(self.current_sensor_lag.map(Effect::CurrentSensorLag));
        out.extend(self.thermal_drift.map(Effect::ThermalDrift));
        out.extend(self.quadratic_drag.map(Effect::QuadraticDrag));
        out.extend(self.brush_drop.map(Effect::BrushDrop));
        out.extend(self.inductance_saturation.map(Effect::InductanceSaturation));
        out
    }

    /// Whether no effect is on: the paper's model.
    pub fn is_nominal(&self) -> bool {
        self.list().is_empty()
    }
}
