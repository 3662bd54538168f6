//! `motorid identify`: motor parameters from step records (or Ts from steady tests).

use std::path::Path;

use anyhow::Result;
use fit::{
    electrical_equation, equation_error_start, fit_apparent_resistance, identify_full_with_inputs,
    identify_inverse_model, identify_output_error_with_inputs, identify_paper, locate_step_with,
    steady_state_start, voltage_input, voltage_levels, ExcitedRecord, FullFit,
    InverseModelSettings, LevelPrior, LmSettings, PaperIdentification, StepInputs, StepTest,
    MECHANICAL_NAMES, PARAM_NAMES, PARAM_UNITS,
};
use motor_model::{central_difference, Derived, Input, MotorParams, Record};
use serde_json::{json, Value};

use crate::args::{AxisArg, DriveArg, IdentifyArgs, MethodArg};
use crate::record_csv::{read_loaded, read_mapped, ColumnMap, Loaded};
use crate::{BadInput, NotConverged};

/// A 95 % interval wider than this fraction of the value marks a poorly determined parameter.
const POORLY_DETERMINED: f64 = 0.1;

/// A step record read and located: owns the columns the [`StepTest`] borrows.
pub struct LoadedStep {
    /// File it came from.
    pub path: String,
    /// The file with the line span of its samples (`hv.csv:7-50007`), for errors.
    pub label: String,
    volts: f64,
    /// Whether the step was negative: its channels are kept with their signs reversed.
    pub mirrored: bool,
    dt: f64,
    current: Vec<f64>,
    speed: Option<Vec<f64>>,
    position: Option<Vec<f64>>,
    exclude_current: Option<Vec<bool>>,
    exclude_speed: Option<Vec<bool>>,
    /// What the record leaves unknown about the step (height and instant).
    pub inputs: StepInputs,
}

impl LoadedStep {
    /// Whether any sample is left out as clipped.
    pub fn has_clipping(&self) -> bool {
        self.exclude_current.is_some() || self.exclude_speed.is_some()
    }

    /// The identification's view of the record.
    pub fn test(&self) -> StepTest<'_> {
        StepTest {
            volts: self.volts,
            t_first: 0.0,
            dt: self.dt,
            current: &self.current,
            speed: self.speed.as_deref(),
            position: self.position.as_deref(),
            exclude_current: self.exclude_current.as_deref(),
            exclude_speed: self.exclude_speed.as_deref(),
        }
    }
}

/// Samples of current and speed to leave out, `None` where nothing is clipped.
pub type ClipMasks = (Option<Vec<bool>>, Option<Vec<bool>>);

/// Largest fraction of a channel that may sit on an ADC rail before the record is refused.
const MAX_CLIPPED_FRACTION: f64 = 0.25;
/// Largest fraction of the voltage that may be clipped: the fits take the voltage as known.
const MAX_CLIPPED_VOLTAGE: f64 = 0.01;

/// Refuses a record whose clipping hides too much, and warns (unless `quiet`) about the rest:
/// those samples are left out of the fits. Returns the masks of current and speed, `None` where
/// nothing is clipped.
pub fn check_clipping(shown: &str, loaded: &Loaded, quiet: bool) -> Result<ClipMasks> {
    let report = loaded.clipping_report();
    let fraction = |m: &[bool]| m.iter().filter(|&&x| x).count() as f64 / m.len().max(1) as f64;
    let limits = [
        MAX_CLIPPED_VOLTAGE,
        MAX_CLIPPED_FRACTION,
        MAX_CLIPPED_FRACTION,
    ];
    let mut line = report.iter();
    for (c, mask) in loaded.clipped.iter().enumerate() {
        if mask.iter().any(|&x| x) {
            let text = line.next().cloned().unwrap_or_default();
            if fraction(mask) > limits[c] {
                let what = if c == 0 {
                    "the fits need the applied voltage"
                } else {
                    "too much of the record is lost"
                };
                return Err(BadInput(format!(
                    "{shown}: {text}: {what}; record again with a wider range"
                ))
                .into());
            }
            if !quiet {
                eprintln!("warning: {shown}: {text}; those samples are left out of the fit");
            }
        }
    }
    let mask = |m: &Vec<bool>| m.iter().any(|&x| x).then(|| m.clone());
    Ok((mask(&loaded.clipped[1]), mask(&loaded.clipped[2])))
}

