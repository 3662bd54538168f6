//! One channel localised: its excess by phase, window, operating band and trend, its spectrum,
//! its ripple over shaft angle, its whiteness and its cross-correlation with the input.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

use crate::diagnose::localise::floor::{
    autocorrelation, excess_test, factor_of, floor_model, given_floor_model, FloorModel, Prefix,
    MIN_RIPPLE_REVOLUTIONS, MIN_RIPPLE_SAMPLES, NEAR_ZERO_FRACTION, RIPPLE_NYQUIST, Z_99,
};
use crate::diagnose::localise::types::{
    AngleRipple, Band, Bands, ChannelLocalisation, CrossCorrelation, LocaliseSettings, Phase,
    PhaseExcess, ResidualChannel, ResidualRecord, SpectralPeak, Spectrum, Trend, Whiteness,
    WindowExcess,
};
use crate::estimation::records::Channel;
use crate::estimation::stats::{chi_square_sf, f_sf, normal_sf, NeweyWest};

pub(crate) fn localise_channel(
    rec: &ResidualRecord,
    ch: &ResidualChannel,
    given_floor: Option<f64>,
    phases: &[Phase],
    settings: &LocaliseSettings,
    family_alpha: f64,
    planner: &mut FftPlanner<f64>,
) -> ChannelLocalisation {
    let y = ch.measured;
    let n = y.len();
    let r: Vec<f64> = y.iter().zip(ch.model).map(|(a, b)| a - b).collect();
    let y_mean = y.iter().sum::<f64>() / n as f64;
    let y_ss: f64 = y.iter().map(|v| (v - y_mean).powi(2)).sum();
    let r_ss: f64 = r.iter().map(|v| v * v).sum();
    let nrmse = if y_ss > 0.0 {
        (r_ss / y_ss).sqrt()
    } else {
        f64::INFINITY
    };
    let floor = match given_floor {
        Some(sigma) => given_floor_model(ch, sigma, y_ss),
        None => floor_model(rec, ch, y_ss, settings.dithered_steps),
    };
    let full_residual = r;
    // The residual of the tests: zero at the samples left out.
    let r: Vec<f64> = full_residual
        .iter()
        .zip(&floor.keep)
        .map(|(&r, &k)| if k { r } else { 0.0 })
        .collect();
    let rho = autocorrelation(&r, settings.max_lag.min(n - 1));
    let c = factor_of(&rho);
    let prefix = Prefix::new(&r, &floor);
    let overall = excess_test(prefix.sums(0, n), n, c, family_alpha);
    // Tests of the residual's pattern (spectrum, whiteness, input correlation, ripple) need an
    // error that is noise: not an encoder's counts, nor a quantiser whose noise does not yet
    // dither it (module docs).
    let pattern_tested = ch.kind != Channel::EncoderSpeed && floor.report.patterns_testable();

    let phase_alpha = family_alpha / phases.len().max(1) as f64;
    let phase_stats = phases
        .iter()
        .map(|ph| {
            let seg = &full_residual[ph.start..ph.end];
            let len = seg.len().max(1) as f64;
            PhaseExcess {
                phase: *ph,
                rms_residual: (seg.iter().map(|v| v * v).sum::<f64>() / len).sqrt(),
                mean_residual: seg.iter().sum::<f64>() / len,
                test: excess_test(prefix.sums(ph.start, ph.end), seg.len(), c, phase_alpha),
            }
        })
        .collect();

    let windows = top_windows(&prefix, n, rec.dt, c, settings, family_alpha);
    let speed_bands =
        operating_variable(rec, ch, &[Channel::Speed, Channel::EncoderSpeed], rec.speed)
            .map(|s| bands(&r, &floor, s, "speed", true, c, settings, family_alpha));
    let current_bands = operating_variable(rec, ch, &[Channel::Current], rec.current)
        .map(|s| bands(&r, &floor, s, "current", false, c, settings, family_alpha));
    let sigma2 = floor.report.sigma.powi(2);
    let spectrum = welch(
        &r,
        rec.dt,
        sigma2,
        pattern_tested,
        settings,
        family_alpha,
        planner,
    );
    let angle_ripple = rec
        .angle
        .and_then(|th| angle_ripple(&r, th, settings.max_harmonic, pattern_tested, family_alpha));
    let whiteness = whiteness(&rho, n, pattern_tested, family_alpha);
    let cross_correlation = cross_correlation(
        &r,
        &rho,
        rec.voltage,
        settings.max_lag,
        pattern_tested,
        family_alpha,
    );
    ChannelLocalisation {
        channel: ch.kind,
        samples: n,
        nrmse,
        gap: nrmse - floor.report.nrmse_floor,
        floor: floor.report,
        overall,
        correlation_factor: c,
        phases: phase_stats,
        windows,
        speed_bands,
        current_bands,
        spectrum,
        angle_ripple,
        whiteness,
        cross_correlation,
    }
}

