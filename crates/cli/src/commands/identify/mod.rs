//! `motorid identify`: motor parameters from step records (or Ts from steady tests).

mod batch;
mod kinds;

use anyhow::Result;
use fit::diagnose::localise::{Localisation, LocaliseSettings};
use fit::{
    fit_apparent_resistance, identify_inverse_model_pooled, parameter_estimates, record_speed,
    steady_value, torque_constant, voltage_input, ChannelQuality, Drive, ExcitedRecord, FullFit,
    InverseModelSettings, KnownConstants, OffsetStatus, PaperIdentification, RecordKind, RecordSet,
    TorqueConstantError, MECHANICAL_NAMES, PARAM_NAMES,
};
use motor_model::{Derived, MotorParams};
use serde_json::{json, Value};

use std::path::PathBuf;

use crate::args::{AxisArg, DriveArg, IdentifyArgs};
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};
use crate::figures::FigureRecord;
use crate::progress::Phases;
use crate::record_csv::{read_loaded, read_loaded_current_optional, ColumnMap, Loaded};
use crate::settings;
use crate::steps::{
    common_channels, excited_from, file_lines, fit_excited_from, fit_voltage_speed, identify_pair,
    in_order, load_step_pair, measured_channels, LoadedExcited, LoadedStep, StepPair,
};

/// Where the records of an identification come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A high- and a low-voltage step record (`--high`, `--low`).
    Pair {
        /// High-voltage step record.
        high: PathBuf,
        /// Low-voltage step record.
        low: PathBuf,
    },
    /// Steady-state records at several voltages (`--steady`), with R \[Ω\] and k \[N·m/A\]
    /// known.
    Steady {
        /// The records.
        paths: Vec<PathBuf>,
        /// Known armature resistance R \[Ω\].
        resistance_ohm: f64,
        /// Known torque constant k \[N·m/A\].
        torque_constant: f64,
    },
    /// Records of any waveform (`--record`), voltage- or current-driven as `drive` says.
    Records(Vec<PathBuf>),
    /// A folder of motor folders (`--batch`).
    Batch(PathBuf),
}

/// Whether positions are angles or lengths (the units of J, f, Ts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Angles in rad: kg·m², N·m·s/rad, N·m.
    Rotary,
    /// Positions in m: kg, N·s/m, N.
    Linear,
}

/// How long one motor folder of `--batch` may take by default \[s\]: ten minutes, far beyond
/// the few seconds a folder of logger records takes.
const DEFAULT_FOLDER_LIMIT_S: f64 = 600.0;
/// The `--folder-limit` values accepted \[s\]: from a microsecond (every folder set aside, as
/// a test of the summary) to about eleven days.
const FOLDER_LIMIT_RANGE_S: (f64, f64) = (1e-6, 1e6);

/// What `motorid identify` identifies and how, validated from its arguments.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The records.
    pub source: Source,
    /// What drives the axis: voltage steps or a current loop.
    pub drive: Drive,
    /// The step-pair method.
    pub method: fit::StepMethod,
    /// `--resistance` R \[Ω\], checked positive (for `--record` files without a current).
    pub resistance: Option<f64>,
    /// `--torque-constant` k \[N·m/A\] (N/A for a linear axis), checked positive.
    pub torque_constant: Option<f64>,
    /// Which of R and k are given.
    pub known: KnownConstants,
    /// The start of the output-error fit, if given.
    pub start: Option<MotorParams>,
    /// Folder for the figures, if asked for.
    pub plot: Option<PathBuf>,
    /// No progress messages or warnings on standard error.
    pub quiet: bool,
    /// One JSON object instead of tables.
    pub json: bool,
    /// Header names of the record columns.
    pub columns: ColumnMap,
    /// Rotary or linear axis.
    pub axis: Axis,
    /// Cut-off of the zero-phase position filter for `--input current` \[Hz\].
    pub cutoff_hz: f64,
    /// Decimation factor for `--input current` (1: none).
    pub decimation: usize,
    /// How each record's simulation starts; `None`: told from its first samples.
    pub initial_state: Option<fit::InitialState>,
    /// `--folder-limit`: how long one motor folder of `--batch` may take before it is set
    /// aside as an error row.
    pub folder_limit: std::time::Duration,
}

