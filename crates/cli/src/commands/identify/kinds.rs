//! The record-kind line of `identify` (what the records can give, decided by
//! [`fit::RecordKind`]) and the voltage-and-speed report (kS, kV, kA; J, f, Ts with R and k).

use anyhow::Result;
use fit::{CurrentUnused, FeedforwardFit, KindRefusal, KnownConstant, RecordKind, TauE};
use serde_json::{json, Value};

use super::options::Settings;
use super::report::{channels_json, print_channels, sig};
use crate::console::outln;
use crate::errors::{BadInput, NotConverged};

/// The option that gives a known constant.
fn option(c: KnownConstant) -> &'static str {
    match c {
        KnownConstant::Resistance => "--resistance",
        KnownConstant::TorqueConstant => "--torque-constant",
    }
}

/// Why a present current column is not used, in words.
fn current_unused_text(why: &CurrentUnused) -> String {
    match why {
        CurrentUnused::Coarse { adc_steps } => format!(
            "the current spans {adc_steps:.0} ADC steps (fewer than {}): too coarse to show R and L, so it is not used",
            fit::MIN_CURRENT_ADC_STEPS
        ),
    }
}

/// `record kind: voltage and speed only: kS, kV, kA; give --resistance and --torque-constant
/// for J, f, Ts`.
pub fn kind_line(kind: &RecordKind) -> String {
    let mut line = format!(
        "record kind: {}: {}",
        kind.measured(),
        kind.identifiable().join(", ")
    );
    if let Some((needs, gives)) = kind.more_with() {
        let needs: Vec<&str> = needs.iter().map(|c| option(*c)).collect();
        line.push_str(&format!(
            "; give {} for {}",
            needs.join(" and "),
            gives.join(", ")
        ));
    }
    if let RecordKind::VoltageSpeed {
        current_unused: Some(why),
        ..
    } = kind
    {
        line.push_str(&format!("; {}", current_unused_text(why)));
    }
    line
}

/// The kind as `--json` gives it under `record_kind`.
pub fn kind_json(kind: &RecordKind) -> Value {
    json!({
        "measured": kind.measured(),
        "identifiable": kind.identifiable(),
        "more_with": kind.more_with().map(|(needs, gives)| json!({
            "give": needs.iter().map(|c| option(*c)).collect::<Vec<_>>(),
            "for": gives,
        })),
        "current_unused": match kind {
            RecordKind::VoltageSpeed { current_unused: Some(why), .. } => Some(current_unused_text(why)),
            _ => None,
        },
        "text": kind_line(kind),
    })
}

/// A refusal of the kind decision as bad input about `shown` (a file and its header line, or
/// the records).
pub fn refused(shown: &str, why: KindRefusal) -> anyhow::Error {
    match why {
        KindRefusal::OneOfResistanceAndTorqueConstant { missing } => {
            let given = match missing {
                KnownConstant::Resistance => KnownConstant::TorqueConstant,
                _ => KnownConstant::Resistance,
            };
            BadInput(format!(
                "{shown}: {} without {}: {why} (give {} too, or neither)",
                option(given),
                option(missing),
                option(missing)
            ))
            .into()
        }
        KindRefusal::NoResponse => BadInput(format!(
            "{shown}: {why}; a record needs t, voltage and a current, speed or position column"
        ))
        .into(),
        _ => BadInput(format!("{shown}: {why}")).into(),
    }
}

/// What τe did to the fit, in one line, or `None` when it is fitted and nothing is lost.
fn tau_e_text(tau_e: &TauE) -> String {
    match tau_e {
        TauE::Fitted { value_s, ci95_s } => format!(
            "tau_e = L/R = {} s [{}, {}] fitted with the constants (the model with the electrical lag: kA = R J/k holds)",
            sig(*value_s),
            sig(ci95_s[0]),
            sig(ci95_s[1])
        ),
        TauE::NotResolved { upper_s } => format!(
            "tau_e = L/R not resolved by these records (below {} s): kS, kV, kA are those of the model with it, their intervals carry what it leaves unknown",
            sig(*upper_s)
        ),
        TauE::Traded {
            lead_v_s2_per_rad,
            lead_ci95,
            product_v_s3_per_rad,
            product_ci95,
        } => format!(
            "tau_e = L/R is not small, but with no --torque-constant the records cannot split kA from it: they fix kA tau_e = {} V·s³/rad [{}, {}] and kA + tau_e (kV - k) = {} V·s²/rad [{}, {}], and any kA up to that fits them alike (kA's interval is [0, {}]); give --torque-constant (k) to split them",
            sig(*product_v_s3_per_rad),
            sig(product_ci95[0]),
            sig(product_ci95[1]),
            sig(*lead_v_s2_per_rad),
            sig(lead_ci95[0]),
            sig(lead_ci95[1]),
            sig(lead_ci95[1]),
        ),
        TauE::Unfitted => "the fit with tau_e = L/R failed: the reduced model (tau_e = 0) is used; kA then holds about (kV - k) tau_e on top of R J/k, and at every reversal kS trades against tau_e (record at a rate above 1/tau_e, or measure the current)".into(),
        _ => "tau_e = L/R neglected: the reduced model is used (kA holds about (kV - k) tau_e on top of R J/k)".into(),
    }
}

