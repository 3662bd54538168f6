//! Zero-phase filtering and decimation, for differentiating measured positions (the
//! "bandpass filtering" and "decimate" steps of inverse-model identification, IDIM-LS).

use crate::error::FitError;

/// One second-order section `(b0 + b1 z⁻¹ + b2 z⁻²)/(1 + a1 z⁻¹ + a2 z⁻²)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

/// A Butterworth low-pass filter as cascaded second-order sections.
#[derive(Debug, Clone, PartialEq)]
pub struct Butterworth {
    sections: Vec<Biquad>,
    /// Samples of odd reflection added at each end by [`Butterworth::filtfilt`]: long enough
    /// for the start-up transient of each pass to die out (1.5 × the order times the cut-off's
    /// period, in samples; never fewer than MATLAB's 3 × order).
    pad: usize,
}

impl Butterworth {
    /// A low-pass of even `order` (2, 4, 6, 8) with its −3 dB point at `cutoff_hz` for samples
    /// at `rate_hz`, by the bilinear transform with frequency pre-warping.
    pub fn low_pass(order: usize, cutoff_hz: f64, rate_hz: f64) -> Result<Self, FitError> {
        if order == 0 || !order.is_multiple_of(2) || order > 16 {
            return Err(FitError::InvalidSetting {
                name: "Butterworth order",
                value: order as f64,
                expected: "an even order from 2 to 16",
            });
        }
        if !(cutoff_hz > 0.0 && rate_hz > 0.0 && cutoff_hz < 0.5 * rate_hz) {
            return Err(FitError::InvalidSetting {
                name: "cut-off frequency",
                value: cutoff_hz,
                expected: "a frequency between 0 and half the sample rate",
            });
        }
        // Pre-warped analog cut-off, bilinear constant K = tan(π fc / fs).
        let k = (std::f64::consts::PI * cutoff_hz / rate_hz).tan();
        let sections = (0..order / 2)
            .map(|i| {
                // Analog pole pair angle: s² + 2 cos(θ) s + 1 with θ = π(2i+1)/(2n).
                let theta = std::f64::consts::PI * (2 * i + 1) as f64 / (2 * order) as f64;
                let q = 2.0 * theta.cos(); // s² + q s + 1
                let norm = 1.0 + q * k + k * k;
                let b0 = k * k / norm;
                Biquad {
                    b: [b0, 2.0 * b0, b0],
                    a: [2.0 * (k * k - 1.0) / norm, (1.0 - q * k + k * k) / norm],
                }
            })
            .collect();
        // The slowest pole of an order-n Butterworth decays with rate ωc sin(π/(2n)): 1.5 n
        // periods of the cut-off leave e^-14 of a start-up transient (with
        // 3 × order samples a 4 Hz filter at 1 kHz erred by 80 rad/s on the speed of a ramp's
        // last 100 samples).
        let periods = 1.5 * order as f64 * rate_hz / cutoff_hz;
        let pad = (3 * order).max(periods.ceil().min(1e9) as usize);
        Ok(Butterworth { sections, pad })
    }

    fn run(&self, x: &mut [f64]) {
        for s in &self.sections {
            // Start in the steady state of the first sample (no start-up transient).
            let x0 = x.first().copied().unwrap_or(0.0);
            let (mut z1, mut z2) = steady_state(s, x0);
            for v in x.iter_mut() {
                let y = s.b[0] * *v + z1;
                z1 = s.b[1] * *v - s.a[0] * y + z2;
                z2 = s.b[2] * *v - s.a[1] * y;
                *v = y;
            }
        }
    }

    /// Zero-phase filtering: forward then backward over the signal extended at both ends by
    /// odd reflection (3 × order samples), as MATLAB's `filtfilt`; the output has no lag and
    /// the magnitude response squared.
    pub fn filtfilt(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        if n < 2 {
            return x.to_vec();
        }
        let pad = self.pad.min(n - 1);
        let (first, last) = (x[0], x[n - 1]);
        let mut ext = Vec::with_capacity(n + 2 * pad);
        ext.extend((1..=pad).rev().map(|i| 2.0 * first - x[i]));
        ext.extend_from_slice(x);
        ext.extend((1..=pad).map(|i| 2.0 * last - x[n - 1 - i]));
        self.run(&mut ext);
        ext.reverse();
        self.run(&mut ext);
        ext.reverse();
        ext[pad..pad + n].to_vec()
    }
}

