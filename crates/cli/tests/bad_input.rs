//! Broken record files: each gives a one-line error naming the file, the line and the problem,
//! with exit code 2, and none panics.

mod common;

use common::{assert_bad_input, motorid, scratch, stderr};
use std::path::{Path, PathBuf};

const HEADER: &str = "t,voltage,current,speed\n";

/// A plausible record of `n` rows after `header`.
fn rows(n: usize) -> String {
    (0..n)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let on = if i >= 5 { 40.0 } else { 0.0 };
            format!("{t},{on},{},{}\n", on * (1.0 - (-t).exp()) / 0.3, 10.0 * t)
        })
        .collect()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Runs `motorid simulate` with `args` into `dir/name`.
fn simulated(dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let mut all = vec!["simulate", "-o", path.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = motorid(&all);
    assert!(out.status.success(), "{}", stderr(&out));
    path
}

#[test]
fn broken_files_give_one_line_errors_naming_file_and_line() {
    let dir = scratch("broken-files");
    let good = rows(200);
    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            // Voltage and speed alone are a record kind of their own; voltage alone is not.
            "voltage_only.csv",
            format!("t,voltage\n{}", "0,1\n0.001,1\n").into_bytes(),
            ":1: neither current nor speed nor position",
        ),
        (
            "text_in_number.csv",
            format!("{HEADER}{}0.5,40,abc,1\n", rows(3)).into_bytes(),
            ":5: column `current`: `abc` is not a number",
        ),
        (
            "nan.csv",
            format!("{HEADER}{}0.5,40,NaN,1\n", rows(3)).into_bytes(),
            ":5: column `current` is NaN",
        ),
        (
            "inf.csv",
            format!("{HEADER}{}0.5,inf,1,1\n", rows(3)).into_bytes(),
            ":5: column `voltage` is inf",
        ),
        (
            "overflow.csv",
            format!("{HEADER}{}0.5,1e999,1,1\n", rows(3)).into_bytes(),
            ":5: column `voltage` is inf",
        ),
        (
            "time_backwards.csv",
            format!("{HEADER}0,0,0,0\n0.002,0,0,0\n0.001,0,0,0\n").into_bytes(),
            ":4: t goes back to 0.001 s",
        ),
        (
            "time_repeats.csv",
            format!("{HEADER}0,0,0,0\n0.001,0,0,0\n0.001,0,0,0\n").into_bytes(),
            ":4: t repeats 0.001 s",
        ),
        (
            "duplicate_header.csv",
            b"t,voltage,current,current\n0,1,2,3\n".to_vec(),
            ":1: columns `current` and `current` both give current",
        ),
        (
            "alias_clash.csv",
            b"t,voltage,current,omega,speed\n0,1,2,3,4\n".to_vec(),
            ":1: columns `omega` and `speed` both give speed",
        ),
        ("empty.csv", Vec::new(), ":1: no header row (empty file?)"),
        (
            "only_comments.csv",
            b"# motor: test\n# nothing else\n".to_vec(),
            ":2: no header row",
        ),
        (
            "header_only.csv",
            HEADER.as_bytes().to_vec(),
            ":1: no data rows after the header",
        ),
        (
            "single_row.csv",
            format!("{HEADER}0,40,1,0\n").into_bytes(),
            ":2: a single data row",
        ),
        (
            "unknown_unit.csv",
            format!("t,voltage,current[furlong],speed\n{good}").into_bytes(),
            ":1: column `current[furlong]`: unknown unit `furlong`",
        ),
        (
            "unknown_column.csv",
            format!("t,voltage,curent,speed\n{good}").into_bytes(),
            ":1: unknown column `curent`",
        ),
        (
            "no_header.csv",
            good.clone().into_bytes(),
            ":1: the first row `0,0,0,0` is numbers, not a header",
        ),
        (
            "empty_name.csv",
            b"t,,current\n0,1,2\n".to_vec(),
            ":1: an empty column name",
        ),
        (
            "cut_mid_line.csv",
            format!("{HEADER}{}0.5,40", rows(3)).into_bytes(),
            ":5: 2 fields where the header has 4",
        ),
        (
            "cut_mid_number.csv",
            format!("{HEADER}{}0.5,40,12.", rows(3)).into_bytes(),
            ":5: 3 fields where the header has 4",
        ),
        (
            "cut_no_newline.csv",
            format!("{HEADER}{}0.005,40,1.2,0.0", rows(5)).into_bytes(),
            ":7: the last line has no line break",
        ),
        (
            "too_many_fields.csv",
            format!("{HEADER}{}0.5,40,1,1,9\n", rows(3)).into_bytes(),
            ":5: 5 fields where the header has 4 (a stray comma",
        ),
        (
            "bars.csv",
            b"t|voltage|current\n0|1|2\n".to_vec(),
            ":1: the header is separated by bars",
        ),
        (
            // Semicolons are a delimiter (with decimal commas); a row with commas in it
            // then has a field that is not a number.
            "semicolons_mixed.csv",
            b"t;voltage;current\n0;1;2\n0.001;1,2,3;2\n".to_vec(),
            ":3: column `voltage`: `1,2,3` is not a number",
        ),
        (
            "latin1.csv",
            b"# caf\xe9\nt,voltage,current\n".to_vec(),
            ":1: not UTF-8 text",
        ),
        (
            "utf16.csv",
            b"\xff\xfet\0,\0v\0o\0l\0t\0a\0g\0e\0\n\0".to_vec(),
            ":1: UTF-16 text",
        ),
        (
            "utf16_no_bom.csv",
            b"t\0,\0v\0o\0l\0t\0a\0g\0e\0\n\0".to_vec(),
            ":1: UTF-16 text",
        ),
        (
            "cr_only.csv",
            format!("{HEADER}{}", rows(3))
                .replace('\n', "\r")
                .into_bytes(),
            ":1: lines end in a carriage return alone",
        ),
        (
            "decimal_comma_quoted.csv",
            format!("{HEADER}{}0.5,\"40,5\",1,1\n", rows(3)).into_bytes(),
            ":5: column `voltage`: `\"40,5\"` is not a number (a decimal comma?",
        ),
        (
            "thousands.csv",
            b"t;voltage;current;speed\n0;1.000,5;1;1\n".to_vec(),
            ":2: column `voltage`: `1.000,5` is not a number (thousands separators?",
        ),
        (
            "binary.png",
            b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec(),
            ":1: not UTF-8 text",
        ),
        (
            "nul.csv",
            b"t,voltage,current\n0,1\x002,3\n".to_vec(),
            ":2: NUL byte",
        ),
        (
            "all_zero_voltage.csv",
            format!(
                "{HEADER}{}",
                (0..200)
                    .map(|i| format!("{},0,0,0\n", i as f64 * 1e-3))
                    .collect::<String>()
            )
            .into_bytes(),
            ":2-201: the voltage is 0 V throughout",
        ),
        (
            "no_speed.csv",
            format!(
                "t,voltage,current\n{}",
                (0..200)
                    .map(|i| format!("{},40,1\n", i as f64 * 1e-3))
                    .collect::<String>()
            )
            .into_bytes(),
            ":1: neither speed nor position",
        ),
    ];
    // BOM and CRLF are read; the error is then the real problem further on (a text field).
    let mut bom = b"\xef\xbb\xbf".to_vec();
    bom.extend_from_slice(format!("{HEADER}{}0.5,40,x,1\n", rows(3)).as_bytes());
    cases.push((
        "bom_then_text.csv",
        bom,
        ":5: column `current`: `x` is not a number",
    ));
    let crlf = format!("{HEADER}{}0.5,40,y,1\n", rows(3)).replace('\n', "\r\n");
    cases.push((
        "crlf_then_text.csv",
        crlf.into_bytes(),
        ":5: column `current`: `y` is not a number",
    ));
    assert!(cases.len() >= 25);
    for (name, bytes, needle) in &cases {
        let path = write(&dir, name, bytes);
        let shown = path.to_str().unwrap();
        assert_bad_input(&["identify", "--record", shown], needle);
        // Every message names the file.
        assert_bad_input(&["identify", "--record", shown], shown);
    }
    // Not a file at all.
    assert_bad_input(
        &["identify", "--record", dir.to_str().unwrap()],
        "a directory, not a record file",
    );
    assert_bad_input(
        &["identify", "--record", "/no/such/record.csv"],
        "/no/such/record.csv: cannot read",
    );
}

