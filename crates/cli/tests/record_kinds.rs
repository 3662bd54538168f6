//! Record kinds through `identify --record`: records of `fixtures/motors/small_servo.json`
//! simulated through the logger, their current column removed, give kS, kV, kA whose 95 %
//! intervals contain the motor's (kS = R Ts/k, kV = (R f + k²)/k, kA = R J/k), and J, f, Ts
//! whose intervals contain the truth when R and k are given; with an encoder or a tachometer.
//! A current too coarse to use is set aside; records that cannot answer are refused in one line.

mod common;

use common::{assert_bad_input, interval, motorid, scratch, simulate_to, stderr, stdout};

const SERVO: &str = "../../fixtures/motors/small_servo.json";
/// small_servo.json: R, k, and J, f, Ts.
const R: f64 = 2.0;
const K: f64 = 0.05;
const J: f64 = 2e-5;
const F: f64 = 4e-4;
const TS: f64 = 4e-3;

/// The logger of the tests (10-bit ADC, 1 LSB of noise) with the speed from a 2000-count
/// encoder, or from the tachometer.
fn logger(tacho: bool) -> Vec<&'static str> {
    let mut v = vec!["--adc-bits", "10", "--noise-lsb", "1"];
    if tacho {
        v.extend(["--speed-from", "tacho"]);
    } else {
        v.extend(["--encoder-cpr", "2000", "--speed-from", "encoder"]);
    }
    v
}

/// Writes `src` to `dst` without the columns named in `drop` (and without the samples before
/// `from_s` \[s\], the record then starting where the motor runs).
fn without(src: &std::path::Path, dst: &std::path::Path, drop: &[&str], from_s: f64) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut keep: Option<Vec<usize>> = None;
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let idx = keep.get_or_insert_with(|| {
            (0..fields.len())
                .filter(|&i| !drop.iter().any(|d| fields[i].starts_with(d)))
                .collect()
        });
        if let Ok(t) = fields[0].parse::<f64>() {
            if t < from_s {
                continue;
            }
        }
        let kept: Vec<&str> = idx.iter().map(|&i| fields[i]).collect();
        out.push_str(&kept.join(","));
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
}

/// `identify --record FILE ... --json`, which must succeed: the report.
fn identify(files: &[&std::path::Path], extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["identify"];
    for f in files {
        args.extend(["--record", f.to_str().unwrap()]);
    }
    args.extend(extra);
    args.push("--json");
    let out = motorid(&args);
    assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
    serde_json::from_str(&stdout(&out)).unwrap()
}

/// kS, kV, kA inside their intervals without R and k; with them, J, f, Ts too. Prints the
/// figures for the record.
fn assert_voltage_speed_truth(what: &str, files: &[&std::path::Path]) {
    let plain = identify(files, &[]);
    assert_eq!(plain["method"], "voltage_speed", "{what}");
    assert!(
        plain["record_kind"]["text"]
            .as_str()
            .unwrap()
            .contains("give --resistance and --torque-constant for J, f, Ts"),
        "{what}: {}",
        plain["record_kind"]
    );
    let feedforward = [
        ("kS", R * TS / K),
        ("kV", (R * F + K * K) / K),
        ("kA", R * J / K),
    ];
    let given = identify(files, &["--resistance", "2", "--torque-constant", "0.05"]);
    for (report, truth) in [
        (&plain, &feedforward[..]),
        (
            &given,
            &[
                feedforward[0],
                feedforward[1],
                feedforward[2],
                ("J", J),
                ("f", F),
                ("Ts", TS),
            ][..],
        ),
    ] {
        for &(name, value) in truth {
            let (lo, hi) = interval(report, name);
            eprintln!("{what}: {name} [{lo:.6e}, {hi:.6e}] truth {value:.6e}");
            assert!(
                lo <= value && value <= hi,
                "{what}: {name} [{lo}, {hi}] misses {value}"
            );
            // Determined: the interval narrower than the value.
            assert!(hi - lo < value, "{what}: {name} [{lo}, {hi}] undetermined");
        }
    }
}

