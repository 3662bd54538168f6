//! Known loads on a servo's output (SPEC section 8): given by the user, never fitted.
//!
//! Each is written `name:key=value,...` (`--load`, or `# load:` in a record) and read by the
//! same table parser as the effects'.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::sim::effects::{parse_kind, Domain, ParamSpec};

/// Standard gravity g \[m/s²\] (CGPM 1901).
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// A load on the output shaft, in SI units. Angles are the output's, `q = 0` where a pendulum
/// hangs straight down.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Load {
    /// A point mass `m` \[kg\] at distance `l` \[m\] on an arm of mass `arm` \[kg\] (a uniform rod
    /// from the axis to the mass): gravity torque `(m + arm/2) g l sin q` \[N·m\], inertia
    /// `(m + arm/3) l²` \[kg·m²\].
    Pendulum {
        /// Mass at the end `m` \[kg\].
        mass_kg: f64,
        /// Distance from the axis `l` \[m\].
        length_m: f64,
        /// Mass of the arm \[kg\].
        arm_kg: f64,
    },
    /// A rigid inertia `j` \[kg·m²\] on the output.
    Inertia {
        /// Inertia \[kg·m²\].
        j_kg_m2: f64,
    },
    /// A torsion spring: torque `k (q − q0)` \[N·m\] opposing the motor.
    Spring {
        /// Stiffness \[N·m/rad\].
        k_nm_per_rad: f64,
        /// Rest angle \[rad\].
        q0_rad: f64,
    },
    /// A constant torque \[N·m\] opposing positive motor torque.
    Constant {
        /// Torque \[N·m\].
        t_nm: f64,
    },
}

const PENDULUM: [ParamSpec; 3] = [
    spec("m", "m", "kg", "mass at the end", None, Domain::Positive),
    spec(
        "l",
        "l",
        "m",
        "distance of the mass from the axis",
        None,
        Domain::Positive,
    ),
    spec(
        "arm",
        "m_arm",
        "kg",
        "mass of the arm",
        Some(0.0),
        Domain::NonNegative,
    ),
];
const INERTIA: [ParamSpec; 1] = [spec("j", "J", "kg·m²", "inertia", None, Domain::Positive)];
const SPRING: [ParamSpec; 2] = [
    spec("k", "k", "N·m/rad", "stiffness", None, Domain::NonNegative),
    spec("q0", "q0", "rad", "rest angle", Some(0.0), Domain::Finite),
];
const CONSTANT: [ParamSpec; 1] = [spec("t", "T", "N·m", "torque", None, Domain::Finite)];

/// The load kinds by name, with their tables.
const KINDS: [(&str, &[ParamSpec]); 4] = [
    ("pendulum", &PENDULUM),
    ("inertia", &INERTIA),
    ("spring", &SPRING),
    ("constant", &CONSTANT),
];

pub(crate) const fn spec(
    key: &'static str,
    symbol: &'static str,
    unit: &'static str,
    description: &'static str,
    default: Option<f64>,
    domain: Domain,
) -> ParamSpec {
    ParamSpec {
        key,
        symbol,
        unit,
        description,
        default,
        domain,
        fitted: false,
    }
}

impl Load {
    /// Torque \[N·m\] the load applies against positive motor torque at output angle `q` \[rad\].
    pub fn torque_nm(&self, q: f64) -> f64 {
        match *self {
            Load::Pendulum {
                mass_kg,
                length_m,
                arm_kg,
            } => (mass_kg + arm_kg / 2.0) * STANDARD_GRAVITY_M_S2 * length_m * q.sin(),
            Load::Inertia { .. } => 0.0,
            Load::Spring {
                k_nm_per_rad,
                q0_rad,
            } => k_nm_per_rad * (q - q0_rad),
            Load::Constant { t_nm } => t_nm,
        }
    }

    /// Inertia \[kg·m²\] the load adds on the output.
    pub fn inertia_kg_m2(&self) -> f64 {
        match *self {
            Load::Pendulum {
                mass_kg,
                length_m,
                arm_kg,
            } => (mass_kg + arm_kg / 3.0) * length_m * length_m,
            Load::Inertia { j_kg_m2 } => j_kg_m2,
            Load::Spring { .. } | Load::Constant { .. } => 0.0,
        }
    }

    /// Refuses a value outside its table's domain, as [`Load::from_str`] does.
    pub fn check(&self) -> Result<(), ModelError> {
        for (p, v) in self.table().iter().zip(self.values()) {
            p.domain.check(p.key, v).map_err(|e| ModelError::RigSpec {
                what: "load",
                spec: self.to_string(),
                reason: e.to_string(),
            })?;
        }
        Ok(())
    }

    fn name(&self) -> &'static str {
        match self {
            Load::Pendulum { .. } => "pendulum",
            Load::Inertia { .. } => "inertia",
            Load::Spring { .. } => "spring",
            Load::Constant { .. } => "constant",
        }
    }

    /// The values in the order of its table.
    fn values(&self) -> Vec<f64> {
        match *self {
            Load::Pendulum {
                mass_kg,
                length_m,
                arm_kg,
            } => vec![mass_kg, length_m, arm_kg],
            Load::Inertia { j_kg_m2 } => vec![j_kg_m2],
            Load::Spring {
                k_nm_per_rad,
                q0_rad,
            } => vec![k_nm_per_rad, q0_rad],
            Load::Constant { t_nm } => vec![t_nm],
        }
    }

    fn table(&self) -> &'static [ParamSpec] {
        match self {
            Load::Pendulum { .. } => &PENDULUM,
            Load::Inertia { .. } => &INERTIA,
            Load::Spring { .. } => &SPRING,
            Load::Constant { .. } => &CONSTANT,
        }
    }
}

impl fmt::Display for Load {
    /// `name:key=value,...`, the form [`Load::from_str`] reads.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())?;
        for (i, (p, v)) in self.table().iter().zip(self.values()).enumerate() {
            write!(f, "{}{}={}", if i == 0 { ':' } else { ',' }, p.key, v)?;
        }
        Ok(())
    }
}

impl FromStr for Load {
    type Err = ModelError;

    /// Parses `pendulum:m=0.49,l=0.1`, `inertia:j=…`, `spring:k=…[,q0=…]`, `constant:t=…`.
    fn from_str(text: &str) -> Result<Self, ModelError> {
        let (name, v) = parse_kind(text, "load", &KINDS)?;
        Ok(match name {
            "pendulum" => Load::Pendulum {
                mass_kg: v[0],
                length_m: v[1],
                arm_kg: v[2],
            },
            "inertia" => Load::Inertia { j_kg_m2: v[0] },
            "spring" => Load::Spring {
                k_nm_per_rad: v[0],
                q0_rad: v[1],
            },
            _ => Load::Constant { t_nm: v[0] },
        })
    }
}
