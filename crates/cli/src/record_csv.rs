//! Records in the CSV contract of SPEC section 4: reading them with errors that name the file
//! and line, and writing them (through [`crate::output`]).

use std::io::{BufRead, Write};
use std::path::Path;

use anyhow::Result;
use motor_model::Record;

use crate::errors::BadInput;

/// The `measurement` metadata of a record simulated without ADC, noise or encoder.
pub const IDEAL_MEASUREMENT: &str = "ideal (exact values)";

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

/// Other names accepted for each record column (case-insensitive).
const ALIASES: [(&str, &[&str]); 5] = [
    ("t", &["time", "time_s", "t_s", "seconds"]),
    (
        "voltage",
        &["v", "u", "e", "volt", "volts", "armature_voltage"],
    ),
    ("current", &["i", "ia", "amps", "armature_current"]),
    ("speed", &["w", "omega", "velocity", "vel", "tach", "tacho"]),
    ("position", &["theta", "angle", "pos", "q", "encoder"]),
];

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

/// Which record column a header name (unit stripped) stands for, by name or alias.
fn canonical(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    ALIASES
        .iter()
        .find(|(c, aliases)| *c == lower || aliases.contains(&lower.as_str()))
        .map(|(c, _)| *c)
}

/// Splits `name[unit]` or `name (unit)` into the name and the unit.
fn split_unit(header: &str) -> (String, Option<String>) {
    let h = header.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let (Some(a), true) = (h.find(open), h.ends_with(close)) {
            let name = h[..a].trim().to_string();
            let unit = h[a + open.len_utf8()..h.len() - close.len_utf8()].trim();
            return (name, Some(unit.to_string()));
        }
    }
    (h.to_string(), None)
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

/// A CSV file's numeric columns by header name, with the line number of every row.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Header names as written, without a bracketed unit, in file order.
    pub names: Vec<String>,
    /// The unit each header states in brackets, if any.
    pub units: Vec<Option<String>>,
    /// One vector per header name, as written in the file (no unit conversion).
    pub columns: Vec<Vec<f64>>,
    /// 1-based line number of each row.
    pub lines: Vec<usize>,
    /// Line number of the header.
    pub header_line: usize,
    /// `# key: value` lines before the header.
    pub metadata: Vec<(String, String)>,
}

impl Table {
    /// The column named `name` (case-insensitive, unit ignored), if any.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.index(name).map(|i| self.columns[i].as_slice())
    }

    fn index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n.eq_ignore_ascii_case(name))
    }

    /// The value of metadata `key`, if given.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v.as_str())
    }
}

/// Longest line the reader accepts \[bytes\]: a CSV row of a record is far shorter.
const MAX_LINE_BYTES: usize = 64 * 1024;

/// Most rows the reader reserves room for before it has seen them (beyond, the columns grow
/// as they fill): 16 M rows of 8-byte values.
const MAX_RESERVED_ROWS: usize = 1 << 24;

/// Fewest rows in the reader's buffer from which [`TableParser::reserve_rows`] takes their
/// mean length.
const MIN_SAMPLED_ROWS: usize = 64;

/// Whether `b` is ASCII white space as [`str::trim`] sees it (`char::is_whitespace`: tab, line
/// feed, vertical tab, form feed, carriage return, space).
fn is_space(b: u8) -> bool {
    matches!(b, b'\t'..=b'\r' | b' ')
}

/// `bytes` from the first byte that is not white space ([`is_space`]) on.
fn skip_space(bytes: &[u8]) -> &[u8] {
    let start = bytes
        .iter()
        .position(|&b| !is_space(b))
        .unwrap_or(bytes.len());
    &bytes[start..]
}

/// The table being read, line by line, with the state the checks across lines need.
struct TableParser {
    table: Table,
    /// 1-based number of the last line seen.
    line_no: usize,
    /// Whether the last line seen ended with a line break.
    saw_newline: bool,
    /// Length of the input \[bytes\] if known: room for its rows is reserved from the first one.
    size_hint: usize,
    /// Whether data rows of plain numbers are read from the bytes ([`TableParser::numeric_row`]);
    /// without, every line takes [`TableParser::text_line`] (the tests compare the two).
    rows_from_bytes: bool,
}

