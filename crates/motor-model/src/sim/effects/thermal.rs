//! `thermal_drift`: the winding's resistance rising with its temperature, heated by the copper
//! loss through a first-order thermal network.

use serde::{Deserialize, Serialize};

use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

/// Copper's temperature coefficient of resistance at 20 °C \[1/K\] (IEC 60028 annealed copper).
pub const COPPER_ALPHA_PER_K: f64 = 0.00393;

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

/// The table of its parameters, in the order of [`ThermalDrift::to_values`].
pub(crate) const THERMAL_PARAMS: [ParamSpec; 3] = [
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

impl ThermalDrift {
    /// Its parameter values in the order of its table ([`THERMAL_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![
            self.thermal_resistance_k_per_w,
            self.thermal_capacity_j_per_k,
            self.alpha_per_k,
        ]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        ThermalDrift {
            thermal_resistance_k_per_w: v[0],
            thermal_capacity_j_per_k: v[1],
            alpha_per_k: v[2],
        }
    }
}

impl Dynamics for ThermalDrift {
    /// The winding's temperature rise ΔT \[K\].
    fn states(&self) -> usize {
        1
    }
    /// `R = R0 (1 + α ΔT)`.
    fn resistance_factor(&self, own: &[f64]) -> f64 {
        1.0 + self.alpha_per_k * own[0]
    }
    /// `Cth dΔT/dt = I² R − ΔT/Rth`.
    fn derivative(&self, i: f64, r: f64, own: &[f64], d_own: &mut [f64]) {
        d_own[0] =
            (i * i * r - own[0] / self.thermal_resistance_k_per_w) / self.thermal_capacity_j_per_k;
    }
}
