//! `motorid demo`: the paper's example, end to end, against its printed tables.

use anyhow::Result;
use fit::diagnose::{diagnose, DiagnoseSettings};
use fit::{
    accuracy, equation_error_start, from_high_voltage, identify_full, identify_paper,
    voltage_input, ExcitedRecord, FullFit, LmSettings, PaperIdentification, Params33, PARAM_NAMES,
};
use motor_model::{
    Derived, Effect, Effects, Input, MeasurementModel, MotorParams, Simulator, StepResponse, Trace,
};

use crate::args::DemoArgs;
use crate::console::outln;
use crate::paper_values::{
    compare, HIGH_VOLTAGE_V, LOGGER_RATE_HZ, LOW_VOLTAGE_V, TABLE_1, TABLE_2, TEST_LENGTH_S,
};
use crate::record_csv;
use crate::settings::Logger;
use crate::simulated::{metadata, record};
use crate::steps::{step_from_record, LoadedStep};

fn mark(same: bool) -> &'static str {
    if same {
        "="
    } else {
        "≠"
    }
}

/// What `motorid demo` writes besides its report, from its arguments.
pub struct Settings {
    /// Folder for the two simulated records, if asked for.
    pub out: Option<std::path::PathBuf>,
}

impl Settings {
    /// The options of `a` (the folder is checked when it is written).
    pub fn from_args(a: &DemoArgs) -> Settings {
        Settings { out: a.out.clone() }
    }
}

/// Runs the paper's example end to end and prints it beside the paper's tables.
pub fn run(a: &Settings) -> Result<()> {
    let motor = MotorParams::paper();
    let d = Derived::new(&motor);
    outln!("motorid demo — the simulated motor of the paper's Sec. 4.1")?;
    outln!(
        "R = {} ohm, L = {} H, k = {} N·m/A, f = {} N·m·s/rad, J = {} kg·m², Ts = {} N·m\n",
        motor.r_ohm,
        motor.l_henry,
        motor.k_nm_per_a,
        motor.f_nms_per_rad,
        motor.j_kgm2,
        motor.ts_nm
    )?;

    outln!("Table 1 — derived constants, Eqs. (16)-(26)")?;
    outln!(
        "  {:<6} {:>12} {:>12}    {:<8}",
        "",
        "motorid",
        "paper",
        "unit"
    )?;
    let ours = |key: &str| match key {
        "KE" => d.k_e,
        "Ks" => d.k_s,
        "wn" => d.omega_n,
        "zeta" => d.zeta,
        "sigma" => d.sigma,
        "wa" => d.omega_a,
        "tau_m" => d.tau_m,
        "tau_e" => d.tau_e,
        "alpha" => d.alpha.unwrap_or(f64::NAN),
        "gamma" => d.gamma.unwrap_or(f64::NAN),
        _ => d.i0,
    };
    for (key, printed, unit) in TABLE_1 {
        let (text, same) = compare(ours(key), printed);
        let note = if key == "wa" && !same {
            "  (paper's typo: 0.3381 for 0.3881, cf. its Table 3)"
        } else {
            ""
        };
        outln!(
            "  {key:<6} {text:>12} {} {printed:<10} {unit:<8}{note}",
            mark(same)
        )?;
    }

    outln!("\nTable 2 — values at t = {TEST_LENGTH_S} s (exact response; RK4 stick-slip simulation beside it)")?;
    let mut records = Vec::new();
    for (e, rows) in [
        (HIGH_VOLTAGE_V, &TABLE_2[0..2]),
        (LOW_VOLTAGE_V, &TABLE_2[2..4]),
    ] {
        let exact = StepResponse::new(&motor, e).at(TEST_LENGTH_S);
        let input = Input::step(e, 0.0)?;
        let sim = Simulator::new(motor, Effects::none(), input.clone())?
            .run(TEST_LENGTH_S, LOGGER_RATE_HZ)?;
        let last = sim.t.len() - 1;
        for (i, (test, qty, printed, unit)) in rows.iter().enumerate() {
            let (value, simulated) = if i == 0 {
                (exact.current_a, sim.current[last])
            } else {
                (exact.speed_rad_s, sim.speed[last])
            };
            let (text, same) = compare(value, printed);
            outln!(
                "  {test:<11} {qty:<3} {text:>9} {} {printed:<7} {unit:<6} (exact {value:.6}, simulated {simulated:.6})",
                mark(same)
            )?;
        }
        records.push((e, input, sim));
    }
    let t0_high = StepResponse::new(&motor, HIGH_VOLTAGE_V).breakaway_time();
    let t0_low = StepResponse::new(&motor, LOW_VOLTAGE_V).breakaway_time();
    outln!(
        "\nBreakaway, Eq. (11): t0 = {:.4} ms at {HIGH_VOLTAGE_V} V, {:.4} ms at {LOW_VOLTAGE_V} V",
        t0_high.unwrap_or(f64::NAN) * 1e3,
        t0_low.unwrap_or(f64::NAN) * 1e3
    )?;
    identification_story(&motor, &records)?;
    diagnosis_story()?;

    if let Some(dir) = &a.out {
        crate::output::create_dir(dir)?;
        for (e, input, trace) in records {
            let record = motor_model::MeasurementModel::default().apply(&trace)?;
            let path = dir.join(format!("paper_{e}V.csv"));
            record_csv::write_file(&path, &record, &metadata(&motor, &Effects::none(), &input))?;
            outln!("wrote {}", path.display())?;
        }
    }
    Ok(())
}

