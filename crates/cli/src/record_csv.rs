//! Records in the CSV contract of SPEC section 4: reading them with errors that name the file
//! and line, and writing them (through [`crate::output`]).

use std::io::Write;
use std::path::Path;

use anyhow::Result;
use motor_model::Record;

use crate::csv_table::{canonical, read_table, split_unit, Table};
use crate::errors::BadInput;
use crate::record_checks::{
    adc_lsb, check_isolated_outliers, check_unit_plausibility, check_within_rails, metadata_rails,
    metadata_says_no_adc, zero_rail_while_moving,
};

/// Which header names hold the record's columns (`t`, `voltage`, `current`, `speed`,
/// `position`), for files written by other tools: `--columns t=time_s,current=vir,...`.
#[derive(Debug, Clone, Default)]
pub struct ColumnMap {
    pairs: Vec<(String, String)>,
}

/// The record's own column names.
const COLUMNS: [&str; 5] = ["t", "voltage", "current", "speed", "position"];

impl ColumnMap {
    /// The `--columns` text that gives this map again (`name=header,...`), `None` for the
    /// record's own names.
    pub fn as_option(&self) -> Option<String> {
        (!self.pairs.is_empty()).then(|| {
            self.pairs
                .iter()
                .map(|(name, header)| format!("{name}={header}"))
                .collect::<Vec<_>>()
                .join(",")
        })
    }

    /// Parses `name=header,...`.
    pub fn parse(text: &str) -> Result<Self> {
        let mut pairs = Vec::new();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, header) = item.split_once('=').ok_or_else(|| {
                BadInput(format!(
                    "--columns: `{item}` is not of the form name=header, e.g. t=time_s"
                ))
            })?;
            let name = name.trim();
            if !COLUMNS.contains(&name) {
                return Err(BadInput(format!(
                    "--columns: unknown column `{name}`; the names are {}",
                    COLUMNS.join(", ")
                ))
                .into());
            }
            pairs.push((name.to_string(), header.trim().to_string()));
        }
        Ok(ColumnMap { pairs })
    }

    /// The header name of column `name`.
    fn header<'a>(&'a self, name: &'a str) -> &'a str {
        self.pairs
            .iter()
            .find(|(n, _)| n == name)
            .map_or(name, |(_, h)| h.as_str())
    }
}

/// Units a header may state in brackets, `speed[rpm]`, and their factor to SI.
fn unit_factor(column: &str, unit: &str) -> Option<f64> {
    use std::f64::consts::PI;
    let u = unit.trim();
    Some(match (column, u) {
        ("t", "s") => 1.0,
        ("t", "ms") => 1e-3,
        ("t", "us" | "µs") => 1e-6,
        ("voltage", "V") => 1.0,
        ("voltage", "mV") => 1e-3,
        ("current", "A") => 1.0,
        ("current", "mA") => 1e-3,
        ("speed", "rad/s") => 1.0,
        ("speed", "rpm" | "RPM" | "r/min") => 2.0 * PI / 60.0,
        ("speed", "deg/s") => PI / 180.0,
        ("speed", "rev/s" | "rps") => 2.0 * PI,
        ("speed", "m/s") => 1.0,
        ("speed", "mm/s") => 1e-3,
        ("position", "rad") => 1.0,
        ("position", "deg") => PI / 180.0,
        ("position", "rev") => 2.0 * PI,
        ("position", "m") => 1.0,
        ("position", "mm") => 1e-3,
        _ => return None,
    })
}

/// The units `unit_factor` knows for a column, for error messages.
fn known_units(column: &str) -> &'static str {
    match column {
        "t" => "s, ms, us",
        "voltage" => "V, mV",
        "current" => "A, mA",
        "speed" => "rad/s, rpm, deg/s, rev/s (m/s, mm/s for a linear axis)",
        _ => "rad, deg, rev (m, mm for a linear axis)",
    }
}

/// A record read from a file, with what the reader found out about it.
#[derive(Debug, Clone, Default)]
pub struct Loaded {
    /// The record in SI units (`clipped` counts the samples at a rail per channel).
    pub record: Record,
    /// 1-based line number of each sample.
    pub lines: Vec<usize>,
    /// Samples of voltage, current and speed at an ADC rail.
    pub clipped: [Vec<bool>; 3],
    /// One ADC step of the voltage channel \[V\], from the `# measurement:` metadata, if given;
    /// 0 where the metadata says the record was read without an ADC (its voltage is exact).
    pub voltage_lsb: Option<f64>,
    /// One ADC step of the current channel \[A\], likewise.
    pub current_lsb: Option<f64>,
    /// Current samples that read a rail at exactly 0 A, noisy about it, while the motor
    /// turns ([`zero_rail_while_moving`]): how many, and the first and last.
    pub current_on_zero_rail: Option<(usize, usize, usize)>,
}

