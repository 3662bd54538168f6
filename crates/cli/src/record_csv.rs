//! Records in the CSV contract of SPEC section 4: reading them with errors that name the file
//! and line, and writing them atomically.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use motor_model::Record;

use crate::BadInput;

/// Which header names hold the record's columns (`t`, `voltage`, `current`, `speed`,
/// `position`), for files written by other tools: `--columns t=time_s,current=vir,...`.
#[derive(Debug, Clone, Default)]
pub struct ColumnMap {
    pairs: Vec<(String, String)>,
}

/// The record's own column names.
const COLUMNS: [&str; 5] = ["t", "voltage", "current", "speed", "position"];

impl ColumnMap {
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

/// Reads a record file. Every problem is a [`BadInput`] naming the file, the line and the value.
pub fn read_file(path: &Path) -> Result<Record> {
    read_mapped(path, &ColumnMap::default(), true)
}

/// Reads a record file whose columns `map` names; `voltage` may be absent when
/// `need_voltage` is false (a current-driven axis). With a map, unmapped columns are ignored.
pub fn read_mapped(path: &Path, map: &ColumnMap, need_voltage: bool) -> Result<Record> {
    let shown = path.display();
    let bytes = std::fs::read(path).map_err(|e| BadInput(format!("{shown}: cannot read ({e})")))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        BadInput(format!(
            "{shown}: not UTF-8 text (invalid byte at offset {}): is this a CSV record?",
            e.utf8_error().valid_up_to()
        ))
    })?;
    parse(&text, map, need_voltage)
        .map_err(|(line, msg)| BadInput(format!("{shown}:{line}: {msg}")).into())
}

/// Parses record text; errors carry the 1-based line number.
fn parse(
    text: &str,
    map: &ColumnMap,
    need_voltage: bool,
) -> std::result::Result<Record, (usize, String)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let (header_line, header) = lines
        .by_ref()
        .find(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'))
        .ok_or((
            1,
            "no header row: expected a line such as t,voltage,current,speed,position".to_string(),
        ))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| names.iter().position(|n| *n == map.header(name));
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err((
                header_line,
                format!("column `{name}` appears twice in the header"),
            ));
        }
        if map.pairs.is_empty() && !COLUMNS.contains(name) {
            return Err((header_line, format!("unknown column `{name}`: expected t, voltage, current and optionally speed, position (or map a file's own names with --columns)")));
        }
    }
    let required = |name: &str| {
        find(name).ok_or((
            header_line,
            format!(
                "no `{}` column in the header `{header}`: a record needs t, current{} (map other names with --columns)",
                map.header(name),
                if need_voltage { ", voltage" } else { "" }
            ),
        ))
    };
    let (it, ic) = (required("t")?, required("current")?);
    let iv = if need_voltage {
        Some(required("voltage")?)
    } else {
        find("voltage")
    };
    let (is, ip) = (find("speed"), find("position"));
    let mut cols = Record {
        speed: is.map(|_| Vec::new()),
        position: ip.map(|_| Vec::new()),
        ..Record::default()
    };
    let mut values = Vec::with_capacity(names.len());
    let mut last_t = f64::NEG_INFINITY;
    for (line_no, line) in lines {
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        values.clear();
        for (k, field) in line.split(',').enumerate() {
            let name = names.get(k).ok_or((
                line_no,
                format!(
                    "{} fields where the header has {}",
                    line.split(',').count(),
                    names.len()
                ),
            ))?;
            let v: f64 = field.trim().parse().map_err(|_| {
                (
                    line_no,
                    format!("column `{name}`: `{}` is not a number", field.trim()),
                )
            })?;
            if !v.is_finite() {
                return Err((
                    line_no,
                    format!("column `{name}` is {v}: every value must be finite"),
                ));
            }
            values.push(v);
        }
        if values.len() != names.len() {
            return Err((
                line_no,
                format!(
                    "{} fields where the header has {} (a line cut short?)",
                    values.len(),
                    names.len()
                ),
            ));
        }
        if values[it] <= last_t {
            return Err((line_no, format!("t = {} s does not come after the previous t = {last_t} s: time must increase strictly", values[it])));
        }
        last_t = values[it];
        cols.t.push(values[it]);
        if let Some(i) = iv {
            cols.voltage.push(values[i]);
        }
        cols.current.push(values[ic]);
        if let (Some(i), Some(c)) = (is, cols.speed.as_mut()) {
            c.push(values[i]);
        }
        if let (Some(i), Some(c)) = (ip, cols.position.as_mut()) {
            c.push(values[i]);
        }
    }
    if cols.t.is_empty() {
        return Err((header_line, "no data rows after the header".into()));
    }
    Ok(cols)
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
    let mut header = String::from("t,voltage,current");
    if record.speed.is_some() {
        header.push_str(",speed");
    }
    if record.position.is_some() {
        header.push_str(",position");
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

/// Writes `record` to `path` atomically: a temporary file beside it, flushed and synced, then
/// renamed over `path`. A failure never leaves a half-written record under `path`.
pub fn write_file(path: &Path, record: &Record, metadata: &[(String, String)]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file name", path.display()))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    let tmp: PathBuf = dir.join(tmp_name);
    let result = (|| -> Result<()> {
        let file = File::create(&tmp)?;
        let mut w = BufWriter::new(file);
        write_to(&mut w, record, metadata)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("cannot write {}", path.display()))
}
