//! Where the model disagrees with the records: the residual `r = y − ŷ` of every record and
//! channel against a noise floor estimated from the records themselves (SPEC section 7), located
//! in time, in operating region, in frequency and shaft angle, with the whiteness and input
//! cross-correlation that MATLAB's `resid` reports.
//!
//! # The floor model
//!
//! Every test compares the residual with what a perfect model would still leave: per sample `i`
//! a floor variance `vᵢ` (the expected `rᵢ²`) and the variance `wᵢ` of `rᵢ²` under that floor.
//!
//! - An analog channel (current, tachometer speed): `vᵢ = σ²` with `σ` the largest of
//!   the steady-state scatter (pooled line-fit scatter of the flat 32-sample blocks of the
//!   measured signal), the second-difference noise ([`crate::noise_std`]) and the ADC step
//!   `q/√12` (the quantum found from the values); `wᵢ = 2σ⁴` (Gaussian; conservative for the
//!   uniform error of a quantiser, whose `Var r² = 0.8 σ⁴`). The largest, so that a floor is
//!   never below what any of the three shows.
//! - An encoder speed (central difference of the counts, [`Channel::EncoderSpeed`](crate::Channel::EncoderSpeed)): the speed
//!   step `q_s = Δθ/(2 dt)` is found from the values (or from the angle). With the model moving
//!   `mᵢ = |ŷᵢ|/q_s` speed steps, the measured difference is one of the two codes around `mᵢ`,
//!   so with `g = frac(m)(1 − frac(m))`: `vᵢ = q_s² g`, `wᵢ = q_s⁴ g (1 − 4g)` (exact for a
//!   smooth motion; `Δθ²/(24 dt²)` on average, 0 at rest). `g` is floored at 0.01 and `w` at
//!   `v²/2`.
//! - An analog channel's `σ` is at least [`PRECISION_FLOOR`] (1e-6) of its signal's RMS about
//!   its mean, the accuracy of the simulations and of six written digits
//!   ([`FloorSource::Precision`]); a channel at that floor (a record simulated without noise)
//!   has its pattern tests untested, as its error is the integrator's, not noise.
//!
//! The reported `σ_floor` is `√(mean vᵢ)` and the NRMSE floor `√(Σ vᵢ)/‖y − ȳ‖` (=
//! `σ_floor √n/‖y − ȳ‖`); the gap is NRMSE − floor.
//!
//! Samples that the model puts within `3σ` of an ADC rail of a quantised channel (an extreme
//! value held by at least 1 % of the samples: a current at rest on a unipolar channel) are left
//! out of the tests (not of the NRMSE): the rail clips half of the noise there.
//!
//! # The excess test
//!
//! Over a set `S` of samples (a phase, a window, a band, the whole channel), `A = Σ rᵢ²` is
//! compared with `B = Σ vᵢ`. Residual samples are correlated (the noise may be coloured, and a
//! gap itself is), so the variance of `A` is `c Σ wᵢ` with `c = 1 + 2 Σₖ ρₖ²` (`ρₖ` the
//! residual's autocorrelation at lags `1..=max_lag`: `Var Σ r² = 2 Σᵢⱼ Cov(rᵢ, rⱼ)²` for
//! Gaussian residuals). `A` is then a scaled chi-square (Satterthwaite): `A ~ s χ²_ν` with
//! `s = c W/(2B)`, `ν = 2B²/(c W)`; the p-value is `P(χ²_ν > A/s)`. With white noise and a
//! constant floor, `ν = n/c` is the effective sample size and `A/s = Σ r²/σ²`.
//!
//! # Where
//!
//! - Phases ([`PhaseKind`]) from the voltage levels ([`crate::voltage_input`]) and the measured
//!   speed and current; the windows of `n/50` samples (half-overlapping) with the largest mean
//!   excess `rᵢ² − vᵢ`.
//! - Bands of |Ω| (a near-zero band, |Ω| ≤ 10 % of the largest, then equal-width bands) and of
//!   |I|; the operating variable is the model's prediction for the channel itself and the
//!   other sensor's measurement otherwise (a channel's own measurement would select its own
//!   noise). Trends: the least-squares slope of `rᵢ² − vᵢ` on |x| with its t under the floor
//!   model.
//! - Welch spectrum of the residual against the floor's white density; harmonic regression on
//!   the shaft angle.
//! - Whiteness (autocorrelation with 99 % bounds, Ljung–Box) and cross-correlation with the
//!   input's first difference, as MATLAB's `resid`.
//!
//! # False alarms
//!
//! Each channel has eleven families of tests (whole channel, phases, windows, speed bands,
//! speed trend, current bands, current trend, spectrum, angle ripple, whiteness, input
//! cross-correlation). A test is *significant* when its p-value is below
//! `alpha / (11 × channels × tests in its family)` (Bonferroni), so that under the floor model
//! the probability of any significant finding in one call of [`localise`] is at most
//! [`LocaliseSettings::alpha`] (default 1 %). The tests are approximations (Satterthwaite,
//! Bartlett, Newey–West), checked on simulated records in `tests/localise.rs`.
//!
//! Tests whose null hypothesis the encoder's quantisation breaks are reported but not used as
//! evidence (`tested: false`): at constant speed the counts make a deterministic, periodic
//! error, neither white nor flat in spectrum, whose sidebands put a speed ripple at other N per
//! revolution. An encoder speed is judged on magnitudes only (whiteness, cross-correlation,
//! spectrum and angle ripple are reported untested). With
//! [`LocaliseSettings::dithered_steps`] so is an ADC channel whose noise is below that many of
//! its steps, and its floor is at least half a step: without noise a quantiser's error is a
//! deterministic sawtooth of the signal, held for as many samples as the signal stays within
//! one code (up to ±q/2 for seconds on a settled signal), neither white nor flat in spectrum,
//! and noise below a step or so dithers it only in part. On the paper's noise-free 10-bit step
//! pair the correct model's residual had Ljung–Box Q = 4·10⁵ and spectral peaks 15 times the
//! floor; at 0.3–0.5 LSB of noise the correct model of the small servo or of the paper's motor
//! was "not white" in every seed tried, at 1 LSB in 3 of 20 seeds of an 8-bit record. The
//! step is found from the values, or from their differences where the values are too many
//! to show it (a 14-bit record).

