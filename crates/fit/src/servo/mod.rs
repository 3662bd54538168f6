//! Servo rigs (SPEC section 8): the motor of a geared servo fitted to its logs, with known
//! loads and the firmware's position loop, and its logs replayed.
//!
//! - [`ServoRecord`]: a log with its rig; [`Loop`]: closed loop from the set-point or open.
//! - [`ServoFit`]: the fit (a builder) → [`ServoFitResult`] with 95 % intervals.
//! - [`score_records`], [`replay_record`]: position MAE and RMSE of a replay.

mod fit;
mod records;
mod score;

pub use fit::{Friction, ServoFit, ServoFitResult, SERVO_NAMES, SERVO_UNITS, SMALL_SERVO_START};
pub use records::{Loop, ServoRecord};
pub use score::{replay_record, score, score_records, ReplayScore};
