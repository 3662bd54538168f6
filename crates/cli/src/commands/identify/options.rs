//! What `motorid identify` is asked, validated from its command line: the records, the route
//! (steps, steady tests, current-driven axes), the columns and the outputs.

use std::path::PathBuf;

use anyhow::Result;
use fit::{Drive, KnownConstants};
use motor_model::MotorParams;

use crate::args::{AxisArg, DriveArg, FrictionArg, IdentifyArgs};
use crate::errors::BadInput;
use crate::record_csv::ColumnMap;
use crate::servo_csv::{self, RigOptions};
use crate::settings;

/// Where the records of an identification come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A high- and a low-voltage step record (`--high`, `--low`).
    Pair {
        /// High-voltage step record.
        high: PathBuf,
        /// Low-voltage step record.
        low: PathBuf,
    },
    /// Steady-state records at several voltages (`--steady`), with R \[Ω\] and k \[N·m/A\]
    /// known.
    Steady {
        /// The records.
        paths: Vec<PathBuf>,
        /// Known armature resistance R \[Ω\].
        resistance_ohm: f64,
        /// Known torque constant k \[N·m/A\].
        torque_constant: f64,
    },
    /// Records of any waveform (`--record`), voltage- or current-driven as `drive` says.
    Records(Vec<PathBuf>),
    /// A folder of motor folders (`--batch`).
    Batch(PathBuf),
    /// Servo logs (`--record` files with `duty` or `goal`, or a rig given with `--load` /
    /// `--controller` / `--gear`), with held-out records (`--validate`).
    Servo {
        /// The records fitted.
        records: Vec<PathBuf>,
        /// The held-out records.
        validate: Vec<PathBuf>,
    },
}

/// Whether positions are angles or lengths (the units of J, f, Ts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Angles in rad: kg·m², N·m·s/rad, N·m.
    Rotary,
    /// Positions in m: kg, N·s/m, N.
    Linear,
}

/// How long one motor folder of `--batch` may take by default \[s\]: ten minutes, far beyond
/// the few seconds a folder of logger records takes.
pub(crate) const DEFAULT_FOLDER_LIMIT_S: f64 = 600.0;

/// The `--folder-limit` values accepted \[s\]: from a microsecond (every folder set aside, as
/// a test of the summary) to about eleven days.
pub(crate) const FOLDER_LIMIT_RANGE_S: (f64, f64) = (1e-6, 1e6);

/// What `motorid identify` identifies and how, validated from its arguments.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The records.
    pub source: Source,
    /// What drives the axis: voltage steps or a current loop.
    pub drive: Drive,
    /// The step-pair method.
    pub method: fit::StepMethod,
    /// `--resistance` R \[Ω\], checked positive (for `--record` files without a current).
    pub resistance: Option<f64>,
    /// `--torque-constant` k \[N·m/A\] (N/A for a linear axis), checked positive.
    pub torque_constant: Option<f64>,
    /// Which of R and k are given.
    pub known: KnownConstants,
    /// The start of the output-error fit, if given.
    pub start: Option<MotorParams>,
    /// Folder for the figures, if asked for.
    pub plot: Option<PathBuf>,
    /// No progress messages or warnings on standard error.
    pub quiet: bool,
    /// One JSON object instead of tables.
    pub json: bool,
    /// Header names of the record columns.
    pub columns: ColumnMap,
    /// Rotary or linear axis.
    pub axis: Axis,
    /// Cut-off of the zero-phase position filter for `--input current` \[Hz\].
    pub cutoff_hz: f64,
    /// Decimation factor for `--input current` (1: none).
    pub decimation: usize,
    /// How each record's simulation starts; `None`: told from its first samples.
    pub initial_state: Option<fit::InitialState>,
    /// `--folder-limit`: how long one motor folder of `--batch` may take before it is set
    /// aside as an error row.
    pub folder_limit: std::time::Duration,
    /// The servo rig given on the command line (`--load`, `--controller`, `--gear`).
    pub rig: RigOptions,
    /// `--open-loop`: servo logs fitted on their recorded duty.
    pub open_loop: bool,
    /// `--friction`: the servo's friction model.
    pub friction: fit::Friction,
    /// `--save-model`: where the identified servo model is written.
    pub save_model: Option<PathBuf>,
}

