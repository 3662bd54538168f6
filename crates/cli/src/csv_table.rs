//! A CSV file read as a table of numbers: the metadata comments before the header, the header,
//! and the rows, each failure naming the file, the line and the value.

use std::io::BufRead;
use std::path::Path;

use anyhow::Result;

use crate::errors::BadInput;

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

    pub(crate) fn index(&self, name: &str) -> Option<usize> {
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
pub(crate) const MAX_LINE_BYTES: usize = 64 * 1024;

/// Most rows the reader reserves room for before it has seen them (beyond, the columns grow
/// as they fill): 16 M rows of 8-byte values.
pub(crate) const MAX_RESERVED_ROWS: usize = 1 << 24;

/// Fewest rows in the reader's buffer from which [`TableParser::reserve_rows`] takes their
/// mean length.
pub(crate) const MIN_SAMPLED_ROWS: usize = 64;

/// Whether `b` is ASCII white space as [`str::trim`] sees it (`char::is_whitespace`: tab, line
/// feed, vertical tab, form feed, carriage return, space).
pub(crate) fn is_space(b: u8) -> bool {
    matches!(b, b'\t'..=b'\r' | b' ')
}

/// `bytes` from the first byte that is not white space ([`is_space`]) on; the field
/// `delimiter` (a tab) is never skipped.
pub(crate) fn skip_space(bytes: &[u8], delimiter: u8) -> &[u8] {
    let start = bytes
        .iter()
        .position(|&b| b == delimiter || !is_space(b))
        .unwrap_or(bytes.len());
    &bytes[start..]
}

/// The table being read, line by line, with the state the checks across lines need.
pub(crate) struct TableParser {
    pub(crate) table: Table,
    /// 1-based number of the last line seen.
    pub(crate) line_no: usize,
    /// Whether the last line seen ended with a line break.
    pub(crate) saw_newline: bool,
    /// Length of the input \[bytes\] if known: room for its rows is reserved from the first one.
    pub(crate) size_hint: usize,
    /// Whether data rows of plain numbers are read from the bytes ([`TableParser::numeric_row`]);
    /// without, every line takes [`TableParser::text_line`] (the tests compare the two).
    pub(crate) rows_from_bytes: bool,
    /// How the file writes its rows, found from its header ([`Dialect::of_header`]).
    pub(crate) dialect: Dialect,
}

/// How a CSV file writes its rows, as spreadsheets and data tools export them: the field
/// delimiter (`,`; `;` as Excel writes it where the decimal mark is a comma; a tab), whether a
/// comma inside a field is a decimal mark, and whether the first column is an unnamed index
/// (pandas' `to_csv()`), read and dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Dialect {
    /// The field delimiter.
    pub(crate) delimiter: u8,
    /// Whether a comma inside a field is the decimal mark (`1,5` for 1.5): with `;` or a tab
    /// as the delimiter.
    pub(crate) decimal_comma: bool,
    /// Whether the first column is an index with no name, dropped from every row.
    pub(crate) index_column: bool,
}

impl Default for Dialect {
    fn default() -> Self {
        Dialect {
            delimiter: b',',
            decimal_comma: false,
            index_column: false,
        }
    }
}

impl Dialect {
    /// The dialect a header line shows: the delimiter among `,`, `;` and a tab that it holds
    /// most often (a comma on a tie), a decimal comma with any other delimiter, and an index
    /// column when its first name is empty and others follow.
    pub(crate) fn of_header(line: &str) -> Dialect {
        let count = |c: char| line.matches(c).count();
        let delimiter = [(b';', count(';')), (b'\t', count('\t'))]
            .into_iter()
            .filter(|&(_, n)| n > count(','))
            .max_by_key(|&(_, n)| n)
            .map_or(b',', |(d, _)| d);
        let names = split_fields(line, delimiter);
        let index_column = names.len() > 1 && unquote(names[0]).is_empty();
        Dialect {
            delimiter,
            decimal_comma: delimiter != b',',
            index_column,
        }
    }