impl Loaded {
    /// `"lines a–b"` for samples `from..to` of the record.
    pub fn line_span(&self, from: usize, to: usize) -> String {
        let a = self.lines.get(from).copied().unwrap_or(0);
        let b = self.lines.get(to.saturating_sub(1)).copied().unwrap_or(a);
        if a == b {
            format!("line {a}")
        } else {
            format!("lines {a}–{b}")
        }
    }

    /// The samples of each analog channel at an ADC rail, by channel.
    pub fn clipped_channels(&self) -> [(fit::RecordChannel, &[bool]); 3] {
        let [voltage, current, speed] = &self.clipped;
        [
            (fit::RecordChannel::Voltage, voltage),
            (fit::RecordChannel::Current, current),
            (fit::RecordChannel::Speed, speed),
        ]
    }

    /// The samples of `channel` at an ADC rail.
    pub fn clipped_mask(&self, channel: fit::RecordChannel) -> &[bool] {
        self.clipped_channels()
            .into_iter()
            .find_map(|(c, m)| (c == channel).then_some(m))
            .unwrap_or_default()
    }

    /// One line per clipped channel: how many samples, where, at which value.
    pub fn clipping_report(&self) -> Vec<String> {
        let names = ["voltage", "current", "speed"];
        let columns = [
            Some(&self.record.voltage),
            Some(&self.record.current),
            self.record.speed.as_ref(),
        ];
        let mut out = Vec::new();
        for (c, mask) in self.clipped.iter().enumerate() {
            let count = mask.iter().filter(|&&m| m).count();
            if count == 0 {
                continue;
            }
            let first = mask.iter().position(|&m| m).unwrap_or(0);
            let last = mask.iter().rposition(|&m| m).unwrap_or(first);
            let value = columns[c]
                .and_then(|col| col.get(first))
                .copied()
                .unwrap_or(f64::NAN);
            out.push(format!(
                "{count} {} samples ({:.1} %) sit on an ADC rail at {value} ({} to {})",
                names[c],
                100.0 * count as f64 / mask.len().max(1) as f64,
                self.line_span(first, first + 1),
                self.line_span(last, last + 1),
            ));
        }
        out
    }
}

/// Reads a record file whose columns `map` names; `voltage` may be absent when
/// `need_voltage` is false (a current-driven axis). With a map, unmapped columns are ignored.
pub fn read_mapped(path: &Path, map: &ColumnMap, need_voltage: bool) -> Result<Record> {
    Ok(read_loaded(path, map, need_voltage)?.record)
}

/// Reads a record file with its line numbers and the samples found at an ADC rail.
pub fn read_loaded(path: &Path, map: &ColumnMap, need_voltage: bool) -> Result<Loaded> {
    read_with(path, map, need_voltage, true)
}

/// [`read_loaded`] of a voltage-driven record whose current column may be absent (voltage and
/// speed only): `record.current` is then empty.
pub fn read_loaded_current_optional(path: &Path, map: &ColumnMap) -> Result<Loaded> {
    read_with(path, map, true, false)
}

fn read_with(
    path: &Path,
    map: &ColumnMap,
    need_voltage: bool,
    need_current: bool,
) -> Result<Loaded> {
    let table = read_table(path)?;
    to_record(table, map, need_voltage, need_current)
        .map_err(|(line, msg)| BadInput(format!("{}:{line}: {msg}", path.display())).into())
}

