//! The withheld-effect benchmark generator: its case mix, its determinism, its plant against
//! the candidate simulator and the exact response, and the (b) forms' difference in shape.

use motor_model::withheld::{
    benchmark_case, benchmark_cases, case_mix, generate, simulate_plant, visibility,
    withheld_effect_names, CaseSpec, Form, Plant, PlantEffect, RecordRole,
};
use motor_model::{simulate, Effect, Effects, Input, MotorParams, StepResponse, Trace};

const SEED: u64 = 20_261_201;

/// The candidate model's spelling of an (a)-form effect (`name:key=value,...`, the form
/// `motorid simulate --effect` takes).
fn candidate(effect: &PlantEffect) -> Option<Effect> {
    let spec = match *effect {
        PlantEffect::StribeckGaussian {
            static_torque_nm,
            stribeck_speed_rad_s,
        } => format!("stribeck_friction:tst={static_torque_nm},ws={stribeck_speed_rad_s}"),
        PlantEffect::CoggingSine {
            amplitude_nm,
            periods_per_rev,
            phase_rad,
        } => format!("cogging_torque:amp={amplitude_nm},n={periods_per_rev},phase={phase_rad}"),
        PlantEffect::SensorFirstOrder { tau_f_s } => format!("current_sensor_lag:tau={tau_f_s}"),
        PlantEffect::ThermalOneNode {
            thermal_resistance_k_per_w,
            thermal_capacity_j_per_k,
            alpha_per_k,
        } => format!(
            "thermal_drift:rth={thermal_resistance_k_per_w},cth={thermal_capacity_j_per_k},alpha={alpha_per_k}"
        ),
        PlantEffect::DragQuadratic { c_nms2_per_rad2 } => {
            format!("quadratic_drag:c={c_nms2_per_rad2}")
        }
        PlantEffect::BrushClamp {
            drop_v,
            knee_current_a,
        } => format!("brush_drop:vb={drop_v},knee={knee_current_a}"),
        PlantEffect::SaturationLorentzian {
            saturation_current_a,
            min_ratio,
        } => format!("inductance_saturation:isat={saturation_current_a},ratio={min_ratio}"),
        _ => return None,
    };
    Some(spec.parse().expect("an (a) form is a candidate effect"))
}

/// Largest `|a − b|` over the largest `|b|` of one channel.
fn relative_gap(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(b)
        .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
    worst / scale
}

/// One single-effect case per effect and form from the `n` cases of the benchmark (found in
/// the mix, then built alone).
fn one_case_per_effect_and_form(n: usize) -> Vec<CaseSpec> {
    let mix = case_mix(SEED, n);
    let mut picked = Vec::new();
    for name in withheld_effect_names() {
        for form in [Form::SameShape, Form::OtherShape] {
            let index = mix
                .iter()
                .position(|m| m.as_slice() == [(name, form)])
                .expect("every effect in both forms");
            let case = benchmark_case(SEED, index, n).unwrap();
            assert_eq!(case.truth(), vec![name]);
            assert_eq!(case.effects[0].effect.form(), form);
            picked.push(case);
        }
    }
    picked
}