/// Reads `path`, finds the step and keeps the samples from it on; clipped samples are left out
/// of the fits (and a record with too many is refused).
pub fn load_step(path: &Path, map: &ColumnMap, quiet: bool) -> Result<LoadedStep> {
    let shown = path.display().to_string();
    let loaded = read_loaded(path, map, true)?;
    let (exclude_current, exclude_speed) = check_clipping(&shown, &loaded, quiet)?;
    let label = file_lines(&shown, &loaded.lines);
    let mut step = step_from_record_with(label, loaded.record, loaded.voltage_lsb)?;
    step.inputs.current_lsb_a = loaded.current_lsb.unwrap_or(0.0);
    step.path = shown;
    let from = loaded.lines.len() - step.current.len();
    step.exclude_current = exclude_current.map(|m| m[from..].to_vec());
    // The encoder speed has no ADC: only a tachometer column can be clipped.
    if step.position.is_none() {
        step.exclude_speed = exclude_speed.map(|m| m[from..].to_vec());
    }
    Ok(step)
}

/// Finds the step in a record (named `shown` in errors) and keeps the samples from it on. Speed
/// (for the paper method's Ωrm) comes from the `position` column ([`encoder_speed`]), else the
/// `speed` column; the full fit uses the encoder angle where there is one.
pub fn step_from_record(shown: String, cols: Record) -> Result<LoadedStep> {
    step_from_record_with(shown, cols, None)
}

/// [`step_from_record`] with the voltage's ADC step `voltage_lsb` \[V\] if known (a noise-free
/// quantised step height is known only to ±½ step).
pub fn step_from_record_with(
    shown: String,
    cols: Record,
    voltage_lsb: Option<f64>,
) -> Result<LoadedStep> {
    let loc = locate_step_with(&cols.t, &cols.voltage, voltage_lsb)
        .map_err(|e| BadInput(format!("{shown}: {e}")))?;
    let from = loc.index;
    // Eq. (1)-(2) with Coulomb friction opposing the motion are odd in (E, I, Ω, θ): a
    // negative step from rest is the mirror image of a positive one, and is fitted as such.
    let sign = if loc.volts < 0.0 { -1.0 } else { 1.0 };
    let tail = |v: &[f64]| v[from..].iter().map(|x| sign * x).collect::<Vec<f64>>();
    // The encoder first, as the paper did (and as the full fit does): a speed column beside it
    // may be a one-sample difference of the same encoder, quantised to 0 or 157 rad/s at
    // 100 kHz.
    let speed = match (&cols.speed, &cols.position) {
        (_, Some(p)) => Some(tail(&encoder_speed(&cols.t, p))),
        (Some(s), None) => Some(tail(s)),
        (None, None) => None,
    };
    Ok(LoadedStep {
        label: shown.clone(),
        path: shown,
        volts: sign * loc.volts,
        mirrored: sign < 0.0,
        dt: loc.dt,
        current: tail(&cols.current),
        speed,
        position: cols.position.as_deref().map(tail),
        exclude_current: None,
        exclude_speed: None,
        inputs: loc.inputs(),
    })
}

/// Shortest time base \[s\] of the speed taken from the encoder for the paper's method: at
/// 100 kHz a 2000-count encoder moves half a count per sample at 160 rad/s, and the central
/// difference of one sample reads 0 or 157 rad/s (the last sample is the method's Ωrm).
const ENCODER_SPEED_BASE_S: f64 = 1e-3;

