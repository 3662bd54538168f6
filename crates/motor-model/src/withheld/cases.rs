//! The benchmark's cases: random motors, effects, magnitudes and loggers, and their records.

use serde::{Deserialize, Serialize};

use super::chain::{ChannelRanges, MeasurementSpec, NoiseFloors, NoiseSpec, SpeedSensor};
use super::forms::{withheld_effect_names, Form, PlantEffect};
use super::plant::simulate_plant;
use crate::derived::Derived;
use crate::error::ModelError;
use crate::measure::Record;
use crate::params::MotorParams;
use crate::rng::NoiseRng;
use crate::sim::input::Input;
use crate::sim::trace::Trace;
use crate::steady::steady_state;

/// Copper's temperature coefficient at 20 °C \[1/K\] (IEC 60028), the thermal cases' α.
const ALPHA_COPPER_PER_K: f64 = 0.00393;
/// Visibility targets are drawn log-uniformly in this range \[noise floors\]; the stored
/// visibility is the one computed on the final records (SPEC asks for 3–30).
const TARGET_VISIBILITY: (f64, f64) = (4.0, 25.0);
/// Stribeck exponent δ of the LuGre cases \[-\]: far from the Gaussian's 2, so that the
/// friction excess decays slowly, `exp(−√(|Ω|/Ωs))`.
const LUGRE_STRIBECK_EXPONENT: f64 = 0.5;
/// Range of a LuGre friction's presliding displacement `g(0)/σ0` as drawn \[rad\].
const LUGRE_PRESLIDING_RAD: (f64, f64) = (1e-3, 4e-3);
/// Magnitude corrections per effect (each one simulation of the case's records).
const CALIBRATION_ROUNDS: usize = 4;
/// A visibility within this factor of its target ends the calibration.
const CALIBRATION_TOLERANCE: f64 = 1.25;
/// Largest change of magnitude in one calibration round \[-\].
const MAX_ROUND_FACTOR: f64 = 10.0;
/// Share of the breakaway margin `k E_low/R − Ts` one effect may take (two effects together
/// stay below it, so the low step still turns) \[-\].
const MARGIN_SHARE: f64 = 0.45;
/// Shortest and longest sensor delay \[sample periods\] (a delay far below a sample period
/// hides in the first sample after a step, and would only slow the plant down).
const SENSOR_DELAY_SAMPLES: (f64, f64) = (0.1, 3.0);
/// Longest record \[s\] (SPEC issue 9: records of at most 5 s).
const MAX_RECORD_S: f64 = 5.0;

/// What a record is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordRole {
    /// The paper's high-voltage step (Sec. 2.4).
    HighStep,
    /// The low-voltage step, a few times the breakaway voltage `R Ts/k`.
    LowStep,
    /// Validation: a square wave of ±0.6 E_high reversing the motor six times (heats the
    /// winding, drives the current to twice the step's, crosses zero speed).
    Reversal,
    /// Validation: a slow staircase of six levels from just above breakaway to 0.9 E_high and
    /// back through a low-voltage reversal.
    Staircase,
}

/// One record of a case: its input and length and the logger's ranges for it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordSpec {
    /// What the record is for.
    pub role: RecordRole,
    /// The armature voltage applied (0 V during the pre-trigger samples).
    pub input: Input,
    /// Length \[s\].
    pub duration_s: f64,
    /// Conditioning ranges, set from the nominal motor's signals as an engineer sets gains.
    pub ranges: ChannelRanges,
}

/// One effect of a case with how visible it is alone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseEffect {
    /// The effect, its form and parameters.
    pub effect: PlantEffect,
    /// Largest RMS change it makes alone on any record's current or speed, in noise floors
    /// of that channel, from the true nominal motor ([`visibility`]) or, for a case sized on a
    /// gap measure ([`benchmark_case_with_gap`]), from the nominal model that measure fits
    /// (where it could be computed) \[-\].
    pub visibility: f64,
}

