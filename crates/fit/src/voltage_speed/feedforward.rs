//! Identification from the voltage and the speed alone (no current sensor): the
//! voltage-to-speed model of a DC motor whose electrical time constant is negligible.
//!
//! With `L dI/dt` neglected in Eq. (2a), `I = (E − kΩ)/R`, and Eq. (2b) times `R/k` reads
//!
//! `E = kS sign(Ω) + kV Ω + kA dΩ/dt`, with `kS = R Ts/k` \[V\], `kV = k + R f/k` \[V·s/rad\],
//! `kA = R J/k` \[V·s²/rad\]
//!
//! (WPILib SysId's feedforward constants); the rotor is stuck while `|E| ≤ kS`. Only these three
//! combinations reach the speed: J, f and Ts follow when R and k are known
//! ([`FeedforwardParams::mechanical`]). The reduced model holds while `τe = L/R` is small
//! against `τm = kA/kV`; when it is not, the speed's rise is rounded over about τe and kA
//! absorbs it (kA is then too large by about `kV τe`).
//!
//! The fit is by output error on the measured speed (the tachometer, or the central difference
//! of the encoder angle, as the simulated angle is differentiated alike): the model is solved
//! exactly between the instants where the voltage changes (a relaxation of time constant
//! `kA/kV` towards `(E − kS d)/kV`, zero crossings of the speed found in closed form), so the
//! cost is smooth in the parameters. A record that does not start at rest gets its initial
//! speed as a fitted parameter. The start is the inverse model
//! ([`crate::identify_inverse_model_pooled`] with the voltage as the "torque").

use motor_model::{central_difference, Input, MotorParams};
use nalgebra::DMatrix;

use crate::current_driven::mechanical::{
    identify_inverse_model_pooled, AxisRecord, InverseModelSettings,
};
use crate::error::FitError;
use crate::estimation::lm::{
    half_squared_norm, solve, LeastSquares, LmReport, LmSettings, NormalEquations, Termination,
};
use crate::estimation::parameters::ParameterEstimate;
use crate::estimation::records::{
    noise_floor, noise_std, reweighted_sigma, Channel, ChannelQuality,
};
use crate::estimation::stats::{
    at_least, equal_runs, newey_west_run_covariance, sandwich_uncertainty, Uncertainty,
};
use crate::estimation::weighted::quality_from_sums;
use crate::excitation::input_uncertainty::{bias_group_sizes, pooled_level_variance, LevelPrior};

/// The voltage-to-speed constants of a motor (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedforwardParams {
    /// Static (dead-band) voltage kS = R Ts/k \[V\].
    pub ks_v: f64,
    /// Velocity constant kV = k + R f/k \[V·s/rad\].
    pub kv_v_s_per_rad: f64,
    /// Acceleration constant kA = R J/k \[V·s²/rad\].
    pub ka_v_s2_per_rad: f64,
}

/// J, f and Ts of a motor from its feedforward constants and a given R and k.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MechanicalFromFeedforward {
    /// Inertia J = kA k/R \[kg·m²\].
    pub j_kgm2: f64,
    /// Viscous friction f = (kV − k) k/R \[N·m·s/rad\].
    pub f_nms_per_rad: f64,
    /// Coulomb torque Ts = kS k/R \[N·m\].
    pub ts_nm: f64,
}

impl FeedforwardParams {
    /// The constants of a motor (module docs; exact when L = 0).
    pub fn of_motor(p: &MotorParams) -> Self {
        FeedforwardParams {
            ks_v: p.r_ohm * p.ts_nm / p.k_nm_per_a,
            kv_v_s_per_rad: p.k_nm_per_a + p.r_ohm * p.f_nms_per_rad / p.k_nm_per_a,
            ka_v_s2_per_rad: p.r_ohm * p.j_kgm2 / p.k_nm_per_a,
        }
    }

    /// J, f and Ts given R \[Ω\] and k \[N·m/A\]. `f` comes out negative when kV < k: the k
    /// given is larger than the records allow.
    pub fn mechanical(&self, r_ohm: f64, k_nm_per_a: f64) -> MechanicalFromFeedforward {
        let scale = k_nm_per_a / r_ohm;
        MechanicalFromFeedforward {
            j_kgm2: self.ka_v_s2_per_rad * scale,
            f_nms_per_rad: (self.kv_v_s_per_rad - k_nm_per_a) * scale,
            ts_nm: self.ks_v * scale,
        }
    }

    /// Mechanical time constant τm = kA/kV \[s\].
    pub fn tau_m_s(&self) -> f64 {
        self.ka_v_s2_per_rad / self.kv_v_s_per_rad
    }
}

/// One record of voltage and speed.
#[derive(Debug, Clone, Copy)]
pub struct SpeedRecord<'a> {
    /// The armature voltage applied, time from the record's first sample
    /// ([`crate::voltage_input`] builds it from a measured column).
    pub input: &'a Input,
    /// Sample period \[s\].
    pub dt: f64,
    /// Tachometer speed \[rad/s\], if measured. Not used when `position` is given.
    pub speed: Option<&'a [f64]>,
    /// Encoder angle \[rad\], if measured.
    pub position: Option<&'a [f64]>,
    /// Samples to leave out (a rail, a glitch), if any.
    pub exclude: Option<&'a [bool]>,
    /// What the record leaves unknown of each level of a piecewise-constant `input` (from
    /// [`crate::voltage_levels`], one per level), or empty: the fit then moves the levels and
    /// their instants within these priors and its intervals carry what remains unknown.
    pub priors: &'a [LevelPrior],
    /// How the record starts: `Some(true)` at rest, `Some(false)` in steady motion at a
    /// fitted speed, `None` as its speed shows (at rest when the first sample, or the mean of
    /// the first five, is within three noise levels of zero).
    pub at_rest: Option<bool>,
}

