//! `motorid model`: the derived constants (16)–(25) of a motor.

use anyhow::Result;
use fit::FeedforwardParams;
use motor_model::{Derived, MotorParams, Regime};
use serde_json::json;

use crate::args::ModelArgs;
use crate::console::outln;
use crate::settings;

/// SI unit of every number `motorid model --json` prints, by key (the motor's by its own
/// keys).
const UNITS: [(&str, &str); 20] = [
    ("KE", "A/V"),
    ("Ks", "A/(N·m)"),
    ("tau_e", "s"),
    ("tau_m", "s"),
    ("wn", "rad/s"),
    ("zeta", "-"),
    ("wa", "rad/s"),
    ("sigma", "1/s"),
    ("alpha", "-"),
    ("gamma", "-"),
    ("i0", "A"),
    ("kS", "V"),
    ("kV", "V·s/rad"),
    ("kA", "V·s²/rad"),
    ("R", "ohm"),
    ("L", "H"),
    ("k", "N·m/A"),
    ("f", "N·m·s/rad"),
    ("J", "kg·m²"),
    ("Ts", "N·m"),
];

/// The derived constants as a JSON object (keys KE, Ks, wn, zeta, sigma, wa, tau_m, tau_e,
/// alpha, gamma, i0, regime), the voltage-to-speed feedforward constants kS, kV, kA of the
/// motor (`E = kS sign(Ω) + kV Ω + kA dΩ/dt`, Eq. (2) with L neglected), the motor beside them,
/// and `units`: the SI unit of every number, by key.
pub fn to_json(p: &MotorParams) -> serde_json::Value {
    let d = Derived::new(p);
    let ff = FeedforwardParams::of_motor(p);
    let mut v = serde_json::to_value(d).unwrap_or_default();
    if let Some(obj) = v.as_object_mut() {
        obj.insert("kS".into(), json!(ff.ks_v));
        obj.insert("kV".into(), json!(ff.kv_v_s_per_rad));
        obj.insert("kA".into(), json!(ff.ka_v_s2_per_rad));
        obj.insert("motor".into(), json!(p));
        obj.insert(
            "units".into(),
            UNITS
                .iter()
                .map(|&(k, u)| (k.to_string(), json!(u)))
                .collect(),
        );
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
    let ff = FeedforwardParams::of_motor(&p);
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
        (
            "kS",
            format!("{:.6}", ff.ks_v),
            "V",
            "static voltage R Ts/k (feedforward, Eq. (2) with L neglected)",
        ),
        (
            "kV",
            format!("{:.6}", ff.kv_v_s_per_rad),
            "V·s/rad",
            "velocity voltage k + R f/k",
        ),
        (
            "kA",
            format!("{:.6}", ff.ka_v_s2_per_rad),
            "V·s²/rad",
            "acceleration voltage R J/k",
        ),
    ];
    for (name, value, unit, what) in rows {
        outln!("  {name:<6} {value:>14} {unit:<8} {what}")?;
    }
    Ok(())
}