/// `input` (simulate's options) on `motor` (a motor file) through the logger, written into
/// `dir` as `name.csv` without its current (and, with a tachometer, without the exact angle the
/// simulator writes beside it: not a measurement here), from `from_s` \[s\] on.
fn record_without_current(
    dir: &std::path::Path,
    name: &str,
    motor: &str,
    input: &[&str],
    tacho: bool,
    from_s: f64,
) -> std::path::PathBuf {
    let full = dir.join(format!("{name}_{tacho}_full.csv"));
    let mut args = vec!["--motor", motor, "--quiet"];
    args.extend(input);
    args.extend(logger(tacho));
    simulate_to(&full, &args);
    let path = dir.join(format!("{name}_{tacho}.csv"));
    let drop: &[&str] = if tacho {
        &["current", "position"]
    } else {
        &["current"]
    };
    without(&full, &path, drop, from_s);
    path
}

/// [`record_without_current`] of the servo from its first sample.
fn servo_record(
    dir: &std::path::Path,
    name: &str,
    input: &[&str],
    tacho: bool,
) -> std::path::PathBuf {
    record_without_current(dir, name, SERVO, input, tacho, 0.0)
}

/// A staircase from rest (2, 6, 3, 9 V), 0.7 s at 2 kHz.
fn staircase(dir: &std::path::Path, tacho: bool) -> std::path::PathBuf {
    servo_record(dir, "stairs", SERVO_CASES[0].input, tacho)
}