/// The operating variable of the bands of channel `ch`: the measured signal of another sensor
/// (its noise is independent of the channel's), but the model's prediction of the channel
/// itself (a channel's own measured value would select its own noise: the samples in the top
/// band of a measured current are those with positive noise); the model of a channel of
/// `kinds` when the record has no such signal.
pub(crate) fn operating_variable<'a>(
    rec: &ResidualRecord<'a>,
    ch: &ResidualChannel<'a>,
    kinds: &[Channel],
    measured: Option<&'a [f64]>,
) -> Option<&'a [f64]> {
    if kinds.contains(&ch.kind) {
        return Some(ch.model);
    }
    measured.or_else(|| {
        rec.channels
            .iter()
            .find(|c| kinds.contains(&c.kind))
            .map(|c| c.model)
    })
}

pub(crate) fn top_windows(
    prefix: &Prefix,
    n: usize,
    dt: f64,
    c: f64,
    settings: &LocaliseSettings,
    family_alpha: f64,
) -> Vec<WindowExcess> {
    let len = if settings.window_samples > 0 {
        settings.window_samples.min(n)
    } else {
        (n / 50).clamp(16, 1000).min(n)
    };
    let step = (len / 2).max(1);
    let starts: Vec<usize> = (0..=(n - len)).step_by(step).collect();
    let alpha_test = family_alpha / starts.len().max(1) as f64;
    let mut all: Vec<(usize, f64)> = starts
        .iter()
        .map(|&s| {
            let (a, b, _) = prefix.sums(s, s + len);
            (s, (a - b) / len as f64)
        })
        .collect();
    all.sort_by(|x, y| y.1.total_cmp(&x.1));
    let mut chosen: Vec<WindowExcess> = Vec::new();
    for (s, excess) in all {
        if chosen.len() >= settings.top_windows {
            break;
        }
        if chosen.iter().any(|w| s < w.end && w.start < s + len) {
            continue;
        }
        chosen.push(WindowExcess {
            start: s,
            end: s + len,
            t_start_s: s as f64 * dt,
            t_end_s: (s + len) as f64 * dt,
            excess,
            test: excess_test(prefix.sums(s, s + len), len, c, alpha_test),
        });
    }
    chosen
}

/// Sums of `r²`, `v`, `w` over `idx`.
pub(crate) fn sums_over(r: &[f64], floor: &FloorModel, idx: &[usize]) -> (f64, f64, f64) {
    idx.iter().fold((0.0, 0.0, 0.0), |(a, b, w), &i| {
        (a + r[i] * r[i], b + floor.v[i], w + floor.w[i])
    })
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn bands(
    r: &[f64],
    floor: &FloorModel,
    x: &[f64],
    variable: &'static str,
    near_zero_band: bool,
    c: f64,
    settings: &LocaliseSettings,
    family_alpha: f64,
) -> Bands {
    let ax: Vec<f64> = x.iter().map(|v| v.abs()).collect();
    let max = ax.iter().copied().fold(0.0, f64::max);
    let zero_limit = if near_zero_band {
        NEAR_ZERO_FRACTION * max
    } else {
        0.0
    };
    let width = (max - zero_limit) / settings.bands as f64;
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); settings.bands + 1];
    for (i, &v) in ax.iter().enumerate() {
        let slot = if near_zero_band && v <= zero_limit {
            0
        } else if width > 0.0 {
            1 + (((v - zero_limit) / width) as usize).min(settings.bands - 1)
        } else {
            1
        };
        members[slot].push(i);
    }
    let tests = members.iter().filter(|m| !m.is_empty()).count();
    let alpha_test = family_alpha / tests.max(1) as f64;
    let band = |k: usize, idx: &[usize]| Band {
        lo: if k == 0 {
            0.0
        } else {
            zero_limit + (k - 1) as f64 * width
        },
        hi: if k == 0 {
            zero_limit
        } else {
            zero_limit + k as f64 * width
        },
        test: excess_test(sums_over(r, floor, idx), idx.len(), c, alpha_test),
    };
    let near_zero = (near_zero_band && !members[0].is_empty()).then(|| band(0, &members[0]));
    let bands = (1..=settings.bands)
        .filter(|&k| !members[k].is_empty())
        .map(|k| band(k, &members[k]))
        .collect();
    // The trend over the samples in the tests, above the near-zero band (tested apart).
    let used: Vec<usize> = (0..r.len())
        .filter(|&i| floor.keep[i] && !(near_zero_band && ax[i] <= zero_limit))
        .collect();
    let excess: Vec<f64> = used.iter().map(|&i| r[i] * r[i] - floor.v[i]).collect();
    let at: Vec<f64> = used.iter().map(|&i| ax[i]).collect();
    let wt: Vec<f64> = used.iter().map(|&i| floor.w[i]).collect();
    let tested = floor.report.patterns_testable();
    let trend = floor_slope(&excess, &at, &wt, c).map(|(slope, t)| {
        let p_value = (2.0 * normal_sf(t.abs())).min(1.0);
        Trend {
            slope,
            t,
            p_value,
            tested,
            significant: tested && p_value < family_alpha,
        }
    });
    Bands {
        variable,
        near_zero,
        bands,
        trend,
    }
}