/// Result of [`identify_feedforward`].
#[derive(Debug, Clone, PartialEq)]
pub struct FeedforwardFit {
    /// The fitted constants.
    pub params: FeedforwardParams,
    /// 95 % intervals of kS, kV, kA (same order and units as the fields of
    /// [`FeedforwardParams`]; Newey–West sandwich, each standard error at least the
    /// model-based one, delta method from the logarithms); `None` when they cannot be
    /// computed.
    pub ci95: Option<[[f64; 2]; 3]>,
    /// What the records said of the electrical time constant.
    pub tau_e: TauE,
    /// Initial speed of each record \[rad/s\]: 0 for a record that starts at rest, else fitted.
    pub initial_speed_rad_s: Vec<f64>,
    /// Fit quality of each record's speed channel.
    pub quality: Vec<ChannelQuality>,
    /// Each record's residual RMS over its noise as its samples show it (second differences,
    /// [`crate::noise_std`]): about 1 where the model explains the record; well above
    /// [`EXPLAINED_RATIO`] it does not (τe far from every start, an unmodelled effect).
    pub residual_over_noise: Vec<f64>,
    /// Accepted iterations (every stage).
    pub iterations: u64,
    /// Why the solver stopped.
    pub termination: Termination,
}

/// Names of the feedforward constants as reports give them, in the order of
/// [`FeedforwardFit::ci95`].
pub const FEEDFORWARD_NAMES: [&str; 3] = ["kS", "kV", "kA"];
/// SI units of [`FEEDFORWARD_NAMES`].
pub const FEEDFORWARD_UNITS: [&str; 3] = ["V", "V·s/rad", "V·s²/rad"];

impl FeedforwardFit {
    /// kS, kV, kA with names, units and 95 % intervals; and, given `known` = (R \[Ω\],
    /// k \[N·m/A\]), J, f, Ts ([`FeedforwardParams::mechanical`]) with the intervals of kA, kV,
    /// kS mapped through the same linear relations (R and k taken as exact: their own
    /// uncertainty is not in these intervals).
    pub fn estimates(&self, known: Option<(f64, f64)>) -> Vec<ParameterEstimate> {
        let p = &self.params;
        let values = [p.ks_v, p.kv_v_s_per_rad, p.ka_v_s2_per_rad];
        let mut out: Vec<ParameterEstimate> = (0..3)
            .map(|i| ParameterEstimate {
                name: FEEDFORWARD_NAMES[i],
                unit: FEEDFORWARD_UNITS[i],
                value: values[i],
                ci95: self.ci95.map(|c| c[i]),
            })
            .collect();
        if let Some((r_ohm, k)) = known {
            let m = p.mechanical(r_ohm, k);
            let scale = k / r_ohm;
            let map = |i: usize, shift: f64| {
                self.ci95
                    .map(|c| [(c[i][0] - shift) * scale, (c[i][1] - shift) * scale])
            };
            for (name, unit, value, ci95) in [
                ("J", "kg·m²", m.j_kgm2, map(2, 0.0)),
                ("f", "N·m·s/rad", m.f_nms_per_rad, map(1, k)),
                ("Ts", "N·m", m.ts_nm, map(0, 0.0)),
            ] {
                out.push(ParameterEstimate {
                    name,
                    unit,
                    value,
                    ci95,
                });
            }
        }
        out
    }
}

/// The electrical time constant in a [`FeedforwardFit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TauE {
    /// Fitted: τe = L/R \[s\] with its 95 % interval.
    Fitted {
        /// τe \[s\].
        value_s: f64,
        /// 95 % interval \[s\].
        ci95_s: [f64; 2],
    },
    /// Fitted, but not significantly above 0 (its interval reaches 0): below `upper_s` \[s\],
    /// the upper end of that interval. kS, kV and kA are those of the fit with τe, so their
    /// intervals carry what τe leaves unknown.
    NotResolved {
        /// Upper end of τe's 95 % interval \[s\].
        upper_s: f64,
    },
    /// The fit with τe failed (no convergence, or no intervals): the reduced model (τe = 0) is
    /// used. kA then holds about `(kV − k) τe` of the true τe on top of `R J/k`, and at every
    /// reversal kS trades against τe.
    Unfitted,
    /// Fitted, but with no torque constant given the records cannot split kA from τe. The
    /// model's speed answers the voltage through `1/(kA τe s² + (kA + τe (kV − k)) s + kV)`:
    /// the records fix the two coefficients, `kA τe` and `lead = kA + τe (kV − k)`, and with
    /// the viscous share `b = kV − k` unknown, a kA fits them as well as any other wherever
    /// `τe = (kA τe)/kA` and `b = (lead − kA)/τe` are physical (`0 ≤ b ≤ kV`): every such kA
    /// lies in `(0, lead]` (all of it when `lead² ≤ 4 (kA τe) kV`). kS and kV are determined;
    /// kA's interval in [`FeedforwardFit::ci95`] is then `[0, upper end of lead's interval]`.
    /// Giving k (the torque constant, [`FeedforwardSettings::torque_constant`]) splits them.
    Traded {
        /// `lead = kA + τe (kV − k)` \[V·s²/rad\]: the largest kA the records allow.
        lead_v_s2_per_rad: f64,
        /// 95 % interval of `lead` \[V·s²/rad\].
        lead_ci95: [f64; 2],
        /// `kA τe` \[V·s³/rad\].
        product_v_s3_per_rad: f64,
        /// 95 % interval of `kA τe` \[V·s³/rad\].
        product_ci95: [f64; 2],
    },
    /// Not asked for ([`FeedforwardSettings::electrical`] false): the reduced model.
    Neglected,
}

/// Settings of [`identify_feedforward`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedforwardSettings {
    /// The solver's settings.
    pub lm: LmSettings,
    /// Fit the electrical time constant τe too (default), or neglect it.
    pub electrical: bool,
    /// The torque constant k \[N·m/A\] (the back-EMF constant, V·s/rad) if known: with τe, the
    /// viscous share of kV is `kV − k`. Unknown, k is taken as kV (viscous friction small
    /// against the back-EMF), which affects only how τe couples to the speed.
    pub torque_constant: Option<f64>,
}

impl Default for FeedforwardSettings {
    fn default() -> Self {
        FeedforwardSettings {
            lm: LmSettings::default(),
            electrical: true,
            torque_constant: None,
        }
    }
}