impl TableParser {
    /// A parser for an input of `size_hint` bytes (0 if unknown).
    fn new(size_hint: usize) -> Self {
        TableParser {
            table: Table::default(),
            line_no: 0,
            saw_newline: true,
            size_hint,
            rows_from_bytes: true,
        }
    }

    /// The error for a line longer than [`MAX_LINE_BYTES`] (the line after the last one seen).
    fn too_long(&mut self) -> (usize, String) {
        self.line_no += 1;
        (
            self.line_no,
            format!(
                "longer than {} KiB without a line break: not a CSV record",
                MAX_LINE_BYTES / 1024
            ),
        )
    }

    /// Reads one line (without its line break; `newline` whether it had one); `ahead` is the
    /// input from the line's start to the end of the reader's buffer (for [`Self::reserve_rows`]).
    fn line(
        &mut self,
        bytes: &[u8],
        newline: bool,
        ahead: &[u8],
    ) -> std::result::Result<(), (usize, String)> {
        if bytes.len() > MAX_LINE_BYTES {
            return Err(self.too_long());
        }
        self.line_no += 1;
        // A data row of plain numbers is read straight from the bytes; anything else (a
        // comment, a blank line, a field that is not a finite number, a count of fields other
        // than the header's) takes the checks of `text_line`, which give every message.
        if self.rows_from_bytes && !self.table.names.is_empty() && self.numeric_row(bytes, ahead) {
            self.saw_newline = newline;
            return Ok(());
        }
        self.text_line(bytes, newline)
    }

    /// Appends `bytes` as a data row if it is exactly as many finite numbers as the header has
    /// names, separated by commas (white space around them allowed); otherwise leaves the
    /// table as it was and returns false. One pass over the bytes: `fast_float2` reads each
    /// number where it starts and says where it ends; it reads the decimal grammar of
    /// [`str::parse`] (both correctly rounded), so a field it reads whole is a field the text
    /// path reads, to the same value.
    fn numeric_row(&mut self, bytes: &[u8], ahead: &[u8]) -> bool {
        if self.table.lines.is_empty() {
            self.reserve_rows(bytes.len(), ahead);
        }
        let columns = &mut self.table.columns;
        let mut rest = bytes;
        let mut pushed = 0;
        let complete = loop {
            let Some(column) = columns.get_mut(pushed) else {
                break false;
            };
            let field = skip_space(rest);
            let Ok((v, used)) = fast_float2::parse_partial::<f64, _>(field) else {
                break false;
            };
            if !v.is_finite() {
                break false;
            }
            column.push(v);
            pushed += 1;
            match skip_space(&field[used..]).split_first() {
                None => break pushed == columns.len(),
                Some((b',', tail)) => rest = tail,
                Some(_) => break false,
            }
        };
        if !complete {
            for column in &mut columns[..pushed] {
                column.pop();
            }
            return false;
        }
        self.table.lines.push(self.line_no);
        true
    }

    /// Reserves room for the rows of the input: one allocation per column instead of a
    /// doubling series of copies. The count is estimated from the mean length of the rows in
    /// `ahead` (the input from the first row to the end of the reader's buffer) plus 1/64,
    /// else, with fewer than [`MIN_SAMPLED_ROWS`] rows there, from the length of the first
    /// row (later rows are rarely shorter than the first, at rest). Room reserved and never
    /// written costs little, but not nothing: an allocator that backs large blocks with huge
    /// pages clears every huge page a block starts, written or not.
    fn reserve_rows(&mut self, first_row_bytes: usize, ahead: &[u8]) {
        let span = memchr::memrchr(b'\n', ahead).map_or(0, |i| i + 1);
        let breaks = memchr::memchr_iter(b'\n', &ahead[..span]).count();
        let rows = if breaks >= MIN_SAMPLED_ROWS {
            let rows = self.size_hint / (span / breaks);
            rows + rows / 64 + 16
        } else {
            self.size_hint / (first_row_bytes + 1) + 16
        }
        .min(MAX_RESERVED_ROWS);
        for column in &mut self.table.columns {
            column.reserve(rows);
        }
        self.table.lines.reserve(rows);
    }

