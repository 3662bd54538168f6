//! `motorid diagnose`: reads the records, calls `fit::diagnose`, prints the verdict.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use fit::diagnose::{diagnose, DiagnoseError, DiagnoseProgress, DiagnoseSettings, Diagnosis};
use fit::{equation_error_start, parameter_estimates, ExcitedRecord, StepMethod};
use motor_model::EffectKind;
use serde_json::json;

use crate::args::DiagnoseArgs;
use crate::record_csv::ColumnMap;
use crate::steps::{identify_pair, in_order, load_excited, load_step, LoadedExcited};
use crate::{BadInput, NotConverged};

/// The command's settings, validated from its arguments.
pub struct Settings {
    /// The step pair, when given (`--high`, `--low`): the nominal fit starts from its
    /// identification.
    pair: Option<(PathBuf, PathBuf)>,
    training: Vec<PathBuf>,
    validation: Vec<PathBuf>,
    columns: ColumnMap,
    diagnose: DiagnoseSettings,
    json: bool,
    quiet: bool,
}

/// The options of `a`, each checked: records given, candidates known, `--max-effects` ≥ 1,
/// `--columns`.
pub fn settings(a: &DiagnoseArgs) -> Result<Settings> {
    let mut training: Vec<PathBuf> = a.high.iter().chain(&a.low).cloned().collect();
    training.extend(a.records.iter().cloned());
    if training.is_empty() {
        return Err(BadInput(
            "diagnose needs records: --high HV.csv --low LV.csv, or --record FILE.csv (repeatable)"
                .into(),
        )
        .into());
    }
    let candidates = if a.candidates.is_empty() {
        EffectKind::ALL.to_vec()
    } else {
        a.candidates
            .iter()
            .map(|c| {
                c.trim().parse::<EffectKind>().map_err(|_| {
                    BadInput(format!(
                        "--candidates: unknown effect `{c}`; known: {}",
                        EffectKind::ALL.map(EffectKind::name).join(", ")
                    ))
                })
            })
            .collect::<Result<_, _>>()?
    };
    if a.max_effects == 0 {
        return Err(BadInput("--max-effects 0: give 1 or more".into()).into());
    }
    let columns = match &a.columns {
        Some(text) => ColumnMap::parse(text)?,
        None => ColumnMap::default(),
    };
    Ok(Settings {
        pair: a.high.clone().zip(a.low.clone()),
        training,
        validation: a.validate.clone(),
        columns,
        diagnose: DiagnoseSettings {
            candidates,
            max_effects: a.max_effects,
            ..DiagnoseSettings::default()
        },
        json: a.json,
        quiet: a.quiet,
    })
}

