//! Inputs that once gave a wrong answer called "converged" (exit 0), or hung: each now gives the
//! right answer within its interval, or a refusal that names the cause with its exit code.

mod common;

use common::{
    assert_bad_input, assert_truth_in_intervals, interval, motorid, motorid_within, scratch,
    simulate_to, small_servo_steps, stderr, stdout, LOGGER, PAPER_TRUTH as TRUTH,
    SMALL_SERVO_TRUTH,
};
use serde_json::Value;

fn json_of(args: &[&str]) -> (Value, std::process::Output) {
    let mut all = args.to_vec();
    all.extend_from_slice(&["--json", "--quiet"]);
    let out = motorid(&all);
    let v = serde_json::from_str(&stdout(&out)).unwrap_or(Value::Null);
    (v, out)
}

/// [`json_of`] of `identify --high hv --low lv`.
fn pair_json(hv: &std::path::Path, lv: &std::path::Path) -> (Value, std::process::Output) {
    json_of(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
    ])
}

/// A run of what once hung: a test failure, not a test that hangs with it, if it takes longer
/// (each takes a second or two on the 2-core CI machine).
const ONCE_HUNG_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

/// [`json_of`] for inputs that once hung: killed and failed past [`ONCE_HUNG_LIMIT`].
fn json_within_limit(args: &[&str]) -> (Value, std::process::Output) {
    let mut all = args.to_vec();
    all.extend_from_slice(&["--json", "--quiet"]);
    let out = motorid_within(&all, ONCE_HUNG_LIMIT).unwrap_or_else(|| {
        panic!(
            "{args:?} still running after {} s: it hangs again",
            ONCE_HUNG_LIMIT.as_secs()
        )
    });
    let v = serde_json::from_str(&stdout(&out)).unwrap_or(Value::Null);
    (v, out)
}

