//! The benchmark's own plant: Eq. (2) with the effects of [`super::forms`], integrated by its
//! own fixed-step RK4 with stick/slip events located by the Illinois method.
//!
//! Deliberately independent of `sim/` (see the module docs of [`crate::withheld`]): the state,
//! the step-size rule, the event locator and every effect formula are written here again.

use super::forms::PlantEffect;
use crate::derived::Derived;
use crate::error::{positive, ModelError};
use crate::params::MotorParams;
use crate::sim::input::Input;
use crate::sim::trace::Trace;

/// RK4 steps per time constant of the fastest mode (`h λmax = 1/8`: the per-step error of
/// that mode is `(hλ)⁵/120 ≈ 3e-7` of its amplitude, and it dies out within a few steps; the
/// nominal step response comes out within 1e-6 of the exact one).
pub const STEPS_PER_FASTEST_TIME_CONSTANT: f64 = 8.0;
/// Once the fast electrical mode excited by a jump or an event has decayed for
/// `FINE_WINDOW_TIME_CONSTANTS` of its time constants (to e⁻¹² ≈ 6e-6), the electrical part of
/// the step limit is relaxed by `SETTLED_STEP_FACTOR` (`h λ = 3/8`, well inside RK4's stability
/// bound of 2.78; the per-step error on what is left of the mode is below 1e-9 of the jump).
const FINE_WINDOW_TIME_CONSTANTS: f64 = 12.0;
/// Width over which the (b) inductance form rounds `|I|` at zero, in units of I_sat \[-\].
pub const SATURATION_ROUNDING: f64 = 0.02;
/// See [`FINE_WINDOW_TIME_CONSTANTS`].
const SETTLED_STEP_FACTOR: f64 = 3.0;
/// RK4 steps per period of the highest cogging harmonic at the present speed.
/// Below `STRIBECK_ZONE` Ωs of speed, a step changes the speed by at most
/// `STRIBECK_STEP_FRACTION` Ωs (the friction falls from Tst to Ts across Ωs).
const STRIBECK_ZONE: f64 = 3.0;
/// See [`STRIBECK_ZONE`].
const STRIBECK_STEP_FRACTION: f64 = 0.1;
const STEPS_PER_COGGING_PERIOD: f64 = 24.0;
/// Above this `h σ0|Ω|/g(Ω)` the bristle is held at its sliding equilibrium `z = g sign Ω / σ0`
/// for the step instead of being integrated (it relaxes in less than a step).
const BRISTLE_EQUILIBRIUM_RATE_STEPS: f64 = 0.5;
/// Illinois iterations locating a stick/slip event inside a step.
const EVENT_ITERATIONS: u32 = 60;
/// Events accepted inside one step before the rest of it is taken as is.
const MAX_EVENTS_PER_STEP: u32 = 6;
/// Sub-steps allowed between two samples before the plant gives up (a guard, never reached
/// by the benchmark's cases).
const MAX_SUBSTEPS_PER_SAMPLE: usize = 200_000;
/// Longest record the plant produces \[samples\].
pub const MAX_PLANT_SAMPLES: usize = 1_000_000;

const I: usize = 0;
const W: usize = 1;
const TH: usize = 2;
const T_WINDING: usize = 3;
const T_HOUSING: usize = 4;
const Z: usize = 5;
const S1: usize = 6;
const S2: usize = 7;
/// `[I, Ω, θ, Tw, Th, z, s1, s2]`: current \[A\], speed \[rad/s\], angle \[rad\], winding and
/// housing temperature rises \[K\], bristle deflection \[rad\], sensor states \[A, A/s\].
type State = [f64; 8];

/// How the dry friction acts at the present instant.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Held at rest by static friction: Ω ≡ 0.
    Stuck,
    /// Sliding in direction ±1.
    Sliding(f64),
    /// LuGre: no stuck phase, the bristle state carries the friction.
    Bristle,
}

