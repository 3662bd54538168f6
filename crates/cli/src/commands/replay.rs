//! `motorid replay`: servo logs replayed with a model file, each on its own time stamps,
//! closed loop from `goal` where the model has a controller and the record a goal.

use std::path::PathBuf;

use anyhow::Result;
use fit::{Loop, ServoRecord};
use motor_model::ModelFile;
use serde_json::json;

use crate::args::ReplayArgs;
use crate::console::outln;
use crate::errors::BadInput;
use crate::servo_csv::{read_servo, RigOptions};
use crate::servo_report::{mean_mae, plot_replays, print_scores, scores_json};

/// What `replay` is asked, validated.
#[derive(Debug, Clone)]
pub struct Settings {
    model: ModelFile,
    path: String,
    records: Vec<PathBuf>,
    rig: RigOptions,
    open_loop: bool,
    plot: Option<PathBuf>,
    quiet: bool,
    json: bool,
}

impl Settings {
    /// Reads and checks the model file; the rig options over the model's own.
    pub fn from_args(a: &ReplayArgs) -> Result<Settings> {
        let shown = a.model.display();
        let text = std::fs::read_to_string(&a.model)
            .map_err(|e| BadInput(format!("{shown}: cannot read ({e})")))?;
        let model: ModelFile = serde_json::from_str(&text).map_err(|e| {
            BadInput(format!(
                "{shown}:{}: not a model file ({e}); write one with `motorid identify … --save-model`",
                e.line()
            ))
        })?;
        model
            .check()
            .map_err(|e| BadInput(format!("{shown}: {e}")))?;
        let given = RigOptions::parse(&a.rig.load, a.rig.controller.as_deref(), a.rig.gear)?;
        let rig = RigOptions {
            loads: if given.loads.is_empty() {
                model.rig.loads.clone()
            } else {
                given.loads
            },
            controller: given.controller.or_else(|| model.rig.controller.clone()),
            gear: given.gear.or(Some(model.rig.gear)),
        };
        Ok(Settings {
            model,
            path: shown.to_string(),
            records: a.record.clone(),
            rig,
            open_loop: a.open_loop,
            plot: a.plot.clone(),
            quiet: a.quiet,
            json: a.json,
        })
    }
}

/// Replays every record and prints the scores.
pub fn run(s: &Settings) -> Result<()> {
    let records: Vec<ServoRecord> = s
        .records
        .iter()
        .map(|p| read_servo(p, &s.rig))
        .collect::<Result<_>>()?;
    let mode = if s.open_loop {
        Loop::Open
    } else {
        Loop::Closed
    };
    let motor = s.model.rig.motor;
    let traces = records
        .iter()
        .map(|r| {
            fit::replay_record(r, motor, mode, Default::default())
                .map_err(|e| BadInput(format!("{}: replayed with {}: {e}", r.name, s.path)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let scores: Vec<fit::ReplayScore> = records
        .iter()
        .zip(&traces)
        .map(|(r, t)| fit::score(r, t, r.closed_loop(mode)))
        .collect();
    if s.json {
        let report = json!({
            "records": scores_json(&records, &scores),
            "mae_rad": mean_mae(&scores),
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        print_scores("replayed:", &records, &scores)?;
    }
    if let Some(dir) = &s.plot {
        plot_replays(dir, &records, &traces, s.quiet)?;
    }
    Ok(())
}
