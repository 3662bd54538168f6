//! The withheld-effect benchmark: generates the cases of `motor_model::withheld` for a seed,
//! diagnoses each without telling it the effect, and prints the confusion matrix, the top-1
//! accuracy, false alarms on `none`, the both-named rate of two-effect cases and the median
//! held-out NRMSE after/before of correctly named effects — over every held-out channel as
//! SPEC section 7 summarises them, and on the one channel of one record where the gap before
//! is widest (each beside the ratio a perfect model would reach).
//!
//! ```text
//! cargo run --release -p fit --example withheld_benchmark -- [SEED] [N] [CASE]
//! ```
//!
//! With CASE, only that case is diagnosed and every candidate of every stage printed (with
//! `WITHHELD_DIFF=NAME`, also the held-out samples where candidate NAME's refit loses and
//! gains most against its stage's base model). With `WITHHELD_CASES=3,15,66`, only the cases
//! listed are diagnosed and scored.
//!
//! The cases are `fit::diagnose::benchmark::calibrated_case`'s: each effect sized on the gap
//! the nominal model cannot absorb (`nominal_gap`). With `WITHHELD_PLAIN=1` they are
//! `motor_model::withheld::benchmark_case`'s instead, sized against the true nominal motor.
//! With `WITHHELD_SEEN=1` each case line also gives that gap, and the summary the top-1
//! accuracy of the effect cases by it.
//!
//! (default seed 1, 160 cases: 20 `none`, 20 with two effects, 120 with one; heavy — minutes
//! per ten cases on two cores). One line per case as it finishes, the summary at the end.

use fit::diagnose::benchmark::{
    calibrated_case, diagnose_case, nominal_gap, run_case, CaseOutcome, Summary,
};
use fit::diagnose::DiagnoseSettings;
use motor_model::withheld::{benchmark_case, simulate_plant, visibility};
use motor_model::Input;

