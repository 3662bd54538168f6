//! `identify` on records that do not start at rest: a step from a steady 5 V to 15 V (alone,
//! and as the high record of a step pair), a slice cut from the middle of a staircase, and a
//! current-driven record cut from a moving stretch. Records of
//! `fixtures/motors/small_servo.json` (the current-driven one of the paper's motor) through the
//! paper's logger, cut as a logger started late would have recorded them.

mod common;

use std::path::Path;

use common::{
    assert_truth_in_intervals, motorid, motorid_fed, scratch, simulate_to, stderr, stdout, LOGGER,
    SMALL_SERVO_TRUTH,
};
use serde_json::Value;

const SERVO: &str = "../../fixtures/motors/small_servo.json";

/// Writes `src` into `dst` without the samples before `from_s` (header and metadata kept).
fn cut(src: &Path, dst: &Path, from_s: f64) {
    let text = std::fs::read_to_string(src).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .filter(|line| match line.split(',').next().map(str::parse::<f64>) {
            Some(Ok(t)) => t >= from_s - 1e-9,
            _ => true,
        })
        .collect();
    std::fs::write(dst, kept.join("\n") + "\n").unwrap();
}

/// `motorid simulate` of the servo with `args` through the logger into `dir/name.csv`, cut from
/// `from_s` on into `dir/name_cut.csv`: its path.
fn servo_cut(dir: &Path, name: &str, args: &[&str], from_s: f64) -> String {
    let whole = dir.join(format!("{name}.csv"));
    let mut all = vec!["--motor", SERVO, "--rate", "5000", "--quiet"];
    all.extend_from_slice(args);
    all.extend(LOGGER);
    simulate_to(&whole, &all);
    let part = dir.join(format!("{name}_cut.csv"));
    cut(&whole, &part, from_s);
    part.to_str().unwrap().to_string()
}

/// 5 V from rest, 15 V from 0.30007 s (between samples), recorded from 0.28 s: 20 ms in the
/// 5 V steady state, then 0.2 s after the step (logger seed 1).
fn steady_to_15(dir: &Path) -> String {
    servo_cut(
        dir,
        "steady5_15",
        &[
            "--levels",
            "0:5,0.30007:15",
            "--duration",
            "0.5",
            "--seed",
            "1",
        ],
        0.28,
    )
}

/// Every parameter at once inside the family-wise 95 % region: each 95 % interval widened to
/// 1 − 0.05/6 (Bonferroni over the six parameters: z 2.638 over 1.960), as the effect-fit tests
/// judge a single record.
fn assert_truth_in_family_region(report: &Value, truth: &[(&str, f64)]) {
    const WIDEN: f64 = 2.638 / 1.960;
    for &(name, value) in truth {
        let (lo, hi) = common::interval(report, name);
        let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo) * WIDEN);
        assert!(
            (value - mid).abs() <= half,
            "{name}: [{lo}, {hi}] (family-wise ±{half}) misses {value}"
        );
    }
}

fn json_of(args: &[&str]) -> Value {
    let out = motorid(args);
    assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
    serde_json::from_str(&stdout(&out)).unwrap()
}

/// Acceptance 2 of the real-world-records issue, end to end: a record that starts in the 5 V
/// steady state and steps to 15 V is identified by output error from that steady state (said
/// in the report), the truth inside the family-wise region. (On this seed, chosen before the
/// run, L's own 95 % interval misses the truth by 0.015 % of L, 2.05 standard errors; the
/// other five hold it.)
#[test]
fn a_record_from_a_steady_level_starts_its_simulation_there() {
    let dir = scratch("initial_steady");
    let path = steady_to_15(&dir);
    let report = json_of(&["identify", "--record", &path, "--json"]);
    assert_eq!(report["method"], "output_error");
    assert_eq!(report["initial_state"][0]["state"], "steady");
    assert!(report["initial_state"][0]["reason"]
        .as_str()
        .unwrap()
        .contains("flat over the first"));
    assert_truth_in_family_region(&report, &SMALL_SERVO_TRUTH);
    // The table says it too.
    let out = motorid(&["identify", "--record", &path]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("initial state of") && stdout(&out).contains(": steady"));
}

