//! A current-driven axis (the drive closes the current loop, so force or torque is commanded
//! directly) under a discrete PD position controller — the structure of the EMPS benchmark.
//!
//! Plant: `J q̈ = gτ ν − f q̇ − Ts sign(q̇) − offset`, with Coulomb stick-slip (the axis stays at
//! rest while `|gτ ν − offset| ≤ Ts`). Controller, once per sample period `dt` with the command
//! held in between (EMPS Eq. (6)): `ν = kp kv (qr − q) − kv q̇m`, where `q̇m` is the difference
//! of the FIR-filtered position `qf(k) = ½ (q(k) + q(k−1))`.

use serde::Serialize;

use crate::error::{finite, positive, ModelError};

/// Mechanical parameters of a linear axis such as EMPS's, in SI units. A rotary axis reads
/// the same equations with kg·m², N·m·s/rad and N·m in place of kg, N·s/m and N.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AxisParams {
    /// Moving mass M \[kg\] (inertia J for a rotary axis).
    pub mass_kg: f64,
    /// Viscous friction Fv \[N·s/m\].
    pub viscous_ns_per_m: f64,
    /// Coulomb friction Fc \[N\] (≥ 0).
    pub coulomb_n: f64,
    /// Constant load offset \[N\] (either sign).
    pub offset_n: f64,
}

/// A PD position controller with its drive gain (EMPS Eq. (6), (7)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PdController {
    /// Position gain kp \[1/s\].
    pub kp_per_s: f64,
    /// Velocity gain kv \[V/(m/s)\]: command volts per unit speed.
    pub kv_v_per_m_s: f64,
    /// Drive gain gτ \[N/V\]: force per volt of command.
    pub drive_gain_n_per_v: f64,
}

/// EMPS drive gain gτ \[N/V\] (EMPS_Description Eq. (7)).
pub const EMPS_DRIVE_GAIN_N_PER_V: f64 = 35.15;
/// EMPS position gain kp \[1/s\] (EMPS_Description Eq. (6)).
pub const EMPS_KP_PER_S: f64 = 160.18;
/// EMPS velocity gain kv \[V/(m/s)\] (EMPS_Description Eq. (6)).
pub const EMPS_KV_V_PER_M_S: f64 = 243.45;
/// The EMPS force pulses as drive command \[V\]: the column `pulses_N` is not in newtons — the
/// recorded command `vir` jumps by exactly ±5.0 at every pulse edge (e.g. 0.833 → 5.907 at
/// t = 0.344 s), so a pulse is 5 V of command added before the drive.
pub const EMPS_PULSE_COMMAND_V: f64 = 5.0;
/// The force of one EMPS pulse on the axis \[N\]: `5 V × 35.15 N/V = 175.75 N`.
pub const EMPS_PULSE_FORCE_N: f64 = EMPS_PULSE_COMMAND_V * EMPS_DRIVE_GAIN_N_PER_V;

impl PdController {
    /// The EMPS benchmark's controller and drive (kp, kv, gτ above).
    pub fn emps() -> Self {
        PdController {
            kp_per_s: EMPS_KP_PER_S,
            kv_v_per_m_s: EMPS_KV_V_PER_M_S,
            drive_gain_n_per_v: EMPS_DRIVE_GAIN_N_PER_V,
        }
    }
}

/// `100 ‖a − b‖ / ‖a‖` \[%\] of a measured signal `a` and its simulation `b` — the EMPS
/// benchmark's relative error (Eq. (11) of its description); NaN when `a` is all zero.
pub fn relative_error_percent(measured: &[f64], simulated: &[f64]) -> f64 {
    let num: f64 = measured
        .iter()
        .zip(simulated)
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    let den: f64 = measured.iter().map(|a| a * a).sum();
    100.0 * (num / den).sqrt()
}

/// The simulation error of a record split by whether a disturbance (EMPS: a force pulse) acts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PulseSplit {
    /// RMS of `measured − simulated` over the samples where the pulse is on (signal unit).
    pub rms_on: f64,
    /// RMS over the samples where it is off (signal unit).
    pub rms_off: f64,
    /// Fraction of the samples with the pulse on.
    pub fraction_on: f64,
}

/// [`PulseSplit`] of `measured − simulated` by `pulse_on` (all three of one length; extra
/// samples of a longer slice are ignored). An empty side has an RMS of 0.
pub fn pulse_split(measured: &[f64], simulated: &[f64], pulse_on: &[bool]) -> PulseSplit {
    let mut sums = [(0.0_f64, 0_usize); 2];
    for ((m, s), on) in measured.iter().zip(simulated).zip(pulse_on) {
        let side = &mut sums[usize::from(*on)];
        side.0 += (m - s).powi(2);
        side.1 += 1;
    }
    let rms = |(sum, n): (f64, usize)| (sum / n.max(1) as f64).sqrt();
    let total = sums[0].1 + sums[1].1;
    PulseSplit {
        rms_on: rms(sums[1]),
        rms_off: rms(sums[0]),
        fraction_on: sums[1].1 as f64 / total.max(1) as f64,
    }
}

/// Integration sub-steps per controller period.
const SUBSTEPS: usize = 20;

