//! `brush_drop`: a voltage drop across the brushes, linear below a knee current.

use serde::{Deserialize, Serialize};

use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

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

/// The table of its parameters, in the order of [`BrushDrop::to_values`].
pub(crate) const BRUSH_PARAMS: [ParamSpec; 2] = [
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

impl BrushDrop {
    /// Its parameter values in the order of its table ([`BRUSH_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![self.drop_v, self.knee_current_a]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        BrushDrop {
            drop_v: v[0],
            knee_current_a: v[1],
        }
    }
}

impl Dynamics for BrushDrop {
    /// `Vb clamp(I/I_knee, −1, 1)`.
    fn voltage_drop(&self, i: f64) -> f64 {
        self.drop_v * (i / self.knee_current_a).clamp(-1.0, 1.0)
    }
    /// The brush film's resistance below the knee, `Vb/I_knee`.
    fn incremental_resistance(&self) -> f64 {
        self.drop_v / self.knee_current_a
    }
}
