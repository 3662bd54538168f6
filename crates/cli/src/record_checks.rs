//! Checks of a record's values against what its metadata and units make plausible: ADC rails,
//! a current at zero while the motor turns, isolated outliers, units that give no motor.

use motor_model::Record;

use crate::csv_table::Table;

/// The conditioning ranges `[lo, hi]` of voltage, current and speed stated in the metadata, with
/// half an ADC step as tolerance: `# measurement:` as `motorid simulate` writes it, or
/// `# range_voltage: LO,HI` (likewise `range_current`, `range_speed`).
/// Whether the record's metadata says it was measured without an ADC (`motorid simulate`'s
/// ideal records, or a measurement model with no ADC): nothing in it can sit on a rail. Its
/// steady values are then exact and repeat for as long as they hold — a current settled at
/// E/R for the last quarter of a record looked clipped, and a step below breakaway was
/// refused as "25 % of the current on an ADC rail".
pub(crate) fn metadata_says_no_adc(table: &Table) -> bool {
    table.meta("measurement").is_some_and(|text| {
        text == crate::record_checks::IDEAL_MEASUREMENT
            || serde_json::from_str::<motor_model::MeasurementModel>(text)
                .is_ok_and(|m| m.adc.is_none())
    })
}

pub(crate) fn metadata_rails(table: &Table) -> [Option<([f64; 2], f64)>; 3] {
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
pub(crate) const MAX_PLAIN_PERIOD_S: f64 = 0.01;

/// A peak voltage × peak current above this \[W\] on a `current` column without a unit is
/// taken for a current in mA: 100 kW is beyond any servomotor this tool is for (the paper's
/// motor draws 2.1 kW at its 40 V step).
pub(crate) const MAX_PLAIN_POWER_W: f64 = 1e5;

/// A peak voltage over peak current below this \[Ω\] on a `current` column without a unit is
/// taken for a current in mA too. A step from rest never draws more than its stall current E/R,
/// so this apparent resistance is at least R: a servomotor's armature is tenths of an ohm to
/// tens of ohms (the paper's, 0.3 Ω, peaks at 40 V / 53.6 A = 0.75 Ω), and the same motor in mA
/// reads a thousand times less. (A motor whose current stays far below its stall current
/// reads, in mA, like a stronger motor in A: no threshold tells those apart; the unit does.)
pub(crate) const MIN_PLAIN_OHM: f64 = 0.05;

/// Refuses a record whose unit-less `t` or `current` column is implausible in SI units (a time
/// in ms, a current in mA): the fit would converge to a motor scaled by 1000 in every
/// parameter. A unit in the header (`t[s]`, `current[A]`) confirms the values as they are.
pub(crate) fn check_unit_plausibility(
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
pub(crate) const BEYOND_RAIL_FRACTION: f64 = 0.01;

/// Refuses a record whose voltage, current or (tachometer) speed lies beyond the rails its
/// metadata gives (`# measurement:`, `# range_current:` …) by more than [`BEYOND_RAIL_FRACTION`] of the range: an ADC cannot read
/// there, so the column is in other units than the header says (a current in mA under
/// `current[A]`: every sample was "at a rail" and the record refused for clipping) or the
/// metadata is another record's. Names the first such line and value.
pub(crate) fn check_within_rails(
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
pub(crate) const ZERO_RAIL_NEIGHBOURS: usize = 3;

/// Share of the largest |speed| above which the motor counts as turning, and samples either
/// side over which an angle must change for it ([`zero_rail_while_moving`]).
pub(crate) const TURNING_FRACTION: f64 = 0.05;

pub(crate) const TURNING_SAMPLES: usize = 10;

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
pub(crate) fn zero_rail_while_moving(
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
pub(crate) const OUTLIER_SPANS: f64 = 10.0;

/// The sample of `y` (its index) that lies more than [`OUTLIER_SPANS`] times the span of the
/// other samples beyond all of them, if any, with a sample on either side (the first or last
/// sample of a record may be a level of its own: one sample before a step); `None` when the
/// others do not vary (nothing to judge by).
pub(crate) fn isolated_outlier(y: &[f64]) -> Option<usize> {
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
pub(crate) fn check_isolated_outliers(
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
pub(crate) fn adc_lsb(table: &Table, c: usize) -> Option<f64> {
    let m = table
        .meta("measurement")
        .and_then(|text| serde_json::from_str::<motor_model::MeasurementModel>(text).ok())?;
    Some(m.adc?.lsb((*m.ranges.get(c)?)?))
}

/// The `measurement` metadata of a record simulated without ADC, noise or encoder.
pub const IDEAL_MEASUREMENT: &str = "ideal (exact values)";