/// Simulates the closed loop over `reference` (one sample every `dt` \[s\]) from rest at
/// `q0`, adding the external force `disturbance[k]` (if given) to the plant. Returns the
/// position and the commanded force at each sample.
pub fn simulate_pd_axis(
    axis: &AxisParams,
    controller: &PdController,
    reference: &[f64],
    disturbance: Option<&[f64]>,
    dt: f64,
    q0: f64,
) -> Result<(Vec<f64>, Vec<f64>), ModelError> {
    positive("axis inertia", axis.mass_kg)?;
    finite("axis viscous friction", axis.viscous_ns_per_m)?;
    finite("axis Coulomb friction", axis.coulomb_n)?;
    finite("axis offset", axis.offset_n)?;
    positive("sample period", dt)?;
    for (name, v) in [
        ("kp", controller.kp_per_s),
        ("kv", controller.kv_v_per_m_s),
        ("drive gain", controller.drive_gain_n_per_v),
    ] {
        finite(name, v)?;
    }
    let h = dt / SUBSTEPS as f64;
    let (mut q, mut v) = (q0, 0.0_f64);
    let (mut q_prev, mut qf_prev) = (q0, q0);
    let mut positions = Vec::with_capacity(reference.len());
    let mut forces = Vec::with_capacity(reference.len());
    for (k, &qr) in reference.iter().enumerate() {
        let qf = 0.5 * (q + q_prev);
        let speed_estimate = if k == 0 { 0.0 } else { (qf - qf_prev) / dt };
        let command = controller.kp_per_s * controller.kv_v_per_m_s * (qr - q)
            - controller.kv_v_per_m_s * speed_estimate;
        let force = controller.drive_gain_n_per_v * command;
        positions.push(q);
        forces.push(force);
        let external = disturbance.and_then(|d| d.get(k)).copied().unwrap_or(0.0);
        let drive = force + external - axis.offset_n;
        (q_prev, qf_prev) = (q, qf);
        for _ in 0..SUBSTEPS {
            if v == 0.0 && drive.abs() <= axis.coulomb_n {
                continue; // stuck
            }
            let direction = if v != 0.0 { v.signum() } else { drive.signum() };
            let a = (drive - axis.viscous_ns_per_m * v - axis.coulomb_n * direction) / axis.mass_kg;
            let v_next = v + a * h;
            // Sticks when the speed would cross zero and friction can hold the axis.
            v = if v != 0.0 && v_next * v < 0.0 && drive.abs() <= axis.coulomb_n {
                0.0
            } else {
                v_next
            };
            q += v * h;
        }
    }
    Ok((positions, forces))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step of the reference settles at the reference (PD with Coulomb friction leaves a
    /// dead band of `Ts/(gτ kp kv)`), and a free mass under a constant force accelerates as F/M.
    #[test]
    fn closed_loop_settles_and_open_loop_obeys_newton() {
        let axis = AxisParams {
            mass_kg: 2.0,
            viscous_ns_per_m: 1.0,
            coulomb_n: 0.5,
            offset_n: 0.0,
        };
        let pd = PdController {
            kp_per_s: 20.0,
            kv_v_per_m_s: 10.0,
            drive_gain_n_per_v: 3.0,
        };
        let (q, _) = simulate_pd_axis(&axis, &pd, &[0.1; 5000], None, 1e-3, 0.0).unwrap();
        let dead_band = axis.coulomb_n / (pd.drive_gain_n_per_v * pd.kp_per_s * pd.kv_v_per_m_s);
        assert!((q[4999] - 0.1).abs() <= dead_band + 1e-9, "{}", q[4999]);
        // kp = kv = 0: only the disturbance acts; friction-free mass.
        let free = AxisParams {
            mass_kg: 2.0,
            viscous_ns_per_m: 0.0,
            coulomb_n: 0.0,
            offset_n: 0.0,
        };
        let none = PdController {
            kp_per_s: 0.0,
            kv_v_per_m_s: 0.0,
            drive_gain_n_per_v: 1.0,
        };
        let (q, _) =
            simulate_pd_axis(&free, &none, &[0.0; 1001], Some(&[4.0; 1001]), 1e-3, 0.0).unwrap();
        // q(1 s) = ½ (F/M) t² = 1 m (the last sample is taken at t = 1 s).
        assert!((q[1000] - 1.0).abs() < 1e-3, "{}", q[1000]);
    }

    #[test]
    fn relative_error_and_pulse_split_of_known_signals() {
        // ‖(1, 2, 2) − (1, 2, 0)‖/‖(1, 2, 2)‖ = 2/3.
        let e = relative_error_percent(&[1.0, 2.0, 2.0], &[1.0, 2.0, 0.0]);
        assert!((e - 200.0 / 3.0).abs() < 1e-12, "{e}");
        let split = pulse_split(
            &[1.0, 1.0, 4.0, 4.0],
            &[0.0, 2.0, 1.0, 1.0],
            &[false, false, true, true],
        );
        assert_eq!(split.rms_off, 1.0);
        assert_eq!(split.rms_on, 3.0);
        assert_eq!(split.fraction_on, 0.5);
        assert!((EMPS_PULSE_FORCE_N - 175.75).abs() < 1e-9);
    }
}
