//! Records in the CSV contract of SPEC section 4: reading them with errors that name the file
//! and line, and writing them atomically.

use std::fs::File;
use std::io::Write;
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
    let table = read_table(path)?;
    to_record(&table, map, need_voltage)
        .map_err(|(line, msg)| BadInput(format!("{}:{line}: {msg}", path.display())).into())
}

/// A CSV file's numeric columns by header name, with the line number of every row.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Header names, in file order.
    pub names: Vec<String>,
    /// One vector per header name.
    pub columns: Vec<Vec<f64>>,
    /// 1-based line number of each row.
    pub lines: Vec<usize>,
    /// Line number of the header.
    pub header_line: usize,
}

impl Table {
    /// The column named `name`, if any.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }
}

/// Parses CSV text: `#` lines and blank lines skipped, one header row, numeric fields;
/// errors carry the 1-based line number.
fn parse_table(text: &str) -> std::result::Result<Table, (usize, String)> {
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
    let names: Vec<String> = header.split(',').map(|n| n.trim().to_string()).collect();
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err((
                header_line,
                format!("column `{name}` appears twice in the header"),
            ));
        }
    }
    let mut table = Table {
        columns: vec![Vec::new(); names.len()],
        names,
        lines: Vec::new(),
        header_line,
    };
    for (line_no, line) in lines {
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != table.names.len() {
            return Err((
                line_no,
                format!(
                    "{} fields where the header has {} (a line cut short?)",
                    fields.len(),
                    table.names.len()
                ),
            ));
        }
        for (k, field) in fields.iter().enumerate() {
            let name = &table.names[k];
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
            table.columns[k].push(v);
        }
        table.lines.push(line_no);
    }
    if table.lines.is_empty() {
        return Err((header_line, "no data rows after the header".into()));
    }
    Ok(table)
}

/// Reads a CSV file as a [`Table`]; every problem is a [`BadInput`] naming file and line.
pub fn read_table(path: &Path) -> Result<Table> {
    let shown = path.display();
    let bytes = std::fs::read(path).map_err(|e| BadInput(format!("{shown}: cannot read ({e})")))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        BadInput(format!(
            "{shown}: not UTF-8 text (invalid byte at offset {}): is this a CSV file?",
            e.utf8_error().valid_up_to()
        ))
    })?;
    parse_table(&text).map_err(|(line, msg)| BadInput(format!("{shown}:{line}: {msg}")).into())
}

/// Maps a table's columns to a record (SPEC section 4): `t` strictly increasing, `current`
/// required, `voltage` required when `need_voltage`.
fn to_record(
    table: &Table,
    map: &ColumnMap,
    need_voltage: bool,
) -> std::result::Result<Record, (usize, String)> {
    let header_line = table.header_line;
    if map.pairs.is_empty() {
        if let Some(name) = table.names.iter().find(|n| !COLUMNS.contains(&n.as_str())) {
            return Err((header_line, format!("unknown column `{name}`: expected t, voltage, current and optionally speed, position (or map a file's own names with --columns)")));
        }
    }
    let get = |name: &str| table.column(map.header(name)).map(<[f64]>::to_vec);
    let required = |name: &str| {
        get(name).ok_or((
            header_line,
            format!(
                "no `{}` column in the header `{}`: a record needs t, current{} (map other names with --columns)",
                map.header(name),
                table.names.join(","),
                if need_voltage { ", voltage" } else { "" }
            ),
        ))
    };
    let t = required("t")?;
    for (i, w) in t.windows(2).enumerate() {
        if w[1] <= w[0] {
            return Err((table.lines[i + 1], format!("t = {} s does not come after the previous t = {} s: time must increase strictly", w[1], w[0])));
        }
    }
    Ok(Record {
        current: required("current")?,
        voltage: if need_voltage {
            required("voltage")?
        } else {
            get("voltage").unwrap_or_default()
        },
        speed: get("speed"),
        position: get("position"),
        t,
        clipped: [0; 3],
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

/// Writes `record` to `path` atomically (see [`write_atomically`]).
pub fn write_file(path: &Path, record: &Record, metadata: &[(String, String)]) -> Result<()> {
    let mut bytes = Vec::new();
    write_to(&mut bytes, record, metadata)?;
    write_atomically(path, &bytes)
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, flushed and synced, then
/// renamed over `path`. A failure never leaves a half-written file under `path`.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
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
        let mut file = File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("cannot write {}", path.display()))
}
