//! What the servo commands (`identify` on servo logs, `replay`) print and draw: each record's
//! replay error, as a table, as JSON and as figures.

use std::path::Path;

use anyhow::Result;
use fit::{ReplayScore, ServoRecord};
use motor_model::ServoTrace;
use serde_json::{json, Value};

use crate::console::{errln, outln};
use crate::plot::{self, Panel, Series};
use crate::servo_csv::rig_text;

/// Prints one line per record (MAE, RMSE, largest error in mrad; loop; rig) and the mean MAE.
pub fn print_scores(title: &str, records: &[ServoRecord], scores: &[ReplayScore]) -> Result<()> {
    outln!("{title}")?;
    outln!(
        "  {:<40} {:>9} {:>9} {:>9}  {:<6}  rig",
        "record",
        "MAE",
        "RMSE",
        "max",
        "loop"
    )?;
    for (r, s) in records.iter().zip(scores) {
        outln!(
            "  {:<40} {:>9.2} {:>9.2} {:>9.2}  {:<6}  {}",
            s.name,
            s.mae_rad * 1e3,
            s.rmse_rad * 1e3,
            s.max_error_rad * 1e3,
            if s.closed_loop { "closed" } else { "open" },
            rig_text(r)
        )?;
    }
    outln!(
        "  mean position MAE {:.2} mrad over {} records (errors in mrad)",
        mean_mae(scores) * 1e3,
        scores.len()
    )?;
    Ok(())
}

/// Mean over records of their MAE \[rad\] (NaN without records).
pub fn mean_mae(scores: &[ReplayScore]) -> f64 {
    scores.iter().map(|s| s.mae_rad).sum::<f64>() / scores.len() as f64
}

/// `{"file", "mae_rad", "rmse_rad", "max_error_rad", "samples", "loop", "rig"}` per record.
pub fn scores_json(records: &[ServoRecord], scores: &[ReplayScore]) -> Vec<Value> {
    records
        .iter()
        .zip(scores)
        .map(|(r, s)| {
            json!({
                "file": s.name,
                "mae_rad": s.mae_rad,
                "rmse_rad": s.rmse_rad,
                "max_error_rad": s.max_error_rad,
                "samples": s.samples,
                "loop": if s.closed_loop { "closed" } else { "open" },
                "rig": rig_text(r),
            })
        })
        .collect()
}

/// Draws, for each record, the logged and replayed position and their difference into `dir`
/// (`<record stem>_replay.svg` and `.png`).
pub fn plot_replays(
    dir: &Path,
    records: &[ServoRecord],
    traces: &[ServoTrace],
    quiet: bool,
) -> Result<()> {
    crate::output::create_dir(dir)?;
    for (r, tr) in records.iter().zip(traces) {
        let stem = Path::new(&r.name)
            .file_stem()
            .map_or_else(|| "record".into(), |s| s.to_string_lossy().into_owned());
        let diff: Vec<f64> = tr.q_rad.iter().zip(&r.q_rad).map(|(s, m)| s - m).collect();
        let panels = [
            Panel {
                y_label: "position [rad]",
                series: vec![
                    Series {
                        label: "logged",
                        values: &r.q_rad,
                        color: plot::MEASURED,
                    },
                    Series {
                        label: "replayed",
                        values: &tr.q_rad,
                        color: plot::MODEL,
                    },
                ],
            },
            Panel {
                y_label: "replayed - logged [rad]",
                series: vec![Series {
                    label: "difference",
                    values: &diff,
                    color: plot::OTHER,
                }],
            },
        ];
        let paths = plot::time_series(
            &dir.join(format!("{stem}_replay")),
            &format!("{}: logged and replayed position", r.name),
            &r.t_s,
            &panels,
        )?;
        if !quiet {
            for p in paths {
                errln!("wrote {}", p.display());
            }
        }
    }
    Ok(())
}
