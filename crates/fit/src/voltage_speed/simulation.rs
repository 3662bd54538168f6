//! The voltage-to-speed model solved exactly between the voltage's changes: a relaxation of
//! time constant kA/kV, the rotor stuck while |E| ≤ kS, zero crossings in closed form.

use motor_model::Input;

use crate::voltage_speed::model::{FeedforwardParams, VoltageSpeedModel};

/// Sub-intervals per sample where the voltage is not piecewise constant (a sine, a replayed
/// waveform): the voltage is taken at each sub-interval's midpoint.
pub(crate) const SUBSTEPS_SMOOTH: usize = 4;

/// Bisections locating a zero crossing of the speed (2⁻⁵⁰ of a check interval).
pub(crate) const CROSSING_BISECTIONS: u32 = 50;

/// The speed \[rad/s\] and angle \[rad\] of the model at `n` samples `dt` apart, from
/// `initial_speed` \[rad/s\] in steady motion (or rest) at angle 0: solved in closed form
/// between the instants where the voltage changes, zero crossings of the speed located by
/// bisection on the closed form.
pub fn simulate_voltage_speed(
    model: &VoltageSpeedModel,
    input: &Input,
    dt: f64,
    n: usize,
    initial_speed: f64,
) -> (Vec<f64>, Vec<f64>) {
    let c = &model.constants;
    let d0 = initial_speed.signum();
    let b = c.kv_v_s_per_rad - model.back_emf_v_s_per_rad;
    let mut state = Motion {
        w: initial_speed,
        theta: 0.0,
        u: if initial_speed != 0.0 {
            b * initial_speed + c.ks_v * d0
        } else {
            0.0
        },
        moving: (initial_speed != 0.0).then_some(d0),
    };
    let (mut speed, mut angle) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let jumps: &[f64] = match input {
        Input::Piecewise { times_s, .. } => times_s,
        Input::Step { at_s, .. } => std::slice::from_ref(at_s),
        _ => &[],
    };
    let piecewise = matches!(input, Input::Piecewise { .. } | Input::Step { .. });
    let mut next_jump = 0;
    for i in 0..n {
        speed.push(state.w);
        angle.push(state.theta);
        if i + 1 == n {
            break;
        }
        let (t0, t1) = (i as f64 * dt, (i + 1) as f64 * dt);
        let mut t = t0;
        while next_jump < jumps.len() && jumps[next_jump] <= t {
            next_jump += 1;
        }
        if piecewise {
            while next_jump < jumps.len() && jumps[next_jump] < t1 {
                let tj = jumps[next_jump];
                state.advance(model, input.volts_at(0.5 * (t + tj)), tj - t);
                t = tj;
                next_jump += 1;
            }
            state.advance(model, input.volts_at(0.5 * (t + t1)), t1 - t);
        } else {
            let h = dt / SUBSTEPS_SMOOTH as f64;
            for s in 0..SUBSTEPS_SMOOTH {
                state.advance(model, input.volts_at(t0 + (s as f64 + 0.5) * h), h);
            }
        }
    }
    (speed, angle)
}

/// [`simulate_voltage_speed`] of the reduced model (τe = 0).
pub fn simulate_feedforward(
    params: &FeedforwardParams,
    input: &Input,
    dt: f64,
    n: usize,
    initial_speed: f64,
) -> (Vec<f64>, Vec<f64>) {
    let model = VoltageSpeedModel {
        constants: *params,
        tau_e_s: 0.0,
        back_emf_v_s_per_rad: params.kv_v_s_per_rad,
    };
    simulate_voltage_speed(&model, input, dt, n, initial_speed)
}

/// `e^{Mt}` of a 2 × 2 matrix `m` (row-major), from its eigenvalues: real, repeated or complex.
pub(crate) fn expm2(m: [[f64; 2]; 2], t: f64) -> [[f64; 2]; 2] {
    let mu = 0.5 * (m[0][0] + m[1][1]);
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let q2 = mu * mu - det;
    let n = [[m[0][0] - mu, m[0][1]], [m[1][0], m[1][1] - mu]];
    // e^{Mt} = e^{μt} (a I + s N), N = M − μI, with (a, s) = (cosh qt, sinh(qt)/q) for real
    // eigenvalues μ ± q, (cos, sin/q) for complex ones, (1, t) for a double one.
    let (a, s, scale) = if q2 > 0.0 {
        let q = q2.sqrt();
        if q * t < 1e-4 {
            (
                1.0 + 0.5 * q2 * t * t,
                t * (1.0 + q2 * t * t / 6.0),
                (mu * t).exp(),
            )
        } else {
            // Through the eigenvalues, so that a large |μ| does not overflow cosh and sinh.
            let (l1, l2) = (mu + q, mu - q);
            let (e1, e2) = ((l1 * t).exp(), (l2 * t).exp());
            (0.5 * (e1 + e2), 0.5 * (e1 - e2) / q, 1.0)
        }
    } else {
        let q = (-q2).sqrt();
        if q * t < 1e-4 {
            (
                1.0 - 0.5 * (-q2) * t * t,
                t * (1.0 - (-q2) * t * t / 6.0),
                (mu * t).exp(),
            )
        } else {
            ((q * t).cos(), (q * t).sin() / q, (mu * t).exp())
        }
    };
    [
        [scale * (a + s * n[0][0]), scale * s * n[0][1]],
        [scale * s * n[1][0], scale * (a + s * n[1][1])],
    ]
}

/// State of the model: speed, angle, voltage-equivalent current `u = R I` \[V\], and the
/// direction of motion (`None` while static friction holds the rotor).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Motion {
    pub(crate) w: f64,
    pub(crate) theta: f64,
    pub(crate) u: f64,
    pub(crate) moving: Option<f64>,
}