/// The effects sorted by the part of the plant they act on (at most one each).
#[derive(Debug, Clone, Copy, Default)]
struct Slots {
    friction: Option<PlantEffect>,
    cogging: Option<PlantEffect>,
    sensor: Option<PlantEffect>,
    thermal: Option<PlantEffect>,
    drag: Option<PlantEffect>,
    brush: Option<PlantEffect>,
    saturation: Option<PlantEffect>,
}

/// The benchmark plant: a motor, its effects and an input.
#[derive(Debug, Clone)]
pub struct Plant {
    motor: MotorParams,
    slots: Slots,
    input: Input,
    /// Longest step while the electrical transient of a jump or an event is alive \[s\].
    h_max: f64,
    /// Longest step once it has died out \[s\].
    h_settled: f64,
    /// How long the fine step is kept after a jump or an event \[s\].
    settle_s: f64,
}

impl Plant {
    /// A plant of `motor` with `effects` (each SPEC name at most once), driven by `input`.
    pub fn new(
        motor: MotorParams,
        effects: &[PlantEffect],
        input: Input,
    ) -> Result<Self, ModelError> {
        motor.validate()?;
        let mut slots = Slots::default();
        for e in effects {
            e.validate(&motor)?;
            let slot = match e.name() {
                "stribeck_friction" => &mut slots.friction,
                "cogging_torque" => &mut slots.cogging,
                "current_sensor_lag" => &mut slots.sensor,
                "thermal_drift" => &mut slots.thermal,
                "quadratic_drag" => &mut slots.drag,
                "brush_drop" => &mut slots.brush,
                _ => &mut slots.saturation,
            };
            if slot.replace(*e).is_some() {
                return Err(ModelError::InvalidSetting {
                    name: format!("{} given twice", e.name()),
                    value: 2.0,
                    expected: "each effect at most once",
                });
            }
        }
        let mut plant = Plant {
            motor,
            slots,
            input,
            h_max: 0.0,
            h_settled: 0.0,
            settle_s: 0.0,
        };
        let (electrical, other, decay) = plant.rates_of_modes();
        let h_other = 1.0 / (other * STEPS_PER_FASTEST_TIME_CONSTANT);
        let h_electrical = 1.0 / (electrical * STEPS_PER_FASTEST_TIME_CONSTANT);
        plant.h_max = h_electrical.min(h_other);
        plant.h_settled = (SETTLED_STEP_FACTOR * h_electrical).min(h_other);
        plant.settle_s = FINE_WINDOW_TIME_CONSTANTS / decay;
        Ok(plant)
    }

    /// The same plant with its RK4 step at most `h_s` \[s\] (for convergence checks).
    pub fn with_max_step(mut self, h_s: f64) -> Result<Self, ModelError> {
        let h_s = positive("plant step", h_s)?;
        self.h_max = self.h_max.min(h_s);
        self.h_settled = self.h_settled.min(h_s);
        Ok(self)
    }

    /// The longest RK4 step \[s\] (while a transient is alive; 3 times longer after).
    pub fn max_step_s(&self) -> f64 {
        self.h_max
    }

