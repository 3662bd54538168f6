//! `motorid identify`: motor parameters from step records (or Ts from steady tests).

mod batch;
mod kinds;
mod model_check;
mod options;
mod report;
mod servo;

pub use options::Settings;

use anyhow::Result;
use fit::{
    fit_apparent_resistance, identify_inverse_model_pooled, record_speed, steady_value,
    torque_constant, voltage_input, Drive, ExcitedRecord, FullFit, InverseModelSettings,
    KnownConstants, OffsetStatus, RecordKind, RecordSet, TorqueConstantError, MECHANICAL_NAMES,
};
use serde_json::json;

use std::path::PathBuf;

use crate::commands::identify::model_check::fit_steps;
use crate::commands::identify::model_check::shown_records;
use crate::commands::identify::model_check::ModelCheck;
use crate::commands::identify::model_check::MODEL_CHECK_PHASE;
use crate::commands::identify::options::Axis;
use crate::commands::identify::options::Source;
use crate::commands::identify::report::print_table;
use crate::commands::identify::report::report_json;
use crate::commands::identify::report::sig;
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};
use crate::figures::FigureRecord;
use crate::progress::Phases;
use crate::record_csv::{read_loaded, read_loaded_current_optional, Loaded};
use crate::steps::{
    common_channels, excited_from, file_lines, fit_excited_from, fit_voltage_speed, identify_pair,
    in_order, load_step_pair, measured_channels, StepPair,
};

/// `--steady`: the apparent-resistance law (8) over the steady records at `paths`, and Ts by
/// Eq. (9) from the known R = `r` \[Ω\] and k = `k` \[N·m/A\].
fn run_steady(a: &Settings, paths: &[PathBuf], r: f64, k: f64) -> Result<()> {
    let mut tests = Vec::new();
    for path in paths {
        let loaded = read_loaded(path, &a.columns, true)?;
        let cols = &loaded.record;
        let dt = motor_model::mean_period(&cols.t);
        // The current alone can look steady at its peak: check the speed too where it is
        // recorded.
        let label = file_lines(&path.display().to_string(), &loaded.lines);
        let speed = record_speed(&cols.t, cols.speed.as_deref(), cols.position.as_deref());
        let advice =
            "Eq. (8) needs the steady state — record longer (several mechanical time constants)";
        fit::check_settled_for(&label, "current", &cols.current, dt, advice)
            .and_then(|()| match &speed {
                Some(w) => fit::check_settled_for(&label, "speed", w, dt, advice),
                None => Ok(()),
            })
            .map_err(|e| BadInput(e.to_string()))?;
        let (Some(e), Some(ir)) = (steady_value(&cols.voltage), steady_value(&cols.current)) else {
            return Err(BadInput(format!("{label}: no samples")).into());
        };
        tests.push((e, ir));
    }
    let fit = fit_apparent_resistance(&tests, r, k).map_err(|e| BadInput(e.to_string()))?;
    if a.json {
        let report = json!({
            "method": "steady",
            "a_ohm": fit.a_ohm, "b_ohm_a": fit.b_ohm_a, "ci95": fit.ci95,
            "parameters": {"Ts": {"value": fit.ts_nm, "unit": "N·m"}},
            "points": fit.points.iter().map(|(i, dr)| json!({"Ir": i, "deltaR": dr})).collect::<Vec<_>>(),
            "termination": fit.termination.text(),
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!(
            "apparent resistance, Eq. (8): dR = a - b/Ir over {} tests",
            tests.len()
        )?;
        for ((path, (e, ir)), (_, dr)) in paths.iter().zip(&tests).zip(&fit.points) {
            outln!(
                "  {}: E = {e:.6} V, Ir = {ir:.6} A, dR = {dr:.6} ohm",
                path.display()
            )?;
        }
        outln!(
            "  a = {:.6} ohm, b = {:.6} ohm·A ({})",
            fit.a_ohm,
            fit.b_ohm_a,
            fit.termination.text()
        )?;
        outln!("Ts = k b / a = {:.6} N·m  (Eq. (9))", fit.ts_nm)?;
    }
    if let Some(dir) = &a.plot {
        crate::output::create_dir(dir)?;
        let (lo, hi) = fit
            .points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.0), hi.max(p.0))
            });
        let curve: Vec<(f64, f64)> = (0..=200)
            .map(|j| lo + (hi - lo) * f64::from(j) / 200.0)
            .map(|ir| (ir, fit.a_ohm - fit.b_ohm_a / ir))
            .collect();
        let paths = crate::plot::xy(
            &dir.join("apparent_resistance"),
            &crate::plot::XyPlot {
                title: "Apparent resistance, Eq. (8): dR = a - b/Ir",
                x_label: "steady current Ir [A]",
                y_label: "dR = E/Ir - R [ohm]",
                points: ("tests", &fit.points),
                curve: ("fitted law", &curve),
            },
        )?;
        if !a.quiet {
            for p in paths {
                crate::console::errln!("wrote {}", p.display());
            }
        }
    }
    Ok(())
}

