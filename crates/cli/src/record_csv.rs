//! Writing records in the CSV contract of SPEC section 4, atomically.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use motor_model::Record;

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
