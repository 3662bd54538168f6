//! The stick-slip simulator of Appendix D, with pluggable effects.
//!
//! The state is `x = [I, Ω, θ, x_e…]`: armature current \[A\], speed \[rad/s\], angle \[rad\],
//! then the states each effect that is on has of its own (the winding temperature rise ΔT \[K\]
//! of thermal drift, the current I_f \[A\] seen by a lagging sensor), laid out when the
//! simulator is built: the nominal model integrates three states. Two modes:
//!
//! - **stuck**: `Ω ≡ 0` exactly, `L(I) dI/dt = E − V(I) − R(x) I`; the rotor stays at rest
//!   while the torque it feels, `|k I − T_load(0, θ)|`, does not exceed the static friction
//!   (`T_c(0)`: `Ts`, or `Tst` with Stribeck friction);
//! - **moving** in direction `d = ±1`: Eq. (2) with the effects,
//!   `L(I) dI/dt = E − V(I) − R(x) I − k Ω`,
//!   `J dΩ/dt = k I − f Ω − d T_c(Ω) − T_load(Ω, θ)`.
//!
//! Each effect's part (`L(I)`, `V(I)`, `R(x)`, `T_load`, `T_c`, its own states) is its own
//! [`Dynamics`](super::dynamics) implementation.
//!
//! The nominal model under a step or piecewise-constant voltage is propagated exactly, each
//! mode being linear between the voltage's jumps (the matrix exponential,
//! switching instants located within the sample). Otherwise integration is classical RK4 with a step of at most 1/40 of the fastest time constant (and,
//! with cogging, of a cogging period at the current speed — or at a speed bound given up front,
//! [`Simulator::with_speed_bound`], so that the step does not depend on the state). A lagging
//! current sensor's state, a one-way first-order filter of I, is advanced exactly over each
//! step on the cubic through I's values and slopes at its ends, so that a filter far faster
//! than the plant neither bounds the step nor makes it unstable. The
//! switching instants (breakaway, and each zero crossing of Ω, where the rotor sticks again or
//! reverses) are located by bisection to 2⁻⁴⁸ of a step, so the stuck intervals are exact to
//! far below the sample period.

use super::dynamics::Dynamics;
use super::effects::{Effect, Effects};
use super::exact::ExactPropagator;
use super::input::Input;
use crate::derived::signed_damped_pulsation_sq;
use crate::error::{positive, ModelError};
use crate::params::MotorParams;
use crate::sim::dynamics::STEPS_PER_TIME_CONSTANT;
use crate::sim::trace::{sample_grid, Trace};

/// Bisection iterations locating a mode switch inside one step (2⁻⁴⁸ of the step).
const EVENT_BISECTIONS: u32 = 48;
/// Mode switches allowed inside one integration step before it is accepted as is (guards
/// against chattering at a threshold).
const MAX_EVENTS_PER_STEP: u32 = 8;
/// Most RK4 steps a run may take per sample it produces, on average ([`Simulator::run`]): a
/// time constant 2,500 times below the sample period (a 1 µs electrical one at 1 kHz takes
/// 40,000 a sample, about 6 s a second of record).
pub const MAX_RK4_STEPS_PER_SAMPLE: f64 = 100_000.0;
/// Steps a run may take whatever its length ([`MAX_RK4_STEPS_PER_SAMPLE`] below it).
const MIN_STEP_BUDGET: f64 = 1e6;
/// Steps no run may exceed, however long (minutes of work).
const MAX_STEP_BUDGET: f64 = 1e9;
/// Capacity of the state vector: `[I, Ω, θ]` and the effects' own states.
pub const MAX_STATES: usize = 8;

const I_IDX: usize = 0;
const W_IDX: usize = 1;
const TH_IDX: usize = 2;
/// States of the nominal model.
const PLANT_STATES: usize = 3;
/// The state, `N` = [`Simulator::state_len`] (the integrator is compiled for each size, so
/// that the nominal model integrates three numbers).
type State<const N: usize> = [f64; N];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Stuck,
    Moving(f64),
}

/// An effect that is on, with the place of its own states in the state vector.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Active {
    effect: Effect,
    /// Index of its first own state.
    offset: usize,
    /// Number of its own states.
    states: usize,
}

