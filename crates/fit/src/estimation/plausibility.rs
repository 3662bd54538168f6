//! Whether a fit that ran to its solver's convergence is a result at all.
//!
//! A least-squares solver converges to a minimum, not necessarily to the motor: a bad start or
//! records in the wrong units can leave it at parameters that explain the records worse than
//! their mean does, or that no motor could have with these records. Such a fit is refused
//! ([`Refusal`]) with the reason, never reported as converged.

use motor_model::{Domain, MotorParams};

use crate::estimation::fitted::FullFit;
use crate::estimation::intervals::MotorIntervals;
use crate::estimation::parameters::EffectEstimate;
use crate::estimation::records::{Channel, ChannelQuality};
use crate::estimation::refusal::Refusal;

/// A time constant below this fraction of the sample period is not seen by the records: the
/// transient is over a thousand times faster than one sample.
const FASTEST_VISIBLE: f64 = 1e-3;
/// A time constant above this multiple of the record's span is not seen either: the record
/// shows a thousandth of the transient.
const SLOWEST_VISIBLE: f64 = 1e3;

/// What a fit's records show, for [`assess`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RecordFacts {
    /// Shortest sample period of the records \[s\].
    pub dt_min_s: f64,
    /// Longest record \[s\].
    pub span_max_s: f64,
    /// Largest |current| measured \[A\].
    pub peak_current_a: f64,
    /// Whether some record shows the motor turning.
    pub moved: bool,
}

/// The reason to refuse a converged fit, if any: [`assess_parts`] on its motor, intervals,
/// effect estimates and quality.
pub(crate) fn assess(fit: &FullFit, facts: &RecordFacts) -> Option<Refusal> {
    assess_parts(
        &fit.params,
        fit.ci95.as_ref(),
        &fit.effect_estimates,
        &fit.quality,
        facts,
    )
}

/// Judges a converged fit: sets `fit.refusal` ([`assess`]) and `fit.refusal_beside_channels`,
/// the refusal its motor, intervals and effect estimates alone give ([`assess_parts`] with no
/// channel quality).
pub(crate) fn judge(fit: &mut FullFit, facts: &RecordFacts) {
    fit.refusal = assess(fit, facts);
    fit.refusal_beside_channels = assess_parts(
        &fit.params,
        fit.ci95.as_ref(),
        &fit.effect_estimates,
        &[],
        facts,
    );
}

/// The reason to refuse a converged fit of `params`, if any. An effect parameter that must be
/// positive (a time constant, a speed or current scale: [`Domain::Positive`]) is judged as a
/// motor parameter is; an effect's size (which may be 0) or phase is reported with its
/// interval and left to the caller's significance test.
pub(crate) fn assess_parts(
    params: &MotorParams,
    ci95: Option<&MotorIntervals>,
    effects: &[EffectEstimate],
    quality: &[ChannelQuality],
    facts: &RecordFacts,
) -> Option<Refusal> {
    if let Some(q) = quality
        .iter()
        .find(|q| q.nrmse_fit_percent.is_finite() && q.nrmse_fit_percent < 0.0)
    {
        return Some(Refusal::WorseThanConstant {
            test: q.test,
            channel: q.channel,
            nrmse: 1.0 - q.nrmse_fit_percent / 100.0,
        });
    }
    if let Some(refusal) = implausible_motor(params, facts) {
        return Some(refusal);
    }
    let p = params;
    let Some(ci) = ci95 else {
        return Some(vanished(p, facts).unwrap_or(Refusal::NoIntervals));
    };
    intervals_refusal(p, ci, effects)
}

/// A share of its scale below which a friction parameter has vanished ([`Refusal::Vanished`]).
const VANISHED_SHARE: f64 = 1e-12;

/// The friction parameter of `p` that has vanished, if one has: Ts below [`VANISHED_SHARE`] of
/// the largest motor torque `k·|I|` of records with `facts`, or f below that share of the
/// electrical damping `k²/R`. In the fit's coordinate `ln p` such a parameter's column of the
/// Jacobian is `p ∂r/∂p`, zero to rounding: the cause of a singular Jacobian, to be named.
fn vanished(p: &MotorParams, facts: &RecordFacts) -> Option<Refusal> {
    let torque = p.k_nm_per_a * facts.peak_current_a;
    let damping = p.k_nm_per_a.powi(2) / p.r_ohm;
    [
        ("Ts", p.ts_nm, "N·m", torque),
        ("f", p.f_nms_per_rad, "N·m·s/rad", damping),
    ]
    .into_iter()
    .find_map(|(parameter, value, unit, scale)| {
        let share = value / scale;
        (scale > 0.0 && share < VANISHED_SHARE).then_some(Refusal::Vanished {
            parameter,
            value,
            unit,
            share,
        })
    })
}