    /// Simulates from rest for `duration_s` \[s\], sampled at `rate_hz` \[Hz\] from t = 0.
    pub fn run(&self, duration_s: f64, rate_hz: f64) -> Result<Trace, ModelError> {
        let dt = 1.0 / positive("sample rate", rate_hz)?;
        let count = (positive("duration", duration_s)? * rate_hz).floor() + 1.0;
        if count > MAX_PLANT_SAMPLES as f64 {
            return Err(ModelError::InvalidSetting {
                name: "plant samples".into(),
                value: count,
                expected: "at most 1,000,000 samples",
            });
        }
        let n = count as usize;
        let mut out = Trace::with_capacity(n);
        let mut x: State = [0.0; 8];
        let mut phase = if self
            .slots
            .friction
            .is_some_and(|f| matches!(f, PlantEffect::LuGre { .. }))
        {
            Phase::Bristle
        } else {
            Phase::Stuck
        };
        let mut t = 0.0;
        let mut excited_at = 0.0;
        for j in 0..n {
            let t_j = j as f64 * dt;
            while let Some(jump) = self.input.next_jump_after(t).filter(|&tj| tj < t_j) {
                self.advance(&mut x, &mut phase, t, jump, &mut excited_at)?;
                t = jump;
                excited_at = jump;
            }
            if t_j > t {
                self.advance(&mut x, &mut phase, t, t_j, &mut excited_at)?;
                t = t_j;
            }
            out.t.push(t_j);
            out.voltage.push(self.input.volts_at(t_j));
            out.armature_current.push(x[I]);
            out.current.push(if self.slots.sensor.is_some() {
                x[S1]
            } else {
                x[I]
            });
            out.speed.push(x[W]);
            out.position.push(x[TH]);
            out.stuck.push(phase == Phase::Stuck);
        }
        Ok(out)
    }

    /// The fastest rates of the plant \[1/s\]: of the electrical modes (the motor's, the stuck
    /// pole with the brush film and the smallest inductance), of the effects' own dynamics, and
    /// the decay rate of the motor's fast mode.
    fn rates_of_modes(&self) -> (f64, f64, f64) {
        let p = &self.motor;
        let d = Derived::new(p);
        let (moving, decay) = if d.omega_a > 0.0 && d.zeta > 1.0 {
            (d.sigma + d.omega_a, d.sigma + d.omega_a)
        } else {
            (d.omega_n.max(d.sigma), d.sigma)
        };
        let decay = decay.min(p.r_ohm / p.l_henry);
        let l_min = match self.slots.saturation {
            Some(PlantEffect::SaturationLorentzian { min_ratio, .. })
            | Some(PlantEffect::SaturationAbsolute { min_ratio, .. }) => p.l_henry * min_ratio,
            _ => p.l_henry,
        };
        let brush_slope = match self.slots.brush {
            Some(PlantEffect::BrushClamp {
                drop_v,
                knee_current_a,
            }) => drop_v / knee_current_a,
            Some(PlantEffect::BrushLogarithmic {
                drop_v,
                onset_current_a,
            }) => drop_v / onset_current_a,
            _ => 0.0,
        };
        let electrical = (moving * p.l_henry / l_min).max((p.r_ohm + brush_slope) / l_min);
        let mut rate = f64::MIN_POSITIVE;
        if let Some(PlantEffect::ThermalTwoNode {
            winding_capacity_j_per_k,
            winding_to_housing_k_per_w,
            ..
        }) = self.slots.thermal
        {
            rate = rate.max(1.0 / (winding_capacity_j_per_k * winding_to_housing_k_per_w));
        }
        if let Some(c) = self.slots.cogging {
            // Pulsation of small oscillations in a detent well: √(max dT_cog/dθ / J).
            rate = rate.max((cogging_stiffness(&c) / p.j_kgm2).sqrt());
        }
        if let Some(PlantEffect::LuGre {
            bristle_stiffness_nm_per_rad,
            bristle_damping_nms_per_rad,
            ..
        }) = self.slots.friction
        {
            rate = rate
                .max((bristle_stiffness_nm_per_rad / p.j_kgm2).sqrt())
                .max(bristle_damping_nms_per_rad / p.j_kgm2);
        }
        (electrical, rate, decay)
    }