/// 160 cases: ≥ 15 single-effect cases per effect, 20 `none`, 20 with two distinct effects,
/// at least a third of the effect instances in the (b) form; every effect case visible.
#[test]
fn a_160_case_benchmark_has_the_required_mix() {
    let cases = benchmark_cases(SEED, 160).unwrap();
    assert_eq!(cases.len(), 160);
    let none = cases.iter().filter(|c| c.effects.is_empty()).count();
    let pairs: Vec<&CaseSpec> = cases.iter().filter(|c| c.effects.len() == 2).collect();
    assert_eq!(none, 20);
    assert_eq!(pairs.len(), 20);
    for pair in &pairs {
        assert_ne!(pair.effects[0].effect.name(), pair.effects[1].effect.name());
    }
    for name in withheld_effect_names() {
        let single = cases.iter().filter(|c| c.truth() == vec![name]).count();
        assert!(single >= 15, "{name}: {single} single-effect cases");
    }
    let instances: Vec<_> = cases.iter().flat_map(|c| c.effects.iter()).collect();
    let other = instances
        .iter()
        .filter(|e| e.effect.form() == Form::OtherShape)
        .count();
    assert!(
        3 * other >= instances.len(),
        "{other} of {} effects in the (b) form",
        instances.len()
    );
    // Visibility: calibrated to 4-25 noise floors; a few effects cannot reach it within their
    // limits (sensor delay of 3 samples at most, cogging below the breakaway margin), so the
    // check is on the bulk.
    let visible = instances
        .iter()
        .filter(|e| (3.0..=30.0).contains(&e.visibility))
        .count();
    assert!(
        visible * 10 >= instances.len() * 9,
        "{visible} of {} effects within 3-30 noise floors",
        instances.len()
    );
    assert!(cases
        .iter()
        .all(|c| c.effects.is_empty() == (c.visibility == 0.0)));
    // Sensors, rates and resolutions vary.
    let rates: std::collections::BTreeSet<u64> =
        cases.iter().map(|c| c.measurement.rate_hz as u64).collect();
    let bits: std::collections::BTreeSet<u8> =
        cases.iter().map(|c| c.measurement.adc_bits).collect();
    assert!(rates.len() >= 4 && bits.len() >= 4, "{rates:?} {bits:?}");
    assert!(cases.iter().any(|c| c.measurement.noise.ar1_pole > 0.0));
    assert!(cases.iter().any(|c| c.measurement.noise.ar1_pole == 0.0));
}

/// The same seed gives the same cases and records bit for bit; case `i` built alone is case
/// `i` of the set; another seed gives other cases; a case survives a JSON round trip.
#[test]
fn cases_and_records_are_determined_by_the_seed() {
    let n = 16;
    let all = benchmark_cases(SEED, n).unwrap();
    for index in [0, 5, 11] {
        let alone = benchmark_case(SEED, index, n).unwrap();
        assert_eq!(alone, all[index]);
        assert_eq!(generate(&alone).unwrap(), generate(&all[index]).unwrap());
    }
    let other = benchmark_case(SEED + 1, 0, n).unwrap();
    assert_ne!(other.motor, all[0].motor);
    let json = serde_json::to_string(&all[3]).unwrap();
    let back: CaseSpec = serde_json::from_str(&json).unwrap();
    assert_eq!(back, all[3]);
    assert_eq!(generate(&back).unwrap(), generate(&all[3]).unwrap());
}

/// Records carry what the sensors give: an encoder gives an angle, a tachometer none; the
/// pre-trigger samples are at 0 V.
#[test]
fn records_follow_the_logger_settings() {
    for case in benchmark_cases(SEED, 24).unwrap() {
        let records = generate(&case).unwrap();
        let pre = case.measurement.pre_trigger_samples;
        for r in std::iter::once(&records.high)
            .chain(std::iter::once(&records.low))
            .chain(records.validation.iter().map(|(_, r)| r))
        {
            let encoder = matches!(
                case.measurement.speed_sensor,
                motor_model::withheld::SpeedSensor::Encoder { .. }
            );
            assert_eq!(r.position.is_some(), encoder);
            assert!(r.speed.is_some());
            let dt = 1.0 / case.measurement.rate_hz;
            assert!((r.t[1] - r.t[0] - dt).abs() < 1e-12);
            // Pre-trigger voltage is noise around 0 V, far below the levels that follow.
            let peak = r.voltage.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            for v in r.voltage.iter().take(pre) {
                assert!(
                    v.abs() < 0.1 * peak,
                    "{v} V before the trigger, {peak} V after"
                );
            }
        }
        assert_eq!(records.validation.len(), 2);
    }
}

