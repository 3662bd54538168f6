//! Servo rigs (SPEC section 8): a geared motor seen from its output, with known loads and the
//! firmware's position loop, replayed on a log's own time stamps.
//!
//! - [`Load`]: pendulum, inertia, spring, constant torque (`--load`, `# load:`).
//! - [`Controller`]: the position loop, `p:…`, `pd:…` and presets (`dynamixel-xl330:kp=N`).
//! - [`ServoMotor`], [`ServoRig`]: the motor at the output and the whole rig.
//! - [`replay`]: a record simulated open loop from its voltage or duty, or closed loop from its
//!   set-point ([`ServoRun`], [`ServoDrive`]).
//! - [`ModelFile`]: the versioned model file (`--save-model`, `--model`).

mod controller;
mod load;
mod model_file;
mod plant;
mod replay;

pub use controller::{Controller, XL330_GAIN_PER_RAD};
pub use load::{Load, STANDARD_GRAVITY_M_S2};
pub use model_file::{ModelFile, MODEL_FILE_FORMAT, MODEL_FILE_VERSION};
pub use plant::{ServoMotor, ServoRig};
pub use replay::{replay, ReplaySettings, ServoDrive, ServoRun, ServoTrace, MAX_REPLAY_SUBSTEPS};