    /// Integrates from `t0` to `t1` in sub-steps no longer than the plant allows at the
    /// present state.
    fn advance(
        &self,
        x: &mut State,
        phase: &mut Phase,
        t0: f64,
        t1: f64,
        excited_at: &mut f64,
    ) -> Result<(), ModelError> {
        let mut t = t0;
        for _ in 0..MAX_SUBSTEPS_PER_SAMPLE {
            let left = t1 - t;
            if left <= 0.0 {
                return Ok(());
            }
            let h_allowed = self.step_limit(x, t - *excited_at);
            let pieces = (left / h_allowed).ceil().max(1.0);
            let h = left / pieces;
            if let Some(t_event) = self.step(x, phase, t, h) {
                *excited_at = t_event;
            }
            t = if pieces <= 1.0 { t1 } else { t + h };
        }
        Err(ModelError::InvalidSetting {
            name: "plant sub-steps between two samples".into(),
            value: MAX_SUBSTEPS_PER_SAMPLE as f64,
            expected: "a plant that can be integrated in fewer steps (lower the cogging order or bristle stiffness)",
        })
    }

    /// The longest step at the present state \[s\], `since_s` \[s\] after the last jump or
    /// event: the fine or the settled step, a fraction of Ωs in the Stribeck zone, a fraction
    /// of a cogging period at the present speed.
    fn step_limit(&self, x: &State, since_s: f64) -> f64 {
        let mut h = if since_s < self.settle_s {
            self.h_max
        } else {
            self.h_settled
        };
        let stribeck = match self.slots.friction {
            Some(PlantEffect::StribeckGaussian {
                static_torque_nm,
                stribeck_speed_rad_s,
            })
            | Some(PlantEffect::LuGre {
                static_torque_nm,
                stribeck_speed_rad_s,
                ..
            }) => Some((static_torque_nm, stribeck_speed_rad_s)),
            _ => None,
        };
        if let Some((tst, ws)) = stribeck {
            if x[W].abs() < STRIBECK_ZONE * ws {
                // Bound on |dΩ/dt| from the motor torque and the static friction.
                let p = &self.motor;
                let accel = (p.k_nm_per_a * x[I].abs() + tst) / p.j_kgm2;
                h = h.min(STRIBECK_STEP_FRACTION * ws / accel);
            }
        }
        if let Some(c) = self.slots.cogging {
            let highest = match c {
                PlantEffect::CoggingHarmonics {
                    periods_per_rev, ..
                } => 3.0 * f64::from(periods_per_rev),
                PlantEffect::CoggingSine {
                    periods_per_rev, ..
                } => f64::from(periods_per_rev),
                _ => 0.0,
            };
            let w = x[W].abs() * highest;
            if w > 0.0 {
                h = h.min(std::f64::consts::TAU / (w * STEPS_PER_COGGING_PERIOD));
            }
        }
        h
    }

    /// One step of length `h` from `t`, with the stick/slip events inside it; returns the
    /// instant of the last event, if any.
    fn step(&self, x: &mut State, phase: &mut Phase, t: f64, h: f64) -> Option<f64> {
        if *phase == Phase::Bristle {
            let equilibrium = self.bristle_in_equilibrium(x, h);
            *x = self.rk4_sensed(x, *phase, equilibrium, t, h);
            if equilibrium {
                x[Z] = self.bristle_sliding_deflection(x[W]);
            }
            return None;
        }
        let mut t = t;
        let mut left = h;
        let mut event = None;
        for _ in 0..MAX_EVENTS_PER_STEP {
            let end = self.rk4(x, *phase, false, t, left);
            if self.event_value(&end, *phase) <= 0.0 {
                *x = self.with_sensor(x, &end, *phase, t, left);
                return event;
            }
            let s = self.locate_event(x, *phase, t, left);
            let at = self.rk4(x, *phase, false, t, s * left);
            let mut at = self.with_sensor(x, &at, *phase, t, s * left);
            at[W] = 0.0;
            *phase = self.phase_at_rest(&at);
            *x = at;
            t += s * left;
            event = Some(t);
            left *= 1.0 - s;
            if left <= 0.0 {
                return event;
            }
        }
        *x = self.rk4_sensed(x, *phase, false, t, left);
        event
    }