/// Speed \[rad/s\] from the encoder angle `theta` by differences over ±m samples, m the
/// fewest that span [`ENCODER_SPEED_BASE_S`] (m = 1, the central difference, at 1 kHz and
/// below); one-sided near the ends.
fn encoder_speed(t: &[f64], theta: &[f64]) -> Vec<f64> {
    let n = t.len().min(theta.len());
    let dt = motor_model::mean_period(t);
    let m = if dt > 0.0 {
        ((0.5 * ENCODER_SPEED_BASE_S / dt).ceil() as usize).max(1)
    } else {
        1
    };
    if m == 1 {
        return central_difference(t, theta);
    }
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(m), (i + m).min(n - 1));
            (theta[b] - theta[a]) / (t[b] - t[a])
        })
        .collect()
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
        "steady_values": {"Irm": paper.steady_values[0], "Wrm": paper.steady_values[1], "Irb": paper.steady_values[2]},
        "c8_speed_check": match &paper.speed_check {
            Ok(c) => json!({"wn": c.omega_n, "zeta": c.zeta, "rms": c.rms, "termination": c.termination.text(),
                            "wn_from_current": h.omega_n, "zeta_from_current": h.zeta}),
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
    let v = params.values();
    let mut parameters = serde_json::Map::new();
    for i in 0..6 {
        let ci = full.and_then(|f| f.ci95).map(|c| json!(c[i]));
        parameters.insert(
            PARAM_NAMES[i].into(),
            json!({"value": v[i], "ci95": ci, "unit": PARAM_UNITS[i]}),
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
            "channels": f.quality.iter().map(|q| json!({
                "record": files[q.test], "channel": q.channel.name(), "rms_residual": q.rms_residual,
                "nrmse_fit_percent": q.nrmse_fit_percent, "noise_std": q.noise_std,
            })).collect::<Vec<_>>(),
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

fn print_table(
    method: &str,
    paper: Result<&PaperIdentification, &str>,
    full: Option<&FullFit>,
    files: &[&str],
) {
    let params = match (full, paper) {
        (Some(f), _) => f.params,
        (None, Ok(p)) => p.params,
        (None, Err(_)) => return,
    };
    let v = params.values();
    match method {
        "full" => println!("full model: R, L, k, f, J, Ts fitted jointly to both records (exact response, breakaway included)"),
        "paper" => println!("paper method: fit of Eq. (33), then Eqs. (34)-(51) (the method gives no confidence intervals)"),
        _ => println!("output error: R, L, k, f, J, Ts fitted by simulating each record's own voltage (stick-slip model, Appendix D)"),
    }
    println!("      {:>12}   {:<27} unit", "value", "95% CI");
    let mut poorly = Vec::new();
    for i in 0..6 {
        let ci = full.and_then(|f| f.ci95).map(|c| c[i]);
        let ci_text = ci.map_or("-".to_string(), |[lo, hi]| {
            format!("[{}, {}]", sig(lo), sig(hi))
        });
        if let Some([lo, hi]) = ci {
            let rel = 0.5 * (hi - lo) / v[i];
            if rel > POORLY_DETERMINED {
                poorly.push(format!("{} (±{:.0} %)", PARAM_NAMES[i], 100.0 * rel));
            }
        }
        println!(
            "  {:<3} {:>12}   {:<27} {}",
            PARAM_NAMES[i],
            sig(v[i]),
            ci_text,
            PARAM_UNITS[i]
        );
    }
    let d = Derived::new(&params);
    println!(
        "derived: KE = {:.6} A/V, Ks = {:.6} A/(N·m), tau_e = {:.6} s, tau_m = {:.6} s, wn = {:.6} rad/s, zeta = {:.6}",
        d.k_e, d.k_s, d.tau_e, d.tau_m, d.omega_n, d.zeta
    );
    match full {
        Some(f) => {
            match &f.refusal {
                Some(why) if f.termination.converged() => {
                    println!("fit: FAILED after {} iterations — {why}", f.iterations)
                }
                _ => println!(
                    "fit: {} after {} iterations",
                    f.termination.text(),
                    f.iterations
                ),
            }
            for q in &f.quality {
                println!(
                    "  {} {}: residual RMS {:.3e}, fit {:.3} %, noise {:.3e}",
                    files[q.test],
                    q.channel.name(),
                    q.rms_residual,
                    q.nrmse_fit_percent,
                    q.noise_std
                );
            }
        }
        None => {
            if let Ok(paper) = paper {
                println!(
                    "Eq. (33) fit: alpha = {:.6}, sigma = {:.6} 1/s, wa = {:.6} rad/s; {} after {} iterations",
                    paper.fit_33.params.alpha, paper.fit_33.params.sigma, paper.fit_33.params.omega_a,
                    paper.fit_33.report.termination.text(), paper.fit_33.report.iterations
                )
            }
        }
    }
    if let Ok(paper) = paper {
        match &paper.speed_check {
            Ok(c) => println!(
                "(C.8) speed check: wn = {:.6} rad/s, zeta = {:.6} from the speed; {:.6}, {:.6} from the current (Eqs. (35), (36))",
                c.omega_n, c.zeta, paper.high.omega_n, paper.high.zeta
            ),
            Err(e) => println!("(C.8) speed check not made: {e}"),
        }
    }
    if let (Err(why), Some(_), "full") = (paper, full, method) {
        println!("note: the paper's method does not apply to these records ({why}); the full fit started from the steady states instead");
    }
    if !poorly.is_empty() {
        println!(
            "warning: poorly determined by these records: {} — the 95% interval is wider than {:.0} % of the value",
            poorly.join(", "),
            100.0 * POORLY_DETERMINED
        );
    }
}

fn run_steady(a: &IdentifyArgs) -> Result<()> {
    let (Some(r), Some(k)) = (a.resistance, a.torque_constant) else {
        return Err(BadInput("--steady needs --resistance OHM and --torque-constant NM_PER_A: Sec. 2.2 assumes R and k known".into()).into());
    };
    let mut tests = Vec::new();
    for path in &a.steady {
        let loaded = read_loaded(path, &column_map(a)?, true)?;
        let cols = &loaded.record;
        let dt = motor_model::mean_period(&cols.t);
        // The current alone can look steady at its peak: check the speed too where it is
        // recorded.
        let label = file_lines(&path.display().to_string(), &loaded.lines);
        let speed = match (&cols.position, &cols.speed) {
            (Some(p), _) => Some(central_difference(&cols.t, p)),
            (None, Some(w)) => Some(w.clone()),
            (None, None) => None,
        };
        let advice =
            "Eq. (8) needs the steady state — record longer (several mechanical time constants)";
        fit::check_settled_for(&label, "current", &cols.current, dt, advice)
            .and_then(|()| match &speed {
                Some(w) => fit::check_settled_for(&label, "speed", w, dt, advice),
                None => Ok(()),
            })
            .map_err(|e| BadInput(e.to_string()))?;
        // Steady values: medians of the last tenth of the record.
        let tail = |v: &[f64]| {
            let mut t = v[v.len() - (v.len() / 10).max(1)..].to_vec();
            let mid = t.len() / 2;
            *t.select_nth_unstable_by(mid, f64::total_cmp).1
        };
        tests.push((tail(&cols.voltage), tail(&cols.current)));
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
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "apparent resistance, Eq. (8): dR = a - b/Ir over {} tests",
            tests.len()
        );
        for ((path, (e, ir)), (_, dr)) in a.steady.iter().zip(&tests).zip(&fit.points) {
            println!(
                "  {}: E = {e:.6} V, Ir = {ir:.6} A, dR = {dr:.6} ohm",
                path.display()
            );
        }
        println!(
            "  a = {:.6} ohm, b = {:.6} ohm·A ({})",
            fit.a_ohm,
            fit.b_ohm_a,
            fit.termination.text()
        );
        println!("Ts = k b / a = {:.6} N·m  (Eq. (9))", fit.ts_nm);
    }
    if let Some(dir) = &a.plot {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
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
                eprintln!("wrote {}", p.display());
            }
        }
    }
    Ok(())
}