/// A gigabyte of NUL bytes (a sparse file: no disk used) is refused at its first line, at once.
#[test]
fn a_gigabyte_of_garbage_is_refused_at_the_first_line() {
    let dir = scratch("garbage");
    let path = dir.join("huge.csv");
    let file = std::fs::File::create(&path).unwrap();
    file.set_len(1 << 30).unwrap();
    drop(file);
    assert_bad_input(
        &["identify", "--record", path.to_str().unwrap()],
        ":1: longer than 64 KiB without a line break",
    );
    // Random bytes with line breaks: refused at the first bad line.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let garbage: Vec<u8> = (0..4_000_000)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect();
    let path = write(&dir, "random.csv", &garbage);
    let out = motorid(&["identify", "--record", path.to_str().unwrap()]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        !err.contains("panicked") && err.trim_end().lines().count() == 1,
        "{err}"
    );
    assert!(err.contains("random.csv:1:"), "{err}");
    std::fs::remove_file(dir.join("huge.csv")).unwrap();
}

/// Records that read well but cannot be identified: each error names the file and its lines.
#[test]
fn unusable_records_are_named_with_their_lines() {
    let dir = scratch("unusable");
    let logger = ["--adc-bits", "10", "--noise-lsb", "1", "--step-at", "0.005"];
    let with = |v: &str, extra: &[&str]| -> Vec<String> {
        let duration = if extra.contains(&"--duration") {
            None
        } else {
            Some("20")
        };
        let mut a: Vec<String> = ["--voltage", v].iter().map(|s| s.to_string()).collect();
        if let Some(d) = duration {
            a.extend(["--duration".to_string(), d.to_string()]);
        }
        a.extend(logger.iter().map(|s| s.to_string()));
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let sim = |name: &str, args: Vec<String>| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        simulated(&dir, name, &refs)
    };
    let high = sim("high.csv", with("40", &[]));
    let stuck = sim("stuck.csv", with("0.05", &[]));
    let clipped = sim(
        "clipped_current.csv",
        with("40", &["--range-current", "-5,20"]),
    );
    let clipped_v = sim(
        "clipped_voltage.csv",
        with("40", &["--range-voltage", "-5,30"]),
    );
    let short_high = sim("short_high.csv", with("40", &["--duration", "3"]));
    let short_low = sim("short_low.csv", with("2.5", &["--duration", "3"]));
    let p = |x: &PathBuf| x.to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, String)> = vec![
        (
            vec![
                "identify".into(),
                "--high".into(),
                p(&high),
                "--low".into(),
                p(&stuck),
            ],
            format!("{}:7-20007", p(&stuck)),
        ),
        (
            vec![
                "identify".into(),
                "--high".into(),
                p(&high),
                "--low".into(),
                p(&stuck),
            ],
            "does not break the Coulomb friction".into(),
        ),
        (
            vec!["identify".into(), "--record".into(), p(&clipped)],
            "current samples".into(),
        ),
        (
            vec!["identify".into(), "--record".into(), p(&clipped)],
            "sit on an ADC rail at 20 (line".into(),
        ),
        (
            vec!["identify".into(), "--record".into(), p(&clipped_v)],
            "the fits need the applied voltage".into(),
        ),
        (
            vec![
                "identify".into(),
                "--method".into(),
                "paper".into(),
                "--high".into(),
                p(&short_high),
                "--low".into(),
                p(&short_low),
            ],
            "has not settled".into(),
        ),
        (
            vec![
                "identify".into(),
                "--steady".into(),
                p(&short_high),
                "--resistance".into(),
                "0.3".into(),
                "--torque-constant".into(),
                "0.15".into(),
            ],
            format!("{}:7-3007: the speed has not settled", p(&short_high)),
        ),
    ];
    for (args, needle) in &cases {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_bad_input(&refs, needle);
    }
}