/// Least-squares slope of the excess `y` on `x` and its t statistic under the floor model:
/// `Var(slope) = c Σ (xᵢ − x̄)² wᵢ / Sxx²` with `wᵢ` the floor variance of `rᵢ²` and `c` the
/// effective-sample-size factor. The variance is the floor's, not estimated from the residuals:
/// a sandwich estimate is biased low exactly when a few high-leverage samples (a transient
/// among thousands of steady-state ones) happen to lie low, and then overstates |t|.
/// `None` when `x` is constant.
pub(crate) fn floor_slope(y: &[f64], x: &[f64], w: &[f64], c: f64) -> Option<(f64, f64)> {
    if y.len() < 2 {
        return None;
    }
    let n = y.len() as f64;
    let xm = x.iter().sum::<f64>() / n;
    let ym = y.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|v| (v - xm).powi(2)).sum();
    if sxx.is_nan() || sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - xm) * (b - ym)).sum();
    let slope = sxy / sxx;
    let var: f64 = c * x
        .iter()
        .zip(w)
        .map(|(a, w)| (a - xm).powi(2) * w)
        .sum::<f64>()
        / (sxx * sxx);
    (var > 0.0).then(|| (slope, slope / var.sqrt()))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn welch(
    r: &[f64],
    dt: f64,
    sigma2: f64,
    tested: bool,
    settings: &LocaliseSettings,
    family_alpha: f64,
    planner: &mut FftPlanner<f64>,
) -> Spectrum {
    let n = r.len();
    let len = (settings.welch_segment.min(n / 2).max(8) / 2) * 2;
    let hop = len / 2;
    let window: Vec<f64> = (0..len)
        .map(|j| 0.5 * (1.0 - (std::f64::consts::TAU * j as f64 / len as f64).cos()))
        .collect();
    let w2: f64 = window.iter().map(|w| w * w).sum();
    let rho_w: f64 = window[hop..]
        .iter()
        .zip(&window[..len - hop])
        .map(|(a, b)| a * b)
        .sum::<f64>()
        / w2;
    let fft = planner.plan_fft_forward(len);
    let mut power = vec![0.0; len / 2 + 1];
    let mut segments = 0usize;
    let mut buf = vec![Complex::new(0.0, 0.0); len];
    let mut start = 0;
    while start + len <= n {
        let seg = &r[start..start + len];
        let m = seg.iter().sum::<f64>() / len as f64;
        for ((b, x), w) in buf.iter_mut().zip(seg).zip(&window) {
            *b = Complex::new((x - m) * w, 0.0);
        }
        fft.process(&mut buf);
        for (p, b) in power.iter_mut().zip(&buf) {
            *p += b.norm_sqr();
        }
        segments += 1;
        start += hop;
    }
    let k = segments.max(1) as f64;
    let scale = 2.0 * dt / (w2 * k);
    let psd: Vec<f64> = power.iter().map(|p| p * scale).collect();
    let dof = 2.0 * k / (1.0 + 2.0 * (1.0 - 1.0 / k) * rho_w * rho_w);
    let floor_psd = 2.0 * sigma2 * dt;
    let bins = len / 2 - 1;
    let alpha_test = family_alpha / bins.max(1) as f64;
    let mut peaks: Vec<SpectralPeak> = (1..len / 2)
        .filter(|&i| psd[i] >= psd[i - 1] && psd[i] >= psd[i + 1])
        .map(|i| {
            let ratio = if floor_psd > 0.0 {
                psd[i] / floor_psd
            } else {
                f64::INFINITY
            };
            let p_value = chi_square_sf(dof * ratio, dof);
            SpectralPeak {
                frequency_hz: i as f64 / (len as f64 * dt),
                psd: psd[i],
                ratio,
                p_value,
                significant: tested && p_value < alpha_test,
            }
        })
        .collect();
    peaks.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    peaks.truncate(settings.spectrum_peaks);
    Spectrum {
        segment: len,
        dof,
        floor_psd,
        tested,
        peaks,
    }
}

