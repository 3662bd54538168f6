//! `current_sensor_lag`: a first-order low-pass between the armature current and its channel.

use serde::{Deserialize, Serialize};

use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

/// `current_sensor_lag`: the current channel sees `I_f` with `τf dI_f/dt = I − I_f` \[A\]
/// (first-order low-pass of time constant τf); the plant itself is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurrentSensorLag {
    /// Filter time constant τf \[s\], key `tau`.
    pub tau_f_s: f64,
}

/// The table of its parameters, in the order of [`CurrentSensorLag::to_values`].
pub(crate) const SENSOR_LAG_PARAMS: [ParamSpec; 1] = [ParamSpec {
    key: "tau",
    symbol: "τf",
    unit: "s",
    description: "filter time constant",
    default: None,
    domain: Domain::Positive,
    fitted: true,
}];

impl CurrentSensorLag {
    /// Its parameter values in the order of its table ([`SENSOR_LAG_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![self.tau_f_s]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        CurrentSensorLag { tau_f_s: v[0] }
    }
}

impl Dynamics for CurrentSensorLag {
    /// The sensor's current `I_f`.
    fn states(&self) -> usize {
        1
    }
    /// `τf dI_f/dt = I − I_f`.
    fn derivative(&self, i: f64, _r: f64, own: &[f64], d_own: &mut [f64]) {
        d_own[0] = (i - own[0]) / self.tau_f_s;
    }
    fn sensor_state(&self) -> Option<usize> {
        Some(0)
    }
    /// τf: the filter is advanced exactly, and its rate does not bound the step.
    fn sensor_time_constant(&self) -> Option<f64> {
        Some(self.tau_f_s)
    }
}
