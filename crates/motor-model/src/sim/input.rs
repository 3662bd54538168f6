use serde::{Deserialize, Serialize};

use crate::error::{finite, non_negative, positive, ModelError};

/// Armature voltage waveform E(t) \[V\] applied by the simulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Input {
    /// 0 V before `at_s`, then `volts` \[V\] (either sign). The paper's tests (Sec. 2.4, 4.1).
    Step {
        /// Step height \[V\].
        volts: f64,
        /// Step instant \[s\].
        at_s: f64,
    },
    /// `E(t) = amplitude_v · sin(2π frequency_hz · t)` \[V\], as in Appendix D
    /// (`0.1 sin(πt/10)`: amplitude 0.1 V, 0.05 Hz).
    Sine {
        /// Amplitude \[V\].
        amplitude_v: f64,
        /// Frequency \[Hz\].
        frequency_hz: f64,
    },
}

impl Input {
    /// A step of `volts` \[V\] at `at_s` \[s\], validated.
    pub fn step(volts: f64, at_s: f64) -> Result<Self, ModelError> {
        Ok(Input::Step {
            volts: finite("step voltage", volts)?,
            at_s: non_negative("step instant", at_s)?,
        })
    }

    /// A sine of `amplitude_v` \[V\] and `frequency_hz` \[Hz\], validated.
    pub fn sine(amplitude_v: f64, frequency_hz: f64) -> Result<Self, ModelError> {
        Ok(Input::Sine {
            amplitude_v: finite("sine amplitude", amplitude_v)?,
            frequency_hz: positive("sine frequency", frequency_hz)?,
        })
    }

    /// The voltage \[V\] at time `t_s` \[s\].
    #[inline]
    pub fn volts_at(&self, t_s: f64) -> f64 {
        match *self {
            Input::Step { volts, at_s } => {
                if t_s >= at_s {
                    volts
                } else {
                    0.0
                }
            }
            Input::Sine {
                amplitude_v,
                frequency_hz,
            } => amplitude_v * (std::f64::consts::TAU * frequency_hz * t_s).sin(),
        }
    }

    /// Largest |E| \[V\] the waveform reaches.
    pub fn peak_volts(&self) -> f64 {
        match *self {
            Input::Step { volts, .. } => volts.abs(),
            Input::Sine { amplitude_v, .. } => amplitude_v.abs(),
        }
    }

    /// Instants \[s\] where E(t) jumps; the integrator puts a step boundary on each.
    pub(crate) fn discontinuity(&self) -> Option<f64> {
        match *self {
            Input::Step { at_s, .. } => Some(at_s),
            Input::Sine { .. } => None,
        }
    }
}