impl Active {
    fn own<'a, const N: usize>(&self, x: &'a State<N>) -> &'a [f64] {
        &x[self.offset..self.offset + self.states]
    }
}

/// The stick-slip simulator: a motor, its effects and an input waveform.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulator {
    params: MotorParams,
    effects: Effects,
    input: Input,
    /// The effects that are on, in the order of `EFFECT_NAMES`, with their state layout.
    active: Vec<Active>,
    /// Length of the state vector in use.
    n_states: usize,
    /// The state the current sensor reads, if not the armature current.
    sensor: Option<usize>,
    /// The sensor state's filter time constant \[s\], when it is a first-order filter of the
    /// armature current advanced exactly ([`sensor_filter_step`]).
    sensor_tau_s: Option<f64>,
    /// Dry friction holding the rotor at rest \[N·m\].
    static_friction_nm: f64,
    max_step_s: f64,
    /// Whether the step may shorten with the state (cogging at the current speed): not once
    /// a fit has fixed the step or a speed bound is given.
    state_dependent_step: bool,
    /// Armature current \[A\] and speed \[rad/s\] at `t = 0` (rest by default).
    initial: (f64, f64),
    /// Integrate by RK4 even where exact propagation applies ([`Simulator::integrated`]).
    rk4_only: bool,
}

impl Simulator {
    /// A simulator of `params` with `effects`, driven by `input`. Refuses a motor or an effect
    /// value outside its domain ([`Effects::validate`]: every effect parameter, and Stribeck's
    /// Tst at least the motor's Ts).
    pub fn new(params: MotorParams, effects: Effects, input: Input) -> Result<Self, ModelError> {
        params.validate()?;
        effects.validate(&params)?;
        let mut active = Vec::new();
        let mut offset = PLANT_STATES;
        let mut sensor = None;
        let mut sensor_tau_s = None;
        for effect in effects.list() {
            let states = effect.states();
            if offset + states > MAX_STATES {
                return Err(ModelError::InvalidSetting {
                    name: "states of the effects that are on".into(),
                    value: (offset + states) as f64,
                    expected: "at most MAX_STATES states together with I, Ω and θ",
                });
            }
            if let Some(j) = effect.sensor_state() {
                sensor = Some(offset + j);
                sensor_tau_s = effect.sensor_time_constant();
            }
            active.push(Active {
                effect,
                offset,
                states,
            });
            offset += states;
        }
        let static_friction_nm = active
            .iter()
            .rev()
            .find_map(|a| a.effect.dry_friction(params.ts_nm, 0.0))
            .unwrap_or(params.ts_nm);
        let mut sim = Simulator {
            params,
            effects,
            input,
            active,
            n_states: offset,
            sensor,
            sensor_tau_s,
            static_friction_nm,
            max_step_s: f64::INFINITY,
            state_dependent_step: true,
            initial: (0.0, 0.0),
            rk4_only: false,
        };
        sim.max_step_s = sim.fastest_time_constant() / STEPS_PER_TIME_CONSTANT;
        Ok(sim)
    }

    /// The longest RK4 step \[s\] the integrator takes: 1/40 of the fastest time constant.
    pub fn max_step_s(&self) -> f64 {
        self.max_step_s
    }

    /// The effects simulated.
    pub fn effects(&self) -> &Effects {
        &self.effects
    }

    /// Number of states integrated: 3 (`I`, `Ω`, `θ`) and those of the effects that are on.
    pub fn state_len(&self) -> usize {
        self.n_states
    }

    /// The same simulator with its longest RK4 step set to `max_step_s` \[s\] (at most the
    /// default of [`Simulator::max_step_s`]). A fit that differentiates the simulation with
    /// respect to the parameters fixes the step this way, so that the step count does not jump
    /// between neighbouring parameter values: from then on the step no longer shortens with
    /// the state (cogging at the current speed; give [`Simulator::with_speed_bound`] for that).
    pub fn with_max_step(mut self, max_step_s: f64) -> Result<Self, ModelError> {
        let h = positive("max step", max_step_s)?;
        self.max_step_s = self.max_step_s.min(h);
        self.state_dependent_step = false;
        Ok(self)
    }