    /// Reads one line as text: the checks and messages of every kind of line.
    fn text_line(
        &mut self,
        bytes: &[u8],
        newline: bool,
    ) -> std::result::Result<(), (usize, String)> {
        let line_no = self.line_no;
        if let Some(i) = bytes.iter().position(|&b| b == 0) {
            return Err((
                line_no,
                format!(
                    "NUL byte at column {}: binary data, not a CSV record",
                    i + 1
                ),
            ));
        }
        let mut text = std::str::from_utf8(bytes).map_err(|e| {
            (
                line_no,
                format!(
                    "not UTF-8 text (invalid byte at column {}): is this a CSV file?",
                    e.valid_up_to() + 1
                ),
            )
        })?;
        if line_no == 1 {
            text = text.strip_prefix('\u{feff}').unwrap_or(text);
        }
        let line = text.trim_end_matches('\r');
        self.saw_newline = newline;
        let table = &mut self.table;
        if line.trim().is_empty() {
            return Ok(());
        }
        if let Some(comment) = line.strip_prefix('#') {
            if table.names.is_empty() {
                if let Some((k, v)) = comment.split_once(':') {
                    table
                        .metadata
                        .push((k.trim().to_string(), v.trim().to_string()));
                }
            }
            return Ok(());
        }
        if table.names.is_empty() {
            return parse_header(table, line, line_no);
        }
        let width = table.names.len();
        let mut count = 0usize;
        for field in line.split(',') {
            let Some(name) = table.names.get(count) else {
                count += 1;
                break;
            };
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
            table.columns[count].push(v);
            count += 1;
        }
        if count != width {
            let (fields, hint) = if count > width {
                (
                    line.split(',').count(),
                    "a stray comma, or lines of two files run together?",
                )
            } else {
                (count, "a line cut short?")
            };
            return Err((
                line_no,
                format!("{fields} fields where the header has {width} ({hint})"),
            ));
        }
        table.lines.push(line_no);
        Ok(())
    }

    /// The checks once the input has ended.
    fn finish(self) -> std::result::Result<Table, (usize, String)> {
        let TableParser {
            table,
            line_no,
            saw_newline,
            ..
        } = self;
        if table.names.is_empty() {
            return Err((
                line_no.max(1),
                "no header row (empty file?): expected a line such as t,voltage,current,speed,position"
                    .to_string(),
            ));
        }
        if !saw_newline && table.lines.last() == Some(&line_no) && table.lines.len() > 1 {
            // The last row has no line break: a file cut while being written may have lost digits.
            return Err((line_no, "the last line has no line break: the file may have been cut while being written (remove the line if it is complete)".into()));
        }
        if table.lines.is_empty() {
            return Err((table.header_line, "no data rows after the header".into()));
        }
        Ok(table)
    }
}

/// Parses CSV from `reader` (`size_hint` its length in bytes, if known, else 0): `#` lines and
/// blank lines skipped (`# key: value` kept as metadata), one header row, numeric fields;
/// errors carry the 1-based line number. Stops at the first bad line, so a large file of
/// garbage costs one line. Lines are read where they lie in the reader's buffer; only a line
/// across two buffer fills is copied.
fn parse_table(
    reader: &mut impl BufRead,
    size_hint: usize,
) -> std::result::Result<Table, (usize, String)> {
    parse_with(reader, TableParser::new(size_hint))
}

/// [`parse_table`] through `parser`.
fn parse_with(
    reader: &mut impl BufRead,
    mut parser: TableParser,
) -> std::result::Result<Table, (usize, String)> {
    // The start of a line whose end is in the next buffer fill.
    let mut partial: Vec<u8> = Vec::new();
    loop {
        let chunk = reader
            .fill_buf()
            .map_err(|e| (parser.line_no + 1, format!("read error ({e})")))?;
        if chunk.is_empty() {
            break;
        }
        let filled = chunk.len();
        let mut rest = chunk;
        while let Some(i) = memchr::memchr(b'\n', rest) {
            if partial.is_empty() {
                parser.line(&rest[..i], true, rest)?;
            } else {
                partial.extend_from_slice(&rest[..i]);
                parser.line(&partial, true, &partial)?;
                partial.clear();
            }
            rest = &rest[i + 1..];
        }
        if partial.len() + rest.len() > MAX_LINE_BYTES {
            return Err(parser.too_long());
        }
        partial.extend_from_slice(rest);
        reader.consume(filled);
    }
    if !partial.is_empty() {
        parser.line(&partial, false, &partial)?;
    }
    parser.finish()
}

