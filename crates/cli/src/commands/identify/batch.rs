//! `motorid identify --batch DIR`: every motor folder under DIR identified in parallel, one
//! summary table (CSV and JSON).
//!
//! A motor folder holds `high.csv` and `low.csv` (identified by the full model from the step
//! method's start) or other `*.csv` records of any voltage waveform (output error). A
//! `motor.json` beside them is the truth: the summary then gives each parameter's error and
//! whether its 95 % interval contains the truth. One folder's failure is a row of the summary,
//! not the end of the batch.

use std::path::{Path, PathBuf};

use anyhow::Result;
use fit::{
    accuracy, parameter_estimates, summarize, FullFit, ParameterAccuracy, StepMethod, PARAM_NAMES,
    PARAM_UNITS,
};
use motor_model::MotorParams;
use serde_json::{json, Value};

use super::model_check::ModelCheck;
use super::options::Settings;
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};
use crate::progress::Jobs;
use crate::record_csv::ColumnMap;
use crate::steps::{fit_excited, identify_pair, in_order, load_excited, load_step, LoadedExcited};
use crate::{output, parallel, settings};

/// Outcome of one folder.
enum Outcome {
    Fitted(Box<FullFit>),
    Failed { bad_input: bool, message: String },
}

struct Row {
    name: String,
    method: &'static str,
    outcome: Outcome,
    truth: Option<MotorParams>,
    /// The fit against `truth`, when both are there.
    against: Option<Vec<ParameterAccuracy>>,
    /// The model check of the fit, as `identify` makes it; `None` where the folder gave no fit.
    model_check: Option<ModelCheck>,
    seconds: f64,
}

/// The paths of the readable `entries` that `keep` accepts, sorted by name.
fn sorted_paths(entries: std::fs::ReadDir, keep: impl Fn(&Path) -> bool) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| keep(p))
        .collect();
    out.sort();
    out
}

/// The motor folders under `dir`, sorted by name.
fn motor_folders(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        BadInput(format!(
            "--batch {}: cannot read the folder ({e})",
            dir.display()
        ))
    })?;
    let out = sorted_paths(entries, Path::is_dir);
    if out.is_empty() {
        return Err(BadInput(format!(
            "--batch {}: no motor folders inside (expected DIR/NAME/high.csv and low.csv, or DIR/NAME/*.csv)",
            dir.display()
        ))
        .into());
    }
    Ok(out)
}