    /// The same simulator with its longest RK4 step `factor` times the default 1/40 of the
    /// fastest time constant (`factor` in (0, 20]: at 20 a step is half a time constant, inside
    /// RK4's stability bound; the global error grows as the step to the fourth power, about
    /// 1e-6 of the response at 8). The steps an effect needs at speed
    /// ([`Simulator::with_speed_bound`]) are not made longer. For fits that only need the
    /// response to the noise level of a record.
    pub fn with_step_factor(mut self, factor: f64) -> Result<Self, ModelError> {
        let factor = positive("step factor", factor)?;
        if factor > 20.0 {
            return Err(ModelError::InvalidSetting {
                name: "step factor".into(),
                value: factor,
                expected: "at most 20 (half the fastest time constant a step)",
            });
        }
        self.max_step_s *= factor;
        Ok(self)
    }

    /// The same simulator with the steps an effect needs at speed (1/40 of a cogging period)
    /// taken at `|Ω| ≤ speed_rad_s` \[rad/s\] for the whole run rather than at the current
    /// speed: the step count on an interval then does not depend on the state, and the
    /// simulation is smooth in the parameters.
    pub fn with_speed_bound(self, speed_rad_s: f64) -> Result<Self, ModelError> {
        self.bounded(speed_rad_s, None)
    }

    /// [`Simulator::with_speed_bound`], the steps an effect needs at speed taken no shorter
    /// than keeps the integration error it causes in the speed below `tolerance_rad_s`
    /// \[rad/s\] at `|Ω| ≤ speed_rad_s` (for cogging: RK4's error on the speed ripple, which
    /// grows with the speed, is `tolerance_rad_s` at the bound; a quarter ripple period a step
    /// at most, 1/40 at least). A fit gives a small share of its records' noise floor: a step
    /// far longer than 1/40 of a period then changes the simulated record by far less than the
    /// noise.
    pub fn with_speed_bound_and_tolerance(
        self,
        speed_rad_s: f64,
        tolerance_rad_s: f64,
    ) -> Result<Self, ModelError> {
        let tol = positive("speed tolerance", tolerance_rad_s)?;
        self.bounded(speed_rad_s, Some(tol))
    }

    /// The speed bound of [`Simulator::with_speed_bound_and_tolerance`], `tolerance` optional.
    fn bounded(mut self, speed_rad_s: f64, tolerance: Option<f64>) -> Result<Self, ModelError> {
        let w = positive("speed bound", speed_rad_s)?;
        for a in &self.active {
            let h = a.effect.step_limit(&self.params, w, tolerance);
            self.max_step_s = self.max_step_s.min(h);
        }
        self.state_dependent_step = false;
        Ok(self)
    }

    /// The same simulator integrated by RK4 on its step settings even where [`Simulator::run`]
    /// would propagate exactly (the nominal model under a step or piecewise-constant
    /// voltage): to cross-check the two and to measure what exact propagation saves.
    pub fn integrated(mut self) -> Self {
        self.rk4_only = true;
        self
    }

    /// The same simulator started at `t = 0` with armature current `current_a` \[A\] and speed
    /// `speed_rad_s` \[rad/s\] instead of at rest (the angle starts at 0; a lagging current
    /// sensor reads `current_a`, a winding starts at ambient temperature). A rotor started
    /// moving is in the moving mode in the direction of its speed, and sticks only where its
    /// speed next crosses 0 with the torque below the static friction; a rotor started at
    /// speed 0 is stuck while `|k I| ≤ Ts` (the steady state of a voltage below breakaway,
    /// Eq. (1)), else moving towards its torque. Use [`crate::steady_state`] for the state a
    /// constant voltage settles at (Eqs. (4), (5)).
    pub fn with_initial_state(
        mut self,
        current_a: f64,
        speed_rad_s: f64,
    ) -> Result<Self, ModelError> {
        for (name, value) in [
            ("initial current", current_a),
            ("initial speed", speed_rad_s),
        ] {
            if !value.is_finite() {
                return Err(ModelError::InvalidSetting {
                    name: name.into(),
                    value,
                    expected: "a finite number",
                });
            }
        }
        self.initial = (current_a, speed_rad_s);
        Ok(self)
    }

