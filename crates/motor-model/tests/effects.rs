//! Each effect of SPEC section 5 leaves its signature in a simulated record.

use motor_model::{
    breakaway_time, Effect, Effects, Input, MotorParams, Simulator, StepResponse, Trace,
};

fn run(effect: &str, input: Input, duration: f64, rate: f64) -> Trace {
    let effects = Effects::none().with(effect.parse::<Effect>().unwrap());
    Simulator::new(MotorParams::paper(), effects, input)
        .unwrap()
        .run(duration, rate)
        .unwrap()
}

fn first_moving(trace: &Trace) -> Option<f64> {
    trace.stuck.iter().position(|s| !s).map(|i| trace.t[i])
}

/// Breakaway needs |k I| > Tst: the breakaway instant is Eq. (11) with Tst for Ts.
#[test]
fn stribeck_friction_delays_breakaway_to_the_static_level() {
    let p = MotorParams::paper();
    let e = 2.5;
    let trace = run(
        "stribeck_friction:tst=0.06,ws=0.5",
        Input::step(e, 0.0).unwrap(),
        0.2,
        10_000.0,
    );
    let static_motor = MotorParams { ts_nm: 0.06, ..p };
    let expected = breakaway_time(&static_motor, e).unwrap();
    let got = first_moving(&trace).unwrap();
    assert!(
        (got - expected).abs() <= 1e-4,
        "breakaway {got} s, Eq. (11) with Tst: {expected} s"
    );
    assert!(got > breakaway_time(&p, e).unwrap() * 1.5);
    // A step that breaks Ts but not Tst never moves (k E/R = 0.05 N·m between 0.03 and 0.06).
    let held = run(
        "stribeck_friction:tst=0.06",
        Input::step(0.1, 0.0).unwrap(),
        5.0,
        100.0,
    );
    assert!(held.stuck.iter().all(|&s| s));
}

/// Speed ripple at N times the rotation frequency.
#[test]
fn cogging_torque_ripples_at_n_times_rotation_frequency() {
    let n = 6;
    let trace = run(
        &format!("cogging_torque:amp=0.05,n={n}"),
        Input::step(2.5, 0.0).unwrap(),
        120.0,
        200.0,
    );
    let nominal = run("none", Input::step(2.5, 0.0).unwrap(), 120.0, 200.0);
    // Steady part: last 40 s.
    let start = trace.t.iter().position(|&t| t >= 80.0).unwrap();
    let t = &trace.t[start..];
    let w = &trace.speed[start..];
    let mean = w.iter().sum::<f64>() / w.len() as f64;
    let rotation_hz = mean / std::f64::consts::TAU;
    // Power of the detrended speed at frequency f (a single DFT bin).
    let power = |w: &[f64], f: f64| {
        let m = w.iter().sum::<f64>() / w.len() as f64;
        let (mut c, mut s) = (0.0, 0.0);
        for (wi, ti) in w.iter().zip(t) {
            let ph = std::f64::consts::TAU * f * ti;
            c += (wi - m) * ph.cos();
            s += (wi - m) * ph.sin();
        }
        c * c + s * s
    };
    let at_n = power(w, n as f64 * rotation_hz);
    for other in [0.5, 1.0, 2.0, 3.0, 4.5, 5.0, 7.0, 9.0] {
        let p = power(w, other * rotation_hz);
        assert!(
            at_n > 20.0 * p,
            "ripple power at {n}×f_rot {at_n} vs at {other}×: {p}"
        );
    }
    // The nominal motor has no line there.
    let nominal_at_n = power(&nominal.speed[start..], n as f64 * rotation_hz);
    assert!(
        nominal_at_n < 1e-3 * at_n,
        "nominal {nominal_at_n} vs cogging {at_n}"
    );
}

/// The current channel lags the armature current by about τf on the rising ramp.
#[test]
fn current_sensor_lag_delays_the_current_rise_by_tau_f() {
    let tau_f = 0.05;
    let trace = run(
        &format!("current_sensor_lag:tau={tau_f}"),
        Input::step(40.0, 0.0).unwrap(),
        2.0,
        10_000.0,
    );
    let level = 60.0; // A, on the initial rise (peak ≈ 115 A)
    let crossing = |y: &[f64]| {
        let i = y.iter().position(|&v| v >= level).unwrap();
        let (t0, t1, y0, y1) = (trace.t[i - 1], trace.t[i], y[i - 1], y[i]);
        t0 + (level - y0) / (y1 - y0) * (t1 - t0)
    };
    let delay = crossing(&trace.current) - crossing(&trace.armature_current);
    assert!(
        (delay - tau_f).abs() < 0.1 * tau_f,
        "delay {delay} s for tau_f {tau_f} s"
    );
}