/// The folder's name, for the summary.
fn folder_name(folder: &Path) -> String {
    folder
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// Whether the folder holds a step pair (`high.csv` and `low.csv`).
fn has_step_pair(folder: &Path) -> bool {
    folder.join("high.csv").exists() && folder.join("low.csv").exists()
}

/// [`identify_folder`] on a thread of its own, set aside after `limit`: the folder is then an
/// error row, and the batch goes on (the fit itself is bounded by its iterations and ends in
/// the background, or with the process).
fn identify_folder_within(folder: &Path, limit: std::time::Duration) -> Row {
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = folder.to_path_buf();
    let spawned = std::thread::Builder::new()
        .name(format!("folder {}", folder_name(folder)))
        .spawn(move || tx.send(identify_folder(&owned)).ok());
    if spawned.is_err() {
        // No thread to spare: fitted here, unbounded but for its iterations.
        return identify_folder(folder);
    }
    match rx.recv_timeout(limit) {
        Ok(row) => row,
        Err(_) => Row {
            name: folder_name(folder),
            method: if has_step_pair(folder) {
                "full"
            } else {
                "output_error"
            },
            outcome: Outcome::Failed {
                bad_input: false,
                message: format!(
                    "{}: no result within --folder-limit {} s: set aside (raise --folder-limit, or identify the folder on its own to see where the time goes)",
                    folder.display(),
                    limit.as_secs_f64()
                ),
            },
            truth: None,
            against: None,
            model_check: None,
            seconds: limit.as_secs_f64(),
        },
    }
}

/// Identifies one motor folder.
fn identify_folder(folder: &Path) -> Row {
    let started = std::time::Instant::now();
    let name = folder_name(folder);
    let truth_path = folder.join("motor.json");
    let truth = truth_path
        .exists()
        .then(|| settings::motor(truth_path.to_str().unwrap_or_default()).ok())
        .flatten();
    let (high, low) = (folder.join("high.csv"), folder.join("low.csv"));
    let (method, result): (&'static str, Result<(FullFit, ModelCheck)>) = if has_step_pair(folder) {
        let fitted = (|| {
            let (hv, lv) = (
                load_step(&high, &ColumnMap::default(), true)?,
                load_step(&low, &ColumnMap::default(), true)?,
            );
            let (hv, lv, _) = in_order(hv, lv);
            let result = identify_pair(&hv, &lv, StepMethod::Full)?;
            let checked = ModelCheck::of_pair(&result, &hv, &lv, &ColumnMap::default());
            let full = result.full.ok_or_else(|| anyhow::anyhow!("no full fit"))?;
            Ok((full, checked))
        })();
        ("full", fitted)
    } else {
        let fitted = (|| {
            let csvs = sorted_paths(std::fs::read_dir(folder)?, |p| {
                p.extension().is_some_and(|x| x == "csv")
            });
            if csvs.is_empty() {
                return Err(BadInput(format!(
                    "{}: no high.csv/low.csv pair and no other *.csv record",
                    folder.display()
                ))
                .into());
            }
            let loaded = csvs
                .iter()
                .map(|p| load_excited(p, &ColumnMap::default(), true))
                .collect::<Result<Vec<LoadedExcited>>>()?;
            let (_, fit) = fit_excited(&loaded, None, &folder.display().to_string(), "")?;
            let checked = ModelCheck::of_excited(&fit, &loaded, &ColumnMap::default());
            Ok((fit, checked))
        })();
        ("output_error", fitted)
    };
    let (outcome, model_check) = match result {
        Ok((fit, checked)) => (Outcome::Fitted(Box::new(fit)), Some(checked)),
        Err(e) => (
            Outcome::Failed {
                bad_input: e.chain().any(|c| c.is::<BadInput>()),
                message: format!("{e:#}"),
            },
            None,
        ),
    };
    let against = match (&outcome, &truth) {
        (Outcome::Fitted(f), Some(t)) => Some(accuracy(&f.params, f.ci95.as_ref(), t)),
        _ => None,
    };
    Row {
        name,
        method,
        outcome,
        truth,
        against,
        model_check,
        seconds: started.elapsed().as_secs_f64(),
    }
}

fn row_json(r: &Row) -> Value {
    let mut obj = json!({"motor": r.name, "method": r.method, "seconds": r.seconds});
    match &r.outcome {
        Outcome::Failed { message, .. } => {
            obj["status"] = json!("error");
            obj["error"] = json!(message);
        }
        Outcome::Fitted(fit) => {
            obj["status"] = json!(status_of(fit));
            if let Some(why) = fit.failure() {
                obj["error"] = json!(why);
            }
            obj["iterations"] = json!(fit.iterations);
            if let Some(check) = &r.model_check {
                obj["model_check"] = check.json();
            }
            let mut params = serde_json::Map::new();
            for (k, e) in parameter_estimates(&fit.params, fit.ci95.as_ref())
                .into_iter()
                .enumerate()
            {
                let mut p = json!({"value": e.value, "ci95": e.ci95});
                if let Some(a) = r.against.as_ref().and_then(|a| a.get(k)) {
                    p["truth"] = json!(a.truth);
                    p["error_percent"] = json!(100.0 * a.relative_error);
                    p["covered"] = json!(a.covered);
                }
                params.insert(e.name.into(), p);
            }
            obj["parameters"] = Value::Object(params);
        }
    }
    obj
}

/// The summary as CSV: one row per motor.
fn summary_csv(rows: &[Row]) -> String {
    // Units in brackets after each name, as in a record's header.
    let mut out = String::from("motor,method,status,iterations,seconds[s]");
    for (name, unit) in PARAM_NAMES.iter().zip(PARAM_UNITS) {
        out.push_str(&format!(
            ",{name}[{unit}],{name}_ci_lo[{unit}],{name}_ci_hi[{unit}],{name}_truth[{unit}],{name}_error[%]"
        ));
    }
    out.push_str(",model_check,error\n");
    for r in rows {
        let (status, iterations, estimates, message) = match &r.outcome {
            Outcome::Fitted(f) => (
                status_of(f),
                f.iterations.to_string(),
                parameter_estimates(&f.params, f.ci95.as_ref()),
                f.failure().unwrap_or_default(),
            ),
            Outcome::Failed { message, .. } => (
                "error",
                String::new(),
                Vec::new(),
                message.replace(['"', '\n'], "'"),
            ),
        };
        let truths = r
            .truth
            .map(|t| parameter_estimates(&t, None))
            .unwrap_or_default();
        out.push_str(&format!(
            "{},{},{status},{iterations},{:.3}",
            r.name, r.method, r.seconds
        ));
        for k in 0..PARAM_NAMES.len() {
            let e = estimates.get(k);
            let ci = e.and_then(|e| e.ci95);
            let error = r.against.as_ref().and_then(|a| a.get(k));
            let cell = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x}"));
            out.push_str(&format!(
                ",{},{},{},{},{}",
                cell(e.map(|e| e.value)),
                cell(ci.map(|c| c[0])),
                cell(ci.map(|c| c[1])),
                cell(truths.get(k).map(|t| t.value)),
                cell(error.map(|a| 100.0 * a.relative_error))
            ));
        }
        let check = match r.model_check.as_ref().and_then(ModelCheck::findings) {
            Some(0) => "noise".to_string(),
            Some(n) => format!("misses ({n} findings)"),
            None => String::new(),
        };
        out.push_str(&format!(",{check},\"{message}\"\n"));
    }
    out
}

