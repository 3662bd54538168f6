//! The paper's own closed forms, regime by regime, as printed or as corrected.
//!
//! These exist to reproduce the paper and to cross-check [`crate::StepResponse`], which is the
//! form to use for computation (it is exact in every regime and does not lose accuracy near
//! ζ = 1, where α and γ of (24), (25) diverge). Every correction of a printed formula is listed
//! in `docs/errata.md` with its derivation; the tests in this crate show each printed form
//! failing and each corrected one agreeing with the exact response.
//!
//! All times here are `τ = t − t0` \[s\], the time since breakaway (Appendix B convention),
//! except for the approximations (32), (33), (C.8), which the paper writes in `t`.

use crate::derived::{Derived, Regime};
use crate::error::ModelError;
use crate::params::MotorParams;

/// The three components of the current after breakaway, Eq. (12): `I = I0 + ITs + IE` \[A\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentComponents {
    /// Response to the initial current `Ts/k`, Eq. (13) / (B.11) / (B.14) \[A\].
    pub i_0: f64,
    /// Response to the Coulomb torque, Eq. (14) / (B.12) / (B.15) \[A\].
    pub i_ts: f64,
    /// Response to the voltage step, Eq. (15) / (B.13) / (B.16) \[A\].
    pub i_e: f64,
}

impl CurrentComponents {
    /// Eq. (12): the total current \[A\].
    pub fn total(&self) -> f64 {
        self.i_0 + self.i_ts + self.i_e
    }
}

fn domain(formula: &'static str, reason: String) -> ModelError {
    ModelError::OutOfDomain { formula, reason }
}

/// α of Eq. (24) where the ζ > 1 forms hold.
///
/// They hold iff the zero `−1/τm` of `I_E(s)` (B.6) lies between the slow pole and the origin,
/// which (the characteristic polynomial being `k² > 0` at both `−1/τm` and `−1/τe`, so that one
/// of them lies on each side of the poles) is exactly `τm > τe`. Otherwise α may still be real,
/// but on the other branch, and (13)–(15) give wrong values.
fn overdamped_alpha(d: &Derived, formula: &'static str) -> Result<f64, ModelError> {
    match (d.regime, d.alpha) {
        (Regime::Overdamped, Some(alpha)) if d.tau_m > d.tau_e => Ok(alpha),
        (Regime::Overdamped, _) => Err(domain(
            formula,
            format!(
                "the zeta > 1 forms need tau_m > tau_e; this motor has tau_m = {} s, tau_e = {} s",
                d.tau_m, d.tau_e
            ),
        )),
        _ => Err(domain(
            formula,
            format!(
                "it is written for zeta > 1; this motor has zeta = {}",
                d.zeta
            ),
        )),
    }
}

