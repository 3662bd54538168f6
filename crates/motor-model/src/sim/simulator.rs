//! The stick-slip simulator of Appendix D, with pluggable effects.
//!
//! The state is `x = [I, Ω, θ, ΔT, I_f]`: armature current \[A\], speed \[rad/s\], angle \[rad\],
//! winding temperature rise \[K\] (thermal drift) and the current seen by the sensor \[A\]
//! (sensor lag). Two modes:
//!
//! - **stuck**: `Ω ≡ 0` exactly, `L(I) dI/dt = E − V_brush(I) − R(ΔT) I`; the rotor stays at rest
//!   while the torque it feels, `|k I − T_cog(θ)|`, does not exceed the static friction
//!   (`Ts`, or `Tst` with Stribeck friction);
//! - **moving** in direction `d = ±1`: Eq. (2) with the effects,
//!   `L(I) dI/dt = E − V_brush(I) − R(ΔT) I − k Ω`,
//!   `J dΩ/dt = k I − f Ω − d T_c(Ω) − T_cog(θ) − c Ω|Ω|`.
//!
//! Integration is classical RK4 with a step of at most 1/40 of the fastest time constant. The
//! switching instants (breakaway, and each zero crossing of Ω, where the rotor sticks again or
//! reverses) are located by bisection to 2⁻⁴⁸ of a step, so the stuck intervals are exact to
//! far below the sample period.

use serde::Serialize;

use super::effects::Effects;
use super::input::Input;
use crate::derived::signed_damped_pulsation_sq;
use crate::error::{positive, ModelError};
use crate::params::MotorParams;

/// RK4 steps per fastest time constant of the plant (global error ≈ 1e-8 of the response).
const STEPS_PER_TIME_CONSTANT: f64 = 40.0;
/// RK4 steps per cogging period at the current speed.
const STEPS_PER_COGGING_PERIOD: f64 = 40.0;
/// Bisection iterations locating a mode switch inside one step (2⁻⁴⁸ of the step).
const EVENT_BISECTIONS: u32 = 48;
/// Mode switches allowed inside one integration step before it is accepted as is (guards
/// against chattering at a threshold).
const MAX_EVENTS_PER_STEP: u32 = 8;
/// Longest record the simulator will produce, in samples (about 80 MB of output).
pub const MAX_SAMPLES: usize = 10_000_000;

const I_IDX: usize = 0;
const W_IDX: usize = 1;
const TH_IDX: usize = 2;
const DT_IDX: usize = 3;
const IF_IDX: usize = 4;
type State = [f64; 5];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Stuck,
    Moving(f64),
}

/// A simulated record at the plant (before the measurement model), SI units.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Trace {
    /// Sample times \[s\].
    pub t: Vec<f64>,
    /// Armature voltage E(t) applied \[V\].
    pub voltage: Vec<f64>,
    /// Current seen by the current sensor \[A\] (equals the armature current unless
    /// `current_sensor_lag` is on).
    pub current: Vec<f64>,
    /// True armature current \[A\].
    pub armature_current: Vec<f64>,
    /// Speed Ω \[rad/s\].
    pub speed: Vec<f64>,
    /// Angle θ \[rad\].
    pub position: Vec<f64>,
    /// Whether the rotor was stuck (Coulomb friction holding it) at the sample.
    pub stuck: Vec<bool>,
}

/// The stick-slip simulator: a motor, its effects and an input waveform.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulator {
    params: MotorParams,
    effects: Effects,
    input: Input,
    max_step_s: f64,
}

impl Simulator {
    /// A simulator of `params` with `effects`, driven by `input`.
    pub fn new(params: MotorParams, effects: Effects, input: Input) -> Result<Self, ModelError> {
        params.validate()?;
        if let Some(s) = effects.stribeck_friction {
            if s.static_torque_nm < params.ts_nm {
                return Err(ModelError::InvalidSetting {
                    name: "stribeck_friction tst".into(),
                    value: s.static_torque_nm,
                    expected: "a static torque at least the motor's Coulomb torque Ts",
                });
            }
        }
        let max_step_s = fastest_time_constant(&params, &effects) / STEPS_PER_TIME_CONSTANT;
        Ok(Simulator {
            params,
            effects,
            input,
            max_step_s,
        })
    }

