//! Where each candidate's refit starts: its shape parameters from the records (the cogging
//! period count from the residual's ripple, knee scales, time constants, speeds and currents
//! from their peaks), the cogging prefilter, and the starts that split an effect from the motor
//! parameter the nominal fit absorbed it into.

use motor_model::{
    BrushDrop, CoggingTorque, CurrentSensorLag, Effect, EffectKind, InductanceSaturation,
    MotorParams, QuadraticDrag, StribeckFriction, ThermalDrift, COPPER_ALPHA_PER_K,
};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::diagnose::base::Base;
use crate::diagnose::heldout::channel_sigma;
use crate::diagnose::jumps::record_rows;
use crate::diagnose::localise::{Localisation, LocaliseSettings};
use crate::diagnose::report::DiagnoseSettings;
use crate::diagnose::screen::BaseProjection;
use crate::estimation::fitted::FullFit;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel};

/// Cogging period counts screened with their full signature at most, beside the angle
/// search's: the best by [`cogging_prefilter`].
pub(crate) const COGGING_SCREENED: usize = 4;

/// The cogging period counts whose full signature the screening computes on top of `base`:
/// the angle search's ([`ripple_periods`]) and the best [`COGGING_SCREENED`] others by
/// [`cogging_prefilter`]; every N of [`cogging_counts`] when that cannot be built.
pub(crate) fn cogging_screened(
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    projection: &BaseProjection,
    localisation: &Localisation,
    settings: &DiagnoseSettings,
) -> Vec<u32> {
    let first = ripple_periods(localisation);
    let max_harmonic = settings.localise.max_harmonic;
    match cogging_prefilter(base, sigmas, projection, max_harmonic, settings.step_factor) {
        Some(ranked) => std::iter::once(first)
            .chain(
                ranked
                    .into_iter()
                    .filter(|&n| n != first)
                    .take(COGGING_SCREENED),
            )
            .collect(),
        None => cogging_counts(first, max_harmonic),
    }
}

/// Sub-steps of the linear response per sample at most, so that the probe `sin Nθ` turns at
/// most half a radian per sub-step where it can.
pub(crate) const PROBE_SUBSTEPS: usize = 16;

