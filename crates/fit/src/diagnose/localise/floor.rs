//! The noise floor model of a channel (quantum, steady-state scatter, rails, the encoder's
//! code pattern), the residual's correlation factor and the excess test against the floor.

use crate::diagnose::localise::types::{
    ExcessTest, FloorSource, NoiseFloor, ResidualChannel, ResidualRecord, PRECISION_FLOOR,
};
use crate::estimation::records::{noise_std, second_difference, Channel};
use crate::estimation::stats::chi_square_sf;
use crate::excitation::input_uncertainty::detect_quantum;

/// Test families per channel (for the Bonferroni split of [`LocaliseSettings::alpha`]).
pub(crate) const FAMILIES: f64 = 11.0;

/// Samples of a block of the steady-state scatter.
pub(crate) const SCATTER_BLOCK: usize = 32;

/// Flat blocks needed for a steady-state scatter.
pub(crate) const MIN_FLAT_BLOCKS: usize = 3;

/// A flat block whose scatter is more than this many times the median flat block's holds a
/// transient, not noise, and is left out of the steady-state scatter \[-\]. The scatter of
/// 30 degrees of freedom exceeds twice its median with a probability below 1e-7.
pub(crate) const SCATTER_OUTLIER: f64 = 2.0;

/// Floor of `g = frac(m)(1 − frac(m))` of an encoder speed.
pub(crate) const ENCODER_G_MIN: f64 = 0.01;

/// Two-sided 99 % point of the standard normal (the bounds of MATLAB's `resid`).
pub(crate) const Z_99: f64 = 2.575_829_303_548_901;

/// Fraction of the largest |speed| under which the motor is taken as stopped.
pub(crate) const STOPPED_FRACTION: f64 = 0.02;

/// Fraction of a column's samples at its extreme value that makes that value an ADC rail.
pub(crate) const RAIL_FRACTION: f64 = 0.01;

/// Fraction of the largest |Ω| of the near-zero speed band.
pub(crate) const NEAR_ZERO_FRACTION: f64 = 0.1;

/// Fraction of the largest |voltage| under which the voltage is taken as off.
pub(crate) const VOLTAGE_OFF_FRACTION: f64 = 0.02;

/// Relative tolerance of "settled" on the final value.
pub(crate) const SETTLED_FRACTION: f64 = 0.02;

/// Fraction of unsettled samples a steady state may hold.
pub(crate) const UNSETTLED_FRACTION: f64 = 0.01;

/// The peak neighbourhood: current above this fraction of the way from final to peak value.
pub(crate) const PEAK_LEVEL: f64 = 0.8;

/// Overshoot (relative to the final current) that makes a current peak.
pub(crate) const PEAK_FRACTION: f64 = 0.1;

/// Largest harmonic frequency, in cycles per sample, at which a sample enters the angle-ripple
/// regression of that harmonic (0.4: below Nyquist with a margin; above it a ripple in
/// the angle cannot be told from the aliased pattern of the encoder's counts).
pub(crate) const RIPPLE_NYQUIST: f64 = 0.4;

/// Revolutions its samples must travel for a harmonic to be fitted (ripple locked to the
/// rotation repeats; a transient gap over part of a turn does not).
pub(crate) const MIN_RIPPLE_REVOLUTIONS: f64 = 8.0;

/// Samples needed for the regression of one harmonic.
pub(crate) const MIN_RIPPLE_SAMPLES: usize = 64;

/// Half-width of the moving average of speed and current for the phases \[samples\].
pub(crate) const PHASE_SMOOTHING: usize = 2;

/// Samples needed in a channel.
pub(crate) const MIN_SAMPLES: usize = 32;

/// The quantum of values that are multiples of one step up to rounding (differences of
/// quantised angles, central differences of counts): [`detect_quantum`] of the values rounded to
/// 1e-9 of their largest magnitude.
pub(crate) fn quantum_of(x: &[f64]) -> Option<f64> {
    let grid = 1e-9 * x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if grid.is_nan() || grid <= 0.0 {
        return None;
    }
    let rounded: Vec<f64> = x.iter().map(|v| (v / grid).round() * grid).collect();
    detect_quantum(&rounded)
}