/// `--input current`: J, f, Ts and the offset of a current-driven axis by inverse-model least
/// squares (the EMPS benchmark's IDIM-LS).
fn run_current(a: &Settings, paths: &[PathBuf]) -> Result<()> {
    let recs: Vec<motor_model::Record> = paths
        .iter()
        .map(|p| crate::steps::load_axis_record(p, &a.columns, a.cutoff_hz))
        .collect::<Result<_>>()?;
    let each: Vec<_> = recs.iter().map(|r| measured_channels(r, None)).collect();
    let kind = RecordKind::decide(
        common_channels(&each),
        Drive::Current,
        RecordSet::AnyWaveform,
        a.known,
    )
    .map_err(|why| kinds::refused(&shown_records(paths), why))?;
    let (Some(path), Some(rec)) = (paths.first(), recs.first()) else {
        return Err(BadInput("--input current needs --record FILE.csv".into()).into());
    };
    let shown = shown_records(paths);
    let position = rec.position.as_deref().unwrap_or_default();
    let dt = motor_model::mean_period(&rec.t);
    // The torque constant: given, or from the voltage equation (2a) of the first record when
    // the armature voltage is recorded.
    let input = match a.torque_constant {
        None if !rec.voltage.is_empty() => Some(
            voltage_input(&rec.t, &rec.voltage)
                .map_err(|e| BadInput(format!("{}: {e}", path.display())))?,
        ),
        _ => None,
    };
    let excited = input.as_ref().map(|input| ExcitedRecord {
        input,
        dt,
        current: &rec.current,
        speed: None,
        position: Some(position),
        exclude_current: None,
        exclude_speed: None,
    });
    let (k, k_source) = torque_constant(a.torque_constant, excited.as_ref(), a.cutoff_hz * dt)
        .map_err(|e| match e {
            TorqueConstantError::NotPositive(k) => {
                BadInput(format!("--torque-constant {k}: expected a positive number"))
            }
            TorqueConstantError::VoltageEquation(e) => BadInput(format!(
                "{}: k from the voltage: {e} (give --torque-constant K)",
                path.display()
            )),
            _ => BadInput("--input current needs --torque-constant K (the torque or force per unit of the current column) or a voltage column to estimate it from".into()),
        })?;
    let k_source = k_source.text();
    let torques = crate::steps::axis_torques(&recs, k);
    let axis_records = crate::steps::axis_records(&recs, &torques);
    let settings = InverseModelSettings {
        position_cutoff_hz: a.cutoff_hz,
        position_filter_order: 4,
        decimation: a.decimation,
        fit_offset: true,
    };
    // A fit the data cannot support at these settings is refused (exit 3); unusable records
    // are bad input (exit 2).
    let fit = identify_inverse_model_pooled(&axis_records, settings).map_err(|e| match e {
        fit::FitError::MethodDomain { .. } => {
            anyhow::Error::new(NotConverged(format!("{shown}: {e}")))
        }
        e => BadInput(format!("{shown}: {e}")).into(),
    })?;
    let offset_note = match fit.offset_status {
        OffsetStatus::Fitted => None,
        OffsetStatus::FixedOneDirection => Some(
            "the axis moves one way only: the offset is fixed at 0 and Ts includes any constant load (add a record moving the other way to separate them)",
        ),
        OffsetStatus::FixedBySettings => Some("the offset is fixed at 0"),
        _ => Some("the offset is fixed at 0"),
    };
    let units = match a.axis {
        Axis::Rotary => fit::MECHANICAL_UNITS_ROTARY,
        Axis::Linear => fit::MECHANICAL_UNITS_LINEAR,
    };
    if let Some(dir) = &a.plot {
        crate::output::create_dir(dir)?;
        let Some(f) = fit.fitted.first() else {
            anyhow::bail!("the inverse model returned no fitted samples");
        };
        let t: Vec<f64> = f.t_s.iter().map(|s| rec.t[0] + s).collect();
        let residual = crate::plot::residual(&f.measured, &f.model);
        let (torque_label, residual_label) = match a.axis {
            Axis::Rotary => ("torque k·I [N·m]", "torque residual [N·m]"),
            Axis::Linear => ("force k·I [N]", "force residual [N]"),
        };
        let name = path
            .file_stem()
            .map_or_else(|| "record".into(), |s| s.to_string_lossy().into_owned());
        let panels = [
            crate::plot::Panel {
                y_label: torque_label,
                series: vec![
                    crate::plot::Series {
                        label: "measured (filtered, decimated)",
                        values: &f.measured,
                        color: crate::plot::MEASURED,
                    },
                    crate::plot::Series {
                        label: "J q'' + f q' + Ts sign(q') + offset",
                        values: &f.model,
                        color: crate::plot::MODEL,
                    },
                ],
            },
            crate::plot::Panel {
                y_label: residual_label,
                series: vec![crate::plot::Series {
                    label: "measured - model",
                    values: &residual,
                    color: crate::plot::OTHER,
                }],
            },
        ];
        let written = crate::plot::time_series(
            &dir.join(format!("{name}_inverse_model")),
            &format!("{shown}: inverse model of the current-driven axis"),
            &t,
            &panels,
        )?;
        if !a.quiet {
            for p in written {
                crate::console::errln!("wrote {}", p.display());
            }
        }
    }
    // J (or M), f, Ts and the offset with their names, intervals and units.
    let rows = || {
        fit.estimates(units)
            .into_iter()
            .map(|e| (e.name, e.value, e.ci95, e.unit))
    };
    if a.json {
        let mut parameters = serde_json::Map::new();
        for (name, value, ci, unit) in rows() {
            parameters.insert(
                name.into(),
                json!({"value": value, "ci95": ci, "unit": unit}),
            );
        }
        let report = json!({
            "method": "inverse_model",
            "input": "current",
            "record_kind": kinds::kind_json(&kind),
            "model_check": {"made": false, "reason": "not made by identify for a current-driven axis: motorid diagnose --input current localises the torque residual"},
            "parameters": parameters,
            "quality": {
                "samples_after_decimation": fit.samples,
                "torque_residual_rms": fit.residual_rms,
                "nrmse_fit_percent": fit.nrmse_fit_percent,
                "quantisation_bias": MECHANICAL_NAMES.iter().zip({ let b = fit.quantisation_bias; [b.mass_kg, b.viscous_ns_per_m, b.coulomb_n, b.offset_n] }).map(|(n, b)| (n.to_string(), json!(b))).collect::<serde_json::Map<_, _>>(),
                "correlation": fit.correlation.as_ref().map(|c| json!({
                    "order": &MECHANICAL_NAMES[..c.nrows().min(4)],
                    "matrix": (0..c.nrows()).map(|i| (0..c.ncols()).map(|j| c[(i, j)]).collect::<Vec<f64>>()).collect::<Vec<_>>(),
                })),
            },
            "settings": {"cutoff_hz": a.cutoff_hz, "decimation": a.decimation, "torque_constant": k, "torque_constant_source": k_source},
            "records": paths.len(),
            "offset_fitted": fit.offset_status == OffsetStatus::Fitted,
            "offset_note": offset_note,
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(());
    }
    outln!("{}", kinds::kind_line(&kind))?;
    outln!(
        "inverse model (current-driven axis): torque = J q'' + f q' + Ts sign(q') + offset, from {shown}"
    )?;
    if k_source != "given" {
        outln!("torque constant k = {} from the {k_source}", sig(k))?;
    }
    if let Some(note) = offset_note {
        outln!("note: {note}")?;
    }
    outln!("      {:>12}   {:<27} unit", "value", "95% CI")?;
    for (name, value, ci, unit) in rows() {
        let ci = ci.map_or("-".to_string(), |[lo, hi]| {
            format!("[{}, {}]", sig(lo), sig(hi))
        });
        outln!("  {name:<6} {:>12}   {ci:<27} {unit}", sig(value))?;
    }
    outln!(
        "fit: {} samples after decimation by {}, torque residual RMS {}, fit {:.2} %",
        fit.samples,
        a.decimation,
        sig(fit.residual_rms),
        fit.nrmse_fit_percent
    )?;
    Ok(())
}

/// Identifies the motor (or axis) from the records the settings name and prints the result;
/// exit 3 when a fit did not converge or is refused.
pub fn run(a: &Settings) -> Result<()> {
    let (high, low) = match &a.source {
        Source::Records(paths) if a.drive == Drive::Current => return run_current(a, paths),
        Source::Steady {
            paths,
            resistance_ohm,
            torque_constant,
        } => return run_steady(a, paths, *resistance_ohm, *torque_constant),
        Source::Records(paths) => return run_output_error(a, paths, None),
        Source::Batch(dir) => return batch::run(a, dir),
        Source::Servo { records, validate } => return servo::run(a, records, validate),
        Source::Pair { high, low } => (high, low),
    };
    let map = &a.columns;
    let bytes: u64 = [high, low]
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    let phases = Phases::start_with("identify", a.quiet, fit_steps);
    phases.enter(format!(
        "reading {} and {} ({:.0} MB)",
        high.display(),
        low.display(),
        bytes as f64 / 1e6
    ));
    // `--initial-state steady|free`: the step methods, which start every step from rest, do
    // not apply.
    if let Some(state) = a.initial_state.filter(|s| *s != fit::InitialState::Rest) {
        drop(phases);
        let note = from_rest_note(a, &format!("--initial-state {}", state.name()));
        return run_output_error(a, &[high.clone(), low.clone()], Some(&note));
    }
    let assume_rest = a.initial_state == Some(fit::InitialState::Rest);
    let (hv, lv) = match load_step_pair(high, low, map, a.quiet, assume_rest)? {
        StepPair::Steps(pair) => *pair,
        StepPair::Moving { records, why } => {
            drop(phases);
            let note = from_rest_note(a, &why);
            let [h, l] = *records;
            return fit_output_error(a, &[high.clone(), low.clone()], vec![h, l], Some(&note));
        }
    };
    let kind = RecordKind::decide(
        common_channels(&[hv.channels, lv.channels]),
        Drive::Voltage,
        RecordSet::StepPair,
        KnownConstants::default(),
    )
    .map_err(|why| kinds::refused(&format!("{} / {}", hv.label, lv.label), why))?;
    let (hv, lv, swapped) = in_order(hv, lv);
    if !a.quiet {
        if let Some(note) = swapped {
            crate::console::errln!("note: {note}");
        }
        for s in [&hv, &lv].into_iter().filter(|s| s.mirrored) {
            crate::console::errln!(
                "note: {}: a negative step ({} V), fitted as its mirror image (the model is odd in E, I and the speed)",
                s.label, -s.volts
            );
        }
    }
    let files = [hv.path.as_str(), lv.path.as_str()];
    phases.enter(format!(
        "fitting {} samples",
        hv.current.len() + lv.current.len()
    ));
    let result = identify_pair(&hv, &lv, a.method)?;
    phases.enter(MODEL_CHECK_PHASE.into());
    let check = ModelCheck::of_pair(&result, &hv, &lv, &a.columns);
    drop(phases);
    let why = result.paper.as_ref().map_err(ToString::to_string);
    let paper = why.as_ref().copied().map_err(String::as_str);
    let method = result.route.method_name();
    let full = result.full.as_ref();
    if a.json {
        let mut report = report_json(method, paper, full, &files);
        if let Some(obj) = report.as_object_mut() {
            obj.insert("record_kind".into(), kinds::kind_json(&kind));
            obj.insert("model_check".into(), check.json());
        }
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!("{}", kinds::kind_line(&kind))?;
        let note = result.note();
        let whole = hv.whole.is_some() && lv.whole.is_some();
        print_table(method, whole, paper, full, &files, note.as_deref())?;
        check.print()?;
    }
    if let (Some(dir), Some(f)) = (&a.plot, full) {
        let records = [&hv, &lv].map(|s| FigureRecord {
            path: &s.path,
            t: s.times(),
            voltage: None,
        });
        crate::figures::fit_figures(dir, &records, f, a.quiet)?;
    }
    let outcome = converged(full);
    // The process ends with this command: the records' memory goes back to the system with
    // it, not freed column by column first.
    std::mem::forget((hv, lv));
    outcome
}

/// The note of a step pair fitted whole by output error because the step methods, which start
/// every step from rest, do not apply (`why`: `--initial-state steady|free`, or the records
/// whose first samples show a running motor), written to standard error unless `--quiet` or
/// `--json`.
fn from_rest_note(a: &Settings, why: &str) -> String {
    let note = format!(
        "the step methods need records that start at rest ({why}): both records are fitted whole by output error"
    );
    if !a.quiet && !a.json {
        crate::console::errln!("note: {note}");
    }
    note
}

/// `--record A.csv --record B.csv ...` (or a step pair that does not start at rest): all six
/// parameters by output error on the records at `paths`, each started from the state
/// `--initial-state` gives or its first samples show, or kS, kV, kA (and J, f, Ts with R and k
/// given) from records without a usable current; `note` says why a step pair came here.
fn run_output_error(a: &Settings, paths: &[PathBuf], note: Option<&str>) -> Result<()> {
    let read = paths
        .iter()
        .map(|path| read_loaded_current_optional(path, &a.columns))
        .collect::<Result<Vec<_>>>()?;
    fit_output_error(a, paths, read, note)
}

/// [`run_output_error`] of the records `read` from `paths` (each file is read once: a pipe
/// serves as a file does).
fn fit_output_error(
    a: &Settings,
    paths: &[PathBuf],
    records: Vec<Loaded>,
    note: Option<&str>,
) -> Result<()> {
    let known = a.known;
    let mut channels = Vec::new();
    let mut read = Vec::new();
    for (path, loaded) in paths.iter().zip(records) {
        let c = measured_channels(&loaded.record, loaded.current_lsb);
        let header = loaded.lines.first().map_or(1, |l| l.saturating_sub(1));
        // Each record on its own first, so that a refusal names its file.
        RecordKind::decide(c, Drive::Voltage, RecordSet::AnyWaveform, known)
            .map_err(|why| kinds::refused(&format!("{}:{header}", path.display()), why))?;
        channels.push(c);
        read.push(loaded);
    }
    let kind = RecordKind::decide(
        common_channels(&channels),
        Drive::Voltage,
        RecordSet::AnyWaveform,
        known,
    )
    .map_err(|why| kinds::refused("records", why))?;
    let loaded = paths
        .iter()
        .zip(read)
        .map(|(p, l)| excited_from(p, l, a.quiet))
        .collect::<Result<Vec<_>>>()?;
    let files: Vec<&str> = loaded.iter().map(|l| l.path.as_str()).collect();
    let all = loaded
        .iter()
        .map(|l| l.label.as_str())
        .collect::<Vec<_>>()
        .join(" / ");
    if kind.is_voltage_speed() {
        // A given k fixes the back-EMF's share of kV, which τe couples to the speed: without
        // it that share is a nuisance with a uniform prior, and kA's interval is 5–20 times
        // wider.
        let fit = fit_voltage_speed(&loaded, a.torque_constant, a.initial_state, &all)?;
        return kinds::report(a, &kind, &fit, &files);
    }
    if a.resistance.is_some() || a.torque_constant.is_some() {
        return Err(BadInput(format!(
            "{all}: --resistance and --torque-constant are for records without a usable current; these have one, and R and k are fitted from it"
        ))
        .into());
    }
    let given = a.start;
    let samples: usize = loaded.iter().map(|l| l.record.t.len()).sum();
    let phases = Phases::start_with("identify", a.quiet, fit_steps);
    phases.enter(format!(
        "fitting {} record(s), {samples} samples, by simulation (about 7 simulations per iteration)",
        loaded.len()
    ));
    let fitted = fit_excited_from(
        &loaded,
        a.initial_state,
        given,
        &all,
        " (give a start with --start FILE.json)",
    )?;
    let (start, full) = (fitted.start, fitted.full);
    phases.enter(MODEL_CHECK_PHASE.into());
    let check = ModelCheck::of_excited(&full, &loaded, &a.columns);
    let initial: Vec<(
        &str,
        &fit::DetectedInitialState,
        Option<&fit::FittedInitialState>,
    )> = files
        .iter()
        .zip(&fitted.initial)
        .enumerate()
        .map(|(k, (file, chosen))| (*file, chosen, full.initial_states.get(k)))
        .collect();
    drop(phases);
    if a.json {
        let mut report = report_json(
            "output_error",
            Err("the paper's method needs a high- and a low-voltage step (--high, --low)"),
            Some(&full),
            &files,
        );
        if let Some(obj) = report.as_object_mut() {
            obj.remove("paper_method");
            obj.insert("start".into(), serde_json::to_value(start)?);
            obj.insert(
                "initial_state".into(),
                initial
                    .iter()
                    .map(|(file, chosen, fitted)| {
                        json!({
                            "record": file,
                            "state": chosen.state.name(),
                            "reason": chosen.reason,
                            "current": fitted.map(|f| json!({"value": f.current_a, "unit": "A"})),
                            "speed": fitted.map(|f| json!({"value": f.speed_rad_s, "unit": "rad/s"})),
                        })
                    })
                    .collect(),
            );
            if let Some(note) = note {
                obj.insert("note".into(), note.into());
            }
            obj.insert("record_kind".into(), kinds::kind_json(&kind));
            obj.insert("model_check".into(), check.json());
        }
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!("{}", kinds::kind_line(&kind))?;
        print_table("output_error", false, Err(""), Some(&full), &files, None)?;
        for (file, chosen, fitted) in &initial {
            let at = fitted.map_or(String::new(), |f| {
                format!(
                    "; fitted start: current {} A, speed {} rad/s",
                    sig(f.current_a),
                    sig(f.speed_rad_s)
                )
            });
            outln!(
                "initial state of {file}: {} — {}{at}",
                chosen.state.name(),
                chosen.reason
            )?;
        }
        if let Some(note) = note {
            outln!("note: {note}")?;
        }
        check.print()?;
    }
    if let Some(dir) = &a.plot {
        let records: Vec<FigureRecord> = loaded
            .iter()
            .map(|l| FigureRecord {
                path: &l.path,
                t: l.record.t.clone(),
                voltage: Some(&l.record.voltage),
            })
            .collect();
        crate::figures::fit_figures(dir, &records, &full, a.quiet)?;
    }
    converged(Some(&full))
}

/// Exit status of a full fit: [`NotConverged`] with the reason when the solver gave up or the
/// result is refused.
fn converged(full: Option<&FullFit>) -> Result<()> {
    match full.and_then(FullFit::failure) {
        Some(why) => Err(NotConverged(why).into()),
        None => Ok(()),
    }
}
