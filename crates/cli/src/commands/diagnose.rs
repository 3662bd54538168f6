//! `motorid diagnose`: reads the records, calls `fit::diagnose`, prints the verdict.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use fit::diagnose::localise::Localisation;
use fit::diagnose::{
    diagnose, diagnose_inverse, Assessment, AxisGeometry, CandidateReport, DiagnoseError,
    DiagnoseProgress, DiagnoseSettings, Diagnosis, InverseDiagnoseSettings, SeparatingTest, Stage,
};
use fit::{equation_error_start, ExcitedRecord, InverseModelSettings, StepMethod};
use motor_model::EffectKind;
use serde_json::json;

use crate::args::{AxisArg, DiagnoseArgs, DriveArg};
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};
use crate::figures::{FigureRecord, ResidualFigure};
use crate::record_csv::{read_loaded, ColumnMap};
use crate::steps::{excited_from, identify_pair, in_order, load_excited, step_from, LoadedExcited};

/// The command's settings, validated from its arguments ([`settings`]).
pub struct Settings {
    /// Whether the first two training records are a step pair (`--high`, `--low`): the
    /// nominal fit starts from its identification.
    pair: bool,
    /// The training records: the step pair first, if any, then the `--record` files.
    training: Vec<PathBuf>,
    validation: Vec<PathBuf>,
    columns: ColumnMap,
    diagnose: DiagnoseSettings,
    /// `--input current`: the inverse model's diagnosis instead of output error.
    current: Option<CurrentDrive>,
    plot: Option<PathBuf>,
    json: bool,
    quiet: bool,
}

/// What `--input current` adds: the current's torque constant and the inverse model's.
struct CurrentDrive {
    /// Torque (force) per unit of the current column \[N·m/A or N/A\].
    torque_constant: f64,
    /// The inverse model's diagnosis (filter cut-off \[Hz\], decimation, axis, candidates).
    inverse: InverseDiagnoseSettings,
}

/// The `--candidates` list, parsed (default: every effect); an effect named twice is refused.
fn candidates(a: &DiagnoseArgs) -> Result<Vec<EffectKind>> {
    if a.candidates.is_empty() {
        return Ok(EffectKind::ALL.to_vec());
    }
    let mut kinds = Vec::with_capacity(a.candidates.len());
    for c in &a.candidates {
        let kind = c.trim().parse::<EffectKind>().map_err(|_| {
            BadInput(format!(
                "--candidates: unknown effect `{c}`; known: {}",
                EffectKind::ALL.map(EffectKind::name).join(", ")
            ))
        })?;
        if kinds.contains(&kind) {
            return Err(BadInput(format!(
                "--candidates: `{}` is named twice; name each effect once",
                kind.name()
            ))
            .into());
        }
        kinds.push(kind);
    }
    Ok(kinds)
}

/// Whether `a` and `b` name the same file: the same device and inode where both exist (links
/// symbolic or hard, `./`, `..`), else the paths as given (`/dev/stdin` twice).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return (x.dev(), x.ino()) == (y.dev(), y.ino());
        }
    }
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// Refuses a record file given twice among `--high`, `--low`, `--record` and `--validate`: a
/// `--validate` record that is also a training record would judge a candidate on data it was
/// fitted to, and a training record given twice (`--high X --low X`) counts its samples twice
/// and is no step pair.
fn distinct_records(a: &DiagnoseArgs) -> Result<()> {
    let given: Vec<(&str, &PathBuf)> = a
        .high
        .iter()
        .map(|p| ("--high", p))
        .chain(a.low.iter().map(|p| ("--low", p)))
        .chain(a.records.iter().map(|p| ("--record", p)))
        .chain(a.validate.iter().map(|p| ("--validate", p)))
        .collect();
    for (k, (flag, path)) in given.iter().enumerate() {
        if let Some((first, earlier)) = given[..k].iter().find(|(_, p)| same_file(p, path)) {
            let what = if *flag == "--validate" && *first != "--validate" {
                "held-out data must differ from training data: give a record not used for training"
            } else {
                "each record counts once: give each file once"
            };
            return Err(BadInput(format!(
                "{flag} {}: the same file as {first} {}; {what}",
                path.display(),
                earlier.display()
            ))
            .into());
        }
    }
    Ok(())
}