impl Settings {
    /// The options of `a`, each checked once, before any record is read: which records,
    /// `--resistance` and `--torque-constant` (positive, and only where they apply),
    /// `--decimation` ≥ 1, `--columns`, `--start`.
    pub fn from_args(a: &IdentifyArgs) -> Result<Settings> {
        if a.resistance.is_some()
            && a.steady.is_empty()
            && (a.record.is_empty() || a.input == DriveArg::Current)
        {
            return Err(BadInput(
                "--resistance is for --steady, or with --torque-constant for --record files of voltage and speed only".into(),
            )
            .into());
        }
        let drive = match a.input {
            DriveArg::Voltage => Drive::Voltage,
            DriveArg::Current => Drive::Current,
        };
        if drive == Drive::Current {
            if a.record.is_empty() {
                return Err(BadInput(
                    "--input current needs --record FILE.csv (current and position of the axis; repeatable: records of one axis are pooled)".into(),
                )
                .into());
            }
            if a.decimation == 0 {
                return Err(BadInput(
                    "--decimation 0: expected a factor of 1 (none) or more".into(),
                )
                .into());
            }
        }
        let source = if drive == Drive::Current {
            Source::Records(a.record.clone())
        } else if !a.steady.is_empty() {
            let (Some(resistance_ohm), Some(torque_constant)) = (a.resistance, a.torque_constant)
            else {
                return Err(BadInput("--steady needs --resistance OHM and --torque-constant NM_PER_A: Sec. 2.2 assumes R and k known".into()).into());
            };
            Source::Steady {
                paths: a.steady.clone(),
                resistance_ohm,
                torque_constant,
            }
        } else if !a.record.is_empty() {
            Source::Records(a.record.clone())
        } else if let Some(dir) = &a.batch {
            Source::Batch(dir.clone())
        } else if let (Some(high), Some(low)) = (&a.high, &a.low) {
            Source::Pair {
                high: high.clone(),
                low: low.clone(),
            }
        } else {
            return Err(BadInput(
                "give --high HV.csv --low LV.csv (step records), or --steady FILE.csv ...".into(),
            )
            .into());
        };
        if a.folder_limit.is_some() && a.batch.is_none() {
            return Err(BadInput(
                "--folder-limit is for --batch DIR: one identification is bounded by its fit's iterations".into(),
            )
            .into());
        }
        let limit_s = a.folder_limit.unwrap_or(DEFAULT_FOLDER_LIMIT_S);
        if !(FOLDER_LIMIT_RANGE_S.0..=FOLDER_LIMIT_RANGE_S.1).contains(&limit_s) {
            return Err(BadInput(format!(
                "--folder-limit {limit_s:.3e}: expected seconds from {:e} to {:e}",
                FOLDER_LIMIT_RANGE_S.0, FOLDER_LIMIT_RANGE_S.1
            ))
            .into());
        }
        let folder_limit = std::time::Duration::from_secs_f64(limit_s);
        let columns = match &a.columns {
            Some(text) => ColumnMap::parse(text)?,
            None => ColumnMap::default(),
        };
        // The steady fit checks its own R and k (Eq. (9)).
        let known = if matches!(source, Source::Steady { .. }) {
            KnownConstants::default()
        } else {
            kinds::known_constants(a.resistance, a.torque_constant)?
        };
        Ok(Settings {
            source,
            drive,
            method: settings::step_method(a.method),
            resistance: a.resistance,
            torque_constant: a.torque_constant,
            known,
            start: a.start.as_deref().map(settings::motor).transpose()?,
            plot: a.plot.clone(),
            quiet: a.quiet,
            json: a.json,
            columns,
            axis: match a.axis {
                AxisArg::Rotary => Axis::Rotary,
                AxisArg::Linear => Axis::Linear,
            },
            cutoff_hz: a.cutoff,
            decimation: a.decimation,
            initial_state: settings::initial_state(a.initial_state),
            folder_limit,
        })
    }
}

/// `x` with 7 significant digits, in plain or scientific notation as suits its size.
fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-4..6).contains(&magnitude) {
        format!("{:.*}", (6 - magnitude).max(0) as usize, x)
    } else {
        format!("{x:.6e}")
    }
}

/// The fit quality of each channel of each record (named from `files`), for `--json`.
fn channels_json(quality: &[ChannelQuality], files: &[&str]) -> Value {
    quality
        .iter()
        .map(|q| {
            json!({
                "record": files.get(q.test), "channel": q.channel.name(), "rms_residual": q.rms_residual,
                "nrmse_fit_percent": q.nrmse_fit_percent, "noise_std": q.noise_std,
            })
        })
        .collect()
}

/// One line per channel of each record (named from `files`): residual RMS, fit, noise.
fn print_channels(quality: &[ChannelQuality], files: &[&str]) -> Result<()> {
    for q in quality {
        outln!(
            "  {} {}: residual RMS {:.3e}, fit {:.3} %, noise {:.3e}",
            files.get(q.test).copied().unwrap_or("?"),
            q.channel.name(),
            q.rms_residual,
            q.nrmse_fit_percent,
            q.noise_std
        )?;
    }
    Ok(())
}