/// The acquisition commands' bad input: one line, exit code 2.
#[test]
fn acquisition_options_are_checked() {
    let dir = scratch("acquire-bad");
    let out = dir.join("x.csv");
    let o = out.to_str().unwrap();
    let bad_cal = write(
        &dir,
        "cal.json",
        b"{\"voltage\": [5, -5], \"current\": [0, 1], \"speed\": [0, 1], \"counts_per_rev\": 10}",
    );
    let typo_cal = write(&dir, "typo.json", b"{\"volts\": [0, 1]}");
    let small_cal = write(
        &dir,
        "small.json",
        b"{\"voltage\": [-10, 10], \"current\": [-20, 20], \"speed\": [-50, 50], \"counts_per_rev\": 500}",
    );
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "1",
                "-o",
                o,
            ],
            "--port /no/such/tty: cannot open",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "-1",
                "-o",
                o,
            ],
            "--duration -1: expected a positive length",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "1",
                "--rate",
                "20000",
                "-o",
                o,
            ],
            "--rate 20000: expected 1 to 10000 Hz",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "1",
                "--calibration",
                bad_cal.to_str().unwrap(),
                "-o",
                o,
            ],
            "lo < hi",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "1",
                "--calibration",
                typo_cal.to_str().unwrap(),
                "-o",
                o,
            ],
            "unknown field `volts`",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/dev/null",
                "--voltage",
                "40",
                "--duration",
                "1",
                "-o",
                o,
            ],
            "--port /dev/null: not a serial port (a device that is not a terminal); give the logger's port, e.g. /dev/ttyUSB0, or the PTY path `motorid emulate --pty` prints",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "1000",
                "--duration",
                "1",
                "-o",
                o,
            ],
            "--voltage 1000: outside the logger's calibrated voltage range -50 to 50 V",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "-12",
                "--duration",
                "1",
                "--calibration",
                small_cal.to_str().unwrap(),
                "-o",
                o,
            ],
            "--voltage -12: outside the logger's calibrated voltage range -10 to 10 V (from ",
        ),
        (
            vec![
                "acquire",
                "--port",
                "/no/such/tty",
                "--voltage",
                "40",
                "--duration",
                "1e6",
                "-o",
                o,
            ],
            "--duration: 1000000 s at 1000 Hz is 1000000001 samples; the logger's 16 Mbit flash holds at most 349525 (6 bytes a sample)",
        ),
        (
            vec!["emulate", "--pty", "--faults", "ber"],
            "--faults: `ber` is not KEY=VALUE",
        ),
        (
            vec!["emulate", "--pty", "--faults", "warp=1"],
            "unknown key `warp`",
        ),
        (
            vec!["emulate", "--pty", "--motor", "/no/such.json"],
            "cannot read the file",
        ),
    ];
    for (args, needle) in cases {
        assert_bad_input(&args, needle);
    }
    assert!(!out.exists());
}

