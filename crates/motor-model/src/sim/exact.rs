//! Exact propagation of the nominal stick-slip model under a piecewise-constant voltage.
//!
//! In each mode Eq. (2) is linear with constant coefficients while E(t) holds a level: with
//! `z = [I, Ω, θ, 1]`, `dz/dt = M z`, where moving in direction `d = ±1`
//!
//! ```text
//! M = [ −R/L  −k/L  0   E/L     ]
//!     [  k/J  −f/J  0  −d Ts/J  ]
//!     [  0     1    0   0       ]
//!     [  0     0    0   0       ]
//! ```
//!
//! and stuck (`Ω ≡ 0`) only the current's row remains, `[−R/L 0 0 E/L]`. A stretch of length
//! `h` is then `z(h) = exp(M h) z(0)`, exact for any ratio of `h` to the time constants: a
//! sample costs one 4×4 product whatever the record's rate, where an explicit integrator
//! needs steps below the fastest time constant. The matrix exponential is nalgebra's
//! (Padé with scaling and squaring), computed once per level, mode and sample period.
//!
//! Mode switches are located within their stretch: breakaway (`|k I|` reaching Ts while
//! stuck: the current is a single exponential there, solved in closed form) and the speed
//! crossing 0 while moving (bisection to 2⁻⁴⁸ of the stretch on the exact solution). While
//! moving, Ω is a constant plus two exponentials (or a damped sinusoid), so between two of its
//! extrema it is monotone: stretches are cut to 0.9 π/ω_d when underdamped, and a stretch
//! whose ends are both on the moving side but whose acceleration turns from braking to
//! driving is searched for a dip through 0 in between.

use nalgebra::{Matrix4, Vector4};

use super::input::Input;
use super::trace::Trace;
use crate::derived::signed_damped_pulsation_sq;
use crate::params::MotorParams;

/// Bisection iterations locating a zero crossing of the speed (2⁻⁴⁸ of the stretch).
const EVENT_BISECTIONS: u32 = 48;
/// Mode switches allowed within one stretch before the rest of it is taken in the current
/// mode (guards against chattering at a threshold).
const MAX_EVENTS_PER_STRETCH: u32 = 8;
/// Largest `‖M h‖` (max-abs entry) propagated: beyond it the caller integrates instead (the
/// exponential's scaling would need more squarings than its accuracy warrants).
const MAX_SCALED_NORM: f64 = 1e12;
/// Fraction of the half period `π/ω_d` of an underdamped motor a moving stretch may span.
const HALF_PERIOD_SHARE: f64 = 0.9;
/// Relative size below which a sign of the acceleration is taken as rounding.
const ACCELERATION_TOLERANCE: f64 = 1e-9;
/// Most pieces a moving stretch is cut into (an oscillation this much faster than the
/// sampling is left to the integrator).
const MAX_PIECES: f64 = 1e6;
/// Propagators kept per run (levels × modes × stretch lengths).
const CACHE_CAPACITY: usize = 64;

const I: usize = 0;
const W: usize = 1;
const TH: usize = 2;
/// Index of the constant 1 in `z`.
const ONE: usize = 3;

/// The mode of the rotor: stuck (0) or moving in direction ±1.
type Direction = f64;

/// Exact propagation of `params` (nominal model) under a piecewise-constant `input`.
pub(crate) struct ExactPropagator<'a> {
    params: &'a MotorParams,
    input: &'a Input,
    /// Longest moving stretch \[s\] between checks of the speed's sign.
    max_moving_s: f64,
    cache: Vec<(u64, i8, u64, Matrix4<f64>)>,
}

impl<'a> ExactPropagator<'a> {
    /// A propagator of `params` under `input`, `None` unless `input` is a step or piecewise
    /// constant (where E(t) holds between its jumps).
    pub(crate) fn new(params: &'a MotorParams, input: &'a Input) -> Option<Self> {
        if !matches!(input, Input::Step { .. } | Input::Piecewise { .. }) {
            return None;
        }
        let q = signed_damped_pulsation_sq(params);
        let max_moving_s = if q < 0.0 {
            HALF_PERIOD_SHARE * std::f64::consts::PI / (-q).sqrt()
        } else {
            f64::INFINITY
        };
        if max_moving_s.is_nan() || max_moving_s <= 0.0 {
            return None;
        }
        Some(ExactPropagator {
            params,
            input,
            max_moving_s,
            cache: Vec::new(),
        })
    }

    /// `M` of the mode `dir` (0 stuck) at `volts` \[V\].
    fn generator(&self, volts: f64, dir: Direction) -> Matrix4<f64> {
        let p = self.params;
        let (r, l, k, f, j, ts) = (
            p.r_ohm,
            p.l_henry,
            p.k_nm_per_a,
            p.f_nms_per_rad,
            p.j_kgm2,
            p.ts_nm,
        );
        let mut m = Matrix4::zeros();
        m[(I, I)] = -r / l;
        m[(I, ONE)] = volts / l;
        if dir != 0.0 {
            m[(I, W)] = -k / l;
            m[(W, I)] = k / j;
            m[(W, W)] = -f / j;
            m[(W, ONE)] = -dir * ts / j;
            m[(TH, W)] = 1.0;
        }
        m
    }