/// Diagnoses the records and prints the verdict.
pub fn run(s: &Settings) -> Result<()> {
    let load = |paths: &[PathBuf]| -> Result<Vec<LoadedExcited>> {
        paths
            .iter()
            .map(|p| load_excited(p, &s.columns, s.quiet || s.json))
            .collect()
    };
    let training = load(&s.training)?;
    let validation = load(&s.validation)?;
    let train: Vec<ExcitedRecord<'_>> = training.iter().map(LoadedExcited::excited).collect();
    let valid: Vec<ExcitedRecord<'_>> = validation.iter().map(LoadedExcited::excited).collect();
    let names: Vec<&str> = training
        .iter()
        .chain(&validation)
        .map(|l| l.path.as_str())
        .collect();
    let label = names.join(", ");
    // The start: the step pair's identification when there is one (the paper's method, else
    // the full step fit), the equation-error estimate otherwise.
    let start = match &s.pair {
        Some((high, low)) => {
            let hv = load_step(high, &s.columns, true)?;
            let lv = load_step(low, &s.columns, true)?;
            let (hv, lv, _) = in_order(hv, lv);
            identify_pair(&hv, &lv, StepMethod::Paper)?
                .params()
                .ok_or_else(|| {
                    BadInput(format!(
                        "{} / {}: the step pair identifies no motor to start from",
                        hv.label, lv.label
                    ))
                })?
        }
        None => equation_error_start(&train).map_err(|e| BadInput(format!("{label}: {e}")))?,
    };
    let t0 = Instant::now();
    let quiet = s.quiet;
    // Progress on standard error once the diagnosis has taken more than a second.
    let progress = move |p: DiagnoseProgress| {
        let elapsed = t0.elapsed().as_secs_f64();
        if quiet || elapsed < 1.0 {
            return;
        }
        match p {
            DiagnoseProgress::Nominal => {
                eprintln!("diagnose: fitting the nominal model ({elapsed:.1} s)")
            }
            DiagnoseProgress::Screening { stage } => {
                eprintln!("diagnose: effect {stage}: screening the candidates ({elapsed:.1} s)")
            }
            DiagnoseProgress::Candidates { stage, done, total } if done > 0 => eprintln!(
                "diagnose: effect {stage}: {done}/{total} candidates refitted ({elapsed:.1} s)"
            ),
            DiagnoseProgress::Candidates { .. } => {}
        }
    };
    let d = match diagnose(&train, &valid, &names, &start, &s.diagnose, &progress) {
        Ok(d) => d,
        Err(DiagnoseError::NominalFailed(why)) => {
            return Err(NotConverged(format!(
                "{label}: the nominal identification failed ({why}); no effect is named on top of a model that is not a result"
            ))
            .into())
        }
        Err(DiagnoseError::Fit(e)) => return Err(BadInput(format!("{label}: {e}")).into()),
        Err(e) => return Err(anyhow::anyhow!("{label}: {e}")),
    };
    if s.json {
        println!("{}", serde_json::to_string_pretty(&report_json(&d))?);
    } else {
        print_report(&d, t0.elapsed().as_secs_f64());
    }
    Ok(())
}