/// Reads the header row into `table`.
fn parse_header(
    table: &mut Table,
    line: &str,
    line_no: usize,
) -> std::result::Result<(), (usize, String)> {
    if !line.contains(',') {
        for (sep, name) in [(';', "semicolons"), ('\t', "tabs"), ('|', "bars")] {
            if line.contains(sep) {
                return Err((line_no, format!("the header is separated by {name}: records are comma-separated (e.g. tr '{}' ',' < in > out)", if sep == '\t' { "\\t".to_string() } else { sep.to_string() })));
            }
        }
    }
    table.header_line = line_no;
    for raw in line.split(',') {
        let (name, unit) = split_unit(raw);
        if name.is_empty() {
            return Err((
                line_no,
                format!("an empty column name in the header `{line}`"),
            ));
        }
        if name.parse::<f64>().is_ok() {
            return Err((line_no, format!("the first row `{line}` is numbers, not a header: add a header such as t,voltage,current,speed")));
        }
        let clash = table.names.iter().position(|n| {
            n.eq_ignore_ascii_case(&name)
                || canonical(n).is_some_and(|c| Some(c) == canonical(&name))
        });
        if let Some(j) = clash {
            return Err((
                line_no,
                format!(
                    "columns `{}` and `{}` both give {}: keep one",
                    table.names[j],
                    name,
                    canonical(&name).unwrap_or(&name)
                ),
            ));
        }
        table.names.push(name);
        table.units.push(unit);
        table.columns.push(Vec::new());
    }
    Ok(())
}

/// Reads a CSV file as a [`Table`]; every problem is a [`BadInput`] naming file and line.
pub fn read_table(path: &Path) -> Result<Table> {
    let shown = path.display();
    let file = crate::fifo::open_read(path)
        .map_err(|e| BadInput(format!("{shown}: cannot read ({e})")))?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        return Err(BadInput(format!("{shown}: a directory, not a record file")).into());
    }
    let size = file.metadata().map_or(0, |m| m.len());
    let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
    parse_table(&mut reader, usize::try_from(size).unwrap_or(0))
        .map_err(|(line, msg)| BadInput(format!("{shown}:{line}: {msg}")).into())
}

/// Parses CSV bytes as a [`Table`] (the reader behind [`read_table`]); errors are `(line, message)`.
#[cfg(test)]
fn parse_bytes(bytes: &[u8]) -> std::result::Result<Table, (usize, String)> {
    parse_table(&mut &bytes[..], bytes.len())
}

/// The conditioning ranges `[lo, hi]` of voltage, current and speed stated in the metadata, with
/// half an ADC step as tolerance: `# measurement:` as `motorid simulate` writes it, or
/// `# range_voltage: LO,HI` (likewise `range_current`, `range_speed`).
/// Whether the record's metadata says it was measured without an ADC (`motorid simulate`'s
/// ideal records, or a measurement model with no ADC): nothing in it can sit on a rail. Its
/// steady values are then exact and repeat for as long as they hold — a current settled at
/// E/R for the last quarter of a record looked clipped, and a step below breakaway was
/// refused as "25 % of the current on an ADC rail".
fn metadata_says_no_adc(table: &Table) -> bool {
    table.meta("measurement").is_some_and(|text| {
        text == crate::record_csv::IDEAL_MEASUREMENT
            || serde_json::from_str::<motor_model::MeasurementModel>(text)
                .is_ok_and(|m| m.adc.is_none())
    })
}