/// Moves file column `i` (if any) out of `table` as record column `name` in SI units, or
/// copies it where `shared(i)` (a map gives it to two record columns); an unknown unit is an
/// error on the header line.
fn take_column(
    table: &mut Table,
    i: Option<usize>,
    name: &str,
    shared: impl Fn(usize) -> bool,
) -> std::result::Result<Option<Vec<f64>>, (usize, String)> {
    let Some(i) = i else { return Ok(None) };
    let factor = match &table.units[i] {
        None => 1.0,
        Some(unit) => unit_factor(name, unit).ok_or_else(|| {
            (
                table.header_line,
                format!(
                    "column `{}[{unit}]`: unknown unit `{unit}` for {name}; known: {}",
                    table.names[i],
                    known_units(name)
                ),
            )
        })?,
    };
    let mut column = if shared(i) {
        table.columns[i].clone()
    } else {
        std::mem::take(&mut table.columns[i])
    };
    // Scaling by 1 changes no value: SI columns are kept as read.
    if factor != 1.0 {
        column.iter_mut().for_each(|v| *v *= factor);
    }
    Ok(Some(column))
}

/// Maps a table's columns to a record (SPEC section 4): names or aliases, units converted, `t`
/// strictly increasing, `current` required when `need_current` (else empty when absent),
/// `voltage` required when `need_voltage`; finds the samples at an ADC rail.
fn to_record(
    mut table: Table,
    map: &ColumnMap,
    need_voltage: bool,
    need_current: bool,
) -> std::result::Result<Loaded, (usize, String)> {
    let header_line = table.header_line;
    if map.pairs.is_empty() {
        if let Some(name) = table.names.iter().find(|n| canonical(n).is_none()) {
            return Err((header_line, format!("unknown column `{name}`: expected t, voltage, current and optionally speed, position (or map a file's own names with --columns)")));
        }
    }
    let find = |table: &Table, name: &str| -> Option<usize> {
        match map.pairs.iter().find(|(n, _)| n == name) {
            Some((_, header)) => table.index(&split_unit(header).0),
            None => table.names.iter().position(|n| canonical(n) == Some(name)),
        }
    };
    // A unit given with a mapped header (`--columns speed=speed_rpm[rpm]`) is that column's
    // unit when the file's header gives none; a different one is a contradiction.
    for (name, header) in &map.pairs {
        let (file_name, Some(unit)) = split_unit(header) else {
            continue;
        };
        let Some(i) = table.index(&file_name) else {
            continue;
        };
        match &table.units[i] {
            None => table.units[i] = Some(unit),
            Some(own) if own.eq_ignore_ascii_case(&unit) => {}
            Some(own) => {
                return Err((
                    header_line,
                    format!("--columns {name}={header}: the file's header gives `{file_name}[{own}]`; give the unit once"),
                ))
            }
        }
    }
    // Each file column goes to the record once, moved rather than copied, unless a map gives
    // it to two record columns.
    let sources: Vec<Option<usize>> = COLUMNS.iter().map(|name| find(&table, name)).collect();
    let get = |table: &mut Table, name: &str| {
        let i = COLUMNS
            .iter()
            .position(|c| *c == name)
            .and_then(|c| sources[c]);
        take_column(table, i, name, |i| {
            sources.iter().filter(|&&s| s == Some(i)).count() > 1
        })
    };
    let names = table.names.join(",");
    let required = |table: &mut Table, name: &str| {
        get(table, name)?.ok_or((
            header_line,
            format!(
                "no `{}` column in the header `{names}`: a record needs {} (map other names with --columns){}",
                map.header(name),
                match (need_voltage, need_current) {
                    (true, true) => "t, current, voltage",
                    (false, _) => "t, current",
                    (true, false) => "t, voltage and a current, speed or position",
                },
                if name == "current" && need_voltage && need_current {
                    "; without a current sensor, `identify --record FILE` fits voltage and speed alone (kS, kV, kA; J, f, Ts with --resistance and --torque-constant)"
                } else {
                    ""
                }
            ),
        ))
    };
    let t = required(&mut table, "t")?;
    for (i, w) in t.windows(2).enumerate() {
        if w[1] <= w[0] {
            let what = if w[1] == w[0] {
                "repeats"
            } else {
                "goes back to"
            };
            return Err((
                table.lines[i + 1],
                format!(
                    "t {what} {} s after t = {} s on the line before: time must increase strictly",
                    w[1], w[0]
                ),
            ));
        }
    }
    if t.len() < 2 {
        return Err((
            table.lines[0],
            "a single data row: a record needs many samples".into(),
        ));
    }
    let mut record = Record {
        current: if need_current {
            required(&mut table, "current")?
        } else {
            get(&mut table, "current")?.unwrap_or_default()
        },
        voltage: if need_voltage {
            required(&mut table, "voltage")?
        } else {
            get(&mut table, "voltage")?.unwrap_or_default()
        },
        speed: get(&mut table, "speed")?,
        position: get(&mut table, "position")?,
        t,
        clipped: [0; 3],
    };
    check_isolated_outliers(&table, &record)?;
    check_unit_plausibility(&table, &|name| find(&table, name), &record)?;
    let rails = metadata_rails(&table);
    check_within_rails(&table, &record, &rails)?;
    let no_adc = metadata_says_no_adc(&table);
    let masks: [Vec<bool>; 3] = std::array::from_fn(|c| {
        // With a position column the fits take the speed from the encoder (no ADC), so a
        // speed column beside it is not checked.
        let col = match c {
            0 => Some(&record.voltage),
            1 => Some(&record.current),
            _ => record.speed.as_ref().filter(|_| record.position.is_none()),
        };
        match col {
            Some(y) if !y.is_empty() && no_adc && rails[c].is_none() => vec![false; y.len()],
            Some(y) if !y.is_empty() => {
                let (r, tol) = rails[c].map_or((None, 0.0), |(r, tol)| (Some(r), tol));
                fit::find_clipping(y, r, tol)
            }
            _ => Vec::new(),
        }
    });
    for (c, m) in masks.iter().enumerate() {
        record.clipped[c] = m.iter().filter(|&&x| x).count();
    }
    let current_on_zero_rail =
        rails[1].and_then(|(r, tol)| zero_rail_while_moving(&record, r, tol));
    Ok(Loaded {
        record,
        current_on_zero_rail,
        clipped: masks,
        voltage_lsb: if metadata_says_no_adc(&table) {
            Some(0.0)
        } else {
            adc_lsb(&table, 0)
        },
        current_lsb: adc_lsb(&table, 1),
        lines: table.lines,
    })
}

