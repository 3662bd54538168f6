use serde::Serialize;

use crate::error::ModelError;
use crate::params::MotorParams;
use crate::real::Real;

/// Eq. (11) in any scalar: `t0 = −τe ln(1 − R Ts/(k E))` for `E = e_abs > 0`, `None` when
/// `R Ts/(k E) ≥ 1`.
pub(crate) fn breakaway_generic<T: Real>(r: T, l: T, k: T, ts: T, e_abs: T) -> Option<T> {
    if e_abs.value() <= 0.0 {
        return None;
    }
    if ts.value() == 0.0 {
        return Some(T::cst(0.0));
    }
    let ratio = r * ts / (k * e_abs);
    (ratio.value() < 1.0).then(|| -(l / r) * (-ratio).ln_1p())
}

/// Eqs. (4), (5) in any scalar for `E = e_abs > 0` of a moving motor: `(Ir, Ωr)`, with Ir as
/// `KE E + Ks Ts` (49) to avoid cancellation.
pub(crate) fn steady_generic<T: Real>(r: T, k: T, f: T, ts: T, e_abs: T) -> (T, T) {
    let rf_k2 = r * f + k * k;
    ((f * e_abs + k * ts) / rf_k2, (e_abs * k - ts * r) / rf_k2)
}

/// Steady state of a voltage step, Eqs. (4) and (5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SteadyState {
    /// Eq. (4) `Ωr = (E k − Ts R)/(R f + k²)` \[rad/s\]; 0 when the motor never breaks away.
    pub speed_rad_s: f64,
    /// Eq. (5) `Ir = (E − k Ωr)/R` \[A\], computed as `KE E + Ks Ts` (49) to avoid cancellation.
    pub current_a: f64,
    /// Whether the step breaks the Coulomb friction at all (`|E| > R Ts / k`).
    pub moving: bool,
}

/// Steady state reached by a constant armature voltage `e_volt` \[V\], either sign.
///
/// When `|E| ≤ R Ts/k` the motor never breaks away: the current settles at `E/R` and the speed
/// stays 0 (Eq. (1) holds for ever).
pub fn steady_state(p: &MotorParams, e_volt: f64) -> SteadyState {
    let dir = e_volt.signum();
    let e = e_volt.abs();
    if e == 0.0 {
        return SteadyState {
            speed_rad_s: 0.0,
            current_a: 0.0,
            moving: false,
        };
    }
    if breakaway_time(p, e).is_none() {
        return SteadyState {
            speed_rad_s: 0.0,
            current_a: dir * e / p.r_ohm,
            moving: false,
        };
    }
    let (current_a, speed_rad_s) =
        steady_generic(p.r_ohm, p.k_nm_per_a, p.f_nms_per_rad, p.ts_nm, e);
    SteadyState {
        speed_rad_s: dir * speed_rad_s,
        current_a: dir * current_a,
        moving: true,
    }
}

/// Current while the rotor is still at rest, Eq. (10): `I(t) = E/R (1 − e^(−t/τe))` \[A\].
pub fn standstill_current(p: &MotorParams, e_volt: f64, t_s: f64) -> f64 {
    -e_volt / p.r_ohm * (-t_s * p.r_ohm / p.l_henry).exp_m1()
}

/// Breakaway instant of a step of `e_volt` \[V\], Eq. (11): `t0 = −τe ln(1 − R Ts/(k E))` \[s\].
///
/// `None` when `|E| ≤ R Ts/k`: the torque `k I` never exceeds `Ts` and the motor stays at rest.
pub fn breakaway_time(p: &MotorParams, e_volt: f64) -> Option<f64> {
    breakaway_generic(p.r_ohm, p.l_henry, p.k_nm_per_a, p.ts_nm, e_volt.abs())
}

/// Apparent resistance increase of Eqs. (6)–(8): `ΔR = E/Ir − R = a − b/Ir` \[Ω\].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ApparentResistance {
    /// `a = k²/f` \[Ω\], Eq. (7).
    pub a_ohm: f64,
    /// `b = Ts k / f` \[Ω·A\], Eq. (7).
    pub b_ohm_a: f64,
}

impl ApparentResistance {
    /// The law's coefficients for a motor, Eq. (7).
    pub fn of_motor(p: &MotorParams) -> Self {
        ApparentResistance {
            a_ohm: p.k_nm_per_a * p.k_nm_per_a / p.f_nms_per_rad,
            b_ohm_a: p.ts_nm * p.k_nm_per_a / p.f_nms_per_rad,
        }
    }

    /// `ΔR = a − b/Ir` \[Ω\] at steady current `ir_a` \[A\], Eq. (8).
    pub fn delta_r(&self, ir_a: f64) -> f64 {
        self.a_ohm - self.b_ohm_a / ir_a
    }

    /// Eq. (9): the Coulomb torque `Ts = k b / a` \[N·m\] given the torque constant `k`.
    pub fn coulomb_torque(&self, k_nm_per_a: f64) -> Result<f64, ModelError> {
        if self.a_ohm == 0.0 || !self.a_ohm.is_finite() {
            return Err(ModelError::OutOfDomain {
                formula: "Eq. (9) Ts = k b / a",
                reason: format!("a = {} Ω must be finite and non-zero", self.a_ohm),
            });
        }
        Ok(k_nm_per_a * self.b_ohm_a / self.a_ohm)
    }
}
