//! Every public entry point that takes channels checks that they align: channels of mismatched
//! lengths (current, speed, angle, exclusion masks, time and voltage) give an error, never a
//! panic or an out-of-bounds index.

use fit::diagnose::localise::{
    localise, localise_with_floors, LocaliseSettings, ResidualChannel, ResidualRecord,
};
use fit::diagnose::{
    diagnose, diagnose_inverse, DiagnoseProgress, DiagnoseSettings, InverseDiagnoseSettings,
};
use fit::{
    check_step_test, detect_initial_state, electrical_equation, encoder_speed,
    equation_error_start, equation_error_start_with_initial_states, fit_33, identify_feedforward,
    identify_full, identify_full_with_inputs, identify_inverse_model,
    identify_inverse_model_pooled, identify_paper, identify_step_pair, locate_step,
    locate_step_with, predict_output_error, record_speed, speed_check_c8, steady_state_start,
    torque_constant, voltage_input, voltage_levels, AxisRecord, Channel, ExcitedRecord,
    FeedforwardSettings, InitialState, InverseModelSettings, LmSettings, OutputError, Params33,
    Record33, SpeedRecord, StepInputs, StepMethod, StepRecord, StepTest,
};
use motor_model::{Effects, Input, MotorParams, MotorState, StepResponse};
use proptest::prelude::*;

/// A noise-free 40 V step of the paper's motor, 2 s at 1 kHz: current, speed, angle.
fn channels() -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut s = vec![MotorState::default(); 2001];
    StepResponse::new(&MotorParams::paper(), 40.0).fill(0.0, 1e-3, &mut s);
    (
        s.iter().map(|x| x.current_a).collect(),
        s.iter().map(|x| x.speed_rad_s).collect(),
        s.iter().map(|x| x.position_rad).collect(),
    )
}