/// Whether harmonic `N` at angle step `step` \[rad per sample\] is below [`RIPPLE_NYQUIST`].
pub(crate) fn below_nyquist(order: usize, step: f64) -> bool {
    order as f64 * step <= RIPPLE_NYQUIST * std::f64::consts::TAU
}

pub(crate) fn angle_ripple(
    r: &[f64],
    theta: &[f64],
    max_n: u32,
    tested: bool,
    family_alpha: f64,
) -> Option<AngleRipple> {
    let n = r.len();
    let (lo, hi) = theta
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    if hi - lo < std::f64::consts::TAU || n < MIN_RIPPLE_SAMPLES {
        return None;
    }
    // Angle step per sample at each sample (central difference).
    let step: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (theta[b] - theta[a]).abs() / (b - a) as f64
        })
        .collect();
    let m = max_n as usize;
    // Per N: count, Σr, Σr², Σs, Σc, Σss, Σcc, Σsc, Σrs, Σrc and the angle travelled over the
    // samples where N is below the Nyquist limit.
    let mut acc = vec![[0.0f64; 11]; m];
    for ((&ri, &th), &st) in r.iter().zip(theta).zip(&step) {
        let (s1, c1) = th.sin_cos();
        let (mut s, mut c) = (s1, c1);
        for (k, a) in acc.iter_mut().enumerate() {
            if !below_nyquist(k + 1, st) {
                break;
            }
            a[0] += 1.0;
            a[1] += ri;
            a[2] += ri * ri;
            a[3] += s;
            a[4] += c;
            a[5] += s * s;
            a[6] += c * c;
            a[7] += s * c;
            a[8] += ri * s;
            a[9] += ri * c;
            a[10] += st;
            (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
        }
    }
    let normal = |a: &[f64; 11]| Matrix3::new(a[0], a[3], a[4], a[3], a[5], a[7], a[4], a[7], a[6]);
    let mut best: Option<(usize, f64, Vector3<f64>)> = None;
    for (k, a) in acc.iter().enumerate() {
        let nk = a[0];
        if nk < MIN_RIPPLE_SAMPLES as f64 || a[10] < MIN_RIPPLE_REVOLUTIONS * std::f64::consts::TAU
        {
            continue;
        }
        let rhs = Vector3::new(a[1], a[8], a[9]);
        let Some(beta) = normal(a).try_inverse().map(|h| h * rhs) else {
            continue;
        };
        let rss0 = a[2] - a[1] * a[1] / nk;
        let rss1 = (a[2] - beta.dot(&rhs)).max(0.0);
        let f = if rss1 > 0.0 {
            ((rss0 - rss1) / 2.0) / (rss1 / (nk - 3.0))
        } else {
            f64::INFINITY
        };
        if best.as_ref().is_none_or(|b| f > b.1) {
            best = Some((k + 1, f, beta));
        }
    }
    let (order, f, beta) = best?;
    let a = &acc[order - 1];
    let h_inv = normal(a).try_inverse()?;
    let mut nw = NeweyWest::new(3, a[0] as usize);
    for ((&ri, &th), &st) in r.iter().zip(theta).zip(&step) {
        if !below_nyquist(order, st) {
            continue;
        }
        let (s, c) = (order as f64 * th).sin_cos();
        let e = ri - beta[0] - beta[1] * s - beta[2] * c;
        nw.push(&[e, s * e, c * e]);
    }
    let score = nw.finish()?;
    let score = Matrix3::from_iterator(score.iter().copied());
    let cov = h_inv * score * h_inv;
    let cov2 = Matrix2::new(cov[(1, 1)], cov[(1, 2)], cov[(2, 1)], cov[(2, 2)]);
    let b2 = Vector2::new(beta[1], beta[2]);
    let wald = cov2
        .try_inverse()
        .map_or(f64::INFINITY, |ci| b2.dot(&(ci * b2)));
    let p_value = (chi_square_sf(wald, 2.0) * f64::from(max_n)).min(1.0);
    Some(AngleRipple {
        periods_per_rev: order as u32,
        samples: a[0] as usize,
        amplitude: b2.norm(),
        phase_rad: beta[2].atan2(beta[1]),
        f_statistic: f,
        f_p_value: f_sf(f, 2.0, a[0] - 3.0),
        wald,
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    })
}

