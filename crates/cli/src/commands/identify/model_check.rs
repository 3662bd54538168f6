//! The identified model checked against the records' noise: where its residual still stands
//! above the floor, and the `motorid diagnose` command that looks for the cause.

use std::path::PathBuf;

use anyhow::Result;
use fit::diagnose::localise::{Localisation, LocaliseSettings};
use fit::{ExcitedRecord, FullFit};
use serde_json::{json, Value};

use crate::console::outln;
use crate::record_csv::ColumnMap;
use crate::steps::{LoadedExcited, LoadedStep};

/// What the check of an accepted fit's residual against the records' own noise found
/// ([`fit::diagnose::localise_fit`]): its significant findings, or why it was not made; and
/// the `motorid diagnose` command for the same records.
pub(crate) struct ModelCheck {
    pub(crate) result: std::result::Result<Checked, String>,
    pub(crate) diagnose: String,
}

/// A check made: the significant findings, and each channel's noise floor.
pub(crate) struct Checked {
    pub(crate) findings: Vec<fit::diagnose::localise::Finding>,
    pub(crate) floors: Value,
}

impl ModelCheck {
    /// The check of a step pair's full fit ([`fit::StepPairIdentification::localise`]), the
    /// records read with `columns`.
    pub(crate) fn of_pair(
        result: &fit::StepPairIdentification,
        hv: &LoadedStep,
        lv: &LoadedStep,
        columns: &ColumnMap,
    ) -> ModelCheck {
        let names = [hv.path.as_str(), lv.path.as_str()];
        ModelCheck::of(
            result.full.as_ref(),
            diagnose_command(columns, &[("--high", &hv.path), ("--low", &lv.path)]),
            || result.localise(&hv.step_record(), &lv.step_record(), &names),
        )
    }

    /// The check of an output-error fit `full` of the records `loaded`, read with `columns`.
    pub(crate) fn of_excited(
        full: &FullFit,
        loaded: &[LoadedExcited],
        columns: &ColumnMap,
    ) -> ModelCheck {
        let records: Vec<(&str, &str)> = loaded
            .iter()
            .map(|l| ("--record", l.path.as_str()))
            .collect();
        ModelCheck::of(Some(full), diagnose_command(columns, &records), || {
            let excited: Vec<ExcitedRecord> = loaded.iter().map(LoadedExcited::excited).collect();
            let names: Vec<&str> = loaded.iter().map(|l| l.path.as_str()).collect();
            Some(fit::diagnose::localise_fit(
                &excited,
                &full.fitted,
                &names,
                &LocaliseSettings::model_check(),
            ))
        })
    }

    /// The check of `full` when it is accepted, from the localisation `run` makes; a refused
    /// or missing fit is not checked, and says why.
    pub(crate) fn of(
        full: Option<&FullFit>,
        diagnose: String,
        run: impl FnOnce() -> Option<std::result::Result<Localisation, fit::FitError>>,
    ) -> ModelCheck {
        if !full.is_some_and(FullFit::accepted) {
            return ModelCheck {
                result: Err(if full.is_some() {
                    "the fit is refused"
                } else {
                    "the paper's method leaves no residual of the whole records to check (--method full checks it)"
                }
                .into()),
                diagnose,
            };
        }
        let result = match run() {
            Some(Ok(l)) => Ok(Checked {
                findings: l.significant_findings(),
                floors: l
                    .records
                    .iter()
                    .flat_map(|r| {
                        r.channels.iter().map(|c| {
                            json!({"record": r.name, "channel": c.channel.name(), "floor": c.floor})
                        })
                    })
                    .collect(),
            }),
            Some(Err(e)) => Err(e.to_string()),
            None => Err("no fit to check".into()),
        };
        ModelCheck { result, diagnose }
    }

    /// How many findings a check made has: 0 where the residual is the records' noise.
    pub(crate) fn findings(&self) -> Option<usize> {
        self.result.as_ref().ok().map(|c| c.findings.len())
    }

    /// The `model_check` object of `--json`, with the `diagnose` command for the same records.
    pub(crate) fn json(&self) -> Value {
        let diagnose = &self.diagnose;
        match &self.result {
            Ok(c) => json!({
                "made": true,
                "alpha": LocaliseSettings::model_check().alpha,
                "model_misses": !c.findings.is_empty(),
                "findings": c.findings,
                "floors": c.floors,
                "diagnose": (!c.findings.is_empty()).then_some(diagnose),
            }),
            Err(why) => json!({"made": false, "reason": why}),
        }
    }

    /// The warning of the table when the residual is not the records' noise, with the
    /// command that looks for the cause on the same records.
    pub(crate) fn print(&self) -> Result<()> {
        let diagnose = &self.diagnose;
        let Ok(Checked {
            findings: found, ..
        }) = &self.result
        else {
            return Ok(());
        };
        if found.is_empty() {
            return Ok(());
        }
        let shown = found.len().min(MODEL_CHECK_SHOWN);
        outln!(
            "warning: the residual is not the records' noise: the model misses something they show ({} finding(s) at a family-wise false-alarm level of {:e}{}):",
            found.len(),
            LocaliseSettings::model_check().alpha,
            if shown < found.len() {
                format!("; the first {shown}, --json lists all")
            } else {
                String::new()
            }
        )?;
        for f in &found[..shown] {
            outln!("  {}", f.text)?;
        }
        outln!(
            "  The values and intervals above assume the model is complete: where the cause is an effect it lacks, they carry its bias beyond their intervals. `{diagnose}` looks for the effect and refits the motor with it."
        )
    }
}

/// `path` as one word of a POSIX shell command: as it is when it holds only characters no
/// shell treats specially, else in single quotes.
pub(crate) fn shell_word(path: &str) -> String {
    let plain = !path.is_empty()
        && path
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_./,:=+-@%".contains(c));
    if plain {
        path.to_string()
    } else {
        format!("'{}'", path.replace('\'', "'\\''"))
    }
}

/// The `motorid diagnose` command for records given as `records` (`--high`, `--low`,
/// `--record` with their paths), read with `columns`.
pub(crate) fn diagnose_command(columns: &ColumnMap, records: &[(&str, &str)]) -> String {
    let mut words = vec!["motorid".to_string(), "diagnose".to_string()];
    for (option, path) in records {
        words.push(option.to_string());
        words.push(shell_word(path));
    }
    if let Some(columns) = columns.as_option() {
        words.push("--columns".into());
        words.push(shell_word(&columns));
    }
    words.join(" ")
}

/// The fit's progress for the lines on standard error: the steps its solver has taken.
pub(crate) fn fit_steps() -> Option<String> {
    let steps = fit::accepted_steps();
    (steps > 0).then(|| format!("{steps} solver steps so far"))
}

/// The phase of the model check, for the progress on standard error.
pub(crate) const MODEL_CHECK_PHASE: &str = "checking the residual against the records' noise";

/// Findings of the model check printed in the table (`--json` gives them all).
pub(crate) const MODEL_CHECK_SHOWN: usize = 4;

/// The files of `paths`, comma-separated, for errors about all of them.
pub(crate) fn shown_records(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}
