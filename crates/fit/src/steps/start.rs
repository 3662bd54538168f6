//! A start for the full model that needs no damping regime: steady states and rise times.
//!
//! With the steady values of two steps, Eq. (5) `E = R Ir + k Ωr` gives R and k (two linear
//! equations), and the torque balance `k Ir = Ts + f Ωr` gives Ts and f. L follows from the
//! first current sample, which obeys Eq. (10) before the back-EMF builds up, and J from the
//! time the high-voltage speed takes to reach 1 − 1/e of its final value (the slow time
//! constant `≈ J R/(R f + k²)` when τe ≪ τm). Rough, but on the right side of every regime.

use motor_model::MotorParams;

use crate::error::FitError;
use crate::estimation::checks::tail_mean;
use crate::estimation::records::StepTest;

fn bad(reason: String) -> FitError {
    FitError::MethodDomain {
        equation: "steady-state start (Eqs. (5), (2), (10))",
        reason,
    }
}

/// Solves `[a b; c d] x = [e; f]`.
fn solve2(a: f64, b: f64, c: f64, d: f64, e: f64, f: f64) -> Option<(f64, f64)> {
    let det = a * d - b * c;
    (det.abs() > f64::EPSILON * (a * d).abs().max((b * c).abs()))
        .then(|| ((e * d - b * f) / det, (a * f - e * c) / det))
}

/// The value a series settles to: the mean of its last tenth, or, where the record ends while
/// still converging on it, that value extrapolated by Aitken's Δ² from the means of its last
/// three tenths `a₁, a₂, a₃`, `a₃ − (a₃ − a₂)²/((a₃ − a₂) − (a₂ − a₁))` — exact for a tail that
/// is one decaying exponential plus a constant, which the slowest mode of Eq. (2) makes of any
/// step response once the faster one has died out. Used only when the three means move the
/// same way and by shrinking steps (`0 < (a₃ − a₂)/(a₂ − a₁) < 0.9`) by more than their noise;
/// a paper-motor step recorded for 20 s (one mechanical time constant) read its steady speed
/// 13 % low from the tail mean and the full fit started from it ended at L = 8e-87 H.
fn extrapolated_steady_value(y: &[f64]) -> f64 {
    let m = y.len() / 10;
    if m < 3 {
        return tail_mean(y);
    }
    let n = y.len();
    let mean = |a: usize| y[a..a + m].iter().sum::<f64>() / m as f64;
    let (a1, a2, a3) = (mean(n - 3 * m), mean(n - 2 * m), mean(n - m));
    let (d1, d2) = (a2 - a1, a3 - a2);
    // Noise of a tenth's mean, from the scatter within the last tenth about its own line.
    let noise = crate::estimation::records::noise_std(&y[n - m..]) / (m as f64).sqrt();
    let ratio = d2 / d1;
    if d1.abs() > 10.0 * noise && ratio > 0.0 && ratio < 0.9 {
        a3 + d2 * ratio / (1.0 - ratio)
    } else {
        a3
    }
}

/// A start for [`crate::identify_full`] from a high- and a low-voltage test with speed.
pub fn steady_state_start(
    high: &StepTest<'_>,
    low: &StepTest<'_>,
) -> Result<MotorParams, FitError> {
    crate::estimation::checks::check_step_test("high-voltage test", high)?;
    crate::estimation::checks::check_step_test("low-voltage test", low)?;
    let (Some(wh), Some(wl)) = (high.speed, low.speed) else {
        return Err(bad("both tests need a speed (or position) channel".into()));
    };
    let (ih, il) = (
        extrapolated_steady_value(high.current),
        extrapolated_steady_value(low.current),
    );
    let (oh, ol) = (extrapolated_steady_value(wh), extrapolated_steady_value(wl));
    // The start reads steady values off the records' ends: where it fails, a record that has
    // not settled is the likelier cause, and the one to name.
    let unsettled = || {
        [("high", high, wh), ("low", low, wl)]
            .into_iter()
            .flat_map(|(which, t, w)| [(which, "current", t.current, t.dt), (which, "speed", w, t.dt)])
            .find_map(|(which, name, y, dt)| {
                crate::estimation::checks::check_settled_for(
                    &format!("{which}-voltage test"),
                    name,
                    y,
                    dt,
                    "the steady-state start needs settled records: record longer (several mechanical time constants)",
                )
                .err()
            })
    };
    let (r, k) = solve2(ih, oh, il, ol, high.volts, low.volts).ok_or_else(|| {
        unsettled().unwrap_or_else(|| {
            bad("the two tests' steady states are proportional: use two different voltages".into())
        })
    })?;
    // k Ir = Ts + f Ωr for both tests.
    let (ts, f) = solve2(1.0, oh, 1.0, ol, k * ih, k * il)
        .ok_or_else(|| bad("the two tests reach the same speed".into()))?;
    // Eq. (10) where the current first reaches 30 % of its peak: I = E/R (1 − e^{−t R/L}),
    // the back-EMF still small there. (Read at the first sample after the step, the current of
    // a 40 V step on the paper's motor, 0.13 A after 1 ms, sat within the noise of a 10-bit
    // ADC and could read ≤ 0, which took L as unresolved: 2.8e-5 H, and the fit ended at
    // L = 8e-87 H.)
    let peak = high
        .current
        .iter()
        .fold(0.0f64, |m, &i| m.max(i * high.volts.signum()));
    let crossing = high
        .current
        .iter()
        .position(|&i| i * high.volts.signum() >= 0.3 * peak)
        .unwrap_or(1)
        .max(1);
    let t1 = high.t_first + crossing as f64 * high.dt;
    let i1 = high.current.get(crossing).copied().unwrap_or(f64::NAN);
    let frac = r * i1 / high.volts;
    let l = if frac > 0.0 && frac < 1.0 {
        -t1 * r / (-frac).ln_1p()
    } else {
        // Current already near E/R at that sample: L is below what the record resolves.
        0.1 * t1 * r
    };
    let target = (1.0 - (-1.0f64).exp()) * oh;
    let rise = wh
        .iter()
        .position(|w| w.abs() >= target.abs())
        .map_or(f64::NAN, |i| high.t_first + i as f64 * high.dt);
    // A speed past 63 % of its steady value at the first sample after the step: J is below
    // what the record resolves (as L above), and the rise is taken as half a period.
    let rise = if rise <= 0.0 { 0.5 * high.dt } else { rise };
    let j = rise * (r * f + k * k) / r;
    // R, k, f and Ts as the steady states give them, settled: a motor they refuse is one the
    // nominal model cannot explain (an unmodelled effect), a failed identification.
    MotorParams::new(r, l, k, f, j, ts).map_err(|e| {
        unsettled().unwrap_or(FitError::Model {
            context: "steady-state start (Eqs. (5), (2), (10))",
            source: e,
        })
    })
}
