//! The test that would separate an ambiguous verdict: when two candidate effects explain the
//! records equally well, both fitted alternatives (motor and effects) are simulated over
//! candidate step records — voltages and durations — and the record whose predictions differ
//! most relative to the noise floor is proposed.
//!
//! For each step voltage `E` (fractions of the largest voltage the records applied: the
//! proposal never asks for more than the motor has already seen) both alternatives are
//! simulated from rest for the longest candidate duration; a shorter duration is a prefix of
//! it. On the current and speed channels the difference of the predictions, sample by sample,
//! is divided by that channel's noise floor `σ` (from the localisation: what a perfect model
//! would still leave), giving `d_i`. Two numbers judge a record:
//! - `separation = Σ d_i²`: the expected rise of the weighted cost if the wrong alternative were
//!   fitted to it, in noise variances (a χ² of the likelihood-ratio test between them);
//! - `max |d_i|`: the largest difference in noise deviations.
//!
//! Both only grow with the duration, so at each voltage the duration proposed is the shortest
//! that reaches [`SEPARATION_SHARE`] of that voltage's separation at the longest duration; the
//! voltage proposed is the one of the largest separation at its duration.

use motor_model::{Effects, Input, MotorParams, Simulator};
use serde::Serialize;

use crate::diagnose::localise::Localisation;
use crate::diagnose::report::Diagnosis;
use crate::estimation::records::Channel;

/// Share of the longest duration's separation a shorter proposed record must reach.
pub const SEPARATION_SHARE: f64 = 0.9;

/// One fitted alternative: its effect's name, and the motor and effects it was fitted with.
#[derive(Debug, Clone, Copy)]
pub struct Alternative<'a> {
    /// The effect's name (SPEC section 5).
    pub name: &'a str,
    /// The motor fitted with it.
    pub motor: MotorParams,
    /// The effects fitted with it.
    pub effects: Effects,
}

/// Settings of [`propose_separating_test`].
#[derive(Debug, Clone, PartialEq)]
pub struct ProposeSettings {
    /// Largest step voltage the proposal may ask for \[V\] (> 0): the records' largest.
    pub max_voltage_v: f64,
    /// Candidate step voltages as fractions of `max_voltage_v` (each in (0, 1]).
    pub voltage_fractions: Vec<f64>,
    /// Candidate durations \[s\] (each > 0).
    pub durations_s: Vec<f64>,
    /// Length of the records \[s\] (> 0): the comparison
    /// [`SeparatingTest::separation_at_records`] is a step of `max_voltage_v` this long.
    pub records_length_s: f64,
    /// Sample rate of the proposed record \[Hz\] (> 0): the records'.
    pub rate_hz: f64,
    /// Noise floor of the current \[A\] (> 0).
    pub current_noise_a: f64,
    /// Noise floor of the speed \[rad/s\] (> 0; `None`: the speed is not compared).
    pub speed_noise_rad_s: Option<f64>,
}

/// Default voltage fractions: from 5 % to all of the largest voltage.
pub const VOLTAGE_FRACTIONS: [f64; 8] = [0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.85, 1.0];
/// Default durations as multiples of the records' length.
pub const DURATION_MULTIPLES: [f64; 4] = [0.25, 0.5, 1.0, 2.0];

/// The proposed record and how well it separates the two alternatives.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SeparatingTest {
    /// The two alternatives, the verdict's first.
    pub between: [String; 2],
    /// Step voltage from rest \[V\].
    #[serde(rename = "voltage_V")]
    pub voltage_v: f64,
    /// Record length \[s\].
    pub duration_s: f64,
    /// Sample rate \[Hz\].
    #[serde(rename = "rate_Hz")]
    pub rate_hz: f64,
    /// Largest difference of the two predictions over the noise floor, `max |d_i|`.
    pub max_difference_over_noise: f64,
    /// The channel where it is largest (`current` or `speed`).
    pub channel: &'static str,
    /// Time of that largest difference from the step \[s\].
    pub at_s: f64,
    /// `Σ d_i²` over both channels \[noise variances\] (module docs).
    pub separation: f64,
    /// The same separation on a step of the records' largest voltage, as long as the
    /// records, for comparison \[noise variances\].
    pub separation_at_records: f64,
    /// That step's voltage \[V\].
    #[serde(rename = "records_voltage_V")]
    pub records_voltage_v: f64,
    /// That step's length \[s\].
    pub records_length_s: f64,
}

impl SeparatingTest {
    /// One sentence for the report.
    pub fn text(&self) -> String {
        format!(
            "To separate them, record a {:.3} V step from rest for {:.3} s at {:.0} Hz: the two fitted models differ there by up to {:.1} times the noise floor ({} at {:.3} s; Σ d² = {:.3e} noise variances, against {:.3e} for a {:.3} V step as long as the records).",
            self.voltage_v,
            self.duration_s,
            self.rate_hz,
            self.max_difference_over_noise,
            self.channel,
            self.at_s,
            self.separation,
            self.separation_at_records,
            self.records_voltage_v
        )
    }
}