    /// The event function: positive once the phase must change. Stuck: `|τ_rest| − Tst`;
    /// sliding in direction d: `−d Ω`.
    fn event_value(&self, x: &State, phase: Phase) -> f64 {
        match phase {
            Phase::Stuck => self.torque_at_rest(x).abs() - self.static_friction(),
            Phase::Sliding(d) => -d * x[W],
            Phase::Bristle => -1.0,
        }
    }

    /// The fraction `s ∈ (0, 1]` of the step at which the event function crosses zero, by the
    /// Illinois variant of regula falsi on `s ↦ event(RK4(x, s h))`.
    fn locate_event(&self, x: &State, phase: Phase, t: f64, h: f64) -> f64 {
        let g = |s: f64| self.event_value(&self.rk4(x, phase, false, t, s * h), phase);
        let (mut a, mut b) = (0.0_f64, 1.0_f64);
        let (mut ga, mut gb) = (g(a), g(b));
        if ga > 0.0 {
            return 0.0;
        }
        let mut last_side = 0i8;
        for _ in 0..EVENT_ITERATIONS {
            if b - a <= 1e-15 {
                break;
            }
            let mut c = (a * gb - b * ga) / (gb - ga);
            if !(c > a && c < b) {
                c = 0.5 * (a + b);
            }
            let gc = g(c);
            if gc > 0.0 {
                b = c;
                gb = gc;
                if last_side == 1 {
                    ga *= 0.5;
                }
                last_side = 1;
            } else {
                a = c;
                ga = gc;
                if last_side == -1 {
                    gb *= 0.5;
                }
                last_side = -1;
            }
        }
        b
    }

    /// Torque on the rotor at rest apart from friction \[N·m\]: `k I − T_cog(θ)`.
    fn torque_at_rest(&self, x: &State) -> f64 {
        self.motor.k_nm_per_a * x[I] - self.cogging_torque(x[TH])
    }

    /// The torque static friction can hold \[N·m\].
    fn static_friction(&self) -> f64 {
        match self.slots.friction {
            Some(PlantEffect::StribeckGaussian {
                static_torque_nm, ..
            }) => static_torque_nm,
            _ => self.motor.ts_nm,
        }
    }

    fn phase_at_rest(&self, x: &State) -> Phase {
        let torque = self.torque_at_rest(x);
        if torque.abs() > self.static_friction() {
            Phase::Sliding(torque.signum())
        } else {
            Phase::Stuck
        }
    }

    fn cogging_torque(&self, theta: f64) -> f64 {
        match self.slots.cogging {
            Some(PlantEffect::CoggingSine {
                amplitude_nm,
                periods_per_rev,
                phase_rad,
            }) => amplitude_nm * (f64::from(periods_per_rev) * theta + phase_rad).sin(),
            Some(PlantEffect::CoggingHarmonics {
                amplitude_nm,
                periods_per_rev,
                phase_rad,
                second_ratio,
                second_phase_rad,
                third_ratio,
                third_phase_rad,
            }) => {
                let a = f64::from(periods_per_rev) * theta;
                amplitude_nm
                    * ((a + phase_rad).sin()
                        + second_ratio * (2.0 * a + second_phase_rad).sin()
                        + third_ratio * (3.0 * a + third_phase_rad).sin())
            }
            _ => 0.0,
        }
    }

    /// LuGre `g(Ω)` \[N·m\] (the sliding friction level).
    fn lugre_level(&self, w: f64) -> f64 {
        match self.slots.friction {
            Some(PlantEffect::LuGre {
                static_torque_nm,
                stribeck_speed_rad_s,
                stribeck_exponent,
                ..
            }) => {
                let ts = self.motor.ts_nm;
                ts + (static_torque_nm - ts)
                    * (-(w.abs() / stribeck_speed_rad_s).powf(stribeck_exponent)).exp()
            }
            _ => self.motor.ts_nm,
        }
    }

    fn bristle_stiffness(&self) -> f64 {
        match self.slots.friction {
            Some(PlantEffect::LuGre {
                bristle_stiffness_nm_per_rad,
                ..
            }) => bristle_stiffness_nm_per_rad,
            _ => 0.0,
        }
    }