    /// Simulates `duration_s` \[s\] from rest (or the state of
    /// [`Simulator::with_initial_state`]), sampled at `rate_hz` \[Hz\] (`t = 0, 1/rate, …`).
    ///
    /// The nominal model under a step or piecewise-constant voltage is propagated exactly
    /// (the matrix exponential of each mode): its step settings do not apply and
    /// a sample costs the same whatever the ratio of the sample period to the time constants.
    /// Every other model and input is integrated by RK4 (module docs).
    pub fn run(&self, duration_s: f64, rate_hz: f64) -> Result<Trace, ModelError> {
        let (n, dt) = sample_grid(duration_s, rate_hz)?;
        if self.active.is_empty() && !self.rk4_only {
            if let Some(trace) = ExactPropagator::new(&self.params, &self.input)
                .and_then(|exact| exact.run(n, dt, self.initial))
            {
                return Ok(trace);
            }
        }
        // The work bound: refused at once where the step alone exceeds it, else counted (an
        // effect's step may shorten with the state).
        let budget = (MAX_RK4_STEPS_PER_SAMPLE * n as f64).clamp(MIN_STEP_BUDGET, MAX_STEP_BUDGET);
        let needed = n as f64 * (dt / self.max_step_s).ceil().max(1.0);
        if needed > budget {
            return Err(self.too_stiff(budget, 0.0));
        }
        match self.n_states {
            3 => self.run_sized::<3>(n, dt, budget),
            4 => self.run_sized::<4>(n, dt, budget),
            5 => self.run_sized::<5>(n, dt, budget),
            6 => self.run_sized::<6>(n, dt, budget),
            7 => self.run_sized::<7>(n, dt, budget),
            _ => self.run_sized::<MAX_STATES>(n, dt, budget),
        }
    }

    /// The refusal of a run that would take more than `budget` RK4 steps, `at_s` \[s\] where
    /// it ran out (0: refused before the start).
    fn too_stiff(&self, budget: f64, at_s: f64) -> ModelError {
        ModelError::TooStiff {
            budget,
            at_s,
            max_step_s: self.max_step_s,
        }
    }

    /// [`Simulator::run`] on `n` samples every `dt` \[s\] with a state of `N` numbers, in at
    /// most `budget` RK4 steps; refused where the state leaves the finite numbers.
    fn run_sized<const N: usize>(
        &self,
        n: usize,
        dt: f64,
        budget: f64,
    ) -> Result<Trace, ModelError> {
        let mut trace = Trace::with_capacity(n);
        let sensor = self.sensor.filter(|&s| s < N).unwrap_or(I_IDX);
        let mut x: State<N> = [0.0; N];
        let (i0, w0) = self.initial;
        x[I_IDX] = i0;
        x[sensor] = i0;
        x[W_IDX] = w0;
        let mut mode = if w0 == 0.0 {
            self.mode_at_rest(&x)
        } else {
            Mode::Moving(w0.signum())
        };
        let mut t = 0.0;
        let mut left = budget;
        for i in 0..n {
            let t_i = i as f64 * dt;
            // Integrate to t_i, splitting at every jump of E(t) on the way.
            while let Some(t_jump) = self.input.next_jump_after(t).filter(|&tj| tj < t_i) {
                t = self.integrate(&mut x, &mut mode, t, t_jump, &mut left);
                if t < t_jump {
                    return Err(self.too_stiff(budget, t));
                }
            }
            if t_i > t {
                t = self.integrate(&mut x, &mut mode, t, t_i, &mut left);
                if t < t_i {
                    return Err(self.too_stiff(budget, t));
                }
            }
            if !x.iter().all(|v| v.is_finite()) {
                return Err(ModelError::Diverged { at_s: t_i });
            }
            trace.t.push(t_i);
            trace.voltage.push(self.input.volts_at(t_i));
            trace.armature_current.push(x[I_IDX]);
            trace.current.push(x[sensor]);
            trace.speed.push(x[W_IDX]);
            trace.position.push(x[TH_IDX]);
            trace.stuck.push(mode == Mode::Stuck);
        }
        Ok(trace)
    }