/// Settings that cannot give a meaningful result are refused before any work, exit code 2,
/// with what to fix: a Monte Carlo study whose every run would fail, a record that would be
/// all zeros, physically absurd voltages and motors, a probability above 1.
#[test]
fn settings_are_checked_before_the_first_run() {
    let dir = scratch("settings");
    let huge_r = write(
        &dir,
        "huge_r.json",
        br#"{"R": 1e308, "L": 0.3, "k": 0.15, "f": 0.05, "J": 1, "Ts": 0.03}"#,
    );
    let huge = huge_r.to_str().unwrap();
    let x = dir.join("x.csv");
    let o = x.to_str().unwrap();
    let fleet_dir = dir.join("fleet");
    let fleet = fleet_dir.to_str().unwrap();
    let mc = |extra: &[&'static str]| {
        let mut v = vec!["montecarlo", "--runs", "2"];
        v.extend_from_slice(extra);
        v
    };
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            mc(&["--duration", "0"]),
            "--duration 0: expected a record length greater than 0 s",
        ),
        (
            mc(&["--rate", "1e9"]),
            "--duration 50 at --rate 1e9: 5.0000000001e10 samples; at most 10000000 fit in memory",
        ),
        (mc(&["--adc-bits", "0"]), "--adc-bits 0: expected 1 to 24 bits"),
        (
            vec!["montecarlo", "--runs", "0"],
            "--runs 0: expected 1 to 1000000 record pairs",
        ),
        (
            vec!["montecarlo", "--runs", "1000000000000"],
            "--runs 1000000000000: expected 1 to 1000000 record pairs",
        ),
        (mc(&["--adc-bits", "30"]), "--adc-bits 30: expected 1 to 24 bits"),
        // A settings file is read up to 1 MiB: /dev/zero grew to gigabytes and never ended.
        (
            vec!["model", "--motor", "/dev/zero"],
            "--motor /dev/zero: cannot read the file (more than 1048576 bytes: not a settings file)",
        ),
        // Issue "No silent wrong answers", item 5: `montecarlo --noise-lsb 0` reported 0 %
        // coverage — every run read the 40 V level exactly halfway between two codes.
        (
            mc(&["--noise-lsb", "0", "--subsample-step", "--motor-spread", "0.02"]),
            "--noise-lsb 0 without --vary-range: with no noise every run reads each level at the same place between two ADC codes",
        ),
        (
            mc(&["--voltage-noise-lsb", "0"]),
            "--voltage-noise-lsb 0 without --vary-range",
        ),
        (
            mc(&["--noise-lsb", "0", "--voltage-noise-lsb", "1"]),
            "--noise-lsb 0 (current and speed, no --motor-spread) without --vary-range",
        ),
        // The paper's motor breaks away above R·Ts/k = 0.3 · 0.03 / 0.15 = 0.06 V.
        (
            mc(&["--low-voltage", "0.01"]),
            "--low-voltage 0.01: the rotor never breaks away: this motor needs |E| > R·Ts/k = 0.0600 V",
        ),
        // At 0.07 V, Eq. (11): t0 = −1 s · ln(1 − 0.06/0.07) = 1.946 s.
        (
            mc(&["--low-voltage", "0.07", "--duration", "1"]),
            "breaks away only at t0 = 1.946 s (Eq. (11)), after the 1 s record ends",
        ),
        (
            mc(&["--high-voltage", "1e300"]),
            "--high-voltage 1e300: expected a voltage between -1e5 and 1e5 V",
        ),
        (
            vec![
                "simulate",
                "--voltage",
                "40",
                "--step-at",
                "100",
                "--duration",
                "50",
                "-o",
                o,
            ],
            "--step-at 100: expected an instant from 0 s to before the end of the 50 s record",
        ),
        (
            vec![
                "simulate",
                "--levels",
                "60:40",
                "--duration",
                "50",
                "-o",
                o,
            ],
            "the first level starts at 60 s, not before the end of the 50 s record",
        ),
        (
            vec!["simulate", "--sine", "10,1e7", "-o", o],
            "--sine 10,1e7: 1e7 Hz is above half the sample rate (500 Hz): the record would alias it",
        ),
        (
            vec!["simulate", "--prbs", "20,0.0001", "-o", o],
            "--prbs 20,0.0001: a bit of 0.0001 s is shorter than the sample period 0.001 s",
        ),
        (
            vec!["simulate", "--voltage", "1e300", "-o", o],
            "--voltage 1e300: expected a voltage between -1e5 and 1e5 V",
        ),
        (
            vec!["simulate", "--voltage", "-2e5", "-o", o],
            "--voltage -200000: expected a voltage between",
        ),
        (
            vec!["simulate", "--voltage", "40", "--rate", "NaN", "-o", o],
            "--rate NaN: expected a sample rate greater than 0 Hz",
        ),
        (
            vec!["simulate", "--voltage", "40", "--motor", huge, "-o", o],
            "R = 1e308 Ω is outside the range of physical motors this tool handles (1e-12 to 1e6 Ω)",
        ),
        (
            vec!["model", "--motor", huge],
            "R = 1e308 Ω is outside the range",
        ),
        (
            vec!["emulate", "--pty", "--faults", "ber=2"],
            "--faults ber: 2 is not a probability: expected a number from 0 to 1",
        ),
        (
            vec!["emulate", "--pty", "--faults", "drop=1.5"],
            "--faults drop: 1.5 is not a probability",
        ),
        (
            vec!["fleet", "--out", fleet, "--spread", "1e300"],
            "--spread 1e300: expected a factor from 1 to 100",
        ),
        (
            vec!["fleet", "--out", fleet, "--low-voltage", "0.001"],
            "motor_001: --low-voltage 0.001: the rotor never breaks away",
        ),
    ];
    for (args, needle) in cases {
        assert_bad_input(&args, needle);
    }
    assert!(!x.exists(), "a refused simulation wrote its output");
    assert!(
        !fleet_dir.join("motor_001").join("low.csv").exists(),
        "a refused fleet wrote records"
    );
}

