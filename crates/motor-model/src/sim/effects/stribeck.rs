//! `stribeck_friction`: the dry friction falling from a static level to Ts with speed.

use serde::{Deserialize, Serialize};

use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

/// `stribeck_friction`: the dry friction falls from a static level `Tst > Ts` to `Ts` with speed,
/// `T_c(Ω) = Ts + (Tst − Ts) exp(−(Ω/Ωs)²)` \[N·m\]; breakaway needs `|k I| > Tst`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StribeckFriction {
    /// Static (breakaway) torque Tst \[N·m\], key `tst`; must exceed the motor's Ts.
    pub static_torque_nm: f64,
    /// Stribeck speed Ωs \[rad/s\], key `ws` (default 1).
    pub stribeck_speed_rad_s: f64,
}

/// The table of its parameters, in the order of [`StribeckFriction::to_values`].
pub(crate) const STRIBECK_PARAMS: [ParamSpec; 2] = [
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

impl StribeckFriction {
    /// Its parameter values in the order of its table ([`STRIBECK_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![self.static_torque_nm, self.stribeck_speed_rad_s]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        StribeckFriction {
            static_torque_nm: v[0],
            stribeck_speed_rad_s: v[1],
        }
    }
}

impl Dynamics for StribeckFriction {
    /// `T_c(Ω) = Ts + (Tst − Ts) exp(−(Ω/Ωs)²)`: `Tst` at rest.
    fn dry_friction(&self, ts: f64, w: f64) -> Option<f64> {
        if w == 0.0 {
            return Some(self.static_torque_nm);
        }
        let u = w / self.stribeck_speed_rad_s;
        Some(ts + (self.static_torque_nm - ts) * (-u * u).exp())
    }
}
