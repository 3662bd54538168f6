//! Servo rigs: the load and controller specs, and the replay's physics on cases with a known
//! answer.

use motor_model::{
    replay, Controller, Load, ModelFile, ReplaySettings, ServoDrive, ServoMotor, ServoRig,
    ServoRun, STANDARD_GRAVITY_M_S2, XL330_GAIN_PER_RAD,
};

fn motor() -> ServoMotor {
    ServoMotor {
        ke_nm_per_a: 0.3,
        r_ohm: 2.0,
        j_kg_m2: 2e-3,
        fc_nm: 0.0,
        fv_nm_s_per_rad: 0.0,
        mu_motor: 0.0,
        mu_load: 0.0,
        fs_nm: 0.0,
        ws_rad_s: 1.0,
    }
}

#[test]
fn specs_parse_print_and_refuse() {
    let p: Load = "pendulum:m=0.49,l=0.1".parse().unwrap();
    assert_eq!(p.to_string(), "pendulum:m=0.49,l=0.1,arm=0");
    assert_eq!(p.to_string().parse::<Load>().unwrap(), p);
    // (m + arm/2) g l sin q and (m + arm/3) l².
    let arm: Load = "pendulum:m=0.4,l=0.2,arm=0.3".parse().unwrap();
    let q = 0.7_f64;
    assert!((arm.torque_nm(q) - 0.55 * STANDARD_GRAVITY_M_S2 * 0.2 * q.sin()).abs() < 1e-12);
    assert!((arm.inertia_kg_m2() - 0.5 * 0.04).abs() < 1e-12);
    let c: Controller = "dynamixel-xl330:kp=200".parse().unwrap();
    assert_eq!(c.gain, XL330_GAIN_PER_RAD);
    assert!((c.duty(1.0, 0.0, 0.0) - 200.0 * XL330_GAIN_PER_RAD).abs() < 1e-15);
    assert_eq!(c.duty(100.0, 0.0, 0.0), 1.0, "saturates at max_duty");
    for (bad, needle) in [
        ("pendulum:m=0.49", "missing `l=`"),
        ("pendulum:m=0.49,l=0.1,x=2", "unknown key `x`"),
        ("pendulum:m=-1,l=0.1", "m = -1"),
        ("rope:m=1", "unknown load `rope`"),
    ] {
        let e = bad.parse::<Load>().unwrap_err().to_string();
        assert!(e.contains(needle), "{bad}: {e}");
    }
    for (bad, needle) in [
        ("dynamixel-xl330", "missing `kp=`"),
        ("p:kp=1,max_duty=2", "max_duty = 2"),
        ("pid:kp=1", "unknown controller `pid`"),
    ] {
        let e = bad.parse::<Controller>().unwrap_err().to_string();
        assert!(e.contains(needle), "{bad}: {e}");
    }
}

/// A frictionless pendulum, drive off, swings with the small-angle period 2π √(J_tot/(m g l))
/// whatever the stamps' jitter.
#[test]
fn free_pendulum_swings_at_its_period_on_jittered_stamps() {
    let load: Load = "pendulum:m=0.5,l=0.2".parse().unwrap();
    let rig = ServoRig {
        motor: motor(),
        gear: 1.0,
        loads: vec![load],
        controller: None,
    };
    let j = rig.total_inertia_kg_m2();
    let period = 2.0 * std::f64::consts::PI * (j / (0.5 * STANDARD_GRAVITY_M_S2 * 0.2)).sqrt();
    // Stamps 5 ms ± 20 % apart.
    let mut t = vec![0.0];
    let mut state = 12345_u64;
    while *t.last().unwrap() < 3.0 * period {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
        let u = (state >> 11) as f64 / (1u64 << 53) as f64;
        t.push(t.last().unwrap() + 0.005 * (0.8 + 0.4 * u));
    }
    let zeros = vec![0.0; t.len()];
    let off = vec![false; t.len()];
    let run = ServoRun {
        t_s: &t,
        drive: ServoDrive::Voltage(&zeros),
        enable: Some(&off),
        q0_rad: 0.01,
        w0_rad_s: 0.0,
    };
    let trace = replay(&rig, &run, ReplaySettings { max_step_s: 1e-5 }).unwrap();
    // Upward zero crossings of the angle, interpolated.
    let crossings: Vec<f64> = (1..t.len())
        .filter(|&k| trace.q_rad[k - 1] < 0.0 && trace.q_rad[k] >= 0.0)
        .map(|k| {
            let (a, b) = (trace.q_rad[k - 1], trace.q_rad[k]);
            t[k - 1] + (t[k] - t[k - 1]) * (-a) / (b - a)
        })
        .collect();
    assert!(crossings.len() >= 2, "{crossings:?}");
    let measured = crossings[1] - crossings[0];
    // Semi-implicit Euler at 10 µs: the period within 1e-4 of the exact one.
    assert!(
        (measured / period - 1.0).abs() < 1e-4,
        "{measured} vs {period}"
    );
}

/// A constant load below the dry friction never moves the output; above it, it does.
#[test]
fn dry_friction_holds_the_output_until_the_load_exceeds_it() {
    let mut m = motor();
    m.fc_nm = 0.1;
    let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.005).collect();
    let zeros = vec![0.0; t.len()];
    for (load, moves) in [(0.09, false), (0.11, true)] {
        let rig = ServoRig {
            motor: m,
            gear: 1.0,
            loads: vec![Load::Constant { t_nm: load }],
            controller: None,
        };
        let run = ServoRun {
            t_s: &t,
            drive: ServoDrive::Voltage(&zeros),
            enable: None,
            q0_rad: 0.0,
            w0_rad_s: 0.0,
        };
        let trace = replay(&rig, &run, ReplaySettings::default()).unwrap();
        let end = *trace.q_rad.last().unwrap();
        assert_eq!(end != 0.0, moves, "load {load}: end angle {end}");
    }
}

#[test]
fn replay_refuses_what_it_cannot_replay() {
    let rig = ServoRig {
        motor: motor(),
        gear: 1.0,
        loads: vec![],
        controller: None,
    };
    let t = [0.0, 0.01, 0.005];
    let v = [0.0; 3];
    let run = ServoRun {
        t_s: &t,
        drive: ServoDrive::Voltage(&v),
        enable: None,
        q0_rad: 0.0,
        w0_rad_s: 0.0,
    };
    let e = replay(&rig, &run, ReplaySettings::default()).unwrap_err();
    assert!(e.to_string().contains("t[2]"), "{e}");
    let goal = [0.0; 3];
    let t = [0.0, 0.01, 0.02];
    let run = ServoRun {
        t_s: &t,
        drive: ServoDrive::Goal {
            goal_rad: &goal,
            supply_v: &v,
        },
        ..run
    };
    let e = replay(&rig, &run, ReplaySettings::default()).unwrap_err();
    assert!(e.to_string().contains("controller"), "{e}");
}

#[test]
fn model_files_of_another_version_are_refused() {
    let rig = ServoRig {
        motor: motor(),
        gear: 1.0,
        loads: vec![],
        controller: Some("dynamixel-xl330:kp=100".parse().unwrap()),
    };
    let mut file = ModelFile::new(rig);
    assert!(file.check().is_ok());
    let text = serde_json::to_string(&file).unwrap();
    let back: ModelFile = serde_json::from_str(&text).unwrap();
    assert_eq!(back, file);
    file.version = 99;
    assert!(file.check().unwrap_err().to_string().contains("version 99"));
}
