//! The identification's report: the parameter table with intervals, the channels' fit, the
//! paper's method beside it, as text and as JSON.

use anyhow::Result;
use fit::{parameter_estimates, ChannelQuality, FullFit, PaperIdentification, PARAM_NAMES};
use motor_model::Derived;
use serde_json::{json, Value};

use crate::console::outln;

/// `x` with 7 significant digits, in plain or scientific notation as suits its size.
pub(crate) fn sig(x: f64) -> String {
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
pub(crate) fn channels_json(quality: &[ChannelQuality], files: &[&str]) -> Value {
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
pub(crate) fn print_channels(quality: &[ChannelQuality], files: &[&str]) -> Result<()> {
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

pub(crate) fn paper_json(paper: &PaperIdentification) -> Value {
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
pub(crate) fn print_table(
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