/// With the rotor blocked (E too low to break away), R rises with the copper loss and the
/// current falls to E / (R0 (1 + α ΔT)) with ΔT = Rth I² R.
#[test]
fn thermal_drift_raises_resistance_with_copper_loss() {
    let p = MotorParams::paper();
    let e = 0.05; // below R Ts / k = 0.06 V: blocked rotor
    let (rth, cth, alpha) = (2.0, 5.0, 0.00393);
    let trace = run(
        &format!("thermal_drift:rth={rth},cth={cth}"),
        Input::step(e, 0.0).unwrap(),
        200.0,
        50.0,
    );
    let i_end = *trace.current.last().unwrap();
    // Fixed point of ΔT = Rth (E/R)² R, R = R0 (1 + α ΔT).
    let mut dtemp = 0.0;
    for _ in 0..100 {
        let r = p.r_ohm * (1.0 + alpha * dtemp);
        dtemp = rth * e * e / r;
    }
    let r_hot = p.r_ohm * (1.0 + alpha * dtemp);
    assert!(
        (i_end - e / r_hot).abs() < 1e-3 * (e / r_hot),
        "I = {i_end}, expected {}",
        e / r_hot
    );
    let i_cold = e / p.r_ohm;
    assert!(
        i_end < i_cold * (1.0 - 0.5 * alpha * dtemp),
        "no drift: {i_end} vs cold {i_cold}"
    );
}

/// Steady state satisfies k I = f Ω + Ts + c Ω².
#[test]
fn quadratic_drag_adds_c_omega_squared_to_the_load() {
    let p = MotorParams::paper();
    let c = 0.001;
    let trace = run(
        &format!("quadratic_drag:c={c}"),
        Input::step(40.0, 0.0).unwrap(),
        300.0,
        10.0,
    );
    let (i, w) = (*trace.current.last().unwrap(), *trace.speed.last().unwrap());
    let balance = p.k_nm_per_a * i - p.f_nms_per_rad * w - p.ts_nm - c * w * w;
    assert!(balance.abs() < 1e-6, "torque balance {balance}");
    let nominal = StepResponse::new(&p, 40.0).steady().1;
    assert!(w < 0.9 * nominal, "speed {w} vs nominal {nominal}");
}

/// Steady state satisfies E − Vb = R I + k Ω.
#[test]
fn brush_drop_takes_vb_from_the_armature_voltage() {
    let p = MotorParams::paper();
    let vb = 1.0;
    let trace = run(
        &format!("brush_drop:vb={vb}"),
        Input::step(10.0, 0.0).unwrap(),
        300.0,
        10.0,
    );
    let (i, w) = (*trace.current.last().unwrap(), *trace.speed.last().unwrap());
    let balance = 10.0 - vb - p.r_ohm * i - p.k_nm_per_a * w;
    assert!(balance.abs() < 1e-6, "voltage balance {balance}");
}

/// The incremental inductance seen while stuck, (E − R I)/(dI/dt), follows
/// L0 (r + (1 − r)/(1 + (I/Isat)²)).
#[test]
fn inductance_saturation_lowers_l_as_current_grows() {
    let p = MotorParams::paper();
    let (isat, ratio) = (0.5, 0.4);
    let rate = 100_000.0;
    // Rotor blocked by a huge Coulomb torque: pure R-L circuit.
    let blocked = MotorParams { ts_nm: 1e6, ..p };
    let effects = Effects::none().with(
        format!("inductance_saturation:isat={isat},ratio={ratio}")
            .parse()
            .unwrap(),
    );
    let e = 1.0;
    let trace = Simulator::new(blocked, effects, Input::step(e, 0.0).unwrap())
        .unwrap()
        .run(1.0, rate)
        .unwrap();
    for target in [0.1, 0.5, 1.0, 2.0] {
        let i = trace.current.iter().position(|&c| c >= target).unwrap();
        let slope = (trace.current[i + 1] - trace.current[i - 1]) * rate / 2.0;
        let l_seen = (e - p.r_ohm * trace.current[i]) / slope;
        let u = trace.current[i] / isat;
        let l_model = p.l_henry * (ratio + (1.0 - ratio) / (1.0 + u * u));
        assert!(
            (l_seen - l_model).abs() < 1e-3 * l_model,
            "L at {} A: {l_seen} vs {l_model}",
            trace.current[i]
        );
    }
}