/// `input` as the candidate and the plant both read it without jumps: sampled at `rate_hz`
/// and linearly interpolated, so that each jump becomes a ramp over one sample period. (The
/// candidate simulator reads E at the end of a step that ends on a jump, a leak of about
/// `h ΔE / (6 L)` of current into the step before; on a continuous input both codes see the
/// same E(t).)
fn without_jumps(input: &Input, duration_s: f64, rate_hz: f64) -> Input {
    let n = (duration_s * rate_hz).floor() as usize + 1;
    let volts = (0..n).map(|j| input.volts_at(j as f64 / rate_hz)).collect();
    Input::sampled(0.0, 1.0 / rate_hz, volts).unwrap()
}

/// Each (a)-form effect, on the records of a benchmark case, agrees with the candidate
/// simulator given the same effect: the two are independent codes (different step rules and
/// event locators), each accurate to about 1e-6 of the signal, so they agree to 1e-4 of the
/// channel's peak (a margin for the step-size rules, which differ by up to 5x in h).
#[test]
fn same_shape_forms_agree_with_the_candidate_simulator() {
    for case in one_case_per_effect_and_form(112)
        .into_iter()
        .filter(|c| c.effects[0].effect.form() == Form::SameShape)
    {
        let effect = case.effects[0].effect;
        let effects = Effects::none().with(candidate(&effect).unwrap());
        for spec in &case.records {
            let rate = case.measurement.rate_hz;
            let input = without_jumps(&spec.input, spec.duration_s, rate);
            let ours =
                simulate_plant(&case.motor, &[effect], &input, spec.duration_s, rate).unwrap();
            let theirs = simulate(&case.motor, effects, &input, spec.duration_s, rate).unwrap();
            let gaps = [
                relative_gap(&ours.current, &theirs.current),
                relative_gap(&ours.speed, &theirs.speed),
            ];
            assert!(
                gaps.iter().all(|g| *g <= 1e-4),
                "{} {:?}: current {:.2e}, speed {:.2e} of the peak",
                effect.name(),
                spec.role,
                gaps[0],
                gaps[1]
            );
        }
    }
}

/// The nominal plant is the exact step response (Eqs. (10), (2), (3) through
/// `StepResponse`) to 1e-6 of each channel's peak, for a servo and the paper's motor, at a
/// high and a low step after pre-trigger samples.
#[test]
fn nominal_plant_matches_the_exact_step_response() {
    let servo = MotorParams::new(4.0, 1.5e-3, 0.03, 5e-6, 4e-6, 8e-4).unwrap();
    for (motor, volts, duration, rate) in [
        (servo, 12.0, 0.5, 5000.0),
        (servo, 0.4, 0.5, 5000.0),
        (MotorParams::paper(), 40.0, 5.0, 1000.0),
        (MotorParams::paper(), 0.2, 5.0, 1000.0),
    ] {
        let at = 10.0 / rate;
        let ours = simulate_plant(
            &motor,
            &[],
            &Input::step(volts, at).unwrap(),
            duration,
            rate,
        )
        .unwrap();
        let exact = StepResponse::new(&motor, volts)
            .trace(at, duration, rate)
            .unwrap();
        for (name, a, b) in [
            ("current", &ours.current, &exact.current),
            ("speed", &ours.speed, &exact.speed),
            ("position", &ours.position, &exact.position),
        ] {
            let gap = relative_gap(a, b);
            assert!(gap <= 1e-6, "{volts} V, {name}: {gap:.2e} of the peak");
        }
    }
}