/// Identification on the demo's records: the paper's method against its Tables 3 and 4, then
/// the full model, then both through the paper's logger.
fn identification_story(motor: &MotorParams, records: &[(f64, Input, Trace)]) -> Result<()> {
    let steps: Vec<LoadedStep> = records
        .iter()
        .map(|(e, _, trace)| {
            step_from_record(
                format!("{e} V record"),
                MeasurementModel::default().apply(trace)?,
            )
        })
        .collect::<Result<_>>()?;
    let tests = [steps[0].test(), steps[1].test()];
    let settings = LmSettings::default();
    let paper = identify_paper(&tests[0], &tests[1], settings)?;
    let t3 = paper.fit_33.params;
    outln!(
        "\nTable 3 — the paper's fit of Eq. (33) to the normalised 40 V current (start 1, 1, 1)"
    )?;
    for (name, value, printed) in [
        ("alpha", t3.alpha, "4.9832"),
        ("sigma", t3.sigma, "0.5237"),
        ("wa", t3.omega_a, "0.3858"),
    ] {
        let (text, same) = compare(value, printed);
        let note = if name == "alpha" && !same {
            "  (the paper truncated 4.98328; docs/errata.md E9)"
        } else {
            ""
        };
        outln!(
            "  {name:<6} {text:>9} {} {printed:<8} (full {value:.6}){note}",
            mark(same)
        )?;
    }
    // Table 4 from the paper's own rounded inputs, and from ours at full precision.
    let rounded = from_high_voltage(
        Params33 {
            alpha: 4.9832,
            sigma: 0.5237,
            omega_a: 0.3858,
        },
        HIGH_VOLTAGE_V,
        53.57,
        159.6,
    )?;
    let h = &paper.high;
    outln!("\nTable 4 — Eqs. (34)-(44), Eq. (37) corrected (docs/errata.md E8)")?;
    outln!(
        "  {:<6} {:>10} {:>12} {:>10}",
        "",
        "paper",
        "rounded in",
        "full prec."
    )?;
    let rows = [
        ("wn", "0.3542", rounded.omega_n, h.omega_n),
        ("zeta", "1.4788", rounded.zeta, h.zeta),
        ("tau_m", "19.8097", rounded.tau_m, h.tau_m),
        ("L", "0.3005", rounded.l_henry, h.l_henry),
        ("R", "0.2996", rounded.r_ohm, h.r_ohm),
        ("k", "0.1501", rounded.k_nm_per_a, h.k_nm_per_a),
        ("f", "0.0504", rounded.f_nms_per_rad, h.f_nms_per_rad),
        ("J", "0.9978", rounded.j_kgm2, h.j_kgm2),
        ("Ks", "3.9900", rounded.k_s, h.k_s),
        ("KE", "1.3393", rounded.k_e, h.k_e),
    ];
    for (name, printed, from_rounded, full) in rows {
        let (r_text, _) = compare(from_rounded, printed);
        let (f_text, _) = compare(full, printed);
        outln!("  {name:<6} {printed:>10} {r_text:>12} {f_text:>10}")?;
    }
    outln!(
        "  Ts (48) = {:.4} N·m (paper 0.0299), KE (50) = {:.4} A/V (paper 1.3363), Ks (51) = {:.4} A/(N·m) (paper 3.9950)",
        paper.low.ts_nm, paper.low.k_e, paper.low.k_s
    )?;

    let full = identify_full(&tests, &paper.params, settings)?;
    outln!(
        "\nFull model — R, L, k, f, J, Ts fitted jointly to both records with the exact response"
    )?;
    print_errors(motor, &paper, &full)?;
    exact_records_note(motor, &full, settings.xtol)?;

    outln!("\nThrough the paper's logger — 10-bit ADC, 1 LSB noise, 2000-count encoder, speed from the encoder")?;
    let logger = Logger::paper(TEST_LENGTH_S, LOGGER_RATE_HZ);
    let (hv, lv) = (
        record(&logger, motor, HIGH_VOLTAGE_V, 1)?,
        record(&logger, motor, LOW_VOLTAGE_V, 2)?,
    );
    let noisy = [hv.test(), lv.test()];
    let paper_noisy = identify_paper(&noisy[0], &noisy[1], settings)?;
    let full_noisy = identify_full(&noisy, &paper_noisy.params, settings)?;
    print_errors(motor, &paper_noisy, &full_noisy)?;
    outln!("  (errors and 95% CI coverage over many such records: motorid montecarlo)")?;
    Ok(())
}