/// `--input current`: J, f, Ts and the offset of a current-driven axis by inverse-model least
/// squares (the EMPS benchmark's IDIM-LS).
fn run_current(a: &IdentifyArgs) -> Result<()> {
    let path = match a.record.as_slice() {
        [one] => one,
        [] => {
            return Err(BadInput(
                "--input current needs --record FILE.csv (current and position of the axis)".into(),
            )
            .into())
        }
        more => {
            return Err(BadInput(format!(
                "--input current identifies one record; {} were given",
                more.len()
            ))
            .into())
        }
    };
    if a.decimation == 0 {
        return Err(
            BadInput("--decimation 0: expected a factor of 1 (none) or more".into()).into(),
        );
    }
    let rec = read_mapped(path, &column_map(a)?, false)?;
    let shown = path.display();
    let position = rec.position.as_ref().ok_or_else(|| {
        BadInput(format!("{shown}: no position column: --input current fits J, f, Ts from the position (map it with --columns position=HEADER)"))
    })?;
    let dt = motor_model::mean_period(&rec.t);
    // The torque constant: given, or from the voltage equation (2a) when the armature voltage
    // is recorded.
    let (k, k_source) = match a.torque_constant {
        Some(k) if k.is_finite() && k > 0.0 => (k, "given"),
        Some(k) => {
            return Err(BadInput(format!("--torque-constant {k}: expected a positive number")).into())
        }
        None if !rec.voltage.is_empty() => {
            let input = voltage_input(&rec.t, &rec.voltage)
                .map_err(|e| BadInput(format!("{shown}: {e}")))?;
            let excited = ExcitedRecord {
                input: &input,
                dt,
                current: &rec.current,
                speed: None,
                position: Some(position),
                exclude_current: None,
                exclude_speed: None,
            };
            let [_, _, k] = electrical_equation(&[excited], a.cutoff * dt)
                .map_err(|e| BadInput(format!("{shown}: k from the voltage: {e} (give --torque-constant K)")))?;
            (k, "voltage equation (2a)")
        }
        None => {
            return Err(BadInput("--input current needs --torque-constant K (the torque or force per unit of the current column) or a voltage column to estimate it from".into()).into())
        }
    };
    let torque: Vec<f64> = rec.current.iter().map(|i| k * i).collect();
    let settings = InverseModelSettings {
        position_cutoff_hz: a.cutoff,
        position_filter_order: 4,
        decimation: a.decimation,
        fit_offset: true,
    };
    let fit = identify_inverse_model(dt, &torque, position, settings)
        .map_err(|e| BadInput(format!("{shown}: {e}")))?;
    let units = match a.axis {
        AxisArg::Rotary => ["kg·m²", "N·m·s/rad", "N·m", "N·m"],
        AxisArg::Linear => ["kg", "N·s/m", "N", "N"],
    };
    if let Some(dir) = &a.plot {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
        let Some(f) = fit.fitted.first() else {
            anyhow::bail!("the inverse model returned no fitted samples");
        };
        let t: Vec<f64> = f.t_s.iter().map(|s| rec.t[0] + s).collect();
        let residual: Vec<f64> = f
            .measured
            .iter()
            .zip(&f.model)
            .map(|(y, m)| y - m)
            .collect();
        let (torque_label, residual_label) = match a.axis {
            AxisArg::Rotary => ("torque k·I [N·m]", "torque residual [N·m]"),
            AxisArg::Linear => ("force k·I [N]", "force residual [N]"),
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
                eprintln!("wrote {}", p.display());
            }
        }
    }
    if a.json {
        let mut parameters = serde_json::Map::new();
        for i in 0..4 {
            parameters.insert(
                MECHANICAL_NAMES[i].into(),
                json!({"value": fit.values[i], "ci95": fit.ci95.map(|c| c[i]), "unit": units[i]}),
            );
        }
        let report = json!({
            "method": "inverse_model",
            "input": "current",
            "parameters": parameters,
            "quality": {
                "samples_after_decimation": fit.samples,
                "torque_residual_rms": fit.residual_rms,
                "nrmse_fit_percent": fit.nrmse_fit_percent,
                "correlation": fit.correlation.as_ref().map(|c| json!({
                    "order": MECHANICAL_NAMES,
                    "matrix": (0..4).map(|i| (0..4).map(|j| c[(i, j)]).collect::<Vec<f64>>()).collect::<Vec<_>>(),
                })),
            },
            "settings": {"cutoff_hz": a.cutoff, "decimation": a.decimation, "torque_constant": k, "torque_constant_source": k_source},
        });
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "inverse model (current-driven axis): torque = J q'' + f q' + Ts sign(q') + offset, from {shown}"
    );
    if k_source != "given" {
        println!("torque constant k = {} from the {k_source}", sig(k));
    }
    println!("      {:>12}   {:<27} unit", "value", "95% CI");
    for i in 0..4 {
        let ci = fit.ci95.map_or("-".to_string(), |c| {
            format!("[{}, {}]", sig(c[i][0]), sig(c[i][1]))
        });
        println!(
            "  {:<6} {:>12}   {:<27} {}",
            MECHANICAL_NAMES[i],
            sig(fit.values[i]),
            ci,
            units[i]
        );
    }
    println!(
        "fit: {} samples after decimation by {}, torque residual RMS {}, fit {:.2} %",
        fit.samples,
        a.decimation,
        sig(fit.residual_rms),
        fit.nrmse_fit_percent
    );
    Ok(())
}

