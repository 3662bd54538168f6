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
    /// Piecewise constant (a staircase, a PRBS, reversals): 0 V before `times_s[0]`, then
    /// `volts[j]` \[V\] from `times_s[j]` \[s\] until the next time.
    Piecewise {
        /// Instants \[s\] at which the level changes, strictly increasing.
        times_s: Vec<f64>,
        /// The level from each instant on \[V\].
        volts: Vec<f64>,
    },
    /// A sampled waveform, linearly interpolated: `volts[j]` \[V\] at `t0_s + j·dt_s`, held
    /// at its end values outside. Used to replay a measured voltage of any shape.
    Sampled {
        /// Time of the first sample \[s\].
        t0_s: f64,
        /// Sample period \[s\].
        dt_s: f64,
        /// The samples \[V\].
        volts: Vec<f64>,
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

    /// A piecewise-constant waveform from `(time [s], volts [V])` pairs, validated: finite
    /// levels, non-negative times in strictly increasing order, at least one pair.
    pub fn piecewise(steps: &[(f64, f64)]) -> Result<Self, ModelError> {
        if steps.is_empty() {
            return Err(ModelError::InvalidSetting {
                name: "piecewise levels".into(),
                value: 0.0,
                expected: "at least one time:volts pair",
            });
        }
        let mut times_s = Vec::with_capacity(steps.len());
        let mut volts = Vec::with_capacity(steps.len());
        for &(t, v) in steps {
            let t = non_negative("level time", t)?;
            if times_s.last().is_some_and(|&last| t <= last) {
                return Err(ModelError::InvalidSetting {
                    name: "level time".into(),
                    value: t,
                    expected: "level times in strictly increasing order",
                });
            }
            times_s.push(t);
            volts.push(finite("level voltage", v)?);
        }
        Ok(Input::Piecewise { times_s, volts })
    }

    /// A pseudo-random binary sequence: `±volts` \[V\], the sign drawn afresh every `bit_s`
    /// \[s\] from `seed` (a change happens on about half of the bits), starting at 0 V until
    /// `start_s` \[s\], over `duration_s` \[s\].
    pub fn prbs(
        volts: f64,
        bit_s: f64,
        start_s: f64,
        duration_s: f64,
        seed: u64,
    ) -> Result<Self, ModelError> {
        let volts = finite("PRBS amplitude", volts)?;
        let bit_s = positive("PRBS bit period", bit_s)?;
        let start_s = non_negative("PRBS start", start_s)?;
        let duration_s = positive("PRBS duration", duration_s)?;
        let bits = ((duration_s - start_s) / bit_s).ceil().max(1.0);
        if bits > 1e6 {
            return Err(ModelError::InvalidSetting {
                name: "PRBS bits".into(),
                value: bits,
                expected: "at most 1,000,000 bits: lengthen the bit period",
            });
        }
        let mut rng = crate::rng::NoiseRng::new(seed);
        let steps: Vec<(f64, f64)> = (0..bits as usize)
            .map(|j| {
                let sign = if rng.next_u64() >> 63 == 0 { 1.0 } else { -1.0 };
                (start_s + j as f64 * bit_s, sign * volts)
            })
            .collect();
        Input::piecewise(&steps)
    }

    /// A sampled waveform (linear interpolation), validated: `dt_s > 0`, finite samples, at
    /// least one.
    pub fn sampled(t0_s: f64, dt_s: f64, volts: Vec<f64>) -> Result<Self, ModelError> {
        let t0_s = finite("first sample time", t0_s)?;
        let dt_s = positive("sample period", dt_s)?;
        if volts.is_empty() {
            return Err(ModelError::InvalidSetting {
                name: "sampled voltage".into(),
                value: 0.0,
                expected: "at least one sample",
            });
        }
        for &v in &volts {
            finite("voltage sample", v)?;
        }
        Ok(Input::Sampled { t0_s, dt_s, volts })
    }

    /// The voltage \[V\] at time `t_s` \[s\].
    #[inline]
    pub fn volts_at(&self, t_s: f64) -> f64 {
        match self {
            Input::Step { volts, at_s } => {
                if t_s >= *at_s {
                    *volts
                } else {
                    0.0
                }
            }
            Input::Sine {
                amplitude_v,
                frequency_hz,
            } => amplitude_v * (std::f64::consts::TAU * frequency_hz * t_s).sin(),
            Input::Piecewise { times_s, volts } => {
                // Number of level times at or before t_s.
                let j = times_s.partition_point(|&t| t <= t_s);
                if j == 0 {
                    0.0
                } else {
                    volts[j - 1]
                }
            }
            Input::Sampled { t0_s, dt_s, volts } => {
                let x = (t_s - t0_s) / dt_s;
                let last = volts.len() - 1;
                if x <= 0.0 || last == 0 {
                    return volts[0];
                }
                if x >= last as f64 {
                    return volts[last];
                }
                let j = x.floor() as usize;
                let frac = x - j as f64;
                volts[j] + frac * (volts[j + 1] - volts[j])
            }
        }
    }

    /// Largest |E| \[V\] the waveform reaches.
    pub fn peak_volts(&self) -> f64 {
        match self {
            Input::Step { volts, .. } => volts.abs(),
            Input::Sine { amplitude_v, .. } => amplitude_v.abs(),
            Input::Piecewise { volts, .. } | Input::Sampled { volts, .. } => {
                volts.iter().fold(0.0, |m, v| m.max(v.abs()))
            }
        }
    }

    /// The first instant after `t_s` \[s\] where E(t) jumps; the integrator puts a step
    /// boundary on each (kinks of a sampled waveform fall on its samples and need none).
    pub(crate) fn next_jump_after(&self, t_s: f64) -> Option<f64> {
        match self {
            Input::Step { at_s, .. } => (*at_s > t_s).then_some(*at_s),
            Input::Piecewise { times_s, .. } => {
                let j = times_s.partition_point(|&t| t <= t_s);
                times_s.get(j).copied()
            }
            Input::Sine { .. } | Input::Sampled { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_levels_hold_from_their_instants() {
        let u = Input::piecewise(&[(1.0, 5.0), (2.0, -3.0)]).unwrap();
        assert_eq!(u.volts_at(0.999), 0.0);
        assert_eq!(u.volts_at(1.0), 5.0);
        assert_eq!(u.volts_at(1.999), 5.0);
        assert_eq!(u.volts_at(2.0), -3.0);
        assert_eq!(u.volts_at(100.0), -3.0);
        assert_eq!(u.next_jump_after(0.0), Some(1.0));
        assert_eq!(u.next_jump_after(1.0), Some(2.0));
        assert_eq!(u.next_jump_after(2.0), None);
        assert_eq!(u.peak_volts(), 5.0);
        assert!(Input::piecewise(&[(1.0, 5.0), (1.0, 2.0)]).is_err());
        assert!(Input::piecewise(&[]).is_err());
        assert!(Input::piecewise(&[(0.0, f64::NAN)]).is_err());
    }

    #[test]
    fn sampled_waveform_interpolates_linearly_and_holds_its_ends() {
        let u = Input::sampled(1.0, 0.5, vec![0.0, 2.0, 1.0]).unwrap();
        assert_eq!(u.volts_at(0.0), 0.0);
        assert_eq!(u.volts_at(1.25), 1.0);
        assert_eq!(u.volts_at(1.75), 1.5);
        assert_eq!(u.volts_at(5.0), 1.0);
        assert_eq!(u.next_jump_after(0.0), None);
    }

    #[test]
    fn prbs_switches_sign_on_its_bit_grid() {
        let u = Input::prbs(10.0, 0.5, 1.0, 20.0, 7).unwrap();
        let Input::Piecewise { times_s, volts } = &u else {
            panic!("a PRBS is piecewise constant")
        };
        assert_eq!(times_s.len(), 38);
        assert!(volts.iter().all(|v| v.abs() == 10.0));
        let changes = volts.windows(2).filter(|w| w[0] != w[1]).count();
        assert!((10..=28).contains(&changes), "{changes} sign changes");
        assert_eq!(u.volts_at(0.5), 0.0);
    }
}
