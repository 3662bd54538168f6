//! Record kinds: from the channels a set of records measured, what drives the motor and which
//! constants are known, which identification applies and which parameters it can determine.
//!
//! | measured | drive | identifiable |
//! |---|---|---|
//! | voltage, current, speed | voltage | R, L, k, f, J, Ts |
//! | voltage, current (step pair) | voltage | R, L, k, f, J, Ts (the paper's method) |
//! | voltage, speed | voltage | kS, kV, kA; J, f, Ts when R and k are known |
//! | current, position | current | J, f, Ts and a constant offset |
//!
//! A current column that spans fewer than [`MIN_CURRENT_ADC_STEPS`] ADC steps is not used: it
//! cannot show the electrical side (R, L) and would mislead the fit; the record is then of the
//! voltage-and-speed kind.

use std::fmt;

/// A current column spanning fewer ADC steps than this (4 bits of range) is too coarse to be
/// fitted: its quantisation error, up to ±½ step, is then at least 3 % of the current's whole
/// range at every sample, and the current says little beyond its steady levels. A threshold of
/// judgement, not a derived bound; the coarse-current test of the CLI (a small motor at 50 Hz)
/// backs it.
pub const MIN_CURRENT_ADC_STEPS: f64 = 16.0;

/// The current channel of a set of records, as far as the kind depends on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CurrentChannel {
    /// No current column.
    Absent,
    /// A current column whose range spans `adc_steps` ADC steps in the record that spans the
    /// fewest (`f64::INFINITY` when the column is not quantised: no step found).
    Present {
        /// Range (max − min) over one ADC step \[-\] ([`current_adc_steps`]).
        adc_steps: f64,
    },
}

/// The channels a set of records measured (every record the same).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredChannels {
    /// An armature voltage column.
    pub voltage: bool,
    /// The current column.
    pub current: CurrentChannel,
    /// An encoder angle (position) column.
    pub position: bool,
    /// A tachometer speed column.
    pub tachometer: bool,
}

/// What drives the motor in the records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drive {
    /// The armature voltage is the input (the paper's tests, any waveform).
    Voltage,
    /// A drive controls the current: the torque is k times the current.
    Current,
}

/// How the records are given: as one high- and one low-voltage step (the step pair), or as
/// records of any waveform.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordSet {
    /// A high- and a low-voltage step from rest.
    StepPair,
    /// Records of any waveform, pooled.
    AnyWaveform,
}

/// Which motor constants are known (given by the user) besides the records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KnownConstants {
    /// The armature resistance R.
    pub resistance: bool,
    /// The torque constant k.
    pub torque_constant: bool,
}

/// A constant that a record kind needs to be given to determine more.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KnownConstant {
    /// The armature resistance R \[Ω\].
    Resistance,
    /// The torque constant k \[N·m/A\].
    TorqueConstant,
}

/// Why a current column that is present is not used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CurrentUnused {
    /// It spans `adc_steps` ADC steps, fewer than [`MIN_CURRENT_ADC_STEPS`].
    Coarse {
        /// Range over one ADC step \[-\].
        adc_steps: f64,
    },
}

/// What a set of records can identify ([`RecordKind::decide`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecordKind {
    /// Voltage, current and speed: R, L, k, f, J, Ts by output error.
    VoltageCurrentSpeed,
    /// A step pair with voltage and current (speed optional): R, L, k, f, J, Ts.
    StepPair,
    /// Voltage and speed: kS, kV, kA ([`crate::identify_feedforward`]); J, f, Ts as well when
    /// `mechanical` (R and k known).
    VoltageSpeed {
        /// R and k are known: J, f, Ts follow.
        mechanical: bool,
        /// Why a current column present is not used, if one is.
        current_unused: Option<CurrentUnused>,
    },
    /// A current-driven axis with a position: J, f, Ts and a constant offset (k given or
    /// estimated from a voltage column).
    CurrentDriven,
}