    /// The fields of a row, the index column dropped; a delimiter inside double quotes
    /// (`"1,5"`, a header name `"a;b"`) is part of its field.
    pub(crate) fn fields<'a>(&self, line: &'a str) -> impl Iterator<Item = &'a str> {
        split_fields(line, self.delimiter)
            .into_iter()
            .skip(usize::from(self.index_column))
    }

    /// The number a field holds: white space and quotes around it removed, a decimal comma
    /// read as a point.
    pub(crate) fn number(&self, field: &str) -> Option<f64> {
        let field = unquote(field);
        if self.decimal_comma && field.contains(',') {
            field.replace(',', ".").parse().ok()
        } else {
            field.parse().ok()
        }
    }
}

/// The fields of `line` between its `delimiter`s; a delimiter inside double quotes is part of
/// its field.
fn split_fields(line: &str, delimiter: u8) -> Vec<&str> {
    let mut fields = Vec::new();
    let (mut start, mut quoted) = (0, false);
    for (i, b) in line.bytes().enumerate() {
        if b == b'"' {
            quoted = !quoted;
        } else if b == delimiter && !quoted {
            fields.push(&line[start..i]);
            start = i + 1;
        }
    }
    fields.push(&line[start..]);
    fields
}

/// `field` without the white space and the pair of double quotes around it (`"t[s]"` as
/// Python's `csv` and Excel write a header).
pub(crate) fn unquote(field: &str) -> &str {
    let field = field.trim();
    field
        .strip_prefix('"')
        .and_then(|f| f.strip_suffix('"'))
        .map_or(field, str::trim)
}

impl TableParser {
    /// A parser for an input of `size_hint` bytes (0 if unknown).
    pub(crate) fn new(size_hint: usize) -> Self {
        TableParser {
            table: Table::default(),
            line_no: 0,
            saw_newline: true,
            size_hint,
            rows_from_bytes: true,
            dialect: Dialect::default(),
        }
    }