/// Identifies every motor folder under `dir` in parallel and writes the summaries.
pub fn run(a: &Settings, dir: &Path) -> Result<()> {
    let folders = motor_folders(dir)?;
    let n = folders.len();
    let threads = parallel::threads(n);
    let started = std::time::Instant::now();
    if !a.quiet {
        crate::console::errln!("identifying {n} motors on {threads} threads…");
    }
    let progress = Jobs::new(n, "motors", a.quiet);
    let rows = parallel::map(
        n,
        |i| identify_folder_within(&folders[i], a.folder_limit),
        |done| progress.done(done, String::new),
    );
    drop(progress);
    let elapsed = started.elapsed().as_secs_f64();
    let csv_path = dir.join("summary.csv");
    let json_path = dir.join("summary.json");
    output::write_generated(&csv_path, summary_csv(&rows).as_bytes())?;
    let ok = rows
        .iter()
        .filter(|r| matches!(&r.outcome, Outcome::Fitted(f) if f.accepted()))
        .count();
    let not_converged = rows
        .iter()
        .filter(|r| matches!(&r.outcome, Outcome::Fitted(f) if !f.accepted()))
        .count();
    let failed = n - ok - not_converged;
    let fitted: Vec<&[ParameterAccuracy]> =
        rows.iter().filter_map(|r| r.against.as_deref()).collect();
    let aggregate: Vec<_> = summarize(fitted.iter().copied())
        .into_iter()
        .map(|p| {
            let median = p.median_abs_relative_error.map_or(f64::NAN, |m| 100.0 * m);
            (p.name, median, p.covered, p.with_ci)
        })
        .collect();
    let report = json!({
        "motors": n, "converged": ok, "not_converged": not_converged, "failed": failed,
        "seconds": elapsed, "threads": threads,
        "against_truth": aggregate.iter().map(|(name, med, cov, with)| json!({
            "parameter": name, "median_abs_error_percent": med, "ci95_covered": cov, "with_ci": with,
        })).collect::<Vec<_>>(),
        "rows": rows.iter().map(row_json).collect::<Vec<_>>(),
    });
    output::write_generated(
        &json_path,
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!(
            "{:<16} {:<13} {:>12} {:>12} {:>12} {:>12} {:>12} {:>12}",
            "motor",
            "status",
            "R",
            "L",
            "k",
            "f",
            "J",
            "Ts"
        )?;
        for r in &rows {
            match &r.outcome {
                Outcome::Fitted(f) => {
                    let p = &f.params;
                    outln!(
                        "{:<16} {:<13} {:>12.5e} {:>12.5e} {:>12.5e} {:>12.5e} {:>12.5e} {:>12.5e}",
                        r.name,
                        status_of(f),
                        p.r_ohm,
                        p.l_henry,
                        p.k_nm_per_a,
                        p.f_nms_per_rad,
                        p.j_kgm2,
                        p.ts_nm
                    )?;
                }
                Outcome::Failed { message, .. } => outln!("{:<16} error: {message}", r.name)?,
            }
        }
        outln!(
            "{n} motors: {ok} identified, {not_converged} not converged or refused, {failed} failed; {elapsed:.1} s on {threads} threads"
        )?;
        let misses: Vec<&str> = rows
            .iter()
            .filter(|r| r.model_check.as_ref().and_then(ModelCheck::findings) > Some(0))
            .map(|r| r.name.as_str())
            .collect();
        if !misses.is_empty() {
            outln!(
                "warning: the model misses something the records of {} of {ok} identified motors show (their residual is not their noise; model_check in {}): {} — motorid diagnose on a folder's records looks for the cause",
                misses.len(),
                json_path.display(),
                misses.join(", ")
            )?;
        }
        if !fitted.is_empty() {
            outln!("against motor.json (median |error|, 95 % intervals containing the truth):")?;
            for (name, med, cov, with) in &aggregate {
                outln!("  {name:<3} {med:>9.4} %   {cov}/{with}")?;
            }
        }
        outln!("wrote {} and {}", csv_path.display(), json_path.display())?;
    }
    let bad = rows.iter().any(|r| {
        matches!(
            r.outcome,
            Outcome::Failed {
                bad_input: true,
                ..
            }
        )
    });
    if bad {
        return Err(BadInput(format!(
            "{failed} of {n} motors could not be identified (see the error column of {})",
            csv_path.display()
        ))
        .into());
    }
    if failed > 0 {
        // No bad input among them: fits that failed, or folders set aside at --folder-limit.
        return Err(NotConverged(format!(
            "{failed} of {n} motors could not be identified (see the error column of {})",
            csv_path.display()
        ))
        .into());
    }
    if not_converged > 0 {
        return Err(NotConverged(format!(
            "{not_converged} of {n} fits did not converge (see {})",
            csv_path.display()
        ))
        .into());
    }
    Ok(())
}

/// A fitted folder's status: `ok`, `refused` (converged to parameters that are no result) or
/// `not converged`.
fn status_of(fit: &fit::FullFit) -> &'static str {
    if fit.accepted() {
        "ok"
    } else if fit.termination.converged() {
        "refused"
    } else {
        "not converged"
    }
}