fn tau_e_json(tau_e: &TauE) -> Value {
    let (status, value, ci) = match tau_e {
        TauE::Fitted { value_s, ci95_s } => ("fitted", Some(*value_s), Some(*ci95_s)),
        TauE::NotResolved { upper_s } => ("not_resolved", None, Some([0.0, *upper_s])),
        TauE::Traded { .. } => ("traded_with_ka", None, None),
        TauE::Unfitted => ("unfitted_reduced_model", None, None),
        _ => ("neglected_reduced_model", None, None),
    };
    let mut out = json!({"status": status, "value": value, "ci95": ci, "unit": "s", "note": tau_e_text(tau_e)});
    if let TauE::Traded {
        lead_v_s2_per_rad,
        lead_ci95,
        product_v_s3_per_rad,
        product_ci95,
    } = tau_e
    {
        out["ka_plus_tau_e_viscous_share"] =
            json!({"value": lead_v_s2_per_rad, "ci95": lead_ci95, "unit": "V·s²/rad"});
        out["ka_times_tau_e"] =
            json!({"value": product_v_s3_per_rad, "ci95": product_ci95, "unit": "V·s³/rad"});
    }
    out
}

/// Prints the voltage-and-speed report (`--json` or the table) of `fit` on `files`, with
/// `known` = (R, k) if given; exit 3 when the fit did not converge or gave no intervals.
pub fn report(a: &Settings, kind: &RecordKind, fit: &FeedforwardFit, files: &[&str]) -> Result<()> {
    let known = a.resistance.zip(a.torque_constant);
    let estimates = fit.estimates(known);
    if a.json {
        let mut parameters = serde_json::Map::new();
        for p in &estimates {
            parameters.insert(
                p.name.into(),
                json!({"value": p.value, "ci95": p.ci95, "unit": p.unit}),
            );
        }
        let report = json!({
            "method": "voltage_speed",
            "record_kind": kind_json(kind),
            "model_check": {"made": false, "reason": "not made for the voltage-to-speed model: motorid diagnose needs a current"},
            "parameters": parameters,
            "tau_e": tau_e_json(&fit.tau_e),
            "tau_m": match fit.tau_e {
                TauE::Traded { lead_ci95, .. } => json!({"value": null, "at_most": lead_ci95[1] / fit.params.kv_v_s_per_rad, "unit": "s"}),
                _ => json!({"value": fit.params.tau_m_s(), "unit": "s"}),
            },
            "initial_speed": fit.initial_speed_rad_s.iter().zip(files).map(|(w, f)| json!({"record": f, "value": w, "unit": "rad/s"})).collect::<Vec<_>>(),
            "given": {"R": a.resistance, "k": a.torque_constant},
            "quality": {
                "termination": fit.termination.text(),
                "converged": fit.termination.converged(),
                "iterations": fit.iterations,
                "channels": channels_json(&fit.quality, files),
            },
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        outln!("{}", kind_line(kind))?;
        outln!(
            "voltage and speed: E = kS sign(w) + kV w + kA dw/dt ({}) fitted by output error on the speed{}",
            match fit.tau_e {
                TauE::Fitted { .. } | TauE::NotResolved { .. } | TauE::Traded { .. } => {
                    "with the electrical lag tau_e"
                }
                _ => "the reduced model, tau_e = 0",
            },
            match known {
                Some((r, k)) => format!("; J, f, Ts from the given R = {} ohm, k = {} N·m/A (their own uncertainty not included)", sig(r), sig(k)),
                None => String::new(),
            }
        )?;
        outln!("      {:>12}   {:<27} unit", "value", "95% CI")?;
        let mut poorly = Vec::new();
        for p in &estimates {
            let ci = p.ci95.map_or("-".to_string(), |[lo, hi]| {
                format!("[{}, {}]", sig(lo), sig(hi))
            });
            if let (true, Some(rel)) = (p.poorly_determined(), p.relative_half_width()) {
                poorly.push(format!("{} (±{:.0} %)", p.name, 100.0 * rel));
            }
            outln!("  {:<3} {:>12}   {ci:<27} {}", p.name, sig(p.value), p.unit)?;
        }
        let tau_m = match fit.tau_e {
            TauE::Traded { lead_ci95, .. } => format!(
                "at most {} s",
                sig(lead_ci95[1] / fit.params.kv_v_s_per_rad)
            ),
            _ => format!("{} s", sig(fit.params.tau_m_s())),
        };
        outln!(
            "derived: tau_m = kA/kV = {tau_m}; {}",
            tau_e_text(&fit.tau_e)
        )?;
        for (w, f) in fit.initial_speed_rad_s.iter().zip(files) {
            if *w != 0.0 {
                outln!("  {f}: starts running at {} rad/s (fitted)", sig(*w))?;
            }
        }
        outln!(
            "fit: {} after {} iterations",
            fit.termination.text(),
            fit.iterations
        )?;
        print_channels(&fit.quality, files)?;
        if !poorly.is_empty() {
            outln!(
                "warning: poorly determined by these records: {} — the 95% interval is wider than {:.0} % of the value",
                poorly.join(", "),
                100.0 * fit::POORLY_DETERMINED
            )?;
        }
    }
    if !fit.termination.converged() {
        return Err(NotConverged(format!(
            "the voltage-and-speed fit did not converge: {}",
            fit.termination.text()
        ))
        .into());
    }
    if fit.ci95.is_none() {
        return Err(NotConverged(
            "the voltage-and-speed fit gave no intervals: the records do not determine kS, kV and kA separately (excite the motor with several levels or both directions)".into(),
        )
        .into());
    }
    if let Some((file, ratio)) = files
        .iter()
        .zip(&fit.residual_over_noise)
        .find(|(_, &x)| x > fit::EXPLAINED_RATIO)
    {
        return Err(NotConverged(format!(
            "the voltage-and-speed model does not explain {file}: its residual is {ratio:.1} times the record's noise (an electrical lag beyond what the fit tried, or an effect the model lacks: measure the current, or excite the motor more slowly)"
        ))
        .into());
    }
    Ok(())
}