/// The voltage-to-speed model with the electrical time constant: the constants, `τe = L/R`
/// and the back-EMF constant `k` (module docs). `tau_e_s = 0` is the reduced model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageSpeedModel {
    /// kS, kV, kA.
    pub constants: FeedforwardParams,
    /// Electrical time constant τe = L/R \[s\]; 0 neglects it.
    pub tau_e_s: f64,
    /// Back-EMF constant k \[V·s/rad\] (= the torque constant in N·m/A), at most kV: the rest
    /// of kV, `kV − k = R f/k`, is the viscous friction's share. Only matters when τe > 0.
    pub back_emf_v_s_per_rad: f64,
}

/// Sub-intervals per sample where the voltage is not piecewise constant (a sine, a replayed
/// waveform): the voltage is taken at each sub-interval's midpoint.
const SUBSTEPS_SMOOTH: usize = 4;
/// Step of the forward-difference Jacobian (in ln k and, scaled, in the initial speeds).
const FD_STEP: f64 = 1e-6;
/// Most checks for a zero crossing of the speed within one constant-voltage interval.
const MAX_CHECKS: usize = 64;
/// How far \[ln\] below its start the reduced fit may take kS before the τe stage restarts
/// it from the start (a factor of 1000).
const KS_COLLAPSE_LN: f64 = 6.907755278982137;
/// Whether a fit took kS, `ln_ks` its logarithm, [`KS_COLLAPSE_LN`] below the start's `ks0`
/// \[V\]: driven to 0, where its gradient in the logarithm vanishes and it has no interval.
fn ks_collapsed(ln_ks: f64, ks0: f64) -> bool {
    ln_ks < ks0.ln() - KS_COLLAPSE_LN
}
/// Decimation of the start's inverse model.
const START_DECIMATION: usize = 5;
/// Cut-offs of the start's position filter, as fractions of the sample rate, tried in turn.
const START_CUTOFFS: [f64; 3] = [0.02, 0.005, 0.00125];
/// Bisections locating a zero crossing of the speed (2⁻⁵⁰ of a check interval).
const CROSSING_BISECTIONS: u32 = 50;

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
fn expm2(m: [[f64; 2]; 2], t: f64) -> [[f64; 2]; 2] {
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
struct Motion {
    w: f64,
    theta: f64,
    u: f64,
    moving: Option<f64>,
}

impl Motion {
    /// Advances by `h` \[s\] under the constant voltage `e` \[V\].
    fn advance(&mut self, m: &VoltageSpeedModel, e: f64, h: f64) {
        if m.tau_e_s > 0.0 {
            self.advance_electrical(m, e, h);
        } else {
            self.advance_reduced(&m.constants, e, h);
        }
    }

    /// The reduced model: a first-order relaxation, its stops in closed form.
    fn advance_reduced(&mut self, p: &FeedforwardParams, e: f64, h: f64) {
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
    fn advance_electrical(&mut self, m: &VoltageSpeedModel, e: f64, h: f64) {
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

/// One record prepared for the fit.
struct FfRecord {
    input: Input,
    dt: f64,
    n: usize,
    kind: Channel,
    keep: Vec<usize>,
    data: Vec<f64>,
    sigma: f64,
    /// The smallest `sigma` may become ([`noise_floor`] of `data`).
    floor: f64,
    /// Which of the fitted initial speeds is this record's (0 for the first such record), if
    /// it does not start at rest.
    free_start: Option<usize>,
    /// The levels of a piecewise-constant voltage with what is unknown of them, if given.
    levels: Vec<Level>,
    /// Where the shift common to every level change's instant sits among the nuisances (in
    /// units of a change's standard deviation), if any change has an uncertain instant: an
    /// excitation clocked with the logger changes at the same point of every sample period
    /// (a PRBS whose bits fall on samples), so the instants' errors are not independent.
    common_start_slot: Option<usize>,
}

/// One level of a record's voltage as measured: its value and start with their standard
/// deviations, and where their corrections sit among the fit's nuisance parameters (each
/// nuisance is the correction in units of its standard deviation, with a unit normal prior).
#[derive(Debug, Clone, Copy)]
struct Level {
    volts: f64,
    start_s: f64,
    volts_sd: f64,
    start_sd: f64,
    volts_slot: Option<usize>,
    start_slot: Option<usize>,
}

struct FfProblem {
    records: Vec<FfRecord>,
    /// Whether τe is fitted (the fourth parameter, as ln τe).
    electrical: bool,
    /// The back-EMF constant k \[V·s/rad\] if given; else taken as kV.
    back_emf: Option<f64>,
    /// With τe and no k given: k taken as kV (the viscous share of kV fixed at 0, not a
    /// nuisance), the fit of [`TauE::Traded`]'s two coefficients.
    share_at_zero: bool,
    free_starts: usize,
    /// Nuisance parameters of the levels (values and instants), after the initial speeds;
    /// with τe and no k given, one more follows: the viscous share of kV (module docs).
    level_nuisances: usize,
    /// Data residuals.
    n_data: usize,
    /// Scale of the initial speeds in the parameter vector \[rad/s\] (so that every parameter
    /// moves by similar amounts).
    speed_scale: f64,
}

impl FfProblem {
    /// Nuisance parameters: the levels', and the viscous share of kV when τe is fitted without
    /// a given k (its prior uniform over `[0, kV]`: the share is Φ(z) of a nuisance z with a unit
    /// normal prior, so that a share near 0 or 1 is as likely as one about ½).
    fn nuisances(&self) -> usize {
        self.level_nuisances
            + usize::from(self.electrical && self.back_emf.is_none() && !self.share_at_zero)
    }

    /// Residuals: the data and one prior per nuisance.
    fn n_residuals(&self) -> usize {
        self.n_data + self.nuisances()
    }

    /// Parameters of the model itself (before the initial speeds).
    fn n_model(&self) -> usize {
        if self.electrical {
            4
        } else {
            3
        }
    }

    fn params_of(&self, theta: &[f64]) -> Option<VoltageSpeedModel> {
        let m = self.n_model();
        if theta.len() != m + self.free_starts + self.nuisances()
            || !theta.iter().all(|t| t.is_finite())
            || !theta[..m].iter().all(|t| t.abs() < 700.0)
        {
            return None;
        }
        let constants = FeedforwardParams {
            ks_v: theta[0].exp(),
            kv_v_s_per_rad: theta[1].exp(),
            ka_v_s2_per_rad: theta[2].exp(),
        };
        let kv = constants.kv_v_s_per_rad;
        let back_emf_v_s_per_rad = match (self.electrical, self.back_emf) {
            (_, Some(k)) => k.min(kv),
            (false, None) => kv,
            (true, None) if self.share_at_zero => kv,
            (true, None) => {
                let share = crate::excitation::input_uncertainty::phi(theta[theta.len() - 1]);
                kv * (1.0 - share)
            }
        };
        Some(VoltageSpeedModel {
            constants,
            tau_e_s: if self.electrical { theta[3].exp() } else { 0.0 },
            back_emf_v_s_per_rad,
        })
    }

    fn initial_speed(&self, r: &FfRecord, theta: &[f64]) -> f64 {
        r.free_start
            .map_or(0.0, |j| theta[self.n_model() + j] * self.speed_scale)
    }

    /// The voltage of record `r` with its levels corrected by the nuisances in `theta`;
    /// `None` where the corrected instants are out of order.
    fn input_of(&self, r: &FfRecord, theta: &[f64]) -> Option<Input> {
        if r.levels.is_empty() {
            return Some(r.input.clone());
        }
        let base = self.n_model() + self.free_starts;
        let shift = |slot: Option<usize>, sd: f64| slot.map_or(0.0, |j| theta[base + j] * sd);
        let steps: Vec<(f64, f64)> = r
            .levels
            .iter()
            .map(|l| {
                let common = if l.start_slot.is_some() {
                    shift(r.common_start_slot, l.start_sd)
                } else {
                    0.0
                };
                (
                    l.start_s + shift(l.start_slot, l.start_sd) + common,
                    l.volts + shift(l.volts_slot, l.volts_sd),
                )
            })
            .collect();
        Input::piecewise(&steps).ok()
    }

    /// The model of every record's fitted channel at `theta`.
    fn model(&self, theta: &[f64]) -> Option<Vec<Vec<f64>>> {
        let p = self.params_of(theta)?;
        let out: Vec<Vec<f64>> = self
            .records
            .iter()
            .map(|r| {
                let w0 = self.initial_speed(r, theta);
                let input = self.input_of(r, theta)?;
                let (speed, angle) = simulate_voltage_speed(&p, &input, r.dt, r.n, w0);
                let full = match r.kind {
                    Channel::EncoderSpeed => {
                        let t: Vec<f64> = (0..r.n).map(|i| i as f64 * r.dt).collect();
                        central_difference(&t, &angle)
                    }
                    _ => speed,
                };
                Some(r.keep.iter().map(|&i| full[i]).collect())
            })
            .collect::<Option<_>>()?;
        out.iter().flatten().all(|v| v.is_finite()).then_some(out)
    }

    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let model = self.model(theta)?;
        let mut r = Vec::with_capacity(self.n_residuals());
        for (rec, m) in self.records.iter().zip(&model) {
            r.extend(rec.data.iter().zip(m).map(|(y, m)| (m - y) / rec.sigma));
        }
        // The nuisances' unit normal priors.
        r.extend_from_slice(&theta[theta.len() - self.nuisances()..]);
        Some(r)
    }

    /// Lengths of the independent series of the residual vector: each record's channel, then
    /// each prior on its own.
    fn series(&self) -> Vec<usize> {
        let mut s: Vec<usize> = self.records.iter().map(|r| r.data.len()).collect();
        s.extend(std::iter::repeat_n(1, self.nuisances()));
        s
    }

    fn jacobian(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let r0 = self.residuals(theta)?;
        let n_params = theta.len();
        let mut jac = DMatrix::zeros(r0.len(), n_params);
        for j in 0..n_params {
            let mut th = theta.to_vec();
            th[j] += FD_STEP;
            let r = self.residuals(&th)?;
            for (i, (a, b)) in r.iter().zip(&r0).enumerate() {
                jac[(i, j)] = (a - b) / FD_STEP;
            }
        }
        Some((r0, jac))
    }

    fn quality(&self, theta: &[f64]) -> Vec<ChannelQuality> {
        let model = self.model(theta);
        self.records
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let mean = r.data.iter().sum::<f64>() / r.data.len().max(1) as f64;
                let sst = r.data.iter().map(|y| (y - mean).powi(2)).sum::<f64>();
                let sse = model.as_ref().map_or(f64::NAN, |m| {
                    m[k].iter().zip(&r.data).map(|(a, b)| (a - b).powi(2)).sum()
                });
                quality_from_sums(k, r.kind, r.sigma, sse, sst, r.data.len())
            })
            .collect()
    }
}

impl LeastSquares for FfProblem {
    fn n_params(&self) -> usize {
        self.n_model() + self.free_starts + self.nuisances()
    }

    fn cost(&self, theta: &[f64]) -> Option<f64> {
        Some(half_squared_norm(&self.residuals(theta)?))
    }

    fn normal_equations(&self, theta: &[f64]) -> Option<NormalEquations> {
        let (r, jac) = self.jacobian(theta)?;
        Some(NormalEquations::from_jacobian(r, &jac))
    }
}

fn bad(series: impl Into<String>, reason: String) -> FitError {
    FitError::BadData {
        series: series.into(),
        reason,
    }
}

/// Identifies kS, kV and kA (and τe where the records resolve it) from records of voltage and
/// speed (module docs), by output error from the inverse-model start: the reduced model first,
/// each record weighted by its noise and then by its residual RMS; then, if asked, with τe, kept
/// when its interval is narrower than its value. Intervals from the Newey–West sandwich.
pub fn identify_feedforward(
    records: &[SpeedRecord<'_>],
    settings: FeedforwardSettings,
) -> Result<FeedforwardFit, FitError> {
    if records.is_empty() {
        return Err(bad("records", "no record given".into()));
    }
    let mut prepared = Vec::with_capacity(records.len());
    let mut positions = Vec::with_capacity(records.len());
    let mut free = 0usize;
    let mut nuisances = 0usize;
    // Every record's levels in order, with how many read the same code.
    let groups = bias_group_sizes(
        &records
            .iter()
            .flat_map(|r| r.priors)
            .map(|q| {
                let uncertain = q.volts_variance_v2 > 0.0;
                let bias = if uncertain {
                    q.volts_bias_variance_v2
                } else {
                    0.0
                };
                (bias, q.volts_bias_code)
            })
            .collect::<Vec<_>>(),
    );
    let mut group = groups.into_iter();
    for (k, rec) in records.iter().enumerate() {
        let label = format!("record {}", k + 1);
        if !(rec.dt.is_finite() && rec.dt > 0.0) {
            return Err(bad(
                label,
                format!("sample period {} s: expected a positive period", rec.dt),
            ));
        }
        let t_of = |n: usize| -> Vec<f64> { (0..n).map(|i| i as f64 * rec.dt).collect() };
        let (kind, full, position) = match (rec.position, rec.speed) {
            (Some(angle), _) => (
                Channel::EncoderSpeed,
                central_difference(&t_of(angle.len()), angle),
                angle.to_vec(),
            ),
            (None, Some(speed)) => {
                // The angle as the running trapezoid of the speed, for the start only.
                let mut theta = Vec::with_capacity(speed.len());
                let mut acc = 0.0;
                for (i, w) in speed.iter().enumerate() {
                    if i > 0 {
                        acc += 0.5 * (w + speed[i - 1]) * rec.dt;
                    }
                    theta.push(acc);
                }
                (Channel::Speed, speed.to_vec(), theta)
            }
            (None, None) => {
                return Err(bad(
                    label,
                    "no speed or angle: the speed is what is fitted".into(),
                ))
            }
        };
        let n = full.len();
        if n < crate::MIN_SAMPLES {
            return Err(bad(
                label,
                format!("{n} samples: at least {} are needed", crate::MIN_SAMPLES),
            ));
        }
        if let Some((i, v)) = full.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(bad(
                label,
                format!("speed sample {i} is {v}: remove or repair it"),
            ));
        }
        if rec.exclude.is_some_and(|m| m.len() != n) {
            return Err(bad(
                label,
                "the exclusion mask does not align with the speed".into(),
            ));
        }
        let keep: Vec<usize> = (0..n)
            .filter(|&i| !rec.exclude.is_some_and(|m| m[i]))
            .collect();
        let data: Vec<f64> = keep.iter().map(|&i| full[i]).collect();
        let sigma = noise_std(&data);
        // At rest: the speed at the first sample within the noise of zero, or the mean of the
        // first five (and an encoder that has not moved). The first sample alone decides for a
        // motor that a voltage applied at that sample speeds up within five samples (a servo's
        // PRBS at 2 kHz: its head mean said "running", and the fitted start drove kS to 0).
        let head = &full[..n.min(5)];
        let head_mean = head.iter().sum::<f64>() / head.len() as f64;
        let at_rest = rec
            .at_rest
            .unwrap_or(full[0].abs() <= 3.0 * sigma || head_mean.abs() <= 3.0 * sigma);
        let free_start = if at_rest {
            None
        } else {
            free += 1;
            Some(free - 1)
        };
        let levels = match (rec.input, rec.priors.is_empty()) {
            (_, true) => Vec::new(),
            (Input::Piecewise { times_s, volts }, false) if volts.len() == rec.priors.len() => {
                times_s
                    .iter()
                    .zip(volts)
                    .zip(rec.priors)
                    .map(|((t, v), q)| {
                        let mut slot = |variance: f64| {
                            (variance > 0.0).then(|| {
                                nuisances += 1;
                                nuisances - 1
                            })
                        };
                        let volts_slot = slot(q.volts_variance_v2);
                        let start_slot = slot(q.start_variance_s2);
                        Level {
                            volts: *v,
                            start_s: *t,
                            volts_sd: pooled_level_variance(
                                q.volts_variance_v2,
                                q.volts_bias_variance_v2,
                                group.next().unwrap_or(1),
                            )
                            .max(0.0)
                            .sqrt(),
                            start_sd: q.start_variance_s2.max(0.0).sqrt(),
                            volts_slot,
                            start_slot,
                        }
                    })
                    .collect()
            }
            _ => {
                return Err(bad(
                    label,
                    "level priors given for a voltage that is not piecewise constant with as many levels".into(),
                ))
            }
        };
        if rec.priors.iter().any(|q| {
            !(q.volts_variance_v2.is_finite()
                && q.volts_variance_v2 >= 0.0
                && q.start_variance_s2.is_finite()
                && q.start_variance_s2 >= 0.0)
        }) {
            return Err(bad(label, "level variances must be finite and ≥ 0".into()));
        }
        // Each instant's error is one common to the record plus one of its own, each with the
        // variance of a change within its sample period: the prior holds for an excitation
        // clocked with the logger (every change at the same point of its period) and for one
        // that is not (each change anywhere in its period).
        let common_start_slot = levels.iter().any(|l| l.start_slot.is_some()).then(|| {
            nuisances += 1;
            nuisances - 1
        });
        prepared.push(FfRecord {
            input: rec.input.clone(),
            dt: rec.dt,
            n,
            kind,
            keep,
            floor: noise_floor(&data),
            data,
            sigma,
            free_start,
            levels,
            common_start_slot,
        });
        positions.push(position);
    }
    // Start: the inverse model E = kA Ω̇ + kV Ω + kS sign Ω on every record, the voltage as
    // the "torque" (no offset: the model has none), decimated by START_DECIMATION: a record
    // too short for it is refused here, in the fit's own terms.
    let min = crate::current_driven::mechanical::min_samples(START_DECIMATION);
    if let Some(r) = prepared.iter().find(|r| r.n < min) {
        return Err(bad(
            "record",
            format!(
                "{} samples: the voltage-and-speed fit needs at least {min} (record for longer, or at a higher rate)",
                r.n
            ),
        ));
    }
    let voltages: Vec<Vec<f64>> = prepared
        .iter()
        .map(|r| {
            (0..r.n)
                .map(|i| r.input.volts_at(i as f64 * r.dt))
                .collect()
        })
        .collect();
    let axis: Vec<AxisRecord<'_>> = prepared
        .iter()
        .zip(&voltages)
        .zip(&positions)
        .map(|((r, v), q)| AxisRecord {
            dt: r.dt,
            torque: v,
            position: q,
        })
        .collect();
    let dt_min = prepared.iter().map(|r| r.dt).fold(f64::INFINITY, f64::min);
    // At a fiftieth of the sample rate, else lower where the angle's resolution does not
    // support that cut-off (a slow motor read through an encoder: the quantisation,
    // differentiated twice, would bias the start's kA).
    let mut inverse = Err(FitError::Solver("no start tried".into()));
    for fraction in START_CUTOFFS {
        inverse = identify_inverse_model_pooled(
            &axis,
            InverseModelSettings {
                position_cutoff_hz: fraction / dt_min,
                position_filter_order: 4,
                decimation: START_DECIMATION,
                fit_offset: false,
            },
        );
        if inverse.is_ok() {
            break;
        }
    }
    let inverse = inverse.map_err(|e| FitError::MethodDomain {
        equation: "voltage-to-speed start (E = kS sign Ω + kV Ω + kA dΩ/dt)",
        reason: e.to_string(),
    })?;
    let motor_model::AxisParams {
        mass_kg: ka0,
        viscous_ns_per_m: kv0,
        coulomb_n: ks0,
        ..
    } = inverse.axis;
    let peak_e = voltages
        .iter()
        .flatten()
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    let peak_w = prepared
        .iter()
        .flat_map(|r| r.data.iter())
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    if !(peak_w > 0.0 && peak_e > 0.0) {
        return Err(bad(
            "records",
            "the motor never moves: nothing to identify — record it with a voltage that breaks the friction, Eq. (11)".into(),
        ));
    }
    let kv0 = if kv0 > 0.0 { kv0 } else { peak_e / peak_w };
    let ka0 = if ka0 > 0.0 { ka0 } else { kv0 * 10.0 * dt_min };
    let ks0 = if ks0 > 0.0 { ks0 } else { 1e-3 * peak_e };
    let n_data = prepared.iter().map(|r| r.data.len()).sum::<usize>();
    let mut problem = FfProblem {
        records: prepared,
        electrical: false,
        back_emf: settings.torque_constant,
        share_at_zero: false,
        free_starts: free,
        level_nuisances: nuisances,
        n_data,
        speed_scale: peak_w,
    };
    // Each record's noise as its samples show it, before any weighting by residuals.
    let noise: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
    let mut theta0 = vec![ks0.ln(), kv0.ln(), ka0.ln()];
    for r in &problem.records {
        if r.free_start.is_some() {
            theta0.push(r.data.first().copied().unwrap_or(0.0) / peak_w);
        }
    }
    theta0.extend(std::iter::repeat_n(0.0, nuisances));
    let mut iterations = 0;
    let reduced = fit_stages(&mut problem, &theta0, settings.lm, &mut iterations)?;
    // The kept fit, what it says of τe, and its uncertainty where already computed.
    let mut result = (reduced.clone(), TauE::Neglected, None);
    // The reduced fit is only a start for the model with τe: one that stalled (the reduced
    // model disagreeing with a record whose τe is not small) starts it as well.
    let usable = reduced.termination.converged() || reduced.termination == Termination::Stalled;
    if settings.electrical && usable {
        let p = problem
            .params_of(&reduced.params)
            .ok_or_else(|| FitError::Solver("parameters left the representable range".into()))?;
        // τe from several starts about the sample period and up to a tenth of τm (the cost
        // has a local minimum where τe trades against kS at every reversal); the lowest wins.
        // Where none explains the records down to their noise, τe is not small against τm (an
        // underdamped motor: τe = 0.1 s against τm = 0.04 s), and starts about the reduced τm
        // follow.
        problem.electrical = true;
        let sigmas: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
        let tau_m = p.constants.tau_m_s();
        let near_sample = [0.1, 0.3, 1.0, 3.0].map(|x| x * dt_min);
        let near_tau_m = [0.3, 1.0, 3.0].map(|x| x * tau_m);
        let mut best: Option<(LmReport, Vec<f64>, f64)> = None;
        for (i, tau0) in near_sample.into_iter().chain(near_tau_m).enumerate() {
            let about_tau_m = i >= near_sample.len();
            if about_tau_m {
                let explained = best
                    .as_ref()
                    .is_some_and(|(fit, _, _)| explains(&problem, &fit.params, &noise));
                if explained {
                    break;
                }
            } else if tau0 >= 0.1 * tau_m && best.is_some() {
                continue;
            }
            for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                r.sigma = *s;
            }
            let mut theta = reduced.params[..3].to_vec();
            // Where τe's lag at the reversals looks like a smaller kS, the reduced fit can
            // drive kS to 0 (its logarithm far below the start's): kS restarts there from the
            // start's value, or its gradient in the logarithm vanishes.
            if ks_collapsed(theta[0], ks0) {
                theta[0] = ks0.ln();
            }
            theta.push(
                if about_tau_m {
                    tau0
                } else {
                    tau0.min(0.1 * tau_m)
                }
                .ln(),
            );
            theta.extend_from_slice(&reduced.params[3..]);
            if settings.torque_constant.is_none() {
                theta.push(0.0); // the viscous share of kV at its prior mean
            }
            let fit = fit_stages(&mut problem, &theta, settings.lm, &mut iterations)?;
            // A fit that drove kS to 0 (its logarithm far below the start's) leaves kS no
            // interval, so it is no result; the next starts are tried instead (with R and k
            // given, a PRBS of the paper's motor read by an encoder converged there from every
            // start about the sample period, and fitted kS from those about τm).
            if !fit.termination.converged() || ks_collapsed(fit.params[0], ks0) {
                continue;
            }
            // Starts compared at the records' own noise levels (the second stage's weights
            // differ from one start to the next).
            let weights: Vec<f64> = problem.records.iter().map(|r| r.sigma).collect();
            for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                r.sigma = *s;
            }
            let cost = problem.cost(&fit.params).unwrap_or(f64::INFINITY);
            if best.as_ref().is_none_or(|(_, _, c)| cost < *c) {
                best = Some((fit, weights, cost));
            }
        }
        // Kept whenever it converged: its intervals carry what τe leaves unknown.
        let mut kept = None;
        if let Some((fit, weights, _)) = best {
            for (r, s) in problem.records.iter_mut().zip(&weights) {
                r.sigma = *s;
            }
            let unc = fit_uncertainty(&problem, &fit);
            let ci = unc.as_ref().map(|u| intervals_of(&problem, &fit, u));
            // Without k, kA can trade against τe and the viscous share of kV (no interval, or
            // kA's reaching 0): then the two coefficients the records fix are fitted instead.
            let undetermined = ci.as_ref().is_none_or(|(_, c)| c[2][0] <= 0.0);
            let unc = unc.filter(|_| !undetermined);
            kept = if settings.torque_constant.is_none() && undetermined {
                traded(&mut problem, &fit, ks0, settings.lm, &mut iterations)?
            } else {
                ci.map(|(_, c)| {
                    let ci = c[3];
                    // τe is reported where it is significantly above 0 (its interval
                    // excludes 0).
                    let t = if ci[0] > 0.0 {
                        TauE::Fitted {
                            value_s: fit.params[3].exp(),
                            ci95_s: ci,
                        }
                    } else {
                        TauE::NotResolved { upper_s: ci[1] }
                    };
                    (fit, t, unc)
                })
            };
        }
        match kept {
            Some(r) => result = r,
            None => {
                problem.electrical = false;
                for (r, s) in problem.records.iter_mut().zip(&sigmas) {
                    r.sigma = *s;
                }
                result.1 = TauE::Unfitted;
                result.2 = None;
            }
        }
    }
    let (report, tau_e, unc) = result;
    let model = problem
        .params_of(&report.params)
        .ok_or_else(|| FitError::Solver("parameters left the representable range".into()))?;
    let ci95 = unc
        .or_else(|| fit_uncertainty(&problem, &report))
        .map(|u| intervals_of(&problem, &report, &u))
        .map(|(_, ci)| {
            let ka = match tau_e {
                TauE::Traded { lead_ci95, .. } => [0.0, lead_ci95[1]],
                _ => ci[2],
            };
            [ci[0], ci[1], ka]
        });
    let initial_speed_rad_s = problem
        .records
        .iter()
        .map(|r| problem.initial_speed(r, &report.params))
        .collect();
    let quality = problem.quality(&report.params);
    let residual_over_noise = residual_over_noise(&quality, &noise);
    Ok(FeedforwardFit {
        residual_over_noise,
        params: model.constants,
        ci95,
        tau_e,
        initial_speed_rad_s,
        quality,
        iterations,
        termination: report.termination,
    })
}

