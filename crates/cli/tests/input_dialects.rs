//! Records as spreadsheets and data tools write them: a pandas `to_csv()` file (an unnamed
//! index column first), a header in double quotes (Python's `csv`, Excel), `;` with decimal
//! commas (Excel where the decimal mark is a comma), tabs. Each is the same record as the
//! plain CSV it was rewritten from, and identifies to the very same parameters.

mod common;

use std::path::Path;

use common::{motorid, scratch, small_servo_steps, stderr, stdout};
use serde_json::Value;

/// Writes `src` to `dst` with its header line passed through `header` and each data row
/// (numbered from 0) through `row`; comment lines are kept as they are.
fn rewrite(
    src: &str,
    dst: &Path,
    header: impl Fn(&str) -> String,
    row: impl Fn(usize, &str) -> String,
) -> String {
    let text = std::fs::read_to_string(src).unwrap();
    let mut out = String::new();
    let mut rows = 0;
    let mut seen_header = false;
    for line in text.lines() {
        let line = if line.starts_with('#') {
            line.to_string()
        } else if !seen_header {
            seen_header = true;
            header(line)
        } else {
            rows += 1;
            row(rows - 1, line)
        };
        out.push_str(&line);
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
    dst.to_str().unwrap().to_string()
}

/// [`rewrite`] of both records of a pair into `dir`, each named `{prefix}-{its name}`.
fn rewrite_pair(
    dir: &Path,
    pair: [&str; 2],
    prefix: &str,
    header: impl Fn(&str) -> String,
    row: impl Fn(usize, &str) -> String,
) -> [String; 2] {
    pair.map(|src| {
        let file = Path::new(src).file_name().unwrap().to_str().unwrap();
        rewrite(src, &dir.join(format!("{prefix}-{file}")), &header, &row)
    })
}

/// The identified parameters of a step pair (`parameters` of `identify --json`).
fn parameters(high: &str, low: &str) -> Value {
    let out = motorid(&[
        "identify", "--high", high, "--low", low, "--json", "--quiet",
    ]);
    assert!(out.status.success(), "{high}: {}", stderr(&out));
    let json: Value = serde_json::from_str(&stdout(&out)).unwrap();
    json["parameters"].clone()
}

#[test]
fn records_as_spreadsheets_and_data_tools_write_them_identify_as_the_plain_csv() {
    let dir = scratch("input-dialects");
    let [high, low] = small_servo_steps(&dir, None);
    let plain = parameters(&high, &low);
    assert!(plain.is_object() && plain["R"].is_object(), "{plain}");
    type Rewrite = (&'static str, fn(&str) -> String, fn(usize, &str) -> String);
    let dialects: [Rewrite; 4] = [
        ("pandas", |h| format!(",{h}"), |i, r| format!("{i},{r}")),
        (
            "quoted",
            |h| {
                h.split(',')
                    .map(|f| format!("\"{f}\""))
                    .collect::<Vec<_>>()
                    .join(",")
            },
            |_, r| r.to_string(),
        ),
        (
            "excel-decimal-comma",
            |h| h.replace(',', ";"),
            |_, r| r.replace(',', ";").replace('.', ","),
        ),
        (
            "tabs",
            |h| h.replace(',', "\t"),
            |_, r| r.replace(',', "\t"),
        ),
    ];
    for (name, header, row) in dialects {
        let [h, l] = rewrite_pair(dir.as_ref(), [&high, &low], name, header, row);
        assert_ne!(
            std::fs::read_to_string(&h).unwrap(),
            std::fs::read_to_string(&high).unwrap(),
            "{name}: not rewritten"
        );
        assert_eq!(parameters(&h, &l), plain, "{name}");
    }
}

#[test]
fn a_decimal_comma_in_a_comma_separated_file_is_still_an_error_naming_the_line() {
    // With commas as delimiters, `1,5` is two fields: the row has one field too many.
    let dir = scratch("input-dialects-bad");
    let path = dir.as_ref().join("mixed.csv");
    let mut text = String::from("t,voltage,current,speed\n");
    for i in 0..50 {
        text.push_str(&format!("{},12,1,{}\n", i as f64 * 1e-3, i));
    }
    text.push_str("0,05,12,1,5\n");
    std::fs::write(&path, text).unwrap();
    let p = path.to_str().unwrap();
    let out = motorid(&["identify", "--high", p, "--low", p]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("mixed.csv:52: 5 fields where the header has 4"),
        "{}",
        stderr(&out)
    );
}

/// `--columns` gives a file's own names and, where its header has none, their units: a
/// record whose time is in ms and speed in rpm under bare names identifies as the SI file.
#[test]
fn columns_map_a_tools_own_names_and_units() {
    let dir = scratch("input-dialects-columns");
    let [high, low] = small_servo_steps(&dir, None);
    let plain = parameters(&high, &low);
    let rpm = 60.0 / std::f64::consts::TAU;
    let [h, l] = rewrite_pair(
        dir.as_ref(),
        [&high, &low],
        "tool",
        |_| "time_ms,u,i,speed_rpm,pos".to_string(),
        |_, r| {
            let v: Vec<f64> = r.split(',').map(|x| x.parse().unwrap()).collect();
            format!("{},{},{},{},{}", v[0] * 1e3, v[1], v[2], v[3] * rpm, v[4])
        },
    );
    let map = "t=time_ms[ms],voltage=u,current=i,speed=speed_rpm[rpm],position=pos";
    let out = motorid(&[
        "identify",
        "--high",
        &h,
        "--low",
        &l,
        "--columns",
        map,
        "--json",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let mapped: Value = serde_json::from_str(&stdout(&out)).unwrap();
    for name in ["R", "L", "k", "f", "J", "Ts"] {
        let (a, b) = (
            mapped["parameters"][name]["value"].as_f64().unwrap(),
            plain[name]["value"].as_f64().unwrap(),
        );
        // Unit conversions round the data at 1e-16: the fit moves far less than 1e-9.
        assert!((a / b - 1.0).abs() < 1e-9, "{name}: {a} against {b}");
    }
    // A unit that contradicts the file's own header is refused, naming both.
    let out = motorid(&[
        "identify",
        "--high",
        &high,
        "--low",
        &low,
        "--columns",
        "speed=speed[rpm]",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("--columns speed=speed[rpm]: the file's header gives `speed[rad/s]`"),
        "{}",
        stderr(&out)
    );
}

/// Time stamps as Unix time (seconds since 1970, to the microsecond), as loggers stamp them:
/// a double holds 1.7e9 s to 2.4e-7 s, a sizeable part of a 5 kHz period, and the grid was
/// refused as not uniform. The pair identifies as its twin stamped from 0, to far within the
/// intervals.
#[test]
fn unix_time_stamps_identify_as_stamps_from_zero() {
    let dir = scratch("input-dialects-unix");
    let [high, low] = small_servo_steps(&dir, None);
    let plain = parameters(&high, &low);
    let [h, l] = rewrite_pair(
        dir.as_ref(),
        [&high, &low],
        "unix",
        |h| h.to_string(),
        |_, r| {
            let (t, rest) = r.split_once(',').unwrap();
            let us = (t.parse::<f64>().unwrap() * 1e6).round() as u64;
            format!(
                "{}.{:06},{rest}",
                1_733_587_200 + us / 1_000_000,
                us % 1_000_000
            )
        },
    );
    let unix = parameters(&h, &l);
    for name in ["R", "L", "k", "f", "J", "Ts"] {
        let (a, b) = (
            unix[name]["value"].as_f64().unwrap(),
            plain[name]["value"].as_f64().unwrap(),
        );
        let ci = plain[name]["ci95"].as_array().unwrap();
        let half = (ci[1].as_f64().unwrap() - ci[0].as_f64().unwrap()) / 2.0;
        // The stamps' rounding (1.2e-7 s of 2e-4 s) moves the fit by about 1e-6 of a value,
        // a thousandth of its interval.
        assert!(
            (a - b).abs() < 1e-2 * half,
            "{name}: {a} against {b} (±{half})"
        );
    }
}
