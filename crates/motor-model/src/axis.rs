//! A current-driven axis (the drive closes the current loop, so force or torque is commanded
//! directly) under a discrete PD position controller — the structure of the EMPS benchmark.
//!
//! Plant: `J q̈ = gτ ν − f q̇ − Ts sign(q̇) − offset`, with Coulomb stick-slip (the axis stays at
//! rest while `|gτ ν − offset| ≤ Ts`). Controller, once per sample period `dt` with the command
//! held in between (EMPS Eq. (6)): `ν = kp kv (qr − q) − kv q̇m`, where `q̇m` is the difference
//! of the FIR-filtered position `qf(k) = ½ (q(k) + q(k−1))`.

use serde::Serialize;

use crate::error::{finite, positive, ModelError};

/// Mechanical parameters of an axis (rotary: kg·m², N·m·s/rad, N·m; linear: kg, N·s/m, N).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AxisParams {
    /// Inertia J (or mass M).
    pub inertia: f64,
    /// Viscous friction f.
    pub viscous: f64,
    /// Coulomb friction Ts (≥ 0).
    pub coulomb: f64,
    /// Constant load offset (either sign).
    pub offset: f64,
}

/// A PD position controller with its drive gain.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PdController {
    /// Position gain kp \[1/s\].
    pub kp: f64,
    /// Velocity gain kv (command per unit speed).
    pub kv: f64,
    /// Drive gain gτ (force or torque per unit command).
    pub drive_gain: f64,
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
    positive("axis inertia", axis.inertia)?;
    finite("axis viscous friction", axis.viscous)?;
    finite("axis Coulomb friction", axis.coulomb)?;
    finite("axis offset", axis.offset)?;
    positive("sample period", dt)?;
    for (name, v) in [
        ("kp", controller.kp),
        ("kv", controller.kv),
        ("drive gain", controller.drive_gain),
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
        let command = controller.kp * controller.kv * (qr - q) - controller.kv * speed_estimate;
        let force = controller.drive_gain * command;
        positions.push(q);
        forces.push(force);
        let external = disturbance.and_then(|d| d.get(k)).copied().unwrap_or(0.0);
        let drive = force + external - axis.offset;
        (q_prev, qf_prev) = (q, qf);
        for _ in 0..SUBSTEPS {
            if v == 0.0 && drive.abs() <= axis.coulomb {
                continue; // stuck
            }
            let direction = if v != 0.0 { v.signum() } else { drive.signum() };
            let a = (drive - axis.viscous * v - axis.coulomb * direction) / axis.inertia;
            let v_next = v + a * h;
            // Sticks when the speed would cross zero and friction can hold the axis.
            v = if v != 0.0 && v_next * v < 0.0 && drive.abs() <= axis.coulomb {
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
            inertia: 2.0,
            viscous: 1.0,
            coulomb: 0.5,
            offset: 0.0,
        };
        let pd = PdController {
            kp: 20.0,
            kv: 10.0,
            drive_gain: 3.0,
        };
        let (q, _) = simulate_pd_axis(&axis, &pd, &[0.1; 5000], None, 1e-3, 0.0).unwrap();
        let dead_band = axis.coulomb / (pd.drive_gain * pd.kp * pd.kv);
        assert!((q[4999] - 0.1).abs() <= dead_band + 1e-9, "{}", q[4999]);
        // kp = kv = 0: only the disturbance acts; friction-free mass.
        let free = AxisParams {
            inertia: 2.0,
            viscous: 0.0,
            coulomb: 0.0,
            offset: 0.0,
        };
        let none = PdController {
            kp: 0.0,
            kv: 0.0,
            drive_gain: 1.0,
        };
        let (q, _) =
            simulate_pd_axis(&free, &none, &[0.0; 1001], Some(&[4.0; 1001]), 1e-3, 0.0).unwrap();
        // q(1 s) = ½ (F/M) t² = 1 m (the last sample is taken at t = 1 s).
        assert!((q[1000] - 1.0).abs() < 1e-3, "{}", q[1000]);
    }
}
