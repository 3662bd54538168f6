//! End-to-end tests: they run the real `motorid` binary.

mod common;

use common::{
    assert_bad_input, interval, motorid, scratch, simulate_to, stderr, stdout, LOGGER, PAPER_TRUTH,
};
use std::path::PathBuf;

/// Acceptance 2: `model --motor paper --json` reproduces Table 1 to the printed digits
/// (ωa: 0.3881, the table's 0.3381 being a typo).
#[test]
fn model_json_reproduces_table_1() {
    let out = motorid(&["model", "--motor", "paper", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let expected = [
        ("KE", 1.3333, 4),
        ("Ks", 4.0, 4),
        ("wn", 0.3536, 4),
        ("zeta", 1.4849, 4),
        ("sigma", 0.5250, 4),
        ("wa", 0.3881, 4),
        ("tau_m", 20.0, 4),
        ("tau_e", 1.0, 4),
        ("alpha", 4.9896, 4),
        ("gamma", 0.9110, 4),
        ("i0", 0.2, 4),
    ];
    for (key, printed, decimals) in expected {
        let value = v[key]
            .as_f64()
            .unwrap_or_else(|| panic!("key {key} in {v}"));
        assert_eq!(
            format!("{value:.decimals$}"),
            format!("{printed:.decimals$}"),
            "{key}"
        );
    }
    // The feedforward constants of Eq. (2) with L neglected: kS = R Ts/k, kV = k + R f/k,
    // kA = R J/k (0.3·0.03/0.15, 0.15 + 0.3·0.05/0.15, 0.3·1/0.15).
    for (key, truth) in [("kS", 0.06), ("kV", 0.25), ("kA", 2.0)] {
        let value = v[key]
            .as_f64()
            .unwrap_or_else(|| panic!("key {key} in {v}"));
        assert!((value / truth - 1.0).abs() < 1e-12, "{key} {value}");
    }
    // Every number printed has its unit, the motor's too.
    let units = &v["units"];
    let numbers = v.as_object().unwrap().iter().filter(|(_, x)| x.is_number());
    let motor = v["motor"].as_object().unwrap().iter();
    for (key, _) in numbers.chain(motor) {
        assert!(
            units[key.as_str()].is_string(),
            "no unit for {key} in {units}"
        );
    }
}

/// Reads the last data row of a record CSV as numbers.
fn last_row(csv: &str) -> Vec<f64> {
    let line = csv.lines().rfind(|l| !l.starts_with('#')).unwrap();
    line.split(',').map(|x| x.parse().unwrap()).collect()
}

/// Acceptance 2: simulated 40 V and 2.5 V steps reproduce Table 2 at t = 50 s, with both
/// solvers, through the record file.
#[test]
fn simulate_reproduces_table_2_with_both_solvers() {
    let dir = scratch("table2");
    for solver in ["analytic", "ode"] {
        for (volts, current, speed) in [("40", "53.57", "159.6"), ("2.5", "3.46", "9.748")] {
            let path = dir.join(format!("{solver}-{volts}.csv"));
            let out = motorid(&[
                "simulate",
                "--motor",
                "paper",
                "--voltage",
                volts,
                "--duration",
                "50",
                "--rate",
                "1000",
                "--solver",
                solver,
                "-o",
                path.to_str().unwrap(),
            ]);
            assert!(out.status.success(), "{}", stderr(&out));
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text
                .lines()
                .any(|l| l == "t[s],voltage[V],current[A],speed[rad/s],position[rad]"));
            let row = last_row(&text);
            assert_eq!(row[0], 50.0);
            assert_eq!(
                format!("{:.2}", row[2]),
                current,
                "{solver} {volts} V current"
            );
            let dec = speed.len() - speed.find('.').unwrap() - 1;
            assert_eq!(
                format!("{:.dec$}", row[3]),
                speed,
                "{solver} {volts} V speed"
            );
        }
    }
}

#[test]
fn simulate_sine_with_effect_and_logger_measurement() {
    let out = motorid(&[
        "simulate",
        "--sine",
        "0.1,0.05",
        "--duration",
        "30",
        "--rate",
        "100",
        "--effect",
        "cogging_torque:amp=0.005,n=6",
        "--adc-bits",
        "10",
        "--noise-lsb",
        "1",
        "--encoder-cpr",
        "2000",
        "--speed-from",
        "encoder",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("# effects: cogging_torque:amp=0.005,n=6,phase=0"));
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 3001);
    // Negative voltages occur (a sine) and the 10-bit voltage channel has at most 1024 levels.
    assert!(rows.iter().any(|r| r[1] < 0.0));
    let mut levels: Vec<i64> = rows.iter().map(|r| (r[1] * 1e9) as i64).collect();
    levels.sort();
    levels.dedup();
    assert!(levels.len() <= 1024);
}

#[test]
fn motor_json_file_is_read_and_checked() {
    let dir = scratch("motor-json");
    let good = dir.join("servo.json");
    std::fs::write(
        &good,
        r#"{"R": 2.0, "L": 0.002, "k": 0.05, "f": 1e-5, "J": 2e-5, "Ts": 0.004}"#,
    )
    .unwrap();
    let out = motorid(&["model", "--motor", good.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert!((v["tau_e"].as_f64().unwrap() - 0.001).abs() < 1e-15);
}

/// Bad input: a one-line error naming what is wrong, exit code 2, never a panic.
#[test]
fn bad_input_gives_one_line_errors_and_exit_code_2() {
    let dir = scratch("bad");
    let negative_r = dir.join("negative_r.json");
    std::fs::write(
        &negative_r,
        r#"{"R": -1, "L": 1, "k": 1, "f": 1, "J": 1, "Ts": 0}"#,
    )
    .unwrap();
    let missing_key = dir.join("missing.json");
    std::fs::write(&missing_key, r#"{"R": 1, "L": 1, "k": 1, "f": 1, "J": 1}"#).unwrap();
    let unknown_key = dir.join("unknown.json");
    std::fs::write(
        &unknown_key,
        r#"{"R": 1, "L": 1, "k": 1, "f": 1, "J": 1, "Ts": 0, "Rr": 2}"#,
    )
    .unwrap();
    let not_json = dir.join("garbage.json");
    std::fs::write(&not_json, "R = 1\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["model", "--motor", negative_r.to_str().unwrap()],
            "R = -1: must be greater than zero",
        ),
        (
            vec!["model", "--motor", missing_key.to_str().unwrap()],
            "missing field `Ts`",
        ),
        (
            vec!["model", "--motor", unknown_key.to_str().unwrap()],
            "unknown field `Rr`",
        ),
        (
            vec!["model", "--motor", not_json.to_str().unwrap()],
            "line 1",
        ),
        (
            vec!["model", "--motor", "/no/such/motor.json"],
            "cannot read the file",
        ),
        (vec!["simulate", "--duration", "1"], "give one input"),
        (
            vec!["simulate", "--voltage", "1", "--duration", "-1"],
            "--duration -1: expected a record length greater than 0 s",
        ),
        (
            vec!["simulate", "--voltage", "1", "--rate", "0"],
            "--rate 0: expected a sample rate greater than 0 Hz",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "1",
                "--duration",
                "1e9",
                "--rate",
                "1e6",
            ],
            "1e15 samples; at most 10000000 fit in memory",
        ),
        (vec!["simulate", "--sine", "0.1"], "two numbers"),
        (vec!["simulate", "--sine", "0.1,-2"], "sine frequency = -2"),
        (
            vec!["simulate", "--voltage", "1", "--effect", "warp_drive:x=1"],
            "unknown effect",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "1",
                "--effect",
                "cogging_torque:amp=0.01,amp=0.02",
            ],
            "--effect cogging_torque:amp=0.01,amp=0.02: key `amp` given twice; give each key once",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "1",
                "--effect",
                "cogging_torque:amp=0.01,phase",
            ],
            "`phase` is not of the form key=value",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "1",
                "--effect",
                "stribeck_friction:tst=0.001",
            ],
            "at least the motor's Coulomb torque",
        ),
        (
            vec!["simulate", "--voltage", "1", "--noise-lsb", "1"],
            "needs --adc-bits",
        ),
        (
            vec!["simulate", "--voltage", "1", "--adc-bits", "40"],
            "1 to 24 bits",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "1",
                "--range-current",
                "5,1",
                "--adc-bits",
                "10",
            ],
            "lo < hi",
        ),
        (vec!["simulate", "--voltage", "nan"], "voltage"),
    ];
    for (args, needle) in cases {
        assert_bad_input(&args, needle);
    }
}

