use serde::{Deserialize, Serialize};

use crate::error::ModelError;

/// Physical parameters of a DC motor and its load (Fig. 1 of the paper), SI units.
///
/// Construct with [`MotorParams::new`], which refuses non-finite and non-positive values;
/// the fields are public for reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorParams {
    /// Armature resistance R \[Ω\].
    #[serde(rename = "R")]
    pub r_ohm: f64,
    /// Armature inductance L \[H\].
    #[serde(rename = "L")]
    pub l_henry: f64,
    /// Torque constant = back-EMF constant k \[N·m/A = V·s/rad\].
    #[serde(rename = "k")]
    pub k_nm_per_a: f64,
    /// Viscous friction coefficient f of motor + load \[N·m·s/rad\].
    #[serde(rename = "f")]
    pub f_nms_per_rad: f64,
    /// Moment of inertia J of motor + load \[kg·m²\].
    #[serde(rename = "J")]
    pub j_kgm2: f64,
    /// Coulomb (dry) friction torque Ts \[N·m\], constant magnitude, opposing motion.
    #[serde(rename = "Ts")]
    pub ts_nm: f64,
}

impl MotorParams {
    /// Builds a parameter set, refusing any value that is not finite and strictly positive
    /// (`Ts` may be zero: a motor without dry friction).
    pub fn new(
        r_ohm: f64,
        l_henry: f64,
        k_nm_per_a: f64,
        f_nms_per_rad: f64,
        j_kgm2: f64,
        ts_nm: f64,
    ) -> Result<Self, ModelError> {
        let p = MotorParams {
            r_ohm,
            l_henry,
            k_nm_per_a,
            f_nms_per_rad,
            j_kgm2,
            ts_nm,
        };
        p.validate()?;
        Ok(p)
    }

    /// The simulated motor of the paper's Sec. 4.1, Eq. (52):
    /// R = 0.3 Ω, L = 0.3 H, k = 0.15 N·m/A, f = 0.05 N·m·s/rad, J = 1 kg·m², Ts = 0.03 N·m.
    pub fn paper() -> Self {
        MotorParams {
            r_ohm: 0.3,
            l_henry: 0.3,
            k_nm_per_a: 0.15,
            f_nms_per_rad: 0.05,
            j_kgm2: 1.0,
            ts_nm: 0.03,
        }
    }

    /// Checks every field; used after deserialising, where [`MotorParams::new`] was bypassed.
    pub fn validate(&self) -> Result<(), ModelError> {
        let strictly = [
            ("R", self.r_ohm),
            ("L", self.l_henry),
            ("k", self.k_nm_per_a),
            ("f", self.f_nms_per_rad),
            ("J", self.j_kgm2),
        ];
        for (name, value) in strictly {
            if !value.is_finite() {
                return Err(ModelError::InvalidParameter {
                    name,
                    value,
                    reason: "must be a finite number",
                });
            }
            if value <= 0.0 {
                return Err(ModelError::InvalidParameter {
                    name,
                    value,
                    reason: "must be greater than zero",
                });
            }
        }
        if !self.ts_nm.is_finite() || self.ts_nm < 0.0 {
            return Err(ModelError::InvalidParameter {
                name: "Ts",
                value: self.ts_nm,
                reason: "must be a finite number of zero or more",
            });
        }
        Ok(())
    }

    /// The parameters as `[R, L, k, f, J, Ts]` (SI units), the order every array of
    /// parameters in this workspace uses.
    pub fn values(&self) -> [f64; 6] {
        [
            self.r_ohm,
            self.l_henry,
            self.k_nm_per_a,
            self.f_nms_per_rad,
            self.j_kgm2,
            self.ts_nm,
        ]
    }

    /// Builds from `[R, L, k, f, J, Ts]` (SI units), validated as by [`MotorParams::new`].
    pub fn from_values(v: [f64; 6]) -> Result<Self, ModelError> {
        MotorParams::new(v[0], v[1], v[2], v[3], v[4], v[5])
    }

    /// `R f + k²` \[N·m·Ω·s/rad … = V·s·N·m/(A·rad)\], the denominator shared by (4), (16), (17), (20).
    pub fn rf_plus_k2(&self) -> f64 {
        self.r_ohm * self.f_nms_per_rad + self.k_nm_per_a * self.k_nm_per_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_non_finite_and_non_positive_values() {
        let ok = MotorParams::paper();
        assert!(MotorParams::new(0.3, 0.3, 0.15, 0.05, 1.0, 0.0).is_ok());
        let cases = [
            (
                MotorParams { r_ohm: 0.0, ..ok },
                "R = 0: must be greater than zero",
            ),
            (
                MotorParams {
                    l_henry: -1.0,
                    ..ok
                },
                "L = -1",
            ),
            (
                MotorParams {
                    k_nm_per_a: f64::NAN,
                    ..ok
                },
                "k = NaN: must be a finite number",
            ),
            (
                MotorParams {
                    f_nms_per_rad: f64::INFINITY,
                    ..ok
                },
                "f = inf",
            ),
            (MotorParams { j_kgm2: 0.0, ..ok }, "J = 0"),
            (MotorParams { ts_nm: -0.1, ..ok }, "Ts = -0.1"),
        ];
        for (p, needle) in cases {
            let msg = p.validate().unwrap_err().to_string();
            assert!(msg.contains(needle), "{msg}");
        }
    }
}