/// Residual RMS over noise below which a fit explains a record (the noise estimate of
/// [`noise_std`] is itself rough by tens of per cent; fits that explain their records gave
/// 0.99–1.15 on the fixtures' motors, the reduced model of an underdamped one 11–65).
pub const EXPLAINED_RATIO: f64 = 2.0;

/// Each record's residual RMS in `quality` over that record's `noise`.
fn residual_over_noise(quality: &[ChannelQuality], noise: &[f64]) -> Vec<f64> {
    quality
        .iter()
        .zip(noise)
        .map(|(q, s)| q.rms_residual / s)
        .collect()
}

/// Whether the model at `theta` leaves on every record a residual within
/// [`EXPLAINED_RATIO`] of that record's `noise`.
fn explains(problem: &FfProblem, theta: &[f64], noise: &[f64]) -> bool {
    residual_over_noise(&problem.quality(theta), noise)
        .iter()
        .all(|&x| x <= EXPLAINED_RATIO)
}

/// Two stages from `theta0`: the records weighted by their noise, then (if the first
/// converged) by their residual RMS. Counts the iterations into `iterations`.
fn fit_stages(
    problem: &mut FfProblem,
    theta0: &[f64],
    lm: LmSettings,
    iterations: &mut u64,
) -> Result<LmReport, FitError> {
    let first = solve(&*problem, theta0, lm)?;
    *iterations += first.iterations;
    if !first.termination.converged() {
        return Ok(first);
    }
    let quality = problem.quality(&first.params);
    let mut changed = false;
    for (r, q) in problem.records.iter_mut().zip(&quality) {
        if let Some(s) = reweighted_sigma(r.sigma, r.floor, q.rms_residual) {
            r.sigma = s;
            changed = true;
        }
    }
    if !changed {
        return Ok(first);
    }
    let second = solve(&*problem, &first.params, lm)?;
    *iterations += second.iterations;
    Ok(second)
}