pub(crate) fn whiteness(rho: &[f64], n: usize, tested: bool, family_alpha: f64) -> Whiteness {
    let nf = n as f64;
    let bound99 = Z_99 / nf.sqrt();
    let q: f64 = rho
        .iter()
        .enumerate()
        .map(|(k, p)| p * p / (nf - (k + 1) as f64))
        .sum::<f64>()
        * nf
        * (nf + 2.0);
    let p_value = chi_square_sf(q, rho.len() as f64);
    Whiteness {
        autocorrelation: rho.to_vec(),
        bound99,
        outside: (1..=rho.len())
            .filter(|&k| rho[k - 1].abs() > bound99)
            .collect(),
        ljung_box_q: q,
        dof: rho.len(),
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    }
}

pub(crate) fn cross_correlation(
    r: &[f64],
    rho_r: &[f64],
    u: &[f64],
    max_lag: usize,
    tested: bool,
    family_alpha: f64,
) -> Option<CrossCorrelation> {
    // The input prewhitened by its first difference, aligned with the residual.
    let du: Vec<f64> = u.windows(2).map(|w| w[1] - w[0]).collect();
    let r = &r[1..];
    let u = &du[..];
    let n = r.len();
    let nf = n as f64;
    let mean = |x: &[f64]| x.iter().sum::<f64>() / nf;
    let (mr, mu) = (mean(r), mean(u));
    let e: Vec<f64> = r.iter().map(|v| v - mr).collect();
    let d: Vec<f64> = u.iter().map(|v| v - mu).collect();
    let se = e.iter().map(|v| v * v).sum::<f64>().sqrt();
    let su = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(se > 0.0 && su > 0.0) {
        return None;
    }
    let max_lag = max_lag.min(n - 1);
    let rho_u = autocorrelation(u, max_lag);
    let factor = (1.0 + 2.0 * rho_r.iter().zip(&rho_u).map(|(a, b)| a * b).sum::<f64>()).max(1.0);
    let sd = (factor / nf).sqrt();
    let lags: Vec<i64> = (-(max_lag as i64)..=max_lag as i64).collect();
    let values: Vec<f64> = lags
        .iter()
        .map(|&lag| {
            let k = lag.unsigned_abs() as usize;
            let s: f64 = if lag >= 0 {
                e[k..].iter().zip(&d[..n - k]).map(|(a, b)| a * b).sum()
            } else {
                d[k..].iter().zip(&e[..n - k]).map(|(a, b)| a * b).sum()
            };
            s / (se * su)
        })
        .collect();
    let max_ratio = values.iter().fold(0.0f64, |m, v| m.max(v.abs())) / sd;
    let p_value = (2.0 * normal_sf(max_ratio) * lags.len() as f64).min(1.0);
    let bound99 = Z_99 * sd;
    Some(CrossCorrelation {
        outside: lags
            .iter()
            .zip(&values)
            .filter(|(_, v)| v.abs() > bound99)
            .map(|(l, _)| *l)
            .collect(),
        lags,
        values,
        bound99,
        max_ratio,
        p_value,
        tested,
        significant: tested && p_value < family_alpha,
    })
}

/// Centred moving average of half-width `h`.
pub(crate) fn smooth(x: &[f64], h: usize) -> Vec<f64> {
    let n = x.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    let mut acc = 0.0;
    for v in x {
        acc += v;
        prefix.push(acc);
    }
    (0..n)
        .map(|i| {
            let lo = i.saturating_sub(h);
            let hi = (i + h + 1).min(n);
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

pub(crate) fn mean_of(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}