/// Validates `a` into [`Settings`]: exit 2 with what to fix.
pub fn settings(a: &DiagnoseArgs) -> Result<Settings> {
    if a.input == DriveArg::Current {
        return current_settings(a);
    }
    // The options of the inverse model mean nothing to a voltage-driven diagnosis: given, they
    // would be ignored without a word.
    let current_only = [
        ("--torque-constant", a.torque_constant.is_some()),
        ("--cutoff", a.cutoff.is_some()),
        ("--decimation", a.decimation.is_some()),
        ("--axis", a.axis.is_some()),
    ];
    if let Some((flag, _)) = current_only.iter().find(|(_, given)| *given) {
        return Err(BadInput(format!(
            "{flag} applies to a current-driven axis only: add --input current (with --record files of current and position), or leave {flag} out"
        ))
        .into());
    }
    let mut training: Vec<PathBuf> = a.high.iter().chain(&a.low).cloned().collect();
    training.extend(a.records.iter().cloned());
    if training.is_empty() {
        return Err(BadInput(
            "diagnose needs records: --high HV.csv --low LV.csv, or --record FILE.csv (repeatable)"
                .into(),
        )
        .into());
    }
    distinct_records(a)?;
    let candidates = candidates(a)?;
    if a.max_effects == 0 {
        return Err(BadInput("--max-effects 0: give 1 or more".into()).into());
    }
    let columns = match &a.columns {
        Some(text) => ColumnMap::parse(text)?,
        None => ColumnMap::default(),
    };
    Ok(Settings {
        pair: a.high.is_some() && a.low.is_some(),
        training,
        validation: a.validate.clone(),
        columns,
        diagnose: DiagnoseSettings {
            candidates,
            max_effects: a.max_effects,
            ..DiagnoseSettings::default()
        },
        current: None,
        plot: a.plot.clone(),
        json: a.json,
        quiet: a.quiet,
    })
}

/// [`settings`] of `--input current`.
fn current_settings(a: &DiagnoseArgs) -> Result<Settings> {
    if a.records.is_empty() || a.high.is_some() {
        return Err(BadInput(
            "diagnose --input current needs --record FILE.csv (current and position of the axis; repeatable), not --high/--low".into(),
        )
        .into());
    }
    distinct_records(a)?;
    let Some(k) = a.torque_constant else {
        return Err(BadInput(
            "diagnose --input current needs --torque-constant K (the torque or force per unit of the current column)".into(),
        )
        .into());
    };
    if !(k.is_finite() && k > 0.0) {
        return Err(BadInput(format!("--torque-constant {k}: expected a positive number")).into());
    }
    let decimation = a.decimation.unwrap_or(crate::args::DEFAULT_DECIMATION);
    if decimation == 0 {
        return Err(
            BadInput("--decimation 0: expected a factor of 1 (none) or more".into()).into(),
        );
    }
    if a.max_effects == 0 {
        return Err(BadInput("--max-effects 0: give 1 or more".into()).into());
    }
    let candidates = candidates(a)?;
    let columns = match &a.columns {
        Some(text) => ColumnMap::parse(text)?,
        None => ColumnMap::default(),
    };
    let geometry = match a.axis.unwrap_or(AxisArg::Rotary) {
        AxisArg::Rotary => AxisGeometry::Rotary,
        AxisArg::Linear => AxisGeometry::Linear,
    };
    Ok(Settings {
        pair: false,
        training: a.records.clone(),
        validation: a.validate.clone(),
        columns,
        diagnose: DiagnoseSettings::default(),
        current: Some(CurrentDrive {
            torque_constant: k,
            inverse: InverseDiagnoseSettings {
                inverse: InverseModelSettings {
                    position_cutoff_hz: a.cutoff.unwrap_or(crate::args::DEFAULT_CUTOFF_HZ),
                    decimation,
                    ..InverseModelSettings::default()
                },
                geometry,
                torque_constant: k,
                candidates,
                max_effects: a.max_effects,
                ..InverseDiagnoseSettings::default()
            },
        }),
        plot: a.plot.clone(),
        json: a.json,
        quiet: a.quiet,
    })
}

