//! A simulated record at the plant, before the measurement model ([`Trace`]), and the sample
//! grid every simulation of a duration at a rate produces ([`sample_grid`]).

use serde::Serialize;

use crate::error::{positive, ModelError};

/// Longest record the simulator will produce, in samples (about 80 MB of output).
pub const MAX_SAMPLES: usize = 10_000_000;
/// A simulated record at the plant (before the measurement model), SI units.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Trace {
    /// Sample times \[s\].
    pub t: Vec<f64>,
    /// Armature voltage E(t) applied \[V\].
    pub voltage: Vec<f64>,
    /// Current seen by the current sensor \[A\] (equals the armature current unless
    /// `current_sensor_lag` is on).
    pub current: Vec<f64>,
    /// True armature current \[A\].
    pub armature_current: Vec<f64>,
    /// Speed Ω \[rad/s\].
    pub speed: Vec<f64>,
    /// Angle θ \[rad\].
    pub position: Vec<f64>,
    /// Whether the rotor was stuck (Coulomb friction holding it) at the sample.
    pub stuck: Vec<bool>,
}

impl Trace {
    /// An empty trace with room for `n` samples in every channel.
    pub(crate) fn with_capacity(n: usize) -> Self {
        Trace {
            t: Vec::with_capacity(n),
            voltage: Vec::with_capacity(n),
            current: Vec::with_capacity(n),
            armature_current: Vec::with_capacity(n),
            speed: Vec::with_capacity(n),
            position: Vec::with_capacity(n),
            stuck: Vec::with_capacity(n),
        }
    }
}

/// Number of samples `⌊duration·rate⌋ + 1` (t = 0 to `duration_s` \[s\] included) and the
/// sample period \[s\], refusing non-positive settings and records over [`MAX_SAMPLES`].
pub(crate) fn sample_grid(duration_s: f64, rate_hz: f64) -> Result<(usize, f64), ModelError> {
    let duration_s = positive("duration", duration_s)?;
    let rate_hz = positive("sample rate", rate_hz)?;
    let n_f = (duration_s * rate_hz).floor() + 1.0;
    if n_f > MAX_SAMPLES as f64 {
        return Err(ModelError::InvalidSetting {
            name: "duration × rate".into(),
            value: n_f,
            expected: "at most 10,000,000 samples: shorten the record or lower the rate",
        });
    }
    Ok((n_f as usize, 1.0 / rate_hz))
}
