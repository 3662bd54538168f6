//! Output-error fits of the motor together with one unmodelled effect (SPEC section 5): records
//! simulated with the effect and measured through a 12-bit logger are fitted with the motor's
//! six parameters and the effect's own from a start 20 % off; every parameter's 95 % interval
//! holds the truth, and the model with the effect explains the records better than the nominal
//! model does.

use fit::{voltage_input, ExcitedRecord, FullFit, OutputError};
use motor_model::{
    simulate, Effect, Effects, Input, MeasurementModel, MotorParams, Range, Record, SpeedSource,
};

/// A small servo: τe = 1 ms, mechanical time constant about 8 ms.
fn servo() -> MotorParams {
    MotorParams::new(2.0, 2e-3, 0.05, 1e-5, 1e-5, 5e-3).unwrap()
}

const RATE_HZ: f64 = 5000.0;
const SECONDS: f64 = 0.6;

/// A staircase with a reversal, a stop and a low level: speeds from 0 to about ±240 rad/s,
/// breakaways from rest in both directions.
fn staircase() -> Input {
    Input::piecewise(&[
        (0.005, 12.0),
        (0.12, 4.0),
        (0.24, -8.0),
        (0.36, 0.0),
        (0.45, 1.5),
    ])
    .unwrap()
}

/// The records of `motor` with `effects`, through a 12-bit logger (1 LSB of noise) with a
/// tachometer.
fn records(motor: &MotorParams, effects: Effects, seed: u64) -> Vec<Record> {
    [staircase(), Input::step(6.0, 0.005).unwrap()]
        .iter()
        .enumerate()
        .map(|(k, input)| {
            let trace = simulate(motor, effects, input, SECONDS, RATE_HZ).unwrap();
            let ranges = [&trace.voltage, &trace.current, &trace.speed].map(|s| Range::covering(s));
            let logger = MeasurementModel {
                encoder_counts_per_rev: None,
                speed_source: SpeedSource::Tacho,
                ..MeasurementModel::logger(12, ranges, 1.0, 4000, seed + k as u64)
            };
            logger.apply(&trace).unwrap()
        })
        .collect()
}

/// The fit's view of logged records (current and tachometer) with their inputs.
fn excited<'a>(
    recs: &'a [Record],
    inputs: impl Iterator<Item = &'a Input>,
) -> Vec<ExcitedRecord<'a>> {
    recs.iter()
        .zip(inputs)
        .map(|(r, input)| ExcitedRecord {
            input,
            dt: 1.0 / RATE_HZ,
            current: &r.current,
            speed: r.speed.as_deref(),
            position: None,
            exclude_current: None,
            exclude_speed: None,
        })
        .collect()
}

/// Sample-count-weighted mean NRMSE over the channels (SPEC section 7).
fn nrmse(fit: &FullFit) -> f64 {
    let (sum, n) = fit.fitted.iter().fold((0.0, 0.0), |(s, n), ch| {
        let mean = ch.measured.iter().sum::<f64>() / ch.measured.len() as f64;
        let sse = ch.residual_rms().powi(2) * ch.measured.len() as f64;
        let sst: f64 = ch.measured.iter().map(|y| (y - mean).powi(2)).sum();
        let w = ch.measured.len() as f64;
        (s + w * (sse / sst).sqrt(), n + w)
    });
    sum / n
}