/// Loads the records, diagnoses them ([`fit::diagnose`], or the inverse model's
/// [`fit::diagnose::diagnose_inverse`] with `--input current`) and prints the report.
pub fn run(s: &Settings) -> Result<()> {
    if let Some(c) = &s.current {
        return run_current(s, c);
    }
    // Clipping warnings on standard error, unless quiet or the report is JSON.
    let no_warnings = s.quiet || s.json;
    // Each file is read once, so that a pipe (`/dev/stdin`, `<(...)`) serves as a file does:
    // the step pair's records, as read, give the paper's start too.
    let mut pair = Vec::new();
    let mut training = Vec::new();
    for (k, path) in s.training.iter().enumerate() {
        let loaded = read_loaded(path, &s.columns, true)?;
        if s.pair && k < 2 {
            pair.push((path, loaded.clone()));
        }
        training.push(excited_from(path, loaded, no_warnings)?);
    }
    let validation = s
        .validation
        .iter()
        .map(|p| load_excited(p, &s.columns, no_warnings))
        .collect::<Result<Vec<_>>>()?;
    let train: Vec<ExcitedRecord<'_>> = training.iter().map(LoadedExcited::excited).collect();
    let valid: Vec<ExcitedRecord<'_>> = validation.iter().map(LoadedExcited::excited).collect();
    let names: Vec<&str> = training
        .iter()
        .chain(&validation)
        .map(|l| l.path.as_str())
        .collect();
    let label = names.join(", ");
    // The start: the paper's method on the step pair when there is one and it applies, the
    // equation-error estimate otherwise. An unmodelled effect can leave the paper's method
    // without an answer (a 0.3 V brush drop made its Ts negative): the records still go on to
    // the diagnosis, which is there to find that effect.
    let paper_start = match <[_; 2]>::try_from(pair) {
        Ok([(high, hv), (low, lv)]) => {
            let hv = step_from(high, hv, true)?;
            let lv = step_from(low, lv, true)?;
            let (hv, lv, swapped) = in_order(hv, lv);
            if let Some(note) = swapped.filter(|_| !s.quiet) {
                crate::console::errln!("note: {note}");
            }
            identify_pair(&hv, &lv, StepMethod::Paper)
                .ok()
                .and_then(|r| r.params())
        }
        Err(_) => None,
    };
    let start = match paper_start {
        Some(p) => p,
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
                crate::console::errln!("diagnose: fitting the nominal model ({elapsed:.1} s)")
            }
            DiagnoseProgress::Screening { stage } => {
                crate::console::errln!(
                    "diagnose: effect {stage}: screening the candidates ({elapsed:.1} s)"
                )
            }
            DiagnoseProgress::Candidates { stage, done, total } if done > 0 => {
                crate::console::errln!(
                    "diagnose: effect {stage}: {done}/{total} candidates refitted ({elapsed:.1} s)"
                )
            }
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
    let separating = separating_test(&d, &train, &valid);
    let report = Report {
        input: "voltage",
        stages: &d.stages,
        localisation: &d.localisation,
        heldout: &d.heldout,
        nominal_note: d.nominal_note.as_deref(),
        nominal: motor_json(&d),
        separating,
    };
    if s.json {
        outln!("{}", serde_json::to_string_pretty(&report_json(&report))?)?;
    } else {
        print_report(&report, t0.elapsed().as_secs_f64())?;
    }
    if let Some(dir) = &s.plot {
        let records: Vec<FigureRecord> = training
            .iter()
            .chain(&validation)
            .map(|l| FigureRecord {
                path: &l.path,
                t: l.record.t.clone(),
                voltage: None,
            })
            .collect();
        let all: Vec<ExcitedRecord<'_>> = train.iter().chain(&valid).copied().collect();
        let after = d
            .final_model()
            .map(|(motor, effects)| {
                fit::predict_output_error(&all, &motor, &effects).map_err(|e| {
                    anyhow::anyhow!("{label}: predicting the model with its effects: {e}")
                })
            })
            .transpose()?;
        let nominal =
            fit::predict_output_error(&all, &d.nominal.params, &motor_model::Effects::none())
                .map_err(|e| anyhow::anyhow!("{label}: predicting the nominal model: {e}"))?;
        let named = d.named().join(" + ");
        let figures = crate::figures::channel_residuals(&records, &nominal, after.as_deref());
        crate::figures::residual_figures(dir, &figures, &named, s.quiet)?;
    }
    // With no effect named the result is the nominal model: one that is not a result (no
    // intervals, a parameter run off) makes the verdict `none` no result either (exit 3).
    match (d.named().is_empty(), d.nominal_note.as_deref()) {
        (true, Some(note)) => Err(NotConverged(format!(
            "{label}: no effect is named, and the nominal model is not a result ({note}): the verdict `none` rests on it"
        ))
        .into()),
        _ => Ok(()),
    }
}

/// What the report shows, from the diagnosis of a voltage- or a current-driven axis.
struct Report<'a> {
    /// `"voltage"` or `"current"`.
    input: &'static str,
    stages: &'a [Stage],
    localisation: &'a Localisation,
    heldout: &'a str,
    nominal_note: Option<&'a str>,
    /// The nominal model's parameters with units and intervals.
    nominal: serde_json::Value,
    /// The record that would separate an ambiguous verdict, if one is.
    separating: Option<SeparatingTest>,
}