fn metadata_rails(table: &Table) -> [Option<([f64; 2], f64)>; 3] {
    let mut out = [None; 3];
    if let Some(m) = table
        .meta("measurement")
        .and_then(|text| serde_json::from_str::<motor_model::MeasurementModel>(text).ok())
    {
        if let Some(adc) = m.adc {
            for (c, range) in m.ranges.iter().enumerate() {
                if let Some(r) = range {
                    out[c] = Some(([r.lo, r.hi], 0.5 * adc.lsb(*r)));
                }
            }
        }
    }
    for (c, key) in ["range_voltage", "range_current", "range_speed"]
        .iter()
        .enumerate()
    {
        if let Some(text) = table.meta(key) {
            if let Ok((lo, hi)) = crate::settings::pair(key, text) {
                out[c] = Some(([lo, hi], 1e-9 * (hi - lo).abs()));
            }
        }
    }
    out
}

/// A sample period at least this long \[s\] on a column `t` without a unit is taken for a
/// time column in ms: a motor record sampled below 100 Hz is rare (the electrical transient of
/// a servomotor is over in milliseconds), while any logger up to 100 kHz whose times are in ms
/// gives periods of 0.01 or more. Such a record is refused with the advice to state the unit,
/// `t[ms]`, or `t[s]` to confirm seconds; `motorid` writes its records with units.
const MAX_PLAIN_PERIOD_S: f64 = 0.01;
/// A peak voltage × peak current above this \[W\] on a `current` column without a unit is
/// taken for a current in mA: 100 kW is beyond any servomotor this tool is for (the paper's
/// motor draws 2.1 kW at its 40 V step).
const MAX_PLAIN_POWER_W: f64 = 1e5;
/// A peak voltage over peak current below this \[Ω\] on a `current` column without a unit is
/// taken for a current in mA too. A step from rest never draws more than its stall current E/R,
/// so this apparent resistance is at least R: a servomotor's armature is tenths of an ohm to
/// tens of ohms (the paper's, 0.3 Ω, peaks at 40 V / 53.6 A = 0.75 Ω), and the same motor in mA
/// reads a thousand times less. (A motor whose current stays far below its stall current
/// reads, in mA, like a stronger motor in A: no threshold tells those apart; the unit does.)
const MIN_PLAIN_OHM: f64 = 0.05;

/// Refuses a record whose unit-less `t` or `current` column is implausible in SI units (a time
/// in ms, a current in mA): the fit would converge to a motor scaled by 1000 in every
/// parameter. A unit in the header (`t[s]`, `current[A]`) confirms the values as they are.
fn check_unit_plausibility(
    table: &Table,
    find: &dyn Fn(&str) -> Option<usize>,
    record: &Record,
) -> std::result::Result<(), (usize, String)> {
    let stated = |name: &str| find(name).is_some_and(|i| table.units[i].is_some());
    let line = table.header_line;
    let dt = motor_model::mean_period(&record.t);
    if !stated("t") && dt >= MAX_PLAIN_PERIOD_S {
        return Err((
            line,
            format!(
                "the time steps by {dt} between samples: as seconds, below 100 Hz, slower than motor records are taken. \
                 If the time is in ms, write `t[ms]` in the header; write `t[s]` to confirm seconds"
            ),
        ));
    }
    let peak = |y: &[f64]| y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let power = peak(&record.voltage) * peak(&record.current);
    let apparent_ohm = peak(&record.voltage) / peak(&record.current);
    // Without a voltage column (a current-driven axis) there is nothing to compare with, nor
    // without a current column (voltage and speed only).
    let with_voltage = peak(&record.voltage) > 0.0 && !record.current.is_empty();
    if !stated("current")
        && with_voltage
        && (power > MAX_PLAIN_POWER_W || apparent_ohm < MIN_PLAIN_OHM)
    {
        return Err((
            line,
            format!(
                "the current peaks at {} A with {} V applied: {:.3e} W, {:.3e} Ω, beyond any servomotor. \
                 If the current is in mA, write `current[mA]` in the header; write `current[A]` to confirm amperes",
                peak(&record.current),
                peak(&record.voltage),
                power,
                apparent_ohm
            ),
        ));
    }
    Ok(())
}

/// Share of a channel's range by which a sample may lie beyond its rails and still be the
/// rail's reading ([`check_within_rails`]).
const BEYOND_RAIL_FRACTION: f64 = 0.01;

