//! What each effect of SPEC section 5 adds to the plant's equations (Appendix D with effects):
//! one implementation of [`Dynamics`] per effect, next to nothing else.
//!
//! The simulator's equations (see `simulator.rs`) combine them as
//!
//! - `L0 Πₑ l_e(I) dI/dt = E − Σₑ V_e(I) − R0 Πₑ r_e(x_e) I − k Ω`,
//! - `J dΩ/dt = k I − f Ω − d T_c(Ω) − Σₑ T_e(Ω, θ)` while moving in direction `d`, `T_c`
//!   the dry friction (the motor's Ts unless an effect sets its level),
//! - `dx_e/dt` for the states `x_e` an effect has of its own,
//!
//! and the current channel reads the sensor's own state when an effect gives it one.

use super::effects::{
    BrushDrop, CoggingTorque, CurrentSensorLag, Effect, InductanceSaturation, QuadraticDrag,
    StribeckFriction, ThermalDrift,
};
use crate::params::MotorParams;

/// RK4 steps per fastest time constant of the plant (global error ≈ 1e-8 of the response).
pub(crate) const STEPS_PER_TIME_CONSTANT: f64 = 40.0;

/// RK4 steps per cogging period at the speed bound (or the current speed) when no speed
/// tolerance is given: the error on the speed ripple is then 2e-7 of the ripple.
const STEPS_PER_COGGING_PERIOD: f64 = 40.0;
/// Largest advance of the cogging phase `N θ` over one RK4 step \[rad\] with a speed
/// tolerance: a quarter period (4 steps a period, RK4's error on the ripple 2.3e-3 of the
/// ripple), far from the aliasing of a step near a whole period.
const MAX_COGGING_PHASE_PER_STEP: f64 = std::f64::consts::FRAC_PI_2;
/// RK4 on the ripple of a torque `A sin(ω t)` is Simpson's rule on each step: its relative
/// error on the ripple is `(ω h)⁴/2880` (to 8 % up to `ω h = π/2`); half of that constant, for
/// the coupling of the ripple with the angle it follows.
const SIMPSON_RIPPLE_CONSTANT: f64 = 1440.0;

/// An effect's part in the plant's equations (module docs). Every method has the neutral
/// default (no change to the nominal model).
pub(crate) trait Dynamics {
    /// Number of states of its own (appended to `[I, Ω, θ]`).
    fn states(&self) -> usize {
        0
    }
    /// Factor `r_e` on the armature resistance, from its own states.
    fn resistance_factor(&self, _own: &[f64]) -> f64 {
        1.0
    }
    /// Factor `l_e(I)` on the inductance at armature current `i` \[A\].
    fn inductance_factor(&self, _i: f64) -> f64 {
        1.0
    }
    /// Smallest [`Dynamics::inductance_factor`] over all currents.
    fn min_inductance_factor(&self) -> f64 {
        1.0
    }
    /// Voltage drop `V_e(I)` \[V\] in the armature circuit.
    fn voltage_drop(&self, _i: f64) -> f64 {
        0.0
    }
    /// Largest slope `dV_e/dI` \[Ω\] of the drop (an extra resistance for the fastest pole).
    fn incremental_resistance(&self) -> f64 {
        0.0
    }
    /// Load torque `T_e(Ω, θ)` \[N·m\] opposing the motor torque, at speed `w` \[rad/s\] and
    /// angle `theta` \[rad\] (also felt at rest, `w = 0`).
    fn load_torque(&self, _w: f64, _theta: f64) -> f64 {
        0.0
    }
    /// The dry-friction level `T_c(Ω)` \[N·m\] at speed `w` for a motor of Coulomb torque
    /// `ts`, if the effect sets it (at `w = 0`: the static friction that holds the rotor).
    fn dry_friction(&self, _ts: f64, _w: f64) -> Option<f64> {
        None
    }
    /// Derivatives of its own states, with armature current `i` \[A\] and the resistance `r`
    /// \[Ω\] in effect.
    fn derivative(&self, _i: f64, _r: f64, _own: &[f64], _d_own: &mut [f64]) {}
    /// Which of its own states the current sensor reads \[A\], if not the armature current.
    fn sensor_state(&self) -> Option<usize> {
        None
    }
    /// Time constant \[s\] of the first-order filter `τ dI_f/dt = I − I_f` that the sensor
    /// state is, if it is one: the simulator then advances it exactly over each step (on the
    /// cubic through the current's values and slopes at the step's ends) instead of by RK4,
    /// so that a filter far faster than the plant does not bound the step.
    fn sensor_time_constant(&self) -> Option<f64> {
        None
    }
    /// The fastest rate \[1/s\] of its own dynamics on motor `p` (beyond R and L).
    fn own_rate(&self, _p: &MotorParams) -> f64 {
        0.0
    }
    /// Longest RK4 step \[s\] at speeds up to `speed` \[rad/s\] in magnitude on motor `p`;
    /// with `tolerance` \[rad/s\], the longest at which the integration error the effect
    /// causes in the speed stays below it.
    fn step_limit(&self, _p: &MotorParams, _speed: f64, _tolerance: Option<f64>) -> f64 {
        f64::INFINITY
    }
}

/// The nominal model adds nothing.
struct Nominal;
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

impl Dynamics for InductanceSaturation {
    /// `r + (1 − r)/(1 + (I/I_sat)²)`.
    fn inductance_factor(&self, i: f64) -> f64 {
        self.factor(i)
    }
    fn min_inductance_factor(&self) -> f64 {
        self.min_ratio
    }
}
