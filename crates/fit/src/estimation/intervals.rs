//! The 95 % intervals of the six motor parameters, by name and in their units.

use crate::estimation::records::PARAM_NAMES;

/// The 95 % intervals `[lo, hi]` of the six motor parameters, shaped as
/// [`MotorParams`](motor_model::MotorParams): each field in the unit of the parameter it
/// bounds (Ω, H, N·m/A, N·m·s/rad, kg·m², N·m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorIntervals {
    /// Armature resistance R \[Ω\].
    pub r_ohm: [f64; 2],
    /// Armature inductance L \[H\].
    pub l_henry: [f64; 2],
    /// Torque constant k \[N·m/A\].
    pub k_nm_per_a: [f64; 2],
    /// Viscous friction f \[N·m·s/rad\].
    pub f_nms_per_rad: [f64; 2],
    /// Inertia J \[kg·m²\].
    pub j_kgm2: [f64; 2],
    /// Coulomb friction Ts \[N·m\].
    pub ts_nm: [f64; 2],
}

impl MotorIntervals {
    /// The intervals of a solver's parameter vector, R, L, k, f, J, Ts first (further entries,
    /// an effect's or an initial state's, are not the motor's); `None` when fewer than six.
    pub(crate) fn from_solver_order(ci95: &[[f64; 2]]) -> Option<MotorIntervals> {
        match *ci95 {
            [r_ohm, l_henry, k_nm_per_a, f_nms_per_rad, j_kgm2, ts_nm, ..] => {
                Some(MotorIntervals {
                    r_ohm,
                    l_henry,
                    k_nm_per_a,
                    f_nms_per_rad,
                    j_kgm2,
                    ts_nm,
                })
            }
            _ => None,
        }
    }

    /// Each interval with the name of its parameter ([`PARAM_NAMES`]: `R`, `L`, `k`, `f`, `J`,
    /// `Ts`).
    pub fn named(&self) -> [(&'static str, [f64; 2]); 6] {
        let [r, l, k, f, j, ts] = PARAM_NAMES;
        [
            (r, self.r_ohm),
            (l, self.l_henry),
            (k, self.k_nm_per_a),
            (f, self.f_nms_per_rad),
            (j, self.j_kgm2),
            (ts, self.ts_nm),
        ]
    }

    /// The interval of the parameter named `name` (as in [`PARAM_NAMES`]), if it is one.
    pub fn get(&self, name: &str) -> Option<[f64; 2]> {
        self.named()
            .into_iter()
            .find_map(|(n, ci)| (n == name).then_some(ci))
    }

    /// Intervals `motor · (1 ∓ rel)` around each parameter of `motor`, `rel` a fraction.
    #[cfg(test)]
    pub(crate) fn relative(motor: &motor_model::MotorParams, rel: f64) -> MotorIntervals {
        let around = |v: f64| [v * (1.0 - rel), v * (1.0 + rel)];
        MotorIntervals {
            r_ohm: around(motor.r_ohm),
            l_henry: around(motor.l_henry),
            k_nm_per_a: around(motor.k_nm_per_a),
            f_nms_per_rad: around(motor.f_nms_per_rad),
            j_kgm2: around(motor.j_kgm2),
            ts_nm: around(motor.ts_nm),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_solver_order() {
        let ci: Vec<[f64; 2]> = (0..7).map(|i| [i as f64, i as f64 + 0.5]).collect();
        let iv = MotorIntervals::from_solver_order(&ci).unwrap();
        assert_eq!(iv.get("R"), Some([0.0, 0.5]));
        assert_eq!(iv.get("Ts"), Some([5.0, 5.5]));
        assert_eq!(iv.get("x"), None);
        assert!(MotorIntervals::from_solver_order(&ci[..5]).is_none());
    }
}
