//! A geared servo's motor and friction seen from its output shaft, and the whole rig: motor,
//! gearing, known loads and the firmware's position loop.
//!
//! The armature's inductance is left out (its time constant, well under a millisecond in a
//! small servo, is far below a log's sample period), so the motor torque at the output is
//! `τm = ke/R · (V − ke q̇)` (Eq. (1) and (2) of the paper with `L dI/dt = 0`, referred to the
//! output through the gear). With the drive off (`enable` 0) the circuit is open: `τm = 0`.
//!
//! The output obeys `J_tot q̈ = τm − fv q̇ − τ_load(q) − τ_f`, `J_tot = J + Σ J_load`, where the
//! dry friction `|τ_f| ≤ Fc + Fs exp(−(q̇/ωs)²) + |μm τm + μl τ_load|` holds the output at rest while it can: a
//! gearbox's friction grows with the torque its mesh transmits. With the rotor and gears `J` on
//! one side of a rigid mesh and the loads `J_L` on the other, `J q̈ = τm − τ_mesh` and
//! `J_L q̈ = τ_mesh − τ_load` give `τ_mesh = (J_L τm + J τ_load)/(J + J_L)`; `μm` and `μl` are
//! fitted apart because the friction of a gear train depends on which side drives (a worm or a
//! high-ratio train back-drives far worse than it drives).

use serde::{Deserialize, Serialize};

use crate::error::{finite, ModelError};
use crate::servo::controller::Controller;
use crate::servo::load::Load;

/// The motor and gearbox of a servo, referred to its output shaft, in SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ServoMotor {
    /// Torque constant at the output `ke` \[N·m/A\] (= back-EMF constant \[V·s/rad\]); the
    /// motor's own is `ke / gear`.
    pub ke_nm_per_a: f64,
    /// Armature resistance R \[Ω\], with the drive's own.
    pub r_ohm: f64,
    /// Inertia of rotor and gearbox at the output J \[kg·m²\]; the rotor's own is `J / gear²`.
    pub j_kg_m2: f64,
    /// Coulomb friction at the output Fc \[N·m\].
    pub fc_nm: f64,
    /// Viscous friction at the output fv \[N·m·s/rad\].
    pub fv_nm_s_per_rad: f64,
    /// Load-dependent friction on the motor's torque μm \[−\] (module docs).
    pub mu_motor: f64,
    /// Load-dependent friction on the load's torque μl \[−\] (module docs).
    pub mu_load: f64,
    /// Stribeck peak Fs \[N·m\]: dry friction added at rest, fading as `exp(−(q̇/ωs)²)`.
    #[serde(default)]
    pub fs_nm: f64,
    /// Stribeck speed ωs \[rad/s\].
    #[serde(default = "unit_speed")]
    pub ws_rad_s: f64,
}

fn unit_speed() -> f64 {
    1.0
}

impl ServoMotor {
    /// Refuses a value that is not finite, a non-positive ke, R or J, or negative friction.
    pub fn validate(&self) -> Result<(), ModelError> {
        for (name, v, positive) in [
            ("ke", self.ke_nm_per_a, true),
            ("R", self.r_ohm, true),
            ("J", self.j_kg_m2, true),
            ("Fc", self.fc_nm, false),
            ("fv", self.fv_nm_s_per_rad, false),
            ("mu_m", self.mu_motor, false),
            ("mu_l", self.mu_load, false),
            ("Fs", self.fs_nm, false),
            ("ws", self.ws_rad_s, true),
        ] {
            let ok = v.is_finite() && if positive { v > 0.0 } else { v >= 0.0 };
            if !ok {
                return Err(ModelError::InvalidParameter {
                    name,
                    value: v,
                    reason: if positive {
                        "must be finite and greater than zero"
                    } else {
                        "must be finite and zero or more"
                    },
                });
            }
        }
        Ok(())
    }
}

/// A servo rig: its motor, gearing, known loads and (if it runs one) its position loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ServoRig {
    /// The motor at the output.
    pub motor: ServoMotor,
    /// Gear ratio N (output turns once per N motor turns; 1 when positions are the motor's).
    pub gear: f64,
    /// Known loads on the output.
    pub loads: Vec<Load>,
    /// The firmware's position loop, if any.
    pub controller: Option<Controller>,
}

impl ServoRig {
    /// Refuses an invalid motor or a gear ratio that is not finite and positive.
    pub fn validate(&self) -> Result<(), ModelError> {
        self.motor.validate()?;
        let gear = finite("gear", self.gear)?;
        if gear <= 0.0 {
            return Err(ModelError::InvalidSetting {
                name: "gear".into(),
                value: gear,
                expected: "a ratio greater than zero",
            });
        }
        Ok(())
    }

    /// Total inertia at the output \[kg·m²\]: the motor's and the loads'.
    pub fn total_inertia_kg_m2(&self) -> f64 {
        self.motor.j_kg_m2 + self.loads.iter().map(Load::inertia_kg_m2).sum::<f64>()
    }

    /// Sum of the loads' torques \[N·m\] at angle `q` \[rad\].
    pub fn load_torque_nm(&self, q: f64) -> f64 {
        self.loads.iter().map(|l| l.torque_nm(q)).sum()
    }
}
