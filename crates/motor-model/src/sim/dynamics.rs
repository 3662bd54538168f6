//! What an effect of SPEC section 5 may add to the plant's equations (Appendix D with
//! effects): the [`Dynamics`] trait, which each effect implements in its own module under
//! `effects`.
//!
//! The simulator's equations (see `simulator.rs`) combine them as
//!
//! - `L0 Πₑ l_e(I) dI/dt = E − Σₑ V_e(I) − R0 Πₑ r_e(x_e) I − k Ω`,
//! - `J dΩ/dt = k I − f Ω − d T_c(Ω) − Σₑ T_e(Ω, θ)` while moving in direction `d`, `T_c`
//!   the dry friction (the motor's Ts unless an effect sets its level),
//! - `dx_e/dt` for the states `x_e` an effect has of its own,
//!
//! and the current channel reads the sensor's own state when an effect gives it one.

use crate::params::MotorParams;

/// RK4 steps per fastest time constant of the plant (global error ≈ 1e-8 of the response).
pub(crate) const STEPS_PER_TIME_CONSTANT: f64 = 40.0;

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