/// Why no kind applies: what is missing, with what to do.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum KindRefusal {
    /// A voltage drive without a voltage column.
    NoVoltage,
    /// Neither a current nor a speed (nor an encoder angle): nothing responds to the voltage.
    NoResponse,
    /// Records of any waveform with voltage and current but no speed: the output-error fit
    /// needs the speed for k, f, J and Ts.
    NoSpeed,
    /// Voltage and speed only with one of R and k given: J, f, Ts need both.
    OneOfResistanceAndTorqueConstant {
        /// The one that is missing.
        missing: KnownConstant,
    },
    /// A current-driven axis without an encoder angle.
    CurrentDrivenWithoutPosition,
    /// A current drive without a current column.
    CurrentDrivenWithoutCurrent,
    /// A current too coarse to use and no speed to fall back on.
    CoarseCurrentWithoutSpeed {
        /// Range over one ADC step \[-\].
        adc_steps: f64,
    },
    /// A step pair without a usable current: the step method fits the current.
    StepPairWithoutCurrent {
        /// Why the current is not usable: absent (`None`) or too coarse.
        coarse: Option<f64>,
    },
}

impl fmt::Display for KindRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KindRefusal::NoVoltage => write!(f, "no voltage column: a voltage-driven motor is identified from its voltage"),
            KindRefusal::NoResponse => write!(f, "neither current nor speed nor position: nothing responds to the voltage, so nothing can be identified"),
            KindRefusal::NoSpeed => write!(f, "neither speed nor position: k, f, J and Ts need one of them (a high- and a low-voltage step with the current alone: --high, --low)"),
            KindRefusal::OneOfResistanceAndTorqueConstant { missing } => write!(
                f,
                "voltage and speed alone give kS, kV, kA; J, f and Ts follow from them with both R and k known, and {} is not given",
                missing.symbol()
            ),
            KindRefusal::CurrentDrivenWithoutPosition => write!(f, "a current-driven axis is identified from its position, and there is no position column"),
            KindRefusal::CurrentDrivenWithoutCurrent => write!(f, "a current-driven axis is identified from its current, and there is no current column"),
            KindRefusal::CoarseCurrentWithoutSpeed { adc_steps } => write!(
                f,
                "the current spans {adc_steps:.0} ADC steps (fewer than {MIN_CURRENT_ADC_STEPS}): too coarse to show R and L, and there is no speed or position to identify the mechanical side from; record the current over a narrower range or add an encoder"
            ),
            KindRefusal::StepPairWithoutCurrent { coarse: None } => write!(f, "no current column: the step method fits the current"),
            KindRefusal::StepPairWithoutCurrent { coarse: Some(n) } => write!(
                f,
                "the current spans {n:.0} ADC steps (fewer than {MIN_CURRENT_ADC_STEPS}): too coarse for the step method, which fits the current"
            ),
        }
    }
}

impl std::error::Error for KindRefusal {}

impl KnownConstant {
    /// The constant's symbol, `R` or `k`.
    pub fn symbol(self) -> &'static str {
        match self {
            KnownConstant::Resistance => "R",
            KnownConstant::TorqueConstant => "k",
        }
    }
}