/// The period counts N = 1..=`max_harmonic` ranked by the score of an approximate cogging
/// signature (best first), or `None` when it cannot be built. The signature of a small load
/// torque `A sin(Nθ + φ)` is the response of the base motor linearised along its own
/// trajectory — `L δİ = −R δI − k δΩ`, `J δΩ̇ = k δI − f δΩ − u`, `δθ̇ = δΩ` (SPEC (2)) — to
/// the probes `u = sin Nθ(t)` and `u = cos Nθ(t)` while the rotor turns (held at rest while
/// it sticks), advanced exactly over each sub-step (a matrix exponential) and read where the
/// records' channels are (the current, the speed, or the central difference of the angle for
/// an encoder). One such response costs a fraction of a simulation, so every N is looked at;
/// the best few are screened with the full signature ([`candidate_starts`]). The base
/// model's other effects are left out of the linearisation: it ranks N, it does not test.
pub(crate) fn cogging_prefilter(
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    projection: &BaseProjection,
    max_harmonic: u32,
    step_factor: f64,
) -> Option<Vec<u32>> {
    use nalgebra::{Matrix3, Matrix4, Vector3};
    let m = &base.motor;
    let (r, l, k, f, j) = (m.r_ohm, m.l_henry, m.k_nm_per_a, m.f_nms_per_rad, m.j_kgm2);
    // Each training record's rows and the base trajectory they are read along.
    let mut layouts = Vec::with_capacity(base.train.len());
    for (idx, rec) in base.train.iter().enumerate() {
        let rows = record_rows(
            idx,
            rec,
            rec.input,
            (&base.motor, &base.effects),
            sigmas,
            step_factor,
        )?;
        let n = rec.current.len();
        let trace = motor_model::Simulator::new(*m, base.effects, rec.input.clone())
            .and_then(|s| s.with_step_factor(step_factor))
            .and_then(|s| s.run((n as f64 - 0.5) * rec.dt, 1.0 / rec.dt))
            .ok()?;
        if trace.t.len() != n {
            return None;
        }
        layouts.push((rows, trace, rec.dt));
    }
    let total: usize = layouts.iter().map(|(rows, _, _)| rows.len()).sum();
    // The propagator of one sub-step of each record: Φ and the input column Γ, from the
    // exponential of the augmented matrix [[A, B], [0, 0]] h.
    let propagator = |h: f64| -> (Matrix3<f64>, Vector3<f64>) {
        let a = Matrix4::new(
            -r / l,
            -k / l,
            0.0,
            0.0,
            k / j,
            -f / j,
            0.0,
            -1.0 / j,
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ) * h;
        let e = a.exp();
        (
            e.fixed_view::<3, 3>(0, 0).into_owned(),
            e.fixed_view::<3, 1>(0, 3).into_owned(),
        )
    };
    let scored: Vec<(u32, f64)> = (1..=max_harmonic.max(1))
        .into_par_iter()
        .filter_map(|order| {
            let nf = f64::from(order);
            let mut columns = DMatrix::zeros(total, 2);
            let mut at = 0;
            for (rows, trace, dt) in &layouts {
                let n = trace.t.len();
                let turn = trace
                    .position
                    .windows(2)
                    .map(|w| (w[1] - w[0]).abs())
                    .fold(0.0_f64, f64::max);
                let sub = ((nf * turn / 0.5).ceil() as usize).clamp(1, PROBE_SUBSTEPS);
                let h = dt / sub as f64;
                let (phi, gamma) = propagator(h);
                for (c, shift) in [(0usize, 0.0), (1, std::f64::consts::FRAC_PI_2)] {
                    let mut x = Vector3::zeros();
                    let mut states = Vec::with_capacity(n);
                    states.push(x);
                    for i in 1..n {
                        if trace.stuck[i] && trace.stuck[i - 1] {
                            x = Vector3::new(x[0], 0.0, 0.0);
                        } else {
                            for q in 0..sub {
                                let w = (q as f64 + 0.5) / sub as f64;
                                let th = trace.position[i - 1]
                                    + w * (trace.position[i] - trace.position[i - 1]);
                                x = phi * x + gamma * (nf * th + shift).sin();
                            }
                        }
                        if !x.iter().all(|v| v.is_finite()) {
                            return None;
                        }
                        states.push(x);
                    }
                    let angle: Vec<f64> = states.iter().map(|x| x[2]).collect();
                    let encoder = motor_model::central_difference(&trace.t, &angle);
                    for (row, (channel, i, sigma, _)) in rows.iter().enumerate() {
                        let value = match channel {
                            Channel::Current => states[*i][0],
                            Channel::Speed => states[*i][1],
                            Channel::EncoderSpeed => encoder[*i],
                        };
                        columns[(at + row, c)] = value / sigma;
                    }
                }
                at += rows.len();
            }
            let score = projection.score(&columns);
            (score.testable && score.statistic.is_finite()).then_some((order, score.statistic))
        })
        .collect();
    let mut scored = scored;
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    Some(scored.into_iter().map(|(order, _)| order).collect())
}

/// The scale each channel's residual is measured in: for a training record's channel the
/// level the nominal fit weighted it by (its residual RMS there); for a validation record's
/// channel, which no fit weighted, the nominal model's residual RMS on it. Without the second,
/// a validation channel would count in its own unit (A², (rad/s)²), its held-out errors would
/// not compare with the training ones nor with the parameter penalty, and a speed channel
/// would outweigh every current channel.
pub(crate) fn channel_scales(
    nominal: &FullFit,
    fitted: &[FittedChannel],
) -> Vec<(usize, Channel, f64)> {
    let mut sigmas: Vec<(usize, Channel, f64)> = nominal
        .quality
        .iter()
        .map(|q| (q.test, q.channel, q.noise_std))
        .collect();
    for ch in fitted {
        if sigmas
            .iter()
            .any(|(r, c, _)| *r == ch.record && *c == ch.channel)
        {
            continue;
        }
        let rms = ch.residual_rms();
        if rms.is_finite() && rms > 0.0 {
            sigmas.push((ch.record, ch.channel, rms));
        }
    }
    sigmas
}