#[test]
fn one_corrupted_sample_is_named_not_taken_for_a_rail() {
    // A current sample of 1e6 A (or 1e300) in a logger record: with the ADC range in the
    // metadata it was "1 current samples sit on an ADC rail at 1000000 …" (300 digits for
    // 1e300) and left out; without the metadata the fit was refused as "a wrong minimum".
    let dir = scratch("corrupted-sample");
    let logger = ["--adc-bits", "10", "--noise-lsb", "1", "--duration", "20"];
    let mut high_args = vec!["--voltage", "40"];
    high_args.extend(logger);
    let mut low_args = vec!["--voltage", "2.5", "--seed", "2"];
    low_args.extend(logger);
    let high = simulated(&dir, "high.csv", &high_args);
    let low = simulated(&dir, "low.csv", &low_args);
    let text = std::fs::read_to_string(&high).unwrap();
    for (name, value, keep_metadata) in [
        ("big.csv", "1000000", true),
        ("huge.csv", "1e300", true),
        ("bare.csv", "1000000", false),
    ] {
        let mut data_row = 0;
        let mut line_no = 0;
        let mut corrupted = String::new();
        for line in text.lines() {
            if line.starts_with('#') && !keep_metadata {
                continue;
            }
            let mut line = line.to_string();
            if !line.starts_with('#') && !line.starts_with('t') {
                data_row += 1;
                if data_row == 5000 {
                    let mut cells: Vec<&str> = line.split(',').collect();
                    cells[2] = value;
                    line = cells.join(",");
                    line_no = corrupted.lines().count() + 1;
                }
            }
            corrupted.push_str(&line);
            corrupted.push('\n');
        }
        let path = write(&dir, name, corrupted.as_bytes());
        assert_bad_input(
            &[
                "identify",
                "--high",
                path.to_str().unwrap(),
                "--low",
                low.to_str().unwrap(),
            ],
            &format!(
                "{name}:{line_no}: current {:e} A",
                value.parse::<f64>().unwrap()
            ),
        );
    }
}