impl RecordKind {
    /// The kind of a set of records measuring `channels`, driven by `drive`, given as `set`,
    /// with `known` constants; or why none applies.
    pub fn decide(
        channels: MeasuredChannels,
        drive: Drive,
        set: RecordSet,
        known: KnownConstants,
    ) -> Result<RecordKind, KindRefusal> {
        let speed = channels.position || channels.tachometer;
        if drive == Drive::Current {
            return match (channels.current, channels.position) {
                (CurrentChannel::Absent, _) => Err(KindRefusal::CurrentDrivenWithoutCurrent),
                (_, false) => Err(KindRefusal::CurrentDrivenWithoutPosition),
                _ => Ok(RecordKind::CurrentDriven),
            };
        }
        if !channels.voltage {
            return Err(KindRefusal::NoVoltage);
        }
        let coarse = match channels.current {
            CurrentChannel::Present { adc_steps } if adc_steps < MIN_CURRENT_ADC_STEPS => {
                Some(adc_steps)
            }
            _ => None,
        };
        let usable_current =
            matches!(channels.current, CurrentChannel::Present { .. }) && coarse.is_none();
        if set == RecordSet::StepPair {
            return if usable_current {
                Ok(RecordKind::StepPair)
            } else {
                Err(KindRefusal::StepPairWithoutCurrent { coarse })
            };
        }
        match (usable_current, speed) {
            (true, true) => Ok(RecordKind::VoltageCurrentSpeed),
            (true, false) => Err(KindRefusal::NoSpeed),
            (false, false) => Err(match coarse {
                Some(adc_steps) => KindRefusal::CoarseCurrentWithoutSpeed { adc_steps },
                None => KindRefusal::NoResponse,
            }),
            (false, true) => {
                let mechanical = match (known.resistance, known.torque_constant) {
                    (true, true) => true,
                    (false, false) => false,
                    (true, false) => {
                        return Err(KindRefusal::OneOfResistanceAndTorqueConstant {
                            missing: KnownConstant::TorqueConstant,
                        })
                    }
                    (false, true) => {
                        return Err(KindRefusal::OneOfResistanceAndTorqueConstant {
                            missing: KnownConstant::Resistance,
                        })
                    }
                };
                Ok(RecordKind::VoltageSpeed {
                    mechanical,
                    current_unused: coarse.map(|adc_steps| CurrentUnused::Coarse { adc_steps }),
                })
            }
        }
    }

    /// What the records measured, in words (`"voltage and speed only"`).
    pub fn measured(&self) -> &'static str {
        match self {
            RecordKind::VoltageCurrentSpeed => "voltage, current and speed",
            RecordKind::StepPair => "high- and low-voltage steps with current",
            RecordKind::VoltageSpeed {
                current_unused: None,
                ..
            } => "voltage and speed only",
            RecordKind::VoltageSpeed {
                current_unused: Some(_),
                ..
            } => "voltage and speed (current too coarse)",
            RecordKind::CurrentDriven => "current-driven axis with position",
        }
    }

    /// Names of the parameters this kind determines (as the reports name them).
    pub fn identifiable(&self) -> &'static [&'static str] {
        match self {
            RecordKind::VoltageCurrentSpeed | RecordKind::StepPair => {
                &["R", "L", "k", "f", "J", "Ts"]
            }
            RecordKind::VoltageSpeed {
                mechanical: false, ..
            } => &["kS", "kV", "kA"],
            RecordKind::VoltageSpeed {
                mechanical: true, ..
            } => &["kS", "kV", "kA", "J", "f", "Ts"],
            RecordKind::CurrentDriven => &["J", "f", "Ts", "offset"],
        }
    }

    /// The constants to give for more parameters, and those parameters; `None` when nothing
    /// more can be had from these channels.
    pub fn more_with(&self) -> Option<(&'static [KnownConstant], &'static [&'static str])> {
        match self {
            RecordKind::VoltageSpeed {
                mechanical: false, ..
            } => Some((
                &[KnownConstant::Resistance, KnownConstant::TorqueConstant],
                &["J", "f", "Ts"],
            )),
            _ => None,
        }
    }

    /// Whether the voltage-and-speed identification applies ([`crate::identify_feedforward`]).
    pub fn is_voltage_speed(&self) -> bool {
        matches!(self, RecordKind::VoltageSpeed { .. })
    }
}

/// How far \[steps\] a gap between two values of a quantised column may be from a whole
/// number of steps (rounding of the scaled ADC counts).
const QUANTISED_TOLERANCE: f64 = 1e-3;

