//! Servo logs end to end (SPEC section 8): the shared XL330 logs identified with their own
//! `# load:` and `# controller:` lines, the model saved and replayed, and every bad input of a
//! servo rig refused in one line with exit code 2.

mod common;

use common::{assert_bad_input, motorid, scratch, stderr, stdout};
use std::path::{Path, PathBuf};

/// The shared XL330 logs beside the repository (as in CI); `None` elsewhere.
fn xl330(name: &str) -> Option<String> {
    let path = format!(
        "{}/../../../shared/real-data/bam_xl330/xl330_{name}.csv",
        env!("CARGO_MANIFEST_DIR")
    );
    Path::new(&path).exists().then_some(path)
}

#[test]
fn xl330_logs_identify_save_and_replay() {
    let (Some(a), Some(b), Some(held)) = (
        xl330("sin_sin_kp100"),
        xl330("lift_and_drop_kp200"),
        xl330("up_and_down_kp100"),
    ) else {
        eprintln!("skipped: ../shared/real-data/bam_xl330 is not on this machine");
        return;
    };
    let dir = scratch("servo-xl330");
    let model = dir.join("m.json");
    let out = motorid(&[
        "identify",
        "--record",
        &a,
        "--record",
        &b,
        "--validate",
        &held,
        "--save-model",
        model.to_str().unwrap(),
        "--json",
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let records = report["records"].as_array().unwrap();
    assert_eq!(records.len(), 2);
    // Each record used its own controller line (kp 100 and 200).
    assert!(records[0]["rig"].as_str().unwrap().contains("kp=100"));
    assert!(records[1]["rig"].as_str().unwrap().contains("kp=200"));
    for name in ["ke", "R", "J", "Fc", "fv", "mu_m", "mu_l"] {
        let p = &report["parameters"][name];
        let v = p["value"].as_f64().unwrap();
        let ci = p["ci95"].as_array().unwrap();
        assert!(
            ci[0].as_f64().unwrap() <= v && v <= ci[1].as_f64().unwrap(),
            "{name}"
        );
    }
    let fitted = report["mae_rad"].as_f64().unwrap();
    let validation = report["validation"]["mae_rad"].as_f64().unwrap();
    // The replay explains the logs: far below the 0.1 to 0.3 rad the pendulum swings.
    assert!(fitted < 0.06 && validation < 0.1, "{fitted} {validation}");
    // The saved model replays the held-out log to the same error.
    let out = motorid(&[
        "replay",
        "--model",
        model.to_str().unwrap(),
        "--record",
        &held,
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let replay: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(replay["records"][0]["file"], "xl330_up_and_down_kp100.csv");
    let mae = replay["mae_rad"].as_f64().unwrap();
    assert!((mae - validation).abs() < 1e-12, "{mae} vs {validation}");
}

const HEADER: &str = "t[s],position[rad],duty,supply[V],goal[rad],enable\n";

/// A short servo log after `meta` lines; `rows` overrides the body.
fn log(dir: &Path, name: &str, meta: &str, header: &str, body: Option<&str>) -> PathBuf {
    let rows: String = (0..50)
        .map(|k| format!("{},0.0,0.1,7.3,0.2,1\n", k as f64 * 0.005))
        .collect();
    let path = dir.join(name);
    std::fs::write(&path, format!("{meta}{header}{}", body.unwrap_or(&rows))).unwrap();
    path
}

#[test]
fn bad_servo_input_is_one_line_with_exit_2() {
    let dir = scratch("servo-bad");
    let ok_meta = "# load: pendulum:m=0.49,l=0.1\n# controller: dynamixel-xl330:kp=100\n";
    let good = log(&dir, "good.csv", ok_meta, HEADER, None);
    let g = good.to_str().unwrap();
    for (args, needle) in [
        (vec!["--load", "pendulum:m=0.49"], "missing `l=`"),
        (
            vec!["--load", "pendulum:m=0.49,l=0.1,q=3"],
            "unknown key `q`",
        ),
        (vec!["--load", "rope:m=1"], "unknown load `rope`"),
        (vec!["--load", "pendulum:m=-1,l=0.1"], "m = -1"),
        (vec!["--controller", "dynamixel-xl330"], "missing `kp=`"),
        (vec!["--controller", "p:kp=1,max_duty=3"], "max_duty = 3"),
        (vec!["--gear", "0"], "--gear 0"),
    ] {
        let mut all = vec!["identify", "--record", g];
        all.extend(args);
        assert_bad_input(&all, needle);
    }
    let cases = [
        (
            log(
                &dir,
                "nosupply.csv",
                ok_meta,
                "t[s],position[rad],duty\n",
                Some("0,0,0.1\n0.005,0,0.1\n"),
            ),
            "needs a `supply[V]` column",
        ),
        (
            log(
                &dir,
                "goal.csv",
                "",
                "t[s],position[rad],supply[V],goal[rad]\n",
                Some("0,0,7,0\n0.005,0,7,0\n"),
            ),
            "give --controller",
        ),
        (
            log(
                &dir,
                "back.csv",
                ok_meta,
                HEADER,
                Some("0,0,0.1,7.3,0,1\n0.005,0,0.1,7.3,0,1\n0.004,0,0.1,7.3,0,1\n"),
            ),
            "back.csv:6: time stamp 0.004 s is before the previous one",
        ),
        (
            log(
                &dir,
                "dup.csv",
                ok_meta,
                HEADER,
                Some("0,0,0.1,7.3,0,1\n0.005,0,0.1,7.3,0,1\n0.005,0,0.1,7.3,0,1\n"),
            ),
            "dup.csv:6: time stamp 0.005 s repeats the previous one",
        ),
        (
            log(
                &dir,
                "duty.csv",
                ok_meta,
                HEADER,
                Some("0,0,0.1,7.3,0,1\n0.005,0,1.5,7.3,0,1\n"),
            ),
            "duty.csv:5: duty 1.5 is outside -1…1",
        ),
        (
            log(
                &dir,
                "enable.csv",
                ok_meta,
                HEADER,
                Some("0,0,0.1,7.3,0,1\n0.005,0,0.1,7.3,0,2\n"),
            ),
            "enable 2 is neither 0",
        ),
        (
            log(
                &dir,
                "meta.csv",
                "# controller: dynamixel-xl330:kp=0\n",
                HEADER,
                None,
            ),
            "`# controller:` line",
        ),
    ];
    for (path, needle) in &cases {
        assert_bad_input(&["identify", "--record", path.to_str().unwrap()], needle);
    }
    // A model file of another version.
    let model = dir.join("old.json");
    std::fs::write(
        &model,
        r#"{"format":"motorid-model","version":0,"rig":{"motor":{"ke_nm_per_a":0.3,"r_ohm":2,"j_kg_m2":0.002,"fc_nm":0,"fv_nm_s_per_rad":0,"mu_motor":0,"mu_load":0},"gear":1,"loads":[],"controller":null}}"#,
    )
    .unwrap();
    assert_bad_input(
        &["replay", "--model", model.to_str().unwrap(), "--record", g],
        "this motorid reads version 1",
    );
    std::fs::write(&model, "{").unwrap();
    assert_bad_input(
        &["replay", "--model", model.to_str().unwrap(), "--record", g],
        "not a model file",
    );
}

#[test]
fn the_model_file_goes_only_where_it_replaces_nothing_else() {
    let dir = scratch("servo-save");
    let meta = "# load: pendulum:m=0.49,l=0.1\n# controller: dynamixel-xl330:kp=100\n";
    let good = log(&dir, "good.csv", meta, HEADER, None);
    let g = good.to_str().unwrap();
    let target = dir.join("target.txt");
    std::fs::write(&target, "keep").unwrap();
    let link = dir.join("link.json");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let fifo = dir.join("fifo.json");
    common::make_fifo(&fifo);
    for (out, needle) in [
        (link.to_str().unwrap(), "a symbolic link"),
        (fifo.to_str().unwrap(), "not a regular file"),
        ("/dev/null", "not a regular file"),
        (g, "it is the record"),
    ] {
        assert_bad_input(&["identify", "--record", g, "--save-model", out], needle);
    }
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
    assert!(std::fs::read_to_string(&good)
        .unwrap()
        .starts_with("# load"));
    assert_bad_input(&["identify", "--record", g, "--validate", g], "given twice");
    // A fit that is not a result (a still output explains nothing) leaves a saved model alone.
    let still = log(&dir, "still.csv", meta, HEADER, None);
    let keep = dir.join("keep.json");
    std::fs::write(&keep, "previous model").unwrap();
    let out = motorid(&[
        "identify",
        "--record",
        still.to_str().unwrap(),
        "--save-model",
        keep.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(&keep).unwrap(), "previous model");
}

#[test]
fn logs_that_stop_or_contradict_themselves_are_refused() {
    let dir = scratch("servo-meta");
    let meta = "# load: pendulum:m=0.49,l=0.1\n# controller: dynamixel-xl330:kp=100\n";
    let mut body: String = (0..20)
        .map(|k| format!("{},0,0.1,7.3,0.2,1\n", k as f64 * 0.005))
        .collect();
    body.push_str("1000,0,0.1,7.3,0.2,1\n");
    let gap = log(&dir, "gap.csv", meta, HEADER, Some(&body));
    assert_bad_input(
        &["identify", "--record", gap.to_str().unwrap()],
        "gap.csv:24: time stamp 1000 s comes",
    );
    let two = log(
        &dir,
        "two.csv",
        "# controller: dynamixel-xl330:kp=100\n# controller: dynamixel-xl330:kp=200\n",
        HEADER,
        None,
    );
    assert_bad_input(
        &["identify", "--record", two.to_str().unwrap()],
        "2 `# controller:` lines",
    );
    let supply = log(
        &dir,
        "supply.csv",
        meta,
        HEADER,
        Some("0,0,0.1,-7.3,0,1\n0.005,0,0.1,7.3,0,1\n"),
    );
    assert_bad_input(
        &["identify", "--record", supply.to_str().unwrap()],
        "supply.csv:4: supply -7.3 V is negative",
    );
    // A byte-order mark before the metadata: still a servo log.
    let bom = log(
        &dir,
        "bom.csv",
        &format!("\u{feff}{meta}"),
        HEADER,
        Some("0,0,1.5,7.3,0,1\n0.005,0,0.1,7.3,0,1\n"),
    );
    assert_bad_input(
        &["identify", "--record", bom.to_str().unwrap()],
        "duty 1.5 is outside",
    );
    // A model file's controller is checked as the option is.
    let model = dir.join("kp.json");
    std::fs::write(
        &model,
        r#"{"format":"motorid-model","version":1,"rig":{"motor":{"ke_nm_per_a":0.3,"r_ohm":2,"j_kg_m2":0.002,"fc_nm":0,"fv_nm_s_per_rad":0,"mu_motor":0,"mu_load":0},"gear":1,"loads":[],"controller":{"kp":-100,"kd":0,"gain":0.002877,"max_duty":1,"preset":"dynamixel-xl330"}}}"#,
    )
    .unwrap();
    let good = log(&dir, "good.csv", meta, HEADER, None);
    assert_bad_input(
        &[
            "replay",
            "--model",
            model.to_str().unwrap(),
            "--record",
            good.to_str().unwrap(),
        ],
        "kp = -100",
    );
}