/// The noise of `y` from the median of its second differences' magnitudes: `median|Δ²y|`
/// over `0.6745 √6` (Gaussian noise σ gives second differences of deviation `√6 σ`, whose
/// median magnitude is 0.6745 of it). 0 for a signal that holds its value in most windows
/// of three samples (a quantiser without noise).
pub(crate) fn median_noise(y: &[f64]) -> f64 {
    let mut d2: Vec<f64> = y.windows(3).map(|w| second_difference(w).abs()).collect();
    if d2.is_empty() {
        return 0.0;
    }
    let mid = d2.len() / 2;
    let (_, median, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    *median / (0.6745 * 6f64.sqrt())
}

/// Per-sample floor: expected `r²` and the variance of `r²`, zero at the samples left out.
pub(crate) struct FloorModel {
    pub(crate) v: Vec<f64>,
    pub(crate) w: Vec<f64>,
    /// Samples in the tests (not at an ADC rail).
    pub(crate) keep: Vec<bool>,
    pub(crate) report: NoiseFloor,
}

/// Samples whose model value is within three floor deviations of an ADC rail of the measured
/// column `y` (an extreme value held by at least [`RAIL_FRACTION`] of its samples): the rail
/// clips the noise there (half of it reads the rail), so neither the floor nor the residual's
/// mean hold. `false` marks a sample left out.
pub(crate) fn off_rails(y: &[f64], model: &[f64], sigma: f64) -> Vec<bool> {
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let held = |rail: f64| {
        y.iter().filter(|&&v| v == rail).count() as f64 >= RAIL_FRACTION * y.len() as f64
    };
    let (low, high) = (held(lo), held(hi));
    model
        .iter()
        .map(|&m| !((low && m <= lo + 3.0 * sigma) || (high && m >= hi - 3.0 * sigma)))
        .collect()
}

/// Pooled scatter about a line of the flat blocks of `y` (a block is flat when its fitted
/// trend across the block is within two residual standard deviations), leaving out blocks
/// whose scatter is more than [`SCATTER_OUTLIER`] times the median block's: a block holding a
/// transient shorter than itself (a current spike a few samples long when L/R is below the
/// sample period, at each switch of a square wave) has almost no trend and a scatter set by
/// the spike, and a few of them pooled with the quiet blocks made the floor of a 0.6 mA noise
/// 0.11 A.
pub(crate) fn steady_scatter(y: &[f64]) -> Option<f64> {
    let b = SCATTER_BLOCK;
    let xm = (b as f64 - 1.0) / 2.0;
    let sxx: f64 = (0..b).map(|i| (i as f64 - xm).powi(2)).sum();
    let mut flat: Vec<f64> = Vec::new();
    for block in y.chunks_exact(b) {
        let ym = block.iter().sum::<f64>() / b as f64;
        let (syy, sxy) = block
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(syy, sxy), (i, &v)| {
                (syy + (v - ym).powi(2), sxy + (i as f64 - xm) * (v - ym))
            });
        let slope = sxy / sxx;
        let rss = (syy - slope * sxy).max(0.0);
        let s = (rss / (b - 2) as f64).sqrt();
        if s > 0.0 && slope.abs() * b as f64 <= 2.0 * s {
            flat.push(rss);
        }
    }
    if flat.len() < MIN_FLAT_BLOCKS {
        return None;
    }
    flat.sort_by(f64::total_cmp);
    let median = flat[flat.len() / 2];
    let kept: Vec<f64> = flat
        .into_iter()
        .filter(|&rss| rss <= SCATTER_OUTLIER * SCATTER_OUTLIER * median)
        .collect();
    (kept.len() >= MIN_FLAT_BLOCKS)
        .then(|| (kept.iter().sum::<f64>() / (kept.len() * (b - 2)) as f64).sqrt())
}

/// A white floor of deviation `sigma` given by the caller.
pub(crate) fn given_floor_model(ch: &ResidualChannel, sigma: f64, y_ss: f64) -> FloorModel {
    let n = ch.measured.len();
    let v = vec![sigma * sigma; n];
    let report = NoiseFloor {
        sigma,
        source: FloorSource::Given,
        steady_scatter: steady_scatter(ch.measured),
        second_difference: noise_std(ch.measured),
        adc_step: detect_quantum(ch.measured),
        encoder_step_rad: None,
        nrmse_floor: if y_ss > 0.0 {
            sigma * (n as f64).sqrt() / y_ss.sqrt()
        } else {
            f64::INFINITY
        },
        rail_samples: 0,
        undithered: false,
    };
    FloorModel {
        w: vec![2.0 * sigma.powi(4); n],
        v,
        keep: vec![true; n],
        report,
    }
}