    /// `exp(M h)`, `None` where `M h` is not finite or too large to exponentiate accurately.
    fn propagator(&self, volts: f64, dir: Direction, h: f64) -> Option<Matrix4<f64>> {
        let m = self.generator(volts, dir) * h;
        let norm = m.amax();
        (norm.is_finite() && norm <= MAX_SCALED_NORM).then(|| m.exp())
    }

    /// [`Self::propagator`], kept for the lengths a run repeats (the sample period).
    fn cached(&mut self, volts: f64, dir: Direction, h: f64) -> Option<Matrix4<f64>> {
        let key = (volts.to_bits(), dir as i8, h.to_bits());
        if let Some((.., phi)) = self.cache.iter().find(|(v, d, hh, _)| (*v, *d, *hh) == key) {
            return Some(*phi);
        }
        let phi = self.propagator(volts, dir, h)?;
        if self.cache.len() < CACHE_CAPACITY {
            self.cache.push((key.0, key.1, key.2, phi));
        }
        Some(phi)
    }

    /// The mode of a rotor at rest: stuck while friction holds it, else moving towards the
    /// torque.
    fn mode_at_rest(&self, z: &Vector4<f64>) -> Direction {
        let torque = self.params.k_nm_per_a * z[I];
        if torque.abs() > self.params.ts_nm {
            torque.signum()
        } else {
            0.0
        }
    }

    /// `d` times the acceleration \[rad/s²\] moving in direction `d`, and its scale.
    fn acceleration(&self, z: &Vector4<f64>, dir: Direction) -> (f64, f64) {
        let p = self.params;
        let (drive, drag) = (p.k_nm_per_a * z[I], p.f_nms_per_rad * z[W]);
        (
            dir * (drive - drag - dir * p.ts_nm) / p.j_kgm2,
            (drive.abs() + drag.abs() + p.ts_nm) / p.j_kgm2,
        )
    }

    /// Advances `z` by `h` \[s\] at `volts` \[V\] from mode `dir`, switching modes on the way;
    /// `repeated` marks a length the run repeats (cached). `None` where a propagator cannot be
    /// formed.
    fn advance(
        &mut self,
        z: &mut Vector4<f64>,
        dir: &mut Direction,
        volts: f64,
        h: f64,
        repeated: bool,
    ) -> Option<()> {
        let mut left = h;
        let mut whole = repeated;
        for _ in 0..MAX_EVENTS_PER_STRETCH {
            if left <= 0.0 {
                return Some(());
            }
            let at = if *dir == 0.0 {
                self.stuck_stretch(z, volts, left, whole)?
            } else {
                self.moving_stretch(z, *dir, volts, left, whole)?
            };
            let Some(at) = at else {
                return Some(());
            };
            // A switch `at` into the stretch: the rotor stops there (or breaks away).
            z[W] = 0.0;
            *dir = if *dir == 0.0 {
                // Broke away: |k I| is at Ts, moving towards the torque.
                z[I].signum()
            } else {
                self.mode_at_rest(z)
            };
            left -= at;
            whole = false;
        }
        let phi = self.propagator(volts, *dir, left)?;
        *z = phi * *z;
        if *dir == 0.0 {
            z[W] = 0.0;
        }
        Some(())
    }

    /// A stuck stretch of `h`: `z` at its end and `None`, or at breakaway and its time.
    fn stuck_stretch(
        &mut self,
        z: &mut Vector4<f64>,
        volts: f64,
        h: f64,
        repeated: bool,
    ) -> Option<Option<f64>> {
        let phi = if repeated {
            self.cached(volts, 0.0, h)?
        } else {
            self.propagator(volts, 0.0, h)?
        };
        let end = phi * *z;
        let p = self.params;
        let hold = p.ts_nm / p.k_nm_per_a;
        if end[I].abs() <= hold {
            *z = end;
            z[W] = 0.0;
            return Some(None);
        }
        // I(s) = I∞ + (I0 − I∞) exp(−R s/L) reaches ±Ts/k, monotonically.
        let target = hold.copysign(end[I]);
        let settled = volts / p.r_ohm;
        let ratio = (target - settled) / (z[I] - settled);
        let at = if ratio > 0.0 && ratio <= 1.0 {
            (-(p.l_henry / p.r_ohm) * ratio.ln()).clamp(0.0, h)
        } else {
            0.0
        };
        let phi = self.propagator(volts, 0.0, at)?;
        *z = phi * *z;
        z[I] = target;
        Some(Some(at))
    }

