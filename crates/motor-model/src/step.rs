//! Exact step response after breakaway, valid uniformly across ζ < 1, ζ = 1 and ζ > 1.
//!
//! After breakaway the motor obeys the linear system (2). With `x = [I, Ω]ᵀ`,
//! `ẋ = A x + b`, `A = [[−R/L, −k/L], [k/J, −f/J]]`, the deviation `y = x − x_r` from the steady
//! state (4), (5) evolves as `y(τ) = e^{Aτ} y(0)`, `τ = t − t0`. Because the eigenvalues of `A`
//! are `−σ ± √q` with `q = σ² − ωn² = ωn²(ζ² − 1)`, Cayley–Hamilton gives, in every regime,
//!
//! ```text
//! e^{Aτ} = e^{−στ} [ C(τ) 𝟙 + S(τ) (A + σ𝟙) ],
//! C(τ) = Σ (qτ²)ⁿ/(2n)!,   S(τ) = τ Σ (qτ²)ⁿ/(2n+1)!
//! ```
//!
//! i.e. `C = cosh(ωa τ)`, `S = sinh(ωa τ)/ωa` for ζ > 1, `cos`/`sin` for ζ < 1 and `1`, `τ` at
//! ζ = 1. These are entire functions of `q`, so nothing blows up as ζ → 1, unlike α and γ of
//! (24), (25) in the paper's forms (13)–(15), which this module reproduces to rounding error
//! (see the `paper` module and its tests).
//!
//! On a uniform grid `C` and `S` obey the addition rule
//! `C(τ+h) = C(τ)C(h) + q S(τ)S(h)`, `S(τ+h) = S(τ)C(h) + C(τ)S(h)`, so a whole record costs a
//! few multiply-adds per sample and no transcendental function (re-anchored every
//! [`REANCHOR_SAMPLES`] samples to stop rounding from accumulating).

use serde::Serialize;

use crate::error::{non_negative, ModelError};
use crate::params::MotorParams;
use crate::real::Real;
use crate::sim::trace::{sample_grid, Trace};
use crate::steady::{breakaway_generic, steady_generic};

/// Samples between exact re-evaluations of the grid recurrence (bounds rounding drift to
/// about `REANCHOR_SAMPLES` ulps).
pub const REANCHOR_SAMPLES: usize = 512;

/// Largest `σh` for which the grid recurrence is used; beyond it `e^{−σh}` and `cosh(ωa h)`
/// approach the limits of `f64` and each sample is evaluated directly.
const MAX_SIGMA_STEP: f64 = 200.0;

/// Below this `|q τ²|` the series of `C` and `S` is used (8 terms: truncation < 1e-30).
const SERIES_LIMIT: f64 = 1e-2;

/// One instant of a motor's response.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotorState<T = f64> {
    /// Armature current I \[A\].
    pub current_a: T,
    /// Shaft speed Ω \[rad/s\].
    pub speed_rad_s: T,
    /// Shaft angle θ \[rad\], 0 at the step instant.
    pub position_rad: T,
}

/// `(C(τ), S(τ))` of the module docs for signed `q` \[1/s²\] and `τ` \[s\].
pub(crate) fn cosh_sinhc<T: Real>(q: T, tau: T) -> (T, T) {
    let u = q * tau * tau;
    let one = T::cst(1.0);
    if u.value().abs() < SERIES_LIMIT {
        // Horner on Σ uⁿ/(2n)! and Σ uⁿ/(2n+1)!, n = 0..8.
        let mut c = one;
        let mut s = one;
        for n in (1..=8u32).rev() {
            let two_n = f64::from(2 * n);
            c = one + u * c * T::cst(1.0 / (two_n * (two_n - 1.0)));
            s = one + u * s * T::cst(1.0 / (two_n * (two_n + 1.0)));
        }
        (c, tau * s)
    } else if q.value() > 0.0 {
        let w = q.sqrt();
        ((w * tau).cosh(), (w * tau).sinh() / w)
    } else {
        let w = (-q).sqrt();
        ((w * tau).cos(), (w * tau).sin() / w)
    }
}

/// `(e^{−στ}C(τ), e^{−στ}S(τ))` without overflow for any `τ ≥ 0`.
///
/// `omega_n2 = ωn² = σ² − q`. For ζ > 1 and `ωa τ` large the product is split into the slow
/// and fast modes, the slow rate `σ − ωa` being formed as `ωn²/(σ + ωa)` (no cancellation
/// for strongly overdamped motors, τe ≪ τm).
pub(crate) fn decayed_cosh_sinhc<T: Real>(sigma: T, q: T, omega_n2: T, tau: T) -> (T, T) {
    if q.value() > 0.0 {
        let w = q.sqrt();
        if (w * tau).value() > 1.0 {
            let half = T::cst(0.5);
            let fast_rate = sigma + w;
            let slow = (-(omega_n2 / fast_rate) * tau).exp();
            let fast = (-fast_rate * tau).exp();
            return (half * (slow + fast), half * (slow - fast) / w);
        }
    }
    let decay = (-sigma * tau).exp();
    let (c, s) = cosh_sinhc(q, tau);
    (decay * c, decay * s)
}