    /// Advances `x` from `t_from` to `t_to` in RK4 steps no longer than the plant allows, each
    /// taken from the `left` steps of the run's budget: the time reached (`t_to`, or earlier
    /// where the budget ran out).
    fn integrate<const N: usize>(
        &self,
        x: &mut State<N>,
        mode: &mut Mode,
        t_from: f64,
        t_to: f64,
        left: &mut f64,
    ) -> f64 {
        // A step or piecewise-constant voltage is split at its jumps (`run_sized`), so it holds
        // one level over the whole interval: read once, not at every RK4 stage.
        let held = matches!(self.input, Input::Step { .. } | Input::Piecewise { .. })
            .then(|| self.input.volts_at(t_from));
        let mut t = t_from;
        while t < t_to {
            let mut h = self.max_step_s;
            if self.state_dependent_step {
                for a in &self.active {
                    h = h.min(a.effect.step_limit(&self.params, x[W_IDX], None));
                }
            }
            let remaining = t_to - t;
            // Spread the steps evenly over the remaining interval.
            let steps = (remaining / h).ceil().max(1.0);
            if *left < 1.0 {
                return t;
            }
            *left -= 1.0;
            let h = remaining / steps;
            self.step_with_events(x, mode, t, h, t_to, held);
            t = if steps <= 1.0 { t_to } else { t + h };
        }
        t_to
    }
    /// One RK4 step of length `h` from `t`, switching mode at breakaway and zero crossings.
    ///
    /// `t_end` is the end of the interval being integrated: the input is taken as its value
    /// just before `t_end` there (a jump of E(t) at `t_end` belongs to the next interval).
    /// `held`: the voltage over the whole interval when it holds one level.
    fn step_with_events<const N: usize>(
        &self,
        x: &mut State<N>,
        mode: &mut Mode,
        t: f64,
        h: f64,
        t_end: f64,
        held: Option<f64>,
    ) {
        let mut t = t;
        let mut left = h;
        for _ in 0..MAX_EVENTS_PER_STEP {
            let x1 = self.rk4(x, *mode, t, left, t_end, held);
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
                let xm = self.rk4(x, *mode, t, mid * left, t_end, held);
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
            let mut xs = self.rk4(x, *mode, t, hi * left, t_end, held);
            xs[W_IDX] = 0.0;
            *mode = self.mode_at_rest(&xs);
            *x = xs;
            t += hi * left;
            left *= 1.0 - hi;
            if left <= 0.0 {
                return;
            }
        }
        *x = self.rk4(x, *mode, t, left, t_end, held);
    }

    /// Torque acting on the rotor at rest apart from friction \[N·m\]: `k I − T_load(0, θ)`.
    fn torque_at_rest<const N: usize>(&self, x: &State<N>) -> f64 {
        let load: f64 = self
            .active
            .iter()
            .map(|a| a.effect.load_torque(0.0, x[TH_IDX]))
            .sum();
        self.params.k_nm_per_a * x[I_IDX] - load
    }

    fn breaks_away<const N: usize>(&self, x: &State<N>) -> bool {
        self.torque_at_rest(x).abs() > self.static_friction_nm
    }

    /// The mode of a rotor at rest: stuck while friction can hold it, else moving towards the
    /// torque.
    fn mode_at_rest<const N: usize>(&self, x: &State<N>) -> Mode {
        let torque = self.torque_at_rest(x);
        if torque.abs() > self.static_friction_nm {
            Mode::Moving(torque.signum())
        } else {
            Mode::Stuck
        }
    }

