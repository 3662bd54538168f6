//! Servo logs (SPEC section 8) read as [`fit::ServoRecord`]s: the columns `t[s]`,
//! `position[rad]`, `speed[rad/s]`, `voltage[V]` or `duty` with `supply[V]`, `goal[rad]` and
//! `enable`, and the rig each record describes in its metadata lines (`# load:`,
//! `# controller:`, `# gear:`), which win over the command line's for that record.

use std::path::Path;

use anyhow::Result;
use fit::ServoRecord;
use motor_model::{Controller, Load};

use crate::csv_table::{read_table, Table};
use crate::errors::BadInput;

/// The rig given on the command line: the default of every record that does not describe its
/// own.
#[derive(Debug, Clone, Default)]
pub struct RigOptions {
    /// `--load` (repeatable).
    pub loads: Vec<Load>,
    /// `--controller`.
    pub controller: Option<Controller>,
    /// `--gear`.
    pub gear: Option<f64>,
}

impl RigOptions {
    /// Parses `--load`, `--controller` and `--gear`; a bad one is bad input naming the flag.
    pub fn parse(loads: &[String], controller: Option<&str>, gear: Option<f64>) -> Result<Self> {
        let loads = loads
            .iter()
            .map(|l| {
                l.parse::<Load>()
                    .map_err(|e| BadInput(format!("--load: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let controller = controller
            .map(|c| c.parse::<Controller>())
            .transpose()
            .map_err(|e| BadInput(format!("--controller: {e}")))?;
        if let Some(g) = gear {
            check_gear(g).map_err(|why| BadInput(format!("--gear {g}: {why}")))?;
        }
        Ok(RigOptions {
            loads,
            controller,
            gear,
        })
    }
}

fn check_gear(g: f64) -> std::result::Result<f64, &'static str> {
    if g.is_finite() && g > 0.0 {
        Ok(g)
    } else {
        Err("expected a gear ratio greater than zero (N for an N:1 gearbox)")
    }
}

/// `output`, unless it is one of `inputs` (the same file, by any name): writing there would
/// replace a log with the model.
pub fn not_an_input<'a>(
    output: &Path,
    inputs: impl Iterator<Item = &'a std::path::PathBuf>,
) -> Result<std::path::PathBuf> {
    if let Ok(out) = std::fs::canonicalize(output) {
        for input in inputs {
            if std::fs::canonicalize(input).is_ok_and(|i| i == out) {
                return Err(BadInput(format!(
                    "--save-model {}: it is the record {}; name a new file for the model",
                    output.display(),
                    input.display()
                ))
                .into());
            }
        }
    }
    Ok(output.to_path_buf())
}

/// Each of `paths` once: a record given twice, or both fitted and held out, is bad input.
pub fn distinct<'a>(paths: impl Iterator<Item = &'a std::path::PathBuf>) -> Result<()> {
    let mut seen: Vec<(std::path::PathBuf, &std::path::PathBuf)> = Vec::new();
    for p in paths {
        let key = std::fs::canonicalize(p).unwrap_or_else(|_| p.clone());
        if let Some((_, first)) = seen.iter().find(|(k, _)| *k == key) {
            return Err(BadInput(format!(
                "{} is given twice (also as {}): list each record once, fitted (--record) or held out (--validate)",
                p.display(),
                first.display()
            ))
            .into());
        }
        seen.push((key, p));
    }
    Ok(())
}

/// Whether the file at `path` is a servo log: its header names a `duty` or `goal` column, or a
/// comment before it describes the rig (`# load:` / `# controller:`). Only a regular file is
/// looked into, and only up to its header (a FIFO is read once, by its reader; an unreadable
/// file is not a servo log and its reader says why).
pub fn is_servo_log(path: &Path) -> bool {
    use std::io::BufRead;
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    for line in std::io::BufReader::new(file).lines().take(64) {
        let Ok(line) = line else {
            return false;
        };
        let line = line
            .trim_start_matches('\u{feff}')
            .trim()
            .to_ascii_lowercase();
        if let Some(comment) = line.strip_prefix('#') {
            let key = comment.split(':').next().unwrap_or("").trim();
            if key == "load" || key == "controller" {
                return true;
            }
        } else if !line.is_empty() {
            return line
                .split([',', ';', '\t'])
                .map(|h| crate::csv_table::split_unit(h.trim_matches('"')).0)
                .any(|name| name == "duty" || name == "goal");
        }
    }
    false
}

/// Reads the servo log at `path` with `rig` as the default rig.
pub fn read_servo(path: &Path, rig: &RigOptions) -> Result<ServoRecord> {
    let table = read_table(path)?;
    let shown = path.display().to_string();
    let bad = |msg: String| BadInput(format!("{shown}: {msg}"));
    let column = |name: &str, unit: Option<&str>| -> Result<Option<Vec<f64>>> {
        let Some(i) = table.index(name) else {
            return Ok(None);
        };
        if let (Some(want), Some(Some(got))) = (unit, table.units.get(i)) {
            if !got.eq_ignore_ascii_case(want) {
                return Err(bad(format!(
                    "column `{name}[{got}]`: expected the unit [{want}]; convert the column or rename it `{name}[{want}]`"
                ))
                .into());
            }
        }
        Ok(Some(table.columns[i].clone()))
    };
    let t = column("t", Some("s"))?.ok_or_else(|| bad("no `t[s]` column".into()))?;
    let q = column("position", Some("rad"))?.ok_or_else(|| {
        bad("no `position[rad]` column: a servo log is judged by its position".into())
    })?;
    check_stamps(&table, &t).map_err(|(line, msg)| BadInput(format!("{shown}:{line}: {msg}")))?;
    let duty = column("duty", None)?;
    let supply = column("supply", Some("V"))?;
    let voltage = column("voltage", Some("V"))?;
    let goal = column("goal", Some("rad"))?;
    let enable = column("enable", None)?;
    if duty.is_some() && supply.is_none() {
        return Err(bad(
            "a `duty` column needs a `supply[V]` column (the applied voltage is duty × supply)"
                .into(),
        )
        .into());
    }
    if let Some(d) = &duty {
        if let Some(k) = d.iter().position(|v| !(-1.0..=1.0).contains(v)) {
            return Err(BadInput(format!(
                "{shown}:{}: duty {} is outside -1…1; give the duty as a fraction of the supply",
                table.lines[k], d[k]
            ))
            .into());
        }
    }
    if let Some(v) = &supply {
        if let Some(k) = v.iter().position(|v| *v < 0.0) {
            return Err(BadInput(format!(
                "{shown}:{}: supply {} V is negative; give the supply's magnitude (the duty carries the sign)",
                table.lines[k], v[k]
            ))
            .into());
        }
    }
    let enable = match enable {
        None => None,
        Some(e) => {
            if let Some(k) = e.iter().position(|v| *v != 0.0 && *v != 1.0) {
                return Err(BadInput(format!(
                    "{shown}:{}: enable {} is neither 0 (drive off) nor 1 (drive on)",
                    table.lines[k], e[k]
                ))
                .into());
            }
            Some(e.iter().map(|v| *v == 1.0).collect())
        }
    };
    let (loads, controller, gear) = own_rig(&table, rig).map_err(&bad)?;
    if goal.is_some() && duty.is_none() && voltage.is_none() && controller.is_none() {
        return Err(bad(
            "a `goal` column without `duty` or `voltage` is replayed through the servo's position loop: give --controller (e.g. dynamixel-xl330:kp=200) or a `# controller:` line".into(),
        )
        .into());
    }
    if duty.is_none() && voltage.is_none() && goal.is_none() {
        return Err(bad(
            "no input column: give `voltage[V]`, or `duty` with `supply[V]`, or `goal[rad]` with `supply[V]` and a controller".into(),
        )
        .into());
    }
    Ok(ServoRecord {
        name: path
            .file_name()
            .map_or_else(|| shown.clone(), |n| n.to_string_lossy().into_owned()),
        t_s: t,
        q_rad: q,
        w_rad_s: column("speed", Some("rad/s"))?,
        voltage_v: voltage,
        duty,
        supply_v: supply,
        goal_rad: goal,
        enable,
        loads,
        controller,
        gear,
    })
}

/// Largest gap between two stamps, in median spacings of the log.
const MAX_GAP_SPACINGS: f64 = 1000.0;

/// Stamps strictly increasing and without a gap of more than [`MAX_GAP_SPACINGS`]: the line
/// and message of the first that breaks it.
fn check_stamps(table: &Table, t: &[f64]) -> std::result::Result<(), (usize, String)> {
    for (k, w) in t.windows(2).enumerate() {
        if w[1] <= w[0] {
            let what = if w[1] == w[0] {
                "repeats the previous one"
            } else {
                "is before the previous one"
            };
            return Err((
                table.lines[k + 1],
                format!(
                    "time stamp {} s {what} ({} s): stamps must increase; remove the repeated line or sort the log by time",
                    w[1], w[0]
                ),
            ));
        }
    }
    if t.len() < 2 {
        return Err((table.header_line, "fewer than two samples".into()));
    }
    // A gap far beyond the log's own spacing is where it stopped: the drive's input is unknown
    // over it, and holding it would make the replay take as long as the gap is long.
    let mut spacing: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    spacing.sort_by(f64::total_cmp);
    let median = spacing[spacing.len() / 2];
    for (k, w) in t.windows(2).enumerate() {
        if w[1] - w[0] > MAX_GAP_SPACINGS * median {
            return Err((
                table.lines[k + 1],
                format!(
                    "time stamp {} s comes {:.6} s after the previous one, {:.0} times the log's median spacing ({:.6} s): the log stopped here; split it into two records",
                    w[1],
                    w[1] - w[0],
                    (w[1] - w[0]) / median,
                    median
                ),
            ));
        }
    }
    Ok(())
}

/// The record's loads, controller and gear: its own metadata lines where it has them, else
/// `rig`'s.
fn own_rig(
    table: &Table,
    rig: &RigOptions,
) -> std::result::Result<(Vec<Load>, Option<Controller>, f64), String> {
    let own_loads: Vec<Load> = table
        .metadata
        .iter()
        .filter(|(k, _)| k.eq_ignore_ascii_case("load"))
        .map(|(_, v)| {
            v.parse::<Load>()
                .map_err(|e| format!("`# load:` line: {e}"))
        })
        .collect::<Result<_, _>>()?;
    let loads = if own_loads.is_empty() {
        rig.loads.clone()
    } else {
        own_loads
    };
    for key in ["controller", "gear"] {
        let count = table
            .metadata
            .iter()
            .filter(|(k, _)| k.eq_ignore_ascii_case(key))
            .count();
        if count > 1 {
            return Err(format!(
                "{count} `# {key}:` lines; a record has one {key} (keep the right line)"
            ));
        }
    }
    let controller = match table.meta("controller") {
        Some(c) => Some(
            c.parse::<Controller>()
                .map_err(|e| format!("`# controller:` line: {e}"))?,
        ),
        None => rig.controller.clone(),
    };
    let gear = match table.meta("gear") {
        Some(g) => {
            let g: f64 = g
                .trim()
                .parse()
                .map_err(|_| format!("`# gear: {g}`: not a number"))?;
            check_gear(g).map_err(|why| format!("`# gear: {g}`: {why}"))?
        }
        None => rig.gear.unwrap_or(1.0),
    };
    Ok((loads, controller, gear))
}

/// What a record used, in words: `pendulum:m=0.49,l=0.1,arm=0; dynamixel-xl330:kp=200`.
pub fn rig_text(record: &ServoRecord) -> String {
    let mut parts: Vec<String> = record.loads.iter().map(ToString::to_string).collect();
    if parts.is_empty() {
        parts.push("no load".into());
    }
    parts.push(match &record.controller {
        Some(c) => c.to_string(),
        None => "no controller".into(),
    });
    if record.gear != 1.0 {
        parts.push(format!("gear {}", record.gear));
    }
    parts.join("; ")
}
