//! Unmodelled effects of SPEC section 5, each a typed set of parameters with its equation.
//!
//! Effects are switched on in an [`Effects`] set handed to the [`crate::Simulator`]; the nominal
//! model of the paper is the empty set (the effect `none`). Each kind of effect has one table of
//! its parameters ([`EffectKind::params`]: key, symbol, unit, default, domain, whether a fit
//! estimates it); parsing (`name:key=value,...`, keys not given take the table's default),
//! printing, the list of names [`EFFECT_NAMES`] and the conversion to and from a vector of
//! values ([`Effect::to_values`], [`Effect::from_values`]) all read that table.
//!
//! Each effect is one module here: its parameters as a typed struct, its table, its values in
//! the table's order, and what it adds to the plant's equations (its `Dynamics`: terms, own
//! states, step limit). This module is the registry that names them all: the kinds, the
//! [`Effect`] that holds any one of them, the [`Effects`] set, and the parsing and printing
//! of `name:key=value,...`. Adding an effect is one module and its lines here.

mod brush;
mod cogging;
mod drag;
mod saturation;
mod sensor_lag;
mod spec;
mod stribeck;
mod thermal;

pub use brush::BrushDrop;
pub use cogging::CoggingTorque;
pub use drag::QuadraticDrag;
pub use saturation::InductanceSaturation;
pub use sensor_lag::CurrentSensorLag;
pub(crate) use spec::{parse_kind, SpecArgs};
pub use spec::{Domain, ParamSpec};
pub use stribeck::StribeckFriction;
pub use thermal::{ThermalDrift, COPPER_ALPHA_PER_K};

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::params::MotorParams;
use crate::sim::dynamics::Dynamics;

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
            EffectKind::StribeckFriction => &stribeck::STRIBECK_PARAMS,
            EffectKind::CoggingTorque => &cogging::COGGING_PARAMS,
            EffectKind::CurrentSensorLag => &sensor_lag::SENSOR_LAG_PARAMS,
            EffectKind::ThermalDrift => &thermal::THERMAL_PARAMS,
            EffectKind::QuadraticDrag => &drag::DRAG_PARAMS,
            EffectKind::BrushDrop => &brush::BRUSH_PARAMS,
            EffectKind::InductanceSaturation => &saturation::SATURATION_PARAMS,
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
            Effect::StribeckFriction(e) => e.to_values(),
            Effect::CoggingTorque(e) => e.to_values(),
            Effect::CurrentSensorLag(e) => e.to_values(),
            Effect::ThermalDrift(e) => e.to_values(),
            Effect::QuadraticDrag(e) => e.to_values(),
            Effect::BrushDrop(e) => e.to_values(),
            Effect::InductanceSaturation(e) => e.to_values(),
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
            EffectKind::StribeckFriction => {
                Effect::StribeckFriction(StribeckFriction::from_checked(&v))
            }
            EffectKind::CoggingTorque => Effect::CoggingTorque(CoggingTorque::from_checked(&v)),
            EffectKind::CurrentSensorLag => {
                Effect::CurrentSensorLag(CurrentSensorLag::from_checked(&v))
            }
            EffectKind::ThermalDrift => Effect::ThermalDrift(ThermalDrift::from_checked(&v)),
            EffectKind::QuadraticDrag => Effect::QuadraticDrag(QuadraticDrag::from_checked(&v)),
            EffectKind::BrushDrop => Effect::BrushDrop(BrushDrop::from_checked(&v)),
            EffectKind::InductanceSaturation => {
                Effect::InductanceSaturation(InductanceSaturation::from_checked(&v))
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

impl FromStr for Effect {
    type Err = ModelError;

    /// Parses `name:key=value,...`, e.g. `cogging_torque:amp=0.01,n=6`, by the effect's table.
    fn from_str(spec: &str) -> Result<Self, ModelError> {
        let spec = spec.trim();
        let (name, body) = spec.split_once(':').unwrap_or((spec, ""));
        let failed = |reason| ModelError::EffectSpec {
            spec: spec.to_string(),
            reason,
        };
        let args = SpecArgs::parse(body).map_err(failed)?;
        if name.trim() == "none" {
            args.values(&[], "this effect").map_err(failed)?;
            return Ok(Effect::None);
        }
        let kind: EffectKind = name.parse().map_err(|e| match e {
            ModelError::EffectSpec { reason, .. } => ModelError::EffectSpec {
                spec: spec.to_string(),
                reason,
            },
            other => other,
        })?;
        Effect::from_values(
            kind,
            &args.values(kind.params(), "this effect").map_err(failed)?,
        )
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

/// The nominal model adds nothing.
pub(crate) struct Nominal;

impl Dynamics for Nominal {}

/// Calls `$call` on the effect inside `$effect` (static dispatch, so that the simulator's inner
/// loop inlines each effect's equations).
macro_rules! on_effect {
    ($effect:expr, $e:ident => $call:expr) => {
        match $effect {
            Effect::StribeckFriction($e) => $call,
            Effect::CoggingTorque($e) => $call,
            Effect::CurrentSensorLag($e) => $call,
            Effect::ThermalDrift($e) => $call,
            Effect::QuadraticDrag($e) => $call,
            Effect::BrushDrop($e) => $call,
            Effect::InductanceSaturation($e) => $call,
            Effect::None => {
                let $e = &Nominal;
                $call
            }
        }
    };
}

/// An effect's part is that of the effect it holds.
impl Dynamics for Effect {
    fn states(&self) -> usize {
        on_effect!(self, e => e.states())
    }
    fn resistance_factor(&self, own: &[f64]) -> f64 {
        on_effect!(self, e => e.resistance_factor(own))
    }
    fn inductance_factor(&self, i: f64) -> f64 {
        on_effect!(self, e => e.inductance_factor(i))
    }
    fn min_inductance_factor(&self) -> f64 {
        on_effect!(self, e => e.min_inductance_factor())
    }
    fn voltage_drop(&self, i: f64) -> f64 {
        on_effect!(self, e => e.voltage_drop(i))
    }
    fn incremental_resistance(&self) -> f64 {
        on_effect!(self, e => e.incremental_resistance())
    }
    fn load_torque(&self, w: f64, theta: f64) -> f64 {
        on_effect!(self, e => e.load_torque(w, theta))
    }
    fn dry_friction(&self, ts: f64, w: f64) -> Option<f64> {
        on_effect!(self, e => e.dry_friction(ts, w))
    }
    fn derivative(&self, i: f64, r: f64, own: &[f64], d_own: &mut [f64]) {
        on_effect!(self, e => e.derivative(i, r, own, d_own))
    }
    fn sensor_state(&self) -> Option<usize> {
        on_effect!(self, e => e.sensor_state())
    }
    fn sensor_time_constant(&self) -> Option<f64> {
        on_effect!(self, e => e.sensor_time_constant())
    }
    fn own_rate(&self, p: &MotorParams) -> f64 {
        on_effect!(self, e => e.own_rate(p))
    }
    fn step_limit(&self, p: &MotorParams, speed: f64, tolerance: Option<f64>) -> f64 {
        on_effect!(self, e => e.step_limit(p, speed, tolerance))
    }
}
