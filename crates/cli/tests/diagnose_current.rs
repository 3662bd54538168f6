//! `motorid diagnose --input current` end to end, on the EMPS benchmark's real records
//! (issue 9, acceptance 2), and its bad input. The EMPS data lives in ../shared/real-data beside the repository (as in CI); elsewhere those tests
//! say so and stop.

mod common;

use common::{assert_bad_input, motorid, scratch, stderr, stdout};

const EMPS_COLUMNS: &str = "t=time_s,current=vir_controller_output_V,position=qm_motor_position_m";

/// The EMPS file `name`, if this machine has it.
fn emps(name: &str) -> Option<String> {
    let path = format!(
        "{}/../../../shared/real-data/emps/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    if std::path::Path::new(&path).exists() {
        Some(path)
    } else {
        eprintln!("skipped: {path} is not on this machine");
        None
    }
}

/// `diagnose --input current --json` of the EMPS record `path` (force = 35.15 × vir). The
/// columns mapped leave `pulses_N` out: the diagnosis is not told the withheld load.
fn diagnose_emps(path: &str) -> serde_json::Value {
    let out = motorid(&[
        "diagnose",
        "--input",
        "current",
        "--record",
        path,
        "--columns",
        EMPS_COLUMNS,
        "--torque-constant",
        "35.15",
        "--axis",
        "linear",
        "--json",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).expect("one JSON object")
}

/// The time and `pulses_N` columns of the EMPS pulses file.
fn pulses(path: &str) -> Vec<(f64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t, p) = (at("time_s"), at("pulses_N"));
    lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            (f[t], f[p])
        })
        .collect()
}

/// Acceptance 2, first half: the top-ranked time windows of the pulses record's force residual
/// each overlap samples where the unknown pulse force acts (it is on half of the time, in
/// 0.5 s pulses; a window is 0.16 s, so five windows placed by chance would all overlap with a
/// probability of about 0.66⁵ = 13 %).
#[test]
fn emps_pulses_are_located_by_the_top_windows() {
    let Some(path) = emps("DATA_EMPS_PULSES.csv") else {
        return;
    };
    let report = diagnose_emps(&path);
    assert_eq!(report["input"], "current");
    let channel = &report["where"]["records"][0]["channels"][0];
    assert_eq!(channel["floor"]["source"], "given");
    let windows = channel["windows"].as_array().unwrap();
    assert!(windows.len() >= 3, "{channel:#}");
    let samples = pulses(&path);
    let t0 = samples[0].0;
    for w in windows {
        assert_eq!(w["test"]["significant"], true, "{w}");
        let (a, b) = (
            t0 + w["t_start_s"].as_f64().unwrap(),
            t0 + w["t_end_s"].as_f64().unwrap(),
        );
        let on = samples
            .iter()
            .filter(|(t, p)| *t >= a && *t < b && *p != 0.0)
            .count();
        assert!(on > 0, "window {a:.3}–{b:.3} s misses every pulse");
    }
}

/// Acceptance 2, second half: on the estimation record alone, an effect is named only with a
/// significant improvement on the held-out rows.
#[test]
fn emps_estimation_record_raises_no_alarm_it_cannot_back() {
    let Some(path) = emps("DATA_EMPS.csv") else {
        return;
    };
    let report = diagnose_emps(&path);
    let effects = report["effects"].as_array().unwrap();
    let level = report["stages"][0]["verdict"]["level"].as_f64().unwrap();
    for e in effects.iter().filter(|e| e["significant"] == true) {
        let (before, after) = (
            e["heldout_nrmse_before"].as_f64().unwrap(),
            e["heldout_nrmse_after"].as_f64().unwrap(),
        );
        assert!(after < before, "{e:#}");
        assert!(e["heldout_p_value"].as_f64().unwrap() < level, "{e:#}");
    }
    let verdict = report["verdict"].as_str().unwrap();
    assert!(
        verdict == "none"
            || effects
                .iter()
                .any(|e| e["name"] == verdict && e["significant"] == true),
        "{report:#}"
    );
    // The electrical effects are not testable on a current-driven axis, nor cogging on a
    // linear one.
    for name in [
        "thermal_drift",
        "brush_drop",
        "inductance_saturation",
        "cogging_torque",
    ] {
        let e = effects.iter().find(|e| e["name"] == name).unwrap();
        assert_eq!(e["testable"], false, "{e:#}");
    }
}

#[test]
fn current_input_bad_input_is_refused_naming_the_file() {
    assert_bad_input(
        &["diagnose", "--input", "current", "--torque-constant", "1"],
        "needs --record",
    );
    let dir = scratch("diagnose_current_bad");
    let rec = dir.join("axis.csv");
    std::fs::write(&rec, "t,current,position\n0,1,0\n0.001,1,0.1\n").unwrap();
    let rec = rec.to_str().unwrap();
    let with = |extra: &[&'static str]| -> Vec<&str> {
        let mut args = vec!["diagnose", "--input", "current", "--record", rec];
        args.extend(extra);
        args
    };
    assert_bad_input(&with(&[]), "needs --torque-constant");
    assert_bad_input(
        &with(&["--torque-constant", "1", "--cutoff", "900"]),
        &format!("{rec}: --cutoff 900 Hz is not below half its sample rate"),
    );
    assert_bad_input(&with(&["--torque-constant", "1"]), "at least");
}
