//! The base model a stage of the diagnosis builds on: the motor, the effects named so far and
//! the training records' masks and inputs at its own jump instants.

use motor_model::{Effects, MotorParams};

use crate::estimation::records::{ExcitedRecord, FittedChannel};

/// Everything one stage needs about the model it starts from.
pub(crate) struct Base<'a> {
    pub(crate) motor: MotorParams,
    pub(crate) effects: Effects,
    /// Its prediction on every sample of every record (training and held out).
    pub(crate) fitted: Vec<FittedChannel>,
    pub(crate) train: &'a [ExcitedRecord<'a>],
    pub(crate) all: &'a [ExcitedRecord<'a>],
    /// `all` with every voltage jump where the voltage column puts it (on the first sample
    /// that shows it), the bracket a refit's jumps are located in.
    pub(crate) grid: &'a [ExcitedRecord<'a>],
}