mod channel;
mod findings;
pub(crate) mod floor;
mod phases;
mod types;

pub use findings::{Finding, FindingKind};
pub use types::{
    AngleRipple, Band, Bands, ChannelLocalisation, CrossCorrelation, ExcessTest, FloorSource,
    Localisation, LocaliseSettings, NoiseFloor, Phase, PhaseExcess, PhaseKind, RecordLocalisation,
    ResidualChannel, ResidualRecord, SpectralPeak, Spectrum, Trend, Whiteness, WindowExcess,
    PRECISION_FLOOR,
};

use rustfft::FftPlanner;

use crate::diagnose::localise::channel::localise_channel;
use crate::diagnose::localise::floor::FAMILIES;
use crate::diagnose::localise::floor::MIN_SAMPLES;
use crate::diagnose::localise::phases::detect_phases;
use crate::error::FitError;

/// Localises the residual of every record and channel (see the module documentation for the
/// floor model, the tests and their false-alarm rate).
///
/// Errors: a setting out of range ([`FitError::InvalidSetting`]); a record whose period is not
/// positive, whose signals differ in length from its voltage, with non-finite samples or fewer
/// than 32 samples ([`FitError::BadData`]).
pub fn localise(
    records: &[ResidualRecord],
    settings: &LocaliseSettings,
) -> Result<Localisation, FitError> {
    localise_with_floors(records, &[], settings)
}