/// Writes `record` as CSV with `#` metadata lines to `out`.
pub fn write_to(
    out: &mut impl Write,
    record: &Record,
    metadata: &[(String, String)],
) -> Result<()> {
    for (key, value) in metadata {
        writeln!(out, "# {key}: {value}")?;
    }
    // Units in the header: the record states them, so no reader has to guess.
    let mut header = String::from("t[s],voltage[V],current[A]");
    if record.speed.is_some() {
        header.push_str(",speed[rad/s]");
    }
    if record.position.is_some() {
        header.push_str(",position[rad]");
    }
    writeln!(out, "{header}")?;
    let mut line = String::with_capacity(96);
    for i in 0..record.t.len() {
        line.clear();
        // `{}` on f64 prints the shortest text that reads back to the same number.
        use std::fmt::Write as _;
        let _ = write!(
            line,
            "{},{},{}",
            record.t[i], record.voltage[i], record.current[i]
        );
        for column in [&record.speed, &record.position].into_iter().flatten() {
            let _ = write!(line, ",{}", column[i]);
        }
        writeln!(out, "{line}")?;
    }
    Ok(())
}

/// Writes `record` to `path`: a file replaced atomically, a device or FIFO streamed, `-`
/// standard output (see [`crate::output`]).
pub fn write_file(path: &Path, record: &Record, metadata: &[(String, String)]) -> Result<()> {
    crate::output::write_with(path, |mut out| write_to(&mut out, record, metadata))
}