/// Standard errors and 95 % intervals of the model's parameters (kS, kV, kA, and τe when
/// fitted; SI units) at `report`, from its uncertainty `unc` ([`fit_uncertainty`]: the
/// Newey–West sandwich record by record), computed once per kept fit.
fn intervals_of(
    problem: &FfProblem,
    report: &LmReport,
    unc: &Uncertainty,
) -> (Vec<f64>, Vec<[f64; 2]>) {
    let m = problem.n_model();
    let values: Vec<f64> = report.params[..m].iter().map(|t| t.exp()).collect();
    let std: Vec<f64> = (0..m).map(|i| values[i] * unc.std_error[i]).collect();
    let ci = (0..m)
        .map(|i| {
            let half = values[i] * unc.ci95_half_width[i];
            [values[i] - half, values[i] + half]
        })
        .collect();
    (std, ci)
}

/// The sandwich uncertainty of every fitted parameter (in the fit's own coordinates: the
/// logarithms of the constants and of τe, then the initial speeds and the nuisances), each
/// standard error at least the model-based one ([`at_least`]: the small servo's staircase
/// with a tachometer, R and k given, missed kA in 30 of 200 noise seeds with the Newey–West
/// one alone, 10 with the floor).
fn fit_uncertainty(problem: &FfProblem, report: &LmReport) -> Option<Uncertainty> {
    let (mut r, jac) = problem.jacobian(&report.params)?;
    // A prior's row enters the score's covariance with its expected square, 1 (its variance),
    // not the realised one: at the prior mean that would be 0 and the prior's uncertainty lost.
    let priors = problem.nuisances();
    let n = r.len();
    r[n - priors..].iter_mut().for_each(|v| *v = 1.0);
    // Readings that repeat exactly share one quantisation error (an encoder's speed held at 0
    // while the rotor creeps through a reversal): see [`newey_west_run_covariance`].
    let mut runs: Vec<usize> = problem
        .records
        .iter()
        .flat_map(|rec| equal_runs(&rec.data))
        .collect();
    runs.extend(std::iter::repeat_n(1, priors));
    let score = newey_west_run_covariance(&r, &jac, &problem.series(), &runs)?;
    let hac = sandwich_uncertainty(&report.normal, &score)?;
    // The model-based score covariance, `s² J_dᵀJ_d` of the data rows (`s²` their mean square
    // over n − p) and the priors' own: a floor under the Newey–West one ([`at_least`]).
    let data = n - priors;
    let dof = data.checked_sub(jac.ncols()).filter(|&d| d > 0)?;
    let s2 = r[..data].iter().map(|v| v * v).sum::<f64>() / dof as f64;
    let jd = jac.rows(0, data);
    let jp = jac.rows(data, priors);
    let model = jd.transpose() * jd * s2 + jp.transpose() * jp;
    let based = sandwich_uncertainty(&report.normal, &model)?;
    at_least(hac, &based)
}