    /// One classical RK4 step of length `h` from `t`, inside an interval ending at `t_end`
    /// with no jump of the input before it: the stages take the input's left limit at
    /// `t_end` (evaluating a piecewise-constant input after its jump in the last stage would
    /// apply the new level for a sixth of the step); `held`, the level of an input that holds
    /// one over the interval, read once by the caller.
    fn rk4<const N: usize>(
        &self,
        x: &State<N>,
        mode: Mode,
        t: f64,
        h: f64,
        t_end: f64,
        held: Option<f64>,
    ) -> State<N> {
        // t and t + h/2 lie before t_end; only the last stage can reach it.
        let (v_start, v_mid, v_end) = match held {
            Some(v) => (v, v, v),
            None => {
                let t4 = t + h;
                (
                    self.input.volts_at(t),
                    self.input.volts_at(t + 0.5 * h),
                    self.input
                        .volts_at(if t4 >= t_end { t_end.next_down() } else { t4 }),
                )
            }
        };
        let k1 = self.derivative(x, mode, v_start);
        let k2 = self.derivative(&axpy(x, 0.5 * h, &k1), mode, v_mid);
        let k3 = self.derivative(&axpy(x, 0.5 * h, &k2), mode, v_mid);
        let k4 = self.derivative(&axpy(x, h, &k3), mode, v_end);
        let mut out = *x;
        for (i, o) in out.iter_mut().enumerate() {
            *o += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if mode == Mode::Stuck {
            out[W_IDX] = 0.0;
        }
        if let (Some(s), Some(tau)) = (self.sensor.filter(|&s| s < N), self.sensor_tau_s) {
            // The current's slope at the step's end, for the cubic the filter is advanced on.
            let di_end = self.derivative(&out, mode, v_end)[I_IDX];
            out[s] = sensor_filter_step(x[s], tau, h, [x[I_IDX], k1[I_IDX], out[I_IDX], di_end]);
        }
        out
    }

    /// `dx/dt` of the state in the given mode under armature voltage `volts` \[V\] (module
    /// docs).
    fn derivative<const N: usize>(&self, x: &State<N>, mode: Mode, volts: f64) -> State<N> {
        let p = &self.params;
        let i = x[I_IDX];
        let w = x[W_IDX];
        let (mut r, mut l, mut v_drop) = (p.r_ohm, p.l_henry, 0.0);
        for a in &self.active {
            let d = a.effect;
            r *= d.resistance_factor(a.own(x));
            l *= d.inductance_factor(i);
            v_drop += d.voltage_drop(i);
        }
        let mut dx: State<N> = [0.0; N];
        let back_emf = match mode {
            Mode::Stuck => 0.0,
            Mode::Moving(dir) => {
                let mut coulomb = p.ts_nm;
                let mut load = 0.0;
                for a in &self.active {
                    let d = a.effect;
                    load += d.load_torque(w, x[TH_IDX]);
                    if let Some(c) = d.dry_friction(p.ts_nm, w) {
                        coulomb = c;
                    }
                }
                let torque = p.k_nm_per_a * i - p.f_nms_per_rad * w - dir * coulomb - load;
                dx[W_IDX] = torque / p.j_kgm2;
                dx[TH_IDX] = w;
                p.k_nm_per_a * w
            }
        };
        dx[I_IDX] = (volts - v_drop - r * i - back_emf) / l;
        for a in &self.active {
            let (own, d_own) = (a.own(x), &mut dx[a.offset..a.offset + a.states]);
            a.effect.derivative(i, r, own, d_own);
        }
        dx
    }

    /// The fastest time constant \[s\] among the plant's modes and the effects' own dynamics.
    fn fastest_time_constant(&self) -> f64 {
        let p = &self.params;
        let sigma = 0.5 * (p.r_ohm / p.l_henry + p.f_nms_per_rad / p.j_kgm2);
        let q = signed_damped_pulsation_sq(p);
        let omega_n = (p.rf_plus_k2() / (p.l_henry * p.j_kgm2)).sqrt();
        // Fastest pole magnitude: σ + ωa when overdamped, ωn otherwise.
        let mut fastest_rate = if q > 0.0 { sigma + q.sqrt() } else { omega_n };
        // Electrical pole while stuck, with the smallest inductance and the effects' extra
        // resistance (a brush film).
        let (mut l_min, mut r_extra) = (p.l_henry, 0.0);
        for a in &self.active {
            let d = a.effect;
            l_min *= d.min_inductance_factor();
            r_extra += d.incremental_resistance();
            fastest_rate = fastest_rate.max(d.own_rate(p));
        }
        fastest_rate = fastest_rate.max((p.r_ohm + r_extra) / l_min);
        1.0 / fastest_rate
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

/// Terms of the series of [`sensor_filter_step`]'s integrals below `z = 1` (the last term
/// is below 1/19! of the first).
const FILTER_SERIES_TERMS: usize = 16;

/// The output `y(h)` of the first-order filter `τ dy/dt = p(t) − y` over one step of `h` \[s\]
/// from `y0`, for the cubic `p` through `ends = [p(0), p'(0), p(h), p'(h)]` (Hermite): exact
/// for that cubic whatever `h/τ`, so that a filter far faster than the plant neither bounds
/// the step nor goes unstable (RK4 would need `h < 2.8 τ`). With `z = h/τ` and `p` written in
/// `s = t/h` as `Σ c_k s^k`, `y(h) = e^{−z} y0 + z Σ c_k I_k`, `I_k = ∫₀¹ e^{−zu} (1 − u)^k du`:
/// by the series `k! Σ_m (−z)^m/(m + k + 1)!` below `z = 1`, by the recurrence
/// `z I_k = 1 − k I_{k−1}` (errors grow at most k/z a step) above.
fn sensor_filter_step(y0: f64, tau: f64, h: f64, ends: [f64; 4]) -> f64 {
    let c = hermite_in_step_fraction(h, ends);
    let z = h / tau;
    let mut integral = [0.0_f64; 4];
    if z < 1.0 {
        let mut factorial_k = 1.0;
        for (k, ik) in integral.iter_mut().enumerate() {
            if k > 0 {
                factorial_k *= k as f64;
            }
            // Σ_m (−z)^m / (m + k + 1)!, its first term 1/(k + 1)!.
            let mut term = 1.0 / (factorial_k * (k as f64 + 1.0));
            let mut sum = term;
            for m in 1..FILTER_SERIES_TERMS {
                term *= -z / (m + k + 1) as f64;
                sum += term;
            }
            *ik = factorial_k * sum;
        }
    } else {
        integral[0] = -(-z).exp_m1() / z;
        for k in 1..4 {
            integral[k] = (1.0 - k as f64 * integral[k - 1]) / z;
        }
    }
    let forced: f64 = c.iter().zip(&integral).map(|(ck, ik)| ck * ik).sum();
    (-z).exp() * y0 + z * forced
}

/// Coefficients `c_k` of the cubic Hermite `p(s) = Σ c_k s^k`, `s = t/h`, through
/// `ends = [p(0), p'(0), p(h), p'(h)]` over a step of `h` \[s\] (slopes per second).
fn hermite_in_step_fraction(h: f64, ends: [f64; 4]) -> [f64; 4] {
    let [p0, d0, p1, d1] = ends;
    [
        p0,
        h * d0,
        3.0 * (p1 - p0) - h * (2.0 * d0 + d1),
        2.0 * (p0 - p1) + h * (d0 + d1),
    ]
}

fn axpy<const N: usize>(x: &State<N>, a: f64, y: &State<N>) -> State<N> {
    let mut out = *x;
    for (o, yi) in out.iter_mut().zip(y) {
        *o += a * yi;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::effects::{BrushDrop, QuadraticDrag, ThermalDrift};

    fn paper_with(effect: Effect) -> Result<Trace, ModelError> {
        Simulator::new(
            MotorParams::paper(),
            Effects::none().with(effect),
            Input::step(40.0, 0.0)?,
        )?
        .run(0.5, 1000.0)
    }

    /// A brush drop whose knee (10 nA) makes the paper's motor's electrical time constant
    /// L/(R + Vb/I_knee) = 0.3/(0.3 + 3e7) ≈ 1e-8 s, 1e-5 of the 1 ms sample period: refused
    /// before the start (2e9 steps over 501 samples), not run for many minutes.
    #[test]
    fn a_run_beyond_its_step_budget_is_refused_before_it_starts() {
        let err = paper_with(Effect::BrushDrop(BrushDrop {
            drop_v: 0.3,
            knee_current_a: 1e-8,
        }))
        .expect_err("refused");
        match err {
            ModelError::TooStiff { budget, at_s, .. } => {
                assert_eq!(at_s, 0.0);
                assert_eq!(budget, MAX_RK4_STEPS_PER_SAMPLE * 501.0);
            }
            other => panic!("{other}"),
        }
        // A sharp but reachable knee still runs.
        assert!(paper_with(Effect::BrushDrop(BrushDrop {
            drop_v: 0.3,
            knee_current_a: 0.05,
        }))
        .is_ok());
    }

    /// A winding whose resistance grows by a factor of a million per kelvin heats without
    /// bound: refused, where the run used to return a trace of NaN.
    #[test]
    fn a_run_whose_state_leaves_the_finite_numbers_is_refused() {
        let err = paper_with(Effect::ThermalDrift(ThermalDrift {
            thermal_resistance_k_per_w: 1e6,
            thermal_capacity_j_per_k: 1e-6,
            alpha_per_k: 1e6,
        }))
        .expect_err("refused");
        assert!(matches!(err, ModelError::Diverged { .. }), "{err}");
    }

    /// A quadratic drag strong enough to make RK4 unstable at the plant's step (on the small
    /// servo, `c = 3000` ran to −1e9 rad/s under +12 V, finite and exit 0): the drag's own
    /// time constant bounds the step, and the speed stays where the drag holds it, between 0
    /// and the speed at which `c Ω² = k I` at stall, `√(k E/(R c))`.
    #[test]
    fn a_strong_quadratic_drag_bounds_the_step_and_stays_stable() {
        let servo = MotorParams::new(2.0, 0.002, 0.05, 0.0004, 2e-5, 0.004).unwrap();
        let c = 3000.0;
        let trace = Simulator::new(
            servo,
            Effects::none().with(Effect::QuadraticDrag(QuadraticDrag { c_nms2_per_rad2: c })),
            Input::step(12.0, 0.0).unwrap(),
        )
        .unwrap()
        .run(0.05, 5000.0)
        .unwrap();
        let ceiling = (0.05 * 12.0 / (2.0 * c)).sqrt();
        for w in &trace.speed {
            assert!((0.0..=ceiling).contains(w), "{w} outside [0, {ceiling}]");
        }
    }

    /// The filter's output over one step by many small RK4 steps on the same cubic.
    fn by_small_steps(y0: f64, tau: f64, h: f64, ends: [f64; 4]) -> f64 {
        let c = hermite_in_step_fraction(h, ends);
        let p = |t: f64| {
            let s = t / h;
            c[0] + s * (c[1] + s * (c[2] + s * c[3]))
        };
        let n = 200_000;
        let dt = h / n as f64;
        let f = |t: f64, y: f64| (p(t) - y) / tau;
        let mut y = y0;
        for i in 0..n {
            let t = i as f64 * dt;
            let k1 = f(t, y);
            let k2 = f(t + 0.5 * dt, y + 0.5 * dt * k1);
            let k3 = f(t + 0.5 * dt, y + 0.5 * dt * k2);
            let k4 = f(t + dt, y + dt * k3);
            y += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
        y
    }

    #[test]
    fn the_sensor_filter_step_is_exact_on_a_cubic_at_every_ratio_of_step_to_time_constant() {
        let h = 1e-3;
        let ends = [0.3, 800.0, 1.1, -250.0];
        // Either side of the switch from the series to the recurrence (z = 1), and far on
        // both sides.
        for z in [1e-4, 0.05, 0.7, 0.999_999, 1.000_001, 2.5, 40.0] {
            let tau = h / z;
            let exact = sensor_filter_step(-0.2, tau, h, ends);
            let reference = by_small_steps(-0.2, tau, h, ends);
            assert!(
                (exact - reference).abs() < 1e-9,
                "z = {z}: {exact} against {reference}"
            );
        }
        // Far faster than the step: the output is `p − τ p' + τ² p''` at the step's end (the
        // start forgotten; p'' = −4.2e6 there), where RK4 on the step would blow up.
        let tau = 1e-9;
        let y = sensor_filter_step(5.0, tau, h, ends);
        let steady = 1.1 + 250.0 * tau - 4.2e6 * tau * tau;
        assert!((y - steady).abs() < 1e-14, "{y} against {steady}");
        // A constant input from rest: 1 − e^{−z}.
        let y = sensor_filter_step(0.0, 2e-3, h, [1.0, 0.0, 1.0, 0.0]);
        assert!((y + (-0.5_f64).exp_m1()).abs() < 1e-15, "{y}");
    }
}