#[test]
fn a_current_in_ma_beyond_the_metadata_range_is_named_a_units_problem() {
    // A logger record whose current column was rescaled to mA, header and metadata kept: was
    // "49998 current samples (100.0 %) sit on an ADC rail at 270.2 …: record again with a wider
    // range".
    let dir = scratch("ma-beyond-rails");
    let high = simulated(
        &dir,
        "high.csv",
        &[
            "--voltage",
            "40",
            "--duration",
            "20",
            "--adc-bits",
            "10",
            "--noise-lsb",
            "1",
        ],
    );
    let low = simulated(
        &dir,
        "low.csv",
        &[
            "--voltage",
            "2.5",
            "--duration",
            "20",
            "--adc-bits",
            "10",
            "--noise-lsb",
            "1",
            "--seed",
            "2",
        ],
    );
    let scaled: String = std::fs::read_to_string(&high)
        .unwrap()
        .lines()
        .map(|line| {
            if line.starts_with(|c: char| c.is_ascii_digit()) {
                let mut cells: Vec<String> = line.split(',').map(String::from).collect();
                cells[2] = (cells[2].parse::<f64>().unwrap() * 1000.0).to_string();
                cells.join(",") + "\n"
            } else {
                format!("{line}\n")
            }
        })
        .collect();
    let ma = write(&dir, "ma.csv", scaled.as_bytes());
    assert_bad_input(
        &[
            "identify",
            "--high",
            ma.to_str().unwrap(),
            "--low",
            low.to_str().unwrap(),
        ],
        "lies beyond the ADC's range",
    );
}

/// A negative number is an option's value, checked as such, never taken for a flag
/// (`--torque-constant -0.05` was "unexpected argument '-0'").
#[test]
fn negative_numbers_are_option_values_checked_as_such() {
    let dir = scratch("negative-values");
    let h = simulated(&dir, "h.csv", &["--voltage", "40", "--duration", "2", "-q"]);
    let h = h.to_str().unwrap();
    assert_bad_input(
        &[
            "identify",
            "--high",
            h,
            "--low",
            h,
            "--torque-constant",
            "-0.05",
        ],
        "--torque-constant -0.05: expected a positive number",
    );
    assert_bad_input(
        &[
            "diagnose",
            "--record",
            h,
            "--input",
            "current",
            "--torque-constant",
            "-0.05",
        ],
        "--torque-constant -0.05: expected a positive number",
    );
}

/// With `--json`, a command that fails before its own object prints one JSON object on
/// standard output carrying the error and the exit code (it printed nothing), whether the
/// command line or the input is at fault; the message also goes to standard error.
#[test]
fn json_failures_print_one_object_with_the_error_and_its_exit_code() {
    for args in [
        vec![
            "identify",
            "--high",
            "missing.csv",
            "--low",
            "missing.csv",
            "--json",
        ],
        vec![
            "diagnose",
            "--high",
            "missing.csv",
            "--low",
            "missing.csv",
            "--json",
        ],
        vec!["model", "--motor", "/no/such/motor.json", "--json"],
        vec!["identify", "--json", "--no-such-option"],
    ] {
        let out = motorid(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        let v: serde_json::Value = serde_json::from_str(&text)
            .unwrap_or_else(|e| panic!("{args:?}: not one JSON object ({e}): `{text}`"));
        assert_eq!(v["exit_code"], 2, "{args:?}: {v}");
        let message = v["error"].as_str().unwrap_or_default();
        assert!(
            !message.is_empty() && stderr(&out).contains(message.lines().next().unwrap()),
            "{args:?}: {v} against {}",
            stderr(&out)
        );
    }
}