/// Refuses a record whose voltage, current or (tachometer) speed lies beyond the rails its
/// metadata gives (`# measurement:`, `# range_current:` …) by more than [`BEYOND_RAIL_FRACTION`] of the range: an ADC cannot read
/// there, so the column is in other units than the header says (a current in mA under
/// `current[A]`: every sample was "at a rail" and the record refused for clipping) or the
/// metadata is another record's. Names the first such line and value.
fn check_within_rails(
    table: &Table,
    record: &Record,
    rails: &[Option<([f64; 2], f64)>; 3],
) -> std::result::Result<(), (usize, String)> {
    let columns = [
        ("voltage", "V", Some(&record.voltage)),
        ("current", "A", Some(&record.current)),
        // Beside an angle the speed is the encoder's, read by no ADC.
        (
            "speed",
            "rad/s",
            record.speed.as_ref().filter(|_| record.position.is_none()),
        ),
    ];
    for ((name, unit, col), rail) in columns.into_iter().zip(rails) {
        let (Some(y), Some(([lo, hi], _))) = (col, rail) else {
            continue;
        };
        let margin = BEYOND_RAIL_FRACTION * (hi - lo).abs();
        // A column whose negation the range holds has its sign reversed: the sign checks
        // name that.
        if y.iter().all(|&v| -v <= hi + margin && -v >= lo - margin) {
            continue;
        }
        if let Some((i, v)) = y
            .iter()
            .enumerate()
            .find(|(_, &v)| v > hi + margin || v < lo - margin)
        {
            return Err((
                table.lines.get(i).copied().unwrap_or(table.header_line),
                format!(
                    "{name} {v} {unit} lies beyond the ADC's range [{lo}, {hi}] {unit} that the record's metadata gives, \
                     which no reading can: is the column in other units than its header says (e.g. mA: write `{name}[mA]`), \
                     or is the metadata another record's?"
                ),
            ));
        }
    }
    Ok(())
}

/// Samples either side within which a reading above a zero rail shows the channel noisy about
/// it ([`zero_rail_while_moving`]).
const ZERO_RAIL_NEIGHBOURS: usize = 3;
/// Share of the largest |speed| above which the motor counts as turning, and samples either
/// side over which an angle must change for it ([`zero_rail_while_moving`]).
const TURNING_FRACTION: f64 = 0.05;
const TURNING_SAMPLES: usize = 10;

/// The current samples of `record` that read a rail of `rails` at exactly 0 A (within `tol`)
/// while the motor turns and while readings within [`ZERO_RAIL_NEIGHBOURS`] samples lie above
/// it: as `(count, first, last)`, `None` when there are none or no rail is at 0.
///
/// A unipolar range puts a rail at 0 A, and the fits keep its readings (a motor at rest reads
/// 0 A, as modelled). But a turning motor draws current, and a current of a step or two
/// above 0 A with noise about it reads the rail for its noise below: those readings are
/// clipped, the mean of the rest is high, and f, Ts and k came out 4–6 half-widths off their
/// intervals (a 24 V step of a motor drawing 0.74 A at its steady speed on a 0–492 A range).
/// A noise-free current that reads 0 A for good is its quantiser's, not the rail's.
fn zero_rail_while_moving(
    record: &Record,
    rails: [f64; 2],
    tol: f64,
) -> Option<(usize, usize, usize)> {
    let current = &record.current;
    let n = current.len();
    let at_zero: Vec<bool> = current
        .iter()
        .map(|&v| (rails[0] == 0.0 && v <= tol) || (rails[1] == 0.0 && v >= -tol))
        .collect();
    if n == 0 || !at_zero.iter().any(|&z| z) {
        return None;
    }
    let turning: Vec<bool> = match (&record.position, &record.speed) {
        // Turning before the sample and after it: a rotor that starts at a step reads 0 A
        // there as the model does, its current rising from 0 through L.
        (Some(angle), _) if angle.len() == n => (0..n)
            .map(|i| {
                let (a, b) = (
                    i.saturating_sub(TURNING_SAMPLES),
                    (i + TURNING_SAMPLES).min(n - 1),
                );
                angle[a] != angle[i] && angle[i] != angle[b]
            })
            .collect(),
        (_, Some(speed)) if speed.len() == n => {
            let peak = speed.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            speed
                .iter()
                .map(|w| w.abs() > TURNING_FRACTION * peak)
                .collect()
        }
        _ => return None,
    };
    let noisy = |i: usize| {
        let (a, b) = (
            i.saturating_sub(ZERO_RAIL_NEIGHBOURS),
            (i + ZERO_RAIL_NEIGHBOURS).min(n - 1),
        );
        (a..=b).any(|j| !at_zero[j])
    };
    let hits: Vec<usize> = (0..n)
        .filter(|&i| at_zero[i] && turning[i] && noisy(i))
        .collect();
    Some((hits.len(), *hits.first()?, *hits.last()?))
}