#[test]
fn effect_specs_parse_and_errors_say_what_to_fix() {
    let e: Effect = "cogging_torque:amp=0.01,n=8,phase=0.5".parse().unwrap();
    assert_eq!(e.to_string(), "cogging_torque:amp=0.01,n=8,phase=0.5");
    assert_eq!("none".parse::<Effect>().unwrap(), Effect::None);
    let cases = [
        ("magic_friction:x=1", "unknown effect"),
        ("cogging_torque:n=6", "missing `amp=`"),
        ("cogging_torque:amp=abc", "not a number"),
        ("cogging_torque:amp=0.1,n=2.5", "whole number"),
        ("current_sensor_lag:tau=-1", "greater than zero"),
        ("brush_drop:vb=1,volts=2", "unknown key `volts`"),
        // A misspelt required key is named as unknown, not as the one missing.
        (
            "brush_drop:xx=1",
            "unknown key `xx`; this effect takes vb, knee",
        ),
        ("inductance_saturation:isat=1,ratio=2", "(0, 1]"),
        ("quadratic_drag:c", "key=value"),
    ];
    for (spec, needle) in cases {
        let err = spec.parse::<Effect>().unwrap_err().to_string();
        assert!(
            err.contains(needle),
            "`{spec}` gave `{err}`, expected it to mention `{needle}`"
        );
    }
}

/// Every kind parses from its table's keys, prints back to the same text, and goes to a value
/// vector and back unchanged; the table, the names and the parser agree.
#[test]
fn every_kind_round_trips_through_its_table() {
    use motor_model::{EffectKind, EFFECT_NAMES};
    assert_eq!(EFFECT_NAMES.len(), EffectKind::ALL.len() + 1);
    assert_eq!(EFFECT_NAMES[EffectKind::ALL.len()], "none");
    for (k, kind) in EffectKind::ALL.into_iter().enumerate() {
        assert_eq!(EFFECT_NAMES[k], kind.name());
        assert_eq!(kind.name().parse::<EffectKind>().unwrap(), kind);
        // A value inside each domain that is not the default.
        let values: Vec<f64> = kind
            .params()
            .iter()
            .map(|p| match p.domain {
                motor_model::Domain::WholeNumber => 4.0,
                motor_model::Domain::UnitInterval => 0.375,
                motor_model::Domain::Finite => -0.25,
                _ => 0.0625,
            })
            .collect();
        let body: Vec<String> = kind
            .params()
            .iter()
            .zip(&values)
            .map(|(p, v)| format!("{}={v}", p.key))
            .collect();
        let text = format!("{}:{}", kind.name(), body.join(","));
        let parsed: Effect = text.parse().unwrap();
        assert_eq!(parsed.kind(), Some(kind));
        assert_eq!(parsed.to_string(), text);
        assert_eq!(parsed.to_values(), values);
        assert_eq!(Effect::from_values(kind, &values).unwrap(), parsed);
        // Only the required keys: the others take the table's defaults.
        let required: Vec<String> = kind
            .params()
            .iter()
            .zip(&values)
            .filter(|(p, _)| p.default.is_none())
            .map(|(p, v)| format!("{}={v}", p.key))
            .collect();
        let short: Effect = format!("{}:{}", kind.name(), required.join(","))
            .parse()
            .unwrap();
        for ((p, v), (got, given)) in kind
            .params()
            .iter()
            .zip(&values)
            .zip(short.to_values().iter().zip(&values))
        {
            let want = p.default.unwrap_or(*v);
            assert_eq!(*got, want, "{} {}", kind.name(), p.key);
            let _ = given;
        }
        // The fitted view of a set with this effect alone.
        let set = Effects::none().with(parsed);
        let slots = set.fitted_slots();
        let fitted: Vec<f64> = kind
            .params()
            .iter()
            .zip(&values)
            .filter(|(p, _)| p.fitted)
            .map(|(_, v)| *v)
            .collect();
        assert_eq!(slots.len(), fitted.len());
        assert!(slots.iter().all(|(k, p)| *k == kind && p.fitted));
        assert_eq!(set.fitted_values(), fitted);
        let doubled: Vec<f64> = fitted.iter().map(|v| 0.5 * v).collect();
        let moved = set.with_fitted_values(&doubled).unwrap();
        assert_eq!(moved.fitted_values(), doubled);
        assert_eq!(moved.list().len(), 1);
    }
}

