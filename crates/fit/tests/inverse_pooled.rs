//! The inverse model of a current-driven axis on records moving one way only: pooled with a
//! record moving the other way, Ts and the offset separate; alone, the offset is fixed at 0
//! (said) and Ts carries the constant load, with an interval.

use fit::{identify_inverse_model_pooled, AxisRecord, InverseModelSettings, OffsetStatus};
use motor_model::{AxisParams, NoiseRng};

const DT: f64 = 1e-3;

fn axis() -> AxisParams {
    AxisParams {
        mass_kg: 2.0,
        viscous_ns_per_m: 15.0,
        coulomb_n: 4.0,
        offset_n: 1.5,
    }
}

/// An open-loop run of the axis moving in `direction` only under a force that is piecewise
/// constant, sample `i`'s value acting from half a period before its instant to half a period
/// after (centred, so that the record has no half-sample lag of the force behind the motion),
/// integrated exactly (first-order speed dynamics while the direction holds). The force varies
/// so that J and f are excited; the position is quantised to 1 µm and the force is noisy.
fn run(direction: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let a = axis();
    let n = 8000;
    let tau = a.mass_kg / a.viscous_ns_per_m;
    // Enough to break away at once and keep moving: the speed never returns to 0.
    let force_at = |t: f64| direction * (a.coulomb_n + 3.0 + 2.5 * (3.0 * t).sin()) + a.offset_n;
    let mut rng = NoiseRng::new(seed);
    let (mut q, mut v) = (0.0_f64, 0.0_f64);
    let (mut positions, mut forces) = (Vec::with_capacity(n), Vec::with_capacity(n));
    // Advances the state by `h` under `force`: v → v∞ with time constant τ.
    let advance = |q: &mut f64, v: &mut f64, force: f64, h: f64| {
        let v_inf = (force - a.coulomb_n * direction - a.offset_n) / a.viscous_ns_per_m;
        let decay = (-h / tau).exp();
        *q += v_inf * h + (*v - v_inf) * tau * (1.0 - decay);
        *v = v_inf + (*v - v_inf) * decay;
        assert!(*v * direction >= 0.0, "the run must move one way only");
    };
    for i in 0..n {
        let t = i as f64 * DT;
        let force = force_at(t);
        positions.push((q / 1e-6).round() * 1e-6);
        forces.push(force + 0.05 * rng.normal());
        advance(&mut q, &mut v, force, 0.5 * DT);
        advance(&mut q, &mut v, force_at(t + DT), 0.5 * DT);
    }
    (positions, forces)
}

fn settings() -> InverseModelSettings {
    InverseModelSettings {
        position_cutoff_hz: 20.0,
        position_filter_order: 4,
        decimation: 5,
        fit_offset: true,
    }
}

fn inside(value: f64, ci: [f64; 2]) -> bool {
    ci[0] <= value && value <= ci[1]
}

#[test]
fn a_forward_and_a_backward_record_pooled_separate_ts_from_the_offset() {
    let (qf, ff) = run(1.0, 1);
    let (qb, fb) = run(-1.0, 2);
    let records = [
        AxisRecord {
            dt: DT,
            torque: &ff,
            position: &qf,
        },
        AxisRecord {
            dt: DT,
            torque: &fb,
            position: &qb,
        },
    ];
    let fit = identify_inverse_model_pooled(&records, settings()).unwrap();
    assert_eq!(fit.offset_status, OffsetStatus::Fitted);
    let ci = fit.ci95.expect("intervals");
    let a = axis();
    let f = fit.axis;
    eprintln!("pooled: {f:?} {ci:?}");
    for (name, got, truth) in [
        ("M", f.mass_kg, a.mass_kg),
        ("Fv", f.viscous_ns_per_m, a.viscous_ns_per_m),
        ("Fc", f.coulomb_n, a.coulomb_n),
        ("offset", f.offset_n, a.offset_n),
    ] {
        assert!(
            (got / truth - 1.0).abs() < 0.05,
            "{name}: {got} against {truth}"
        );
    }
    assert!(
        inside(a.coulomb_n, ci[2]) && inside(a.offset_n, ci[3]),
        "{ci:?}"
    );
    assert_eq!(fit.fitted.len(), 2);
}

#[test]
fn one_direction_alone_fixes_the_offset_and_ts_carries_the_load() {
    let (q, f) = run(1.0, 3);
    let records = [AxisRecord {
        dt: DT,
        torque: &f,
        position: &q,
    }];
    let fit = identify_inverse_model_pooled(&records, settings()).unwrap();
    assert_eq!(fit.offset_status, OffsetStatus::FixedOneDirection);
    assert_eq!(fit.axis.offset_n, 0.0);
    let ci = fit.ci95.expect("an interval for Ts, not none");
    // Moving forward, friction and the constant load add up: Ts + offset.
    let a = axis();
    let carried = a.coulomb_n + a.offset_n;
    eprintln!("one way: {:?} {ci:?}", fit.axis);
    assert!(
        (fit.axis.coulomb_n / carried - 1.0).abs() < 0.05,
        "Ts {} against Ts + offset {carried}",
        fit.axis.coulomb_n
    );
    assert!(ci[2][1] - ci[2][0] > 0.0 && ci[2][1] - ci[2][0] < 0.5 * carried);
}