/// Why an interval of the fit to exact records may miss the truth: with no noise, the residual
/// is rounding and each interval is narrower than the solver's stopping step (`xtol`, relative),
/// where the estimate stands. Says so, with the intervals' relative half-widths, when one
/// misses; nothing when all contain the truth.
fn exact_records_note(motor: &MotorParams, full: &FullFit, xtol: f64) -> Result<()> {
    let errors = accuracy(&full.params, full.ci95.as_ref(), motor);
    let Some(ci) = full
        .ci95
        .as_ref()
        .filter(|_| errors.iter().any(|a| a.covered == Some(false)))
    else {
        return Ok(());
    };
    let span = |v: &mut dyn Iterator<Item = f64>| {
        v.fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        })
    };
    let (e_lo, e_hi) = span(&mut errors.iter().map(|a| a.relative_error.abs()));
    let (h_lo, h_hi) = span(
        &mut PARAM_NAMES
            .iter()
            .zip(motor.values())
            .filter_map(|(name, truth)| ci.get(name).map(|[lo, hi]| (hi - lo) / 2.0 / truth)),
    );
    outln!(
        "  (\"no\": the records are exact; the errors ({e_lo:.0e} to {e_hi:.0e}) are where the solver stopped (a step below {xtol:.0e} of the parameters), and the intervals, from a residual of rounding alone, are narrower (±{h_lo:.0e} to ±{h_hi:.0e}); with noise, below, the intervals hold)"
    )
}