/// A benchmark case: the truth behind its records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseSpec {
    /// Position in the benchmark.
    pub index: usize,
    /// Seed of everything random in the case (noise included).
    pub seed: u64,
    /// The motor (Eq. (2)'s parameters).
    pub motor: MotorParams,
    /// Rated voltage = the high step \[V\].
    pub rated_voltage_v: f64,
    /// Effects present: none, one or two.
    pub effects: Vec<CaseEffect>,
    /// The logger.
    pub measurement: MeasurementSpec,
    /// The records, high step and low step first.
    pub records: Vec<RecordSpec>,
    /// Largest RMS change all effects together make on any record's current or speed, in
    /// noise floors, measured as [`CaseEffect::visibility`] is \[-\] (0 for `none`).
    pub visibility: f64,
}

/// A case's records as the diagnoser receives them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaseRecords {
    /// The high-voltage step.
    pub high: Record,
    /// The low-voltage step.
    pub low: Record,
    /// The validation records with their roles.
    pub validation: Vec<(RecordRole, Record)>,
}

impl CaseSpec {
    /// The SPEC section 5 names of the effects present, `["none"]` when there is none.
    pub fn truth(&self) -> Vec<&'static str> {
        if self.effects.is_empty() {
            vec!["none"]
        } else {
            self.effects.iter().map(|e| e.effect.name()).collect()
        }
    }

    /// The effects alone, without their visibility.
    pub fn plant_effects(&self) -> Vec<PlantEffect> {
        self.effects.iter().map(|e| e.effect).collect()
    }

    /// The plant traces of every record (noise-free, before the logger), with `effects`.
    pub fn traces_with(&self, effects: &[PlantEffect]) -> Result<Vec<Trace>, ModelError> {
        self.records
            .iter()
            .map(|r| {
                simulate_plant(
                    &self.motor,
                    effects,
                    &r.input,
                    r.duration_s,
                    self.measurement.rate_hz,
                )
            })
            .collect()
    }

    /// The noise floors of every record.
    pub fn floors(&self) -> Vec<NoiseFloors> {
        self.records
            .iter()
            .map(|r| self.measurement.floors(&r.ranges))
            .collect()
    }
}

/// Largest RMS difference of current or speed between `with` and `without`, record by record,
/// in noise floors.
pub fn visibility(with: &[Trace], without: &[Trace], floors: &[NoiseFloors]) -> f64 {
    let rms = |a: &[f64], b: &[f64]| {
        let n = a.len().min(b.len()).max(1);
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    with.iter()
        .zip(without)
        .zip(floors)
        .map(|((w, o), fl)| {
            (rms(&w.current, &o.current) / fl.current_a)
                .max(rms(&w.speed, &o.speed) / fl.speed_rad_s)
        })
        .fold(0.0, f64::max)
}

/// Uniform and log-uniform draws from the case's generator.
struct Draw(NoiseRng);

impl Draw {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.0.uniform()
    }
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.uniform(lo.ln(), hi.ln()).exp()
    }
    fn pick<T: Copy>(&mut self, items: &[T]) -> Option<T> {
        let j = (self.0.uniform() * items.len() as f64).ceil() as usize;
        items.get(j.saturating_sub(1)).copied()
    }
}

