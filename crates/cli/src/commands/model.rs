//! `motorid model`: the derived constants (16)–(25) of a motor.

use anyhow::Result;
use motor_model::{Derived, MotorParams, Regime};
use serde_json::json;

use crate::args::ModelArgs;
use crate::console::outln;
use crate::settings;

/// The derived constants as a JSON object (keys KE, Ks, wn, zeta, sigma, wa, tau_m, tau_e,
/// alpha, gamma, i0, regime) with the motor beside them.
pub fn to_json(p: &MotorParams) -> serde_json::Value {
    let d = Derived::new(p);
    let mut v = serde_json::to_value(d).unwrap_or_default();
    if let Some(obj) = v.as_object_mut() {
        obj.insert("motor".into(), json!(p));
    }
    v
}

/// What `motorid model` prints, validated from its arguments.
pub struct Settings {
    /// The motor whose constants are derived.
    pub motor: MotorParams,
    /// One JSON object instead of the table.
    pub json: bool,
}

impl Settings {
    /// `--motor` read and checked ([`settings::motor`]).
    pub fn from_args(a: &ModelArgs) -> Result<Settings> {
        Ok(Settings {
            motor: settings::motor(&a.motor.motor)?,
            json: a.json,
        })
    }
}

/// Prints the derived constants (16)–(26) of the motor, as a table or one JSON object.
pub fn run(s: &Settings) -> Result<()> {
    let p = s.motor;
    if s.json {
        outln!("{}", serde_json::to_string_pretty(&to_json(&p))?)?;
        return Ok(());
    }
    let d = Derived::new(&p);
    outln!(
        "motor: R = {} ohm, L = {} H, k = {} N·m/A, f = {} N·m·s/rad, J = {} kg·m², Ts = {} N·m",
        p.r_ohm,
        p.l_henry,
        p.k_nm_per_a,
        p.f_nms_per_rad,
        p.j_kgm2,
        p.ts_nm
    )?;
    let regime = match d.regime {
        Regime::Overdamped => "overdamped (zeta > 1)",
        Regime::Critical => "critically damped (zeta = 1)",
        Regime::Underdamped => "underdamped (zeta < 1)",
    };
    outln!("regime: {regime}")?;
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.6}"));
    let rows = [
        ("KE", format!("{:.6}", d.k_e), "A/V", "(16) voltage gain"),
        ("Ks", format!("{:.6}", d.k_s), "A/(N·m)", "(17) torque gain"),
        (
            "tau_e",
            format!("{:.6}", d.tau_e),
            "s",
            "(18) electrical time constant",
        ),
        (
            "tau_m",
            format!("{:.6}", d.tau_m),
            "s",
            "(19) mechanical time constant",
        ),
        (
            "wn",
            format!("{:.6}", d.omega_n),
            "rad/s",
            "(20) natural pulsation",
        ),
        ("zeta", format!("{:.6}", d.zeta), "-", "(21) damping ratio"),
        (
            "wa",
            format!("{:.6}", d.omega_a),
            "rad/s",
            "(22) damped pulsation",
        ),
        (
            "sigma",
            format!("{:.6}", d.sigma),
            "1/s",
            "(23) attenuation",
        ),
        ("alpha", opt(d.alpha), "-", "(24)"),
        ("gamma", opt(d.gamma), "-", "(25)"),
        (
            "i0",
            format!("{:.6}", d.i0),
            "A",
            "(26) breakaway current Ts/k",
        ),
    ];
    for (name, value, unit, what) in rows {
        outln!("  {name:<6} {value:>14} {unit:<8} {what}")?;
    }
    Ok(())
}