    /// `z = g(Ω) sign(Ω)/σ0` \[rad\]: where the bristle settles while sliding.
    fn bristle_sliding_deflection(&self, w: f64) -> f64 {
        self.lugre_level(w) * w.signum() / self.bristle_stiffness()
    }

    fn bristle_in_equilibrium(&self, x: &State, h: f64) -> bool {
        let rate = self.bristle_stiffness() * x[W].abs() / self.lugre_level(x[W]);
        rate * h > BRISTLE_EQUILIBRIUM_RATE_STEPS
    }

    /// [`Plant::rk4`] followed by the sensor over the same step.
    fn rk4_sensed(&self, x: &State, phase: Phase, equilibrium: bool, t: f64, h: f64) -> State {
        let end = self.rk4(x, phase, equilibrium, t, h);
        self.with_sensor(x, &end, phase, t, h)
    }

    /// `end` (the plant state a step `h` after `x`) with the current sensor's states advanced
    /// over the step. The sensor is a one-way filter of I, often much faster than the plant:
    /// it is sub-cycled by RK4 on the cubic Hermite interpolant of I(t) over the step (ends and
    /// slopes from the plant), so that it does not shorten the plant's step.
    fn with_sensor(&self, x: &State, end: &State, phase: Phase, t: f64, h: f64) -> State {
        let mut y = *end;
        let Some(sensor) = self.slots.sensor else {
            return y;
        };
        let rate = match sensor {
            PlantEffect::SensorFirstOrder { tau_f_s } => 1.0 / tau_f_s,
            PlantEffect::SensorSecondOrder {
                natural_pulsation_rad_s,
            } => natural_pulsation_rad_s,
            _ => return y,
        };
        let equilibrium = phase == Phase::Bristle && self.bristle_in_equilibrium(x, h);
        let slope0 = self.rates(x, phase, equilibrium, t, t)[I] * h;
        let slope1 = self.rates(end, phase, equilibrium, t, t + h)[I] * h;
        let (i0, i1) = (x[I], end[I]);
        // Cubic Hermite I(u), u ∈ [0, 1].
        let current = |u: f64| {
            let (u2, u3) = (u * u, u * u * u);
            (2.0 * u3 - 3.0 * u2 + 1.0) * i0
                + (u3 - 2.0 * u2 + u) * slope0
                + (-2.0 * u3 + 3.0 * u2) * i1
                + (u3 - u2) * slope1
        };
        let f = |s: [f64; 2], u: f64| -> [f64; 2] {
            let i = current(u);
            match sensor {
                PlantEffect::SensorSecondOrder {
                    natural_pulsation_rad_s: wc,
                } => [s[1], wc * wc * (i - s[0]) - 2.0 * wc * s[1]],
                _ => [(i - s[0]) * rate, 0.0],
            }
        };
        let pieces = (h * rate * STEPS_PER_FASTEST_TIME_CONSTANT)
            .ceil()
            .clamp(1.0, 1e6);
        let du = 1.0 / pieces;
        let hs = h * du;
        let mut s = [x[S1], x[S2]];
        let mut u = 0.0;
        for _ in 0..pieces as usize {
            let k1 = f(s, u);
            let k2 = f(
                [s[0] + 0.5 * hs * k1[0], s[1] + 0.5 * hs * k1[1]],
                u + 0.5 * du,
            );
            let k3 = f(
                [s[0] + 0.5 * hs * k2[0], s[1] + 0.5 * hs * k2[1]],
                u + 0.5 * du,
            );
            let k4 = f([s[0] + hs * k3[0], s[1] + hs * k3[1]], u + du);
            for j in 0..2 {
                s[j] += hs * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j]) / 6.0;
            }
            u += du;
        }
        y[S1] = s[0];
        y[S2] = s[1];
        y
    }

    fn rk4(&self, x: &State, phase: Phase, equilibrium: bool, t: f64, h: f64) -> State {
        let f = |s: &State, tt: f64| self.rates(s, phase, equilibrium, t, tt);
        let k1 = f(x, t);
        let k2 = f(&add_scaled(x, 0.5 * h, &k1), t + 0.5 * h);
        let k3 = f(&add_scaled(x, 0.5 * h, &k2), t + 0.5 * h);
        let k4 = f(&add_scaled(x, h, &k3), t + h);
        let mut y = *x;
        for (j, y_j) in y.iter_mut().enumerate() {
            *y_j += h * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j]) / 6.0;
        }
        if phase == Phase::Stuck {
            y[W] = 0.0;
        }
        y
    }

    /// E(t) \[V\] inside a step that starts at `t_start`. Steps end on the jumps of a step or
    /// piecewise input, so the level of the whole step is the one at its start (read at the
    /// step's end, a jump at that instant would leak into the step before it).
    fn volts_in_step(&self, t_start: f64, t: f64) -> f64 {
        match self.input {
            Input::Step { .. } | Input::Piecewise { .. } => self.input.volts_at(t_start),
            _ => self.input.volts_at(t),
        }
    }

    /// `dx/dt` (module docs of [`crate::withheld`]).
    fn rates(&self, x: &State, phase: Phase, equilibrium: bool, t_start: f64, t: f64) -> State {
        let p = &self.motor;
        let (i, w) = (x[I], x[W]);
        let mut dx: State = [0.0; 8];
        // Resistance at the winding temperature.
        let alpha = match self.slots.thermal {
            Some(PlantEffect::ThermalOneNode { alpha_per_k, .. })
            | Some(PlantEffect::ThermalTwoNode { alpha_per_k, .. }) => alpha_per_k,
            _ => 0.0,
        };
        let r = p.r_ohm * (1.0 + alpha * x[T_WINDING]);
        let inductance = match self.slots.saturation {
            Some(PlantEffect::SaturationLorentzian {
                saturation_current_a,
                min_ratio,
            }) => {
                let u = i / saturation_current_a;
                p.l_henry * (min_ratio + (1.0 - min_ratio) / (1.0 + u * u))
            }
            Some(PlantEffect::SaturationAbsolute {
                saturation_current_a,
                min_ratio,
            }) => {
                // |I| rounded over ROUNDING Isat: a kink at I = 0 would cost RK4 its order at
                // every reversal.
                let knee = SATURATION_ROUNDING * saturation_current_a;
                let magnitude = (i * i + knee * knee).sqrt() - knee;
                p.l_henry
                    * (min_ratio + (1.0 - min_ratio) / (1.0 + magnitude / saturation_current_a))
            }
            _ => p.l_henry,
        };
        let brush = match self.slots.brush {
            Some(PlantEffect::BrushClamp {
                drop_v,
                knee_current_a,
            }) => drop_v * (i / knee_current_a).clamp(-1.0, 1.0),
            Some(PlantEffect::BrushLogarithmic {
                drop_v,
                onset_current_a,
            }) => drop_v * (i.abs() / onset_current_a).ln_1p() * i.signum(),
            _ => 0.0,
        };
        let load = || {
            let drag = match self.slots.drag {
                Some(PlantEffect::DragQuadratic { c_nms2_per_rad2 }) => {
                    c_nms2_per_rad2 * w * w.abs()
                }
                Some(PlantEffect::DragPowerOneAndHalf { c_nm_per_rad_s_pow }) => {
                    c_nm_per_rad_s_pow * w.abs().powf(1.5) * w.signum()
                }
                _ => 0.0,
            };
            self.cogging_torque(x[TH]) + drag + p.f_nms_per_rad * w
        };
        match phase {
            Phase::Stuck => {}
            Phase::Sliding(d) => {
                let coulomb = match self.slots.friction {
                    Some(PlantEffect::StribeckGaussian {
                        static_torque_nm,
                        stribeck_speed_rad_s,
                    }) => {
                        let u = w / stribeck_speed_rad_s;
                        p.ts_nm + (static_torque_nm - p.ts_nm) * (-u * u).exp()
                    }
                    _ => p.ts_nm,
                };
                dx[W] = (p.k_nm_per_a * i - d * coulomb - load()) / p.j_kgm2;
                dx[TH] = w;
            }
            Phase::Bristle => {
                let (sigma0, sigma1) = match self.slots.friction {
                    Some(PlantEffect::LuGre {
                        bristle_stiffness_nm_per_rad,
                        bristle_damping_nms_per_rad,
                        ..
                    }) => (bristle_stiffness_nm_per_rad, bristle_damping_nms_per_rad),
                    _ => (0.0, 0.0),
                };
                let friction = if equilibrium {
                    self.lugre_level(w) * w.signum()
                } else {
                    dx[Z] = w - sigma0 * w.abs() * x[Z] / self.lugre_level(w);
                    sigma0 * x[Z] + sigma1 * dx[Z]
                };
                dx[W] = (p.k_nm_per_a * i - friction - load()) / p.j_kgm2;
                dx[TH] = w;
            }
        }
        let back_emf = p.k_nm_per_a * w;
        dx[I] = (self.volts_in_step(t_start, t) - brush - r * i - back_emf) / inductance;
        let copper_loss = i * i * r;
        match self.slots.thermal {
            Some(PlantEffect::ThermalOneNode {
                thermal_resistance_k_per_w,
                thermal_capacity_j_per_k,
                ..
            }) => {
                dx[T_WINDING] = (copper_loss - x[T_WINDING] / thermal_resistance_k_per_w)
                    / thermal_capacity_j_per_k;
            }
            Some(PlantEffect::ThermalTwoNode {
                winding_capacity_j_per_k,
                winding_to_housing_k_per_w,
                housing_capacity_j_per_k,
                housing_to_ambient_k_per_w,
                ..
            }) => {
                let to_housing = (x[T_WINDING] - x[T_HOUSING]) / winding_to_housing_k_per_w;
                dx[T_WINDING] = (copper_loss - to_housing) / winding_capacity_j_per_k;
                dx[T_HOUSING] = (to_housing - x[T_HOUSING] / housing_to_ambient_k_per_w)
                    / housing_capacity_j_per_k;
            }
            _ => {}
        }
        dx
    }
}