fn paper_json(paper: &PaperIdentification) -> Value {
    let h = &paper.high;
    json!({
        "table3": {"alpha": paper.fit_33.params.alpha, "sigma": paper.fit_33.params.sigma, "wa": paper.fit_33.params.omega_a,
                   "iterations": paper.fit_33.report.iterations, "termination": paper.fit_33.report.termination.text()},
        "table4": {"wn": h.omega_n, "zeta": h.zeta, "tau_m": h.tau_m, "L": h.l_henry, "R": h.r_ohm, "k": h.k_nm_per_a,
                   "f": h.f_nms_per_rad, "J": h.j_kgm2, "Ks": h.k_s, "KE": h.k_e},
        "eq48_Ts": paper.low.ts_nm,
        "eq50_KE": paper.low.k_e,
        "eq51_Ks": paper.low.k_s,
        "steady_values": {"Irm": paper.steady_values.i_rm_a, "Wrm": paper.steady_values.omega_rm_rad_s, "Irb": paper.steady_values.i_rb_a},
        "c8_speed_check": match &paper.speed_check {
            Ok(c) => json!({"wn": c.omega_n, "zeta": c.zeta, "rms": c.rms, "termination": c.termination.text(),
                            "wn_from_current": h.omega_n, "zeta_from_current": h.zeta,
                            "contradiction": paper.speed_check_contradiction()}),
            Err(e) => json!({"failed": e.to_string()}),
        },
    })
}

/// The JSON report: parameters with 95 % CIs and units, derived constants, fit quality.
pub fn report_json(
    method: &str,
    paper: Result<&PaperIdentification, &str>,
    full: Option<&FullFit>,
    files: &[&str],
) -> Value {
    let params = match (full, paper) {
        (Some(f), _) => f.params,
        (None, Ok(p)) => p.params,
        (None, Err(_)) => return Value::Null,
    };
    let mut parameters = serde_json::Map::new();
    for p in parameter_estimates(&params, full.and_then(|f| f.ci95.as_ref())) {
        parameters.insert(
            p.name.into(),
            json!({"value": p.value, "ci95": p.ci95, "unit": p.unit}),
        );
    }
    let quality = match full {
        Some(f) => json!({
            "termination": f.termination.text(),
            "converged": f.accepted(),
            "refusal": f.refusal.as_ref().map(|r| r.to_string()),
            "iterations": f.iterations,
            "weighted_cost": f.cost,
            "correlation": f.correlation.as_ref().map(|c| json!({
                "order": PARAM_NAMES,
                "matrix": (0..6).map(|i| (0..6).map(|j| c[(i, j)]).collect::<Vec<f64>>()).collect::<Vec<_>>(),
            })),
            "channels": channels_json(&f.quality, files),
        }),
        None => match paper {
            Ok(paper) => json!({
                "termination": paper.fit_33.report.termination.text(),
                "converged": paper.fit_33.report.termination.converged(),
                "iterations": paper.fit_33.report.iterations,
                "eq33_residual_rms": (2.0 * paper.fit_33.report.normal.cost / paper.fit_33.report.normal.n_residuals as f64).sqrt(),
            }),
            Err(_) => Value::Null,
        },
    };
    json!({
        "method": method,
        "parameters": parameters,
        "derived": serde_json::to_value(Derived::new(&params)).unwrap_or(Value::Null),
        "quality": quality,
        "paper_method": match paper {
            Ok(p) => paper_json(p),
            Err(why) => json!({"failed": why}),
        },
    })
}