/// Per sample of a simulated pair: `d²` summed over channels, and the larger |d| with its
/// channel.
struct Differences {
    squared: Vec<f64>,
    largest: Vec<(f64, &'static str)>,
}

fn differences(
    a: &Alternative<'_>,
    b: &Alternative<'_>,
    volts: f64,
    duration_s: f64,
    settings: &ProposeSettings,
) -> Option<Differences> {
    let run = |alt: &Alternative<'_>| {
        Input::step(volts, 0.0)
            .and_then(|input| Simulator::new(alt.motor, alt.effects, input))
            .and_then(|sim| sim.run(duration_s, settings.rate_hz))
            .ok()
    };
    let (ta, tb) = (run(a)?, run(b)?);
    let n = ta.t.len().min(tb.t.len());
    let mut out = Differences {
        squared: Vec::with_capacity(n),
        largest: Vec::with_capacity(n),
    };
    for i in 0..n {
        let di = (ta.current[i] - tb.current[i]) / settings.current_noise_a;
        let dw = settings
            .speed_noise_rad_s
            .map_or(0.0, |s| (ta.speed[i] - tb.speed[i]) / s);
        if !(di.is_finite() && dw.is_finite()) {
            return None;
        }
        out.squared.push(di * di + dw * dw);
        out.largest.push(if di.abs() >= dw.abs() {
            (di.abs(), Channel::Current.name())
        } else {
            (dw.abs(), "speed")
        });
    }
    Some(out)
}

/// The record that separates `a` from `b` best (module docs); `None` when the settings are out
/// of range or no simulation of the grid succeeds.
pub fn propose_separating_test(
    a: &Alternative<'_>,
    b: &Alternative<'_>,
    settings: &ProposeSettings,
) -> Option<SeparatingTest> {
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !(positive(settings.max_voltage_v)
        && positive(settings.records_length_s)
        && positive(settings.rate_hz)
        && positive(settings.current_noise_a)
        && settings.speed_noise_rad_s.is_none_or(positive)
        && settings.durations_s.iter().all(|d| positive(*d))
        && settings
            .voltage_fractions
            .iter()
            .all(|f| positive(*f) && *f <= 1.0))
    {
        return None;
    }
    let longest = settings.durations_s.iter().copied().fold(0.0, f64::max);
    let mut durations = settings.durations_s.clone();
    durations.sort_by(f64::total_cmp);
    let samples = |d: f64| (d * settings.rate_hz).floor() as usize + 1;
    let mut best: Option<SeparatingTest> = None;
    for &fraction in &settings.voltage_fractions {
        let volts = fraction * settings.max_voltage_v;
        let Some(diff) = differences(a, b, volts, longest, settings) else {
            continue;
        };
        let sum_to = |n: usize| diff.squared.iter().take(n).sum::<f64>();
        let full = sum_to(diff.squared.len());
        let Some(&duration) = durations
            .iter()
            .find(|&&d| sum_to(samples(d)) >= SEPARATION_SHARE * full)
        else {
            continue;
        };
        let n = samples(duration).min(diff.squared.len());
        let separation = sum_to(n);
        if best.as_ref().is_some_and(|b| b.separation >= separation) {
            continue;
        }
        let (at, (largest, channel)) = diff.largest.iter().take(n).copied().enumerate().fold(
            (0, (0.0, Channel::Current.name())),
            |m, x| {
                if x.1 .0 > m.1 .0 {
                    x
                } else {
                    m
                }
            },
        );
        best = Some(SeparatingTest {
            between: [a.name.to_string(), b.name.to_string()],
            voltage_v: volts,
            duration_s: duration,
            rate_hz: settings.rate_hz,
            max_difference_over_noise: largest,
            channel,
            at_s: at as f64 / settings.rate_hz,
            separation,
            separation_at_records: f64::NAN,
            records_voltage_v: settings.max_voltage_v,
            records_length_s: settings.records_length_s,
        });
    }
    let mut best = best?;
    best.separation_at_records = differences(
        a,
        b,
        settings.max_voltage_v,
        settings.records_length_s,
        settings,
    )
    .map_or(f64::NAN, |d| d.squared.iter().sum());
    Some(best)
}

/// The mean noise floor of the channels of `kinds` over every record of `localisation`.
fn mean_floor(localisation: &Localisation, kinds: &[Channel]) -> Option<f64> {
    let sigmas: Vec<f64> = localisation
        .records
        .iter()
        .flat_map(|r| &r.channels)
        .filter(|c| kinds.contains(&c.channel))
        .map(|c| c.floor.sigma)
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    (!sigmas.is_empty()).then(|| sigmas.iter().sum::<f64>() / sigmas.len() as f64)
}

