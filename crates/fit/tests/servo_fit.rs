//! The servo fit on simulated rigs: a log with jittered, partly dropped time stamps identifies
//! to the intervals of its uniform twin, both close to the truth.

use fit::{ServoFit, ServoRecord};
use motor_model::{replay, Controller, Load, ReplaySettings, ServoDrive, ServoMotor, ServoRun};

const TRUTH: ServoMotor = ServoMotor {
    ke_nm_per_a: 0.3,
    r_ohm: 2.2,
    j_kg_m2: 2e-3,
    fc_nm: 0.01,
    fv_nm_s_per_rad: 0.01,
    mu_motor: 0.4,
    mu_load: 0.1,
    fs_nm: 0.0,
    ws_rad_s: 1.0,
};

/// Counts per turn of the simulated servo's encoder.
const COUNTS: f64 = 4096.0;

struct Lcg(u64);
impl Lcg {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Time stamps over `duration` s, 5 ms apart; with `jitter`, ±20 % apart and 1 % dropped.
fn stamps(duration: f64, jitter: bool, rng: &mut Lcg) -> Vec<f64> {
    let mut t = vec![0.0];
    while *t.last().unwrap() < duration {
        let dt = if jitter {
            0.005 * (0.8 + 0.4 * rng.uniform())
        } else {
            0.005
        };
        let next = t.last().unwrap() + dt;
        if jitter && rng.uniform() < 0.01 {
            // A dropped sample: the next stamp comes one period later.
            t.push(next + 0.005);
        } else {
            t.push(next);
        }
    }
    t
}

/// One closed-loop log of the true rig on stamps `t`: a goal of two sines, the drive off over
/// `off` (a fraction of the log, at its end), the angle quantised to the encoder's counts.
fn log(name: &str, kp: f64, t: &[f64], off: f64) -> ServoRecord {
    let controller: Controller = format!("dynamixel-xl330:kp={kp}").parse().unwrap();
    let load: Load = "pendulum:m=0.49,l=0.1".parse().unwrap();
    let end = *t.last().unwrap();
    let goal: Vec<f64> = t
        .iter()
        .map(|&t| 0.6 * (1.3 * t).sin() + 0.3 * (4.1 * t + 0.5).sin())
        .collect();
    let supply = vec![7.3; t.len()];
    let enable: Vec<bool> = t.iter().map(|&x| x < end * (1.0 - off)).collect();
    let mut record = ServoRecord {
        name: name.into(),
        t_s: t.to_vec(),
        goal_rad: Some(goal),
        supply_v: Some(supply),
        enable: Some(enable),
        loads: vec![load],
        controller: Some(controller),
        gear: 1.0,
        ..ServoRecord::default()
    };
    let run = ServoRun {
        t_s: t,
        drive: ServoDrive::Goal {
            goal_rad: record.goal_rad.as_deref().unwrap(),
            supply_v: record.supply_v.as_deref().unwrap(),
        },
        enable: record.enable.as_deref(),
        q0_rad: 0.0,
        w0_rad_s: 0.0,
    };
    let trace = replay(&record.rig(TRUTH), &run, ReplaySettings::default()).unwrap();
    let lsb = 2.0 * std::f64::consts::PI / COUNTS;
    record.q_rad = trace
        .q_rad
        .iter()
        .map(|q| (q / lsb).round() * lsb)
        .collect();
    record
}

fn logs(jitter: bool) -> Vec<ServoRecord> {
    let mut rng = Lcg(7);
    vec![
        log("kp100", 100.0, &stamps(6.0, jitter, &mut rng), 0.0),
        log("kp200", 200.0, &stamps(6.0, jitter, &mut rng), 0.0),
        log("drop", 200.0, &stamps(6.0, jitter, &mut rng), 0.4),
    ]
}

#[test]
fn jittered_stamps_identify_to_the_intervals_of_the_uniform_twin() {
    let uniform = ServoFit::new(&logs(false)).fit().unwrap();
    let jittered = ServoFit::new(&logs(true)).fit().unwrap();
    let truth = [
        TRUTH.ke_nm_per_a,
        TRUTH.r_ohm,
        TRUTH.j_kg_m2,
        TRUTH.fc_nm,
        TRUTH.fv_nm_s_per_rad,
        TRUTH.mu_motor,
        TRUTH.mu_load,
    ];
    for ((u, j), truth) in uniform.estimates.iter().zip(&jittered.estimates).zip(truth) {
        let [ulo, uhi] = u.ci95.unwrap();
        let [jlo, jhi] = j.ci95.unwrap();
        eprintln!(
            "{}: uniform {:.5} [{ulo:.5}, {uhi:.5}], jittered {:.5} [{jlo:.5}, {jhi:.5}], truth {truth}",
            u.name, u.value, j.value
        );
        // The same intervals: each estimate inside the other's interval, widths within 2×.
        assert!(
            jlo <= u.value && u.value <= jhi && ulo <= j.value && j.value <= uhi,
            "{}: the twins' estimates disagree",
            u.name
        );
        let ratio = (jhi - jlo) / (uhi - ulo);
        assert!((0.5..2.0).contains(&ratio), "{}: widths {ratio}", u.name);
        // Close to the truth: the encoder's quantisation biases the estimates here by 0.15 %
        // (ke) to 2.2 % (fv) (measured); the intervals, taken over runs of equal counts, hold
        // the truth for five of the seven constants (R misses by 1.1 half-widths, μm by 1.9):
        // 5 % catches a fit that lost the rig, not that bias.
        assert!(
            (u.value / truth - 1.0).abs() < 0.05,
            "{}: {} vs {truth}",
            u.name,
            u.value
        );
    }
    assert!(uniform.mae_rad < 2e-3 && jittered.mae_rad < 2e-3);
}
