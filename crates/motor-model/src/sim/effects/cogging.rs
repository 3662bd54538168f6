//! `cogging_torque`: a load torque periodic in the shaft angle.

use serde::{Deserialize, Serialize};

use crate::params::MotorParams;
use crate::sim::dynamics::Dynamics;
use crate::sim::effects::spec::{Domain, ParamSpec};

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

/// The table of its parameters, in the order of [`CoggingTorque::to_values`].
pub(crate) const COGGING_PARAMS: [ParamSpec; 3] = [
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

impl CoggingTorque {
    /// Its parameter values in the order of its table ([`COGGING_PARAMS`]), SI units.
    pub(crate) fn to_values(self) -> Vec<f64> {
        vec![
            self.amplitude_nm,
            f64::from(self.periods_per_rev),
            self.phase_rad,
        ]
    }

    /// The effect of values `v` in the order of its table, each already checked against its
    /// domain.
    pub(crate) fn from_checked(v: &[f64]) -> Self {
        CoggingTorque {
            amplitude_nm: v[0],
            // A whole number from 1 to 65535 (checked against its domain).
            periods_per_rev: v[1] as u32,
            phase_rad: v[2],
        }
    }
}

/// RK4 steps per cogging period at the speed bound (or the current speed) when no speed
/// tolerance is given: the error on the speed ripple is then 2e-7 of the ripple.
pub(crate) const STEPS_PER_COGGING_PERIOD: f64 = 40.0;

/// Largest advance of the cogging phase `N θ` over one RK4 step \[rad\] with a speed
/// tolerance: a quarter period (4 steps a period, RK4's error on the ripple 2.3e-3 of the
/// ripple), far from the aliasing of a step near a whole period.
pub(crate) const MAX_COGGING_PHASE_PER_STEP: f64 = std::f64::consts::FRAC_PI_2;

/// RK4 on the ripple of a torque `A sin(ω t)` is Simpson's rule on each step: its relative
/// error on the ripple is `(ω h)⁴/2880` (to 8 % up to `ω h = π/2`); half of that constant, for
/// the coupling of the ripple with the angle it follows.
pub(crate) const SIMPSON_RIPPLE_CONSTANT: f64 = 1440.0;

impl Dynamics for CoggingTorque {
    /// `A sin(N θ + φ)`.
    fn load_torque(&self, _w: f64, theta: f64) -> f64 {
        self.amplitude_nm * (f64::from(self.periods_per_rev) * theta + self.phase_rad).sin()
    }
    /// Small-oscillation pulsation of the rotor in a cogging well, `√(A N/J)`.
    fn own_rate(&self, p: &MotorParams) -> f64 {
        (self.amplitude_nm * f64::from(self.periods_per_rev) / p.j_kgm2).sqrt()
    }
    /// 1/40 of a cogging period at `speed`; with `tolerance`, the step at which RK4's error
    /// on the speed ripple at `speed`, `(ω h)⁴/2880` of the ripple `A/(J ω)` (ω = N |Ω| the
    /// ripple's pulsation; Simpson's rule, [`SIMPSON_RIPPLE_CONSTANT`]), is `tolerance`, the
    /// ripple advancing at most a quarter period a step and never less than 1/40. The error
    /// grows as `A N³ |Ω|³ h⁴/J`: at any lower speed it is smaller.
    fn step_limit(&self, p: &MotorParams, speed: f64, tolerance: Option<f64>) -> f64 {
        let w = speed.abs() * f64::from(self.periods_per_rev);
        if w.is_nan() || w <= 0.0 {
            return f64::INFINITY;
        }
        let fine = std::f64::consts::TAU / w / STEPS_PER_COGGING_PERIOD;
        let Some(tol) = tolerance.filter(|t| *t > 0.0 && t.is_finite()) else {
            return fine;
        };
        let ripple = self.amplitude_nm / (p.j_kgm2 * w);
        let phase = if ripple > 0.0 {
            (SIMPSON_RIPPLE_CONSTANT * tol / ripple)
                .powf(0.25)
                .min(MAX_COGGING_PHASE_PER_STEP)
        } else {
            MAX_COGGING_PHASE_PER_STEP
        };
        (phase / w).max(fine)
    }
}