    /// The longest RK4 step \[s\] the integrator takes: 1/40 of the fastest time constant.
    pub fn max_step_s(&self) -> f64 {
        self.max_step_s
    }

    /// The same simulator with its longest RK4 step set to `max_step_s` \[s\] (at most the
    /// default of [`Simulator::max_step_s`]). A fit that differentiates the simulation with
    /// respect to the parameters fixes the step this way, so that the step count does not jump
    /// between neighbouring parameter values.
    pub fn with_max_step(mut self, max_step_s: f64) -> Result<Self, ModelError> {
        let h = positive("max step", max_step_s)?;
        self.max_step_s = self.max_step_s.min(h);
        Ok(self)
    }

    /// Simulates `duration_s` \[s\] from rest, sampled at `rate_hz` \[Hz\] (`t = 0, 1/rate, …`).
    pub fn run(&self, duration_s: f64, rate_hz: f64) -> Result<Trace, ModelError> {
        let (n, dt) = sample_grid(duration_s, rate_hz)?;
        let mut trace = Trace {
            t: Vec::with_capacity(n),
            voltage: Vec::with_capacity(n),
            current: Vec::with_capacity(n),
            armature_current: Vec::with_capacity(n),
            speed: Vec::with_capacity(n),
            position: Vec::with_capacity(n),
            stuck: Vec::with_capacity(n),
        };
        let mut x: State = [0.0; 5];
        let mut mode = Mode::Stuck;
        let mut t = 0.0;
        for i in 0..n {
            let t_i = i as f64 * dt;
            // Integrate to t_i, splitting at every jump of E(t) on the way.
            while let Some(t_jump) = self.input.next_jump_after(t).filter(|&tj| tj < t_i) {
                self.integrate(&mut x, &mut mode, t, t_jump);
                t = t_jump;
            }
            if t_i > t {
                self.integrate(&mut x, &mut mode, t, t_i);
                t = t_i;
            }
            trace.t.push(t_i);
            trace.voltage.push(self.input.volts_at(t_i));
            trace.armature_current.push(x[I_IDX]);
            trace
                .current
                .push(if self.effects.current_sensor_lag.is_some() {
                    x[IF_IDX]
                } else {
                    x[I_IDX]
                });
            trace.speed.push(x[W_IDX]);
            trace.position.push(x[TH_IDX]);
            trace.stuck.push(mode == Mode::Stuck);
        }
        Ok(trace)
    }

    /// Advances `x` from `t_from` to `t_to` in RK4 steps no longer than the plant allows.
    fn integrate(&self, x: &mut State, mode: &mut Mode, t_from: f64, t_to: f64) {
        let mut t = t_from;
        while t < t_to {
            let mut h = self.max_step_s;
            if let Some(c) = self.effects.cogging_torque {
                let w = x[W_IDX].abs() * f64::from(c.periods_per_rev);
                if w > 0.0 {
                    h = h.min(std::f64::consts::TAU / w / STEPS_PER_COGGING_PERIOD);
                }
            }
            let remaining = t_to - t;
            // Spread the steps evenly over the remaining interval.
            let steps = (remaining / h).ceil().max(1.0);
            let h = remaining / steps;
            self.step_with_events(x, mode, t, h);
            t = if steps <= 1.0 { t_to } else { t + h };
        }
    }