/// Direct-form-II-transposed state `(z1, z2)` that leaves a constant input `x0` at its DC gain.
fn steady_state(s: &Biquad, x0: f64) -> (f64, f64) {
    let gain = (s.b[0] + s.b[1] + s.b[2]) / (1.0 + s.a[0] + s.a[1]);
    let y = gain * x0;
    let z2 = s.b[2] * x0 - s.a[1] * y;
    let z1 = s.b[1] * x0 - s.a[0] * y + z2;
    (z1, z2)
}

/// Zero-phase low-pass at 0.8 × the new Nyquist frequency (order-8 Butterworth, forward and
/// backward), then one sample in `factor` kept: the "decimate" step, applied alike to every
/// column of an inverse model and to the measured force.
pub fn decimate(x: &[f64], factor: usize) -> Result<Vec<f64>, FitError> {
    if factor <= 1 {
        return Ok(x.to_vec());
    }
    let filter = Butterworth::low_pass(8, 0.8 * 0.5 / factor as f64, 1.0)?;
    Ok(filter.filtfilt(x).into_iter().step_by(factor).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gain of the zero-phase filter at frequency `f` (fraction of the sample rate), measured
    /// on a long sine: |H|² of the Butterworth, 1/(1 + (f/fc)^(2n)) per pass.
    fn measured_gain(filter: &Butterworth, f: f64) -> f64 {
        let n = 20_000;
        let x: Vec<f64> = (0..n)
            .map(|i| (std::f64::consts::TAU * f * i as f64).sin())
            .collect();
        let y = filter.filtfilt(&x);
        let mid = &y[n / 4..3 * n / 4];
        let ref_mid = &x[n / 4..3 * n / 4];
        let power = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>();
        (power(mid) / power(ref_mid)).sqrt()
    }

    #[test]
    fn butterworth_has_the_butterworth_magnitude_and_no_phase() {
        let fc = 0.05;
        let filter = Butterworth::low_pass(4, fc, 1.0).unwrap();
        for f in [0.01, 0.03, 0.05, 0.08, 0.15] {
            // Bilinear warping makes the digital response exact at fc and close elsewhere.
            let warped = (std::f64::consts::PI * f).tan() / (std::f64::consts::PI * fc).tan();
            let expected = 1.0 / (1.0 + warped.powi(8));
            let got = measured_gain(&filter, f);
            assert!(
                (got - expected).abs() < 2e-3,
                "f = {f}: {got} vs {expected}"
            );
        }
        // No lag: a slow sine comes out in phase.
        let x: Vec<f64> = (0..5000)
            .map(|i| (0.002 * std::f64::consts::TAU * i as f64).sin())
            .collect();
        let y = filter.filtfilt(&x);
        for i in 1000..4000 {
            assert!((y[i] - x[i]).abs() < 1e-6, "sample {i}");
        }
        // A constant passes unchanged, ends included.
        let c = filter.filtfilt(&[3.0; 50]);
        assert!(c.iter().all(|v| (v - 3.0).abs() < 1e-12));
        assert!(Butterworth::low_pass(3, 0.1, 1.0).is_err());
        assert!(Butterworth::low_pass(4, 0.6, 1.0).is_err());
    }

    #[test]
    fn decimate_keeps_slow_signals_and_drops_fast_ones() {
        let x: Vec<f64> = (0..10_000)
            .map(|i| {
                let t = i as f64;
                (0.001 * std::f64::consts::TAU * t).sin()
                    + 0.5 * (0.3 * std::f64::consts::TAU * t).sin()
            })
            .collect();
        let d = decimate(&x, 10).unwrap();
        assert_eq!(d.len(), 1000);
        for (k, v) in d.iter().enumerate().skip(50).take(900) {
            let slow = (0.001 * std::f64::consts::TAU * (10 * k) as f64).sin();
            assert!((v - slow).abs() < 1e-3, "{k}: {v} vs {slow}");
        }
    }
}
