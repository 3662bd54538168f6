//! The servo's own position loop (SPEC section 8), as its firmware runs it: the duty it
//! applies from the position set-point `goal` and the measured position.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::ModelError;
use crate::servo::load::spec;
use crate::sim::effects::{parse_kind, Domain, ParamSpec};

/// Gain of a Dynamixel XL330's position loop per unit of its register `kp` \[1/rad\]:
/// `4096/(2π · 256 · 885)` — 4096 counts a turn, the divisor 256 that the BAM project observed
/// (the e-Manual says 128) and 885 the PWM's full scale.
pub const XL330_GAIN_PER_RAD: f64 = 4096.0 / (2.0 * std::f64::consts::PI * 256.0 * 885.0);

/// A position loop: `duty = clamp(gain · (kp (goal − q) − kd q̇), ±max_duty)`, run by the
/// firmware far faster than it is logged (continuously, in the simulation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Controller {
    /// Proportional gain kp (in the firmware's own units).
    pub kp: f64,
    /// Derivative gain kd (per rad/s, in the firmware's own units; 0 for a P loop).
    pub kd: f64,
    /// Duty per unit of `kp · error` \[1/rad\].
    pub gain: f64,
    /// Largest duty magnitude (1: the full supply).
    pub max_duty: f64,
    /// The preset it was written as, if any (`dynamixel-xl330`), for reports.
    pub preset: Option<String>,
}

const P: [ParamSpec; 3] = [
    spec("kp", "kp", "-", "proportional gain", None, Domain::Positive),
    spec(
        "gain",
        "gain",
        "1/rad",
        "duty per unit of kp·error",
        Some(1.0),
        Domain::Positive,
    ),
    spec(
        "max_duty",
        "max_duty",
        "-",
        "largest duty",
        Some(1.0),
        Domain::UnitInterval,
    ),
];
const PD: [ParamSpec; 4] = [
    spec("kp", "kp", "-", "proportional gain", None, Domain::Positive),
    spec(
        "kd",
        "kd",
        "s",
        "derivative gain",
        None,
        Domain::NonNegative,
    ),
    spec(
        "gain",
        "gain",
        "1/rad",
        "duty per unit of kp·error",
        Some(1.0),
        Domain::Positive,
    ),
    spec(
        "max_duty",
        "max_duty",
        "-",
        "largest duty",
        Some(1.0),
        Domain::UnitInterval,
    ),
];
const XL330: [ParamSpec; 1] = [spec(
    "kp",
    "kp",
    "-",
    "the servo's Position P Gain register",
    None,
    Domain::Positive,
)];

const KINDS: [(&str, &[ParamSpec]); 3] = [("p", &P), ("pd", &PD), ("dynamixel-xl330", &XL330)];

impl Controller {
    /// The duty \[−\] at set-point `goal` \[rad\], position `q` \[rad\] and speed `w` \[rad/s\].
    pub fn duty(&self, goal: f64, q: f64, w: f64) -> f64 {
        let raw = self.gain * (self.kp * (goal - q) - self.kd * w);
        raw.clamp(-self.max_duty, self.max_duty)
    }
}

impl Controller {
    /// Refuses a value outside its table's domain, or a preset of another name, as
    /// [`Controller::from_str`] does.
    pub fn check(&self) -> Result<(), ModelError> {
        let failed = |reason: String| ModelError::RigSpec {
            what: "controller",
            spec: self.to_string(),
            reason,
        };
        if let Some(name) = &self.preset {
            if name != "dynamixel-xl330" {
                return Err(failed(format!("unknown preset `{name}`")));
            }
        }
        for (p, v) in PD.iter().zip([self.kp, self.kd, self.gain, self.max_duty]) {
            p.domain
                .check(p.key, v)
                .map_err(|e| failed(e.to_string()))?;
        }
        Ok(())
    }
}

impl fmt::Display for Controller {
    /// The form [`Controller::from_str`] reads (a preset as its preset).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.preset {
            Some(name) => write!(f, "{name}:kp={}", self.kp),
            None if self.kd == 0.0 => write!(
                f,
                "p:kp={},gain={},max_duty={}",
                self.kp, self.gain, self.max_duty
            ),
            None => write!(
                f,
                "pd:kp={},kd={},gain={},max_duty={}",
                self.kp, self.kd, self.gain, self.max_duty
            ),
        }
    }
}

impl FromStr for Controller {
    type Err = ModelError;

    /// Parses `p:kp=..,gain=..,max_duty=..`, `pd:kp=..,kd=..,gain=..,max_duty=..` or a
    /// preset, `dynamixel-xl330:kp=N` (gain [`XL330_GAIN_PER_RAD`], full duty).
    fn from_str(text: &str) -> Result<Self, ModelError> {
        let (name, v) = parse_kind(text, "controller", &KINDS)?;
        Ok(match name {
            "p" => Controller {
                kp: v[0],
                kd: 0.0,
                gain: v[1],
                max_duty: v[2],
                preset: None,
            },
            "pd" => Controller {
                kp: v[0],
                kd: v[1],
                gain: v[2],
                max_duty: v[3],
                preset: None,
            },
            _ => Controller {
                kp: v[0],
                kd: 0.0,
                gain: XL330_GAIN_PER_RAD,
                max_duty: 1.0,
                preset: Some(name.to_string()),
            },
        })
    }
}