impl Settings {
    /// The options of `a`, each checked once, before any record is read: which records,
    /// `--resistance` and `--torque-constant` (positive, and only where they apply),
    /// `--decimation` ≥ 1, `--columns`, `--start`.
    pub fn from_args(a: &IdentifyArgs) -> Result<Settings> {
        if a.resistance.is_some()
            && a.steady.is_empty()
            && (a.record.is_empty() || a.input == DriveArg::Current)
        {
            return Err(BadInput(
                "--resistance is for --steady, or with --torque-constant for --record files of voltage and speed only".into(),
            )
            .into());
        }
        let drive = match a.input {
            DriveArg::Voltage => Drive::Voltage,
            DriveArg::Current => Drive::Current,
        };
        if drive == Drive::Current {
            if a.record.is_empty() {
                return Err(BadInput(
                    "--input current needs --record FILE.csv (current and position of the axis; repeatable: records of one axis are pooled)".into(),
                )
                .into());
            }
            if a.decimation == 0 {
                return Err(BadInput(
                    "--decimation 0: expected a factor of 1 (none) or more".into(),
                )
                .into());
            }
        }
        let source = if drive == Drive::Current {
            Source::Records(a.record.clone())
        } else if !a.steady.is_empty() {
            let (Some(resistance_ohm), Some(torque_constant)) = (a.resistance, a.torque_constant)
            else {
                return Err(BadInput("--steady needs --resistance OHM and --torque-constant NM_PER_A: Sec. 2.2 assumes R and k known".into()).into());
            };
            Source::Steady {
                paths: a.steady.clone(),
                resistance_ohm,
                torque_constant,
            }
        } else if !a.record.is_empty()
            && (!a.rig.load.is_empty()
                || a.rig.controller.is_some()
                || a.rig.gear.is_some()
                || a.save_model.is_some()
                || !a.validate.is_empty()
                || a.open_loop
                || a.record.iter().any(|p| servo_csv::is_servo_log(p)))
        {
            servo_csv::distinct(a.record.iter().chain(&a.validate))?;
            Source::Servo {
                records: a.record.clone(),
                validate: a.validate.clone(),
            }
        } else if !a.record.is_empty() {
            Source::Records(a.record.clone())
        } else if let Some(dir) = &a.batch {
            Source::Batch(dir.clone())
        } else if let (Some(high), Some(low)) = (&a.high, &a.low) {
            Source::Pair {
                high: high.clone(),
                low: low.clone(),
            }
        } else {
            return Err(BadInput(
                "give the records: --high HV.csv --low LV.csv (a step pair), --record FILE.csv (any voltage waveform, repeatable; with --input current, a current-driven axis), --steady FILE.csv (steady tests), or --batch DIR (a fleet)".into(),
            )
            .into());
        };
        if a.folder_limit.is_some() && a.batch.is_none() {
            return Err(BadInput(
                "--folder-limit is for --batch DIR: one identification is bounded by its fit's iterations".into(),
            )
            .into());
        }
        let limit_s = a.folder_limit.unwrap_or(DEFAULT_FOLDER_LIMIT_S);
        if !(FOLDER_LIMIT_RANGE_S.0..=FOLDER_LIMIT_RANGE_S.1).contains(&limit_s) {
            return Err(BadInput(format!(
                "--folder-limit {limit_s:.3e}: expected seconds from {:e} to {:e}",
                FOLDER_LIMIT_RANGE_S.0, FOLDER_LIMIT_RANGE_S.1
            ))
            .into());
        }
        let folder_limit = std::time::Duration::from_secs_f64(limit_s);
        let columns = match &a.columns {
            Some(text) => ColumnMap::parse(text)?,
            None => ColumnMap::default(),
        };
        // The steady fit checks its own R and k (Eq. (9)).
        let known = if matches!(source, Source::Steady { .. }) {
            KnownConstants::default()
        } else {
            known_constants(a.resistance, a.torque_constant)?
        };
        Ok(Settings {
            source,
            drive,
            method: settings::step_method(a.method),
            resistance: a.resistance,
            torque_constant: a.torque_constant,
            known,
            start: a.start.as_deref().map(settings::motor).transpose()?,
            plot: a.plot.clone(),
            quiet: a.quiet,
            json: a.json,
            columns,
            axis: match a.axis {
                AxisArg::Rotary => Axis::Rotary,
                AxisArg::Linear => Axis::Linear,
            },
            cutoff_hz: a.cutoff,
            decimation: a.decimation,
            initial_state: settings::initial_state(a.initial_state),
            folder_limit,
            rig: RigOptions::parse(&a.rig.load, a.rig.controller.as_deref(), a.rig.gear)?,
            save_model: a
                .save_model
                .as_deref()
                .map(|m| servo_csv::not_an_input(m, a.record.iter().chain(&a.validate)))
                .transpose()?,
            open_loop: a.open_loop,
            friction: match a.friction {
                FrictionArg::Coulomb => fit::Friction::CoulombViscous,
                FrictionArg::LoadDependent => fit::Friction::LoadDependent,
                FrictionArg::Stribeck => fit::Friction::Stribeck,
            },
        })
    }
}

/// The known constants given, `resistance` \[Ω\] and `torque_constant` \[N·m/A\], checked
/// positive and finite.
pub fn known_constants(
    resistance: Option<f64>,
    torque_constant: Option<f64>,
) -> Result<KnownConstants> {
    for (name, value) in [
        ("--resistance", resistance),
        ("--torque-constant", torque_constant),
    ] {
        if let Some(v) = value.filter(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(BadInput(format!("{name} {v}: expected a positive number")).into());
        }
    }
    Ok(KnownConstants {
        resistance: resistance.is_some(),
        torque_constant: torque_constant.is_some(),
    })
}
