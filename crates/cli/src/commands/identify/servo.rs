//! `motorid identify` on servo logs (SPEC section 8): the motor at the output fitted with the
//! known loads and the firmware's position loop, the held-out records scored, the model saved.

use std::path::PathBuf;

use anyhow::Result;
use fit::{Loop, ServoFit, ServoRecord};
use motor_model::ModelFile;
use serde_json::json;

use crate::commands::identify::options::Settings;
use crate::console::{errln, outln};
use crate::errors::{BadInput, NotConverged};
use crate::progress::Phases;
use crate::servo_csv::{read_servo, rig_text};
use crate::servo_report::{mean_mae, plot_replays, print_scores, scores_json};

/// Reads `paths` and `validate`, fits, prints, saves the model if asked.
pub fn run(a: &Settings, paths: &[PathBuf], validate: &[PathBuf]) -> Result<()> {
    let phases = Phases::start("identify", a.quiet);
    phases.enter(format!(
        "reading {} servo logs",
        paths.len() + validate.len()
    ));
    let records: Vec<ServoRecord> = paths
        .iter()
        .map(|p| read_servo(p, &a.rig))
        .collect::<Result<_>>()?;
    let held: Vec<ServoRecord> = validate
        .iter()
        .map(|p| read_servo(p, &a.rig))
        .collect::<Result<_>>()?;
    let mode = if a.open_loop {
        Loop::Open
    } else {
        Loop::Closed
    };
    phases.enter(format!(
        "fitting the motor to {} records ({} samples): global search, then Levenberg-Marquardt",
        records.len(),
        records.iter().map(|r| r.t_s.len()).sum::<usize>()
    ));
    let fit = ServoFit::new(&records)
        .mode(mode)
        .friction(a.friction)
        .fit()
        .map_err(|e| match e {
            fit::FitError::Solver(why) => {
                anyhow::Error::from(NotConverged(format!("the fit failed: {why}")))
            }
            other => BadInput(other.to_string()).into(),
        })?;
    let held_scores = fit::score_records(&held, fit.motor, Loop::Closed, Default::default())
        .map_err(|e| BadInput(e.to_string()))?;
    drop(phases);
    // A fit whose replay is further from the logs than their own mean angle explains nothing.
    let constant_mae: f64 = records
        .iter()
        .map(|r| {
            let mean = r.q_rad.iter().sum::<f64>() / r.q_rad.len() as f64;
            r.q_rad.iter().map(|q| (q - mean).abs()).sum::<f64>() / r.q_rad.len() as f64
        })
        .sum::<f64>()
        / records.len() as f64;
    let failure = if !(fit.termination.converged() || fit.termination == fit::Termination::Stalled)
    {
        Some(format!(
            "the fit did not converge: {}",
            fit.termination.text()
        ))
    } else if fit.mae_rad.partial_cmp(&constant_mae) != Some(std::cmp::Ordering::Less) {
        Some(format!(
            "the replayed position is further from the logs (mean MAE {:.2} mrad) than their own mean angle ({:.2} mrad): the model explains nothing; check the loads, the controller and the columns",
            fit.mae_rad * 1e3,
            constant_mae * 1e3
        ))
    } else if fit
        .estimates
        .iter()
        .any(|e| e.ci95.is_none() && !fit.at_zero.contains(&e.name))
    {
        let open: Vec<&str> = fit
            .estimates
            .iter()
            .filter(|e| e.ci95.is_none() && !fit.at_zero.contains(&e.name))
            .map(|e| e.name)
            .collect();
        Some(format!(
            "the 95 % intervals of {} cannot be computed: the records do not determine them (the motor's constants need motion with the drive on; friction and inertia, motion of either kind; or choose a simpler --friction)",
            open.join(", ")
        ))
    } else {
        None
    };
    // After the global search, a gradient step that lowers nothing leaves the search's best
    // point: the replay of a stick-slip rig is not smooth enough there for LM to improve on it.
    let termination = if fit.termination == fit::Termination::Stalled {
        "the global search's best point (no Levenberg-Marquardt step lowered the cost further)"
    } else {
        fit.termination.text()
    };
    let mut model = ModelFile::new(records[0].rig(fit.motor));
    model.ci95 = fit
        .estimates
        .iter()
        .filter_map(|e| e.ci95.map(|ci| (e.name.to_string(), ci)))
        .collect();
    model.identified_from = records.iter().map(|r| r.name.clone()).collect();
    model.open_loop = a.open_loop;
    if a.json {
        let params: serde_json::Map<String, serde_json::Value> = fit
            .estimates
            .iter()
            .map(|e| {
                (
                    e.name.to_string(),
                    json!({"value": e.value, "unit": e.unit, "ci95": e.ci95,
                        "at_zero": fit.at_zero.contains(&e.name)}),
                )
            })
            .collect();
        let mut report = json!({
            "method": "servo",
            "loop": if a.open_loop { "open" } else { "closed" },
            "parameters": params,
            "termination": termination,
            "iterations": fit.iterations,
            "records": scores_json(&records, &fit.scores),
            "mae_rad": fit.mae_rad,
        });
        if !held.is_empty() {
            report["validation"] = json!({
                "records": scores_json(&held, &held_scores),
                "mae_rad": mean_mae(&held_scores),
            });
        }
        if let Some(why) = &failure {
            report["error"] = json!(why);
            report["exit_code"] = json!(3);
        }
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!(
            "servo motor at the output ({} records, {} loop; {})",
            records.len(),
            if a.open_loop { "open" } else { "closed" },
            termination
        )?;
        for e in &fit.estimates {
            match e.ci95 {
                Some([lo, hi]) => outln!(
                    "  {:<5} = {:<12.5} {:<10} 95 % [{lo:.5}, {hi:.5}]",
                    e.name,
                    e.value,
                    e.unit
                )?,
                None if fit.at_zero.contains(&e.name) => outln!(
                    "  {:<5} = 0            {:<10} (driven to zero: the records show none)",
                    e.name,
                    e.unit
                )?,
                None => outln!(
                    "  {:<5} = {:<12.5} {:<10} (no interval)",
                    e.name,
                    e.value,
                    e.unit
                )?,
            }
        }
        if records[0].gear != 1.0 {
            let n = records[0].gear;
            outln!(
                "  motor side (gear {n}): kt = {:.5e} N·m/A, rotor J = {:.5e} kg·m²",
                fit.motor.ke_nm_per_a / n,
                fit.motor.j_kg_m2 / (n * n)
            )?;
        }
        print_scores("fitted records, replayed:", &records, &fit.scores)?;
        if !held.is_empty() {
            print_scores(
                "held-out records (--validate), replayed:",
                &held,
                &held_scores,
            )?;
        }
    }
    // A fit that is not a result is not saved: it would replace a model that is one.
    if let (Some(path), None) = (&a.save_model, &failure) {
        let text = serde_json::to_string_pretty(&model)?;
        crate::output::write_with(path, |out| Ok(out.write_all(text.as_bytes())?))?;
        if !a.quiet {
            errln!("wrote {} (rig: {})", path.display(), rig_text(&records[0]));
        }
    }
    if let Some(dir) = &a.plot {
        let all: Vec<ServoRecord> = records.iter().chain(&held).cloned().collect();
        let traces = all
            .iter()
            .map(|r| fit::replay_record(r, fit.motor, Loop::Closed, Default::default()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| BadInput(e.to_string()))?;
        plot_replays(dir, &all, &traces, a.quiet)?;
    }
    match failure {
        Some(why) => Err(NotConverged(why).into()),
        None => Ok(()),
    }
}