    /// One RK4 step of length `h` from `t`, switching mode at breakaway and zero crossings.
    fn step_with_events(&self, x: &mut State, mode: &mut Mode, t: f64, h: f64) {
        let mut t = t;
        let mut left = h;
        for _ in 0..MAX_EVENTS_PER_STEP {
            let x1 = self.rk4(x, *mode, t, left);
            let switched = match *mode {
                Mode::Stuck => self.breaks_away(&x1),
                Mode::Moving(d) => d * x1[W_IDX] < 0.0,
            };
            if !switched {
                *x = x1;
                return;
            }
            // Smallest fraction s of the step at which the switch has happened.
            let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
            for _ in 0..EVENT_BISECTIONS {
                let mid = 0.5 * (lo + hi);
                let xm = self.rk4(x, *mode, t, mid * left);
                let happened = match *mode {
                    Mode::Stuck => self.breaks_away(&xm),
                    Mode::Moving(d) => d * xm[W_IDX] <= 0.0,
                };
                if happened {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let mut xs = self.rk4(x, *mode, t, hi * left);
            xs[W_IDX] = 0.0;
            *mode = self.mode_at_rest(&xs);
            *x = xs;
            t += hi * left;
            left *= 1.0 - hi;
            if left <= 0.0 {
                return;
            }
        }
        *x = self.rk4(x, *mode, t, left);
    }

    /// Torque acting on the rotor at rest apart from friction \[N·m\]: `k I − T_cog(θ)`.
    fn torque_at_rest(&self, x: &State) -> f64 {
        self.params.k_nm_per_a * x[I_IDX] - self.cogging(x[TH_IDX])
    }

    /// Friction torque that holds the rotor at rest \[N·m\]: `Tst` or `Ts`.
    fn static_friction(&self) -> f64 {
        self.effects
            .stribeck_friction
            .map_or(self.params.ts_nm, |s| s.static_torque_nm)
    }

    fn breaks_away(&self, x: &State) -> bool {
        self.torque_at_rest(x).abs() > self.static_friction()
    }

    /// The mode of a rotor at rest: stuck while friction can hold it, else moving towards the
    /// torque.
    fn mode_at_rest(&self, x: &State) -> Mode {
        let torque = self.torque_at_rest(x);
        if torque.abs() > self.static_friction() {
            Mode::Moving(torque.signum())
        } else {
            Mode::Stuck
        }
    }

    fn cogging(&self, theta: f64) -> f64 {
        self.effects.cogging_torque.map_or(0.0, |c| {
            c.amplitude_nm * (f64::from(c.periods_per_rev) * theta + c.phase_rad).sin()
        })
    }

    fn rk4(&self, x: &State, mode: Mode, t: f64, h: f64) -> State {
        let k1 = self.derivative(x, mode, t);
        let k2 = self.derivative(&axpy(x, 0.5 * h, &k1), mode, t + 0.5 * h);
        let k3 = self.derivative(&axpy(x, 0.5 * h, &k2), mode, t + 0.5 * h);
        let k4 = self.derivative(&axpy(x, h, &k3), mode, t + h);
        let mut out = *x;
        for (i, o) in out.iter_mut().enumerate() {
            *o += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if mode == Mode::Stuck {
            out[W_IDX] = 0.0;
        }
        out
    }

    /// `dx/dt` of the state in the given mode (module docs).
    fn derivative(&self, x: &State, mode: Mode, t: f64) -> State {
        let p = &self.params;
        let e = &self.effects;
        let i = x[I_IDX];
        let w = x[W_IDX];
        let r = e
            .thermal_drift
            .map_or(p.r_ohm, |th| p.r_ohm * (1.0 + th.alpha_per_k * x[DT_IDX]));
        let l = e.inductance_saturation.map_or(p.l_henry, |s| {
            let u = i / s.saturation_current_a;
            p.l_henry * (s.min_ratio + (1.0 - s.min_ratio) / (1.0 + u * u))
        });
        let v_brush = e
            .brush_drop
            .map_or(0.0, |b| b.drop_v * (i / b.knee_current_a).clamp(-1.0, 1.0));
        let (dw, dth, back_emf) = match mode {
            Mode::Stuck => (0.0, 0.0, 0.0),
            Mode::Moving(d) => {
                let coulomb = e.stribeck_friction.map_or(p.ts_nm, |s| {
                    let u = w / s.stribeck_speed_rad_s;
                    p.ts_nm + (s.static_torque_nm - p.ts_nm) * (-u * u).exp()
                });
                let drag = e
                    .quadratic_drag
                    .map_or(0.0, |q| q.c_nms2_per_rad2 * w * w.abs());
                let torque = p.k_nm_per_a * i
                    - p.f_nms_per_rad * w
                    - d * coulomb
                    - self.cogging(x[TH_IDX])
                    - drag;
                (torque / p.j_kgm2, w, p.k_nm_per_a * w)
            }
        };
        let di = (self.input.volts_at(t) - v_brush - r * i - back_emf) / l;
        let d_temp = e.thermal_drift.map_or(0.0, |th| {
            (i * i * r - x[DT_IDX] / th.thermal_resistance_k_per_w) / th.thermal_capacity_j_per_k
        });
        let d_if = e
            .current_sensor_lag
            .map_or(0.0, |lag| (i - x[IF_IDX]) / lag.tau_f_s);
        [di, dw, dth, d_temp, d_if]
    }
}

/// Simulates `input` on `params` with `effects` for `duration_s` \[s\] at `rate_hz` \[Hz\]:
/// the exact analytic response ([`crate::StepResponse::trace`]) for a step on the nominal
/// model, the stick-slip simulator otherwise. `motorid simulate` and the logger emulator both
/// use it, so that their records agree sample for sample.
pub fn simulate(
    params: &MotorParams,
    effects: Effects,
    input: &Input,
    duration_s: f64,
    rate_hz: f64,
) -> Result<Trace, ModelError> {
    match input {
        Input::Step { volts, at_s } if effects.is_nominal() => {
            crate::StepResponse::new(params, *volts).trace(*at_s, duration_s, rate_hz)
        }
        _ => Simulator::new(*params, effects, input.clone())?.run(duration_s, rate_hz),
    }
}

/// Number of samples `⌊duration·rate⌋ + 1` (t = 0 to `duration_s` \[s\] included) and the
/// sample period \[s\], refusing non-positive settings and records over [`MAX_SAMPLES`].
pub(crate) fn sample_grid(duration_s: f64, rate_hz: f64) -> Result<(usize, f64), ModelError> {
    let duration_s = positive("duration", duration_s)?;
    let rate_hz = positive("sample rate", rate_hz)?;
    let n_f = (duration_s * rate_hz).floor() + 1.0;
    if n_f > MAX_SAMPLES as f64 {
        return Err(ModelError::InvalidSetting {
            name: "duration × rate".into(),
            value: n_f,
            expected: "at most 10,000,000 samples: shorten the record or lower the rate",
        });
    }
    Ok((n_f as usize, 1.0 / rate_hz))
}

fn axpy(x: &State, a: f64, y: &State) -> State {
    let mut out = *x;
    for (o, yi) in out.iter_mut().zip(y) {
        *o += a * yi;
    }
    out
}

/// The fastest time constant \[s\] among the plant's modes and the effects' own dynamics.
fn fastest_time_constant(p: &MotorParams, e: &Effects) -> f64 {
    let sigma = 0.5 * (p.r_ohm / p.l_henry + p.f_nms_per_rad / p.j_kgm2);
    let q = signed_damped_pulsation_sq(p);
    let omega_n = (p.rf_plus_k2() / (p.l_henry * p.j_kgm2)).sqrt();
    // Fastest pole magnitude: σ + ωa when overdamped, ωn otherwise.
    let mut fastest_rate = if q > 0.0 { sigma + q.sqrt() } else { omega_n };
    // Electrical pole while stuck, with the smallest inductance and the brush film resistance.
    let l_min = e
        .inductance_saturation
        .map_or(p.l_henry, |s| p.l_henry * s.min_ratio);
    let r_brush = e.brush_drop.map_or(0.0, |b| b.drop_v / b.knee_current_a);
    fastest_rate = fastest_rate.max((p.r_ohm + r_brush) / l_min);
    if let Some(lag) = e.current_sensor_lag {
        fastest_rate = fastest_rate.max(1.0 / lag.tau_f_s);
    }
    if let Some(c) = e.cogging_torque {
        // Small-oscillation pulsation of the rotor in a cogging well.
        fastest_rate =
            fastest_rate.max((c.amplitude_nm * f64::from(c.periods_per_rev) / p.j_kgm2).sqrt());
    }
    1.0 / fastest_rate
}