/// The range of a current column over one ADC step: `(max − min)/lsb`, with `lsb_a` the step
/// \[A\] if known, else the smallest non-zero difference between two of its values when every
/// difference is a whole number of it (a quantised column takes values on a grid).
/// `f64::INFINITY` when no step is found (a single value, or a column not on a grid).
pub fn current_adc_steps(current: &[f64], lsb_a: Option<f64>) -> f64 {
    let (lo, hi) = current
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let range = hi - lo;
    if range.is_nan() || range <= 0.0 {
        return f64::INFINITY;
    }
    let lsb = match lsb_a {
        Some(l) if l > 0.0 && l.is_finite() => l,
        _ => {
            let mut sorted: Vec<f64> = current.iter().copied().filter(|v| v.is_finite()).collect();
            sorted.sort_by(f64::total_cmp);
            let gaps: Vec<f64> = sorted
                .windows(2)
                .map(|w| w[1] - w[0])
                .filter(|d| *d > 1e-9 * range)
                .collect();
            let step = gaps.iter().copied().fold(f64::INFINITY, f64::min);
            // On a grid only if every gap is a whole number of the smallest: a column that is
            // not quantised has no step.
            let on_grid = gaps
                .iter()
                .all(|d| (d / step - (d / step).round()).abs() < QUANTISED_TOLERANCE);
            if !on_grid {
                return f64::INFINITY;
            }
            step
        }
    };
    range / lsb
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channels(current: CurrentChannel, position: bool) -> MeasuredChannels {
        MeasuredChannels {
            voltage: true,
            current,
            position,
            tachometer: false,
        }
    }

    #[test]
    fn voltage_and_speed_give_the_feedforward_constants_and_j_f_ts_with_r_and_k() {
        let c = channels(CurrentChannel::Absent, true);
        let none = KnownConstants::default();
        let both = KnownConstants {
            resistance: true,
            torque_constant: true,
        };
        let kind = RecordKind::decide(c, Drive::Voltage, RecordSet::AnyWaveform, none).unwrap();
        assert_eq!(kind.identifiable(), ["kS", "kV", "kA"]);
        assert!(kind.more_with().is_some());
        let kind = RecordKind::decide(c, Drive::Voltage, RecordSet::AnyWaveform, both).unwrap();
        assert_eq!(kind.identifiable().len(), 6);
        let r_only = KnownConstants {
            resistance: true,
            torque_constant: false,
        };
        assert_eq!(
            RecordKind::decide(c, Drive::Voltage, RecordSet::AnyWaveform, r_only),
            Err(KindRefusal::OneOfResistanceAndTorqueConstant {
                missing: KnownConstant::TorqueConstant
            })
        );
    }

    #[test]
    fn a_coarse_current_is_set_aside_or_refused_with_its_step_count() {
        let coarse = CurrentChannel::Present { adc_steps: 6.0 };
        let kind = RecordKind::decide(
            channels(coarse, true),
            Drive::Voltage,
            RecordSet::AnyWaveform,
            KnownConstants::default(),
        )
        .unwrap();
        assert!(kind.is_voltage_speed());
        let e = RecordKind::decide(
            channels(coarse, false),
            Drive::Voltage,
            RecordSet::AnyWaveform,
            KnownConstants::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("spans 6 ADC steps"), "{e}");
        let fine = CurrentChannel::Present { adc_steps: 500.0 };
        assert_eq!(
            RecordKind::decide(
                channels(fine, true),
                Drive::Voltage,
                RecordSet::AnyWaveform,
                KnownConstants::default()
            ),
            Ok(RecordKind::VoltageCurrentSpeed)
        );
        assert_eq!(
            RecordKind::decide(
                channels(CurrentChannel::Absent, false),
                Drive::Voltage,
                RecordSet::AnyWaveform,
                KnownConstants::default()
            ),
            Err(KindRefusal::NoResponse)
        );
    }

    #[test]
    fn the_adc_step_is_found_on_a_quantised_column() {
        let lsb = 0.25;
        let col: Vec<f64> = (0..100).map(|i| f64::from(i % 7) * lsb).collect();
        assert!((current_adc_steps(&col, None) - 6.0).abs() < 1e-12);
        assert!((current_adc_steps(&col, Some(0.5)) - 3.0).abs() < 1e-12);
        assert_eq!(current_adc_steps(&[1.0, 1.0], None), f64::INFINITY);
        // Not quantised: no step, however few the samples.
        let rise: Vec<f64> = (0..10).map(|i| 1.0 - (-f64::from(i) * 0.3).exp()).collect();
        assert_eq!(current_adc_steps(&rise, None), f64::INFINITY);
    }
}
