//! Turns command-line text into validated, typed settings for the libraries.

use std::path::Path;

use anyhow::Result;
use motor_model::{
    Adc, Effect, Effects, Input, MeasurementModel, MotorParams, Range, SpeedSource, Trace,
};

use crate::args::{MeasurementArgs, SpeedFromArg};
use crate::BadInput;

/// `paper` or a JSON file with keys R, L, k, f, J, Ts.
pub fn motor(spec: &str) -> Result<MotorParams> {
    if spec == "paper" {
        return Ok(MotorParams::paper());
    }
    let path = Path::new(spec);
    let text = std::fs::read_to_string(path).map_err(|e| {
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
    Ok(params)
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
    let input = if let Some(v) = spec.voltage {
        Input::step(v, spec.step_at)
    } else if let Some(s) = spec.sine {
        let (amp, freq) = pair("--sine", s)?;
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
            (2 | 3, Some(volts), Some(bit), Some(seed)) => {
                Input::prbs(volts, bit, spec.step_at, spec.duration, seed)
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
        let effect: Effect = spec
            .parse()
            .map_err(|e| BadInput(format!("--effect {e}")))?;
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

/// The measurement chain from its options, with ranges fixed for `trace` (a range not given
/// covers the signal with 20 % headroom; noise given in LSBs is converted to SI per channel).
pub fn measurement(a: &MeasurementArgs, trace: &Trace) -> Result<MeasurementModel> {
    let adc = a
        .adc_bits
        .map(|bits| {
            if (1..=24).contains(&bits) {
                Ok(Adc { bits })
            } else {
                Err(BadInput(format!(
                    "--adc-bits {bits}: expected 1 to 24 bits"
                )))
            }
        })
        .transpose()?;
    if a.encoder_cpr == Some(0) {
        return Err(
            BadInput("--encoder-cpr 0: expected a positive count per revolution".into()).into(),
        );
    }
    let given = [
        range("--range-voltage", a.range_voltage.as_deref())?,
        range("--range-current", a.range_current.as_deref())?,
        range("--range-speed", a.range_speed.as_deref())?,
    ];
    let signals = [&trace.voltage, &trace.current, &trace.speed];
    let ranges: [Range; 3] =
        std::array::from_fn(|i| given[i].unwrap_or_else(|| Range::covering(signals[i])));
    let noise_std = match (a.noise_lsb, adc) {
        (None, _) => [0.0; 3],
        (Some(lsb), _) if !(lsb.is_finite() && lsb >= 0.0) => {
            return Err(BadInput(format!("--noise-lsb {lsb}: expected zero or more LSBs")).into())
        }
        (Some(_), None) => {
            return Err(
                BadInput("--noise-lsb needs --adc-bits (the LSB is the ADC's)".into()).into(),
            )
        }
        (Some(lsb), Some(adc)) => ranges.map(|r| lsb * adc.lsb(r)),
    };
    Ok(MeasurementModel {
        adc,
        ranges: ranges.map(Some),
        noise_std,
        encoder_counts_per_rev: a.encoder_cpr,
        speed_source: match a.speed_from {
            SpeedFromArg::Tacho => SpeedSource::Tacho,
            SpeedFromArg::Encoder => SpeedSource::Encoder,
            SpeedFromArg::None => SpeedSource::Omit,
        },
        seed: a.seed,
    })
}
