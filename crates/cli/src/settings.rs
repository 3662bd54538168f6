//! Turns command-line text into validated, typed settings for the libraries.

use std::path::Path;

use anyhow::Result;
use motor_model::{
    Adc, Effect, Effects, Input, MeasurementModel, MotorParams, Range, SpeedSource, Trace,
};

use crate::args::{InitialStateArg, MeasurementArgs, MethodArg, SpeedFromArg};
use crate::errors::BadInput;

/// Longest settings file read (a motor, a start, a calibration): a few hundred bytes in use;
/// beyond this the path names something else (`/dev/zero` would be read for ever).
const MAX_SETTINGS_BYTES: u64 = 1 << 20;

/// The text of a small settings file at `path`, at most [`MAX_SETTINGS_BYTES`]; the error says
/// why it cannot be read (an I/O error, not UTF-8, too large).
pub fn read_settings_file(path: &Path) -> std::result::Result<String, String> {
    use std::io::Read;
    let file = crate::fifo::open_read(path).map_err(|e| e.to_string())?;
    let mut text = String::new();
    file.take(MAX_SETTINGS_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| e.to_string())?;
    if text.len() as u64 > MAX_SETTINGS_BYTES {
        return Err(format!(
            "more than {} bytes: not a settings file",
            MAX_SETTINGS_BYTES
        ));
    }
    Ok(text)
}

/// `paper` or a JSON file with keys R, L, k, f, J, Ts.
pub fn motor(spec: &str) -> Result<MotorParams> {
    if spec == "paper" {
        return Ok(MotorParams::paper());
    }
    let path = Path::new(spec);
    let text = read_settings_file(path).map_err(|e| {
        BadInput(format!(
            "--motor {spec}: cannot read the file ({e}); give `paper` or a JSON file with keys R, L, k, f, J, Ts"
        ))
    })?;
    let params: MotorParams = serde_json::from_str(&text).map_err(|e| {
        BadInput(format!(
            "{}: line {}, column {}: {e}; expected {{\"R\": ohm, \"L\": H, \"k\": N·m/A, \"f\": N·m·s/rad, \"J\": kg·m², \"Ts\": N·m}}",
            path.display(),
            e.line(),
            e.column()
        ))
    })?;
    params
        .validate()
        .map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    sane_motor(&params).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    Ok(params)
}

/// Smallest value of R, L, k, f, J accepted \[SI units\]: a micro-motor's inertia is about
/// 1e-9 kg·m² and its inductance 1e-6 H; below 1e-12 a value is a unit mistake, and the
/// derived constants (τe = L/R, ωn, …) lose all precision.
pub const PARAM_MIN_SI: f64 = 1e-12;
/// Largest value of R, L, k, f, J, Ts accepted \[SI units\]: far above any servomotor or
/// linear axis (the EMPS axis: 95 kg, 215 N·s/m); above it a value is a unit mistake, and
/// the products the models form (k², R·f, E/R) overflow into meaningless digits.
pub const PARAM_MAX_SI: f64 = 1e6;

/// Refuses parameters outside [`PARAM_MIN_SI`, `PARAM_MAX_SI`] (Ts: from zero), naming the
/// first one.
pub fn sane_motor(p: &MotorParams) -> std::result::Result<(), String> {
    let named = [
        ("R", p.r_ohm, "Ω"),
        ("L", p.l_henry, "H"),
        ("k", p.k_nm_per_a, "N·m/A"),
        ("f", p.f_nms_per_rad, "N·m·s/rad"),
        ("J", p.j_kgm2, "kg·m²"),
        ("Ts", p.ts_nm, "N·m"),
    ];
    for (name, value, unit) in named {
        // Ts may be zero (no dry friction) or as small as a fit leaves it.
        let min = if name == "Ts" { 0.0 } else { PARAM_MIN_SI };
        if !(min..=PARAM_MAX_SI).contains(&value) {
            return Err(format!(
                "{name} = {} {unit} is outside the range of physical motors this tool handles ({PARAM_MIN_SI:e} to {PARAM_MAX_SI:e} {unit}); check the units",
                shown(value)
            ));
        }
    }
    Ok(())
}

