//! Exact physics of a DC servomotor with Coulomb friction, after Cova et al., "Motores de CC
//! en aplicaciones de robótica — metodología e instrumentación para la identificación de sus
//! parámetros" (CUDAR, UTN Córdoba). Equation numbers are the paper's.
//!
//! - [`MotorParams`]: R, L, k, f, J, Ts in SI units, validated; [`Derived`]: the constants
//!   (16)–(25) in every damping regime.
//! - [`steady_state`] (4), (5); [`breakaway_time`] (11), [`standstill_current`] (10);
//!   [`ApparentResistance`] (6)–(9).
//! - [`StepResponse`]: the exact current, speed and angle of a step, uniformly valid for
//!   ζ < 1, ζ = 1, ζ > 1 and accurate near ζ = 1; fast on a uniform grid.
//! - [`paper`]: the paper's own closed forms (12)–(15), (B.11)–(B.16), (C.4) and the
//!   approximations (31)–(33), (C.6), (C.8), with the printed errata corrected.
//! - [`Simulator`]: stick-slip simulation for any input [`Input`] with the unmodelled
//!   [`Effects`] of the diagnosis (Stribeck friction, cogging, sensor lag, thermal drift,
//!   quadratic drag, brush drop, inductance saturation).
//! - [`ServoRig`], [`replay`]: a geared servo with known [`Load`]s and its firmware's
//!   [`Controller`], replayed on a log's own time stamps; [`ModelFile`] (SPEC section 8).
//! - [`MeasurementModel`]: ADC, noise and encoder, separate from the plant.
//! - `withheld` (with the feature `withheld`): the data generator of the withheld-effect
//!   benchmark, with a plant of its own and each effect in two functional forms.
//!
//! ```
//! use motor_model::{MotorParams, Derived, StepResponse};
//!
//! let motor = MotorParams::paper();
//! let d = Derived::new(&motor);
//! assert!((d.zeta - 1.4849).abs() < 1e-4); // Table 1
//!
//! let step = StepResponse::new(&motor, 40.0);
//! let at_50s = step.at(50.0);
//! assert!((at_50s.current_a - 53.57).abs() < 0.005); // Table 2
//! ```
#![warn(missing_docs)]

mod axis;
mod derived;
mod error;
mod measure;
pub mod paper;
mod params;
mod real;
mod rng;
mod servo;
mod sim;
mod steady;
mod step;
#[cfg(feature = "withheld")]
pub mod withheld;

pub use axis::{
    pulse_split, relative_error_percent, simulate_pd_axis, AxisParams, PdController, PulseSplit,
    EMPS_DRIVE_GAIN_N_PER_V, EMPS_KP_PER_S, EMPS_KV_V_PER_M_S, EMPS_PULSE_COMMAND_V,
    EMPS_PULSE_FORCE_N,
};
pub use derived::{Derived, Regime};
pub use error::ModelError;
pub use measure::{
    central_difference, difference_over, mean_period, Adc, MeasurementModel, Range, Readings,
    Record, SpeedSource,
};
pub use params::MotorParams;
pub use real::{Dual, Real};
pub use rng::NoiseRng;
pub use servo::{
    replay, Controller, Load, ModelFile, ReplaySettings, ServoDrive, ServoMotor, ServoRig,
    ServoRun, ServoTrace, MAX_REPLAY_SUBSTEPS, MODEL_FILE_FORMAT, MODEL_FILE_VERSION,
    STANDARD_GRAVITY_M_S2, XL330_GAIN_PER_RAD,
};
pub use sim::effects::{
    BrushDrop, CoggingTorque, CurrentSensorLag, Domain, Effect, EffectKind, Effects,
    InductanceSaturation, ParamSpec, QuadraticDrag, StribeckFriction, ThermalDrift,
    COPPER_ALPHA_PER_K, EFFECT_NAMES,
};
pub use sim::input::Input;
pub use sim::simulator::{simulate, Simulator, MAX_RK4_STEPS_PER_SAMPLE, MAX_STATES};
pub use sim::trace::{Trace, MAX_SAMPLES};
pub use steady::{
    breakaway_time, standstill_current, steady_state, ApparentResistance, SteadyState,
};
pub use step::{MotorState, StepResponse, REANCHOR_SAMPLES};