/// Largest slope `|dT_cog/dθ|` of a cogging profile \[N·m/rad\] (a bound: the sum of the
/// harmonics' slopes).
fn cogging_stiffness(c: &PlantEffect) -> f64 {
    match *c {
        PlantEffect::CoggingSine {
            amplitude_nm,
            periods_per_rev,
            ..
        } => amplitude_nm * f64::from(periods_per_rev),
        PlantEffect::CoggingHarmonics {
            amplitude_nm,
            periods_per_rev,
            second_ratio,
            third_ratio,
            ..
        } => {
            amplitude_nm
                * f64::from(periods_per_rev)
                * (1.0 + 2.0 * second_ratio.abs() + 3.0 * third_ratio.abs())
        }
        _ => 0.0,
    }
}

fn add_scaled(x: &State, a: f64, y: &State) -> State {
    let mut out = *x;
    for (o, y_j) in out.iter_mut().zip(y) {
        *o += a * y_j;
    }
    out
}

/// Simulates `input` on `motor` with `effects` through the benchmark's own plant, for
/// `duration_s` \[s\] sampled at `rate_hz` \[Hz\] from rest.
pub fn simulate_plant(
    motor: &MotorParams,
    effects: &[PlantEffect],
    input: &Input,
    duration_s: f64,
    rate_hz: f64,
) -> Result<Trace, ModelError> {
    Plant::new(*motor, effects, input.clone())?.run(duration_s, rate_hz)
}