#[test]
fn a_staircase_without_current_gives_ks_kv_ka_and_j_f_ts_with_r_and_k() {
    let dir = scratch("kinds_stairs");
    for tacho in [false, true] {
        let path = staircase(&dir, tacho);
        let what = if tacho {
            "staircase, tachometer"
        } else {
            "staircase, encoder"
        };
        assert_voltage_speed_truth(what, &[&path]);
    }
    // The record-kind line heads the table.
    let path = staircase(&dir, false);
    let out = motorid(&["identify", "--record", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let first = stdout(&out).lines().next().unwrap_or_default().to_string();
    assert_eq!(
        first,
        "record kind: voltage and speed only: kS, kV, kA; give --resistance and --torque-constant for J, f, Ts"
    );
}

/// A PRBS of ±8 V, 40 ms bits, 0.6 s at 2 kHz.
fn prbs(dir: &std::path::Path, tacho: bool) -> std::path::PathBuf {
    servo_record(dir, "prbs", SERVO_CASES[1].input, tacho)
}

#[test]
fn a_prbs_without_current_and_a_tachometer_gives_the_constants() {
    let dir = scratch("kinds_prbs_tacho");
    assert_voltage_speed_truth("PRBS, tachometer", &[&prbs(&dir, true)]);
}

#[test]
fn a_prbs_without_current_and_an_encoder_gives_the_constants() {
    let dir = scratch("kinds_prbs_encoder");
    assert_voltage_speed_truth("PRBS, encoder", &[&prbs(&dir, false)]);
}

/// A PRBS from its first sample (no samples at 0 V before it): the servo is at rest at that
/// sample and, at 2 kHz, already turns a few samples later. The mean of the first five speeds
/// said "running", and the fitted start (−14 rad/s) drove kS to 0 and no interval; the speed
/// at the first sample now says rest. `--initial-state steady` still asks for the fitted start.
#[test]
fn a_prbs_from_the_first_sample_starts_at_rest() {
    let dir = scratch("kinds_prbs_first_sample");
    let input = [
        "--prbs",
        "12,0.02,7",
        "--duration",
        "0.5",
        "--rate",
        "2000",
        "--seed",
        "1010",
    ];
    let path = servo_record(&dir, "prbs0", &input, true);
    assert_voltage_speed_truth("PRBS from the first sample, tachometer", &[&path]);
    let text = stdout(&motorid(&["identify", "--record", path.to_str().unwrap()]));
    assert!(!text.contains("starts running"), "{text}");
    let steady = motorid(&[
        "identify",
        "--record",
        path.to_str().unwrap(),
        "--initial-state",
        "steady",
    ]);
    assert!(
        stdout(&steady).contains("starts running"),
        "{}",
        stdout(&steady)
    );
}

#[test]
fn a_step_from_one_level_to_another_of_a_running_motor_gives_the_constants() {
    // 5 V from t = 0, 15 V from 0.25 s; the record cut at 0.2 s, where the motor runs steadily
    // at 5 V: it starts running.
    let dir = scratch("kinds_level_to_level");
    let case = &SERVO_CASES[2];
    let path = record_without_current(&dir, "levels", SERVO, case.input, false, case.cut_s);
    assert_voltage_speed_truth("5 V → 15 V, running at the first sample", &[&path]);
    let report = identify(&[&path], &[]);
    let w0 = report["initial_speed"][0]["value"].as_f64().unwrap();
    let steady = (5.0 - R * TS / K) / ((R * F + K * K) / K);
    assert!(
        (w0 / steady - 1.0).abs() < 0.05,
        "starts at {w0}, not {steady}"
    );
}

#[test]
fn a_coarse_current_at_50_hz_is_set_aside_and_the_motor_identified_from_voltage_and_speed() {
    // The small servo with ten times its inertia (τm 0.12 s, τe 1 ms), sampled at 50 Hz: the
    // sample period is twenty times τe, and the current channel's ±500 A range leaves its
    // 10-bit ADC a few steps across the motor's current.
    let dir = scratch("kinds_coarse");
    let motor = dir.join("motor.json");
    std::fs::write(
        &motor,
        r#"{"R": 2.0, "L": 0.002, "k": 0.05, "f": 0.0004, "J": 2e-4, "Ts": 0.004}"#,
    )
    .unwrap();
    let path = dir.join("coarse.csv");
    let mut args = vec![
        "--motor",
        motor.to_str().unwrap(),
        "--levels",
        "0.2:3,2:9,4:5,6:12",
        "--duration",
        "8",
        "--rate",
        "50",
        "--range-current",
        "-500,500",
        "--quiet",
    ];
    args.extend(logger(false));
    simulate_to(&path, &args);
    let report = identify(
        &[&path],
        &["--resistance", "2", "--torque-constant", "0.05"],
    );
    assert_eq!(report["method"], "voltage_speed");
    let unused = report["record_kind"]["current_unused"].as_str().unwrap();
    assert!(unused.contains("ADC steps"), "{unused}");
    for (name, value) in [
        ("kS", R * TS / K),
        ("kV", (R * F + K * K) / K),
        ("kA", R * 2e-4 / K),
        ("J", 2e-4),
        ("f", F),
        ("Ts", TS),
    ] {
        let (lo, hi) = interval(&report, name);
        eprintln!("coarse current, 50 Hz: {name} [{lo:.6e}, {hi:.6e}] truth {value:.6e}");
        assert!(
            lo <= value && value <= hi,
            "{name} [{lo}, {hi}] misses {value}"
        );
    }
    // Without a speed the coarse current is refused with its reason.
    let no_speed = dir.join("coarse_no_speed.csv");
    without(&path, &no_speed, &["speed", "position"], 0.0);
    assert_bad_input(
        &["identify", "--record", no_speed.to_str().unwrap()],
        "ADC steps",
    );
}

#[test]
fn records_that_cannot_answer_are_refused_in_one_line() {
    let dir = scratch("kinds_bad");
    let path = staircase(&dir, false);
    let voltage_only = dir.join("voltage_only.csv");
    without(&path, &voltage_only, &["speed", "position"], 0.0);
    assert_bad_input(
        &["identify", "--record", voltage_only.to_str().unwrap()],
        "neither current nor speed",
    );
    assert_bad_input(
        &[
            "identify",
            "--record",
            path.to_str().unwrap(),
            "--resistance",
            "2",
        ],
        "--resistance without --torque-constant",
    );
    assert_bad_input(
        &[
            "identify",
            "--record",
            path.to_str().unwrap(),
            "--resistance",
            "0",
            "--torque-constant",
            "0.05",
        ],
        "--resistance 0",
    );
    // Too short for the fit: said in its own terms (the start's decimation is not the user's).
    let short_full = dir.join("short_full.csv");
    let mut args = vec![
        "--voltage",
        "10",
        "--duration",
        "0.05",
        "--rate",
        "1000",
        "--quiet",
    ];
    args.extend(logger(false));
    simulate_to(&short_full, &args);
    let short = dir.join("short.csv");
    without(&short_full, &short, &["current"], 0.0);
    assert_bad_input(
        &["identify", "--record", short.to_str().unwrap()],
        "51 samples: the voltage-and-speed fit needs at least 110",
    );
    // A step pair without current: the message points to the fit of voltage and speed.
    assert_bad_input(
        &[
            "identify",
            "--high",
            path.to_str().unwrap(),
            "--low",
            path.to_str().unwrap(),
        ],
        "without a current sensor, `identify --record FILE` fits voltage and speed alone",
    );
}

/// One record of a fixture motor: `simulate`'s input options and where the record is cut
/// (0: from its first sample).
struct FixtureCase {
    motor: &'static str,
    what: &'static str,
    input: &'static [&'static str],
    cut_s: f64,
}

/// The other fixture motors (paper: τe 1 s, τm 8 s; critical: τe 0.17 s, τm 0.24 s;
/// underdamped: τe 0.1 s above τm 0.04 s), each with a staircase, a PRBS and (but the
/// underdamped motor: see the test below) a step from one level to another cut where
/// the motor runs steadily (ten mechanical time constants after it started: the critical
/// motor's double pole still leaves 4 % of its rise after five).
const FIXTURE_CASES: &[FixtureCase] = &[
    FixtureCase {
        motor: "paper",
        what: "staircase",
        input: &[
            "--levels",
            "1:10,15:30,30:15,45:40",
            "--duration",
            "60",
            "--rate",
            "100",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "paper",
        what: "PRBS",
        input: &[
            "--prbs",
            "20,10,1",
            "--step-at",
            "1",
            "--duration",
            "100",
            "--rate",
            "100",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "paper",
        what: "10 V → 30 V running",
        input: &[
            "--levels",
            "0:10,90:30",
            "--duration",
            "120",
            "--rate",
            "100",
        ],
        cut_s: 80.0,
    },
    FixtureCase {
        motor: "critical",
        what: "staircase",
        input: &[
            "--levels",
            "0.1:12,1:30,2:15,3:40",
            "--duration",
            "4",
            "--rate",
            "200",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "critical",
        what: "PRBS",
        input: &[
            "--prbs",
            "30,0.5,1",
            "--step-at",
            "0.1",
            "--duration",
            "5",
            "--rate",
            "200",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "critical",
        what: "20 V → 40 V running",
        input: &["--levels", "0:20,3:40", "--duration", "5", "--rate", "200"],
        cut_s: 2.5,
    },
    FixtureCase {
        motor: "underdamped",
        what: "staircase",
        input: &[
            "--levels",
            "0.05:3,0.5:8,1:4,1.5:12",
            "--duration",
            "2",
            "--rate",
            "1000",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "underdamped",
        what: "PRBS",
        input: &[
            "--prbs",
            "2,0.3,1",
            "--step-at",
            "0.05",
            "--duration",
            "3",
            "--rate",
            "1000",
        ],
        cut_s: 0.0,
    },
];

/// The small servo's records (a staircase, a PRBS, a step from 5 V to 15 V cut where the motor
/// runs steadily at 5 V): the tests' own, and the heavy coverage test's.
const SERVO_CASES: &[FixtureCase] = &[
    FixtureCase {
        motor: "small_servo",
        what: "staircase",
        input: &[
            "--levels",
            "0.05:2,0.2:6,0.35:3,0.5:9",
            "--duration",
            "0.7",
            "--rate",
            "2000",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "small_servo",
        what: "PRBS",
        input: &[
            "--prbs",
            "8,0.04,1",
            "--step-at",
            "0.05",
            "--duration",
            "0.6",
            "--rate",
            "2000",
        ],
        cut_s: 0.0,
    },
    FixtureCase {
        motor: "small_servo",
        what: "5 V → 15 V running",
        input: &[
            "--levels",
            "0:5,0.25:15",
            "--duration",
            "0.5",
            "--rate",
            "4000",
        ],
        cut_s: 0.2,
    },
];

/// One interval of a fixture run: what it is, `[lo, hi]` and the truth.
struct FixtureInterval {
    what: String,
    lo: f64,
    hi: f64,
    truth: f64,
}

impl FixtureInterval {
    fn misses(&self) -> bool {
        !(self.lo <= self.truth && self.truth <= self.hi)
    }
}

/// The intervals `identify` gives on `case` through the logger with an encoder or a
/// tachometer (noise seed `seed`, `simulate`'s default if `None`), without and with R and k:
/// kS, kV, kA against kS = R Ts/k, kV = (R f + k²)/k, kA = R J/k, then J, f, Ts. `Err` with
/// the command's message when `identify` does not exit 0.
fn fixture_intervals(
    dir: &std::path::Path,
    case: &FixtureCase,
    tacho: bool,
    seed: Option<u64>,
) -> Result<Vec<FixtureInterval>, String> {
    let motor = format!("../../fixtures/motors/{}.json", case.motor);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&motor).unwrap()).unwrap();
    let p = |k: &str| m[k].as_f64().unwrap();
    let (r, k, f, j, ts) = (p("R"), p("k"), p("f"), p("J"), p("Ts"));
    let (r_text, k_text) = (r.to_string(), k.to_string());
    let feedforward = [
        ("kS", r * ts / k),
        ("kV", (r * f + k * k) / k),
        ("kA", r * j / k),
    ];
    let physical = [("J", j), ("f", f), ("Ts", ts)];
    let sensor = if tacho { "tachometer" } else { "encoder" };
    let seed_text = seed.map(|s| s.to_string());
    let mut input = case.input.to_vec();
    if let Some(s) = &seed_text {
        input.extend(["--seed", s.as_str()]);
    }
    let name = format!("{}_{}_{}", case.motor, case.what.len(), seed.unwrap_or(0));
    let path = record_without_current(dir, &name, &motor, &input, tacho, case.cut_s);
    let run = |extra: &[&str]| -> Result<serde_json::Value, String> {
        let mut args = vec!["identify", "--record", path.to_str().unwrap()];
        args.extend(extra);
        args.push("--json");
        let out = motorid(&args);
        if out.status.code() != Some(0) {
            return Err(format!(
                "{} {}, {sensor}, seed {seed:?}: {}",
                case.motor,
                case.what,
                stderr(&out).trim()
            ));
        }
        Ok(serde_json::from_str(&stdout(&out)).unwrap())
    };
    let plain = run(&[])?;
    let given = run(&["--resistance", &r_text, "--torque-constant", &k_text])?;
    let mut out = Vec::new();
    for (report, truth, how) in [
        (&plain, feedforward.to_vec(), "without R, k"),
        (
            &given,
            [&feedforward[..], &physical[..]].concat(),
            "with R, k",
        ),
    ] {
        for (name, value) in truth {
            let (lo, hi) = interval(report, name);
            out.push(FixtureInterval {
                what: format!("{} {}, {sensor}, {how}: {name}", case.motor, case.what),
                lo,
                hi,
                truth: value,
            });
        }
    }
    Ok(out)
}

/// [`FIXTURE_CASES`] through the logger with an encoder and with a tachometer, fitted
/// without and with R and k: every run is identified, and over all of them the 95 % intervals
/// miss kS = R Ts/k, kV = (R f + k²)/k, kA = R J/k (and J, f, Ts) no more often than 95 %
/// coverage allows: at most 14 of the 144 intervals (7.2 expected; more than 14 has a
/// probability below 1 % at 95 % coverage). One noise seed: the coverage over many is
/// [`fixture_coverage_over_many_seeds`]'s.
#[test]
fn every_fixture_motor_without_current_gives_its_constants() {
    let dir = scratch("kinds_fixtures");
    let (mut intervals, mut misses) = (0usize, Vec::new());
    for case in FIXTURE_CASES {
        for tacho in [false, true] {
            let found =
                fixture_intervals(&dir, case, tacho, None).unwrap_or_else(|e| panic!("{e}"));
            for i in found {
                intervals += 1;
                let line = format!(
                    "{} [{:.5e}, {:.5e}] truth {:.5e}",
                    i.what, i.lo, i.hi, i.truth
                );
                eprintln!("{line}");
                if i.misses() {
                    misses.push(line);
                }
            }
        }
    }
    assert_eq!(intervals, 144);
    eprintln!("{} of {intervals} intervals miss", misses.len());
    assert!(
        misses.len() <= 14,
        "{} misses:\n{}",
        misses.len(),
        misses.join("\n")
    );
}

/// The paper's motor driven by its PRBS ([`FIXTURE_CASES`]' second record) and read by the
/// encoder, noise seed 2014, with R and k given: every start of τe about the sample period
/// converged to kS → 0, which has no interval, and the fit fell back to the reduced model and
/// was refused ("stalled"); the starts about τm now fit it (2 of 100 seeds refused before).
#[test]
fn a_prbs_whose_first_fits_drive_ks_to_zero_is_identified_from_the_later_starts() {
    let dir = scratch("kinds_prbs_collapse");
    let found = fixture_intervals(&dir, &FIXTURE_CASES[1], false, Some(2014))
        .unwrap_or_else(|e| panic!("{e}"));
    for i in &found {
        assert!(
            !i.misses(),
            "{} [{}, {}] misses {}",
            i.what,
            i.lo,
            i.hi,
            i.truth
        );
    }
}

/// Misses of `n` intervals of 95 % coverage that have a probability below 0.1 % to be
/// exceeded (the binomial tail).
fn miss_bound(n: usize) -> usize {
    let (p, q) = (0.05_f64, 0.95_f64);
    let pmf = |k: usize| -> f64 {
        let ln_choose: f64 = (1..=k).map(|i| ((n - k + i) as f64 / i as f64).ln()).sum();
        (ln_choose + k as f64 * p.ln() + (n - k) as f64 * q.ln()).exp()
    };
    let mut below = 0.0;
    for m in 0..=n {
        below += pmf(m);
        if 1.0 - below < 1e-3 {
            return m;
        }
    }
    n
}

/// Heavy (`MOTORID_HEAVY=1`): the coverage of every interval of [`FIXTURE_CASES`] and
/// [`SERVO_CASES`] over many noise seeds (`MOTORID_SEEDS`, default 100, from
/// `MOTORID_FIRST_SEED`, default 1001). An encoder's angle carries no noise, so its records
/// change little from seed to seed (only the voltage's noise does): their counts are nearly
/// one draw, the tachometer's are many. Each
/// interval (case, sensor, with or without R and k, parameter) misses its truth at most
/// [`miss_bound`] times (a probability below 0.1 % at 95 % coverage), and runs `identify`
/// refuses are at most 5 %. Prints the misses of every interval and the refusals.
#[test]
fn fixture_coverage_over_many_seeds() {
    if std::env::var("MOTORID_HEAVY").map_or(true, |v| v != "1") {
        eprintln!("skipped: set MOTORID_HEAVY=1 (every fixture record over many seeds)");
        return;
    }
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (seeds, first) = (env("MOTORID_SEEDS", 100), env("MOTORID_FIRST_SEED", 1001));
    let dir = scratch("kinds_coverage");
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicU64::new(first);
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let seed = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if seed >= first + seeds {
                    break;
                }
                for case in FIXTURE_CASES.iter().chain(SERVO_CASES) {
                    for tacho in [false, true] {
                        let found = fixture_intervals(&dir, case, tacho, Some(seed));
                        results.lock().unwrap().push(found);
                    }
                }
                eprintln!("seed {seed} done");
            });
        }
    });
    let results = results.into_inner().unwrap();
    let runs = results.len();
    let mut refused = Vec::new();
    let mut tally: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    for r in results {
        match r {
            Ok(found) => {
                for i in found {
                    let e = tally.entry(i.what.clone()).or_default();
                    e.0 += 1;
                    e.1 += usize::from(i.misses());
                }
            }
            Err(e) => refused.push(e),
        }
    }
    let (mut total, mut missed, mut over) = (0, 0, Vec::new());
    for (what, (n, m)) in &tally {
        eprintln!("{what}: {m} of {n} miss");
        total += n;
        missed += m;
        if *m > miss_bound(*n) {
            over.push(format!("{what}: {m} of {n}"));
        }
    }
    eprintln!(
        "{missed} of {total} intervals miss ({:.1} %); {} of {runs} runs refused",
        100.0 * missed as f64 / total.max(1) as f64,
        refused.len()
    );
    for e in &refused {
        eprintln!("refused: {e}");
    }
    assert!(
        over.is_empty(),
        "more misses than 95 % coverage allows:\n{}",
        over.join("\n")
    );
    assert!(
        refused.len() * 20 <= runs,
        "{} of {runs} runs refused",
        refused.len()
    );
}