#[test]
fn output_is_written_atomically_and_unwritable_paths_fail_cleanly() {
    let out = motorid(&[
        "simulate",
        "--voltage",
        "1",
        "--duration",
        "0.01",
        "-o",
        "/no/such/dir/rec.csv",
    ]);
    // Refused before simulating, as input to fix.
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("-o /no/such/dir/rec.csv: directory /no/such/dir does not exist"));
    let dir = scratch("atomic");
    let path = dir.join("rec.csv");
    let out = motorid(&[
        "simulate",
        "--voltage",
        "1",
        "--duration",
        "0.01",
        "-o",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "{leftovers:?}");
}

#[test]
fn demo_prints_tables_1_and_2_beside_the_paper() {
    let out = motorid(&["demo"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for line in [
        "KE           1.3333 = 1.3333",
        "Im      53.57 = 53.57",
        "Wb      9.748 = 9.748",
    ] {
        assert!(text.contains(line), "missing `{line}` in\n{text}");
    }
    assert!(text.contains("0.3881 ≠ 0.3381"));
    // Each full-model table says whether each 95 % interval contains the truth, and a table
    // with a "no" says why in the line after it: through the logger (noise) every one holds.
    let tables: Vec<&str> = text.split("full 95% CI contains truth").skip(1).collect();
    assert_eq!(tables.len(), 2, "{text}");
    for table in &tables {
        let rows: Vec<&str> = table.lines().skip(1).take(6).collect();
        assert!(
            rows.iter().all(|r| r.ends_with("yes") || r.ends_with("no")),
            "{rows:?}"
        );
        if rows.iter().any(|r| r.ends_with("no")) {
            assert!(
                table.contains("(\"no\": the records are exact;"),
                "a \"no\" without its reason:\n{table}"
            );
        }
    }
    let logger_rows: Vec<&str> = tables[1].lines().skip(1).take(6).collect();
    assert!(
        logger_rows.iter().all(|r| r.ends_with("yes")),
        "{logger_rows:?}"
    );
    // It ends with a diagnosis that names the withheld brush drop, its truth in its interval.
    let verdict = text
        .lines()
        .find(|l| l.contains("verdict: "))
        .unwrap_or_else(|| panic!("no diagnosis in\n{text}"));
    assert!(verdict.contains("verdict: brush_drop, Vb = "), "{verdict}");
    let interval = verdict
        .split('[')
        .nth(1)
        .and_then(|r| r.split(']').next())
        .unwrap();
    let bounds: Vec<f64> = interval.split(", ").map(|v| v.parse().unwrap()).collect();
    assert!(bounds[0] <= 0.3 && 0.3 <= bounds[1], "{verdict}");
}

/// Acceptance 3 of the identification issue, small version (the full check is
/// `motorid montecarlo --runs 200`, see the README). 24 seeded record pairs: every full fit
/// converges, the full method's median error is below the paper method's for every parameter,
/// and the 95 % intervals cover the truth in at least 18 of 24 runs (for a true 95 % interval
/// P(X ≤ 17 | n = 24) ≈ 7e-4; the seeds are fixed, so the outcome is reproducible).
#[test]
fn montecarlo_small_version() {
    let v = montecarlo_beats_the_paper(&["--runs", "24"], 24, 18);
    assert_eq!(v["runs"], 24);
}

/// Runs `motorid montecarlo ARGS --json` of `runs` record pairs and checks that every full fit
/// converged, that the full method's median error is below the paper method's for every
/// parameter and that each parameter's interval covered the truth in at least `covered` runs;
/// returns the report.
fn montecarlo_beats_the_paper(args: &[&str], runs: u64, covered: u64) -> serde_json::Value {
    let mut all = vec!["montecarlo", "--json"];
    all.extend(args);
    let out = motorid(&all);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(v["converged"], runs);
    for p in v["parameters"].as_array().unwrap() {
        let paper = p["paper_median_abs_rel_error"].as_f64().unwrap();
        let full = p["full_median_abs_rel_error"].as_f64().unwrap();
        let coverage = p["full_ci95_coverage"].as_f64().unwrap();
        assert!(full < paper, "{p}");
        assert!(coverage >= covered as f64 / runs as f64, "{p}");
    }
    v
}

/// Acceptance 5 of issue 12 for the step methods, small version (the full check is
/// `motorid montecarlo --runs 200 --return-to-zero …`, see the README): 8 seeded record pairs
/// whose steps return to 0 V after 50 s, at a sub-sample instant, on a voltage range whose
/// lower rail is 0 V with ±0.5 LSB of noise. Every full fit (rise and fall) converges, is more
/// accurate than the paper's method on the rise, and its 95 % intervals cover the truth in at
/// least 6 of 8 runs for every parameter (for a true 95 % interval P(X ≤ 5 | n = 8) ≈ 6e-3;
/// the seeds are fixed, so the outcome is reproducible).
#[test]
fn montecarlo_with_a_return_to_zero_covers_the_truth() {
    let v = montecarlo_beats_the_paper(
        &[
            "--runs",
            "8",
            "--seed",
            "3",
            "--return-to-zero",
            "--subsample-step",
            "--voltage-noise-lsb",
            "0.5",
        ],
        8,
        6,
    );
    assert_eq!(v["runs"], 8);
    assert_eq!(v["paper_method_applied"], 8);
}

/// Acceptance 5 of issue 12 without any noise, small version (the full check is
/// `motorid montecarlo --runs 200 --noise-lsb 0 --subsample-step --motor-spread 0.02
/// --vary-range`, see the README): `montecarlo --noise-lsb 0` reported 0 % coverage. 8 seeded
/// record pairs, each with its own motor and its own place between codes: every full fit
/// converges with intervals that cover the truth in at least 6 of 8 runs for every parameter
/// (P(X ≤ 5 | n = 8) ≈ 6e-3 for a true 95 % interval).
#[test]
fn montecarlo_without_noise_covers_the_truth() {
    let out = motorid(&[
        "montecarlo",
        "--runs",
        "8",
        "--noise-lsb",
        "0",
        "--subsample-step",
        "--motor-spread",
        "0.02",
        "--vary-range",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(v["converged"], 8, "{v}");
    for p in v["parameters"].as_array().unwrap() {
        assert!(p["full_ci95_coverage"].as_f64().unwrap() >= 0.75, "{p}");
    }
}

/// `identify` of a pair of logger records whose voltage returns to 0 V after 30 s says that both
/// whole records were fitted, rise and fall, and lands within two half-widths of every 95 %
/// interval of the paper's motor (missed by that much with probability 1e-4 each: coverage
/// itself is measured by `montecarlo --return-to-zero`; this seed's L is 1.2 half-widths off).
#[test]
fn a_step_pair_that_returns_to_zero_is_fitted_whole_and_says_so() {
    let dir = scratch("return-to-zero");
    let records =
        [("h.csv", "0:40,30:0", "1"), ("l.csv", "0:2.5,30:0", "2")].map(|(name, levels, seed)| {
            let path = dir.join(name);
            let mut args = vec!["--levels", levels, "--duration", "60", "--seed", seed];
            args.extend_from_slice(&LOGGER);
            simulate_to(&path, &args);
            path.to_str().unwrap().to_string()
        });
    let pair = ["identify", "--high", &records[0], "--low", &records[1]];
    let out = motorid(&pair);
    let text = stdout(&out);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        text.contains("both whole records, rise and return to 0 V"),
        "{text}"
    );
    let out = motorid(&[&pair[..], &["--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(report["method"], "full");
    for (name, truth) in PAPER_TRUTH {
        let (lo, hi) = interval(&report, name);
        let error = (report["parameters"][name]["value"].as_f64().unwrap() - truth).abs();
        assert!(error <= hi - lo, "{name}: [{lo}, {hi}] is far from {truth}");
    }
}

/// A long simulation reports its phase on standard error (here about 6 s: a 1 µs electrical
/// time constant makes the ODE take 25 ns steps); a short one and `--quiet` do not.
#[test]
fn long_simulations_report_progress_unless_quiet() {
    let dir = scratch("progress");
    let motor = dir.join("fast.json");
    std::fs::write(
        &motor,
        r#"{"R": 0.3, "L": 3e-7, "k": 0.15, "f": 0.05, "J": 1, "Ts": 0.03}"#,
    )
    .unwrap();
    let path = dir.join("p.csv");
    let run = |quiet: bool, duration: &str| {
        let mut args = vec!["simulate", "--motor", motor.to_str().unwrap()];
        // A sine, integrated by RK4 (a step of the nominal model is propagated exactly, in
        // no time): τe = 1 µs makes a second of it take seconds.
        args.extend(["--sine", "40,0.5", "--solver", "ode"]);
        args.extend(["--duration", duration]);
        args.extend(["-o", path.to_str().unwrap()]);
        if quiet {
            args.push("--quiet");
        }
        let out = motorid(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        stderr(&out)
    };
    let long = run(false, "1");
    let started = long
        .lines()
        .find(|l| l.starts_with("  simulate: simulating 1001 samples (stick-slip ODE) ("))
        .unwrap_or_else(|| panic!("no progress: {long}"));
    // The first report comes after about a second, never before.
    let at: f64 = started
        .rsplit('(')
        .next()
        .and_then(|t| t.strip_suffix(" s)"))
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("`{started}`"));
    assert!(at >= 1.0, "{long}");
    assert!(
        long.lines()
            .last()
            .unwrap_or_default()
            .starts_with("wrote 1001 samples"),
        "{long}"
    );
    assert_eq!(run(true, "0.5"), "", "--quiet printed");
    let short = run(false, "0.01");
    assert!(!short.contains("simulate:"), "{short}");
}

/// Identifications that take seconds say what they are doing on standard error (issue "No
/// silent wrong answers", item 9: nothing was printed during a 7 s fit of two 2M-row records):
/// a step pair of more than 50 MB says that it reads, then fits how many samples, then how
/// long it took; an output-error fit of 20,000 samples or more says it fits by simulation.
/// `--quiet` prints none of it, and the results stay right.
#[test]
fn long_identifications_report_progress_unless_quiet() {
    let dir = scratch("identify_progress");
    // 2 × 500,001 rows of about 60 bytes: 62 MB.
    let (hv, lv) = simulate_pair(&dir, "paper", "40", "2.5", "500");
    let (h, l) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    let out = motorid(&["identify", "--high", h, "--low", l, "--json"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    // A line a second once the work has taken a second, naming its phase.
    let fitting: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("  identify: fitting 1000002 samples"))
        .collect();
    assert!(!fitting.is_empty(), "no progress of the fit: {err}");
    let at = |line: &str| -> f64 {
        line.rsplit('(')
            .next()
            .and_then(|t| t.strip_suffix(" s)"))
            .and_then(|t| t.parse().ok())
            .unwrap_or_else(|| panic!("`{line}`"))
    };
    assert!(at(fitting[0]) >= 1.0, "a report before a second: {err}");
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    common::assert_truth_in_intervals(&report, &PAPER_TRUTH);
    let quiet = motorid(&["identify", "--high", h, "--low", l, "--quiet"]);
    assert!(quiet.status.success(), "{}", stderr(&quiet));
    assert_eq!(stderr(&quiet), "", "--quiet printed");

    // A 200,001-sample logger staircase by output error (several seconds).
    let long = dir.join("long.csv");
    let mut args = LOGGER.to_vec();
    args.extend_from_slice(&["--levels", "0.5:40,100.5:2.5", "--duration", "200"]);
    simulate_to(&long, &args);
    let oe = motorid(&["identify", "--record", long.to_str().unwrap(), "--json"]);
    let err = stderr(&oe);
    assert!(oe.status.success(), "{err}");
    assert!(
        err.lines().any(
            |l| l.starts_with("  identify: fitting 1 record(s), 200001 samples, by simulation")
        ),
        "{err}"
    );
}

/// Records of 10 samples (9 ms) end long before the current settles: the paper's method says
/// the record is too short, with the settling time from the current's rise (Eq. (10): 5 τe,
/// τe = L/R = 1 s for the paper's motor), instead of blaming the step voltage.
#[test]
fn ten_sample_records_are_called_too_short() {
    let dir = scratch("short");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    for (path, volts) in [(&hv, "40"), (&lv, "2.5")] {
        let out = motorid(&[
            "simulate",
            "--voltage",
            volts,
            "--duration",
            "0.009",
            "-o",
            path.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert_bad_input(
        &[
            "identify",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
            "--method",
            "paper",
        ],
        "low-voltage test: record too short: 10 samples (0.009 s) end before the current settles, the current needs about 5.000 s to settle (5 τe, τe ≈ 1.000 s from its rise, Eq. (10))",
    );
}

/// A study whose every run fails (records of 0.05 s: the steps are far from settled) exits
/// with code 3 and no table; the progress counts the failures instead of calling them
/// identified.
#[test]
fn montecarlo_runs_that_fail_are_counted_and_give_exit_code_3() {
    let out = motorid(&["montecarlo", "--runs", "2", "--duration", "0.05"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("2/2 record pairs done: 0 identified, 2 failed"),
        "{err}"
    );
    assert!(!err.contains("2/2 record pairs identified"), "{err}");
    assert!(
        err.contains("error: all 2 runs failed; nothing to report. The first: run 0"),
        "{err}"
    );
    assert!(!stdout(&out).contains("NaN"), "{}", stdout(&out));
    // Some runs failing (motors spread by 30 %, 8 s records: one of the eight is refused): the
    // table covers the others, and the exit code is still 3.
    let out = motorid(&[
        "montecarlo",
        "--runs",
        "8",
        "--motor-spread",
        "0.3",
        "--duration",
        "8",
        "--json",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("error: 1 of 8 runs failed: the results above cover the other 7"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(v["runs"], 7, "{v}");
}

/// The identify command on simulated records of the paper's motor: noise-free records give
/// the truth within 0.01 %, JSON has the documented shape.
#[test]
fn identify_recovers_the_paper_motor_from_simulated_records() {
    let dir = scratch("identify");
    let hv = dir.join("hv.csv");
    let lv = dir.join("lv.csv");
    for (path, volts, extra) in [
        (&hv, "40", vec![]),
        (&lv, "2.5", vec!["--step-at", "0.05", "--duration", "50.05"]),
    ] {
        let mut args = vec!["simulate", "--voltage", volts, "-o", path.to_str().unwrap()];
        args.extend(extra);
        assert!(motorid(&args).status.success());
    }
    let out = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(v["method"], "full");
    assert_eq!(v["quality"]["converged"], true);
    for (name, truth, unit) in [
        ("R", 0.3, "ohm"),
        ("L", 0.3, "H"),
        ("k", 0.15, "N·m/A"),
        ("f", 0.05, "N·m·s/rad"),
        ("J", 1.0, "kg·m²"),
        ("Ts", 0.03, "N·m"),
    ] {
        let p = &v["parameters"][name];
        let value = p["value"].as_f64().unwrap();
        assert!((value - truth).abs() < 1e-4 * truth, "{name} = {value}");
        assert_eq!(p["unit"], unit);
        assert_eq!(p["ci95"].as_array().unwrap().len(), 2);
    }
    let paper = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
        "--method",
        "paper",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&paper)).unwrap();
    assert_eq!(v["method"], "paper");
    assert!(v["parameters"]["R"]["ci95"].is_null());
}

fn simulate_pair(
    dir: &std::path::Path,
    motor: &str,
    high: &str,
    low: &str,
    seconds: &str,
) -> (PathBuf, PathBuf) {
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    for (path, volts, seed) in [(&hv, high, "1"), (&lv, low, "2")] {
        let out = motorid(&[
            "simulate",
            "--motor",
            motor,
            "--voltage",
            volts,
            "--duration",
            seconds,
            "--adc-bits",
            "10",
            "--noise-lsb",
            "1",
            "--encoder-cpr",
            "2000",
            "--speed-from",
            "encoder",
            "--seed",
            seed,
            "-o",
            path.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    (hv, lv)
}

/// Acceptance 4: a servo whose τe (0.1 ms) is far below the 1 ms sample period: L's interval
/// is wide and the text output warns. (Whether such intervals cover the truth 95 % of the time
/// is a property of many records, measured by `motorid montecarlo`, not of one.)
#[test]
fn poorly_determined_inductance_is_flagged() {
    let dir = scratch("fast-servo");
    let motor = dir.join("fast.json");
    std::fs::write(
        &motor,
        r#"{"R": 2.0, "L": 0.0002, "k": 0.05, "f": 0.0004, "J": 2e-5, "Ts": 0.004}"#,
    )
    .unwrap();
    let (hv, lv) = simulate_pair(&dir, motor.to_str().unwrap(), "24", "0.5", "0.5");
    let out = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    let warning = text
        .lines()
        .find(|l| l.starts_with("warning: poorly determined"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(warning.contains("L ("), "{warning}");
    let json = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&json)).unwrap();
    let ci = v["parameters"]["L"]["ci95"].as_array().unwrap();
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!((hi - lo) / 0.0002 > 0.2, "[{lo}, {hi}] is not wide");
}

/// Acceptance 4: an underdamped motor (ζ = 0.34), where the paper's method does not apply: the
/// full fit starts from the steady states and recovers every parameter within 0.5 %.
#[test]
fn underdamped_motor_is_identified_without_the_paper_method() {
    let dir = scratch("underdamped");
    let fixture = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/motors/underdamped.json"
    );
    let (hv, lv) = simulate_pair(&dir, fixture, "10", "1", "10");
    let out = motorid(&[
        "identify",
        "--high",
        hv.to_str().unwrap(),
        "--low",
        lv.to_str().unwrap(),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert!(
        v["paper_method"]["failed"].is_string(),
        "{}",
        v["paper_method"]
    );
    for (name, truth) in [
        ("R", 1.0),
        ("L", 0.1),
        ("k", 0.5),
        ("f", 0.01),
        ("J", 0.01),
        ("Ts", 0.01),
    ] {
        let value = v["parameters"][name]["value"].as_f64().unwrap();
        assert!((value - truth).abs() < 5e-3 * truth, "{name} = {value}");
    }
    assert!(
        motorid(&[
            "identify",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
            "--method",
            "paper"
        ])
        .status
        .code()
            == Some(2)
    );
}

/// Issue 4, acceptance 1 (first half): the EMPS benchmark's real record, force = 35.15 × vir,
/// identified as a current-driven linear axis: M, Fv, Fc and the offset within 5 % of the
/// published IDIM-LS reference (M 95.1089 kg, Fv 203.5034 N·s/m, Fc 20.3935 N, offset
/// −3.1648 N), and each reference value inside the 95 % interval. The data lives in
/// ../shared/real-data beside the repository (as in CI); elsewhere the test says so and stops.
#[test]
fn emps_real_data_matches_the_published_reference() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/real-data/emps/DATA_EMPS.csv"
    );
    if !std::path::Path::new(path).exists() {
        eprintln!("skipped: {path} is not on this machine");
        return;
    }
    let plots = scratch("emps-identify-plot");
    let out = motorid(&[
        "identify",
        "--input",
        "current",
        "--record",
        path,
        "--columns",
        "t=time_s,current=vir_controller_output_V,position=qm_motor_position_m",
        "--torque-constant",
        "35.15",
        "--axis",
        "linear",
        "--json",
        "--plot",
        plots.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    // The measured and model force with the residual beneath, as SVG and PNG.
    for ext in ["svg", "png"] {
        let figure = plots.join(format!("DATA_EMPS_inverse_model.{ext}"));
        assert!(
            std::fs::metadata(&figure).unwrap().len() > 10_000,
            "{figure:?}"
        );
    }
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    for (name, reference, unit) in [
        ("J", 95.1089, "kg"),
        ("f", 203.5034, "N·s/m"),
        ("Ts", 20.3935, "N"),
        ("offset", -3.1648, "N"),
    ] {
        let p = &v["parameters"][name];
        let value = p["value"].as_f64().unwrap();
        assert!(
            (value / reference - 1.0).abs() < 0.05,
            "{name} = {value}, reference {reference}"
        );
        let ci = p["ci95"].as_array().unwrap();
        let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
        assert!(
            lo <= reference && reference <= hi,
            "{name}: [{lo}, {hi}] vs {reference}"
        );
        assert_eq!(p["unit"], unit);
    }
}

#[test]
fn current_driven_input_errors_name_what_is_missing() {
    let dir = scratch("current-input");
    let rec = dir.join("axis.csv");
    std::fs::write(&rec, "time_s,vir,qm\n0,1,0\n0.001,1,0.1\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["identify", "--input", "current", "--torque-constant", "2"],
            "needs --record",
        ),
        (
            vec![
                "identify",
                "--input",
                "current",
                "--record",
                rec.to_str().unwrap(),
                "--columns",
                "t=time_s,current=vir,position=qm",
            ],
            "needs --torque-constant K (the torque or force per unit of the current column) or a voltage column",
        ),
        (
            vec![
                "identify",
                "--input",
                "current",
                "--record",
                rec.to_str().unwrap(),
                "--torque-constant",
                "2",
            ],
            "unknown column `vir`",
        ),
        (
            vec![
                "identify",
                "--input",
                "current",
                "--record",
                rec.to_str().unwrap(),
                "--torque-constant",
                "2",
                "--columns",
                "t=time_s,current=vir",
            ],
            "no position column",
        ),
        (
            vec![
                "identify",
                "--input",
                "current",
                "--record",
                rec.to_str().unwrap(),
                "--torque-constant",
                "2",
                "--columns",
                "t=time_s,current=vir,angle=qm",
            ],
            "unknown column `angle`",
        ),
        (
            vec![
                "identify",
                "--input",
                "current",
                "--record",
                rec.to_str().unwrap(),
                "--torque-constant",
                "2",
                "--columns",
                "t=time_s,current=vir,position=qm",
            ],
            "at least",
        ),
    ];
    for (args, needle) in cases {
        assert_bad_input(&args, needle);
    }
}

/// Issue 4, acceptance 1 (second half, without the plot): with the identified parameters the
/// closed-loop simulation of DATA_EMPS_PULSES.csv is compared with the measurement. Unmodelled,
/// the pulses leave a position error while they act close to the PD loop's offset under
/// 175.75 N, F/(gτ kp kv) = 1.284e-4 m; added to the model (as the recorded command shows
/// them: 5 units of vir), the error falls to the estimation record's level.
#[test]
fn emps_pulses_show_where_the_model_disagrees() {
    let dir = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/real-data/emps"
    );
    if !std::path::Path::new(dir)
        .join("DATA_EMPS_PULSES.csv")
        .exists()
    {
        eprintln!("skipped: {dir} is not on this machine");
        return;
    }
    let plots = scratch("emps-plot");
    let out = motorid(&[
        "emps",
        "--dir",
        dir,
        "--json",
        "--plot",
        plots.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let svg = std::fs::read_to_string(plots.join("emps_pulses.svg")).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("pulses unmodelled"),
        "not the figure"
    );
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let val = &v["validation_record"];
    let without = val["without_pulses"]["position_rms_pulse_on_m"]
        .as_f64()
        .unwrap();
    let with = val["with_pulses"]["position_rms_pulse_on_m"]
        .as_f64()
        .unwrap();
    let offset = 175.75 / (35.15 * 160.18 * 243.45);
    assert!(
        (without / offset - 1.0).abs() < 0.1,
        "pulse-on error {without} vs PD offset {offset}"
    );
    assert!(with < 0.05 * without, "{with} vs {without}");
    let est = v["estimation_record"]["position_relerr_percent"]
        .as_f64()
        .unwrap();
    let val_with = val["with_pulses"]["position_relerr_percent"]
        .as_f64()
        .unwrap();
    let val_without = val["without_pulses"]["position_relerr_percent"]
        .as_f64()
        .unwrap();
    assert!(
        val_without > 10.0 * val_with && val_with < 3.0 * est,
        "{est} {val_with} {val_without}"
    );
}

/// `-q`/`--quiet` is accepted by every command, and silences the progress of those that
/// report it (a Monte Carlo study's counter).
#[test]
fn every_command_takes_quiet() {
    for command in [
        "model",
        "simulate",
        "identify",
        "demo",
        "montecarlo",
        "fleet",
        "emulate",
        "acquire",
        "emps",
        "diagnose",
    ] {
        let out = motorid(&[command, "--help"]);
        assert!(
            stdout(&out).contains("-q, --quiet"),
            "{command} --help lists no -q, --quiet"
        );
    }
    let out = motorid(&["model", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = motorid(&["montecarlo", "--runs", "2", "--duration", "5", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stderr(&out), "", "montecarlo -q wrote to standard error");
}

/// `motorid emps` without `--dir` finds the shared EMPS data from any working folder (it ran
/// only from the repository's root), and says which file it read.
#[test]
fn emps_finds_its_data_from_any_folder() {
    let data = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/real-data/emps/DATA_EMPS.csv"
    );
    if !std::path::Path::new(data).exists() {
        eprintln!("skipped: {data} is not on this machine");
        return;
    }
    let elsewhere = scratch("emps-cwd");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(["emps", "--json"])
        .current_dir(&elsewhere)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert!(json.is_object(), "{json}");
}