/// The current components (12)–(15) at `tau_s` \[s\] after breakaway of a step `e_volt` \[V\] ≥ 0,
/// in the form of the motor's damping regime:
///
/// - ζ > 1, Eqs. (13)–(15) as printed (valid where τm > τe — the usual servo; otherwise an
///   `OutOfDomain` error);
/// - ζ < 1, Eqs. (B.11)–(B.13) with the phase taken in the right quadrant (`atan2`) and the sign
///   of (B.12) corrected (errata E2, E3);
/// - ζ = 1, Eqs. (B.14)–(B.16) with (B.16) corrected (erratum E4).
///
/// The regime is the exact one of [`Derived::regime`]; near ζ = 1 these forms lose accuracy
/// (α, γ → ∞) and [`crate::StepResponse`] should be used instead.
pub fn current_components(
    p: &MotorParams,
    e_volt: f64,
    tau_s: f64,
) -> Result<CurrentComponents, ModelError> {
    let d = Derived::new(p);
    let (ts, k, l) = (p.ts_nm, p.k_nm_per_a, p.l_henry);
    let (wn, zeta, sigma, wa, tau_m) = (d.omega_n, d.zeta, d.sigma, d.omega_a, d.tau_m);
    let decay = (-sigma * tau_s).exp();
    match d.regime {
        Regime::Overdamped => {
            let alpha = overdamped_alpha(&d, "Eqs. (13)-(15)")?;
            let gamma = d.gamma.unwrap_or(f64::INFINITY);
            Ok(CurrentComponents {
                // Eq. (13)
                i_0: -d.k_e * l * wn * alpha * ts / k
                    * decay
                    * (wa * tau_s - (tau_m * wn / alpha).asinh()).sinh(),
                // Eq. (14)
                i_ts: d.k_s
                    * ts
                    * (1.0 - gamma * decay * (wa * tau_s + (1.0 / gamma).asinh()).sinh()),
                // Eq. (15)
                i_e: d.k_e
                    * e_volt
                    * (1.0 + alpha * decay * (wa * tau_s + (-1.0 / alpha).asinh()).sinh()),
            })
        }
        Regime::Underdamped => {
            let alpha = d.alpha.unwrap_or(f64::NAN);
            let gamma = d.gamma.unwrap_or(f64::NAN);
            let root = (1.0 - zeta * zeta).sqrt();
            // (B.11) corrected: α° sin φ0 = τm ωn, α° cos φ0 = (1 − ζ τm ωn)/√(1 − ζ²).
            let phi_0 = (tau_m * wn).atan2((1.0 - zeta * tau_m * wn) / root);
            // (B.12) corrected: φs = sin⁻¹(1/γ°) = cos⁻¹ ζ.
            let phi_s = zeta.acos();
            // (B.13) corrected: α° sin φE = 1, α° cos φE = (ζ − τm ωn)/√(1 − ζ²).
            let phi_e = 1.0_f64.atan2((zeta - tau_m * wn) / root);
            Ok(CurrentComponents {
                i_0: l * ts / k * d.k_e * alpha * wn * decay * (wa * tau_s + phi_0).sin(),
                i_ts: d.k_s * ts * (1.0 - gamma * decay * (wa * tau_s + phi_s).sin()),
                i_e: d.k_e * e_volt * (1.0 - alpha * decay * (wa * tau_s + phi_e).sin()),
            })
        }
        Regime::Critical => Ok(CurrentComponents {
            // (B.14)
            i_0: l * ts / k * d.k_e * wn * wn * decay * (tau_m + (1.0 - wn * tau_m) * tau_s),
            // (B.15)
            i_ts: d.k_s * ts * (1.0 - decay * (1.0 + wn * tau_s)),
            // (B.16) corrected: 1 − e^{−ωn τ}[1 + ωn(1 − ωn τm) τ].
            i_e: d.k_e * e_volt * (1.0 - decay * (1.0 + wn * (1.0 - wn * tau_m) * tau_s)),
        }),
    }
}

/// Eq. (C.4): the speed \[rad/s\] at `tau_s` \[s\] after breakaway of a step `e_volt` \[V\] ≥ 0,
/// as printed (ζ > 1 only; the paper gives no other regime — use [`crate::StepResponse`]).
pub fn speed_c4(p: &MotorParams, e_volt: f64, tau_s: f64) -> Result<f64, ModelError> {
    let d = Derived::new(p);
    let alpha = overdamped_alpha(&d, "Eq. (C.4)")?;
    let gamma = d.gamma.unwrap_or(f64::INFINITY);
    let (ts, k, f, l) = (p.ts_nm, p.k_nm_per_a, p.f_nms_per_rad, p.l_henry);
    let (wn, zeta, sigma, wa, tau_m) = (d.omega_n, d.zeta, d.sigma, d.omega_a, d.tau_m);
    let decay = (-sigma * tau_s).exp();
    let mech = (-tau_s / tau_m).exp();
    let from_i0 = l * ts / k * d.k_e * gamma * wn * decay * (wa * tau_s).sinh();
    let from_ts = ts
        * d.k_s
        * (1.0 - (tau_m * wn * gamma / alpha).powi(2) * mech
            + gamma * gamma / alpha
                * decay
                * (wa * tau_s + (-(1.0 - 2.0 * zeta * tau_m * wn) / alpha).asinh()).sinh());
    let from_e =
        e_volt * d.k_e * (1.0 - gamma * decay * (wa * tau_s + (1.0 / gamma).asinh()).sinh());
    Ok(k / f * (from_i0 + from_ts + from_e) - ts / f * (1.0 - mech))
}