/// The exact response of a motor at rest to a voltage step `E` applied at `t = 0`:
/// Eq. (10) up to the breakaway instant `t0` (11), then the solution of (2), (3).
///
/// Either sign of `E`: a negative step is the mirror image. When `|E| ≤ R Ts/k` the motor never
/// moves and the current follows (10) for ever.
///
/// Generic over the scalar: `StepResponse<f64>` (the default) for values,
/// `StepResponse<Dual<N>>` for values with exact derivatives with respect to the parameters
/// (see [`StepResponse::from_values`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepResponse<T = f64> {
    r_ohm: T,
    l_henry: T,
    e_abs: T,
    dir: f64,
    t0: Option<T>,
    sigma: T,
    q: T,
    omega_n2: T,
    i_r: T,
    omega_r: T,
    /// `y(0) = x(t0) − x_r`.
    y0: [T; 2],
    /// `(A + σ𝟙) y(0)`.
    w0: [T; 2],
    /// Speed components of `z = A⁻¹ y(0)` and `(A + σ𝟙) z`, for the angle.
    z0_speed: T,
    wz0_speed: T,
}

impl StepResponse<f64> {
    /// Prepares the response of `params` to a step of `e_volt` \[V\].
    pub fn new(params: &MotorParams, e_volt: f64) -> Self {
        StepResponse::from_values(params.values(), e_volt)
    }

    /// A record of this step applied at `at_s` \[s\] (0 V before), sampled at `rate_hz` \[Hz\]
    /// from `t = 0` to `duration_s` \[s\]: the analytic counterpart of [`crate::Simulator::run`].
    pub fn trace(&self, at_s: f64, duration_s: f64, rate_hz: f64) -> Result<Trace, ModelError> {
        let at_s = non_negative("step instant", at_s)?;
        let (n, dt) = sample_grid(duration_s, rate_hz)?;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let before = t.iter().take_while(|&&ti| ti < at_s).count();
        let mut states = vec![MotorState::default(); n];
        if let Some(after) = states.get_mut(before..) {
            let t_first = t.get(before).map_or(0.0, |&ti| ti - at_s);
            self.fill(t_first, dt, after);
        }
        let volts = self.dir * self.e_abs;
        let t0 = self.t0.unwrap_or(f64::INFINITY);
        Ok(Trace {
            voltage: t
                .iter()
                .map(|&ti| if ti >= at_s { volts } else { 0.0 })
                .collect(),
            current: states.iter().map(|s| s.current_a).collect(),
            armature_current: states.iter().map(|s| s.current_a).collect(),
            speed: states.iter().map(|s| s.speed_rad_s).collect(),
            position: states.iter().map(|s| s.position_rad).collect(),
            stuck: t.iter().map(|&ti| ti - at_s <= t0).collect(),
            t,
        })
    }
}

impl<T: Real> StepResponse<T> {
    /// The response for parameters `[R, L, k, f, J, Ts]` (SI units, in any [`Real`] scalar; the
    /// order of [`MotorParams::values`]) to a
    /// step of `e_volt` \[V\]. The parameters are trusted: validate them with
    /// [`MotorParams::validate`] first.
    pub fn from_values(params: [T; 6], e_volt: f64) -> Self {
        let [r, l, k, f, j, ts] = params;
        let half = T::cst(0.5);
        let dir = if e_volt < 0.0 { -1.0 } else { 1.0 };
        let e_abs = T::cst(e_volt.abs());
        let rf_k2 = r * f + k * k;
        let t0 = breakaway_generic(r, l, k, ts, e_abs);
        let (i_r, omega_r) = steady_generic(r, k, f, ts, e_abs);
        let a = [[-r / l, -k / l], [k / j, -f / j]];
        let sigma = half * (r / l + f / j);
        // q = σ² − ωn² written without cancellation, as in `Derived`.
        let half_diff = half * (r / l - f / j);
        let q = half_diff * half_diff - k * k / (l * j);
        let omega_n2 = rf_k2 / (l * j);
        let y0 = [ts / k - i_r, -omega_r];
        let shifted = |v: [T; 2]| {
            [
                (a[0][0] + sigma) * v[0] + a[0][1] * v[1],
                a[1][0] * v[0] + (a[1][1] + sigma) * v[1],
            ]
        };
        let w0 = shifted(y0);
        // A⁻¹ = [[a11, −a01], [−a10, a00]] / det, det = ωn².
        let z0 = [
            (a[1][1] * y0[0] - a[0][1] * y0[1]) / omega_n2,
            (-a[1][0] * y0[0] + a[0][0] * y0[1]) / omega_n2,
        ];
        let wz0 = shifted(z0);
        StepResponse {
            r_ohm: r,
            l_henry: l,
            e_abs,
            dir,
            t0,
            sigma,
            q,
            omega_n2,
            i_r,
            omega_r,
            y0,
            w0,
            z0_speed: z0[1],
            wz0_speed: wz0[1],
        }
    }