/// [`write_file`] under a name the command made up inside an output folder: only a regular
/// file of that name is replaced ([`crate::output::write_generated`]).
pub fn write_generated_file(
    path: &Path,
    record: &Record,
    metadata: &[(String, String)],
) -> Result<()> {
    crate::output::write_generated_with(path, |mut out| write_to(&mut out, record, metadata))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csv_table::parse_bytes;
    use crate::csv_table::{parse_with, TableParser};
    use crate::record_checks::isolated_outlier;
    use proptest::prelude::*;

    fn record(text: &str) -> std::result::Result<Loaded, (usize, String)> {
        let table = parse_bytes(text.as_bytes())?;
        to_record(table, &ColumnMap::default(), true, true)
    }

    #[test]
    fn a_quoted_header_name_keeps_its_delimiter() {
        let t = parse_bytes(b"\"t[s]\",\"pos,x[rad]\"\n0,1\n0.001,2\n").unwrap();
        assert_eq!(t.names, ["t", "pos,x"]);
        assert_eq!(t.columns, [vec![0.0, 0.001], vec![1.0, 2.0]]);
    }

    #[test]
    fn every_dialect_reads_to_the_same_table() {
        let plain = parse_bytes(b"t[s],voltage[V]\n0,1.5\n0.001,2\n").unwrap();
        for text in [
            &b",t[s],voltage[V]\n0,0,1.5\n1,0.001,2\n"[..],
            b"\"t[s]\",\"voltage[V]\"\n0,1.5\n0.001,2\n",
            b"t[s];voltage[V]\n0;1,5\n0,001;2\n",
            b"\"t[s]\";\"voltage[V]\"\r\n0;\"1,5\"\r\n0,001;2\r\n",
            b"t[s]\tvoltage[V]\n0\t1.5\n0.001\t2\n",
            // A delimiter inside quotes belongs to its field.
            b"t[s];voltage[V]\n\"0\";\"1,5\"\n0,001;\"2\"\n",
        ] {
            let t = parse_bytes(text).unwrap();
            let shown = String::from_utf8_lossy(text);
            assert_eq!(
                (&t.names, &t.units),
                (&plain.names, &plain.units),
                "{shown}"
            );
            assert_eq!(t.columns, plain.columns, "{shown}");
            assert_eq!(t.lines, plain.lines, "{shown}");
        }
    }

    #[test]
    fn units_in_the_header_are_converted_to_si() {
        let loaded = record(
            "# a comment\nt[ms],voltage[mV],current[mA],speed[rpm],position[deg]\n0,0,0,0,0\n1,40000,1500,60,180\n2,40000,1500,60,360\n",
        )
        .unwrap();
        let r = loaded.record;
        assert_eq!(r.t, [0.0, 1e-3, 2e-3]);
        assert_eq!(r.voltage[1], 40.0);
        assert_eq!(r.current[1], 1.5);
        assert!((r.speed.unwrap()[1] - std::f64::consts::TAU).abs() < 1e-12);
        assert!((r.position.unwrap()[2] - std::f64::consts::TAU).abs() < 1e-12);
        assert_eq!(loaded.lines, [3, 4, 5]);
    }

    #[test]
    fn aliases_name_the_columns_and_clashes_are_refused() {
        let r = record("Time,U,I,Omega\n0,1,2,3\n0.001,1,2,3\n")
            .unwrap()
            .record;
        assert_eq!((r.t[1], r.voltage[0], r.current[0]), (0.001, 1.0, 2.0));
        assert_eq!(r.speed.unwrap()[0], 3.0);
        let e = record("t,time,voltage,current\n0,0,1,2\n").unwrap_err();
        assert_eq!(e.0, 1);
        assert!(e.1.contains("both give t"), "{}", e.1);
        let e = record("t,voltage,current[furlong]\n0,1,2\n1,1,2\n").unwrap_err();
        assert!(
            e.1.contains("unknown unit `furlong` for current"),
            "{}",
            e.1
        );
    }

    #[test]
    fn unit_less_columns_in_ms_or_ma_are_refused() {
        let e = record("t,voltage,current\n0,40,0\n1,40,1\n2,40,2\n").unwrap_err();
        assert!(e.1.contains("t[ms]"), "{}", e.1);
        assert!(record("t[s],voltage,current\n0,40,0\n1,40,1\n2,40,2\n").is_ok());
        let e = record("t,voltage,current\n0,40,0\n0.001,40,53570\n").unwrap_err();
        assert!(e.1.contains("current[mA]"), "{}", e.1);
        let r = record("t,voltage,current[mA]\n0,40,0\n0.001,40,53570\n").unwrap();
        assert_eq!(r.record.current[1], 53.57);
    }

    #[test]
    fn one_sample_far_beyond_the_rest_of_its_column_is_an_outlier() {
        let mut y: Vec<f64> = (0..100).map(|i| 1.0 + 0.01 * f64::from(i % 7)).collect();
        assert_eq!(isolated_outlier(&y), None);
        y[40] = 1e6;
        assert_eq!(isolated_outlier(&y), Some(40));
        y[40] = -1e300;
        assert_eq!(isolated_outlier(&y), Some(40));
        // A first sample before the step, a column that does not vary: not judged.
        y[40] = 1.0;
        y[0] = 0.0;
        assert_eq!(isolated_outlier(&y), None);
        assert_eq!(isolated_outlier(&[0.0, 0.0, 5.0, 0.0]), None);
    }

    #[test]
    fn metadata_rails_mark_clipped_samples() {
        let mut text = String::from("# range_current: -10,10\nt,voltage,current\n");
        for i in 0..100 {
            let c = if (40..50).contains(&i) { 10.0 } else { 1.0 };
            text.push_str(&format!("{},{},{}\n", f64::from(i) * 1e-3, 5, c));
        }
        let loaded = record(&text).unwrap();
        assert_eq!(loaded.record.clipped, [0, 10, 0]);
        let report = loaded.clipping_report();
        assert!(report[0].contains("10 current samples"), "{report:?}");
        assert!(report[0].contains("line 43"), "{report:?}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// The reader never panics, whatever the bytes: it returns a table or a line-numbered
        /// error.
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            if let Ok(table) = parse_bytes(&bytes) {
                let _ = to_record(table, &ColumnMap::default(), true, true);
            } else if let Err((line, msg)) = parse_bytes(&bytes) {
                prop_assert!(line >= 1);
                prop_assert!(!msg.is_empty() && !msg.contains('\n'));
            }
        }

        /// Rows read from the bytes give the same table, or the same error, as rows read as
        /// text, whatever the fields, line breaks and buffer boundaries.
        #[test]
        fn rows_from_bytes_read_as_text_does(
            rows in proptest::collection::vec(
                proptest::collection::vec(
                    prop_oneof![
                        Just("0".to_string()), Just("-1.5e-3".to_string()), Just(" 2 ".to_string()),
                        Just("NaN".to_string()), Just("inf".to_string()), Just("".to_string()),
                        Just("\u{a0}1".to_string()), Just("1\r".to_string()), Just("#".to_string()),
                        Just("\0".to_string()), Just("\u{b}3".to_string()),
                        "[0-9.eE+-]{1,8}",
                    ],
                    0..5,
                ),
                0..12,
            ),
            crlf in any::<bool>(),
            buffer in 1usize..64,
            delimiter in prop_oneof![Just(","), Just(";"), Just("\t")],
            index in any::<bool>(),
        ) {
            // Every dialect: the delimiter, and an unnamed index column (pandas) or not.
            let sep = if crlf { "\r\n" } else { "\n" };
            let lead = |i: Option<usize>| match (index, i) {
                (false, _) => String::new(),
                (true, None) => delimiter.to_string(),
                (true, Some(i)) => format!("{i}{delimiter}"),
            };
            let text: String = std::iter::once(lead(None) + &["t", "voltage", "current"].join(delimiter))
                .chain(rows.iter().enumerate().map(|(i, r)| lead(Some(i)) + &r.join(delimiter)))
                .map(|line| line + sep)
                .collect();
            let fast = parse_with(
                &mut std::io::BufReader::with_capacity(buffer, text.as_bytes()),
                TableParser::new(text.len()),
            );
            let mut as_text = TableParser::new(0);
            as_text.rows_from_bytes = false;
            let slow = parse_with(&mut text.as_bytes(), as_text);
            match (fast, slow) {
                (Ok(a), Ok(b)) => {
                    prop_assert_eq!(&a.lines, &b.lines);
                    let bits = |t: &Table| -> Vec<Vec<u64>> {
                        t.columns.iter().map(|c| c.iter().map(|v| v.to_bits()).collect()).collect()
                    };
                    prop_assert_eq!(bits(&a), bits(&b));
                }
                (a, b) => prop_assert_eq!(a.err(), b.err()),
            }
        }

        /// Nor does text that looks almost like a record.
        #[test]
        fn near_records_never_panic(
            rows in proptest::collection::vec(
                proptest::collection::vec(
                    prop_oneof![
                        Just("0".to_string()), Just("1e3".to_string()), Just("-".to_string()),
                        Just("NaN".to_string()), Just("inf".to_string()), Just("".to_string()),
                        Just("t".to_string()), Just("current[mA]".to_string()), Just("#".to_string()),
                        "[0-9.eE+-]{1,8}",
                    ],
                    0..6,
                ),
                0..12,
            ),
            crlf in any::<bool>(),
        ) {
            let sep = if crlf { "\r\n" } else { "\n" };
            let text: String = std::iter::once("t,voltage,current".to_string())
                .chain(rows.iter().map(|r| r.join(",")))
                .collect::<Vec<_>>()
                .join(sep);
            if let Ok(table) = parse_bytes(text.as_bytes()) {
                let _ = to_record(table, &ColumnMap::default(), true, true);
            }
        }
    }
}