/// The errors of the paper's method and of the full fit against the true `motor`, and whether
/// each full 95 % interval contains the truth.
fn print_errors(motor: &MotorParams, paper: &PaperIdentification, full: &FullFit) -> Result<()> {
    outln!(
        "  {:<3} {:>9} {:>15} {:>15}   full 95% CI contains truth",
        "",
        "truth",
        "paper (error)",
        "full (rel. err)"
    )?;
    let paper_errors = accuracy(&paper.params, None, motor);
    let full_errors = accuracy(&full.params, full.ci95.as_ref(), motor);
    for (p, f) in paper_errors.iter().zip(&full_errors) {
        let covered = match f.covered {
            None => "-",
            Some(true) => "yes",
            Some(false) => "no",
        };
        outln!(
            "  {:<3} {:>9} {:>+14.4}% {:>+14.2e}    {covered}",
            p.name,
            p.truth,
            100.0 * p.relative_error,
            f.relative_error,
        )?;
    }
    outln!(
        "  full fit: {} after {} iterations",
        full.termination.text(),
        full.iterations
    )
}

/// The small servo of `fixtures/motors/small_servo.json` (R 2 Ω, L 2 mH, k 0.05 N·m/A,
/// f 4e-4 N·m·s/rad, J 2e-5 kg·m², Ts 4 mN·m), whose 5 kHz records diagnose in seconds.
fn small_servo() -> Result<MotorParams> {
    Ok(MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3)?)
}

/// Brush drop withheld from the diagnosis \[V\].
const WITHHELD_BRUSH_DROP_V: f64 = 0.3;

/// The end of the demo: a 12 V and a 3 V step of a small servo with a brush drop the diagnosis
/// is not told of, through the paper's logger, diagnosed (one effect looked for, to stay short).
fn diagnosis_story() -> Result<()> {
    let motor = small_servo()?;
    let withheld =
        Effects::none().with(format!("brush_drop:vb={WITHHELD_BRUSH_DROP_V}").parse::<Effect>()?);
    outln!(
        "\nDiagnosis — a small servo with a {WITHHELD_BRUSH_DROP_V} V brush drop the model does not know, 12 V and 3 V steps of 0.6 s at 5 kHz through the logger"
    )?;
    let mut steps = Vec::new();
    for (seed, volts) in [(1, 12.0), (2, 3.0)] {
        let trace =
            motor_model::simulate(&motor, withheld, &Input::step(volts, 0.0)?, 0.6, 5000.0)?;
        let record = MeasurementModel::paper_logger(&trace, seed).apply(&trace)?;
        let input = voltage_input(&record.t, &record.voltage)?;
        steps.push((input, record));
    }
    let train: Vec<ExcitedRecord<'_>> = steps
        .iter()
        .map(|(input, r)| ExcitedRecord {
            input,
            dt: motor_model::mean_period(&r.t),
            current: &r.current,
            speed: r.speed.as_deref(),
            position: r.position.as_deref(),
            exclude_current: None,
            exclude_speed: None,
        })
        .collect();
    let start = equation_error_start(&train)?;
    let settings = DiagnoseSettings {
        max_effects: 1,
        ..DiagnoseSettings::default()
    };
    let d = diagnose(&train, &[], &["12 V", "3 V"], &start, &settings, &|_| {})?;
    let stage = d.stages.first();
    let named = d.named();
    match (named.first(), stage) {
        (Some(name), Some(stage)) => {
            let c = stage.candidates.iter().find(|c| c.name == *name);
            let size = c
                .and_then(|c| c.params.first())
                .map_or(String::new(), |p| match p.ci95 {
                    Some([lo, hi]) => format!(
                        ", {} = {:.4} {} [{lo:.4}, {hi:.4}] (truth {WITHHELD_BRUSH_DROP_V})",
                        p.symbol, p.value, p.unit
                    ),
                    None => format!(", {} = {:.4} {}", p.symbol, p.value, p.unit),
                });
            outln!("  verdict: {name}{size}")?;
            if let Some(c) = c {
                outln!(
                    "  held-out NRMSE {:.4} → {:.4} with it (training {:.4} → {:.4})",
                    c.heldout_nrmse_before,
                    c.heldout_nrmse_after,
                    c.train_nrmse_before,
                    c.train_nrmse_after
                )?;
            }
        }
        _ => outln!("  verdict: none — no candidate effect improves the held-out data")?,
    }
    outln!("  (the whole report, its localisation and figures: motorid diagnose)")?;
    Ok(())
}