/// The separating test of the first ambiguous stage of `d` ([`propose_separating_test`] of
/// its verdict and the first candidate it is ambiguous with), for records whose largest
/// voltage is `max_voltage_v` \[V\], `length_s` \[s\] long, sampled at `rate_hz` \[Hz\];
/// durations [`DURATION_MULTIPLES`] of `length_s`, voltages [`VOLTAGE_FRACTIONS`]; the noise
/// floors from `d`'s localisation. `None` when no stage is ambiguous or the two cannot be
/// simulated.
pub fn separating_test(
    d: &Diagnosis,
    max_voltage_v: f64,
    length_s: f64,
    rate_hz: f64,
) -> Option<SeparatingTest> {
    let stage = d
        .stages
        .iter()
        .find(|s| s.verdict.verdict.is_some() && !s.verdict.ambiguous_with.is_empty())?;
    let alternative = |name: &str| {
        let c = stage.candidates.iter().find(|c| c.name == name)?;
        Some(Alternative {
            name: c.name,
            motor: c.motor?,
            effects: c.effects,
        })
    };
    let a = alternative(stage.verdict.verdict.as_deref()?)?;
    let b = alternative(stage.verdict.ambiguous_with.first()?)?;
    let settings = ProposeSettings {
        max_voltage_v,
        voltage_fractions: VOLTAGE_FRACTIONS.to_vec(),
        durations_s: DURATION_MULTIPLES.iter().map(|m| m * length_s).collect(),
        records_length_s: length_s,
        rate_hz,
        current_noise_a: mean_floor(&d.localisation, &[Channel::Current])?,
        speed_noise_rad_s: mean_floor(&d.localisation, &[Channel::Speed, Channel::EncoderSpeed]),
    };
    propose_separating_test(&a, &b, &settings)
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::{Effect, EffectKind};

    fn servo() -> MotorParams {
        MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3).expect("valid motor")
    }

    fn settings() -> ProposeSettings {
        ProposeSettings {
            max_voltage_v: 12.0,
            voltage_fractions: VOLTAGE_FRACTIONS.to_vec(),
            durations_s: DURATION_MULTIPLES.iter().map(|m| m * 0.6).collect(),
            records_length_s: 0.6,
            rate_hz: 5000.0,
            current_noise_a: 0.01,
            speed_noise_rad_s: Some(0.5),
        }
    }

    /// A quadratic drag and an extra viscous friction matched at 12 V: the drag's torque
    /// `c Ω²` equals `Δf Ω` at the 12 V steady speed, so the two agree there and differ most
    /// at a low voltage, where the drag has all but vanished.
    #[test]
    fn the_proposal_is_where_two_alternatives_differ_most() {
        let motor = servo();
        let drag = Effects::none()
            .with(Effect::from_values(EffectKind::QuadraticDrag, &[2e-7]).expect("valid drag"));
        let speed_12v = {
            let sim = Simulator::new(motor, drag, Input::step(12.0, 0.0).unwrap()).unwrap();
            *sim.run(0.6, 5000.0).unwrap().speed.last().unwrap()
        };
        let viscous = MotorParams {
            f_nms_per_rad: motor.f_nms_per_rad + 2e-7 * speed_12v,
            ..motor
        };
        let a = Alternative {
            name: "quadratic_drag",
            motor,
            effects: drag,
        };
        let b = Alternative {
            name: "viscous",
            motor: viscous,
            effects: Effects::none(),
        };
        let t = propose_separating_test(&a, &b, &settings()).expect("a proposal");
        assert!(t.voltage_v < 12.0, "{t:?}");
        // Matched at 12 V, the two are far apart below it.
        assert!(t.separation > 10.0 * t.separation_at_records, "{t:?}");
        // Every other voltage of the grid separates them less at the proposed duration.
        for f in VOLTAGE_FRACTIONS {
            let d = differences(&a, &b, 12.0 * f, t.duration_s, &settings()).unwrap();
            assert!(d.squared.iter().sum::<f64>() <= t.separation * (1.0 + 1e-9));
        }
        // The same model twice separates nothing.
        let same = propose_separating_test(&a, &a, &settings()).expect("a proposal");
        assert_eq!(same.separation, 0.0);
    }

    #[test]
    fn settings_out_of_range_propose_nothing() {
        let motor = servo();
        let a = Alternative {
            name: "none",
            motor,
            effects: Effects::none(),
        };
        for bad in [
            ProposeSettings {
                max_voltage_v: 0.0,
                ..settings()
            },
            ProposeSettings {
                voltage_fractions: vec![1.5],
                ..settings()
            },
            ProposeSettings {
                current_noise_a: f64::NAN,
                ..settings()
            },
        ] {
            assert!(propose_separating_test(&a, &a, &bad).is_none());
        }
    }
}