pub(crate) fn floor_model(
    rec: &ResidualRecord,
    ch: &ResidualChannel,
    y_ss: f64,
    dithered_steps: f64,
) -> FloorModel {
    let y = ch.measured;
    let n = y.len();
    let second_difference = noise_std(y);
    let median_difference = median_noise(y);
    let steady = steady_scatter(y);
    // Where the values are too many to show the step, their differences can (a 14-bit
    // record): looked for only where it matters, for `dithered_steps`.
    let adc_step = detect_quantum(y).or_else(|| {
        (dithered_steps > 0.0)
            .then(|| {
                let differences: Vec<f64> = y.windows(2).map(|w| w[1] - w[0]).collect();
                quantum_of(&differences)
            })
            .flatten()
    });
    let nrmse_floor = |v: &[f64]| {
        let s = v.iter().sum::<f64>().sqrt();
        if y_ss > 0.0 {
            s / y_ss.sqrt()
        } else {
            f64::INFINITY
        }
    };
    if ch.kind == Channel::EncoderSpeed {
        let from_angle = rec.angle.and_then(|th| {
            let steps: Vec<f64> = th.windows(2).map(|w| w[1] - w[0]).collect();
            quantum_of(&steps)
        });
        let q_s = from_angle
            .map(|q| q / (2.0 * rec.dt))
            .or_else(|| quantum_of(y));
        if let Some(q) = q_s {
            let (v, w): (Vec<f64>, Vec<f64>) = ch
                .model
                .iter()
                .map(|m| {
                    let m = m.abs() / q;
                    let f = m - m.floor();
                    let g = (f * (1.0 - f)).max(ENCODER_G_MIN);
                    let v = q * q * g;
                    (v, (q.powi(4) * g * (1.0 - 4.0 * g)).max(0.5 * v * v))
                })
                .unzip();
            let sigma = (v.iter().sum::<f64>() / n as f64).sqrt();
            let report = NoiseFloor {
                sigma,
                source: FloorSource::EncoderCount,
                steady_scatter: steady,
                second_difference,
                adc_step: None,
                encoder_step_rad: Some(2.0 * rec.dt * q),
                nrmse_floor: nrmse_floor(&v),
                rail_samples: 0,
                undithered: false,
            };
            return FloorModel {
                v,
                w,
                keep: vec![true; n],
                report,
            };
        }
    }
    // Each noise estimate can only take some signal for noise, never the reverse: the RMS
    // second difference a fast signal's curvature (a noise-free 14-bit current of a 1 ms τe
    // at 6 kHz read several steps of "noise"), the flat stretches a staircase's transients
    // (9 steps on a noise-free 10-bit one), the median second difference (robust to the
    // few samples of a PRBS's switches) the least. The smallest is the noise.
    let undithered = dithered_steps > 0.0
        && adc_step.is_some_and(|q| {
            let measured_noise = steady
                .unwrap_or(f64::INFINITY)
                .min(second_difference)
                .min(median_difference);
            measured_noise < dithered_steps * q
        });
    // A quantiser the noise does not dither errs by up to half a step, held as long as the
    // signal stays within one code: its floor is that bound.
    let adc = adc_step.map(|q| {
        if undithered {
            0.5 * q
        } else {
            q / 12f64.sqrt()
        }
    });
    // The floor: the smaller of the RMS and the median second difference's noise, raised to
    // the steady-state scatter (which sees the low frequencies of coloured noise that
    // differences remove) and to the ADC step's. A current spike of a few samples at each
    // switch (L/R below the sample period) makes the RMS second difference many times the
    // noise, while the median of a quantised record's second differences, which are whole
    // steps, rounds to a step (1.2 times the noise at one step of noise): each errs where
    // the other does not.
    let mut sigma = second_difference.min(median_difference);
    let mut source = FloorSource::SecondDifference;
    for (s, src) in [
        (steady, FloorSource::SteadyScatter),
        (adc, FloorSource::AdcStep),
    ] {
        if let Some(s) = s.filter(|&s| s > sigma) {
            sigma = s;
            source = src;
        }
    }
    let precision = PRECISION_FLOOR * (y_ss / n as f64).sqrt();
    if precision > sigma {
        sigma = precision;
        source = FloorSource::Precision;
    }
    let mut v = vec![sigma * sigma; n];
    let mut w = vec![2.0 * sigma.powi(4); n];
    let floor_of_all = nrmse_floor(&v);
    let keep = if adc_step.is_some() {
        off_rails(y, ch.model, sigma)
    } else {
        vec![true; n]
    };
    for ((v, w), &k) in v.iter_mut().zip(w.iter_mut()).zip(&keep) {
        if !k {
            (*v, *w) = (0.0, 0.0);
        }
    }
    let report = NoiseFloor {
        sigma,
        source,
        steady_scatter: steady,
        second_difference,
        adc_step,
        encoder_step_rad: None,
        nrmse_floor: floor_of_all,
        rail_samples: keep.iter().filter(|k| !**k).count(),
        undithered,
    };
    FloorModel { v, w, keep, report }
}