/// `v` as typed for ordinary magnitudes (`40`, `0.01`), in exponent form beyond them (`1e300`),
/// so that a message never echoes 300 digits.
pub fn shown(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Largest armature voltage accepted \[V\]: ten times a 10 kV traction motor; more is a typo
/// (`1e300`), and currents and speeds computed from it overflow into meaningless digits.
pub const MAX_VOLTS: f64 = 1e5;

/// A voltage \[V\] of `option`: finite and at most [`MAX_VOLTS`] in magnitude.
pub fn volts(option: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v.abs() <= MAX_VOLTS {
        Ok(v)
    } else {
        Err(BadInput(format!(
            "{option} {}: expected a voltage between -{MAX_VOLTS:e} and {MAX_VOLTS:e} V",
            shown(v)
        ))
        .into())
    }
}

/// A length of time \[s\] of `option`: finite and greater than zero.
pub fn duration(option: &str, s: f64) -> Result<f64> {
    positive(option, s, "a record length greater than 0 s")
}

/// A sample rate \[Hz\] of `option`: finite and greater than zero.
pub fn rate(option: &str, hz: f64) -> Result<f64> {
    positive(option, hz, "a sample rate greater than 0 Hz")
}

/// `v` of `option` if finite and greater than zero; else the bad-input line saying that
/// `expected` was.
fn positive(option: &str, v: f64, expected: &str) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(BadInput(format!("{option} {}: expected {expected}", shown(v))).into())
    }
}

/// Validated `--duration` \[s\] and `--rate` \[Hz\] of a simulated record, refused before anything
/// is allocated when the record would exceed [`motor_model::MAX_SAMPLES`].
pub fn record_grid(duration_s: f64, rate_hz: f64) -> Result<(f64, f64)> {
    let duration_s = duration("--duration", duration_s)?;
    let rate_hz = rate("--rate", rate_hz)?;
    let samples = (duration_s * rate_hz).floor() + 1.0;
    if samples > motor_model::MAX_SAMPLES as f64 {
        // The largest whole rate that fits, when there is one (a rate rounded down to 0 Hz
        // would be refused in turn).
        let fitting = (motor_model::MAX_SAMPLES - 1) as f64;
        let lower_rate = (fitting / duration_s).floor();
        let advice = if lower_rate >= 1.0 {
            format!(" or lower the rate (e.g. --rate {lower_rate})")
        } else {
            String::new()
        };
        return Err(BadInput(format!(
            "--duration {} at --rate {}: {} samples; at most {} fit in memory: shorten the record (at most --duration {} at this rate){advice}",
            shown(duration_s),
            shown(rate_hz),
            shown(samples),
            motor_model::MAX_SAMPLES,
            shown(fitting / rate_hz),
        ))
        .into());
    }
    Ok((duration_s, rate_hz))
}

/// A probability of `option`: a number in \[0, 1\].
pub fn probability(option: &str, p: f64) -> Result<f64> {
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(BadInput(format!(
            "{option}: {} is not a probability: expected a number from 0 to 1",
            shown(p)
        ))
        .into())
    }
}

/// ADC resolution \[bits\] of `option`: 1 to 24 (the paper's logger: 10).
pub fn adc_bits(option: &str, bits: u8) -> Result<Adc> {
    if (1..=24).contains(&bits) {
        Ok(Adc { bits })
    } else {
        Err(BadInput(format!("{option} {bits}: expected 1 to 24 bits")).into())
    }
}

/// The step voltage `volts` of `option` for `motor` recorded for `duration_s` \[s\]: sane
/// ([`volts`]), and high enough for the rotor to break away within the record, Eq. (11):
/// `|E| > R Ts/k` and `t0 = −τe ln(1 − R Ts/(k E)) < duration`.
pub fn breakaway_step(
    option: &str,
    motor: &MotorParams,
    volts_v: f64,
    duration_s: f64,
) -> Result<f64> {
    let volts_v = volts(option, volts_v)?;
    let threshold = motor.r_ohm * motor.ts_nm / motor.k_nm_per_a;
    match motor_model::breakaway_time(motor, volts_v) {
        None => Err(BadInput(format!(
            "{option} {}: the rotor never breaks away: this motor needs |E| > R·Ts/k = {threshold:.4} V (Eq. (11)); raise the step voltage",
            shown(volts_v)
        ))
        .into()),
        Some(t0) if t0 >= duration_s => Err(BadInput(format!(
            "{option} {}: the rotor breaks away only at t0 = {t0:.3} s (Eq. (11)), after the {duration_s} s record ends; raise the step voltage above R·Ts/k = {threshold:.4} V or lengthen --duration",
            shown(volts_v)
        ))
        .into()),
        Some(_) => Ok(volts_v),
    }
}

