//! `identify --input current` on records that move one way only: alone, the offset is fixed at
//! 0 (said) and Ts has an interval; two such records are pooled.

mod common;

use common::{motorid, scratch, simulate_to, stderr, stdout, LOGGER};

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
}
