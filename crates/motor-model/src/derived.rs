use serde::Serialize;

use crate::params::MotorParams;

/// Damping regime of the moving motor, from the sign of `σ² − ωn²`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// ζ > 1: real poles `−σ ± ωa`; the paper's forms (13)–(15), (B.17)–(B.20), (C.4).
    Overdamped,
    /// ζ = 1 exactly: double pole `−ωn`; (B.14)–(B.16).
    Critical,
    /// ζ < 1: complex poles `−σ ± jωa`; (B.10)–(B.13).
    Underdamped,
}

/// The derived constants of Eqs. (16)–(25) and (B.10), SI units.
///
/// `omega_a` is the damped pulsation in every regime: `ωn √|ζ² − 1|` (22) for ζ > 1 and
/// `ω_a^(o) = ωn √(1 − ζ²)` (B.10) for ζ < 1; `alpha` and `gamma` likewise take the real
/// forms (24), (25) or (B.10) of the regime. At ζ = 1 they are infinite and reported as `None`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Derived {
    /// Eq. (16) voltage gain `KE = f/(Rf + k²)` \[A/V\].
    #[serde(rename = "KE")]
    pub k_e: f64,
    /// Eq. (17) torque gain `Ks = k/(Rf + k²)` \[A/(N·m)\].
    #[serde(rename = "Ks")]
    pub k_s: f64,
    /// Eq. (18) electrical time constant `τe = L/R` \[s\].
    pub tau_e: f64,
    /// Eq. (19) mechanical time constant `τm = J/f` \[s\].
    pub tau_m: f64,
    /// Eq. (20) natural pulsation `ωn = √((Rf + k²)/(LJ))` \[rad/s\].
    #[serde(rename = "wn")]
    pub omega_n: f64,
    /// Eq. (21) damping ratio `ζ = ωn (Lf + JR) / (2(Rf + k²))` \[-\].
    pub zeta: f64,
    /// Eq. (23) attenuation `σ = ζ ωn` \[1/s\].
    pub sigma: f64,
    /// Eq. (22) / (B.10) damped pulsation `ωa = ωn √|ζ² − 1|` \[rad/s\] (0 at ζ = 1).
    #[serde(rename = "wa")]
    pub omega_a: f64,
    /// Eq. (24) / (B.10) constant α \[-\]; `None` at ζ = 1 or where the real form does not exist.
    pub alpha: Option<f64>,
    /// Eq. (25) / (B.10) constant `γ = 1/√|ζ² − 1|` \[-\]; `None` at ζ = 1.
    pub gamma: Option<f64>,
    /// Eq. (26) breakaway current `i0 = Ts/k` \[A\].
    pub i0: f64,
    /// Which damping regime these constants describe.
    pub regime: Regime,
}

impl Derived {
    /// Computes (16)–(25) from the physical parameters.
    ///
    /// `σ² − ωn²` is formed as `(R/L − f/J)²/4 − k²/(LJ)`, which has no cancellation, so the
    /// regime is decided reliably even within 1e-12 of ζ = 1.
    pub fn new(p: &MotorParams) -> Self {
        let rf_k2 = p.rf_plus_k2();
        let k_e = p.f_nms_per_rad / rf_k2;
        let k_s = p.k_nm_per_a / rf_k2;
        let tau_e = p.l_henry / p.r_ohm;
        let tau_m = p.j_kgm2 / p.f_nms_per_rad;
        let omega_n = (rf_k2 / (p.l_henry * p.j_kgm2)).sqrt();
        let sigma = 0.5 * (p.r_ohm / p.l_henry + p.f_nms_per_rad / p.j_kgm2);
        let zeta = sigma / omega_n;
        let q = signed_damped_pulsation_sq(p);
        let regime = if q > 0.0 {
            Regime::Overdamped
        } else if q < 0.0 {
            Regime::Underdamped
        } else {
            Regime::Critical
        };
        let omega_a = q.abs().sqrt();
        // |ζ² − 1| = |q| / ωn², without cancellation.
        let zeta2_minus_1_abs = q.abs() / (omega_n * omega_n);
        let tau_m_omega_n = tau_m * omega_n;
        let (alpha, gamma) = match regime {
            Regime::Critical => (None, None),
            Regime::Overdamped => {
                // Eq. (24): exists only where (ζ − τm ωn)² > ζ² − 1.
                let a2 = (zeta - tau_m_omega_n).powi(2) / zeta2_minus_1_abs - 1.0;
                (
                    (a2 > 0.0).then(|| a2.sqrt()),
                    Some(1.0 / zeta2_minus_1_abs.sqrt()),
                )
            }
            Regime::Underdamped => {
                // Eq. (B.10).
                let a2 = 1.0 + (zeta - tau_m_omega_n).powi(2) / zeta2_minus_1_abs;
                (Some(a2.sqrt()), Some(1.0 / zeta2_minus_1_abs.sqrt()))
            }
        };
        Derived {
            k_e,
            k_s,
            tau_e,
            tau_m,
            omega_n,
            zeta,
            sigma,
            omega_a,
            alpha,
            gamma,
            i0: p.ts_nm / p.k_nm_per_a,
            regime,
        }
    }
}

/// `q = σ² − ωn² = ωn²(ζ² − 1)` \[1/s²\], signed: positive when overdamped.
///
/// Written as `(R/L − f/J)²/4 − k²/(LJ)` so that no large terms cancel near ζ = 1.
pub(crate) fn signed_damped_pulsation_sq(p: &MotorParams) -> f64 {
    let half_diff = 0.5 * (p.r_ohm / p.l_henry - p.f_nms_per_rad / p.j_kgm2);
    half_diff * half_diff - p.k_nm_per_a * p.k_nm_per_a / (p.l_henry * p.j_kgm2)
}