/// Writes the motor `json` to `dir/name`: its path, and its six parameters as truth.
fn motor_file(
    dir: &std::path::Path,
    name: &str,
    json: &str,
) -> (std::path::PathBuf, Vec<(&'static str, f64)>) {
    let path = dir.join(name);
    std::fs::write(&path, json).unwrap();
    let v: Value = serde_json::from_str(json).unwrap();
    let truth = ["R", "L", "k", "f", "J", "Ts"]
        .into_iter()
        .map(|p| (p, v[p].as_f64().unwrap()))
        .collect();
    (path, truth)
}

/// Exit 0 within [`ONCE_HUNG_LIMIT`], and every parameter within `rel` of the truth or inside
/// its 95 % interval.
fn assert_identified(args: &[&str], rel: f64) {
    let (v, out) = json_within_limit(args);
    assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
    for (name, truth) in TRUTH {
        let p = &v["parameters"][name];
        let value = p["value"].as_f64().unwrap();
        let (lo, hi) = interval(&v, name);
        let close = ((value - truth) / truth).abs() < rel;
        assert!(
            close || (lo <= truth && truth <= hi),
            "{args:?}: {name} = {value} [{lo}, {hi}], truth {truth}"
        );
    }
}

#[test]
fn the_readme_logger_record_fits_by_output_error_instead_of_hanging() {
    // Ran past 600 s at full CPU: the equation-error start fitted an offset it cannot tell
    // from Ts on a record that never reverses.
    let dir = scratch("hang");
    let hv = dir.join("hv.csv");
    let mut args = LOGGER.to_vec();
    args.extend_from_slice(&["--voltage", "40"]);
    simulate_to(&hv, &args);
    let (v, out) = json_within_limit(&["identify", "--record", hv.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &TRUTH);
}

#[test]
fn single_noise_free_steps_of_any_length_identify_the_motor() {
    // 10, 20 and 40 s steps gave R 0.577, J 0.0037, Ts 2443 N·m "converged"; 5 s said "the motor
    // must move" although it reaches 60 rad/s; 30 and 50 s ran past 600 s.
    let dir = scratch("single");
    for seconds in ["5", "10", "20", "30", "40", "50"] {
        let path = dir.join(format!("s{seconds}.csv"));
        simulate_to(&path, &["--voltage", "40", "--duration", seconds]);
        assert_identified(&["identify", "--record", path.to_str().unwrap()], 1e-4);
    }
}

#[test]
fn a_wrong_minimum_is_refused_not_called_converged() {
    let dir = scratch("refused");
    let path = dir.join("s40.csv");
    simulate_to(&path, &["--voltage", "40", "--duration", "40"]);
    // The minimum the old start led to: Ts far above any torque the motor makes.
    let start = dir.join("start.json");
    std::fs::write(
        &start,
        r#"{"R":0.5768,"L":0.1647,"k":0.1499,"f":7.4887e-5,"J":0.0037,"Ts":2443}"#,
    )
    .unwrap();
    let out = motorid(&[
        "identify",
        "--record",
        path.to_str().unwrap(),
        "--start",
        start.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("fit: FAILED"), "{text}");
    assert!(!text.contains("fit: converged"), "{text}");
    let err = stderr(&out);
    assert!(
        err.contains("refused") && err.contains("worse than its mean"),
        "{err}"
    );
}

#[test]
fn columns_in_ms_or_ma_without_a_unit_are_refused_before_fitting() {
    let dir = scratch("units");
    let hv = dir.join("hv.csv");
    simulate_to(&hv, &["--voltage", "40", "--duration", "5"]);
    let text = std::fs::read_to_string(&hv).unwrap();
    let scaled = |column: usize| -> String {
        let mut header_seen = false;
        text.lines()
            .map(|l| {
                if l.starts_with('#') {
                    return l.to_string();
                }
                if !header_seen {
                    header_seen = true;
                    // Another tool's file: no units in the header.
                    return "t,voltage,current,speed,position".to_string();
                }
                let mut v: Vec<String> = l.split(',').map(str::to_string).collect();
                v[column] = format!("{}", v[column].parse::<f64>().unwrap() * 1000.0);
                v.join(",")
            })
            .collect::<Vec<_>>()
            .join("\n")
            + "\n"
    };
    let ms = dir.join("ms.csv");
    std::fs::write(&ms, scaled(0)).unwrap();
    common::assert_bad_input(&["identify", "--record", ms.to_str().unwrap()], "t[ms]");
    let ma = dir.join("ma.csv");
    std::fs::write(&ma, scaled(2)).unwrap();
    common::assert_bad_input(
        &["identify", "--record", ma.to_str().unwrap()],
        "current[mA]",
    );
    // A unit in the header takes the values as they are (and converts them).
    let stated = dir.join("ma_stated.csv");
    std::fs::write(
        &stated,
        scaled(2).replacen("t,voltage,current,", "t,voltage,current[mA],", 1),
    )
    .unwrap();
    assert_identified(&["identify", "--record", stated.to_str().unwrap()], 1e-4);
}

#[test]
fn swapped_high_and_low_records_are_put_in_order_and_said() {
    // --method paper with --high and --low swapped gave k +3.6 %, f +14 %, J +8.9 %, exit 0.
    let dir = scratch("swapped");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    simulate_to(&hv, &["--voltage", "40"]);
    simulate_to(&lv, &["--voltage", "2.5"]);
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    let ordered = motorid(&["identify", "--high", h, "--low", l, "--method", "paper"]);
    let swapped = motorid(&["identify", "--high", l, "--low", h, "--method", "paper"]);
    assert_eq!(swapped.status.code(), Some(0), "{}", stderr(&swapped));
    assert!(
        stderr(&swapped).contains("taken the other way round"),
        "{}",
        stderr(&swapped)
    );
    assert_eq!(stdout(&ordered), stdout(&swapped));
}

#[test]
fn negative_steps_are_identified_as_mirror_images() {
    // Said "Ts = -0.0299: must be >= 0 ... did both records settle?" although both settled.
    let dir = scratch("negative");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    simulate_to(&hv, &["--voltage", "-40"]);
    simulate_to(&lv, &["--voltage", "-2.5"]);
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    assert_identified(&["identify", "--high", h, "--low", l], 1e-6);
    let out = motorid(&["identify", "--high", h, "--low", l]);
    assert!(stderr(&out).contains("negative step"), "{}", stderr(&out));
}

#[test]
fn an_encoder_moving_half_a_count_per_sample_still_identifies_the_motor() {
    // Two 50 s steps at 100 kHz with a 2000-count encoder (the README's logger otherwise) gave
    // L = 7e-91 H, J = 1.5e-41 kg·m² "converged": the encoder moves half a count per sample, so
    // the one-sample speed column reads multiples of 157 rad/s and its last sample, the paper
    // method's Ωrm, read 0. The same half count per sample at 10 kHz with 200 counts per turn
    // (1 M samples instead of 10 M: 7 s here instead of 2 min).
    let dir = scratch("half_count");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    for (path, volts, seed) in [(&hv, "40", "1"), (&lv, "2.5", "2")] {
        simulate_to(
            path,
            &[
                "--adc-bits",
                "10",
                "--noise-lsb",
                "1",
                "--encoder-cpr",
                "200",
                "--speed-from",
                "encoder",
                "--rate",
                "10000",
                "--voltage",
                volts,
                "--seed",
                seed,
            ],
        );
    }
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    let (v, out) = json_of(&["identify", "--high", h, "--low", l]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &TRUTH);
}

/// The issue's own 100 kHz pair, with `MOTORID_HEAVY=1` only (two 5,000,001-sample records,
/// about 800 MB of CSV and 10 GB of memory, a minute of fitting): `MOTORID_HEAVY=1 cargo test
/// --release -p motorid --test wrong_answers -- --nocapture hundred_khz`.
#[test]
fn the_hundred_khz_logger_pair_identifies_the_motor_heavy() {
    if std::env::var("MOTORID_HEAVY").map_or(true, |v| v != "1") {
        eprintln!("skipped: set MOTORID_HEAVY=1 (the 10-M-sample pair)");
        return;
    }
    let dir = scratch("hundred_khz");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    for (path, volts, seed) in [(&hv, "40", "1"), (&lv, "2.5", "2")] {
        let mut args = LOGGER.to_vec();
        args.extend(["--rate", "100000", "--voltage", volts, "--seed", seed, "-q"]);
        simulate_to(path, &args);
    }
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    let started = std::time::Instant::now();
    let args = ["identify", "--high", h, "--low", l, "--json"];
    let out = motorid_within(&args, std::time::Duration::from_secs(900))
        .expect("the 100 kHz pair still fitting after 900 s");
    eprintln!(
        "identify of the 100 kHz pair: {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    // Its progress: a line a second while it fits.
    assert!(
        err.lines()
            .any(|l| l.starts_with("  identify: fitting 10000002 samples")),
        "{err}"
    );
    let v: Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_truth_in_intervals(&v, &TRUTH);
}

#[test]
fn short_records_are_named_as_too_short() {
    // 10-sample records: the paper method said the step "does not break the Coulomb friction …
    // raise the step voltage" (R·Ts/k is 0.06 V), the full method that the "steady states are
    // proportional".
    let dir = scratch("short");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    simulate_to(&hv, &["--voltage", "40", "--duration", "0.009"]);
    simulate_to(&lv, &["--voltage", "2.5", "--duration", "0.009"]);
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    for method in ["paper", "full"] {
        let out = motorid(&["identify", "--high", h, "--low", l, "--method", method]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{method}: {err}");
        assert!(err.contains("too short"), "{method}: {err}");
        assert!(!err.contains("raise the step voltage"), "{method}: {err}");
        assert!(!err.contains("proportional"), "{method}: {err}");
    }
    common::assert_bad_input(&["identify", "--record", h], "too little motion");
}

#[test]
fn a_return_to_zero_volts_on_a_unipolar_adc_is_read_at_its_rail() {
    // The noise clipped at the 0 V rail read the level as 0.0178 V; R, k, f, J and Ts missed
    // in 3 of 3 seeds.
    let dir = scratch("rail_level");
    let path = dir.join("rec.csv");
    let mut args = LOGGER.to_vec();
    args.extend_from_slice(&["--levels", "0.5:40,100.5:0", "--duration", "150"]);
    simulate_to(&path, &args);
    let (v, out) = json_of(&["identify", "--record", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &TRUTH);
}

/// Two steps of a small servo (0.6 s at 5 kHz through the logger) by output error: the
/// equation-error start averaged each record's own inverse model and ended in a wrong minimum
/// (R 5.6, k 0.017, refused); one inverse model over both records starts it right.
#[test]
fn small_servo_steps_by_output_error_start_from_the_pooled_torque_equation() {
    let dir = scratch("wrong_servo_oe");
    let paths = small_servo_steps(&dir, None);
    let out = motorid(&[
        "identify", "--record", &paths[0], "--record", &paths[1], "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_truth_in_intervals(&report, &SMALL_SERVO_TRUTH);
}

#[test]
fn a_noise_free_adc_pair_with_an_exact_angle_column_is_not_overconfident() {
    // Exit 0 with R 0.3001839 [0.3001832, 0.3001846] (truth 0.3): the exact angle column made
    // the encoder speed's noise 1e-12 of its range, and 40 V on 0–48 V and 2.5 V on 0–3 V both
    // read half a step high, an error the two levels taken as independent halved.
    // `simulate` no longer writes the exact angle beside ADC channels (no bench measures it):
    // the angle of the ideal record of the same step is joined to the ADC's record, as a
    // hand-made record could hold it.
    let dir = scratch("noise-free-pair");
    let (hv, lv) = (dir.join("h.csv"), dir.join("l.csv"));
    for (path, volts) in [(&hv, "40"), (&lv, "2.5")] {
        simulate_to(
            path,
            &["--voltage", volts, "--adc-bits", "10", "--noise-lsb", "0"],
        );
        let measured = std::fs::read_to_string(path).unwrap();
        assert!(
            measured.contains("speed[rad/s]\n"),
            "an exact angle was written"
        );
        let ideal = dir.join("ideal.csv");
        simulate_to(&ideal, &["--voltage", volts]);
        let ideal = std::fs::read_to_string(&ideal).unwrap();
        let angles = ideal
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.rsplit(',').next().unwrap().to_string());
        let rows = measured.lines().filter(|l| !l.starts_with('#'));
        let mut joined: String = measured
            .lines()
            .filter(|l| l.starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect();
        for (row, angle) in rows.zip(angles) {
            joined.push_str(&format!("{row},{angle}\n"));
        }
        assert!(joined.contains(",position[rad]\n"));
        std::fs::write(path, joined).unwrap();
    }
    let (v, out) = pair_json(&hv, &lv);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &TRUTH);
    // By output error: the voltage, one code throughout, was replayed as samples (its level's
    // prior lost), and forward differences of the simulation broke the voltage-scale
    // degeneracy; R 0.30018 [0.30017, 0.30019], 15–80 half-widths off on every parameter.
    let (v, out) = json_of(&[
        "identify",
        "--record",
        hv.to_str().unwrap(),
        "--record",
        lv.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &TRUTH);
}

#[test]
fn logger_pairs_shorter_than_their_settling_identify_the_motor() {
    // Refused with exit 3 ("tau_e = 2e-146 s", "a wrong minimum") though the data answer: the
    // start read the first current sample after the step, within the 10-bit ADC's noise, and
    // took L as unresolved (2.8e-5 H); 20 s is one mechanical time constant of this motor.
    let dir = scratch("unsettled-pairs");
    for (rate, duration) in [("1000", "20"), ("5000", "5")] {
        let (hv, lv) = (dir.join("h.csv"), dir.join("l.csv"));
        for (path, volts) in [(&hv, "40"), (&lv, "2.5")] {
            let mut args = LOGGER.to_vec();
            args.extend_from_slice(&["--voltage", volts, "--rate", rate, "--duration", duration]);
            simulate_to(path, &args);
        }
        let (v, out) = pair_json(&hv, &lv);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{rate} Hz, {duration} s: {}",
            stderr(&out)
        );
        assert_truth_in_intervals(&v, &TRUTH);
    }
}

/// `path` with the column `column` (0-based) of every data row negated.
fn negate_column(from: &std::path::Path, to: &std::path::Path, column: usize) {
    let text = std::fs::read_to_string(from).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') || line.starts_with('t') {
            out.push_str(line);
        } else {
            let fields: Vec<String> = line
                .split(',')
                .enumerate()
                .map(|(i, f)| {
                    if i == column {
                        format!("{}", -f.parse::<f64>().unwrap())
                    } else {
                        f.to_string()
                    }
                })
                .collect();
            out.push_str(&fields.join(","));
        }
        out.push('\n');
    }
    std::fs::write(to, out).unwrap();
}

#[test]
fn refusals_name_the_real_cause() {
    let dir = scratch("real-causes");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    // A step below breakaway on an ideal record: was "25 % of the current on an ADC rail"
    // (the exact settled current repeats and looked clipped).
    simulate_to(&dir.join("h.csv"), &["--voltage", "40"]);
    simulate_to(&dir.join("l005.csv"), &["--voltage", "0.05"]);
    assert_bad_input(
        &["identify", "--high", &p("h.csv"), "--low", &p("l005.csv")],
        "the rotor never moves: the 0.0500 V step does not break the Coulomb friction",
    );
    // Logger records of these step voltages.
    for (name, volts) in [("lh.csv", "40"), ("l0.csv", "0"), ("ll.csv", "2.5")] {
        let mut args = LOGGER.to_vec();
        args.extend_from_slice(&["--voltage", volts]);
        simulate_to(&dir.join(name), &args);
    }
    // A "step" of 0 V through a noisy ADC: was "the voltage steps more than once".
    assert_bad_input(
        &["identify", "--high", &p("lh.csv"), "--low", &p("l0.csv")],
        "no step: the voltage stays within its noise",
    );
    // A current column of the wrong sign: was "R = -0.314: must be greater than zero".
    negate_column(&dir.join("lh.csv"), &dir.join("fh.csv"), 2);
    negate_column(&dir.join("ll.csv"), &dir.join("fl.csv"), 2);
    assert_bad_input(
        &["identify", "--high", &p("fh.csv"), "--low", &p("fl.csv")],
        "V step: its sign is reversed (negate the current column",
    );
    // The same for the encoder's angle.
    negate_column(&dir.join("lh.csv"), &dir.join("ah.csv"), 4);
    negate_column(&dir.join("ll.csv"), &dir.join("al.csv"), 4);
    assert_bad_input(
        &["identify", "--high", &p("ah.csv"), "--low", &p("al.csv")],
        "the angle runs",
    );
    // A record too long for memory at any whole rate: suggested "--rate 0", itself refused.
    assert_bad_input(
        &["simulate", "--duration", "1e9", "-o", &p("x.csv")],
        "shorten the record (at most --duration 9999.999 at this rate)",
    );
    let out = motorid(&["simulate", "--duration", "1e9", "-o", &p("x.csv")]);
    assert!(!stderr(&out).contains("--rate 0"), "{}", stderr(&out));
}

#[test]
fn an_optimiser_that_finds_no_minimum_is_a_failed_fit_not_bad_input() {
    // A small fast servo (τe 1 ms, τm 8 ms) through the logger at 1 kHz: the output-error fit
    // from its own start ended without normal equations, reported as bad input (exit 2) with
    // no hint. The records are sound: a failed fit is exit 3, and says how to give a start.
    let dir = scratch("no-minimum");
    let motor = dir.join("servo.json");
    std::fs::write(
        &motor,
        r#"{"R":2,"L":0.002,"k":0.05,"f":1e-5,"J":1e-5,"Ts":0.005}"#,
    )
    .unwrap();
    let (hv, lv) = (dir.join("h.csv"), dir.join("l.csv"));
    for (path, volts, seed) in [(&hv, "24", "1"), (&lv, "1", "101")] {
        let mut args = LOGGER.to_vec();
        args.extend_from_slice(&[
            "--motor",
            motor.to_str().unwrap(),
            "--voltage",
            volts,
            "--duration",
            "10",
            "--seed",
            seed,
        ]);
        simulate_to(path, &args);
    }
    let out = motorid(&[
        "identify",
        "-q",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
    ]);
    let err = stderr(&out);
    match out.status.code() {
        Some(0) => {}
        Some(3) => assert!(err.contains("--start FILE.json"), "{err}"),
        code => panic!("exit {code:?}: {err}"),
    }
}

#[test]
fn the_paper_method_on_records_it_does_not_suit_is_refused_or_flagged() {
    // A small fast servo (τe 1 ms, τm 8 ms) at 2 kHz: `--method paper` printed k = 1.4e-12
    // N·m/A, exit 0, and a (C.8) speed check "converged" on no samples at all; on 10 s records
    // its speed check gave wn 350 rad/s against the current fit's 1841, without a word.
    let dir = scratch("paper-unsuited");
    let motor = dir.join("servo.json");
    std::fs::write(
        &motor,
        r#"{"R":2,"L":0.002,"k":0.05,"f":1e-5,"J":1e-5,"Ts":0.005}"#,
    )
    .unwrap();
    let pair = |duration: &str| {
        let (hv, lv) = (
            dir.join(format!("h{duration}.csv")),
            dir.join(format!("l{duration}.csv")),
        );
        for (path, volts, seed) in [(&hv, "24", "1"), (&lv, "1", "2")] {
            let mut args = LOGGER.to_vec();
            args.extend_from_slice(&[
                "--motor",
                motor.to_str().unwrap(),
                "--voltage",
                volts,
                "--rate",
                "2000",
                "--duration",
                duration,
                "--seed",
                seed,
            ]);
            simulate_to(path, &args);
        }
        (hv, lv)
    };
    let (hv, lv) = pair("3");
    assert_bad_input(
        &[
            "identify",
            "--method",
            "paper",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
        ],
        "yet the rotor turns in the",
    );
    let (hv, lv) = pair("10");
    let out = motorid(&[
        "identify",
        "--method",
        "paper",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
    ]);
    let text = stdout(&out);
    assert!(
        !out.status.success() || text.contains("warning: the (C.8) speed check contradicts"),
        "{text}"
    );
    // The paper's own motor: the check agrees, no warning.
    let (h, l) = (dir.join("ph.csv"), dir.join("pl.csv"));
    for (path, volts) in [(&h, "40"), (&l, "2.5")] {
        let mut args = LOGGER.to_vec();
        args.extend_from_slice(&["--voltage", volts]);
        simulate_to(path, &args);
    }
    let out = motorid(&[
        "identify",
        "--method",
        "paper",
        "--high",
        h.to_str().unwrap(),
        "--low",
        l.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("(C.8) speed check: wn"));
    assert!(!stdout(&out).contains("contradicts"), "{}", stdout(&out));
    // An underdamped motor: "the fit did not converge (maximum iterations reached …)".
    let (h, l) = (dir.join("uh.csv"), dir.join("ul.csv"));
    for (path, volts) in [(&h, "40"), (&l, "2.5")] {
        let mut args = LOGGER.to_vec();
        args.extend_from_slice(&[
            "--motor",
            "../../fixtures/motors/underdamped.json",
            "--voltage",
            volts,
        ]);
        simulate_to(path, &args);
    }
    assert_bad_input(
        &[
            "identify",
            "--method",
            "paper",
            "--high",
            h.to_str().unwrap(),
            "--low",
            l.to_str().unwrap(),
        ],
        "is underdamped (ζ < 1)",
    );
}

#[test]
fn a_fast_servo_read_with_a_third_of_an_adc_step_of_noise_is_not_overconfident() {
    // Exit 0 with f 9.940e-6 [9.930e-6, 9.950e-6] (truth 1e-5) and Ts 4 half-widths off: the
    // settled current reads the codes either side of its level, more than one step from its
    // mean, so the current was taken as settled for its last 60 samples only and its
    // quantisation offset went into f and Ts; the output-error fit, taken because the step at
    // the first sample read as "a slice of a longer run", had no such offset at all.
    // With `--initial-state rest` the fit from the paper's result (its Eq. (33) fit on a
    // one-sample electrical time constant) was refused as a wrong minimum.
    let dir = scratch("fast-servo-third-lsb");
    let (motor, truth) = motor_file(
        &dir,
        "s.json",
        r#"{"R":2,"L":0.002,"k":0.05,"f":1e-5,"J":1e-5,"Ts":0.005}"#,
    );
    let (hv, lv) = (dir.join("h.csv"), dir.join("l.csv"));
    for seed in [1u32, 2] {
        for (path, volts, s) in [(&hv, "24", seed), (&lv, "1", seed + 100)] {
            simulate_to(
                path,
                &[
                    "--motor",
                    motor.to_str().unwrap(),
                    "--voltage",
                    volts,
                    "--duration",
                    "10",
                    "--rate",
                    "1000",
                    "--adc-bits",
                    "10",
                    "--noise-lsb",
                    "0.3",
                    "--encoder-cpr",
                    "2000",
                    "--speed-from",
                    "encoder",
                    "--seed",
                    &s.to_string(),
                    "--quiet",
                ],
            );
        }
        let pair = [
            "identify",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
        ];
        let text = motorid(&pair);
        assert_eq!(text.status.code(), Some(0), "{}", stderr(&text));
        assert!(
            stdout(&text).starts_with("record kind: high- and low-voltage steps")
                && !stdout(&text).contains("slice of a longer run"),
            "a step at the first sample starts at rest: {}",
            stdout(&text)
        );
        for extra in [&[][..], &["--initial-state", "rest"][..]] {
            let mut args = pair.to_vec();
            args.extend_from_slice(extra);
            let (v, out) = json_of(&args);
            assert_eq!(out.status.code(), Some(0), "{extra:?}: {}", stderr(&out));
            assert_truth_in_intervals(&v, &truth);
        }
    }
}

#[test]
fn a_current_whose_noise_is_clipped_at_a_zero_amp_rail_is_refused() {
    // Exit 0 with f 5.9 and Ts 4.0 half-widths off their intervals: a big motor drawing 0.74 A
    // at its steady speed, 1.5 steps of a 0–492 A range, read 0 A for its noise below; the
    // fits keep readings at a 0 A rail (a motor at rest reads them), and the rest's mean was
    // high. With a range below 0 A the same records identify within their intervals.
    let dir = scratch("zero-amp-rail");
    let (motor, truth) = motor_file(
        &dir,
        "big.json",
        r#"{"R":0.05,"L":0.01,"k":1.0,"f":0.01,"J":50.0,"Ts":0.5}"#,
    );
    let record = |name: &str, volts: &str, seed: &str, range: Option<&str>| {
        let path = dir.join(name);
        let mut args = vec![
            "--motor",
            motor.to_str().unwrap(),
            "--voltage",
            volts,
            "--duration",
            "60",
            "--seed",
            seed,
            "--quiet",
        ];
        args.extend(LOGGER);
        if let Some(r) = range {
            args.extend(["--range-current", r]);
        }
        simulate_to(&path, &args);
        path.to_str().unwrap().to_string()
    };
    let low = record("l.csv", "1", "16", Some("-2,22"));
    let clipped = record("h0.csv", "24", "15", None);
    assert_bad_input(
        &["identify", "--high", &clipped, "--low", &low],
        "read the ADC's 0 A rail while the motor turns",
    );
    let bipolar = record("h.csv", "24", "15", Some("-50,550"));
    let (v, out) = json_of(&["identify", "--high", &bipolar, "--low", &low]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_truth_in_intervals(&v, &truth);
}

#[test]
fn steady_states_no_motor_explains_are_a_failed_fit_not_bad_input() {
    // An unmodelled brush drop of 0.3 V: "steady-state start … k = -0.34: must be greater than
    // zero" with exit 2, as if the files were broken.
    let dir = scratch("brush-drop-start");
    let (hv, lv) = (dir.join("h.csv"), dir.join("l.csv"));
    for (path, volts) in [(&hv, "40"), (&lv, "2.5")] {
        let mut args = LOGGER.to_vec();
        args.extend_from_slice(&["--voltage", volts, "--effect", "brush_drop:vb=0.3"]);
        simulate_to(path, &args);
    }
    let out = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("an unmodelled effect") && stderr(&out).contains("motorid diagnose"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn unmodelled_effects_are_said_to_bias_the_result_not_left_silent() {
    // Through the paper's logger, each of these effects left identify at exit 0 with parameters
    // 5–23 half-widths from the truth and no word of it: the residual exceeded the records'
    // noise, but the table's "noise" column is the residual itself.
    let dir = scratch("mismatch");
    let pair = |name: &str, effect: Option<&str>| -> [String; 2] {
        [("40", "1"), ("2.5", "2")].map(|(volts, seed)| {
            let path = dir.join(format!("{name}_{volts}.csv"));
            let mut args = LOGGER.to_vec();
            args.extend(["--voltage", volts, "--seed", seed, "--quiet"]);
            if let Some(e) = effect {
                args.extend(["--effect", e]);
            }
            simulate_to(&path, &args);
            path.to_str().unwrap().to_string()
        })
    };
    for (name, effect) in [
        ("cogging", "cogging_torque:amp=0.1,n=6"),
        ("stribeck", "stribeck_friction:tst=0.05"),
        ("lag", "current_sensor_lag:tau=0.01"),
        ("saturation", "inductance_saturation:isat=20"),
    ] {
        let [hv, lv] = pair(name, Some(effect));
        let (v, out) = json_of(&["identify", "--high", &hv, "--low", &lv]);
        assert_eq!(out.status.code(), Some(0), "{effect}: {}", stderr(&out));
        let check = &v["model_check"];
        assert_eq!(check["made"], true, "{effect}: {check}");
        assert_eq!(check["model_misses"], true, "{effect}: {check}");
        assert!(
            !check["findings"].as_array().unwrap().is_empty(),
            "{effect}: {check}"
        );
        let text = motorid(&["identify", "--high", &hv, "--low", &lv]);
        let shown = stdout(&text);
        assert!(
            shown.contains("warning: the residual is not the records' noise: the model misses something they show")
                && shown.contains(&format!("motorid diagnose --high {hv} --low {lv}")),
            "{effect}: {shown}"
        );
        if name == "cogging" {
            // The output-error route checks its fit the same way.
            let (v, out) = json_of(&["identify", "--record", &hv, "--record", &lv]);
            assert_eq!(out.status.code(), Some(0), "{effect}: {}", stderr(&out));
            assert_eq!(
                v["model_check"]["model_misses"], true,
                "{}",
                v["model_check"]
            );
        }
    }
    // The same pair without an effect: the residual is the records' noise.
    let [hv, lv] = pair("clean", None);
    let (v, out) = json_of(&["identify", "--high", &hv, "--low", &lv]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(v["model_check"]["made"], true, "{}", v["model_check"]);
    assert_eq!(
        v["model_check"]["model_misses"], false,
        "{}",
        v["model_check"]
    );
    let shown = stdout(&motorid(&["identify", "--high", &hv, "--low", &lv]));
    assert!(!shown.contains("misses something"), "{shown}");
}

#[test]
fn noise_free_adc_pairs_at_every_resolution_hold_their_error() {
    // The issue's `--noise-lsb 0` pair gave R 0.30018 [0.30017, 0.30019], 100–283 half-widths
    // off: quantisation without noise is a bias the residuals cannot show. The default ranges
    // put 40 V on 0–48 V and 2.5 V on 0–3 V exactly halfway between two codes at 8, 10 and
    // 12 bits alike (40 · 1023/48 = 852.5): the grid's worst place, where an interval that
    // counts the place as unknown and uniform over a step (95 % of places inside) may miss by
    // a little — measured 1.20 half-widths at most. Over random places
    // (`montecarlo --noise-lsb 0 --vary-range`) the coverage is 92.5–96 %. The model check
    // takes the quantiser's deterministic error for what it is, not for a missing effect.
    let dir = scratch("noise-free-bits");
    for bits in ["8", "10", "12"] {
        let (hv, lv) = (
            dir.join(format!("h{bits}.csv")),
            dir.join(format!("l{bits}.csv")),
        );
        for (path, volts) in [(&hv, "40"), (&lv, "2.5")] {
            simulate_to(
                path,
                &["--voltage", volts, "--adc-bits", bits, "--noise-lsb", "0"],
            );
        }
        let (v, out) = pair_json(&hv, &lv);
        assert_eq!(out.status.code(), Some(0), "{bits} bits: {}", stderr(&out));
        for (name, truth) in TRUTH {
            let value = v["parameters"][name]["value"].as_f64().unwrap();
            let (lo, hi) = interval(&v, name);
            let off = (value - truth).abs() / (0.5 * (hi - lo));
            assert!(
                off <= 2.0,
                "{bits} bits: {name} = {value} [{lo}, {hi}], {off:.2} half-widths from {truth}"
            );
        }
        assert_eq!(
            v["model_check"]["model_misses"], false,
            "{bits} bits: {}",
            v["model_check"]
        );
    }
}

#[test]
fn a_fast_servo_prbs_identifies_the_motor() {
    // The small servo (τe = 1 ms, two samples at 2 kHz) under a ±12 V PRBS of 20 ms bits:
    // - after 20 samples at 0 V, an exact record was fitted with −12 V from t = 0 (the
    //   reversals' second differences, taken for the voltage's noise, hid the 0 → −12 V jump)
    //   and ended with Ts refused (or 37 % off with an interval of ±40 %);
    // - through the logger, the fit from the equation-error start drove Ts to 1e-15 N·m on 5
    //   of 6 seeds (refused) where the records determine it.
    let dir = scratch("fast-prbs");
    let motor = "../../fixtures/motors/small_servo.json";
    let cases: [(&str, &[&str]); 3] = [
        ("exact", &["--prbs", "12,0.02,1", "--step-at", "0.01025"]),
        ("logger2", &["--prbs", "12,0.02,2", "--seed", "2"]),
        ("logger3", &["--prbs", "12,0.02,3", "--seed", "3"]),
    ];
    for (name, input) in cases {
        let path = dir.join(format!("{name}.csv"));
        let mut args = vec!["--motor", motor, "--duration", "1", "--rate", "2000", "-q"];
        args.extend_from_slice(input);
        if name != "exact" {
            args.extend(LOGGER);
        }
        simulate_to(&path, &args);
        let (v, out) = json_of(&["identify", "--record", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(0), "{name}: {}", stderr(&out));
        for (param, truth) in SMALL_SERVO_TRUTH {
            let value = v["parameters"][param]["value"].as_f64().unwrap();
            let (lo, hi) = interval(&v, param);
            // The exact record has no noise to set an interval by: its values must be the
            // motor's to 1e-4.
            let close = name == "exact" && ((value - truth) / truth).abs() < 1e-4;
            assert!(
                close || (lo <= truth && truth <= hi),
                "{name}: {param} = {value} [{lo}, {hi}], truth {truth}"
            );
        }
    }
}

#[test]
fn an_exact_staircase_is_not_read_as_an_adc_of_its_level_spacing() {
    // 0, 40, −20, 0 and 2.5 V written exactly are multiples of 2.5 V: the voltage was taken as
    // read by an ADC of 2.5 V steps, its levels fitted as such inputs, and the exact record
    // gave R 0.2999941 [0.2999867, 0.3000015]. Its metadata says it was read without an ADC.
    let dir = scratch("exact-staircase");
    let path = dir.join("stairs.csv");
    simulate_to(
        &path,
        &[
            "--levels",
            "0.5:40,40.5:-20,80.5:0,100.5:2.5",
            "--duration",
            "140",
            "-q",
        ],
    );
    let (v, out) = json_of(&["identify", "--record", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    for (name, truth) in TRUTH {
        let value = v["parameters"][name]["value"].as_f64().unwrap();
        assert!(
            ((value - truth) / truth).abs() < 1e-6,
            "{name} = {value}, truth {truth}"
        );
    }
}