pub fn run(a: &IdentifyArgs) -> Result<()> {
    if a.input == DriveArg::Current {
        return run_current(a);
    }
    if !a.steady.is_empty() {
        return run_steady(a);
    }
    if !a.record.is_empty() {
        return run_records(a);
    }
    if let Some(dir) = &a.batch {
        return crate::commands::batch::run(a, dir);
    }
    let (Some(high), Some(low)) = (&a.high, &a.low) else {
        return Err(BadInput(
            "give --high HV.csv --low LV.csv (step records), or --steady FILE.csv ...".into(),
        )
        .into());
    };
    let map = column_map(a)?;
    let clock = std::time::Instant::now();
    let bytes: u64 = [high, low]
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    // About a second of reading on this kind of machine.
    let long = bytes > 50_000_000 && !a.quiet;
    if long {
        eprintln!(
            "reading {} and {} ({:.0} MB)…",
            high.display(),
            low.display(),
            bytes as f64 / 1e6
        );
    }
    let (hv, lv) = (
        load_step(high, &map, a.quiet)?,
        load_step(low, &map, a.quiet)?,
    );
    let (hv, lv, swapped) = in_order(hv, lv);
    if !a.quiet {
        if let Some(note) = swapped {
            eprintln!("note: {note}");
        }
        for s in [&hv, &lv].into_iter().filter(|s| s.mirrored) {
            eprintln!(
                "note: {}: a negative step ({} V), fitted as its mirror image (the model is odd in E, I and the speed)",
                s.label, -s.volts
            );
        }
    }
    let files = [hv.path.as_str(), lv.path.as_str()];
    if long {
        eprintln!(
            "read in {:.1} s; fitting {} samples…",
            clock.elapsed().as_secs_f64(),
            hv.current.len() + lv.current.len()
        );
    }
    let (paper, full) = identify_pair(&hv, &lv, a.method)?;
    if long {
        eprintln!("done in {:.1} s", clock.elapsed().as_secs_f64());
    }
    let paper = paper.as_ref().map_err(String::as_str);
    let method = match a.method {
        MethodArg::Paper => "paper",
        MethodArg::Full => "full",
    };
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report_json(method, paper, full.as_ref(), &files))?
        );
    } else {
        print_table(method, paper, full.as_ref(), &files);
    }
    if let (Some(dir), Some(f)) = (&a.plot, &full) {
        let records = [high, low]
            .iter()
            .map(|p| load_excited(p, &map, true))
            .collect::<Result<Vec<_>>>()?;
        crate::commands::figures::fit_figures(dir, &records, &f.params, a.quiet)?;
    }
    converged(full.as_ref())
}