/// A value outside its domain is refused with the effect's and the parameter's names, from
/// text, from a value vector and from the fitted view alike.
#[test]
fn domain_violations_name_the_parameter() {
    use motor_model::EffectKind;
    let err = Effect::from_values(EffectKind::CurrentSensorLag, &[-1.0])
        .unwrap_err()
        .to_string();
    assert!(err.contains("current_sensor_lag tau"), "{err}");
    assert!(err.contains("greater than zero"), "{err}");
    let err = Effect::from_values(EffectKind::CoggingTorque, &[0.01, 2.5, 0.0])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cogging_torque n") && err.contains("whole number"),
        "{err}"
    );
    let err = Effect::from_values(EffectKind::QuadraticDrag, &[f64::NAN])
        .unwrap_err()
        .to_string();
    assert!(err.contains("quadratic_drag c"), "{err}");
    let err = Effect::from_values(EffectKind::BrushDrop, &[1.0])
        .unwrap_err()
        .to_string();
    assert!(err.contains("brush_drop parameter count"), "{err}");
    let set = Effects::none().with("inductance_saturation:isat=1".parse().unwrap());
    let err = set.with_fitted_values(&[1.0, 1.5]).unwrap_err().to_string();
    assert!(
        err.contains("inductance_saturation ratio") && err.contains("(0, 1]"),
        "{err}"
    );
    // The simulator checks what the text parser cannot: Tst against the motor's Ts, and any
    // effect built in code.
    let low = Effects::none().with("stribeck_friction:tst=0.01".parse().unwrap());
    let err = Simulator::new(MotorParams::paper(), low, Input::step(1.0, 0.0).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("stribeck_friction tst") && err.contains("Coulomb torque"),
        "{err}"
    );
    let mut built = Effects::none();
    built.thermal_drift = Some(motor_model::ThermalDrift {
        thermal_resistance_k_per_w: 2.0,
        thermal_capacity_j_per_k: -3.0,
        alpha_per_k: 0.004,
    });
    let err = Simulator::new(MotorParams::paper(), built, Input::step(1.0, 0.0).unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("thermal_drift cth"), "{err}");
}

/// The unconstrained coordinates invert each other and refuse the boundaries they cannot
/// reach; Stribeck's Tst is carried as its excess over Ts.
#[test]
fn unconstrained_transforms_invert() {
    use motor_model::EffectKind;
    let motor = MotorParams::paper();
    for kind in EffectKind::ALL {
        for p in kind.params().iter().filter(|p| p.fitted) {
            let v = match p.domain {
                motor_model::Domain::UnitInterval => 0.3,
                motor_model::Domain::Finite => -1.2,
                motor_model::Domain::AboveCoulomb => motor.ts_nm * 1.5,
                _ => 0.7,
            };
            let th = p.to_unconstrained(v, &motor).unwrap();
            let back = p.from_unconstrained(th, &motor);
            assert!(
                (back - v).abs() < 1e-12,
                "{} {}: {back} vs {v}",
                kind.name(),
                p.key
            );
            let h = 1e-6;
            let slope = (p.from_unconstrained(th + h, &motor)
                - p.from_unconstrained(th - h, &motor))
                / (2.0 * h);
            assert!((slope - p.slope(th)).abs() < 1e-6 * slope.abs().max(1.0));
        }
    }
    let tst = EffectKind::StribeckFriction.param("tst").unwrap();
    assert!(tst.to_unconstrained(motor.ts_nm, &motor).is_err());
    let c = EffectKind::QuadraticDrag.param("c").unwrap();
    assert!(c.to_unconstrained(0.0, &motor).is_err());
}

/// The state holds I, Ω, θ and the states of the effects that are on, nothing more.
#[test]
fn state_is_sized_by_the_effects_that_are_on() {
    let sim = |specs: &[&str]| {
        let effects = specs
            .iter()
            .fold(Effects::none(), |e, s| e.with(s.parse::<Effect>().unwrap()));
        Simulator::new(
            MotorParams::paper(),
            effects,
            Input::step(1.0, 0.0).unwrap(),
        )
        .unwrap()
    };
    assert_eq!(sim(&[]).state_len(), 3);
    assert_eq!(
        sim(&["quadratic_drag:c=1e-4", "brush_drop:vb=0.5"]).state_len(),
        3
    );
    assert_eq!(sim(&["thermal_drift:rth=2,cth=30"]).state_len(), 4);
    assert_eq!(sim(&["current_sensor_lag:tau=0.01"]).state_len(), 4);
    let both = sim(&["thermal_drift:rth=2,cth=30", "current_sensor_lag:tau=0.01"]);
    assert_eq!(both.state_len(), 5);
    // The sensor reads its own state (after the thermal one): a lag on the current only.
    let trace = both.run(0.2, 1000.0).unwrap();
    let lagged = trace.current[10];
    assert!(lagged < trace.armature_current[10]);
}