/// The generator's step rule is converged for every effect in both forms: with steps four
/// times shorter, the high-step and reversal records change by less than 2 % of a noise floor
/// RMS (the (b) forms have no other reference).
#[test]
fn plant_steps_are_converged_below_the_noise() {
    for case in one_case_per_effect_and_form(112) {
        let effects = case.plant_effects();
        let floors = case.floors();
        for (spec, floor) in case.records.iter().zip(&floors) {
            if !matches!(spec.role, RecordRole::HighStep | RecordRole::Reversal) {
                continue;
            }
            let rate = case.measurement.rate_hz;
            let plant = Plant::new(case.motor, &effects, spec.input.clone()).unwrap();
            let h = plant.max_step_s();
            let coarse = plant.run(spec.duration_s, rate).unwrap();
            let fine = Plant::new(case.motor, &effects, spec.input.clone())
                .unwrap()
                .with_max_step(h / 4.0)
                .unwrap()
                .run(spec.duration_s, rate)
                .unwrap();
            let change = visibility(
                std::slice::from_ref(&coarse),
                std::slice::from_ref(&fine),
                std::slice::from_ref(floor),
            );
            assert!(
                change < 0.02,
                "{} {:?}: {change:.3} noise floors from a 4x finer step",
                effects[0].form_label(),
                spec.role
            );
        }
    }
}

/// Normalised squared distance of two sets of traces: Σ (RMS difference / noise floor)² over
/// records and channels.
fn distance(a: &[Trace], b: &[Trace], case: &CaseSpec) -> f64 {
    let floors = case.floors();
    let ms = |x: &[f64], y: &[f64]| {
        x.iter().zip(y).map(|(p, q)| (p - q).powi(2)).sum::<f64>() / x.len().max(1) as f64
    };
    a.iter()
        .zip(b)
        .zip(&floors)
        .map(|((p, q), f)| {
            ms(&p.current, &q.current) / f.current_a.powi(2)
                + ms(&p.speed, &q.speed) / f.speed_rad_s.powi(2)
        })
        .sum()
}

/// The best (a)-form look-alike of a (b)-form effect, by a compass search on its parameters
/// (`to_effect` maps the search coordinates to the effect), bounded to 80 rounds.
fn best_look_alike(
    case: &CaseSpec,
    target: &[Trace],
    start: Vec<f64>,
    to_effect: impl Fn(&[f64]) -> PlantEffect,
) -> Vec<Trace> {
    let cost = |u: &[f64]| {
        let e = to_effect(u);
        if e.validate(&case.motor).is_err() {
            return (f64::INFINITY, Vec::new());
        }
        match case.traces_with(&[e]) {
            Ok(tr) => (distance(&tr, target, case), tr),
            Err(_) => (f64::INFINITY, Vec::new()),
        }
    };
    let mut u = start;
    let (mut best, mut traces) = cost(&u);
    let mut step = 0.5;
    for _ in 0..80 {
        let mut improved = false;
        for j in 0..u.len() {
            for sign in [1.0, -1.0] {
                let mut v = u.clone();
                v[j] += sign * step;
                let (c, tr) = cost(&v);
                if c < best {
                    (best, traces, u) = (c, tr, v);
                    improved = true;
                }
            }
        }
        if !improved {
            step *= 0.5;
            if step < 1e-3 {
                break;
            }
        }
    }
    traces
}