/// A record of any excitation, read and checked: owns what [`ExcitedRecord`] borrows.
pub struct LoadedExcited {
    /// File it came from.
    pub path: String,
    /// The file with the line span of its samples, for errors.
    pub label: String,
    /// The record (SI units).
    pub record: Record,
    /// The voltage waveform rebuilt from the voltage column, time from the first sample.
    pub input: Input,
    /// What the record leaves unknown about each level of `input` (empty for a replayed one).
    pub priors: Vec<LevelPrior>,
    dt: f64,
    exclude_current: Option<Vec<bool>>,
    exclude_speed: Option<Vec<bool>>,
}

impl LoadedExcited {
    /// The identification's view of the record.
    pub fn excited(&self) -> ExcitedRecord<'_> {
        ExcitedRecord {
            input: &self.input,
            dt: self.dt,
            current: &self.record.current,
            speed: self.record.speed.as_deref(),
            position: self.record.position.as_deref(),
            exclude_current: self.exclude_current.as_deref(),
            exclude_speed: self.exclude_speed.as_deref(),
        }
    }
}

/// Reads a record of any voltage waveform for the output-error fit.
pub fn load_excited(path: &Path, map: &ColumnMap, quiet: bool) -> Result<LoadedExcited> {
    let shown = path.display().to_string();
    let loaded = read_loaded(path, map, true)?;
    let (exclude_current, exclude_speed) = check_clipping(&shown, &loaded, quiet)?;
    let label = file_lines(&shown, &loaded.lines);
    let header_line = loaded.lines.first().map_or(1, |l| l.saturating_sub(1));
    let rec = loaded.record;
    if rec.speed.is_none() && rec.position.is_none() {
        return Err(BadInput(format!(
            "{shown}:{header_line}: neither speed nor position: k, f, J and Ts need one of them"
        ))
        .into());
    }
    let (input, priors) = voltage_levels(&rec.t, &rec.voltage, loaded.voltage_lsb)
        .map_err(|e| BadInput(format!("{label}: {e}")))?;
    if input.peak_volts() == 0.0 {
        return Err(BadInput(format!(
            "{label}: the voltage is 0 V throughout: nothing drives the motor"
        ))
        .into());
    }
    let dt = motor_model::mean_period(&rec.t);
    Ok(LoadedExcited {
        path: shown,
        label,
        input,
        priors,
        dt,
        exclude_current,
        exclude_speed: if rec.position.is_some() {
            None
        } else {
            exclude_speed
        },
        record: rec,
    })
}