/// How the simulated logger of `montecarlo`, `fleet` and `demo` records a step test.
#[derive(Debug, Clone, Copy)]
pub struct Logger {
    /// Record length \[s\].
    pub duration_s: f64,
    /// Sample rate \[Hz\].
    pub rate_hz: f64,
    /// ADC resolution \[bits\].
    pub adc_bits: u8,
    /// Noise on the analog channels \[LSB\].
    pub noise_lsb: f64,
    /// Encoder counts per revolution.
    pub encoder_cpr: u32,
}

impl Logger {
    /// The paper's logger ([`MeasurementModel::paper_logger`]: 10-bit ADC, 1 LSB of noise,
    /// 2000-count encoder) recording `duration_s` \[s\] at `rate_hz` \[Hz\].
    pub fn paper(duration_s: f64, rate_hz: f64) -> Logger {
        Logger {
            duration_s,
            rate_hz,
            adc_bits: 10,
            noise_lsb: 1.0,
            encoder_cpr: 2000,
        }
    }

    /// A logger from its options, each checked: `--duration` and `--rate` ([`record_grid`]),
    /// `--adc-bits` 1–24, `--noise-lsb` ≥ 0, `--encoder-cpr` > 0.
    pub fn new(
        duration_s: f64,
        rate_hz: f64,
        adc_bits_n: u8,
        noise_lsb: f64,
        encoder_cpr: u32,
    ) -> Result<Logger> {
        let (duration_s, rate_hz) = record_grid(duration_s, rate_hz)?;
        let adc = adc_bits("--adc-bits", adc_bits_n)?;
        if !(noise_lsb.is_finite() && noise_lsb >= 0.0) {
            return Err(BadInput(format!(
                "--noise-lsb {}: expected zero or more LSBs",
                shown(noise_lsb)
            ))
            .into());
        }
        if encoder_cpr == 0 {
            return Err(BadInput(
                "--encoder-cpr 0: expected a positive count per revolution".into(),
            )
            .into());
        }
        Ok(Logger {
            duration_s,
            rate_hz,
            adc_bits: adc.bits,
            noise_lsb,
            encoder_cpr,
        })
    }
}

/// Two comma-separated numbers, e.g. `0.1,0.05`.
pub fn pair(option: &str, text: &str) -> Result<(f64, f64)> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let parsed: Vec<f64> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    match (parts.len(), parsed.as_slice()) {
        (2, [a, b]) if a.is_finite() && b.is_finite() => Ok((*a, *b)),
        _ => Err(BadInput(format!(
            "{option} {text}: expected two numbers separated by a comma, e.g. {option} 0.1,0.05"
        ))
        .into()),
    }
}

/// The input waveform options of `motorid simulate`.
#[derive(Debug, Clone, Copy)]
pub struct InputSpec<'a> {
    /// `--voltage`: a step \[V\] at `step_at`.
    pub voltage: Option<f64>,
    /// `--sine AMP,FREQ`.
    pub sine: Option<&'a str>,
    /// `--levels T:V,...`: a staircase.
    pub levels: Option<&'a str>,
    /// `--prbs VOLTS,BIT[,SEED]`: a PRBS from `step_at` to `duration`.
    pub prbs: Option<&'a str>,
    /// `--step-at` \[s\].
    pub step_at: f64,
    /// `--duration` \[s\].
    pub duration: f64,
    /// `--rate` \[Hz\]: a sine above half of it, or PRBS bits shorter than a sample, would
    /// alias.
    pub rate: f64,
}

