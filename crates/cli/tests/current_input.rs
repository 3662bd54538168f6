//! `identify --input current` on records that move one way only: alone, the offset is fixed at
//! 0 (said) and Ts has an interval; two such records are pooled.

mod common;

use common::{
    assert_truth_in_intervals, motorid, scratch, simulate_to, stderr, stdout, LOGGER,
    SMALL_SERVO_TRUTH,
};

fn report(records: &[&str]) -> serde_json::Value {
    let mut args = vec!["identify", "--input", "current"];
    for r in records {
        args.extend(["--record", r]);
    }
    args.extend(["--torque-constant", "0.15", "--cutoff", "5", "--json"]);
    let out = motorid(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).unwrap()
}

fn ci(report: &serde_json::Value, name: &str) -> (f64, f64) {
    let c = &report["parameters"][name]["ci95"];
    (c[0].as_f64().unwrap(), c[1].as_f64().unwrap())
}

#[test]
fn one_way_records_fix_the_offset_with_an_interval_for_ts_and_pool() {
    let dir = scratch("current_input");
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    let mut high = vec!["--voltage", "40"];
    high.extend(LOGGER);
    simulate_to(&hv, &high);
    let mut low = vec!["--voltage", "2.5", "--seed", "2"];
    low.extend(LOGGER);
    simulate_to(&lv, &low);
    let (hv, lv) = (hv.to_str().unwrap(), lv.to_str().unwrap());
    let one = report(&[hv]);
    assert_eq!(one["offset_fitted"], false);
    assert!(one["offset_note"]
        .as_str()
        .unwrap()
        .contains("Ts includes any constant load"));
    let (lo, hi) = ci(&one, "Ts");
    assert!(lo <= 0.03 && 0.03 <= hi, "Ts [{lo}, {hi}]");
    let both = report(&[hv, lv]);
    assert_eq!(both["records"], 2);
    for (name, truth) in [("J", 1.0), ("f", 0.05), ("Ts", 0.03)] {
        let (lo, hi) = ci(&both, name);
        assert!(lo <= truth && truth <= hi, "{name} [{lo}, {hi}]");
    }
    // Pooling the low step narrows Ts's interval.
    let (lo1, hi1) = ci(&one, "Ts");
    let (lo2, hi2) = ci(&both, "Ts");
    assert!(hi2 - lo2 < 0.5 * (hi1 - lo1));
    // A forward and a backward run pooled separate Ts from the offset (0 in the plant).
    let back = dir.join("back.csv");
    let mut reverse = vec!["--voltage", "-40", "--seed", "3"];
    reverse.extend(LOGGER);
    simulate_to(&back, &reverse);
    let two_ways = report(&[hv, back.to_str().unwrap()]);
    assert_eq!(two_ways["offset_fitted"], true);
    assert_eq!(
        two_ways["record_kind"]["identifiable"],
        serde_json::json!(["J", "f", "Ts", "offset"])
    );
    for (name, truth) in [("J", 1.0), ("f", 0.05), ("Ts", 0.03), ("offset", 0.0)] {
        let (lo, hi) = ci(&two_ways, name);
        eprintln!("forward + backward: {name} [{lo:.6e}, {hi:.6e}] truth {truth}");
        assert!(lo <= truth && truth <= hi, "{name} [{lo}, {hi}]");
    }
}

#[test]
fn a_record_sampled_too_slowly_for_the_cutoff_is_named() {
    let dir = scratch("current_input_rates");
    let (fast, slow) = (dir.join("fast.csv"), dir.join("slow.csv"));
    let mut args = vec!["--voltage", "40", "--duration", "5"];
    args.extend(LOGGER);
    simulate_to(&fast, &args);
    args.extend(["--rate", "150"]);
    simulate_to(&slow, &args);
    let slow = slow.to_str().unwrap();
    common::assert_bad_input(
        &[
            "identify",
            "--input",
            "current",
            "--record",
            fast.to_str().unwrap(),
            "--record",
            slow,
            "--torque-constant",
            "0.15",
        ],
        &format!("{slow}: --cutoff 100 Hz is not below half its sample rate (75"),
    );
}

/// The small servo (τe = 1 ms, τm = 50 ms) reversing at ±3 V, 0.5 s at 5 kHz through the
/// logger (2000-count encoder): at a high position cut-off the encoder's step, differentiated
/// twice, is noise in the q̈ column and biased J towards 0 (J 8.3e-6 [2.8e-6, 1.4e-5] at
/// 500 Hz, exit 0, truth 2e-5). Each cut-off must give J, f, Ts inside their intervals, or be refused for
/// the encoder's resolution (exit 3); the default-like 100 Hz must be accepted.
#[test]
fn a_cut_off_beyond_the_encoder_resolution_is_right_or_refused() {
    let dir = scratch("current_input_quantised");
    let rec = dir.join("servo.csv");
    let mut args = vec![
        "--motor",
        "../../fixtures/motors/small_servo.json",
        "--levels",
        "0:3,0.25:-3",
        "--duration",
        "0.5",
        "--rate",
        "5000",
        "--seed",
        "7",
        "--quiet",
    ];
    args.extend(LOGGER);
    simulate_to(&rec, &args);
    let rec = rec.to_str().unwrap();
    let mechanical = &SMALL_SERVO_TRUTH[3..];
    for cutoff in ["100", "200", "500", "1000"] {
        let out = motorid(&[
            "identify",
            "--input",
            "current",
            "--record",
            rec,
            "--cutoff",
            cutoff,
            "--decimation",
            "2",
            "--json",
        ]);
        match out.status.code() {
            Some(0) => {
                let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
                assert_truth_in_intervals(&report, mechanical);
            }
            Some(3) if cutoff != "100" => assert!(
                stderr(&out).contains("above what the position's resolution supports"),
                "--cutoff {cutoff}: {}",
                stderr(&out)
            ),
            code => panic!("--cutoff {cutoff}: exit {code:?}: {}", stderr(&out)),
        }
    }
}