/// How many times the span of the rest of its column a sample may lie beyond the rest before
/// it is taken for a corrupted value ([`check_isolated_outliers`]).
const OUTLIER_SPANS: f64 = 10.0;

/// The sample of `y` (its index) that lies more than [`OUTLIER_SPANS`] times the span of the
/// other samples beyond all of them, if any, with a sample on either side (the first or last
/// sample of a record may be a level of its own: one sample before a step); `None` when the
/// others do not vary (nothing to judge by).
fn isolated_outlier(y: &[f64]) -> Option<usize> {
    if y.len() < 3 {
        return None;
    }
    let mut order: Vec<usize> = (0..y.len()).collect();
    order.sort_by(|&a, &b| y[a].total_cmp(&y[b]));
    let (lo, lo2) = (y[order[0]], y[order[1]]);
    let (hi, hi2) = (y[order[y.len() - 1]], y[order[y.len() - 2]]);
    let beyond = |gap: f64, span: f64| span > 0.0 && gap > OUTLIER_SPANS * span;
    let at = if beyond(hi - hi2, hi2 - lo) {
        order[y.len() - 1]
    } else if beyond(lo2 - lo, hi - lo2) {
        order[0]
    } else {
        return None;
    };
    (at > 0 && at + 1 < y.len()).then_some(at)
}

/// Refuses a record one of whose voltage, current, speed or angle samples lies more than
/// [`OUTLIER_SPANS`] times the span of the rest of its column beyond every other sample: no
/// motor's signal jumps there for one sample and back, an ADC cannot read it, and a fit would
/// either bend to it or (as a rail) leave out a sample that is no rail. The line and the value
/// are named, to correct or delete.
fn check_isolated_outliers(
    table: &Table,
    record: &Record,
) -> std::result::Result<(), (usize, String)> {
    let columns = [
        ("voltage", "V", Some(&record.voltage)),
        ("current", "A", Some(&record.current)),
        ("speed", "rad/s", record.speed.as_ref()),
        ("position", "rad", record.position.as_ref()),
    ];
    for (name, unit, col) in columns {
        let Some(y) = col.filter(|y| !y.is_empty()) else {
            continue;
        };
        if let Some(i) = isolated_outlier(y) {
            let rest = y
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, &v)| {
                    (a.min(v), b.max(v))
                });
            return Err((
                table.lines.get(i).copied().unwrap_or(table.header_line),
                format!(
                    "{name} {:e} {unit}, while every other sample of the column lies within [{:.6e}, {:.6e}] {unit}: \
                     a corrupted value (no motor signal jumps there for one sample) — correct or delete the line",
                    y[i], rest.0, rest.1
                ),
            ));
        }
    }
    Ok(())
}

/// One ADC step of analog channel `c` (0 voltage \[V\], 1 current \[A\], 2 speed \[rad/s\])
/// stated by the `# measurement:` metadata.
fn adc_lsb(table: &Table, c: usize) -> Option<f64> {
    let m = table
        .meta("measurement")
        .and_then(|text| serde_json::from_str::<motor_model::MeasurementModel>(text).ok())?;
    Some(m.adc?.lsb((*m.ranges.get(c)?)?))
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
    use proptest::prelude::*;

    fn record(text: &str) -> std::result::Result<Loaded, (usize, String)> {
        let table = parse_bytes(text.as_bytes())?;
        to_record(table, &ColumnMap::default(), true, true)
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
        ) {
            let sep = if crlf { "\r\n" } else { "\n" };
            let text: String = std::iter::once("t,voltage,current".to_string())
                .chain(rows.iter().map(|r| r.join(",")))
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
