//! `quadratic_drag`: a load torque growing with the square of the speed (fan, fluid).

use serde::{Deserialize, Serialize};

use crate::params::MotorParams;
use crate::sim::dynamics::{Dynamics, STEPS_PER_TIME_CONSTANT};
use crate::sim::effects::spec::{Domain, ParamSpec};

/// `quadratic_drag`: an extra load torque `c Ω|Ω|` \[N·m\] (fan, fluid).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct QuadraticDrag {
    /// Coefficient c \[N·m·s²/rad²\], key `c`.
    pub c_nms2_per_rad2: f64,
}

/// The table of its parameters, in the order of [`QuadraticDrag::to_values`].
pub(crate) const DRAG_PARAMS: [ParamSpec; 1] = [ParamSpec {
    key: "c",
    symbol: "c",
    unit: "N·m·s²/rad²",
    description: "coefficient",
    default: None,
    domain: Domain::NonNegative,
    fitted: true,
}];

impl QuadraticDrag {
    /// Its parameter values in the order of its table ([`DRAG_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![self.c_nms2_per_rad2]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        QuadraticDrag {
            c_nms2_per_rad2: v[0],
        }
    }
}

impl Dynamics for QuadraticDrag {
    /// `c Ω|Ω|`.
    fn load_torque(&self, w: f64, _theta: f64) -> f64 {
        self.c_nms2_per_rad2 * w * w.abs()
    }
    /// 1/40 of the drag's own time constant at `speed`, `J/(2 c |Ω|)` (the linearised rate of
    /// `J dΩ/dt = −c Ω|Ω|`), as for the plant's: a drag this strong is stiff, and a longer RK4
    /// step is unstable (`c = 3000` on a 2e-5 kg·m² rotor ran to −1e9 rad/s under +12 V).
    fn step_limit(&self, p: &MotorParams, speed: f64, _tolerance: Option<f64>) -> f64 {
        let rate = 2.0 * self.c_nms2_per_rad2 * speed.abs() / p.j_kgm2;
        if rate.is_finite() && rate > 0.0 {
            1.0 / (rate * STEPS_PER_TIME_CONSTANT)
        } else {
            f64::INFINITY
        }
    }
}