/// The input waveform: a step of `--voltage` at `--step-at`, `--sine AMP,FREQ`, a staircase
/// `--levels T:V,...` or `--prbs VOLTS,BIT[,SEED]` (from `--step-at` on).
pub fn input(spec: InputSpec<'_>) -> Result<Input> {
    let given = [
        spec.voltage.is_some(),
        spec.sine.is_some(),
        spec.levels.is_some(),
        spec.prbs.is_some(),
    ];
    if given.iter().filter(|&&g| g).count() != 1 {
        return Err(BadInput(
            "give one input: --voltage VOLTS (a step), --sine AMP,FREQ, --levels T:V,... (a staircase) or --prbs VOLTS,BIT[,SEED]".into(),
        )
        .into());
    }
    let end = spec.duration;
    // A step or PRBS that starts at or after the end of the record would leave it all zeros.
    if (spec.voltage.is_some() || spec.prbs.is_some())
        && !(spec.step_at.is_finite() && spec.step_at >= 0.0 && spec.step_at < end)
    {
        return Err(BadInput(format!(
            "--step-at {}: expected an instant from 0 s to before the end of the {} s record (--duration); a later step leaves the record all zeros",
            shown(spec.step_at),
            shown(end)
        ))
        .into());
    }
    let input = if let Some(v) = spec.voltage {
        Input::step(volts("--voltage", v)?, spec.step_at)
    } else if let Some(s) = spec.sine {
        let (amp, freq) = pair("--sine", s)?;
        volts("--sine amplitude", amp)?;
        if freq > 0.5 * spec.rate {
            return Err(BadInput(format!(
                "--sine {s}: {} Hz is above half the sample rate ({} Hz): the record would alias it; raise --rate or lower the frequency",
                shown(freq),
                shown(0.5 * spec.rate)
            ))
            .into());
        }
        Input::sine(amp, freq)
    } else if let Some(text) = spec.levels {
        let steps = text
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|item| {
                item.split_once(':')
                    .and_then(|(t, v)| Some((t.trim().parse().ok()?, v.trim().parse().ok()?)))
                    .ok_or_else(|| {
                        BadInput(format!(
                            "--levels: `{item}` is not TIME:VOLTS, e.g. --levels 0.5:40,40:-20,80:0"
                        ))
                    })
            })
            .collect::<std::result::Result<Vec<(f64, f64)>, _>>()?;
        for &(_, v) in &steps {
            volts("--levels", v)?;
        }
        if let Some(&(first, _)) = steps.first().filter(|(t, _)| t.is_nan() || *t >= end) {
            return Err(BadInput(format!(
                "--levels: the first level starts at {} s, not before the end of the {} s record (--duration): the record would be all zeros",
                shown(first),
                shown(end)
            ))
            .into());
        }
        Input::piecewise(&steps)
    } else {
        let text = spec.prbs.unwrap_or_default();
        let parts: Vec<&str> = text.split(',').map(str::trim).collect();
        let number = |i: usize| parts.get(i).and_then(|p| p.parse::<f64>().ok());
        let seed = match parts.get(2) {
            None => Some(1),
            Some(p) => p.parse::<u64>().ok(),
        };
        match (parts.len(), number(0), number(1), seed) {
            (2 | 3, _, Some(bit), _) if bit < 1.0 / spec.rate => {
                return Err(BadInput(format!(
                    "--prbs {text}: a bit of {} s is shorter than the sample period {} s: bits would fall between samples; lengthen the bit or raise --rate",
                    shown(bit),
                    shown(1.0 / spec.rate)
                ))
                .into())
            }
            (2 | 3, Some(v), Some(bit), Some(seed)) => {
                Input::prbs(volts("--prbs", v)?, bit, spec.step_at, spec.duration, seed)
            }
            _ => {
                return Err(BadInput(format!(
                    "--prbs {text}: expected VOLTS,BIT_SECONDS[,SEED], e.g. --prbs 20,2,7"
                ))
                .into())
            }
        }
    };
    input.map_err(|e| BadInput(e.to_string()).into())
}

/// The `--effect` list.
pub fn effects(specs: &[String]) -> Result<Effects> {
    let mut set = Effects::none();
    for spec in specs {
        let effect: Effect = spec.parse().map_err(|e| match e {
            motor_model::ModelError::EffectSpec { reason, .. } => {
                BadInput(format!("--effect {spec}: {reason}"))
            }
            other => BadInput(format!("--effect {spec}: {other}")),
        })?;
        set = set.with(effect);
    }
    Ok(set)
}

fn range(option: &str, text: Option<&str>) -> Result<Option<Range>> {
    text.map(|t| {
        let (lo, hi) = pair(option, t)?;
        Range::new(lo, hi).map_err(|e| BadInput(format!("{option}: {e}")).into())
    })
    .transpose()
}