/// The underdamped motor (τe = 0.1 s above τm = 0.04 s: ζ = 0.34, its rise decays as
/// e^(−5.5 t)) running steadily at 1 V and at 4 V, then stepped to three times that level; the
/// records start at 1.8 s, ten decay times after the motor started (a cut after 0.6 s, where
/// 4 % of the rise is left, is not a steady start, which the model of the start assumes: its kS
/// and kV miss). Without k the records fix `kA τe` and `lead = kA + τe (kV − k)` but not kA
/// itself: the report says so, kA's interval is `[0, lead]`, and the two coefficients come out
/// within 1 % of the truth; with R and k, J, f and Ts are determined and within twice their
/// half-widths, τe within 1 %.
#[test]
fn the_underdamped_motor_running_at_the_first_sample_gives_its_constants() {
    let (r, l, k, f, j, ts) = (1.0, 0.1, 0.5, 0.01, 0.01, 0.01);
    for (low, high) in [("1", "3"), ("4", "12")] {
        let dir = scratch(&format!("kinds_underdamped_running_{low}"));
        let levels = format!("0:{low},2:{high}");
        let input = ["--levels", &levels, "--duration", "3", "--rate", "1000"];
        let motor = "../../fixtures/motors/underdamped.json";
        let path = record_without_current(&dir, "running", motor, &input, true, 1.8);
        let plain = identify(&[&path], &[]);
        let (lo, hi) = interval(&plain, "kA");
        assert!(lo == 0.0 && hi >= r * j / k, "{low} V: kA [{lo}, {hi}]");
        let tau_e = &plain["tau_e"];
        assert_eq!(tau_e["status"], "traded_with_ka", "{low} V: {tau_e}");
        for (key, truth) in [
            ("ka_times_tau_e", l * j / k),
            ("ka_plus_tau_e_viscous_share", (r * j + l * f) / k),
        ] {
            let value = tau_e[key]["value"].as_f64().unwrap();
            assert!(
                (value / truth - 1.0).abs() < 0.01,
                "{low} V: {key} {value} against {truth}"
            );
        }
        let given = identify(&[&path], &["--resistance", "1", "--torque-constant", "0.5"]);
        for (name, truth) in [("J", j), ("f", f), ("Ts", ts)] {
            let value = given["parameters"][name]["value"].as_f64().unwrap();
            let (lo, hi) = interval(&given, name);
            // Within twice its half-width (whether the interval itself holds the truth is
            // counted with the other fixtures' above), and determined.
            assert!(
                (value - truth).abs() <= hi - lo && hi - lo < truth,
                "{low} V: {name} {value} [{lo}, {hi}] against {truth}"
            );
        }
        let tau = given["tau_e"]["value"].as_f64().unwrap();
        assert!((tau / (l / r) - 1.0).abs() < 0.01, "{low} V: τe {tau}");
    }
}