/// [`localise`] with the noise floor of some channels given: `floors[k][j]`, when present and
/// positive, is the floor deviation `σ` of channel `j` of record `k` (unit of the channel;
/// white, `vᵢ = σ²`, `wᵢ = 2σ⁴`, [`FloorSource::Given`]), for a residual whose floor the
/// measured signal cannot show (a filtered, decimated torque); the others are estimated as
/// [`localise`] does.
pub fn localise_with_floors(
    records: &[ResidualRecord],
    floors: &[Vec<f64>],
    settings: &LocaliseSettings,
) -> Result<Localisation, FitError> {
    check_settings(settings)?;
    for rec in records {
        check_record(rec)?;
    }
    let n_channels: usize = records.iter().map(|r| r.channels.len()).sum();
    let family_alpha = settings.alpha / (FAMILIES * n_channels.max(1) as f64);
    let mut planner = FftPlanner::new();
    let out = records
        .iter()
        .enumerate()
        .map(|(k, rec)| {
            let n = rec.voltage.len();
            let phases = detect_phases(rec, n);
            let channels = rec
                .channels
                .iter()
                .enumerate()
                .map(|(j, ch)| {
                    let given = floors
                        .get(k)
                        .and_then(|f| f.get(j))
                        .copied()
                        .filter(|s| s.is_finite() && *s > 0.0);
                    localise_channel(
                        rec,
                        ch,
                        given,
                        &phases,
                        settings,
                        family_alpha,
                        &mut planner,
                    )
                })
                .collect();
            RecordLocalisation {
                name: rec.name.to_string(),
                phases,
                channels,
            }
        })
        .collect();
    Ok(Localisation {
        settings: *settings,
        family_alpha,
        records: out,
    })
}

fn check_settings(s: &LocaliseSettings) -> Result<(), FitError> {
    let bad = |name: &'static str, value: f64, expected: &'static str| {
        Err(FitError::InvalidSetting {
            name,
            value,
            expected,
        })
    };
    if !(s.alpha > 0.0 && s.alpha < 1.0) {
        return bad("alpha", s.alpha, "a probability strictly between 0 and 1");
    }
    if s.max_lag == 0 {
        return bad("max_lag", 0.0, "at least 1 sample");
    }
    if s.bands == 0 {
        return bad("bands", 0.0, "at least 1 band");
    }
    if s.welch_segment < 8 {
        return bad(
            "welch_segment",
            s.welch_segment as f64,
            "at least 8 samples",
        );
    }
    if s.max_harmonic == 0 {
        return bad("max_harmonic", 0.0, "at least 1 period per revolution");
    }
    Ok(())
}

fn check_record(rec: &ResidualRecord) -> Result<(), FitError> {
    let n = rec.voltage.len();
    let bad = |series: String, reason: String| Err(FitError::BadData { series, reason });
    if !(rec.dt.is_finite() && rec.dt > 0.0) {
        return bad(
            format!("record {}", rec.name),
            format!("sample period {} s: expected a positive period", rec.dt),
        );
    }
    if n < MIN_SAMPLES {
        return bad(
            format!("record {}", rec.name),
            format!("{n} samples: at least {MIN_SAMPLES} are needed to localise a residual"),
        );
    }
    let mut series: Vec<(String, &[f64])> = vec![("voltage".to_string(), rec.voltage)];
    for (name, s) in [
        ("current", rec.current),
        ("speed", rec.speed),
        ("angle", rec.angle),
    ] {
        if let Some(s) = s {
            series.push((name.to_string(), s));
        }
    }
    for ch in &rec.channels {
        series.push((format!("measured {}", ch.kind.name()), ch.measured));
        series.push((format!("model {}", ch.kind.name()), ch.model));
    }
    for (name, s) in series {
        if s.len() != n {
            return bad(
                format!("record {}, {name}", rec.name),
                format!(
                    "{} samples where the voltage has {n}: the channels must align",
                    s.len()
                ),
            );
        }
        if let Some((i, v)) = s.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return bad(
                format!("record {}, {name}", rec.name),
                format!("sample {i} is {v}"),
            );
        }
    }
    Ok(())
}