impl Report<'_> {
    /// The effects named, in the order found.
    fn named(&self) -> Vec<&str> {
        fit::diagnose::named_effects(self.stages)
    }
}

/// Whether the candidate was refitted (its figures after are set).
fn refitted(c: &CandidateReport) -> bool {
    c.refitted() || c.train_nrmse_after.is_finite()
}

/// The nominal motor's parameters with units and intervals, for JSON.
fn motor_json(d: &Diagnosis) -> serde_json::Value {
    fit::parameter_estimates(&d.nominal.params, d.nominal.ci95.as_ref())
        .iter()
        .map(|p| json!({"name": p.name, "unit": p.unit, "value": p.value, "ci95": p.ci95}))
        .collect()
}

/// The JSON object of the contract: verdict, ambiguous_with, where, effects.
fn report_json(d: &Report<'_>) -> serde_json::Value {
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
        "input": d.input,
        "heldout": d.heldout,
        "nominal_note": d.nominal_note,
        "nominal": d.nominal,
        "separating_test": d.separating,
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

/// The report as text: the verdict with what to do, the held-out data and the time taken
/// (`seconds`), where the nominal model misses, and each stage's table of candidates.
fn print_report(d: &Report<'_>, seconds: f64) -> Result<()> {
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
                outln!(
                    "Verdict: {name} ({size}). Modelled, it {} the held-out NRMSE from {:.4} to {:.4} (training {:.4} → {:.4}).{} To do: {}.",
                    // The test weighs each channel by its noise, the NRMSE summary by its
                    // signal: the two can disagree.
                    if c.heldout_nrmse_after < c.heldout_nrmse_before {
                        "cuts"
                    } else {
                        "moves"
                    },
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
                )?;
            }
            if !stage.verdict.ambiguous_with.is_empty() {
                outln!(
                    "Ambiguous: {} explain(s) the held-out data as well as {name}.",
                    stage.verdict.ambiguous_with.join(", ")
                )?;
                match &d.separating {
                    Some(t) => outln!("{}", t.text())?,
                    None => outln!("A record at another voltage or a reversal would separate them.")?,
                }
            }
            for extra in named.iter().skip(1) {
                outln!("Also present, on top of {name}: {extra}.")?;
            }
        }
        _ if d.localisation.any_significant() => outln!(
            "Verdict: none — no candidate effect improves the held-out data significantly, yet the nominal model misses by more than the noise floor (where: below): the cause is outside the candidates, or a candidate fitted against its physics."
        )?,
        _ if d.nominal_note.is_some() => outln!(
            "Verdict: none — no candidate effect improves the held-out data significantly, and the nominal model, though within the records' noise, is not a result (below)."
        )?,
        _ => outln!(
            "Verdict: none — no candidate effect improves the held-out data significantly: the nominal model explains the records to within their noise."
        )?,
    }
    outln!("Held-out data: {}. {:.1} s.", d.heldout, seconds)?;
    if let Some(note) = d.nominal_note {
        outln!("The nominal model alone is not a result here: {note}.")?;
    }
    let findings = d.localisation.significant_findings();
    if !findings.is_empty() {
        outln!("Where the nominal model misses:")?;
        for f in findings.iter().take(5) {
            outln!("  {}", f.text)?;
        }
    }
    for (k, stage) in d.stages.iter().enumerate() {
        outln!(
            "\nstage {} (on top of {}):",
            k + 1,
            if stage.base.is_empty() {
                "the nominal model".to_string()
            } else {
                stage.base.join(" + ")
            }
        )?;
        outln!(
            "  {:<22} {:<20} {:>9} {:>9} {:>17} {:>17}  parameters",
            "effect",
            "assessment",
            "score",
            "p",
            "train NRMSE",
            "held-out NRMSE"
        )?;
        for c in &stage.candidates {
            let score = c
                .screening
                .map_or("-".to_string(), |s| format!("{:.3e}", s.statistic));
            if !refitted(c) {
                outln!(
                    "  {:<22} {:<20} {score:>9} {:>9}  {}",
                    c.name,
                    c.assessment.words(),
                    "-",
                    match (&c.failure, c.assessment) {
                        (Some(why), Assessment::NotTestable) => why.clone(),
                        (Some(why), _) => format!("refit failed: {why}"),
                        (None, _) => "not refitted".to_string(),
                    }
                )?;
                continue;
            }
            let params = c
                .params
                .iter()
                .map(|p| format!("{} {:.3e} {}", p.symbol, p.value, p.unit))
                .collect::<Vec<_>>()
                .join(", ");
            let params = match &c.failure {
                Some(why) => format!("{params} ({why})"),
                None => params,
            };
            outln!(
                "  {:<22} {:<20} {score:>9} {:>9.2e} {:>8.4} → {:<6.4} {:>8.4} → {:<6.4}  {params}",
                c.name,
                c.assessment.words(),
                c.p_value,
                c.train_nrmse_before,
                c.train_nrmse_after,
                c.heldout_nrmse_before,
                c.heldout_nrmse_after
            )?;
        }
    }
    Ok(())
}

