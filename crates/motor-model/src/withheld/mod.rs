//! Data generator of the withheld-effect benchmark (issue 9, point 5): random motors with none,
//! one or two unmodelled effects, measured by varied loggers, for a diagnoser that is not told
//! the effect.
//!
//! # Kept apart from the candidate models on purpose
//!
//! The diagnoser's candidate models live in `sim/` ([`crate::Simulator`], [`crate::Effects`]).
//! To keep the benchmark from being circular, this module's plant is written again from the
//! equations: its own state vector, its own RK4 step rule, its own stick/slip handling (events
//! located by the Illinois variant of regula falsi, not bisection; for LuGre the bristle state
//! itself) and its own effect formulas. This duplication of the physics is deliberate; the
//! tests (`tests/withheld.rs`) check the (a) forms against [`crate::simulate`] and the nominal
//! plant against [`crate::StepResponse`]. What is not a candidate model is reused: [`crate::Input`]
//! for the waveforms, [`crate::MeasurementModel`], [`crate::Adc`], [`crate::Range`] and
//! [`crate::NoiseRng`] for the logger, [`crate::Derived`] for the time constants.
//!
//! # The plant
//!
//! Eq. (2) with the effects: state `[I, Ω, θ, Tw, Th, z, s1, s2]`,
//!
//! ```text
//! L(I) dI/dt = E − V_b(I) − R(Tw) I − k Ω
//! J dΩ/dt    = k I − f Ω − T_f − T_cog(θ) − T_drag(Ω)        dθ/dt = Ω
//! ```
//!
//! With Coulomb-type friction the rotor is **stuck** (Ω ≡ 0) while `|k I − T_cog(θ)| ≤ Tst`
//! (Tst = Ts without Stribeck), and slides in direction `d = ±1` with `T_f = d T_c(Ω)` until Ω
//! crosses zero, where it sticks or reverses. With LuGre friction there is no stuck phase: the
//! bristle deflection z carries the friction through zero speed.
//!
//! # Functional forms (each effect in two shapes)
//!
//! | effect | (a) same shape (SPEC section 5) | (b) other shape |
//! |---|---|---|
//! | `stribeck_friction` | `T_c = Ts + (Tst − Ts) exp(−(Ω/Ωs)²)`, breakaway at Tst | LuGre: `ż = Ω − σ0 |Ω| z/g(Ω)`, `g = Ts + (Tst − Ts) exp(−|Ω/Ωs|^δ)`, δ = 0.5 (presliding 1–4 mrad, scaled with Tst − Ts by the calibration), `T_f = σ0 z + σ1 ż` (σ2 = f) |
//! | `cogging_torque` | `A sin(Nθ + φ)` | `A [sin(Nθ + φ) + a2 sin(2Nθ + φ2) + a3 sin(3Nθ + φ3)]` |
//! | `current_sensor_lag` | `τf İs = I − Is` | critically damped: `Ïs + 2ωc İs + ωc² Is = ωc² I` |
//! | `thermal_drift` | `Cth dT/dt = I²R − T/Rth`, `R = R0 (1 + αT)` | two nodes: `Cw dTw/dt = I²R − (Tw − Th)/Rwh`, `Ch dTh/dt = (Tw − Th)/Rwh − Th/Rha`, `R = R0 (1 + α Tw)` |
//! | `quadratic_drag` | `c Ω|Ω|` | `c |Ω|^1.5 sign Ω` |
//! | `brush_drop` | `Vb clamp(I/I_knee, −1, 1)` | `Vb ln(1 + |I|/I0) sign I` |
//! | `inductance_saturation` | `L0 (r + (1 − r)/(1 + (I/I_sat)²))` | `L0 (r + (1 − r)/(1 + |I|ε/I_sat))`, falling linearly from I = 0 (`|I|ε = √(I² + ε²) − ε`, ε = 0.02 I_sat) |
//!
//! α is copper's 0.00393 1/K.
//!
//! # Integration
//!
//! Classical RK4 with a step of at most 1/8 of the fastest time constant (the motor's fast mode,
//! the stuck electrical pole `(R + dV_b/dI)/L_min`, the winding node, the detent well
//! `√(max dT_cog/dθ / J)`, the bristle `√(σ0/J)`), and at most 1/24 of the period of the
//! highest cogging harmonic at the present speed. Twelve time constants of the fast mode after
//! a jump of E(t) or a stick/slip event, when that mode has decayed to e⁻¹², the electrical
//! part of the limit is relaxed threefold (`h λ = 3/8`, well inside RK4's stability bound).
//! Below 3 Ωs of speed with Stribeck or LuGre
//! friction a step changes the speed by at most Ωs/10. The current sensor, a one-way filter of I
//! that may be much faster than the plant, is sub-cycled by RK4 inside each step on the cubic
//! Hermite interpolant of I(t) (ends and slopes from the plant), 5 sub-steps per time constant. Steps end on every sample and on every jump of
//! E(t). A stick/slip event inside a step (stuck: `|k I − T_cog| − Tst` turning positive;
//! sliding: `d Ω` turning negative) is located on the step fraction by the Illinois method and
//! the step is restarted there. When the bristle's relaxation rate `σ0|Ω|/g(Ω)` exceeds half a
//! step⁻¹ the bristle is held at its sliding equilibrium `z = g(Ω) sign Ω/σ0` for that step.
//!
//! # The measurement chain
//!
//! AR(1) noise `e_k = ρ e_{k−1} + √(1 − ρ²) σ w_k` (ρ = 0: white; σ 0–2 LSB) on voltage, current
//! and a tachometer, then [`crate::MeasurementModel`]: an 8–14-bit ADC over ranges set from the
//! nominal motor's signals with 20 % headroom, and either an encoder of 100–5000 counts per
//! revolution (speed by central differences) or a noisy tachometer (no angle). Sample rates
//! 1–5 kHz; 1–50 pre-trigger samples at 0 V, the step falling between two samples.
//!
//! # The cases
//!
//! [`case_mix`]: for `n` cases, `n/8` `none`, `n/8` with two effects, the rest with one effect
//! cycling through the seven; each effect's occurrences alternate the (a) and (b) forms. Motors
//! are drawn log-uniformly between a small servo (R 2–10 Ω, L 0.5–3 mH, k 0.01–0.05 N·m/A,
//! f 1e-6–2e-5 N·m·s/rad, J 1e-6–1e-5 kg·m², Ts 0.2–2 mN·m, 6–24 V) and the paper's motor
//! (R 0.3 Ω, L 0.3 H, k 0.15, f 0.05, J 1, Ts 0.03, 40 V). Records (the same protocol for every
//! effect, so that the protocol tells nothing): a high step at the rated voltage, a low step at
//! 2–5 times the breakaway voltage `R Ts/k`, a ±0.6 E reversal square wave and a six-level
//! staircase, each at most 5 s. Each effect's magnitude is calibrated (a few simulations) so
//! that alone it changes the current or the speed of some record by 4–25 noise floors RMS; the
//! value reached is stored as `visibility`. [`benchmark_case_with_gap`] calibrates on a measure
//! the caller gives instead: what is left once the nominal model has absorbed what it can (the
//! fit lives in another crate; `fit::diagnose::benchmark::calibrated_case` supplies it).
//!
//! ```
//! use motor_model::withheld::{benchmark_case, generate};
//!
//! let case = benchmark_case(7, 0, 16).unwrap();
//! let records = generate(&case).unwrap();
//! assert_eq!(records.high.t.len(), records.high.current.len());
//! println!("{:?}: visibility {:.1}", case.truth(), case.visibility);
//! ```

mod cases;
mod chain;
mod forms;
mod plant;

pub use cases::{
    benchmark_case, benchmark_case_with_gap, benchmark_cases, case_mix, generate, visibility,
    CaseEffect, CaseRecords, CaseSpec, GapMeasure, RecordRole, RecordSpec,
};
pub use chain::{
    ChannelRanges, ColouredNoise, MeasurementSpec, NoiseFloors, NoiseSpec, SpeedSensor,
};
pub use forms::{withheld_effect_names, Form, Magnitude, PlantEffect};
pub use plant::{
    simulate_plant, Plant, MAX_PLANT_SAMPLES, SATURATION_ROUNDING, STEPS_PER_FASTEST_TIME_CONSTANT,
};