fn fit_with(effect: &str, seed: u64) {
    let truth = servo();
    let effect: Effect = effect.parse().unwrap();
    let effects = Effects::none().with(effect);
    let recs = records(&truth, effects, seed);
    let inputs: Vec<Input> = recs
        .iter()
        .map(|r| voltage_input(&r.t, &r.voltage).unwrap())
        .collect();
    let excited = excited(&recs, inputs.iter());
    let start = MotorParams::from_values(truth.values().map(|v| v * 1.2)).unwrap();
    let start_effects = effects
        .with_fitted_values(
            &effects
                .fitted_values()
                .iter()
                .map(|v| v * 1.2)
                .collect::<Vec<_>>(),
        )
        .unwrap();
    let fit = OutputError::new(&excited, start)
        .effects(start_effects)
        .fit()
        .unwrap();
    assert!(fit.accepted(), "{}: {:?}", effect.name(), fit.failure());
    let names = fit.parameter_names();
    assert_eq!(names.len(), 6 + effects.fitted_slots().len());
    assert_eq!(fit.correlation.as_ref().unwrap().nrows(), names.len());
    // Every parameter at once: the truth inside the family-wise 95 % region, each interval
    // widened from its 95 % level to 1 − 0.05/p (Bonferroni over the p parameters), so that one
    // record set — one seed — fails by chance with probability at most 5 %, not the
    // 1 − 0.95ᵖ ≈ 30 % of p separate 95 % intervals.
    let p = names.len() as f64;
    let widen = fit::student_t_quantile(1.0 - 0.025 / p, 1e9) / fit::student_t_quantile(0.975, 1e9);
    let wide = |[lo, hi]: [f64; 2]| {
        let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo) * widen);
        [mid - half, mid + half]
    };
    let ci = fit.ci95.unwrap().named().map(|(_, c)| c);
    for (k, (got, want)) in fit.params.values().iter().zip(truth.values()).enumerate() {
        let [lo, hi] = wide(ci[k]);
        assert!(
            lo <= want && want <= hi,
            "{}: motor {} = {got} [{lo}, {hi}] does not contain {want}",
            effect.name(),
            names[k]
        );
    }
    assert_eq!(fit.effect_estimates.len(), effects.fitted_slots().len());
    for (e, want) in fit.effect_estimates.iter().zip(effects.fitted_values()) {
        assert_eq!(e.effect, effect.kind().unwrap());
        let [lo, hi] = wide(e.ci95.expect("effect interval"));
        assert!(
            lo <= want && want <= hi,
            "{} {} = {} {} [{lo}, {hi}] does not contain {want}",
            effect.name(),
            e.symbol,
            e.value,
            e.unit
        );
    }
    assert_eq!(
        fit.effects.fitted_values().len(),
        fit.effect_estimates.len()
    );
    let nominal = OutputError::new(&excited, start).fit().unwrap();
    let (with, without) = (nrmse(&fit), nrmse(&nominal));
    eprintln!(
        "{}: NRMSE {with:.5} with the effect, {without:.5} without",
        effect.name()
    );
    assert!(
        with < without,
        "{}: NRMSE {with} with the effect, {without} without",
        effect.name()
    );
}

#[test]
fn quadratic_drag_is_fitted_with_the_motor() {
    fit_with("quadratic_drag:c=5e-8", 1);
}

#[test]
fn stribeck_friction_is_fitted_with_the_motor() {
    fit_with("stribeck_friction:tst=0.01,ws=20", 1);
}

#[test]
fn current_sensor_lag_is_fitted_with_the_motor() {
    fit_with("current_sensor_lag:tau=5e-4", 1);
}

#[test]
fn brush_drop_is_fitted_with_the_motor() {
    fit_with("brush_drop:vb=0.5", 1);
}

/// With the voltage levels and their instants as uncertain inputs (`voltage_levels`: each
/// change half a period before its first sample, of variance dt²/12), the fit of motor +
/// effect moves them where the records put them; every interval, widened by what the inputs
/// leave unknown, holds the truth.
#[test]
fn motor_and_effect_with_uncertain_levels() {
    let truth = servo();
    let effects = Effects::none().with("quadratic_drag:c=5e-8".parse().unwrap());
    let recs = records(&truth, effects, 21);
    let levels: Vec<(Input, Vec<fit::LevelPrior>)> = recs
        .iter()
        .map(|r| fit::voltage_levels(&r.t, &r.voltage, None).unwrap())
        .collect();
    let excited = excited(&recs, levels.iter().map(|(input, _)| input));
    let priors: Vec<Vec<fit::LevelPrior>> = levels.iter().map(|(_, p)| p.clone()).collect();
    let start = MotorParams::from_values(truth.values().map(|v| v * 1.2)).unwrap();
    let start_effects = effects.with_fitted_values(&[6e-8]).unwrap();
    let fit = fit::OutputError::new(&excited, start)
        .level_priors(&priors)
        .effects(start_effects)
        .fit()
        .unwrap();
    assert!(fit.accepted(), "{:?}", fit.failure());
    let names = fit.parameter_names();
    let ci = fit.ci95.unwrap().named().map(|(_, c)| c);
    for (k, want) in truth.values().into_iter().enumerate() {
        let [lo, hi] = ci[k];
        assert!(
            lo <= want && want <= hi,
            "{}: [{lo}, {hi}] vs {want}",
            names[k]
        );
    }
    let c = &fit.effect_estimates[0];
    let [lo, hi] = c.ci95.unwrap();
    assert!(
        lo <= 5e-8 && 5e-8 <= hi,
        "{}: {} [{lo}, {hi}]",
        names[6],
        c.value
    );
}