/// The measurement chain's options, checked: what `simulate` does to the trace once it is
/// known ([`MeasurementOptions::model`] fixes the ranges not given from it).
#[derive(Debug, Clone, Copy)]
pub struct MeasurementOptions {
    /// `--adc-bits`: the ADC of the analog channels, or exact values.
    pub adc: Option<Adc>,
    /// `--range-voltage` \[V\], `--range-current` \[A\], `--range-speed` \[rad/s\], where
    /// given.
    pub ranges: [Option<Range>; 3],
    /// `--noise-lsb`: white noise on every analog channel \[LSB of the ADC\].
    pub noise_lsb: Option<f64>,
    /// `--encoder-cpr`: counts per revolution, or the exact angle.
    pub encoder_cpr: Option<u32>,
    /// `--speed-from`: the source of the speed column.
    pub speed_source: SpeedSource,
    /// `--seed` of the noise.
    pub seed: u64,
}

impl MeasurementOptions {
    /// The options of `a`, each checked: `--adc-bits` 1–24, `--encoder-cpr` > 0, ranges
    /// `LO,HI` with `LO < HI`, `--noise-lsb` ≥ 0 and only with `--adc-bits`.
    pub fn from_args(a: &MeasurementArgs) -> Result<MeasurementOptions> {
        let adc = a
            .adc_bits
            .map(|bits| adc_bits("--adc-bits", bits))
            .transpose()?;
        if a.encoder_cpr == Some(0) {
            return Err(BadInput(
                "--encoder-cpr 0: expected a positive count per revolution".into(),
            )
            .into());
        }
        let ranges = [
            range("--range-voltage", a.range_voltage.as_deref())?,
            range("--range-current", a.range_current.as_deref())?,
            range("--range-speed", a.range_speed.as_deref())?,
        ];
        match (a.noise_lsb, adc) {
            (Some(lsb), _) if !(lsb.is_finite() && lsb >= 0.0) => {
                return Err(
                    BadInput(format!("--noise-lsb {lsb}: expected zero or more LSBs")).into(),
                )
            }
            (Some(_), None) => {
                return Err(
                    BadInput("--noise-lsb needs --adc-bits (the LSB is the ADC's)".into()).into(),
                )
            }
            _ => {}
        }
        Ok(MeasurementOptions {
            adc,
            ranges,
            noise_lsb: a.noise_lsb,
            encoder_cpr: a.encoder_cpr,
            speed_source: match a.speed_from {
                SpeedFromArg::Tacho => SpeedSource::Tacho,
                SpeedFromArg::Encoder => SpeedSource::Encoder,
                SpeedFromArg::None => SpeedSource::Omit,
            },
            seed: a.seed,
        })
    }

    /// The measurement chain with ranges fixed for `trace` (a range not given covers the
    /// signal with 20 % headroom; noise given in LSBs is converted to SI per channel).
    pub fn model(&self, trace: &Trace) -> MeasurementModel {
        let signals = [&trace.voltage, &trace.current, &trace.speed];
        let ranges: [Range; 3] =
            std::array::from_fn(|i| self.ranges[i].unwrap_or_else(|| Range::covering(signals[i])));
        let noise_std = match (self.noise_lsb, self.adc) {
            (Some(lsb), Some(adc)) => ranges.map(|r| lsb * adc.lsb(r)),
            _ => [0.0; 3],
        };
        MeasurementModel {
            adc: self.adc,
            ranges: ranges.map(Some),
            noise_std,
            encoder_counts_per_rev: self.encoder_cpr,
            speed_source: self.speed_source,
            seed: self.seed,
        }
    }
}

/// The initial state `--initial-state` forces, `None` for `auto` (detected per record).
pub fn initial_state(arg: InitialStateArg) -> Option<fit::InitialState> {
    match arg {
        InitialStateArg::Auto => None,
        InitialStateArg::Rest => Some(fit::InitialState::Rest),
        InitialStateArg::Steady => Some(fit::InitialState::Steady),
        InitialStateArg::Free => Some(fit::InitialState::Free),
    }
}

/// The library's step-pair method for `--method`.
pub fn step_method(method: MethodArg) -> fit::StepMethod {
    match method {
        MethodArg::Paper => fit::StepMethod::Paper,
        MethodArg::Full => fit::StepMethod::Full,
    }
}