    /// The error for a line longer than [`MAX_LINE_BYTES`] (the line after the last one seen).
    pub(crate) fn too_long(&mut self) -> (usize, String) {
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
    pub(crate) fn line(
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
    pub(crate) fn numeric_row(&mut self, bytes: &[u8], ahead: &[u8]) -> bool {
        if self.table.lines.is_empty() {
            self.reserve_rows(bytes.len(), ahead);
        }
        let columns = &mut self.table.columns;
        let delimiter = self.dialect.delimiter;
        let mut rest = bytes;
        if self.dialect.index_column {
            // The index: up to the first delimiter, whatever it holds.
            match memchr::memchr(delimiter, rest) {
                Some(i) => rest = &rest[i + 1..],
                None => return false,
            }
        }
        let mut pushed = 0;
        let complete = loop {
            let Some(column) = columns.get_mut(pushed) else {
                break false;
            };
            let field = skip_space(rest, delimiter);
            let Ok((v, used)) = fast_float2::parse_partial::<f64, _>(field) else {
                break false;
            };
            if !v.is_finite() {
                break false;
            }
            column.push(v);
            pushed += 1;
            match skip_space(&field[used..], delimiter).split_first() {
                None => break pushed == columns.len(),
                Some((&b, tail)) if b == delimiter => rest = tail,
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
    pub(crate) fn reserve_rows(&mut self, first_row_bytes: usize, ahead: &[u8]) {
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
    pub(crate) fn text_line(
        &mut self,
        bytes: &[u8],
        newline: bool,
    ) -> std::result::Result<(), (usize, String)> {
        let line_no = self.line_no;
        // UTF-16 with a byte-order mark, or without one: ASCII text with a NUL beside every
        // character.
        let alternate_nuls = |first: usize| {
            bytes.len() >= 4
                && bytes
                    .iter()
                    .skip(first)
                    .step_by(2)
                    .take(64)
                    .all(|&b| b == 0)
        };
        if line_no == 1
            && (bytes.starts_with(&[0xFF, 0xFE])
                || bytes.starts_with(&[0xFE, 0xFF])
                || alternate_nuls(0)
                || alternate_nuls(1))
        {
            return Err((
                line_no,
                "UTF-16 text: save the file as UTF-8 (in Excel: CSV UTF-8; or iconv -f UTF-16 -t UTF-8)".to_string(),
            ));
        }
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
                    "not UTF-8 text (invalid byte at column {}): is this a CSV file? If it is, save it as UTF-8",
                    e.valid_up_to() + 1
                ),
            )
        })?;
        if line_no == 1 {
            text = text.strip_prefix('\u{feff}').unwrap_or(text);
        }
        let line = text.trim_end_matches('\r');
        // Before the header, a carriage return inside the line: the whole file is one line.
        if self.table.names.is_empty() && line.contains('\r') {
            return Err((
                line_no,
                "lines end in a carriage return alone (CR, as old Mac tools write): convert them to line feeds (tr '\\r' '\\n' < in > out)".to_string(),
            ));
        }
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
            self.dialect = Dialect::of_header(line);
            return parse_header(table, line, line_no, self.dialect);
        }
        let dialect = self.dialect;
        let width = table.names.len();
        let mut count = 0usize;
        for field in dialect.fields(line) {
            let Some(name) = table.names.get(count) else {
                count += 1;
                break;
            };
            let v: f64 = dialect.number(field).ok_or_else(|| {
                let text = unquote(field);
                let hint = if text.contains(',') && text.contains('.') {
                    " (thousands separators? write the number without them)"
                } else if text.contains(',') && dialect.delimiter == b',' {
                    " (a decimal comma? write a point, or separate the fields with ;)"
                } else {
                    ""
                };
                (
                    line_no,
                    format!("column `{name}`: `{}` is not a number{hint}", field.trim()),
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
                    dialect.fields(line).count(),
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
    pub(crate) fn finish(self) -> std::result::Result<Table, (usize, String)> {
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
pub(crate) fn parse_table(
    reader: &mut impl BufRead,
    size_hint: usize,
) -> std::result::Result<Table, (usize, String)> {
    parse_with(reader, TableParser::new(size_hint))
}

/// [`parse_table`] through `parser`.
pub(crate) fn parse_with(
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
pub(crate) fn parse_header(
    table: &mut Table,
    line: &str,
    line_no: usize,
    dialect: Dialect,
) -> std::result::Result<(), (usize, String)> {
    if dialect.delimiter == b',' && !line.contains(',') && line.contains('|') {
        return Err((line_no, "the header is separated by bars: records are separated by commas, semicolons or tabs (e.g. tr '|' ',' < in > out)".to_string()));
    }
    table.header_line = line_no;
    for raw in dialect.fields(line) {
        let (name, unit) = split_unit(unquote(raw));
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
pub(crate) fn parse_bytes(bytes: &[u8]) -> std::result::Result<Table, (usize, String)> {
    parse_table(&mut &bytes[..], bytes.len())
}

/// Other names accepted for each record column (case-insensitive).
pub(crate) const ALIASES: [(&str, &[&str]); 5] = [
    ("t", &["time", "time_s", "t_s", "seconds"]),
    (
        "voltage",
        &["v", "u", "e", "volt", "volts", "armature_voltage"],
    ),
    ("current", &["i", "ia", "amps", "armature_current"]),
    ("speed", &["w", "omega", "velocity", "vel", "tach", "tacho"]),
    ("position", &["theta", "angle", "pos", "q", "encoder"]),
];

/// Which record column a header name (unit stripped) stands for, by name or alias.
pub(crate) fn canonical(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    ALIASES
        .iter()
        .find(|(c, aliases)| *c == lower || aliases.contains(&lower.as_str()))
        .map(|(c, _)| *c)
}

/// Splits `name[unit]` or `name (unit)` into the name and the unit.
pub(crate) fn split_unit(header: &str) -> (String, Option<String>) {
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