/// A channel length beside a current of `n` samples: equal (half the time), shorter, longer or
/// empty, by `(choice, amount)`.
fn length(n: usize, (choice, amount): (u8, usize)) -> usize {
    match choice {
        0 => n.saturating_sub(amount),
        1 => n + amount,
        2 => 0,
        _ => n,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn mismatched_channels_are_errors_not_panics(
        n_current in 1usize..2001,
        lengths in proptest::array::uniform4((0u8..6, 1usize..50)),
        use_speed in any::<bool>(),
        use_angle in any::<bool>(),
        use_masks in any::<bool>(),
    ) {
        let [n_speed, n_angle, n_mask_i, n_mask_w] = lengths.map(|l| length(n_current, l));
        let (i, w, th) = channels();
        let grow = |v: &[f64], n: usize| -> Vec<f64> {
            (0..n).map(|k| v.get(k).copied().unwrap_or(0.0)).collect()
        };
        let current = grow(&i, n_current);
        let speed = grow(&w, n_speed);
        let angle = grow(&th, n_angle);
        let mask_i = vec![false; n_mask_i];
        let mask_w = vec![false; n_mask_w];
        let test = StepTest {
            volts: 40.0,
            t_first: 0.0,
            dt: 1e-3,
            current: &current,
            speed: use_speed.then_some(&speed[..]),
            position: use_angle.then_some(&angle[..]),
            exclude_current: use_masks.then_some(&mask_i[..]),
            exclude_speed: use_masks.then_some(&mask_w[..]),
        };
        let check = check_step_test("test", &test);
        // Channels that do not align must be refused; aligned ones may still be refused for
        // other reasons (too short, no motion), but never by a panic.
        let used_misaligned = (use_speed && n_speed != n_current)
            || (use_angle && n_angle != n_current)
            || (use_masks && (n_mask_i != n_current || n_mask_w != n_current));
        if used_misaligned {
            prop_assert!(check.is_err());
        }
        let settings = LmSettings { max_iters: 3, ..LmSettings::default() };
        let start = MotorParams::paper();
        let results = [
            identify_full(&[test, test], &start, settings).err().map(|e| e.to_string()),
            identify_paper(&test, &test, settings).err().map(|e| e.to_string()),
            steady_state_start(&test, &test).err().map(|e| e.to_string()),
            speed_check_c8(&test, 0.0, Params33 { alpha: 5.0, sigma: 0.5, omega_a: 0.4 }, settings)
                .err()
                .map(|e| e.to_string()),
        ];
        if used_misaligned {
            for r in &results {
                prop_assert!(r.is_some());
            }
        }
        let pair = StepRecord { test, inputs: StepInputs::default(), whole: None };
        for method in [StepMethod::Paper, StepMethod::Full] {
            let piped = identify_step_pair(&pair, &pair, method, settings);
            if used_misaligned {
                prop_assert!(piped.is_err());
            }
        }
        let input = Input::Step { volts: 40.0, at_s: 0.0 };
        let record = excited(&input, &test);
        let oe = [
            electrical_equation(&[record], 0.1).err().map(|e| e.to_string()),
            equation_error_start(&[record]).err().map(|e| e.to_string()),
            OutputError::new(&[record], start).solver(settings).fit().err().map(|e| e.to_string()),
        ];
        if used_misaligned {
            for r in &oe {
                prop_assert!(r.is_some());
            }
        }
        let k = torque_constant(None, Some(&record), 0.1);
        if used_misaligned {
            prop_assert!(k.is_err());
        }
        let t_speed: Vec<f64> = (0..n_current).map(|k| k as f64 * 1e-3).collect();
        let w = record_speed(&t_speed, use_speed.then_some(&speed[..]), use_angle.then_some(&angle[..]));
        prop_assert_eq!(w.is_some(), use_speed || use_angle);
        let torque: Vec<f64> = current.iter().map(|c| 0.15 * c).collect();
        let inverse = identify_inverse_model(1e-3, &torque, &angle, InverseModelSettings::default());
        if n_angle != n_current {
            prop_assert!(inverse.is_err());
        }
        let t: Vec<f64> = (0..n_current).map(|k| k as f64 * 1e-3).collect();
        let volts = vec![40.0; n_speed];
        if n_speed != n_current {
            prop_assert!(voltage_input(&t, &volts).is_err());
            prop_assert!(locate_step(&t, &volts).is_err());
        }
        let normalized: Vec<f64> = current.iter().map(|c| c / 53.57).collect();
        let _ = fit_33(&Record33 { t_first: 0.0, dt: 1e-3, normalized_current: &normalized }, Params33 { alpha: 1.0, sigma: 1.0, omega_a: 1.0 }, settings);
    }
}

/// The record of any excitation with the channels of `test`, driven by `input`.
fn excited<'a>(input: &'a Input, test: &StepTest<'a>) -> ExcitedRecord<'a> {
    ExcitedRecord {
        input,
        dt: test.dt,
        current: test.current,
        speed: test.speed,
        position: test.position,
        exclude_current: test.exclude_current,
        exclude_speed: test.exclude_speed,
    }
}

/// A length unlike `n` (≥ 1) by `(choice, amount)` (amount ≥ 1): shorter, longer or empty.
fn other_length(n: usize, (choice, amount): (u8, usize)) -> usize {
    match choice {
        0 => n.saturating_sub(amount),
        1 => n + amount,
        _ => 0,
    }
}

/// Which channel of a record is given the wrong length.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Off {
    Speed,
    Angle,
    Mask,
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// The entry points the test above does not reach (the variants with inputs, effects or
    /// initial states, the predictions, the initial-state detection, the voltage-and-speed fit,
    /// the pooled inverse model, the step location with a quantum, the residual localisation
    /// and both diagnoses), each given one channel of the wrong length: an error every time.
    #[test]
    fn every_other_entry_point_refuses_a_misaligned_channel(
        n in 50usize..2001,
        change in (0u8..3, 1usize..50),
        off in prop_oneof![Just(Off::Speed), Just(Off::Angle), Just(Off::Mask)],
    ) {
        let (i, w, th) = channels();
        let m = other_length(n, change);
        let len = |channel: Off| if channel == off { m } else { n };
        let grow = |v: &[f64], k: usize| -> Vec<f64> {
            (0..k).map(|j| v.get(j).copied().unwrap_or(0.0)).collect()
        };
        let current = grow(&i, n);
        let speed = grow(&w, len(Off::Speed));
        let angle = grow(&th, len(Off::Angle));
        let mask = vec![false; len(Off::Mask)];
        let input = Input::Step { volts: 40.0, at_s: 0.0 };
        let settings = LmSettings { max_iters: 3, ..LmSettings::default() };
        let start = MotorParams::paper();
        let none = Effects::none();
        let test = StepTest {
            volts: 40.0,
            t_first: 0.0,
            dt: 1e-3,
            current: &current,
            speed: Some(&speed),
            position: (off == Off::Angle).then_some(&angle[..]),
            exclude_current: None,
            exclude_speed: Some(&mask),
        };
        let record = excited(&input, &test);
        prop_assert!(identify_full_with_inputs(&[test], &[StepInputs::default()], &start, settings).is_err());
        prop_assert!(detect_initial_state(&record).is_err());
        prop_assert!(equation_error_start_with_initial_states(&[record], &[InitialState::Rest]).is_err());
        prop_assert!(OutputError::new(&[record], start).effects(none).solver(settings).fit().is_err());
        prop_assert!(OutputError::new(&[record], start).level_priors(&[Vec::new()]).solver(settings).fit().is_err());
        prop_assert!(OutputError::new(&[record], start).level_priors(&[Vec::new()]).effects(none).solver(settings).fit().is_err());
        prop_assert!(OutputError::new(&[record], start).initial_states(&[InitialState::Free]).effects(none).solver(settings).fit().is_err());
        prop_assert!(predict_output_error(&[record], &start, &none).is_err());

        // A column of time beside a voltage of another length.
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let volts = vec![40.0; m];
        prop_assert!(voltage_levels(&t, &volts, Some(0.04)).is_err());
        prop_assert!(locate_step_with(&t, &volts, Some(0.04)).is_err());
        // The encoder speed takes the samples both columns have: no panic, no longer than either.
        prop_assert!(encoder_speed(&t, &angle).len() <= n.min(angle.len()));

        // The voltage-and-speed fit: a speed or angle and its mask of different lengths.
        let full_mask = vec![false; n];
        let speed_record = SpeedRecord {
            input: &input,
            dt: 1e-3,
            speed: (off != Off::Angle).then_some(&speed[..]),
            position: (off == Off::Angle).then_some(&angle[..]),
            exclude: Some(if off == Off::Mask { &mask[..] } else { &full_mask[..] }),
            priors: &[],
            at_rest: None,
        };
        prop_assert!(identify_feedforward(&[speed_record], FeedforwardSettings::default()).is_err());

        // The inverse model: a torque and a position of different lengths.
        let torque: Vec<f64> = current.iter().map(|c| 0.15 * c).collect();
        let axis = AxisRecord { dt: 1e-3, torque: &torque, position: &grow(&th, m) };
        prop_assert!(identify_inverse_model_pooled(&[axis], InverseModelSettings::default()).is_err());
        prop_assert!(diagnose_inverse(&[axis], &[], &["axis"], &InverseDiagnoseSettings::default()).is_err());

        // The localisation: a channel's measurement and model, or a record's signals, of
        // different lengths.
        let voltage = vec![40.0; n];
        let model = grow(&i, m);
        let residual = ResidualRecord {
            name: "record",
            dt: 1e-3,
            voltage: &voltage,
            current: Some(&current),
            speed: Some(&speed),
            angle: None,
            channels: vec![ResidualChannel { kind: Channel::Current, measured: &current, model: &model }],
        };
        prop_assert!(localise(std::slice::from_ref(&residual), &LocaliseSettings::default()).is_err());
        prop_assert!(localise_with_floors(&[residual], &[vec![1e-3]], &LocaliseSettings::default()).is_err());

        // The diagnosis, on a misaligned training or validation record.
        let quiet = |_: DiagnoseProgress| {};
        let aligned_speed = grow(&w, n);
        let aligned = ExcitedRecord { speed: Some(&aligned_speed), position: None, exclude_speed: None, ..record };
        prop_assert!(diagnose(&[record], &[], &["record"], &start, &DiagnoseSettings::default(), &quiet).is_err());
        prop_assert!(diagnose(&[aligned], &[record], &["record", "validation"], &start, &DiagnoseSettings::default(), &quiet).is_err());

        // Aligned channels, but one entry too many of what goes with each record: the level
        // priors, the step inputs, the initial states.
        let aligned_test = StepTest { speed: Some(&aligned_speed), position: None, exclude_speed: None, ..test };
        let two_inputs = [StepInputs::default(), StepInputs::default()];
        prop_assert!(identify_full_with_inputs(&[aligned_test], &two_inputs, &start, settings).is_err());
        prop_assert!(OutputError::new(&[aligned], start).level_priors(&[Vec::new(), Vec::new()]).solver(settings).fit().is_err());
        let two_states = [InitialState::Rest, InitialState::Rest];
        prop_assert!(equation_error_start_with_initial_states(&[aligned], &two_states).is_err());
        prop_assert!(OutputError::new(&[aligned], start).initial_states(&two_states).effects(none).solver(settings).fit().is_err());
    }
}
