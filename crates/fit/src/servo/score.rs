//! How well a model replays records: the position error of each, as `motorid replay` and the
//! held-out checks report it.

use motor_model::{replay, ReplaySettings, ServoMotor, ServoTrace};

use crate::error::FitError;
use crate::servo::records::{Loop, ServoRecord};

/// One record replayed.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayScore {
    /// The record's name.
    pub name: String,
    /// Whether it was replayed in closed loop.
    pub closed_loop: bool,
    /// Mean of `|q_replayed − q_logged|` \[rad\].
    pub mae_rad: f64,
    /// Root mean square of `q_replayed − q_logged` \[rad\].
    pub rmse_rad: f64,
    /// Largest `|q_replayed − q_logged|` \[rad\].
    pub max_error_rad: f64,
    /// Samples.
    pub samples: usize,
}

/// Replays `record` with `motor` under `mode`: its trace.
pub fn replay_record(
    record: &ServoRecord,
    motor: ServoMotor,
    mode: Loop,
    settings: ReplaySettings,
) -> Result<ServoTrace, FitError> {
    let run = record.run(mode)?;
    replay(&record.rig(motor), &run, settings).map_err(FitError::model("replay"))
}

/// The position errors of `trace` against `record`.
pub fn score(record: &ServoRecord, trace: &ServoTrace, closed_loop: bool) -> ReplayScore {
    let errors: Vec<f64> = trace
        .q_rad
        .iter()
        .zip(&record.q_rad)
        .map(|(s, m)| s - m)
        .collect();
    let n = errors.len().max(1) as f64;
    ReplayScore {
        name: record.name.clone(),
        closed_loop,
        mae_rad: errors.iter().map(|e| e.abs()).sum::<f64>() / n,
        rmse_rad: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        max_error_rad: errors.iter().fold(0.0, |a, e| a.max(e.abs())),
        samples: errors.len(),
    }
}

/// Every record replayed with `motor` under `mode` and scored.
pub fn score_records(
    records: &[ServoRecord],
    motor: ServoMotor,
    mode: Loop,
    settings: ReplaySettings,
) -> Result<Vec<ReplayScore>, FitError> {
    records
        .iter()
        .map(|r| {
            let trace = replay_record(r, motor, mode, settings)?;
            Ok(score(r, &trace, r.closed_loop(mode)))
        })
        .collect()
}
