//! `inductance_saturation`: the incremental inductance falling as the current grows.

use serde::{Deserialize, Serialize};

use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

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

/// The table of its parameters, in the order of [`InductanceSaturation::to_values`].
pub(crate) const SATURATION_PARAMS: [ParamSpec; 2] = [
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

impl InductanceSaturation {
    /// Its parameter values in the order of its table ([`SATURATION_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![self.saturation_current_a, self.min_ratio]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        InductanceSaturation {
            saturation_current_a: v[0],
            min_ratio: v[1],
        }
    }
}

impl Dynamics for InductanceSaturation {
    /// `r + (1 − r)/(1 + (I/I_sat)²)`.
    fn inductance_factor(&self, i: f64) -> f64 {
        self.factor(i)
    }
    fn min_inductance_factor(&self) -> f64 {
        self.min_ratio
    }
}