/// Each (b) form differs in shape from its best (a)-form look-alike: made as visible as 20
/// noise floors, the best-fitting (a) form with its own parameters free still leaves a residual
/// above white noise by a 3-sigma chi-square margin on some record and channel.
#[test]
fn other_shape_forms_differ_from_their_best_same_shape_look_alike() {
    for case in one_case_per_effect_and_form(112)
        .into_iter()
        .filter(|c| c.effects[0].effect.form() == Form::OtherShape)
    {
        let p = case.motor;
        let nominal = case.traces_with(&[]).unwrap();
        let floors = case.floors();
        let mut effect = case.effects[0].effect;
        // Scale to about 20 noise floors (visibility is close to linear in the magnitude).
        for _ in 0..3 {
            let v = visibility(&case.traces_with(&[effect]).unwrap(), &nominal, &floors);
            effect = effect.scaled(20.0 / v, &p);
        }
        let target = case.traces_with(&[effect]).unwrap();
        let exp = f64::exp;
        let look_alike = match effect {
            PlantEffect::LuGre {
                static_torque_nm,
                stribeck_speed_rad_s,
                ..
            } => best_look_alike(
                &case,
                &target,
                vec![(static_torque_nm - p.ts_nm).ln(), stribeck_speed_rad_s.ln()],
                |u| PlantEffect::StribeckGaussian {
                    static_torque_nm: p.ts_nm + exp(u[0]),
                    stribeck_speed_rad_s: exp(u[1]),
                },
            ),
            PlantEffect::CoggingHarmonics {
                amplitude_nm,
                periods_per_rev,
                phase_rad,
                ..
            } => best_look_alike(&case, &target, vec![amplitude_nm.ln(), phase_rad], |u| {
                PlantEffect::CoggingSine {
                    amplitude_nm: exp(u[0]),
                    periods_per_rev,
                    phase_rad: u[1],
                }
            }),
            PlantEffect::SensorSecondOrder {
                natural_pulsation_rad_s,
            } => best_look_alike(
                &case,
                &target,
                vec![(2.0 / natural_pulsation_rad_s).ln()],
                |u| PlantEffect::SensorFirstOrder { tau_f_s: exp(u[0]) },
            ),
            PlantEffect::ThermalTwoNode {
                winding_capacity_j_per_k,
                winding_to_housing_k_per_w,
                alpha_per_k,
                ..
            } => best_look_alike(
                &case,
                &target,
                vec![
                    winding_to_housing_k_per_w.ln(),
                    winding_capacity_j_per_k.ln(),
                ],
                |u| PlantEffect::ThermalOneNode {
                    thermal_resistance_k_per_w: exp(u[0]),
                    thermal_capacity_j_per_k: exp(u[1]),
                    alpha_per_k,
                },
            ),
            PlantEffect::DragPowerOneAndHalf { c_nm_per_rad_s_pow } => {
                let w = target[0]
                    .speed
                    .last()
                    .copied()
                    .unwrap_or(1.0)
                    .abs()
                    .max(1e-3);
                best_look_alike(
                    &case,
                    &target,
                    vec![(c_nm_per_rad_s_pow / w.sqrt()).ln()],
                    |u| PlantEffect::DragQuadratic {
                        c_nms2_per_rad2: exp(u[0]),
                    },
                )
            }
            PlantEffect::BrushLogarithmic {
                drop_v,
                onset_current_a,
            } => best_look_alike(
                &case,
                &target,
                vec![(2.0 * drop_v).ln(), onset_current_a.ln()],
                |u| PlantEffect::BrushClamp {
                    drop_v: exp(u[0]),
                    knee_current_a: exp(u[1]),
                },
            ),
            PlantEffect::SaturationAbsolute {
                saturation_current_a,
                min_ratio,
            } => best_look_alike(
                &case,
                &target,
                vec![saturation_current_a.ln(), (1.0 - min_ratio).ln()],
                |u| PlantEffect::SaturationLorentzian {
                    saturation_current_a: exp(u[0]),
                    min_ratio: 1.0 - exp(u[1]).min(0.99),
                },
            ),
            other => panic!("not a (b) form: {other:?}"),
        };
        // A deterministic residual of RMS r noise floors over N samples of white noise raises
        // the sum of squares by N r², against a spread of √(2N): detectable at 3 spreads when
        // N r² > 3 √(2N).
        let mut best = 0.0_f64;
        for ((a, b), f) in look_alike.iter().zip(&target).zip(&floors) {
            for (x, y, floor) in [
                (&a.current, &b.current, f.current_a),
                (&a.speed, &b.speed, f.speed_rad_s),
            ] {
                let n = x.len() as f64;
                let ms = x.iter().zip(y).map(|(p, q)| (p - q).powi(2)).sum::<f64>() / n;
                best = best.max(n * ms / floor.powi(2) / (3.0 * (2.0 * n).sqrt()));
            }
        }
        assert!(
            best > 1.0,
            "{}: the best (a) look-alike's residual is only {best:.2} of the detectable level ({:.2} noise floors RMS)",
            effect.name(),
            visibility(&look_alike, &target, &floors)
        );
    }
}