/// [`TauE::Traded`] of `fit` (with τe, no torque constant given, kA undetermined): refitted
/// with the viscous share of kV fixed at 0, where the model's two coefficients are its own
/// parameters (`lead = kA`, `kA τe`), their intervals from that fit's sandwich covariance (the
/// product's by the delta method on `ln kA + ln τe`). `problem` is left in that mode when the
/// refit gives intervals (the returned report is in its coordinates), else restored; `None`
/// when the refit fails. kS restarts from `ks0` \[V\] (the start's) where `fit` drove it to 0,
/// as the stage with τe does.
fn traded(
    problem: &mut FfProblem,
    fit: &LmReport,
    ks0: f64,
    lm: LmSettings,
    iterations: &mut u64,
) -> Result<Option<(LmReport, TauE, Option<Uncertainty>)>, FitError> {
    let Some(p) = problem.params_of(&fit.params) else {
        return Ok(None);
    };
    // The start: the same two coefficients with the share at 0.
    let (ka, tau_e) = (p.constants.ka_v_s2_per_rad, p.tau_e_s);
    let lead = ka + tau_e * (p.constants.kv_v_s_per_rad - p.back_emf_v_s_per_rad);
    let mut theta: Vec<f64> = fit.params[..fit.params.len() - 1].to_vec();
    theta[2] = lead.ln();
    theta[3] = (ka * tau_e / lead).ln();
    if ks_collapsed(theta[0], ks0) {
        theta[0] = ks0.ln();
    }
    problem.share_at_zero = true;
    let refit = fit_stages(problem, &theta, lm, iterations)?;
    let traded = refit
        .termination
        .converged()
        .then(|| fit_uncertainty(problem, &refit))
        .flatten()
        .and_then(|unc| {
            let ratio = unc.ci95_half_width[2] / unc.std_error[2];
            let (ln_ka, ln_tau) = (refit.params[2], refit.params[3]);
            let lead = ln_ka.exp();
            let product = (ln_ka + ln_tau).exp();
            let c = &unc.covariance;
            let h_lead = lead * unc.ci95_half_width[2];
            let h_product =
                product * ratio * (c[(2, 2)] + 2.0 * c[(2, 3)] + c[(3, 3)]).max(0.0).sqrt();
            (h_lead < lead && h_product < product).then_some((
                TauE::Traded {
                    lead_v_s2_per_rad: lead,
                    lead_ci95: [lead - h_lead, lead + h_lead],
                    product_v_s3_per_rad: product,
                    product_ci95: [product - h_product, product + h_product],
                },
                unc,
            ))
        });
    match traded {
        Some((t, unc)) => Ok(Some((refit, t, Some(unc)))),
        None => {
            problem.share_at_zero = false;
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact solution against a fine explicit integration of the same equation, through a
    /// stop and a restart the other way.
    #[test]
    fn the_closed_form_matches_a_fine_integration_through_reversals() {
        let p = FeedforwardParams {
            ks_v: 0.3,
            kv_v_s_per_rad: 0.05,
            ka_v_s2_per_rad: 0.01,
        };
        let input = Input::piecewise(&[(0.0105, 6.0), (0.4003, -4.0), (0.9, 0.2)]).unwrap();
        let (dt, n) = (1e-3, 1500);
        let (speed, angle) = simulate_feedforward(&p, &input, dt, n, 0.0);
        let (mut w, mut th) = (0.0_f64, 0.0_f64);
        let h = 1e-7;
        let per = (dt / h).round() as usize;
        for i in 0..n {
            assert!(
                (speed[i] - w).abs() < 1e-4 * 120.0,
                "speed at {i}: {} vs {w}",
                speed[i]
            );
            assert!(
                (angle[i] - th).abs() < 1e-4 * 50.0,
                "angle at {i}: {} vs {th}",
                angle[i]
            );
            for s in 0..per {
                let t = i as f64 * dt + (s as f64 + 0.5) * h;
                let e = input.volts_at(t);
                let d = if w != 0.0 {
                    w.signum()
                } else if e.abs() > p.ks_v {
                    e.signum()
                } else {
                    0.0
                };
                if d == 0.0 {
                    continue;
                }
                let wn = w + h * (e - p.ks_v * d - p.kv_v_s_per_rad * w) / p.ka_v_s2_per_rad;
                th += 0.5 * (w + wn) * h;
                w = if wn * d < 0.0 { 0.0 } else { wn };
            }
        }
        // It stopped after the reversal command and ran the other way.
        assert!(speed[600] < -10.0, "{}", speed[600]);
        // 0.2 V is inside the dead band: at rest at the end.
        assert_eq!(speed[n - 1], 0.0);
    }
}