    /// A moving stretch of `h` in direction `dir`, in pieces no longer than the speed's
    /// monotone span: `z` at its end and `None`, or where the speed reaches 0 and its time.
    fn moving_stretch(
        &mut self,
        z: &mut Vector4<f64>,
        dir: Direction,
        volts: f64,
        h: f64,
        repeated: bool,
    ) -> Option<Option<f64>> {
        let pieces = (h / self.max_moving_s).ceil().max(1.0);
        if pieces > MAX_PIECES {
            return None;
        }
        let piece = h / pieces;
        let phi = if repeated {
            self.cached(volts, dir, piece)?
        } else {
            self.propagator(volts, dir, piece)?
        };
        for n in 0..pieces as u64 {
            let end = phi * *z;
            let crossing = if dir * end[W] < 0.0 {
                Some(piece)
            } else {
                self.dip_end(z, &end, dir, volts, piece)?
            };
            if let Some(limit) = crossing {
                let at = self.crossing(z, dir, volts, limit)?;
                let phi = self.propagator(volts, dir, at)?;
                *z = phi * *z;
                return Some(Some(n as f64 * piece + at));
            }
            *z = end;
        }
        Some(None)
    }

    /// Where the speed, on the moving side at both ends of a piece, may have dipped through 0
    /// in between: the end of the braking part (its minimum) when it did, else `None`.
    fn dip_end(
        &self,
        z: &Vector4<f64>,
        end: &Vector4<f64>,
        dir: Direction,
        volts: f64,
        h: f64,
    ) -> Option<Option<f64>> {
        let (a0, s0) = self.acceleration(z, dir);
        let (a1, s1) = self.acceleration(end, dir);
        if !(a0 < -ACCELERATION_TOLERANCE * s0 && a1 > ACCELERATION_TOLERANCE * s1) {
            return Some(None);
        }
        // Braking, then driving: bisect for the turn, and see whether the speed got past 0.
        let (mut lo, mut hi) = (0.0_f64, h);
        for _ in 0..EVENT_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            let zm = self.propagator(volts, dir, mid)? * *z;
            if dir * zm[W] <= 0.0 {
                return Some(Some(mid));
            }
            if self.acceleration(&zm, dir).0 < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(None)
    }

    /// The first instant in `(0, limit]` where the speed reaches 0 (it is past 0 at `limit`).
    fn crossing(&self, z: &Vector4<f64>, dir: Direction, volts: f64, limit: f64) -> Option<f64> {
        let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
        for _ in 0..EVENT_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            let zm = self.propagator(volts, dir, mid * limit)? * *z;
            if dir * zm[W] <= 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some(hi * limit)
    }

    /// The run of [`super::simulator::Simulator::run`] on `n` samples every `dt` \[s\] from
    /// current `i0` \[A\] and speed `w0` \[rad/s\]; `None` where a stretch cannot be
    /// propagated exactly (the caller integrates it instead).
    pub(crate) fn run(mut self, n: usize, dt: f64, (i0, w0): (f64, f64)) -> Option<Trace> {
        let mut trace = Trace::with_capacity(n);
        let mut z = Vector4::new(i0, w0, 0.0, 1.0);
        let mut dir = if w0 == 0.0 {
            self.mode_at_rest(&z)
        } else {
            w0.signum()
        };
        // The jumps of E(t) and the level from each on (0 V before the first).
        let (jumps, levels): (&[f64], &[f64]) = match self.input {
            Input::Step { volts, at_s } => {
                (std::slice::from_ref(at_s), std::slice::from_ref(volts))
            }
            Input::Piecewise { times_s, volts } => (times_s, volts),
            _ => return None,
        };
        let level = |k: usize| if k == 0 { 0.0 } else { levels[k - 1] };
        // Jumps at or before t.
        let mut k = jumps.partition_point(|&tj| tj <= 0.0);
        let mut t = 0.0;
        for i in 0..n {
            let t_i = i as f64 * dt;
            // Stretches of constant E(t), split at every jump on the way to t_i.
            while t < t_i {
                let jump = jumps.get(k).copied().filter(|&tj| tj < t_i);
                let end = jump.unwrap_or(t_i);
                // A whole sample period (to rounding) shares one cached propagator.
                let whole = jump.is_none() && ((end - t) - dt).abs() <= 1e-9 * dt;
                let h = if whole { dt } else { end - t };
                self.advance(&mut z, &mut dir, level(k), h, whole)?;
                t = end;
                if jump.is_some() {
                    k += 1;
                }
            }
            // The level read at t_i includes a jump at t_i itself.
            let mut read = k;
            while jumps.get(read).is_some_and(|&tj| tj <= t_i) {
                read += 1;
            }
            if !z.iter().all(|v| v.is_finite()) {
                return None;
            }
            trace.t.push(t_i);
            trace.voltage.push(level(read));
            trace.armature_current.push(z[I]);
            trace.current.push(z[I]);
            trace.speed.push(z[W]);
            trace.position.push(z[TH]);
            trace.stuck.push(dir == 0.0);
        }
        Some(trace)
    }
}
