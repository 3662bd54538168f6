//! `motorid diagnose` end to end: a simulated servo with a withheld effect is diagnosed as that
//! effect with its size inside its interval; the nominal servo as `none`; bad input is refused
//! with exit 2.

mod common;

use common::{assert_bad_input, motorid, scratch, small_servo_steps, stderr, stdout};

fn diagnose_json(high: &str, low: &str) -> serde_json::Value {
    let out = motorid(&[
        "diagnose",
        "--high",
        high,
        "--low",
        low,
        "--candidates",
        "quadratic_drag,cogging_torque",
        "--max-effects",
        "1",
        "--json",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).expect("one JSON object")
}

#[test]
fn a_withheld_quadratic_drag_is_named_with_its_size() {
    let dir = scratch("diagnose_drag");
    let [high, low] = small_servo_steps(&dir, Some("quadratic_drag:c=2e-7"));
    let report = diagnose_json(&high, &low);
    assert_eq!(report["verdict"], "quadratic_drag", "{report:#}");
    let drag = report["effects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["name"] == "quadratic_drag")
        .unwrap();
    assert_eq!(drag["significant"], true);
    let c = &drag["params"][0];
    assert_eq!(c["unit"], "N·m·s²/rad²");
    let (lo, hi) = (
        c["ci95"][0].as_f64().unwrap(),
        c["ci95"][1].as_f64().unwrap(),
    );
    assert!(lo <= 2e-7 && 2e-7 <= hi, "c = {} [{lo}, {hi}]", c["value"]);
    assert!(
        drag["heldout_nrmse_after"].as_f64().unwrap()
            < drag["heldout_nrmse_before"].as_f64().unwrap()
    );
    assert!(report["where"]["records"].as_array().unwrap().len() == 2);
}

#[test]
fn the_nominal_servo_is_diagnosed_as_none() {
    let dir = scratch("diagnose_none");
    let [high, low] = small_servo_steps(&dir, None);
    let report = diagnose_json(&high, &low);
    assert_eq!(report["verdict"], "none", "{report:#}");
    assert!(report["effects"]
        .as_array()
        .unwrap()
        .iter()
        .all(|e| e["significant"] == false));
}

#[test]
fn bad_input_is_refused_naming_the_file() {
    assert_bad_input(&["diagnose"], "diagnose needs records");
    assert_bad_input(
        &["diagnose", "--record", "/nonexistent/r.csv"],
        "/nonexistent/r.csv",
    );
    let dir = scratch("diagnose_bad");
    let [high, low] = small_servo_steps(&dir, None);
    assert_bad_input(
        &[
            "diagnose",
            "--high",
            &high,
            "--low",
            &low,
            "--candidates",
            "wind",
        ],
        "unknown effect `wind`",
    );
}

/// A withheld drag that a Stribeck friction explains as well on these two steps: the verdict is
/// ambiguous, and the report proposes the step record that separates the two fitted
/// alternatives (no higher than the records' 12 V), which separates them better than a step
/// like the records' own.
#[test]
fn an_ambiguous_drag_or_stribeck_verdict_proposes_a_separating_test() {
    let dir = scratch("diagnose_ambiguous");
    let [high, low] = small_servo_steps(&dir, Some("quadratic_drag:c=2e-7"));
    let args = [
        "diagnose",
        "--high",
        &high,
        "--low",
        &low,
        "--candidates",
        "quadratic_drag,stribeck_friction",
        "--max-effects",
        "1",
        "--quiet",
    ];
    let out = motorid(&[&args[..], &["--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let names = ["quadratic_drag", "stribeck_friction"];
    let verdict = report["verdict"].as_str().unwrap();
    assert!(names.contains(&verdict), "{report:#}");
    let other = report["ambiguous_with"][0].as_str().unwrap_or("");
    assert!(names.contains(&other) && other != verdict, "{report:#}");
    let t = &report["separating_test"];
    assert_eq!(t["between"][0], verdict);
    assert_eq!(t["between"][1], other);
    let volts = t["voltage_V"].as_f64().unwrap();
    assert!(volts > 0.0 && volts <= 12.0 + 1e-9, "{t:#}");
    assert!(t["duration_s"].as_f64().unwrap() > 0.0, "{t:#}");
    assert!(
        t["max_difference_over_noise"].as_f64().unwrap() > 0.0,
        "{t:#}"
    );
    assert!(
        t["separation"].as_f64().unwrap() > t["separation_at_records"].as_f64().unwrap(),
        "{t:#}"
    );
    let text = motorid(&args);
    assert!(
        stdout(&text).contains("To separate them, record a"),
        "{}",
        stdout(&text)
    );
}

#[test]
fn a_step_pair_the_paper_method_cannot_read_is_still_diagnosed() {
    // A 0.3 V brush drop on the paper's motor through the logger makes the paper's method give
    // a negative Ts, and `diagnose --high --low` stopped there ("Eq. (48) does not apply"),
    // exit 2, although that is the effect it is there to find. The start is now the
    // equation-error estimate where the paper's method gives none.
    let dir = scratch("diagnose_brush_pair");
    let paths = [("hv.csv", "40", "1"), ("lv.csv", "2.5", "2")].map(|(name, volts, seed)| {
        let path = dir.join(name);
        let mut args = vec![
            "simulate",
            "-q",
            "--voltage",
            volts,
            "--seed",
            seed,
            "--effect",
            "brush_drop:vb=0.3",
            "-o",
            path.to_str().unwrap(),
        ];
        args.extend(common::LOGGER);
        let out = motorid(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        path.to_str().unwrap().to_string()
    });
    let out = motorid(&[
        "diagnose",
        "--high",
        &paths[0],
        "--low",
        &paths[1],
        "--candidates",
        "brush_drop,quadratic_drag",
        "--max-effects",
        "1",
        "--json",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(report["verdict"], "brush_drop", "{report:#}");
}