    /// Breakaway instant t0 \[s\] of Eq. (11), `None` if the motor never moves.
    pub fn breakaway_time(&self) -> Option<T> {
        self.t0
    }

    /// Steady current Ir \[A\] and speed Ωr \[rad/s\] of Eqs. (4), (5), signed like `E`.
    pub fn steady(&self) -> (T, T) {
        let dir = T::cst(self.dir);
        if self.t0.is_some() {
            (dir * self.i_r, dir * self.omega_r)
        } else {
            (dir * self.e_abs / self.r_ohm, T::cst(0.0))
        }
    }

    #[inline(always)]
    fn moving_state(&self, tau: T, ec: T, es: T) -> MotorState<T> {
        let dir = T::cst(self.dir);
        MotorState {
            current_a: dir * (self.i_r + ec * self.y0[0] + es * self.w0[0]),
            speed_rad_s: dir * (self.omega_r + ec * self.y0[1] + es * self.w0[1]),
            position_rad: dir
                * (self.omega_r * tau + ec * self.z0_speed + es * self.wz0_speed - self.z0_speed),
        }
    }

    /// Eq. (10) at `t` (clamped at 0).
    #[inline(always)]
    fn standstill_state(&self, t: f64) -> MotorState<T> {
        let t = T::cst(t.max(0.0));
        MotorState {
            current_a: -T::cst(self.dir) * self.e_abs / self.r_ohm
                * (-t * self.r_ohm / self.l_henry).exp_m1(),
            speed_rad_s: T::cst(0.0),
            position_rad: T::cst(0.0),
        }
    }

    /// Current, speed and angle at time `t_s` \[s\] after the step (0 for `t < 0`).
    pub fn at(&self, t_s: f64) -> MotorState<T> {
        match self.t0 {
            Some(t0) if t_s > t0.value() => {
                let tau = T::cst(t_s) - t0;
                let (ec, es) = decayed_cosh_sinhc(self.sigma, self.q, self.omega_n2, tau);
                self.moving_state(tau, ec, es)
            }
            _ => self.standstill_state(t_s),
        }
    }

    /// Walks the grid `t_i = t_first + i·dt` \[s\], calling `emit(i, state)` for each of `n`
    /// samples in order: the streaming form of [`StepResponse::fill`], for callers that reduce
    /// the response as they go (no buffer at all).
    #[inline(always)]
    pub fn for_each_sample(
        &self,
        t_first: f64,
        dt: f64,
        n: usize,
        mut emit: impl FnMut(usize, MotorState<T>),
    ) {
        let t_of = |i: usize| t_first + i as f64 * dt;
        let Some(t0) = self.t0 else {
            for i in 0..n {
                emit(i, self.standstill_state(t_of(i)));
            }
            return;
        };
        let mut i = 0;
        while i < n && t_of(i) <= t0.value() {
            emit(i, self.standstill_state(t_of(i)));
            i += 1;
        }
        let usable_step = dt > 0.0 && self.sigma.value() * dt <= MAX_SIGMA_STEP;
        if !usable_step {
            for j in i..n {
                emit(j, self.at(t_of(j)));
            }
            return;
        }
        let h = T::cst(dt);
        let (c_h, s_h) = cosh_sinhc(self.q, h);
        let decay_h = (-self.sigma * h).exp();
        let (step_c, step_qs, step_s) = (decay_h * c_h, decay_h * self.q * s_h, decay_h * s_h);
        let mut ec = T::cst(0.0);
        let mut es = T::cst(0.0);
        for j in i..n {
            let tau = T::cst(t_of(j)) - t0;
            if (j - i) % REANCHOR_SAMPLES == 0 {
                (ec, es) = decayed_cosh_sinhc(self.sigma, self.q, self.omega_n2, tau);
            } else {
                (ec, es) = (ec * step_c + es * step_qs, es * step_c + ec * step_s);
            }
            emit(j, self.moving_state(tau, ec, es));
        }
    }

    /// Fills `out[i]` with the state at `t_first + i·dt` \[s\]. No allocation.
    pub fn fill(&self, t_first: f64, dt: f64, out: &mut [MotorState<T>]) {
        let n = out.len();
        self.for_each_sample(t_first, dt, n, |i, s| {
            if let Some(slot) = out.get_mut(i) {
                *slot = s;
            }
        });
    }

    /// Fills `out[i]` with the current \[A\] at `t_first + i·dt` \[s\]. No allocation.
    pub fn fill_current(&self, t_first: f64, dt: f64, out: &mut [T]) {
        let n = out.len();
        self.for_each_sample(t_first, dt, n, |i, s| {
            if let Some(slot) = out.get_mut(i) {
                *slot = s.current_a;
            }
        });
    }
}
