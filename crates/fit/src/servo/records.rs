//! A servo log as the fit sees it: time stamps, the measured output angle, what drove it, and
//! the rig it was taken on (loads and controller, which may differ from record to record).

use motor_model::{Controller, Load, ServoDrive, ServoMotor, ServoRig, ServoRun};

use crate::error::FitError;

/// One log of a servo rig (SPEC section 8), every series one value per time stamp.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ServoRecord {
    /// Its name in reports (the file name).
    pub name: String,
    /// Time stamps \[s\], strictly increasing, as logged (not necessarily uniform).
    pub t_s: Vec<f64>,
    /// Measured output angle \[rad\].
    pub q_rad: Vec<f64>,
    /// Measured output speed \[rad/s\], if logged (only its first value is used: the start).
    pub w_rad_s: Option<Vec<f64>>,
    /// Armature voltage \[V\], if logged.
    pub voltage_v: Option<Vec<f64>>,
    /// PWM duty \[−1…1\], if logged (with `supply_v`).
    pub duty: Option<Vec<f64>>,
    /// Supply \[V\], if logged.
    pub supply_v: Option<Vec<f64>>,
    /// Position set-point \[rad\], if logged.
    pub goal_rad: Option<Vec<f64>>,
    /// Drive on (true) or off, if logged.
    pub enable: Option<Vec<bool>>,
    /// Known loads on the output.
    pub loads: Vec<Load>,
    /// The firmware's position loop, if it runs one.
    pub controller: Option<Controller>,
    /// Gear ratio N (positions on the output of an N:1 gearbox; 1 without one).
    pub gear: f64,
}

/// How a record is replayed: from its set-point through the controller, or from its
/// recorded voltage or duty.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Loop {
    /// Closed loop from `goal` when the record has a controller and a set-point, else open.
    #[default]
    Closed,
    /// Open loop from the recorded voltage or duty.
    Open,
}

impl ServoRecord {
    /// The rig of this record with `motor`.
    pub fn rig(&self, motor: ServoMotor) -> ServoRig {
        ServoRig {
            motor,
            gear: self.gear,
            loads: self.loads.clone(),
            controller: self.controller.clone(),
        }
    }

    /// Whether it is replayed in closed loop under `mode`.
    pub fn closed_loop(&self, mode: Loop) -> bool {
        mode == Loop::Closed
            && self.controller.is_some()
            && self.goal_rad.is_some()
            && self.supply_v.is_some()
    }

    /// The replay input of this record under `mode`; refuses a record with neither a voltage
    /// nor a duty with its supply (nor, in closed loop, a set-point with a controller).
    pub fn run(&self, mode: Loop) -> Result<ServoRun<'_>, FitError> {
        let drive = if self.closed_loop(mode) {
            ServoDrive::Goal {
                goal_rad: self.goal_rad.as_deref().unwrap_or_default(),
                supply_v: self.supply_v.as_deref().unwrap_or_default(),
            }
        } else if let (Some(duty), Some(supply_v)) = (&self.duty, &self.supply_v) {
            ServoDrive::Duty { duty, supply_v }
        } else if let Some(v) = &self.voltage_v {
            ServoDrive::Voltage(v)
        } else {
            return Err(FitError::BadData {
                series: self.name.clone(),
                reason: "no input: give `voltage`, or `duty` with `supply`, or `goal` with `supply` and a controller".into(),
            });
        };
        // Started from the logged angle and speed (0 where no speed is logged).
        Ok(ServoRun {
            t_s: &self.t_s,
            drive,
            enable: self.enable.as_deref(),
            q0_rad: self.q_rad.first().copied().unwrap_or(0.0),
            w0_rad_s: self
                .w_rad_s
                .as_ref()
                .and_then(|w| w.first().copied())
                .unwrap_or(0.0),
        })
    }
}