/// `file:a-b`: a file and the lines of its samples, for errors about a whole record.
pub fn file_lines(shown: &str, lines: &[usize]) -> String {
    format!(
        "{shown}:{}-{}",
        lines.first().copied().unwrap_or(0),
        lines.last().copied().unwrap_or(0)
    )
}

/// The output-error fit of `loaded` from `start`, or from the equation-error start when none is
/// given; errors name `label`, and a failed start adds `start_hint`. Returns the start used and
/// the fit.
pub fn fit_excited(
    loaded: &[LoadedExcited],
    start: Option<MotorParams>,
    label: &str,
    start_hint: &str,
) -> Result<(MotorParams, FullFit)> {
    let records: Vec<ExcitedRecord> = loaded.iter().map(LoadedExcited::excited).collect();
    let start = match start {
        Some(s) => s,
        None => equation_error_start(&records)
            .map_err(|e| BadInput(format!("{label}: {e}{start_hint}")))?,
    };
    let priors: Vec<Vec<LevelPrior>> = loaded.iter().map(|l| l.priors.clone()).collect();
    let full = identify_output_error_with_inputs(&records, &priors, &start, LmSettings::default())
        .map_err(|e| BadInput(format!("{label}: {e}")))?;
    Ok((start, full))
}

/// `--record A.csv --record B.csv ...`: all six parameters by output error.
fn run_records(a: &IdentifyArgs) -> Result<()> {
    let map = column_map(a)?;
    let loaded = a
        .record
        .iter()
        .map(|p| load_excited(p, &map, a.quiet))
        .collect::<Result<Vec<_>>>()?;
    let files: Vec<&str> = loaded.iter().map(|l| l.path.as_str()).collect();
    let all = loaded
        .iter()
        .map(|l| l.label.as_str())
        .collect::<Vec<_>>()
        .join(" / ");
    let given = a.start.as_deref().map(crate::settings::motor).transpose()?;
    let samples: usize = loaded.iter().map(|l| l.record.t.len()).sum();
    let clock = std::time::Instant::now();
    // About a second of fitting on this kind of machine: progress from there on.
    let long = !a.quiet && samples >= 20_000;
    if long {
        eprintln!(
            "fitting {} record(s), {samples} samples, by simulation (about 7 simulations per iteration)…",
            loaded.len()
        );
    }
    let (start, full) = fit_excited(
        &loaded,
        given,
        &all,
        " (give a start with --start FILE.json)",
    )?;
    if long {
        eprintln!(
            "done in {:.1} s ({} iterations)",
            clock.elapsed().as_secs_f64(),
            full.iterations
        );
    }
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
        }
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table("output_error", Err(""), Some(&full), &files);
    }
    if let Some(dir) = &a.plot {
        crate::commands::figures::fit_figures(dir, &loaded, &full.params, a.quiet)?;
    }
    converged(Some(&full))
}