/// How many alternatives the screening picked `kind`'s fixed shape from by looking at the
/// residual: for a cogging torque, the period counts it screened ([`cogging_counts`]); for a
/// brush drop, whose knee current is not fitted, the knees of [`candidate_starts`] the
/// screening chose among; otherwise 1. Without the factor the shape that best matches the
/// noise of an effect-free record would be named an effect more often than α allows.
pub(crate) fn shapes_searched(
    kind: EffectKind,
    localisation: &Localisation,
    settings: &LocaliseSettings,
    records: &[ExcitedRecord<'_>],
) -> usize {
    match kind {
        EffectKind::CoggingTorque => {
            cogging_counts(ripple_periods(localisation), settings.max_harmonic).len()
        }
        EffectKind::BrushDrop => brush_knee_scales(records).len().max(1),
        _ => 1,
    }
}

/// The cogging period count the localisation's angle search points to: that of the channel
/// whose angle ripple is most significant, 6 when no channel was searched.
pub(crate) fn ripple_periods(localisation: &Localisation) -> u32 {
    localisation
        .records
        .iter()
        .flat_map(|r| &r.channels)
        .filter_map(|c| c.angle_ripple.as_ref())
        .min_by(|a, b| a.p_value.total_cmp(&b.p_value))
        .map_or(6, |a| a.periods_per_rev.max(1))
}

/// The cogging period counts N \[periods per revolution\] the screening looks at: `first` (the
/// angle search's, [`ripple_periods`]), then every other N from 1 to `max_harmonic`. The
/// angle search alone picks N from the residual against the angle on every record, the
/// validation records that do not excite the cogging among them, with a regression of
/// constant amplitude, while the ripple a cogging torque leaves falls as `1/(J N Ω)` with
/// speed and shows mostly where the motor turns slowly: a start at its N is refitted at the
/// wrong period count and falls to zero, and another effect acting at low speed (a Stribeck
/// friction) takes the gap. The screening ranks every N by the cogging's signature on the
/// training records ([`cogging_prefilter`]) and screens the best in full
/// ([`cogging_screened`]).
pub(crate) fn cogging_counts(first: u32, max_harmonic: u32) -> Vec<u32> {
    let mut counts = vec![first.max(1)];
    counts.extend((1..=max_harmonic.max(1)).filter(|&n| n != first.max(1)));
    counts
}

/// The current scales \[A\] a brush drop's knee is started from: each record's peak |I|,
/// largest first, those within a factor [`BRUSH_SCALE_RATIO`] of a larger one left out. The
/// knee is not fitted, and a knee far above the currents a record runs at makes the drop a
/// resistance there (`Vb/I_knee`, which R already spans): a step at a few times the breakaway
/// voltage runs hundreds of times below the high step's peak current.
pub(crate) fn brush_knee_scales(records: &[ExcitedRecord<'_>]) -> Vec<f64> {
    let mut peaks: Vec<f64> = records
        .iter()
        .map(peak_current)
        .filter(|p| p.is_finite() && *p > 0.0)
        .collect();
    peaks.sort_by(|a, b| b.total_cmp(a));
    let mut scales: Vec<f64> = Vec::new();
    for p in peaks {
        if scales
            .last()
            .is_none_or(|&last| last > BRUSH_SCALE_RATIO * p)
        {
            scales.push(p);
        }
    }
    scales
}

/// Peak currents within this factor of each other give one brush-knee start.
pub(crate) const BRUSH_SCALE_RATIO: f64 = 3.0;

/// Stribeck speeds the screening starts from, as fractions of the slowest record's peak speed
/// (the fit moves Ωs; the screening keeps the start whose signature explains most of the
/// residual, so that a refit does not start a decade away from a dip near Ω = 0).
pub(crate) const STRIBECK_START_FRACTIONS: [f64; 3] = [0.03, 0.1, 0.3];

/// Saturation currents the screening also starts from, as fractions of the records' peak
/// current (beside [`candidate_start`]'s twice that peak): far above the currents a record
/// runs at, the fall of L is `∝ I²` whatever its size, while a saturation current within them
/// gives an inductance that falls near `I = 0` and then holds — a shape the `I²` signature
/// does not span, so that the screening would miss it and a refit start a decade away.
pub(crate) const SATURATION_START_FRACTIONS: [f64; 3] = [0.1, 0.3, 1.0];

/// The starts of `kind` on `motor` the screening chooses among: [`candidate_start`]; for a
/// Stribeck friction also Stribeck speeds at [`STRIBECK_START_FRACTIONS`] of the slowest
/// record's peak speed; for a brush drop also the drop and knee of [`candidate_start`] scaled
/// to each smaller current scale of [`brush_knee_scales`]; for an inductance saturation also
/// saturation currents at [`SATURATION_START_FRACTIONS`] of the peak; for a cogging torque the period
/// counts `cogging` (the angle search's first; none given: that one alone).
pub(crate) fn candidate_starts(
    kind: EffectKind,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
    localisation: &Localisation,
    cogging: &[u32],
) -> Vec<Effect> {
    let first = candidate_start(kind, motor, records, localisation);
    if let (Effect::CoggingTorque(c), false) = (first, cogging.is_empty()) {
        return cogging
            .iter()
            .map(|&n| {
                Effect::CoggingTorque(CoggingTorque {
                    periods_per_rev: n,
                    ..c
                })
            })
            .collect();
    }
    let mut starts = vec![first];
    if let Effect::BrushDrop(b) = first {
        let scales = brush_knee_scales(records);
        if let Some(&top) = scales.first() {
            starts.extend(scales[1..].iter().map(|&i| {
                Effect::BrushDrop(BrushDrop {
                    drop_v: b.drop_v * i / top,
                    knee_current_a: b.knee_current_a * i / top,
                })
            }));
        }
    }
    if let Effect::StribeckFriction(s) = first {
        let (w_slowest, _) = records_peak_speeds(records);
        if w_slowest.is_finite() && w_slowest > 0.0 {
            starts.extend(STRIBECK_START_FRACTIONS.iter().map(|&x| {
                Effect::StribeckFriction(StribeckFriction {
                    stribeck_speed_rad_s: x * w_slowest,
                    ..s
                })
            }));
        }
    }
    if let Effect::InductanceSaturation(sat) = first {
        let i_max = records_peak_current(records);
        starts.extend(SATURATION_START_FRACTIONS.iter().map(|&x| {
            Effect::InductanceSaturation(InductanceSaturation {
                saturation_current_a: x * i_max,
                ..sat
            })
        }));
    }
    starts
}

/// The running trapezoidal integral of `speed` \[rad/s\] sampled every `dt` \[s\]: the angle
/// \[rad\] turned since the first sample.
pub(crate) fn integrated_angle(speed: &[f64], dt: f64) -> Vec<f64> {
    let mut theta = 0.0;
    let mut out = Vec::with_capacity(speed.len());
    for (i, w) in speed.iter().enumerate() {
        if i > 0 {
            theta += 0.5 * (speed[i - 1] + w) * dt;
        }
        out.push(theta);
    }
    out
}

/// A record's peak |I| \[A\].
pub(crate) fn peak_current(r: &ExcitedRecord<'_>) -> f64 {
    r.current.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The records' peak |I| \[A\], at least 1 µA: the current scale the starts of
/// [`candidate_start`] and [`candidate_starts`] are taken from.
pub(crate) fn records_peak_current(records: &[ExcitedRecord<'_>]) -> f64 {
    records
        .iter()
        .map(peak_current)
        .fold(0.0_f64, f64::max)
        .max(1e-6)
}

/// A record's peak |Ω| \[rad/s\] (from its speed, else its angle's differences).
pub(crate) fn peak_speed(r: &ExcitedRecord<'_>) -> Option<f64> {
    r.speed
        .map(|s| s.iter().fold(0.0_f64, |m, v| m.max(v.abs())))
        .or_else(|| {
            r.position.map(|p| {
                p.windows(2)
                    .map(|w| ((w[1] - w[0]) / r.dt).abs())
                    .fold(0.0_f64, f64::max)
            })
        })
}

/// The slowest and the fastest of the records' peak |Ω| \[rad/s\] ([`peak_speed`]); `(∞, 0)`
/// when no record has a speed or an angle.
pub(crate) fn records_peak_speeds(records: &[ExcitedRecord<'_>]) -> (f64, f64) {
    records
        .iter()
        .filter_map(peak_speed)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), w| {
            (lo.min(w), hi.max(w))
        })
}

/// A small starting size of `kind` on `motor`, its shape from the records.
pub(crate) fn candidate_start(
    kind: EffectKind,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
    localisation: &Localisation,
) -> Effect {
    let peak = |f: &dyn Fn(&ExcitedRecord<'_>) -> Option<f64>| {
        records.iter().filter_map(f).fold(0.0_f64, f64::max)
    };
    let w_max = peak(&peak_speed).max(1e-3);
    let i_max = records_peak_current(records);
    let dt = records.iter().map(|r| r.dt).fold(f64::INFINITY, f64::min);
    let span = peak(&|r| Some(r.current.len() as f64 * r.dt));
    match kind {
        EffectKind::StribeckFriction => Effect::StribeckFriction(StribeckFriction {
            static_torque_nm: 1.5 * motor.ts_nm,
            stribeck_speed_rad_s: 0.05 * w_max,
        }),
        EffectKind::CoggingTorque => Effect::CoggingTorque(CoggingTorque {
            amplitude_nm: 0.1 * motor.ts_nm.max(1e-3 * motor.k_nm_per_a * i_max),
            periods_per_rev: ripple_periods(localisation),
            phase_rad: 0.3,
        }),
        // A tenth of the sample period or of L/R, whichever is shorter: small beside anything
        // a record resolves, and beside the rise of a current whose L/R is below the sample
        // period, so that the screening's signature is the lag's at zero size (the simulator
        // advances the filter exactly, so no time constant of it bounds the step).
        EffectKind::CurrentSensorLag => Effect::CurrentSensorLag(CurrentSensorLag {
            tau_f_s: 0.1 * dt.min(motor.l_henry / motor.r_ohm),
        }),
        EffectKind::ThermalDrift => {
            // A rise of a few kelvin over the records' span at their mean copper loss.
            let loss = records
                .iter()
                .map(|r| {
                    r.current.iter().map(|i| i * i).sum::<f64>() / r.current.len().max(1) as f64
                })
                .fold(0.0_f64, f64::max)
                * motor.r_ohm;
            let rth = 5.0 / loss.max(1e-9);
            Effect::ThermalDrift(ThermalDrift {
                thermal_resistance_k_per_w: rth,
                thermal_capacity_j_per_k: span.max(dt) / rth,
                alpha_per_k: COPPER_ALPHA_PER_K,
            })
        }
        EffectKind::QuadraticDrag => Effect::QuadraticDrag(QuadraticDrag {
            c_nms2_per_rad2: 0.1 * motor.f_nms_per_rad / w_max,
        }),
        EffectKind::BrushDrop => Effect::BrushDrop(BrushDrop {
            drop_v: 0.02 * motor.r_ohm * i_max,
            knee_current_a: 0.05 * i_max,
        }),
        EffectKind::InductanceSaturation => Effect::InductanceSaturation(InductanceSaturation {
            saturation_current_a: 2.0 * i_max,
            min_ratio: 0.9,
        }),
    }
}

/// Least sum of squares \[noise variances\] that a refitted effect's own part of the prediction
/// (the refit with and without the effect) must reach for its fall to be credited to it.
pub(crate) const EFFECT_PART_MIN: f64 = 1.0;

/// Sum over every sample of `a`'s channels of the squared difference from `b`'s, each over its
/// channel's noise level in `sigmas` \[noise variances\].
pub(crate) fn weighted_difference(
    a: &[FittedChannel],
    b: &[FittedChannel],
    sigmas: &[(usize, Channel, f64)],
) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let sigma = channel_sigma(sigmas, x.record, x.channel).unwrap_or(1.0);
            x.model
                .iter()
                .zip(&y.model)
                .map(|(p, q)| ((p - q) / sigma).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Share of the base model's L/R a sensor lag's absorbed start gives the lag
/// ([`absorbed_start`]).
pub(crate) const LAG_SPLIT: f64 = 0.5;

/// How many times the rise of [`candidate_start`]'s thermal drift a thermal drift's absorbed
/// start ([`absorbed_start`]) heats by (the same time constant).
pub(crate) const THERMAL_ABSORBED_RISE: f64 = 10.0;

/// An inductance saturation's absorbed start ([`absorbed_start`]): its saturation current
/// \[share of the training records' peak current\] and its ratio `r`.
pub(crate) const SATURATION_ABSORBED: (f64, f64) = (0.3, 0.5);

/// Share of the base model's Ts a Stribeck friction's absorbed start keeps as the sliding
/// friction Ts ([`absorbed_start`]).
pub(crate) const STRIBECK_SPLIT: f64 = 0.5;

/// A refitted Stribeck speed is taken as one the records visit between these multiples of the
/// slowest and the fastest record's peak speed ([`stribeck_within_records`]).
pub(crate) const STRIBECK_VISITED: (f64, f64) = (1e-3, 1e3);

/// Whether `fit`'s Stribeck friction falls at a speed `records` visit
/// ([`STRIBECK_VISITED`]): not a step of friction at rest (Ωs → 0) nor a constant level
/// (Ωs → ∞), the two ends a refit from the base model's single level runs to.
pub(crate) fn stribeck_within_records(fit: &FullFit, records: &[ExcitedRecord<'_>]) -> bool {
    let Some(Effect::StribeckFriction(s)) = fit.effects.get(EffectKind::StribeckFriction) else {
        return false;
    };
    let (slowest, fastest) = records_peak_speeds(records);
    s.stribeck_speed_rad_s >= STRIBECK_VISITED.0 * slowest
        && s.stribeck_speed_rad_s <= STRIBECK_VISITED.1 * fastest
}

/// A start for `kind` beside the model that absorbed it, where the effect trades against a
/// motor parameter the base fit has already moved to mimic it (from the base model, growing
/// the effect alone only adds to what that parameter does):
/// - a sensor lag: L cut by [`LAG_SPLIT`] and the lag given that share of L/R (a first-order
///   sensor after a first-order electrical response delays the current by about the sum of
///   their time constants, which a model without the sensor gives its L/R alone);
/// - an inductance saturation ([`SATURATION_ABSORBED`]): L0 raised so that the saturating
///   inductance, averaged over the training records' current weighted by how fast it moves
///   (where L acts), is the base model's L;
/// - a thermal drift (`start`'s heating, [`THERMAL_ABSORBED_RISE`] times its rise): R0 lowered
///   so that the heated resistance, averaged over the training records weighted by I² (the
///   drop R·I squared, as the fit weighs it), is the base model's R — the base fit took a
///   winding that heats for one at its mean temperature;
/// - a Stribeck friction (`start`'s Stribeck speed): the base model's Ts kept as the static
///   level Tst and Ts cut to [`STRIBECK_SPLIT`] of it — a fit without the fall of friction
///   with speed sets its one level where the records break away and crawl, which is Tst.
///
/// `None` for the other effects, or when the motor would not be one.
pub(crate) fn absorbed_start(
    kind: EffectKind,
    start: Effect,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
) -> Option<(MotorParams, Effect)> {
    let with = |r_ohm: f64, l_henry: f64| with_electrical(motor, r_ohm, l_henry);
    let with_l = |l_henry: f64| with(motor.r_ohm, l_henry);
    match kind {
        EffectKind::ThermalDrift => {
            let Effect::ThermalDrift(heat) = start else {
                return None;
            };
            let heat = ThermalDrift {
                thermal_resistance_k_per_w: THERMAL_ABSORBED_RISE * heat.thermal_resistance_k_per_w,
                thermal_capacity_j_per_k: heat.thermal_capacity_j_per_k / THERMAL_ABSORBED_RISE,
                ..heat
            };
            let tau = heat.thermal_resistance_k_per_w * heat.thermal_capacity_j_per_k;
            let (mut weighted, mut weight) = (0.0, 0.0);
            for r in records {
                // Each record starts at the ambient temperature; ΔT advanced over each sample
                // period as the exact solution for that period's copper loss, taken in the
                // base model's R (without the heating's own rise of R: second order here).
                let decay = (-r.dt / tau).exp();
                let mut rise = 0.0;
                for &i in r.current {
                    let factor = 1.0 + heat.alpha_per_k * rise;
                    weighted += i * i * factor;
                    weight += i * i;
                    let steady = i * i * motor.r_ohm * heat.thermal_resistance_k_per_w;
                    rise = steady + (rise - steady) * decay;
                }
            }
            let mean = weighted / weight;
            (mean.is_finite() && mean > 0.0).then_some(())?;
            Some((
                with(motor.r_ohm / mean, motor.l_henry)?,
                Effect::ThermalDrift(heat),
            ))
        }
        EffectKind::CurrentSensorLag => Some((
            with_l(motor.l_henry * (1.0 - LAG_SPLIT))?,
            Effect::CurrentSensorLag(CurrentSensorLag {
                tau_f_s: LAG_SPLIT * motor.l_henry / motor.r_ohm,
            }),
        )),
        EffectKind::InductanceSaturation => {
            let (share, ratio) = SATURATION_ABSORBED;
            let sat = InductanceSaturation {
                saturation_current_a: share * records_peak_current(records),
                min_ratio: ratio,
            };
            let (mut weighted, mut weight) = (0.0, 0.0);
            for r in records {
                for w in r.current.windows(2) {
                    let moved = (w[1] - w[0]).abs();
                    weighted += moved * sat.factor(0.5 * (w[0] + w[1]));
                    weight += moved;
                }
            }
            let mean = weighted / weight;
            (mean.is_finite() && mean > 0.0).then_some(())?;
            Some((
                with_l(motor.l_henry / mean)?,
                Effect::InductanceSaturation(sat),
            ))
        }
        EffectKind::StribeckFriction => {
            let Effect::StribeckFriction(stribeck) = start else {
                return None;
            };
            let sliding = MotorParams::new(
                motor.r_ohm,
                motor.l_henry,
                motor.k_nm_per_a,
                motor.f_nms_per_rad,
                motor.j_kgm2,
                STRIBECK_SPLIT * motor.ts_nm,
            )
            .ok()?;
            Some((
                sliding,
                Effect::StribeckFriction(StribeckFriction {
                    static_torque_nm: motor.ts_nm,
                    ..stribeck
                }),
            ))
        }
        _ => None,
    }
}

/// L/R \[sample periods\] the nominal fit of [`diagnose`] starts again from when it ran L/R
/// below it.
pub(crate) const SLOWEST_START_L_OVER_R: f64 = 0.5;

/// `motor` with its L raised so that L/R is [`SLOWEST_START_L_OVER_R`] of the longest sample
/// period of `records`; `None` when it is that long already (or would not be a motor).
pub(crate) fn slower_electrical(
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
) -> Option<MotorParams> {
    let dt = records.iter().map(|r| r.dt).fold(0.0, f64::max);
    let l_henry = SLOWEST_START_L_OVER_R * dt * motor.r_ohm;
    (l_henry > motor.l_henry).then_some(())?;
    with_electrical(motor, motor.r_ohm, l_henry)
}

/// `motor` with R \[Ω\] and L \[H\] replaced (`None` if that is no motor).
pub(crate) fn with_electrical(
    motor: &MotorParams,
    r_ohm: f64,
    l_henry: f64,
) -> Option<MotorParams> {
    MotorParams::new(
        r_ohm,
        l_henry,
        motor.k_nm_per_a,
        motor.f_nms_per_rad,
        motor.j_kgm2,
        motor.ts_nm,
    )
    .ok()
}