/// What each case contains: the effect names with their forms, in the benchmark's order.
///
/// For `n` cases: `n/8` `none`, `n/8` with two effects, the rest with one, cycling through the
/// seven effects; each effect's occurrences alternate the (a) and (b) forms. Shuffled by `seed`.
pub fn case_mix(seed: u64, n: usize) -> Vec<Vec<(&'static str, Form)>> {
    let n_none = n / 8;
    let n_pairs = n / 8;
    let n_single = n - n_none - n_pairs;
    let names = withheld_effect_names();
    let k = names.len().max(1);
    let name = |j: usize| names.get(j % k).copied().unwrap_or("none");
    let form = |occurrence: usize| {
        if occurrence % 2 == 1 {
            Form::OtherShape
        } else {
            Form::SameShape
        }
    };
    let mut mix: Vec<Vec<(&'static str, Form)>> = Vec::with_capacity(n);
    mix.extend((0..n_single).map(|j| vec![(name(j), form(j / k))]));
    mix.extend((0..n_none).map(|_| Vec::new()));
    mix.extend((0..n_pairs).map(|p| {
        let first = p % k;
        let second = (first + 1 + (p / k) % (k - 1).max(1)) % k;
        vec![(name(first), form(p + 1)), (name(second), form(p))]
    }));
    let mut rng = NoiseRng::new(seed ^ 0x5EED_CA5E);
    for j in (1..mix.len()).rev() {
        let pick = (rng.next_u64() % (j as u64 + 1)) as usize;
        mix.swap(j, pick);
    }
    mix
}

/// `n` benchmark cases from `seed` (see [`case_mix`] for the composition and
/// [`benchmark_case`] for each case).
pub fn benchmark_cases(seed: u64, n: usize) -> Result<Vec<CaseSpec>, ModelError> {
    let mix = case_mix(seed, n);
    mix.iter()
        .enumerate()
        .map(|(index, effects)| build_case(seed, index, effects, None))
        .collect()
}

/// How visible an effect stays, in noise floors, once the records' noise-free `traces` (one
/// per record of the case, with the effect) have been explained by the best nominal model that
/// can be found: a measure the caller supplies (this crate fits nothing), `None` when it
/// cannot be computed (the effect is then measured against the true motor, [`visibility`]).
pub type GapMeasure<'a> = &'a dyn Fn(&CaseSpec, &[Trace]) -> Option<f64>;

/// Case `index` of the `n` cases of `seed`, as [`benchmark_case`] draws it, with every
/// effect's magnitude calibrated on `gap` instead of on [`visibility`]: the effect is sized
/// so that what the nominal model cannot absorb (by shifting its six parameters and each
/// voltage jump within its sample period) reaches the drawn target. An effect the nominal
/// model absorbs whole is no gap between model and records: SPEC section 5 calls such records
/// `none`. The stored visibilities are `gap`'s, or [`visibility`]'s where `gap` returned
/// `None`.
pub fn benchmark_case_with_gap(
    seed: u64,
    index: usize,
    n: usize,
    gap: GapMeasure<'_>,
) -> Result<CaseSpec, ModelError> {
    case_at(seed, index, n, Some(gap))
}

/// Case `index` of the `n` cases of `seed`, built alone (so that a caller can build cases in
/// parallel); equal to `benchmark_cases(seed, n)[index]`.
pub fn benchmark_case(seed: u64, index: usize, n: usize) -> Result<CaseSpec, ModelError> {
    case_at(seed, index, n, None)
}

/// Case `index` of the `n` cases of `seed`, sized on `gap` or, without, on [`visibility`].
fn case_at(
    seed: u64,
    index: usize,
    n: usize,
    gap: Option<GapMeasure<'_>>,
) -> Result<CaseSpec, ModelError> {
    let mix = case_mix(seed, n);
    let effects = mix.get(index).ok_or_else(|| ModelError::InvalidSetting {
        name: "case index".into(),
        value: index as f64,
        expected: "an index below the number of cases",
    })?;
    build_case(seed, index, effects, gap)
}

/// The operating points an effect's first guess is sized from.
struct Operating {
    motor: MotorParams,
    e_low: f64,
    i_low: f64,
    w_low: f64,
    w_high: f64,
    i_peak: f64,
    dt: f64,
    reversal_s: f64,
    total_s: f64,
}

impl Operating {
    /// `k E_low/R − Ts` \[N·m\]: how far the low step's standstill torque exceeds Ts.
    fn torque_margin(&self) -> f64 {
        let p = &self.motor;
        p.k_nm_per_a * self.e_low / p.r_ohm - p.ts_nm
    }
    /// `E_low − R Ts/k` \[V\].
    fn voltage_margin(&self) -> f64 {
        let p = &self.motor;
        self.e_low - p.r_ohm * p.ts_nm / p.k_nm_per_a
    }
}

fn random_motor(d: &mut Draw) -> Result<(MotorParams, f64), ModelError> {
    // Size 0: a small servo; 1: the paper's motor (Sec. 4.1). Squared: most cases are servos.
    let size = d.uniform(0.0, 1.0).powi(2);
    let paper = MotorParams::paper();
    let servo = [
        d.log_uniform(2.0, 10.0),
        d.log_uniform(0.5e-3, 3e-3),
        d.log_uniform(0.01, 0.05),
        d.log_uniform(1e-6, 2e-5),
        d.log_uniform(1e-6, 1e-5),
        d.log_uniform(2e-4, 2e-3),
        d.log_uniform(6.0, 24.0),
    ];
    let big = [
        paper.r_ohm,
        paper.l_henry,
        paper.k_nm_per_a,
        paper.f_nms_per_rad,
        paper.j_kgm2,
        paper.ts_nm,
        40.0,
    ];
    let mut v = [0.0; 7];
    for (j, out) in v.iter_mut().enumerate() {
        let jitter = d.log_uniform(0.8, 1.25);
        *out = ((1.0 - size) * servo[j].ln() + size * (big[j] * jitter).ln()).exp();
    }
    let motor = MotorParams::new(v[0], v[1], v[2], v[3], v[4], v[5])?;
    Ok((motor, v[6]))
}

/// The slowest rate of the moving motor \[1/s\].
fn slowest_rate(p: &MotorParams) -> f64 {
    let d = Derived::new(p);
    if d.zeta > 1.0 {
        d.omega_n * d.omega_n / (d.sigma + d.omega_a)
    } else {
        d.sigma
    }
}

fn build_case(
    seed: u64,
    index: usize,
    wanted: &[(&'static str, Form)],
    gap: Option<GapMeasure<'_>>,
) -> Result<CaseSpec, ModelError> {
    let case_seed =
        NoiseRng::new(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)).next_u64();
    let mut d = Draw(NoiseRng::new(case_seed));
    let (motor, rated_voltage_v) = random_motor(&mut d)?;

    let rate_hz = d
        .pick(&[1000.0, 2000.0, 2500.0, 4000.0, 5000.0])
        .unwrap_or(1000.0);
    let pre_trigger_samples = d.pick(&[1usize, 5, 10, 20, 50]).unwrap_or(1);
    let adc_bits = d.pick(&[8u8, 10, 12, 14]).unwrap_or(10);
    let noise = NoiseSpec {
        lsb: d.uniform(0.0, 2.0),
        ar1_pole: if d.uniform(0.0, 1.0) < 0.5 {
            0.0
        } else {
            d.uniform(0.5, 0.95)
        },
    };
    let speed_sensor = if d.uniform(0.0, 1.0) < 0.7 {
        SpeedSensor::Encoder {
            counts_per_rev: d
                .pick(&[100, 256, 500, 1000, 2000, 4096, 5000])
                .unwrap_or(1000),
        }
    } else {
        SpeedSensor::Tachometer {
            noise_lsb: d.uniform(0.5, 3.0),
        }
    };
    let measurement = MeasurementSpec {
        adc_bits,
        rate_hz,
        pre_trigger_samples,
        noise,
        speed_sensor,
    };

    // The protocol: depends on the motor only, never on the effect.
    let dt = 1.0 / rate_hz;
    // The logger's clock is not synchronised with the step: it falls between two samples.
    let at = (pre_trigger_samples as f64 - 1.0 + d.uniform(0.1, 0.9)) * dt;
    let e_high = rated_voltage_v;
    let breakaway_v = motor.r_ohm * motor.ts_nm / motor.k_nm_per_a;
    let e_low = breakaway_v * d.uniform(2.0, 5.0);
    let lambda = slowest_rate(&motor);
    let step_s = (5.0 / lambda).clamp(0.1, MAX_RECORD_S - 0.5);
    let half_s = (2.0 / lambda).clamp(0.02, 0.75);
    let level_s = (2.0 / lambda).clamp(0.02, 0.75);
    let reversal_levels: Vec<(f64, f64)> = (0..6)
        .map(|j| {
            let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
            (at + j as f64 * half_s, sign * 0.6 * e_high)
        })
        .collect();
    let stair_volts = [
        1.5 * e_low,
        0.2 * e_high,
        0.5 * e_high,
        0.9 * e_high,
        0.3 * e_high,
        -1.5 * e_low,
    ];
    let stair_levels: Vec<(f64, f64)> = stair_volts
        .iter()
        .enumerate()
        .map(|(j, &v)| (at + j as f64 * level_s, v))
        .collect();
    let plans = [
        (RecordRole::HighStep, Input::step(e_high, at)?, at + step_s),
        (RecordRole::LowStep, Input::step(e_low, at)?, at + step_s),
        (
            RecordRole::Reversal,
            Input::piecewise(&reversal_levels)?,
            at + 6.0 * half_s,
        ),
        (
            RecordRole::Staircase,
            Input::piecewise(&stair_levels)?,
            at + 6.0 * level_s,
        ),
    ];
    let mut nominal = Vec::with_capacity(plans.len());
    let mut records = Vec::with_capacity(plans.len());
    for (role, input, duration_s) in plans {
        let trace = simulate_plant(&motor, &[], &input, duration_s, rate_hz)?;
        records.push(RecordSpec {
            role,
            input,
            duration_s,
            ranges: ChannelRanges::covering(&trace),
        });
        nominal.push(trace);
    }
    let mut case = CaseSpec {
        index,
        seed: case_seed,
        motor,
        rated_voltage_v,
        effects: Vec::new(),
        measurement,
        records,
        visibility: 0.0,
    };
    let floors = case.floors();
    let low = steady_state(&motor, e_low);
    let high = steady_state(&motor, e_high);
    let op = Operating {
        motor,
        e_low,
        i_low: low.current_a,
        w_low: low.speed_rad_s,
        w_high: high.speed_rad_s,
        i_peak: e_high / motor.r_ohm,
        dt,
        reversal_s: 6.0 * half_s,
        total_s: case.records.iter().map(|r| r.duration_s).sum(),
    };
    // How visible `effects` are: against the true motor, or what `gap` says is left.
    let seen_of = |case: &CaseSpec, effects: &[PlantEffect]| -> Result<f64, ModelError> {
        let traces = case.traces_with(effects)?;
        let plain = || visibility(&traces, &nominal, &floors);
        Ok(gap.and_then(|g| g(case, &traces)).unwrap_or_else(plain))
    };
    let mut calibrated = Vec::with_capacity(wanted.len());
    for &(name, form) in wanted {
        let first = first_guess(name, form, &op, &mut d)?;
        let target = d.log_uniform(TARGET_VISIBILITY.0, TARGET_VISIBILITY.1);
        let mut effect = limit(first, &op);
        let mut seen = seen_of(&case, &[effect])?;
        for _ in 0..CALIBRATION_ROUNDS {
            if seen > 0.0 && (seen / target).ln().abs() < CALIBRATION_TOLERANCE.ln() {
                break;
            }
            let factor = if seen > 0.0 {
                (target / seen).clamp(1.0 / MAX_ROUND_FACTOR, MAX_ROUND_FACTOR)
            } else {
                MAX_ROUND_FACTOR
            };
            let next = limit(effect.scaled(factor, &motor), &op);
            if next == effect {
                break;
            }
            effect = next;
            seen = seen_of(&case, &[effect])?;
        }
        calibrated.push(CaseEffect {
            effect,
            visibility: seen,
        });
    }
    case.visibility = match calibrated.as_slice() {
        [] => 0.0,
        [one] => one.visibility,
        many => {
            let effects: Vec<PlantEffect> = many.iter().map(|e| e.effect).collect();
            seen_of(&case, &effects)?
        }
    };
    case.effects = calibrated;
    Ok(case)
}

/// A first guess of the effect's parameters, sized from the operating points; the magnitude is
/// then calibrated, the shape parameters drawn here are kept.
fn first_guess(
    name: &str,
    form: Form,
    op: &Operating,
    d: &mut Draw,
) -> Result<PlantEffect, ModelError> {
    let p = &op.motor;
    let other = form == Form::OtherShape;
    let tau = std::f64::consts::TAU;
    let effect = match name {
        "stribeck_friction" => {
            let static_torque_nm = p.ts_nm + 0.3 * op.torque_margin();
            let stribeck_speed_rad_s = op.w_low.abs().max(1e-3) * d.uniform(0.2, 0.6);
            if other {
                let presliding_rad = d.uniform(LUGRE_PRESLIDING_RAD.0, LUGRE_PRESLIDING_RAD.1);
                let sigma0 = static_torque_nm / presliding_rad;
                PlantEffect::LuGre {
                    static_torque_nm,
                    stribeck_speed_rad_s,
                    stribeck_exponent: LUGRE_STRIBECK_EXPONENT,
                    bristle_stiffness_nm_per_rad: sigma0,
                    bristle_damping_nms_per_rad: d.uniform(0.3, 1.0)
                        * 2.0
                        * (sigma0 * p.j_kgm2).sqrt(),
                }
            } else {
                PlantEffect::StribeckGaussian {
                    static_torque_nm,
                    stribeck_speed_rad_s,
                }
            }
        }
        "cogging_torque" => {
            let amplitude_nm = 0.2 * op.torque_margin();
            let periods_per_rev = d.pick(&[4, 6, 8, 12, 16, 20, 24]).unwrap_or(6);
            let phase_rad = d.uniform(0.0, tau);
            if other {
                PlantEffect::CoggingHarmonics {
                    amplitude_nm,
                    periods_per_rev,
                    phase_rad,
                    second_ratio: d.uniform(0.6, 1.0),
                    second_phase_rad: d.uniform(0.0, tau),
                    third_ratio: d.uniform(0.4, 0.8),
                    third_phase_rad: d.uniform(0.0, tau),
                }
            } else {
                PlantEffect::CoggingSine {
                    amplitude_nm,
                    periods_per_rev,
                    phase_rad,
                }
            }
        }
        "current_sensor_lag" => {
            let delay = 0.5 * op.dt;
            if other {
                PlantEffect::SensorSecondOrder {
                    natural_pulsation_rad_s: 2.0 / delay,
                }
            } else {
                PlantEffect::SensorFirstOrder { tau_f_s: delay }
            }
        }
        "thermal_drift" => {
            // About 5 K over the reversal record at the first guess.
            let current = 0.6 * op.i_peak;
            let energy = current * current * p.r_ohm * 0.3 * op.reversal_s;
            let capacity = energy / 5.0;
            if other {
                // A housing of comparable capacity that warms within the records: two time
                // constants, the winding's (0.1-0.3 of the reversal record) and a slower one.
                let cw = capacity * d.uniform(0.3, 0.6);
                let rwh = d.uniform(0.1, 0.3) * op.reversal_s / cw;
                PlantEffect::ThermalTwoNode {
                    winding_capacity_j_per_k: cw,
                    winding_to_housing_k_per_w: rwh,
                    housing_capacity_j_per_k: cw * d.uniform(1.0, 3.0),
                    housing_to_ambient_k_per_w: rwh * d.uniform(2.0, 5.0),
                    alpha_per_k: ALPHA_COPPER_PER_K,
                }
            } else {
                PlantEffect::ThermalOneNode {
                    thermal_resistance_k_per_w: d.uniform(3.0, 20.0) * op.total_s / capacity,
                    thermal_capacity_j_per_k: capacity,
                    alpha_per_k: ALPHA_COPPER_PER_K,
                }
            }
        }
        "quadratic_drag" => {
            let w = op.w_high.abs().max(1e-3);
            let torque = 0.05 * (p.f_nms_per_rad * w + p.ts_nm);
            if other {
                PlantEffect::DragPowerOneAndHalf {
                    c_nm_per_rad_s_pow: torque / w.powf(1.5),
                }
            } else {
                PlantEffect::DragQuadratic {
                    c_nms2_per_rad2: torque / (w * w),
                }
            }
        }
        "brush_drop" => {
            let current = op.i_low.abs().max(1e-6) * d.uniform(0.05, 0.3);
            if other {
                PlantEffect::BrushLogarithmic {
                    drop_v: 0.05 * op.voltage_margin(),
                    onset_current_a: current,
                }
            } else {
                PlantEffect::BrushClamp {
                    drop_v: 0.1 * op.voltage_margin(),
                    knee_current_a: current,
                }
            }
        }
        "inductance_saturation" => {
            let saturation_current_a = op.i_peak * d.uniform(0.2, 0.6);
            if other {
                PlantEffect::SaturationAbsolute {
                    saturation_current_a,
                    min_ratio: 0.8,
                }
            } else {
                PlantEffect::SaturationLorentzian {
                    saturation_current_a,
                    min_ratio: 0.8,
                }
            }
        }
        other_name => {
            return Err(ModelError::EffectSpec {
                spec: other_name.to_string(),
                reason: "not one of the seven benchmark effects".into(),
            })
        }
    };
    effect.validate(p)?;
    Ok(effect)
}

/// The effect with its size held within what keeps the case sensible: static friction and
/// cogging within [`MARGIN_SHARE`] of the low step's breakaway margin, the brush drop within
/// that share of its voltage margin, the sensor delay between a tenth of a sample and a few
/// samples.
fn limit(effect: PlantEffect, op: &Operating) -> PlantEffect {
    let p = &op.motor;
    let no_floor = 0.0;
    let (size, floor, cap) = match effect {
        PlantEffect::StribeckGaussian {
            static_torque_nm, ..
        }
        | PlantEffect::LuGre {
            static_torque_nm, ..
        } => (
            static_torque_nm - p.ts_nm,
            no_floor,
            MARGIN_SHARE * op.torque_margin(),
        ),
        PlantEffect::CoggingSine { amplitude_nm, .. } => {
            (amplitude_nm, no_floor, MARGIN_SHARE * op.torque_margin())
        }
        PlantEffect::CoggingHarmonics {
            amplitude_nm,
            second_ratio,
            third_ratio,
            ..
        } => (
            amplitude_nm * (1.0 + second_ratio + third_ratio),
            no_floor,
            MARGIN_SHARE * op.torque_margin(),
        ),
        PlantEffect::SensorFirstOrder { tau_f_s } => (
            tau_f_s,
            SENSOR_DELAY_SAMPLES.0 * op.dt,
            SENSOR_DELAY_SAMPLES.1 * op.dt,
        ),
        PlantEffect::SensorSecondOrder {
            natural_pulsation_rad_s,
        } => (
            2.0 / natural_pulsation_rad_s,
            SENSOR_DELAY_SAMPLES.0 * op.dt,
            SENSOR_DELAY_SAMPLES.1 * op.dt,
        ),
        PlantEffect::BrushClamp { drop_v, .. } => {
            (drop_v, no_floor, MARGIN_SHARE * op.voltage_margin())
        }
        PlantEffect::BrushLogarithmic {
            drop_v,
            onset_current_a,
        } => (
            drop_v * (op.i_low.abs() / onset_current_a).ln_1p(),
            no_floor,
            MARGIN_SHARE * op.voltage_margin(),
        ),
        _ => return effect,
    };
    if size > cap && size > 0.0 {
        effect.scaled(cap / size, p)
    } else if size < floor && size > 0.0 {
        effect.scaled(floor / size, p)
    } else {
        effect
    }
}

/// The records of `case` as the diagnoser receives them: each record's plant trace with the
/// case's effects, through the case's logger, the noise seeded by the case.
pub fn generate(case: &CaseSpec) -> Result<CaseRecords, ModelError> {
    let traces = case.traces_with(&case.plant_effects())?;
    let mut high = None;
    let mut low = None;
    let mut validation = Vec::new();
    for (j, (spec, trace)) in case.records.iter().zip(&traces).enumerate() {
        let noise_seed = NoiseRng::new(case.seed.wrapping_add(j as u64 + 1)).next_u64();
        let record = case.measurement.measure(trace, &spec.ranges, noise_seed)?;
        match spec.role {
            RecordRole::HighStep => high = Some(record),
            RecordRole::LowStep => low = Some(record),
            role => validation.push((role, record)),
        }
    }
    let missing = |what: &str| ModelError::InvalidSetting {
        name: format!("case {} {what} record", case.index),
        value: 0.0,
        expected: "a high-step and a low-step record in the case",
    };
    Ok(CaseRecords {
        high: high.ok_or_else(|| missing("high-step"))?,
        low: low.ok_or_else(|| missing("low-step"))?,
        validation,
    })
}