/// Why `params` cannot be the motor of records with `facts`, if they cannot: a Coulomb torque
/// at least the largest motor torque of records in which the motor turns, or a time constant
/// outside what the records' sample period and span can show.
pub(crate) fn implausible_motor(params: &MotorParams, facts: &RecordFacts) -> Option<Refusal> {
    let p = params;
    let stall_torque = p.k_nm_per_a * facts.peak_current_a;
    if facts.moved && p.ts_nm >= stall_torque {
        return Some(Refusal::Implausible {
            reason: format!(
                "Ts = {:.4e} N·m is at least the largest motor torque k·|I| = {stall_torque:.4e} N·m of the records, \
                 yet the motor turns",
                p.ts_nm
            ),
        });
    }
    // Eq. (18) τe = L/R, and the mechanical time constant of the motor with its electrical
    // damping, J R/(R f + k²) (the speed's time constant when τe ≪ τm; Eq. (19)'s J/f grows
    // without bound as f → 0 and is no test).
    let tau_e = p.l_henry / p.r_ohm;
    let tau_mech = p.j_kgm2 * p.r_ohm / (p.r_ohm * p.f_nms_per_rad + p.k_nm_per_a.powi(2));
    for (name, tau, what) in [
        ("tau_e = L/R", tau_e, "L"),
        ("J R/(R f + k²)", tau_mech, "J"),
    ] {
        let fast = FASTEST_VISIBLE * facts.dt_min_s;
        let slow = SLOWEST_VISIBLE * facts.span_max_s;
        if !(tau.is_finite() && tau >= fast && tau <= slow) {
            return Some(Refusal::Implausible {
                reason: format!(
                    "{name} = {tau:.4e} s is outside what records sampled every {:.4e} s for {:.4e} s can show \
                     ({fast:.1e} to {slow:.1e} s): {what} is not determined by them (are the time and current \
                     columns in the units their headers say?)",
                    facts.dt_min_s, facts.span_max_s
                ),
            });
        }
    }
    None
}