#[path = "../tests/common/diagnose_records.rs"]
mod records;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(160);
    let mut settings = DiagnoseSettings::default();
    if let Some(n) = std::env::var("WITHHELD_ITERS")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        // Iterations of every fit at most (the default bounds the time of a case).
        settings.lm.max_iters = n;
        settings.lm.max_evaluations = 5 * n;
    }
    if let Some(n) = std::env::var("WITHHELD_ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        // Rounds of refits at most (1: the best `refits` candidates alone).
        settings.refit_rounds = n;
    }
    if let Some(n) = std::env::var("WITHHELD_REFITS")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        // Candidates refitted in full at each stage (the best by screening score).
        settings.refits = n;
    }
    if std::env::var_os("WITHHELD_REFIT_ALL").is_some() {
        // Every candidate refitted, whatever its screening score.
        settings.refits = settings.candidates.len();
        settings.screening_alpha = 1.0;
    }
    let plain = std::env::var_os("WITHHELD_PLAIN").is_some();
    let case_of = |i: usize| {
        if plain {
            benchmark_case(seed, i, n)
        } else {
            calibrated_case(seed, i, n, &settings)
        }
    };
    if let Some(index) = args.next().map(|s| s.parse::<usize>()).transpose()? {
        let case = case_of(index)?;
        println!("case {index}: truth {:?}", case.truth());
        if std::env::var_os("WITHHELD_VERBOSE").is_some() {
            println!("{}", serde_json::to_string(&case)?);
            // How visible the effects are on each record (training: the two steps).
            let without = case.traces_with(&[])?;
            let with = case.traces_with(&case.plant_effects())?;
            let floors = case.floors();
            for (j, r) in case.records.iter().enumerate() {
                let seen = visibility(&with[j..=j], &without[j..=j], &floors[j..=j]);
                // The same beside the nominal motor with the voltage's jumps moved within
                // their sample period (the records say only between which samples they fell).
                let dt = 1.0 / case.measurement.rate_hz;
                let shifted = |delta: f64| -> Option<f64> {
                    let input = match &r.input {
                        Input::Step { volts, at_s } => Input::step(*volts, at_s + delta).ok()?,
                        Input::Piecewise { times_s, volts } => {
                            let levels: Vec<(f64, f64)> = times_s
                                .iter()
                                .map(|t| t + delta)
                                .zip(volts.iter().copied())
                                .collect();
                            Input::piecewise(&levels).ok()?
                        }
                        _ => return None,
                    };
                    let plain = simulate_plant(
                        &case.motor,
                        &[],
                        &input,
                        r.duration_s,
                        case.measurement.rate_hz,
                    )
                    .ok()?;
                    Some(visibility(
                        &with[j..=j],
                        std::slice::from_ref(&plain),
                        &floors[j..=j],
                    ))
                };
                let best = (-20..=20)
                    .filter_map(|q| shifted(f64::from(q) * 0.05 * dt))
                    .fold(f64::INFINITY, f64::min);
                println!(
                    "  {:?}: visibility {seen:.1} noise floors ({best:.1} beside the best jump instant within ±1 sample)",
                    r.role
                );
            }
        }
        let d = diagnose_case(&case, &settings)?;
        if std::env::var_os("WITHHELD_VERBOSE").is_some() {
            println!("nominal: {:?} ({:?})", d.nominal.params, d.nominal_note);
            if let Some(path) = std::env::var_os("WITHHELD_DUMP") {
                // The nominal fit's channels, one row per sample: record, channel, sample,
                // measured, model.
                let mut out = String::new();
                for ch in &d.nominal.fitted {
                    for (j, &i) in ch.samples.iter().enumerate() {
                        out.push_str(&format!(
                            "{},{:?},{},{},{}\n",
                            ch.record, ch.channel, i, ch.measured[j], ch.model[j]
                        ));
                    }
                }
                std::fs::write(path, out)?;
            }
            for r in &d.localisation.records {
                for c in &r.channels {
                    println!(
                        "  {} {:?}: floor {:.3e} ({:?}), residual/floor² {:.2}, p {:.2e}",
                        r.name,
                        c.channel,
                        c.floor.sigma,
                        c.floor.source,
                        c.overall.ratio,
                        c.overall.p_value
                    );
                    if let Some(a) = &c.angle_ripple {
                        println!(
                            "  {} {:?}: angle ripple N {} over {} samples, p {:.2e}",
                            r.name, c.channel, a.periods_per_rev, a.samples, a.p_value
                        );
                    }
                }
            }
            for q in &d.nominal.quality {
                println!(
                    "  record {} {:?}: weight {:.3e}, residual RMS {:.3e}, fit {:.2} %",
                    q.test, q.channel, q.noise_std, q.rms_residual, q.nrmse_fit_percent
                );
            }
        }
        records::print_stages(&d);
        if let Ok(name) = std::env::var("WITHHELD_DIFF") {
            // The held-out samples where candidate `name`'s refit loses and gains most against
            // its stage's base model, each squared residual over the base channel's mean.
            for (si, stage) in d.stages.iter().enumerate() {
                let Some(c) = stage.candidates.iter().find(|c| c.name == name) else {
                    continue;
                };
                let mut rows = Vec::new();
                for b in &stage.fitted_before {
                    let Some(a) = c
                        .fitted
                        .iter()
                        .find(|a| a.record == b.record && a.channel == b.channel)
                    else {
                        continue;
                    };
                    let var = b.residual_rms().powi(2);
                    for (j, &i) in b.samples.iter().enumerate().take(a.samples.len()) {
                        if !d.held.get(b.record).is_some_and(|h| h[i]) {
                            continue;
                        }
                        let before = (b.measured[j] - b.model[j]).powi(2) / var;
                        let after = (a.measured[j] - a.model[j]).powi(2) / var;
                        rows.push((after - before, b.record, b.channel, i, j, b, a));
                    }
                }
                let total: f64 = rows.iter().map(|r| r.0).sum();
                rows.sort_by(|x, y| y.0.total_cmp(&x.0));
                println!("stage {si} {name}: held-out loss {total:.1} (base mean squares)");
                let show = |r: &(f64, usize, fit::Channel, usize, usize, _, _)| {
                    let (b, a): (&fit::FittedChannel, &fit::FittedChannel) = (r.5, r.6);
                    println!(
                        "  {:>9.2} record {} {:?} sample {} measured {:.5e} before {:.5e} after {:.5e}",
                        r.0, r.1, r.2, r.3, b.measured[r.4], b.model[r.4], a.model[r.4]
                    );
                };
                rows.iter().take(12).for_each(show);
                rows.iter().rev().take(5).for_each(show);
            }
        }
        if std::env::var_os("WITHHELD_VERBOSE").is_some() {
            for stage in &d.stages {
                for r in &stage.verdict.ranked {
                    println!(
                        "  ranked {:<22} held-out score {:>10.3e} gain {:>8.4} p {:.2e} held-out p {:.2e} significant {}",
                        r.name, r.score, r.heldout_gain, r.p_value, r.heldout_p_value, r.significant
                    );
                }
                println!("  level {:.2e}", stage.verdict.level);
            }
        }
        return Ok(());
    }
    if std::env::var_os("WITHHELD_LIST").is_some() {
        // The cases' truths and forms only, without diagnosing them.
        for i in 0..n {
            let case = case_of(i)?;
            let forms: Vec<String> = case.effects.iter().map(|e| e.effect.form_label()).collect();
            println!(
                "{i:>4}  {:<45} {:?} visibility {:.1}",
                case.truth().join("+"),
                forms,
                case.visibility
            );
        }
        return Ok(());
    }
    // With WITHHELD_SEEN, each case's gap after the nominal refit too, and the accuracy by
    // that gap at the end.
    let seen_too = std::env::var_os("WITHHELD_SEEN").is_some();
    let mut seen: Vec<Option<f64>> = Vec::with_capacity(n);
    let mut outcomes: Vec<CaseOutcome> = Vec::with_capacity(n);
    // With WITHHELD_CASES=3,15,66 only those cases (of the N generated) are diagnosed.
    let only: Option<Vec<usize>> = std::env::var("WITHHELD_CASES")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.trim().parse().ok()).collect());
    for i in 0..n {
        if only.as_ref().is_some_and(|o| !o.contains(&i)) {
            continue;
        }
        let case = case_of(i)?;
        let o = run_case(&case, &settings);
        // A case sized on the gap stores it as its visibility.
        let after = seen_too
            .then(|| {
                if !plain {
                    return Some(case.visibility);
                }
                let traces = case.traces_with(&case.plant_effects()).ok()?;
                nominal_gap(&case, &traces, &settings)
            })
            .flatten();
        seen.push(after);
        let after_text = after.map_or(String::new(), |gap| {
            format!(
                "  visibility {:.1}, gap after the nominal refit {gap:.1}",
                case.visibility
            )
        });
        println!(
            "{:>4}  truth {:<45} named {:<45} ratio {:>6} (floor {:>6}) gap {:>6} channel {:>6} (floor {:>6})  {:.1} s{}{after_text}",
            i,
            o.truth.join("+"),
            match &o.named {
                Ok(v) if v.is_empty() => "none".to_string(),
                Ok(v) => v.join("+"),
                Err(_) => "failed".to_string(),
            },
            o.heldout_ratio.map_or("-".into(), |r| format!("{r:.3}")),
            o.heldout_floor_ratio
                .map_or("-".into(), |r| format!("{r:.3}")),
            o.heldout_gap_ratio
                .map_or("-".into(), |r| format!("{r:.3}")),
            o.heldout_gap_channel
                .map_or("-".into(), |c| format!("{:.3}", c.nrmse_ratio)),
            o.heldout_gap_channel
                .map_or("-".into(), |c| format!("{:.3}", c.floor_ratio)),
            o.seconds,
            o.named
                .as_ref()
                .err()
                .map_or(String::new(), |e| format!("  ({e})"))
                + &if o.ambiguous_with.is_empty() {
                    String::new()
                } else {
                    format!("  (ambiguous with {})", o.ambiguous_with.join(", "))
                }
        );
        outcomes.push(o);
    }
    if seen_too {
        // Top-1 accuracy of the effect cases by their visibility after the nominal refit on
        // the training records.
        for at_least in [0.0, 1.0, 2.0, 4.0] {
            let (mut right, mut cases) = (0, 0);
            for (o, v) in outcomes.iter().zip(&seen) {
                if o.truth == ["none"] || !v.is_some_and(|gap| gap >= at_least) {
                    continue;
                }
                cases += 1;
                right += usize::from(o.top1_correct());
            }
            println!(
                "effect cases at least {at_least} noise floors from the nominal refit: {right} of {cases} named first ({:.1} %)",
                100.0 * right as f64 / cases.max(1) as f64
            );
        }
    }
    let s = Summary::of(&outcomes);
    println!("\nconfusion (rows: truth, one effect or none; columns: top-ranked verdict)");
    let short = |l: &str| l.chars().take(8).collect::<String>();
    print!("{:<22}", "");
    for l in &s.labels {
        print!(" {:>8}", short(l));
    }
    println!();
    for (r, row) in s.confusion.iter().enumerate() {
        print!("{:<22}", s.labels[r]);
        for c in row {
            print!(" {c:>8}");
        }
        println!();
    }
    println!(
        "\nseed {seed}, {} cases: top-1 accuracy {:.1} %, false alarms on none {}/{}, both named {}/{}, median held-out NRMSE after/before {:.3} (a perfect model's {:.3}), median held-out gap after/before {:.3}, median held-out NRMSE after/before on the channel where the gap is {:.3} (a perfect model's {:.3}), failed {}, median {:.1} s a case",
        s.cases,
        100.0 * s.top1_accuracy,
        s.false_alarms.0,
        s.false_alarms.1,
        s.both_named.0,
        s.both_named.1,
        s.median_heldout_ratio,
        s.median_heldout_floor_ratio,
        s.median_heldout_gap_ratio,
        s.median_gap_channel_ratio,
        s.median_gap_channel_floor_ratio,
        s.failed,
        s.median_seconds
    );
    Ok(())
}