/// The `--columns` mapping, if given.
fn column_map(a: &IdentifyArgs) -> Result<ColumnMap> {
    match &a.columns {
        Some(text) => ColumnMap::parse(text),
        None => Ok(ColumnMap::default()),
    }
}

/// The pair with the higher step first (the paper's method needs it: Eq. (33) is the high-voltage
/// approximation), and a note when the records were given the other way round.
pub fn in_order(hv: LoadedStep, lv: LoadedStep) -> (LoadedStep, LoadedStep, Option<String>) {
    if lv.volts > hv.volts {
        let note = format!(
            "--high {} steps to {:.4} V, below --low {} at {:.4} V: taken the other way round",
            hv.label, hv.volts, lv.label, lv.volts
        );
        (lv, hv, Some(note))
    } else {
        (hv, lv, None)
    }
}

/// Identifies a high- and a low-voltage step record: the paper's method (unless clipped
/// samples rule it out), then with `MethodArg::Full` the full model started from it (or from
/// the steady states where it does not apply).
pub fn identify_pair(
    hv: &LoadedStep,
    lv: &LoadedStep,
    method: MethodArg,
) -> Result<(
    std::result::Result<PaperIdentification, String>,
    Option<FullFit>,
)> {
    let tests = [hv.test(), lv.test()];
    let settings = LmSettings::default();
    let both = format!("{} / {}", hv.label, lv.label);
    let paper = if hv.has_clipping() || lv.has_clipping() {
        Err(
            "clipped samples: the paper's method reads the whole current and its steady values"
                .to_string(),
        )
    } else {
        identify_paper(&tests[0], &tests[1], settings).map_err(|e| e.to_string())
    };
    let full = match (method, &paper) {
        (MethodArg::Paper, Err(e)) => return Err(BadInput(format!("{both}: {e}")).into()),
        (MethodArg::Paper, Ok(_)) => None,
        (MethodArg::Full, _) => {
            let start = match &paper {
                Ok(p) => p.params,
                Err(_) => steady_state_start(&tests[0], &tests[1])
                    .map_err(|e| BadInput(format!("{both}: {e}")))?,
            };
            Some(
                identify_full_with_inputs(&tests, &[hv.inputs, lv.inputs], &start, settings)
                    .map_err(|e| BadInput(format!("{both}: {e}")))?,
            )
        }
    };
    Ok((paper, full))
}

/// Exit status of a full fit: [`NotConverged`] with the reason when the solver gave up or the
/// result is refused.
fn converged(full: Option<&FullFit>) -> Result<()> {
    match full.and_then(FullFit::failure) {
        Some(why) => Err(NotConverged(why).into()),
        None => Ok(()),
    }
}