/// Why the intervals `ci` of `p` and of the effects' parameters do not make a result: none of
/// zero width, none wider than the value.
fn intervals_refusal(
    p: &MotorParams,
    ci: &MotorIntervals,
    effects: &[EffectEstimate],
) -> Option<Refusal> {
    let motor = ci
        .named()
        .into_iter()
        .zip(p.values())
        .map(|((name, [lo, hi]), value)| (name, 0.5 * (hi - lo) / value));
    let positive_effects = effects
        .iter()
        .filter(|e| {
            e.effect
                .param(e.key)
                .is_some_and(|s| s.domain == Domain::Positive)
        })
        .map(|e| {
            let rel = e.ci95.map_or(f64::NAN, |c| 0.5 * (c[1] - c[0]) / e.value);
            (e.symbol, rel)
        });
    // An interval of no width is not an interval: a degenerate covariance (every parameter
    // at a point no residual moves from), not a measurement without error.
    let widths: Vec<(&'static str, f64)> = motor.chain(positive_effects).collect();
    if widths.iter().any(|&(_, rel)| rel == 0.0) {
        return Some(Refusal::NoIntervals);
    }
    widths
        .into_iter()
        .find(|&(_, rel)| rel.is_nan() || rel > 1.0)
        .map(|(parameter, rel)| Refusal::Undetermined {
            parameter,
            relative_half_width: rel,
        })
}

impl Default for RecordFacts {
    /// No record yet.
    fn default() -> Self {
        RecordFacts {
            dt_min_s: f64::INFINITY,
            span_max_s: 0.0,
            peak_current_a: 0.0,
            moved: false,
        }
    }
}

impl RecordFacts {
    /// Adds a record of `n` samples every `dt` \[s\] with its fitted channels.
    pub fn add<'a>(
        &mut self,
        dt: f64,
        n: usize,
        channels: impl Iterator<Item = (Channel, &'a [f64])>,
    ) {
        self.dt_min_s = self.dt_min_s.min(dt);
        self.span_max_s = self.span_max_s.max(dt * n as f64);
        for (kind, data) in channels {
            match kind {
                Channel::Current => {
                    let peak = data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    self.peak_current_a = self.peak_current_a.max(peak);
                }
                Channel::Speed | Channel::EncoderSpeed => self.moved |= shows_motion(data),
            }
        }
    }
}

/// Whether a measured speed shows the motor turning: its largest |value| stands above ten
/// times its own noise level (an encoder at rest reads 0 exactly).
pub(crate) fn shows_motion(speed: &[f64]) -> bool {
    let peak = speed.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    peak > 0.0 && peak > 10.0 * crate::estimation::records::noise_std(speed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> MotorParams {
        MotorParams::new(0.3, 0.3, 0.15, 0.05, 1.0, 0.03).unwrap()
    }

    fn facts() -> RecordFacts {
        RecordFacts {
            dt_min_s: 1e-3,
            span_max_s: 50.0,
            peak_current_a: 53.6,
            moved: true,
        }
    }

    /// Intervals of ± `rel` of each value.
    fn ci(p: &MotorParams, rel: f64) -> MotorIntervals {
        MotorIntervals::relative(p, rel)
    }

    fn quality(fit_percent: f64) -> ChannelQuality {
        ChannelQuality {
            test: 0,
            channel: Channel::EncoderSpeed,
            noise_std: 1.0,
            rms_residual: 1.0,
            nrmse_fit_percent: fit_percent,
        }
    }

    #[test]
    fn the_paper_motor_on_its_records_is_accepted() {
        assert_eq!(
            assess_parts(
                &paper(),
                Some(&ci(&paper(), 0.01)),
                &[],
                &[quality(98.4)],
                &facts()
            ),
            None
        );
    }

    /// Intervals of no width (a 21-sample step pair whose full fit ended with a degenerate
    /// covariance, f = 7.7e-169) are no intervals; narrow ones are.
    #[test]
    fn intervals_of_no_width_are_refused() {
        let q = [quality(98.4)];
        assert_eq!(
            assess_parts(&paper(), Some(&ci(&paper(), 0.0)), &[], &q, &facts()),
            Some(Refusal::NoIntervals)
        );
        assert_eq!(
            assess_parts(&paper(), Some(&ci(&paper(), 1e-9)), &[], &q, &facts()),
            None
        );
    }

    #[test]
    fn a_vanished_friction_is_named_as_the_cause_of_missing_intervals() {
        let q = [quality(98.4)];
        assert_eq!(
            assess_parts(&paper(), None, &[], &q, &facts()),
            Some(Refusal::NoIntervals)
        );
        let gone = MotorParams::new(0.3, 0.3, 0.15, 0.05, 1.0, 8e-34).unwrap();
        let refusal = assess_parts(&gone, None, &[], &q, &facts()).expect("refused");
        assert!(
            matches!(
                refusal,
                Refusal::Vanished {
                    parameter: "Ts",
                    ..
                }
            ),
            "{refusal:?}"
        );
        assert!(refusal.to_string().starts_with("Ts went to 8.000e-34 N·m"));
    }

    #[test]
    fn each_impossibility_is_named() {
        // A model worse than the channel's mean (the 40 V step fitted to Ts = 2443 N·m).
        assert!(matches!(
            assess_parts(&paper(), Some(&ci(&paper(), 0.01)), &[], &[quality(-208.9)], &facts()),
            Some(Refusal::WorseThanConstant { nrmse, .. }) if (nrmse - 3.089).abs() < 1e-9
        ));
        // A Coulomb torque the motor's largest torque never overcomes, though it turned.
        let stuck = MotorParams {
            ts_nm: 8.1,
            ..paper()
        };
        assert!(matches!(
            assess_parts(&stuck, Some(&ci(&stuck, 0.01)), &[], &[], &facts()),
            Some(Refusal::Implausible { reason }) if reason.contains("Ts")
        ));
        // The same torque is possible when nothing shows the motor turning.
        let still = RecordFacts {
            moved: false,
            ..facts()
        };
        assert_eq!(
            assess_parts(&stuck, Some(&ci(&stuck, 0.01)), &[], &[], &still),
            None
        );
        // L = 7e-91 H (100 kHz records fitted from a wrong start): τe far below a sample.
        let no_l = MotorParams {
            l_henry: 7e-91,
            ..paper()
        };
        assert!(matches!(
            assess_parts(&no_l, Some(&ci(&no_l, 0.01)), &[], &[], &facts()),
            Some(Refusal::Implausible { reason }) if reason.contains("tau_e")
        ));
        // A mechanical time constant a thousand record spans long.
        let heavy = MotorParams {
            j_kgm2: 1e6,
            ..paper()
        };
        assert!(matches!(
            assess_parts(&heavy, Some(&ci(&heavy, 0.01)), &[], &[], &facts()),
            Some(Refusal::Implausible { reason }) if reason.contains("J is not determined")
        ));
        assert_eq!(
            assess_parts(&paper(), None, &[], &[], &facts()),
            Some(Refusal::NoIntervals)
        );
        // k = 6e-12 N·m/A ± 3.5e7 % (9-sample records at 24 Hz): not determined.
        let mut wide = ci(&paper(), 0.01);
        wide.k_nm_per_a = [-0.5, 0.8];
        assert!(matches!(
            assess_parts(&paper(), Some(&wide), &[], &[], &facts()),
            Some(Refusal::Undetermined { parameter: "k", .. })
        ));
    }

    #[test]
    fn motion_is_told_from_an_encoder_at_rest() {
        let mut f = RecordFacts::default();
        f.add(
            1e-3,
            4,
            [(Channel::EncoderSpeed, &[0.0, 0.0, 0.0, 0.0][..])].into_iter(),
        );
        assert!(!f.moved);
        let ramp: Vec<f64> = (0..100).map(|i| i as f64).collect();
        f.add(1e-3, 100, [(Channel::Speed, &ramp[..])].into_iter());
        assert!(f.moved);
        assert_eq!(f.span_max_s, 0.1);
    }
}