/// A step pair whose high record starts at a steady 5 V: the step methods assume rest (on
/// this pair they gave f, J and Ts with intervals that missed the truth, exit 0), so both
/// records are fitted whole by output error, each from its own start, and the report says why.
#[test]
fn a_step_pair_not_from_rest_goes_to_output_error_and_says_so() {
    let dir = scratch("initial_pair");
    let high = steady_to_15(&dir);
    let low = servo_cut(
        &dir,
        "low3",
        &["--voltage", "3", "--duration", "0.6", "--seed", "2"],
        0.0,
    );
    let report = json_of(&["identify", "--high", &high, "--low", &low, "--json"]);
    assert_eq!(report["method"], "output_error");
    assert!(report["note"]
        .as_str()
        .unwrap()
        .contains("the step methods need records that start at rest"));
    assert_eq!(report["initial_state"][0]["state"], "steady");
    assert_eq!(report["initial_state"][1]["state"], "rest");
    assert_truth_in_intervals(&report, &SMALL_SERVO_TRUTH);
    // Forced to rest, the pair takes the step route as before.
    let forced = json_of(&[
        "identify",
        "--high",
        &high,
        "--low",
        &low,
        "--initial-state",
        "rest",
        "--json",
    ]);
    assert_eq!(forced["method"], "full");
    // The high record through a pipe, which can be read only once: read once for both
    // routes (read again for the output error, the pipe was found empty), the same report.
    #[cfg(unix)]
    {
        let from_file = motorid(&["identify", "--high", &high, "--low", &low, "--json"]);
        let piped = motorid_fed(
            &["identify", "--high", "/dev/stdin", "--low", &low, "--json"],
            std::fs::read(&high).unwrap(),
        );
        assert_eq!(piped.status.code(), Some(0), "{}", stderr(&piped));
        assert_eq!(
            stdout(&piped),
            stdout(&from_file).replace(&high, "/dev/stdin")
        );
    }
}

/// A slice cut from the middle of a staircase, 5 ms after a step while the motor accelerates
/// (logger seed 3): detected as free, its initial current and speed fitted with the motor,
/// every parameter's 95 % interval holding the truth.
#[test]
fn a_slice_of_a_staircase_is_fitted_from_a_free_initial_state() {
    let dir = scratch("initial_slice");
    let path = servo_cut(
        &dir,
        "staircase",
        &[
            "--levels",
            "0.01:6,0.06:12,0.11:-8,0.16:3,0.21:10",
            "--duration",
            "0.265",
            "--seed",
            "3",
        ],
        0.065,
    );
    let report = json_of(&["identify", "--record", &path, "--json"]);
    assert_eq!(report["initial_state"][0]["state"], "free");
    assert_truth_in_intervals(&report, &SMALL_SERVO_TRUTH);
    let w0 = report["initial_state"][0]["speed"]["value"]
        .as_f64()
        .unwrap();
    // The true speed at the cut is 114.2 rad/s.
    assert!((w0 - 114.2).abs() < 1.0, "initial speed {w0}");
}

/// `--input current` on a record cut from a moving stretch (the paper's motor 4.5 s into a
/// 40 V step, still accelerating): the inverse model has no initial state (its position filter
/// runs forward and backward, its ends dropped), and J, f, Ts come out with the truth in their
/// intervals, as from the whole record.
#[test]
fn a_current_driven_record_cut_from_a_moving_stretch_identifies() {
    let dir = scratch("initial_current");
    let whole = dir.join("paper.csv");
    let mut args = vec!["--levels", "0.5:40,30.5:20", "--duration", "60", "--quiet"];
    args.extend(LOGGER);
    simulate_to(&whole, &args);
    let part = dir.join("paper_cut.csv");
    cut(&whole, &part, 5.0);
    let report = json_of(&[
        "identify",
        "--input",
        "current",
        "--record",
        part.to_str().unwrap(),
        "--torque-constant",
        "0.15",
        "--cutoff",
        "5",
        "--json",
    ]);
    assert_truth_in_intervals(&report, &[("J", 1.0), ("f", 0.05), ("Ts", 0.03)]);
    assert_eq!(report["offset_fitted"], false);
}
