//! Every public entry point that takes channels checks that they align: channels of mismatched
//! lengths (current, speed, angle, exclusion masks, time and voltage) give an error, never a
//! panic or an out-of-bounds index.

use fit::{
    check_step_test, electrical_equation, equation_error_start, fit_33, identify_full,
    identify_inverse_model, identify_output_error, identify_paper, identify_step_pair, locate_step,
    record_speed, speed_check_c8, steady_state_start, torque_constant, voltage_input,
    ExcitedRecord, InverseModelSettings, LmSettings, Params33, Record33, StepInputs, StepMethod,
    StepRecord, StepTest,
};
use motor_model::{Input, MotorParams, MotorState, StepResponse};
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
            for r in &results[..3] {
                prop_assert!(r.is_some());
            }
        }
        let pair = StepRecord { test, inputs: StepInputs::default() };
        for method in [StepMethod::Paper, StepMethod::Full] {
            let piped = identify_step_pair(&pair, &pair, method, settings);
            if used_misaligned {
                prop_assert!(piped.is_err());
            }
        }
        let input = Input::Step { volts: 40.0, at_s: 0.0 };
        let record = ExcitedRecord {
            input: &input,
            dt: 1e-3,
            current: &current,
            speed: use_speed.then_some(&speed[..]),
            position: use_angle.then_some(&angle[..]),
            exclude_current: use_masks.then_some(&mask_i[..]),
            exclude_speed: use_masks.then_some(&mask_w[..]),
        };
        let oe = [
            electrical_equation(&[record], 0.1).err().map(|e| e.to_string()),
            equation_error_start(&[record]).err().map(|e| e.to_string()),
            identify_output_error(&[record], &start, settings).err().map(|e| e.to_string()),
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