/// The correlation factor `1 + 2 Σₖ ρₖ²` of `x` over lags 1..=max_lag ([`autocorrelation`]):
/// how much correlation in time inflates the variance of a sum of squares of `x`.
pub(crate) fn correlation_factor(x: &[f64], max_lag: usize) -> f64 {
    factor_of(&autocorrelation(x, max_lag))
}

/// `1 + 2 Σₖ ρₖ²` of the autocorrelations `rho`.
pub(crate) fn factor_of(rho: &[f64]) -> f64 {
    1.0 + 2.0 * rho.iter().map(|p| p * p).sum::<f64>()
}

/// Autocorrelation of `x` (mean removed) at lags 1..=max_lag (biased estimator, as `resid`).
pub(crate) fn autocorrelation(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    let m = x.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = x.iter().map(|v| v - m).collect();
    let c0: f64 = d.iter().map(|v| v * v).sum();
    (1..=max_lag)
        .map(|k| {
            if k >= n || c0 <= 0.0 {
                return 0.0;
            }
            d[k..]
                .iter()
                .zip(&d[..n - k])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / c0
        })
        .collect()
}

/// Prefix sums of `r²`, `v`, `w`.
pub(crate) struct Prefix {
    pub(crate) a: Vec<f64>,
    pub(crate) b: Vec<f64>,
    pub(crate) w: Vec<f64>,
}

impl Prefix {
    pub(crate) fn new(r: &[f64], floor: &FloorModel) -> Self {
        let scan = |it: &mut dyn Iterator<Item = f64>| {
            let mut acc = 0.0;
            std::iter::once(0.0)
                .chain(it.map(|x| {
                    acc += x;
                    acc
                }))
                .collect::<Vec<f64>>()
        };
        Prefix {
            a: scan(&mut r.iter().map(|x| x * x)),
            b: scan(&mut floor.v.iter().copied()),
            w: scan(&mut floor.w.iter().copied()),
        }
    }

    pub(crate) fn sums(&self, start: usize, end: usize) -> (f64, f64, f64) {
        (
            self.a[end] - self.a[start],
            self.b[end] - self.b[start],
            self.w[end] - self.w[start],
        )
    }
}

/// The excess test of sums `A = Σ r²`, `B = Σ v`, `W = Σ w` over `samples` samples.
pub(crate) fn excess_test(
    (a, b, w): (f64, f64, f64),
    samples: usize,
    c: f64,
    alpha_test: f64,
) -> ExcessTest {
    if samples == 0 || b <= 0.0 || w <= 0.0 {
        return ExcessTest {
            samples,
            ratio: f64::NAN,
            chi_square: f64::NAN,
            dof: 0.0,
            p_value: 1.0,
            significant: false,
        };
    }
    let nu = 2.0 * b * b / (c * w);
    let scale = c * w / (2.0 * b);
    let chi_square = a / scale;
    let p_value = chi_square_sf(chi_square, nu);
    ExcessTest {
        samples,
        ratio: a / b,
        chi_square,
        dof: nu,
        p_value,
        significant: p_value < alpha_test,
    }
}