/// The table of `identify`: parameters with intervals, derived constants, fit quality, and
/// `note` (why the full fit did not start from the paper's method) if any; `whole` where the
/// step records return to 0 V and the full fit took them whole.
fn print_table(
    method: &str,
    whole: bool,
    paper: Result<&PaperIdentification, &str>,
    full: Option<&FullFit>,
    files: &[&str],
    note: Option<&str>,
) -> Result<()> {
    let params = match (full, paper) {
        (Some(f), _) => f.params,
        (None, Ok(p)) => p.params,
        (None, Err(_)) => return Ok(()),
    };
    match method {
        "full" if whole => outln!("full model: R, L, k, f, J, Ts fitted jointly to both whole records, rise and return to 0 V (output error, the levels and their instants as uncertain inputs)")?,
        "full" => outln!("full model: R, L, k, f, J, Ts fitted jointly to both records (exact response, breakaway included)")?,
        "paper" => outln!("paper method: fit of Eq. (33), then Eqs. (34)-(51) (the method gives no confidence intervals)")?,
        _ => outln!("output error: R, L, k, f, J, Ts fitted by simulating each record's own voltage (stick-slip model, Appendix D)")?,
    }
    outln!("      {:>12}   {:<27} unit", "value", "95% CI")?;
    let mut poorly = Vec::new();
    for p in parameter_estimates(&params, full.and_then(|f| f.ci95.as_ref())) {
        let ci_text = p.ci95.map_or("-".to_string(), |[lo, hi]| {
            format!("[{}, {}]", sig(lo), sig(hi))
        });
        if let (true, Some(rel)) = (p.poorly_determined(), p.relative_half_width()) {
            poorly.push(format!("{} (±{:.0} %)", p.name, 100.0 * rel));
        }
        outln!(
            "  {:<3} {:>12}   {:<27} {}",
            p.name,
            sig(p.value),
            ci_text,
            p.unit
        )?;
    }
    let d = Derived::new(&params);
    outln!(
        "derived: KE = {:.6} A/V, Ks = {:.6} A/(N·m), tau_e = {:.6} s, tau_m = {:.6} s, wn = {:.6} rad/s, zeta = {:.6}",
        d.k_e, d.k_s, d.tau_e, d.tau_m, d.omega_n, d.zeta
    )?;
    match full {
        Some(f) => {
            match &f.refusal {
                Some(why) if f.termination.converged() => {
                    outln!("fit: FAILED after {} iterations — {why}", f.iterations)?
                }
                _ => outln!(
                    "fit: {} after {} iterations",
                    f.termination.text(),
                    f.iterations
                )?,
            }
            print_channels(&f.quality, files)?;
        }
        None => {
            if let Ok(paper) = paper {
                outln!(
                    "Eq. (33) fit: alpha = {:.6}, sigma = {:.6} 1/s, wa = {:.6} rad/s; {} after {} iterations",
                    paper.fit_33.params.alpha, paper.fit_33.params.sigma, paper.fit_33.params.omega_a,
                    paper.fit_33.report.termination.text(), paper.fit_33.report.iterations
                )?
            }
        }
    }
    if let Ok(paper) = paper {
        match &paper.speed_check {
            Ok(c) => outln!(
                "(C.8) speed check: wn = {:.6} rad/s, zeta = {:.6} from the speed; {:.6}, {:.6} from the current (Eqs. (35), (36))",
                c.omega_n, c.zeta, paper.high.omega_n, paper.high.zeta
            )?,
            Err(e) => outln!("(C.8) speed check not made: {e}")?,
        }
        if let Some(why) = paper.speed_check_contradiction() {
            match full {
                None => outln!("warning: {why} — use the full method (--method full)")?,
                Some(_) => outln!("warning: {why}")?,
            }
        }
    }
    if let Some(why) = note {
        outln!("note: {why}")?;
    }
    if !poorly.is_empty() {
        outln!(
            "warning: poorly determined by these records: {} — the 95% interval is wider than {:.0} % of the value",
            poorly.join(", "),
            100.0 * fit::POORLY_DETERMINED
        )?;
    }
    Ok(())
}

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

/// What the check of an accepted fit's residual against the records' own noise found
/// ([`fit::diagnose::localise_fit`]): its significant findings, or why it was not made; and
/// the `motorid diagnose` command for the same records.
struct ModelCheck {
    result: std::result::Result<Checked, String>,
    diagnose: String,
}

/// A check made: the significant findings, and each channel's noise floor.
struct Checked {
    findings: Vec<fit::diagnose::localise::Finding>,
    floors: Value,
}

impl ModelCheck {
    /// The check of a step pair's full fit ([`fit::StepPairIdentification::localise`]), the
    /// records read with `columns`.
    fn of_pair(
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
    fn of_excited(full: &FullFit, loaded: &[LoadedExcited], columns: &ColumnMap) -> ModelCheck {
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
    fn of(
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
    fn findings(&self) -> Option<usize> {
        self.result.as_ref().ok().map(|c| c.findings.len())
    }

    /// The `model_check` object of `--json`, with the `diagnose` command for the same records.
    fn json(&self) -> Value {
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
    fn print(&self) -> Result<()> {
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
fn shell_word(path: &str) -> String {
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
fn diagnose_command(columns: &ColumnMap, records: &[(&str, &str)]) -> String {
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
fn fit_steps() -> Option<String> {
    let steps = fit::accepted_steps();
    (steps > 0).then(|| format!("{steps} solver steps so far"))
}

/// The phase of the model check, for the progress on standard error.
const MODEL_CHECK_PHASE: &str = "checking the residual against the records' noise";

/// Findings of the model check printed in the table (`--json` gives them all).
const MODEL_CHECK_SHOWN: usize = 4;

/// The files of `paths`, comma-separated, for errors about all of them.
fn shown_records(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Exit status of a full fit: [`NotConverged`] with the reason when the solver gave up or the
/// result is refused.
fn converged(full: Option<&FullFit>) -> Result<()> {
    match full.and_then(FullFit::failure) {
        Some(why) => Err(NotConverged(why).into()),
        None => Ok(()),
    }
}