/// The JSON object of the contract: verdict, ambiguous_with, where, effects.
fn report_json(d: &Diagnosis) -> serde_json::Value {
    let first = d.stages.first();
    let effects: Vec<serde_json::Value> = first
        .map(|s| {
            s.candidates
                .iter()
                .map(|c| {
                    json!({
                        "name": c.name,
                        "significant": c.significant,
                        "assessment": c.assessment,
                        "testable": c.testable,
                        "screening": c.screening,
                        "p_value": c.p_value,
                        "heldout_p_value": c.heldout_p_value,
                        "params": c.params.iter().map(|p| json!({
                            "name": p.symbol, "key": p.key, "value": p.value,
                            "ci95": p.ci95, "unit": p.unit,
                        })).collect::<Vec<_>>(),
                        "train_nrmse_before": c.train_nrmse_before,
                        "train_nrmse_after": c.train_nrmse_after,
                        "heldout_nrmse_before": c.heldout_nrmse_before,
                        "heldout_nrmse_after": c.heldout_nrmse_after,
                        "motor_shift": c.motor_shift,
                        "failure": c.failure,
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    let named = d.named();
    json!({
        "verdict": named.first().copied().unwrap_or("none"),
        "ambiguous_with": first.map(|s| s.verdict.ambiguous_with.clone()).unwrap_or_default(),
        "named": named,
        "heldout": d.heldout,
        "nominal_note": d.nominal_note,
        "nominal": parameter_estimates(&d.nominal.params, d.nominal.ci95.as_ref()).iter().map(|e| json!({
            "name": e.name, "unit": e.unit, "value": e.value, "ci95": e.ci95,
        })).collect::<Vec<_>>(),
        "where": d.localisation,
        "findings": d.localisation.significant_findings().iter().take(10).map(|f| f.text.clone()).collect::<Vec<_>>(),
        "effects": effects,
        "stages": d.stages,
    })
}

/// What to do about each effect, for the report's first paragraph.
fn advice(name: &str) -> &'static str {
    match name {
        "stribeck_friction" => "model the friction's fall from its static level with speed (or compensate it near zero speed)",
        "cogging_torque" => "add the torque ripple locked to the shaft angle to the load model (or feed it forward)",
        "current_sensor_lag" => "model the current sensor's filter, or lower its time constant, before closing a current loop on it",
        "thermal_drift" => "let R follow the winding temperature (or identify hot and cold and keep both)",
        "quadratic_drag" => "add the speed-squared load (fan, fluid) to the load model",
        "brush_drop" => "add the brush voltage drop to the electrical model",
        "inductance_saturation" => "let L fall with current in the electrical model (matters for current-loop tuning at high current)",
        _ => "model it",
    }
}

fn print_report(d: &Diagnosis, seconds: f64) {
    let named = d.named();
    let first = d.stages.first();
    match (named.first(), first) {
        (Some(name), Some(stage)) => {
            let c = stage.candidates.iter().find(|c| c.name == *name);
            if let Some(c) = c {
                let size = c
                    .params
                    .iter()
                    .map(|p| match p.ci95 {
                        Some([lo, hi]) => format!(
                            "{} = {:.4e} {} [{:.4e}, {:.4e}]",
                            p.symbol, p.value, p.unit, lo, hi
                        ),
                        None => format!("{} = {:.4e} {}", p.symbol, p.value, p.unit),
                    })
                    .collect::<Vec<_>>()
                    .join(", ");
                let moved: Vec<String> = c
                    .motor_shift
                    .iter()
                    .filter(|m| m.relative.abs() > 0.01)
                    .map(|m| format!("{} {:+.1} %", m.name, 100.0 * m.relative))
                    .collect();
                println!(
                    "Verdict: {name} ({size}). Modelled, it cuts the held-out NRMSE from {:.4} to {:.4} (training {:.4} → {:.4}).{} To do: {}.",
                    c.heldout_nrmse_before,
                    c.heldout_nrmse_after,
                    c.train_nrmse_before,
                    c.train_nrmse_after,
                    if moved.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " Left out, it biases the motor: with it, {}.",
                            moved.join(", ")
                        )
                    },
                    advice(name)
                );
            }
            if !stage.verdict.ambiguous_with.is_empty() {
                println!(
                    "Ambiguous: {} explain(s) the held-out data as well as {name}; a record at another voltage or a reversal would separate them.",
                    stage.verdict.ambiguous_with.join(", ")
                );
            }
            for extra in named.iter().skip(1) {
                println!("Also present, on top of {name}: {extra}.");
            }
        }
        _ => println!(
            "Verdict: none — no candidate effect improves the held-out data significantly: the nominal model explains the records to within their noise."
        ),
    }
    println!("Held-out data: {}. {:.1} s.", d.heldout, seconds);
    if let Some(note) = &d.nominal_note {
        println!("The nominal model alone is not a result here: {note}.");
    }
    let findings = d.localisation.significant_findings();
    if !findings.is_empty() {
        println!("Where the nominal model misses:");
        for f in findings.iter().take(5) {
            println!("  {}", f.text);
        }
    }
    for (k, stage) in d.stages.iter().enumerate() {
        println!(
            "\nstage {} (on top of {}):",
            k + 1,
            if stage.base.is_empty() {
                "the nominal model".to_string()
            } else {
                stage.base.join(" + ")
            }
        );
        println!(
            "  {:<22} {:<20} {:>9} {:>9} {:>17} {:>17}  parameters",
            "effect", "assessment", "score", "p", "train NRMSE", "held-out NRMSE"
        );
        for c in &stage.candidates {
            let score = c
                .screening
                .map_or("-".to_string(), |s| format!("{:.3e}", s.statistic));
            if !c.refitted() {
                println!(
                    "  {:<22} {:<20} {score:>9} {:>9}  {}",
                    c.name,
                    c.assessment.words(),
                    "-",
                    c.failure
                        .as_ref()
                        .map_or("not refitted".to_string(), |why| format!(
                            "refit failed: {why}"
                        ))
                );
                continue;
            }
            let params = c
                .params
                .iter()
                .map(|p| format!("{} {:.3e} {}", p.symbol, p.value, p.unit))
                .collect::<Vec<_>>()
                .join(", ");
            println!(
                "  {:<22} {:<20} {score:>9} {:>9.2e} {:>8.4} → {:<6.4} {:>8.4} → {:<6.4}  {params}",
                c.name,
                c.assessment.words(),
                c.p_value,
                c.train_nrmse_before,
                c.train_nrmse_after,
                c.heldout_nrmse_before,
                c.heldout_nrmse_after
            );
        }
    }
}