impl Motion {
    /// Advances by `h` \[s\] under the constant voltage `e` \[V\].
    pub(crate) fn advance(&mut self, m: &VoltageSpeedModel, e: f64, h: f64) {
        if m.tau_e_s > 0.0 {
            self.advance_electrical(m, e, h);
        } else {
            self.advance_reduced(&m.constants, e, h);
        }
    }

    /// The reduced model: a first-order relaxation, its stops in closed form.
    pub(crate) fn advance_reduced(&mut self, p: &FeedforwardParams, e: f64, h: f64) {
        let tau = p.tau_m_s();
        let mut left = h;
        // At most a stop and a restart in one interval (a constant voltage drives one way).
        for _ in 0..3 {
            if left <= 0.0 {
                return;
            }
            let d = if self.w != 0.0 {
                self.w.signum()
            } else if e.abs() > p.ks_v {
                e.signum()
            } else {
                return; // stuck: static friction holds the rotor
            };
            let w_inf = (e - p.ks_v * d) / p.kv_v_s_per_rad;
            // Time to reach Ω = 0 when relaxing towards the other side of zero.
            let t_stop = if w_inf * d < 0.0 && self.w != 0.0 {
                tau * ((self.w - w_inf) / (-w_inf)).ln()
            } else {
                f64::INFINITY
            };
            let s = left.min(t_stop);
            let decay = (-s / tau).exp();
            self.theta += w_inf * s + (self.w - w_inf) * tau * (1.0 - decay);
            self.w = if s == t_stop {
                0.0
            } else {
                w_inf + (self.w - w_inf) * decay
            };
            left -= s;
        }
    }

    /// With the electrical time constant: `τe u̇ = E − u − kΩ`, `kA Ω̇ = u − (kV − k)Ω − kS d`
    /// while moving; `u` relaxing to E at rest until `|u| > kS`.
    pub(crate) fn advance_electrical(&mut self, m: &VoltageSpeedModel, e: f64, h: f64) {
        let c = &m.constants;
        let (tau_e, ks) = (m.tau_e_s, c.ks_v);
        let (ka, k) = (c.ka_v_s2_per_rad, m.back_emf_v_s_per_rad);
        let b = c.kv_v_s_per_rad - k;
        let a = [[-1.0 / tau_e, -k / tau_e], [1.0 / ka, -b / ka]];
        let det = c.kv_v_s_per_rad / (tau_e * ka);
        let inv = [
            [-b / ka / det, k / tau_e / det],
            [-1.0 / ka / det, -1.0 / tau_e / det],
        ];
        let mu = 0.5 * (a[0][0] + a[1][1]);
        let q2 = mu * mu - det;
        let mut check = 0.5 * tau_e.min(c.tau_m_s());
        if q2 < 0.0 {
            check = check.min(std::f64::consts::PI / (-q2).sqrt());
        }
        let check = check.max(h / MAX_CHECKS as f64);
        let mut left = h;
        for _ in 0..(MAX_CHECKS + 8) {
            if left <= 0.0 {
                return;
            }
            match self.moving {
                None => {
                    // At rest: u → e with τe; break away where |u| reaches kS.
                    let t_break = if e.abs() > ks && self.u.abs() <= ks {
                        let target = ks * e.signum();
                        tau_e * ((self.u - e) / (target - e)).ln()
                    } else if self.u.abs() > ks {
                        0.0
                    } else {
                        f64::INFINITY
                    };
                    let s = left.min(t_break.max(0.0));
                    self.u = e + (self.u - e) * (-s / tau_e).exp();
                    left -= s;
                    if s == t_break.max(0.0) && t_break.is_finite() {
                        self.moving = Some(self.u.signum());
                    }
                }
                Some(d) => {
                    let w_inf = (e - ks * d) / c.kv_v_s_per_rad;
                    let x_inf = [b * w_inf + ks * d, w_inf];
                    let x0 = [self.u - x_inf[0], self.w - x_inf[1]];
                    let at = |s: f64| -> ([f64; 2], f64) {
                        let phi = expm2(a, s);
                        let x = [
                            phi[0][0] * x0[0] + phi[0][1] * x0[1],
                            phi[1][0] * x0[0] + phi[1][1] * x0[1],
                        ];
                        // ∫₀ˢ e^{Aσ} dσ x0 = A⁻¹ (e^{As} − I) x0, its speed row.
                        let y = [x[0] - x0[0], x[1] - x0[1]];
                        let integral = inv[1][0] * y[0] + inv[1][1] * y[1];
                        ([x_inf[0] + x[0], x_inf[1] + x[1]], w_inf * s + integral)
                    };
                    let s = left.min(check);
                    let (x, dtheta) = at(s);
                    if d * x[1] >= 0.0 {
                        self.u = x[0];
                        self.w = x[1];
                        self.theta += dtheta;
                        left -= s;
                        continue;
                    }
                    // The speed crossed zero within s: find where, stop there.
                    let (mut lo, mut hi) = (0.0_f64, s);
                    for _ in 0..CROSSING_BISECTIONS {
                        let mid = 0.5 * (lo + hi);
                        if d * at(mid).0[1] >= 0.0 {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    let (x, dtheta) = at(hi);
                    self.u = x[0];
                    self.w = 0.0;
                    self.theta += dtheta;
                    left -= hi;
                    self.moving = (self.u.abs() > ks).then_some(self.u.signum());
                }
            }
        }
    }
}

/// Most checks for a zero crossing of the speed within one constant-voltage interval.
pub(crate) const MAX_CHECKS: usize = 64;