/// The separating test of an ambiguous verdict, for records like `train` and `valid`: steps
/// up to their largest voltage, durations around their length, at their sample rate.
fn separating_test(
    d: &Diagnosis,
    train: &[ExcitedRecord<'_>],
    valid: &[ExcitedRecord<'_>],
) -> Option<SeparatingTest> {
    let all: Vec<&ExcitedRecord<'_>> = train.iter().chain(valid).collect();
    let peak = all
        .iter()
        .map(|r| r.input.peak_volts().abs())
        .fold(0.0, f64::max);
    let length = all
        .iter()
        .map(|r| r.dt * r.current.len().saturating_sub(1) as f64)
        .fold(0.0, f64::max);
    let rate = all.first().map(|r| 1.0 / r.dt)?;
    fit::diagnose::separating_test(d, peak, length, rate)
}

/// `--input current`: the inverse model's torque residual of a current-driven axis,
/// diagnosed (as `identify --input current` reads its records).
fn run_current(s: &Settings, c: &CurrentDrive) -> Result<()> {
    let k = c.torque_constant;
    let settings = &c.inverse;
    let geometry = settings.geometry;
    let paths: Vec<&PathBuf> = s.training.iter().chain(&s.validation).collect();
    let recs: Vec<motor_model::Record> = paths
        .iter()
        .map(|p| crate::steps::load_axis_record(p, &s.columns, settings.inverse.position_cutoff_hz))
        .collect::<Result<_>>()?;
    let torques = crate::steps::axis_torques(&recs, k);
    let axis = crate::steps::axis_records(&recs, &torques);
    let (train, valid) = axis.split_at(s.training.len());
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let label = names.join(", ");
    let t0 = Instant::now();
    let d = match diagnose_inverse(train, valid, &names, settings) {
        Ok(d) => d,
        Err(DiagnoseError::NominalFailed(why)) => {
            return Err(NotConverged(format!(
                "{label}: the inverse-model identification failed ({why}); no effect is named on top of a model that is not a result"
            ))
            .into())
        }
        Err(e) => return Err(BadInput(format!("{label}: {e}")).into()),
    };
    let nominal: serde_json::Value = d
        .nominal
        .estimates(geometry.units())
        .iter()
        .map(|e| json!({"name": e.name, "unit": e.unit, "value": e.value, "ci95": e.ci95}))
        .collect();
    let report = Report {
        input: "current",
        stages: &d.stages,
        localisation: &d.localisation,
        heldout: &d.heldout,
        nominal_note: None,
        nominal,
        separating: None,
    };
    if s.json {
        outln!("{}", serde_json::to_string_pretty(&report_json(&report))?)?;
    } else {
        outln!(
            "inverse model of the current-driven axis (torque = J q'' + f q' + Ts sign(q') + offset): its torque residual, localised in the unit of the current column (residual / {k})"
        )?;
        print_report(&report, t0.elapsed().as_secs_f64())?;
    }
    if let Some(dir) = &s.plot {
        let (torque_label, residual_label) = match geometry {
            AxisGeometry::Rotary => ("torque", "torque residual [N·m]"),
            AxisGeometry::Linear => ("force", "force residual [N]"),
        };
        let named = d.named().join(" + ");
        let figures: Vec<ResidualFigure<'_>> = d
            .traces
            .iter()
            .zip(&names)
            .enumerate()
            .map(|(record, (trace, name))| ResidualFigure {
                record,
                path: name,
                channel: torque_label,
                y_label: residual_label,
                t: trace.t_s.clone(),
                before: crate::plot::residual(&trace.measured, &trace.models[0]),
                after: (trace.models.len() > 1).then(|| {
                    crate::plot::residual(&trace.measured, &trace.models[trace.models.len() - 1])
                }),
            })
            .collect();
        crate::figures::residual_figures(dir, &figures, &named, s.quiet)?;
    }
    Ok(())
}