/// Eq. (33): the normalised high-voltage current `Ī(t) = 1 + α e^{−σt} sinh(ωa t − sinh⁻¹(1/α))`
/// \[-\] at `t_s` \[s\]; α \[-\], σ \[1/s\], ωa \[rad/s\]. The model the paper fits in Sec. 2.4.
pub fn normalized_current_33(alpha: f64, sigma: f64, omega_a: f64, t_s: f64) -> f64 {
    1.0 + alpha * (-sigma * t_s).exp() * (omega_a * t_s - (1.0 / alpha).asinh()).sinh()
}

/// Eq. (32): the high-voltage approximation `I ≈ IE(t) = KE E Ī(t)` \[A\] at `t_s` \[s\]
/// after the step (friction and breakaway neglected; valid when (31) holds).
pub fn high_voltage_current_32(p: &MotorParams, e_volt: f64, t_s: f64) -> Result<f64, ModelError> {
    let d = Derived::new(p);
    let alpha = overdamped_alpha(&d, "Eq. (32)")?;
    Ok(d.k_e * e_volt * normalized_current_33(alpha, d.sigma, d.omega_a, t_s))
}

/// Eq. (31): the smallest step voltage \[V\] for which the approximation (32) errs by less than
/// 5 %: `E > 20 Ts (R/k + k/f)`.
pub fn high_voltage_threshold_31(p: &MotorParams) -> f64 {
    20.0 * p.ts_nm * (p.r_ohm / p.k_nm_per_a + p.k_nm_per_a / p.f_nms_per_rad)
}

/// Eq. (C.8): the normalised speed `Ω_EN(τ) = 1 − γ e^{−στ} sinh(ωa τ + sinh⁻¹(1/γ))` \[-\]
/// at `tau_s` \[s\]; γ \[-\], σ \[1/s\], ωa \[rad/s\]. Depends on ωn and ζ only.
pub fn normalized_speed_c8(gamma: f64, sigma: f64, omega_a: f64, tau_s: f64) -> f64 {
    1.0 - gamma * (-sigma * tau_s).exp() * (omega_a * tau_s + (1.0 / gamma).asinh()).sinh()
}

/// Eq. (C.6): the dominant-terms approximation of the speed \[rad/s\] at `tau_s` \[s\] after
/// breakaway, `EKE k/f [C.8] − Ts (1 − k Ks)/f (1 − e^{−στ/4.45})` (the 4.45 is the paper's
/// empirical constant).
pub fn approximate_speed_c6(p: &MotorParams, e_volt: f64, tau_s: f64) -> Result<f64, ModelError> {
    let d = Derived::new(p);
    let (Regime::Overdamped, Some(gamma)) = (d.regime, d.gamma) else {
        return Err(domain(
            "Eq. (C.6)",
            format!(
                "it is written for zeta > 1; this motor has zeta = {}",
                d.zeta
            ),
        ));
    };
    /// The paper's empirical divisor of σ in the friction build-up of (C.6).
    const C6_DIVISOR: f64 = 4.45;
    let (k, f) = (p.k_nm_per_a, p.f_nms_per_rad);
    Ok(
        e_volt * d.k_e * k / f * normalized_speed_c8(gamma, d.sigma, d.omega_a, tau_s)
            - p.ts_nm * (1.0 - k * d.k_s) / f * (1.0 - (-d.sigma * tau_s / C6_DIVISOR).exp()),
    )
}
