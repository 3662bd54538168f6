//! The withheld-effect benchmark (issue 9, point 5): the diagnosis run on cases of
//! [`motor_model::withheld`] without being told their effect, and scored.
//!
//! The cases are [`calibrated_case`]'s: [`motor_model::withheld`]'s random motors, loggers and
//! effect forms, each effect sized so that the gap it leaves once the nominal model has
//! absorbed what it can ([`nominal_gap`]) is 4–25 noise floors RMS on some record (or as near
//! as the generator's limits on its size allow). Each case gives a high and a low step (the
//! training records) and a reversal and a staircase (held out whole). The diagnosis starts
//! from the equation-error estimate ([`crate::equation_error_start`]) on the training records
//! and uses its default settings; samples on an ADC rail are left out
//! ([`crate::find_clipping`]).
//!
//! Scores ([`Summary`]): the confusion matrix of the truth against the top-ranked verdict
//! (cases with one effect or none), the top-1 accuracy (the first effect named is one present,
//! or `none` for `none`; every case), false alarms on `none`, the share of two-effect cases
//! with both named, and the median held-out NRMSE after/before of correctly named effects, and
//! of their held-out gap (the NRMSE above the noise floor) after/before, beside the median
//! NRMSE after/before a perfect model would reach on the same samples ([`HeldoutShrink`]).

use std::borrow::Cow;

use motor_model::withheld::{benchmark_case_with_gap, generate, CaseRecords, CaseSpec, RecordRole};
use motor_model::{Effects, Input, ModelError, MotorParams, Record, Trace, EFFECT_NAMES};
use serde::Serialize;

use crate::diagnose::jumps::{locate_every_jump, with_inputs};
use crate::diagnose::nominal::fit_nominal;
use crate::diagnose::report::{DiagnoseSettings, Diagnosis};
use crate::diagnose::run::diagnose;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel};
use crate::excitation::equation_error::equation_error_start;
use crate::excitation::output_error::predict_with_step_factor;
use crate::excitation::voltage::voltage_input;

/// One case diagnosed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaseOutcome {
    /// The case's index.
    pub index: usize,
    /// The effects present (`["none"]` for none).
    pub truth: Vec<&'static str>,
    /// The effects named, in order (empty: `none`); or why the diagnosis failed.
    pub named: Result<Vec<String>, String>,
    /// Effects the first stage's held-out data could not tell from its verdict.
    pub ambiguous_with: Vec<String>,
    /// Held-out NRMSE after/before of the first effect named, when it is one present.
    pub heldout_ratio: Option<f64>,
    /// Held-out gap (NRMSE above the noise floor, SPEC section 7) after/before of the same
    /// effect, when its gap before is positive.
    pub heldout_gap_ratio: Option<f64>,
    /// Held-out NRMSE of the noise-free records over the NRMSE before, on the same samples and
    /// channels: the lowest NRMSE after/before any model could reach ([`HeldoutShrink`]).
    pub heldout_floor_ratio: Option<f64>,
    /// Held-out NRMSE after/before of the same effect on the one held-out channel of one
    /// record whose NRMSE before stands furthest above its noise-free NRMSE (where the gap is:
    /// [`HeldoutShrink::gap_channel`]), and the ratio a perfect model reaches there.
    pub heldout_gap_channel: Option<GapChannel>,
    /// Wall time of the diagnosis \[s\].
    pub seconds: f64,
}

impl CaseOutcome {
    /// The top-ranked verdict: the first effect named, `none`, or `failed`.
    pub fn verdict(&self) -> &str {
        match &self.named {
            Ok(named) => named.first().map_or("none", String::as_str),
            Err(_) => "failed",
        }
    }

    /// Whether the top-ranked verdict is right (one of the effects present, or `none`).
    pub fn top1_correct(&self) -> bool {
        self.truth.contains(&self.verdict())
    }
}

/// A record with its masks of clipped samples.
struct Owned<'a> {
    input: Input,
    record: &'a Record,
    clipped_current: Vec<bool>,
    clipped_speed: Option<Vec<bool>>,
}

impl<'a> Owned<'a> {
    fn new(record: &'a Record) -> Result<Self, String> {
        let input = voltage_input(&record.t, &record.voltage).map_err(|e| e.to_string())?;
        let clipped_current = crate::find_clipping(&record.current, None, 0.0);
        let clipped_speed = match (&record.position, &record.speed) {
            (None, Some(w)) => Some(crate::find_clipping(w, None, 0.0)),
            _ => None,
        };
        Ok(Owned {
            input,
            record,
            clipped_current,
            clipped_speed,
        })
    }

    fn excited(&self) -> ExcitedRecord<'_> {
        let r = self.record;
        let dt = if r.t.len() > 1 { r.t[1] - r.t[0] } else { 0.0 };
        ExcitedRecord {
            input: &self.input,
            dt,
            current: &r.current,
            speed: if r.position.is_some() {
                None
            } else {
                r.speed.as_deref()
            },
            position: r.position.as_deref(),
            exclude_current: Some(&self.clipped_current),
            exclude_speed: self.clipped_speed.as_deref(),
        }
    }
}

/// Diagnoses one case (module docs).
pub fn run_case(case: &CaseSpec, settings: &DiagnoseSettings) -> CaseOutcome {
    let t0 = std::time::Instant::now();
    let truth = case.truth();
    let named = diagnose_records(case, settings);
    let (named, shrink, ambiguous_with) = match named {
        Ok(n) => {
            let right = n.named.first().is_some_and(|x| truth.contains(&x.as_str()));
            (Ok(n.named), n.shrink.filter(|_| right), n.ambiguous_with)
        }
        Err(e) => (Err(e), None, Vec::new()),
    };
    CaseOutcome {
        index: case.index,
        truth,
        named,
        ambiguous_with,
        heldout_ratio: shrink.map(|s| s.nrmse_ratio),
        heldout_gap_ratio: shrink.and_then(|s| s.gap.and_then(|g| g.gap_ratio)),
        heldout_floor_ratio: shrink.and_then(|s| s.gap.map(|g| g.floor_ratio)),
        heldout_gap_channel: shrink.and_then(|s| s.gap.and_then(|g| g.gap_channel)),
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// What [`diagnose_records`] reads off a diagnosis.
struct Named {
    /// The effects named, in order (empty: `none`).
    named: Vec<String>,
    /// How far the first effect named shrinks the held-out data's misfit.
    shrink: Option<Shrink>,
    /// The effects the first stage could not tell from its verdict.
    ambiguous_with: Vec<String>,
}

/// The first effect named: its held-out NRMSE after/before, and its held-out gap against the
/// noise-free records ([`heldout_gap_ratio`]).
#[derive(Clone, Copy)]
struct Shrink {
    nrmse_ratio: f64,
    gap: Option<HeldoutShrink>,
}

/// The effects named for `case` (see [`Named`]).
fn diagnose_records(case: &CaseSpec, settings: &DiagnoseSettings) -> Result<Named, String> {
    let d = diagnose_case(case, settings)?;
    let named: Vec<String> = d.named().iter().map(|s| s.to_string()).collect();
    let shrink = named.first().and_then(|name| {
        let stage = d.stages.first()?;
        stage
            .candidates
            .iter()
            .find(|c| c.name == name.as_str())
            .map(|c| Shrink {
                nrmse_ratio: c.heldout_nrmse_after / c.heldout_nrmse_before,
                gap: heldout_gap_ratio(case, &d.held, &stage.fitted_before, &c.fitted),
            })
    });
    let ambiguous_with = d
        .stages
        .first()
        .map_or_else(Vec::new, |s| s.verdict.ambiguous_with.clone());
    Ok(Named {
        named,
        shrink,
        ambiguous_with,
    })
}

/// A refit's held-out misfit measured against the noise-free records ([`heldout_gap_ratio`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldoutShrink {
    /// Gap (NRMSE above the noise-free records' NRMSE) after/before; `None` when the gap
    /// before is not positive.
    pub gap_ratio: Option<f64>,
    /// NRMSE of the noise-free records over the NRMSE before, summarised alike: the NRMSE
    /// after/before a perfect model would reach, the lowest there is.
    pub floor_ratio: f64,
    /// The channel of one record with the largest gap before (its NRMSE before minus its
    /// noise-free NRMSE, both over its held-out samples): where the effect shows. Chosen on
    /// the model before and the noise-free record, never on the refit. `None` when no channel
    /// has a positive gap.
    pub gap_channel: Option<GapChannel>,
}

/// One held-out channel of one record, where a refit is judged ([`HeldoutShrink::gap_channel`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GapChannel {
    /// Its NRMSE after/before.
    pub nrmse_ratio: f64,
    /// Its noise-free NRMSE over its NRMSE before: the lowest NRMSE after/before there.
    pub floor_ratio: f64,
}

/// Held-out gap after/before of a refit (`after`) against the model it started from
/// (`before`), both predictions of every record of `case` in the diagnosis's order (the two
/// steps, then the validation records), over the samples `held` holds out. A channel's gap is
/// its NRMSE above the NRMSE the noise-free record would show (SPEC section 7: the floor a
/// perfect model cannot go below; the benchmark knows it exactly, from the case's plant traces
/// before the logger), summarised over channels as the NRMSE is (weighted by held-out
/// samples). `None` when a trace is missing or no channel has held-out samples to compare.
pub fn heldout_gap_ratio(
    case: &CaseSpec,
    held: &[Vec<bool>],
    before: &[FittedChannel],
    after: &[FittedChannel],
) -> Option<HeldoutShrink> {
    let traces = case.traces_with(&case.plant_effects()).ok()?;
    // The records in the diagnosis's order: the high step, the low step, then the others.
    let role_order = |role: RecordRole| match role {
        RecordRole::HighStep => 0,
        RecordRole::LowStep => 1,
        _ => 2,
    };
    let mut order: Vec<usize> = (0..case.records.len()).collect();
    order.sort_by_key(|&j| role_order(case.records[j].role));
    let dt = 1.0 / case.measurement.rate_hz;
    // Each record's noise-free channels, as the fit reads them: the current, and the
    // tachometer's speed or the central difference of the encoder's angle.
    let clean = |record: usize, channel: Channel| -> Option<Cow<'_, [f64]>> {
        let tr = &traces[*order.get(record)?];
        Some(match channel {
            Channel::Current => Cow::Borrowed(&tr.current),
            Channel::Speed => Cow::Borrowed(&tr.speed),
            Channel::EncoderSpeed => {
                let times: Vec<f64> = (0..tr.position.len()).map(|i| i as f64 * dt).collect();
                Cow::Owned(motor_model::central_difference(&times, &tr.position))
            }
        })
    };
    let (mut gap_before, mut gap_after, mut floor_sum, mut before_sum, mut count) =
        (0.0, 0.0, 0.0, 0.0, 0usize);
    // The channel with the largest gap before, with that gap.
    let mut widest: Option<(f64, GapChannel)> = None;
    for b in before {
        let a = after
            .iter()
            .find(|a| a.record == b.record && a.channel == b.channel)?;
        let c = clean(b.record, b.channel)?;
        let idx: Vec<usize> = (0..b.samples.len())
            .filter(|&j| held.get(b.record).is_some_and(|h| h[b.samples[j]]))
            .collect();
        if idx.len() < 2 || a.samples != b.samples {
            continue;
        }
        let mean = idx.iter().map(|&j| b.measured[j]).sum::<f64>() / idx.len() as f64;
        let spread = idx
            .iter()
            .map(|&j| (b.measured[j] - mean).powi(2))
            .sum::<f64>()
            .sqrt();
        if spread <= 0.0 {
            continue;
        }
        let norm = |other: &dyn Fn(usize) -> Option<f64>| -> Option<f64> {
            let mut sse = 0.0_f64;
            for &j in &idx {
                sse += (b.measured[j] - other(j)?).powi(2);
            }
            Some(sse.sqrt() / spread)
        };
        let floor = norm(&|j| c.get(b.samples[j]).copied())?;
        let nrmse_before = norm(&|j| Some(b.model[j]))?;
        let nrmse_after = norm(&|j| Some(a.model[j]))?;
        if nrmse_before - floor > widest.map_or(0.0, |(g, _)| g) {
            widest = Some((
                nrmse_before - floor,
                GapChannel {
                    nrmse_ratio: nrmse_after / nrmse_before,
                    floor_ratio: floor / nrmse_before,
                },
            ));
        }
        gap_before += (nrmse_before - floor) * idx.len() as f64;
        gap_after += (nrmse_after - floor) * idx.len() as f64;
        floor_sum += floor * idx.len() as f64;
        before_sum += nrmse_before * idx.len() as f64;
        count += idx.len();
    }
    (count > 0 && before_sum > 0.0).then(|| HeldoutShrink {
        gap_ratio: (gap_before > 0.0).then(|| gap_after / gap_before),
        floor_ratio: floor_sum / before_sum,
        gap_channel: widest.map(|(_, c)| c),
    })
}

/// The diagnosis of `case`'s records (module docs), or why it could not be made.
pub fn diagnose_case(case: &CaseSpec, settings: &DiagnoseSettings) -> Result<Diagnosis, String> {
    let CaseRecords {
        high,
        low,
        validation,
    } = generate(case).map_err(|e| e.to_string())?;
    let train: Vec<Owned<'_>> = [&high, &low]
        .into_iter()
        .map(Owned::new)
        .collect::<Result<_, _>>()?;
    let held: Vec<Owned<'_>> = validation
        .iter()
        .map(|(_, r)| Owned::new(r))
        .collect::<Result<_, _>>()?;
    let train_x: Vec<ExcitedRecord<'_>> = train.iter().map(Owned::excited).collect();
    let held_x: Vec<ExcitedRecord<'_>> = held.iter().map(Owned::excited).collect();
    let start = equation_error_start(&train_x).map_err(|e| e.to_string())?;
    diagnose(&train_x, &held_x, &[], &start, settings, &|_| {}).map_err(|e| e.to_string())
}

/// How many noise floors the effects behind `traces` (noise-free records of `case`, one per
/// record, [`CaseSpec::traces_with`]) leave that no nominal model can absorb. Each voltage
/// jump is put on the first sample that shows it, then moved within that sample period to
/// where the true motor fits the traces best (the voltage column says only between which two
/// samples a jump fell: the diagnosis locates them the same way, beside its own nominal fit);
/// the nominal model (no effect) is fitted by output error to the current and speed of every
/// record on those instants (from the true motor, each channel weighted by its noise floor,
/// `settings`' solver and step), and its prediction compared with the traces. Returns the
/// largest RMS difference of current or speed of any record, in that channel's noise floors,
/// or the true motor's at the true instants where that is smaller (it is a nominal model
/// too); `None` when a fit or simulation fails.
///
/// [`calibrated_case`] sizes every effect on it. Measured against the *true* nominal motor
/// ([`motor_model::withheld::visibility`]), an effect a parameter shift absorbs — a sensor lag
/// within a sample period is a later step, a drag on two steps more viscous and Coulomb
/// friction — can stand many floors away and still leave records the nominal model explains to
/// within their noise, which SPEC section 5 calls `none`.
pub fn nominal_gap(case: &CaseSpec, traces: &[Trace], settings: &DiagnoseSettings) -> Option<f64> {
    if traces.len() != case.records.len() {
        return None;
    }
    let floors = case.floors();
    let dt = 1.0 / case.measurement.rate_hz;
    // Each jump on the first sample that shows it, as a record's voltage column places it.
    let inputs: Vec<Input> = case
        .records
        .iter()
        .map(|r| on_sample_grid(&r.input, dt))
        .collect::<Option<_>>()?;
    let all: Vec<ExcitedRecord<'_>> = inputs
        .iter()
        .zip(traces)
        .map(|(input, tr)| ExcitedRecord {
            input,
            dt,
            current: &tr.current,
            speed: Some(&tr.speed),
            position: None,
            exclude_current: None,
            exclude_speed: None,
        })
        .collect();
    let sigmas: Vec<(usize, Channel, f64)> = floors
        .iter()
        .enumerate()
        .flat_map(|(k, f)| {
            [
                (k, Channel::Current, f.current_a),
                (k, Channel::Speed, f.speed_rad_s),
            ]
        })
        .collect();
    // The jumps located beside the true motor (a model fitted to records with late jumps
    // would move them less far than they fell), then the model fitted on those instants.
    let located = locate_every_jump(
        &all,
        0..all.len(),
        &case.motor,
        &Effects::none(),
        &sigmas,
        settings.step_factor,
    );
    let moved = with_inputs(&all, &located);
    let motor = fit_nominal(&moved, &case.motor, settings, Some(&sigmas))
        .ok()?
        .params;
    let gap_of = |records: &[ExcitedRecord<'_>], motor: &MotorParams| -> Option<f64> {
        let predicted =
            predict_with_step_factor(records, motor, &Effects::none(), settings.step_factor)
                .ok()?;
        let mut gap = 0.0_f64;
        for ch in &predicted {
            let floor = match ch.channel {
                Channel::Current => floors.get(ch.record)?.current_a,
                _ => floors.get(ch.record)?.speed_rad_s,
            };
            gap = gap.max(ch.residual_rms() / floor);
        }
        gap.is_finite().then_some(gap)
    };
    // The true motor at the true instants is a nominal model too: the gap is never above its.
    let exact: Vec<ExcitedRecord<'_>> = case
        .records
        .iter()
        .zip(&all)
        .map(|(spec, r)| ExcitedRecord {
            input: &spec.input,
            ..*r
        })
        .collect();
    let refitted = gap_of(&moved, &motor)?;
    Some(gap_of(&exact, &case.motor).map_or(refitted, |truth| truth.min(refitted)))
}

/// `input` with every jump moved to the first sample at or after it (period `dt`).
fn on_sample_grid(input: &Input, dt: f64) -> Option<Input> {
    let grid = |t: f64| (t / dt - 1e-9).ceil().max(0.0) * dt;
    match input {
        Input::Step { volts, at_s } => Input::step(*volts, grid(*at_s)).ok(),
        Input::Piecewise { times_s, volts } => {
            let levels: Vec<(f64, f64)> = times_s
                .iter()
                .map(|&t| grid(t))
                .zip(volts.iter().copied())
                .collect();
            Input::piecewise(&levels).ok()
        }
        _ => None,
    }
}

/// Case `index` of the `n` cases of `seed` with every effect sized on [`nominal_gap`]
/// ([`motor_model::withheld::benchmark_case_with_gap`]; `settings` gives the fits' solver and
/// step): the cases the benchmark diagnoses.
pub fn calibrated_case(
    seed: u64,
    index: usize,
    n: usize,
    settings: &DiagnoseSettings,
) -> Result<CaseSpec, ModelError> {
    benchmark_case_with_gap(seed, index, n, &|case, traces| {
        nominal_gap(case, traces, settings)
    })
}

/// The benchmark's scores (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// Row and column labels of [`Summary::confusion`]: `none`, the seven effects, then
    /// `failed` (columns only).
    pub labels: Vec<&'static str>,
    /// `confusion[truth][verdict]`: counts over the cases with one effect or none.
    pub confusion: Vec<Vec<usize>>,
    /// Cases scored.
    pub cases: usize,
    /// Share of cases whose top-ranked verdict is right.
    pub top1_accuracy: f64,
    /// `none` cases with an effect named, and `none` cases.
    pub false_alarms: (usize, usize),
    /// Two-effect cases with both named, and two-effect cases.
    pub both_named: (usize, usize),
    /// Median held-out NRMSE after/before over correctly named effects (NaN if none).
    pub median_heldout_ratio: f64,
    /// Median held-out gap after/before over the same effects (NaN if none).
    pub median_heldout_gap_ratio: f64,
    /// Median over the same effects of the lowest held-out NRMSE after/before a perfect
    /// model would reach ([`HeldoutShrink::floor_ratio`]; NaN if none).
    pub median_heldout_floor_ratio: f64,
    /// Median over the same effects of the held-out NRMSE after/before on the channel where
    /// the gap is ([`CaseOutcome::heldout_gap_channel`]; NaN if none).
    pub median_gap_channel_ratio: f64,
    /// Median over the same effects of the lowest NRMSE after/before on that channel.
    pub median_gap_channel_floor_ratio: f64,
    /// Diagnoses that failed.
    pub failed: usize,
    /// Median wall time of a diagnosis \[s\].
    pub median_seconds: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

impl Summary {
    /// The scores of `outcomes`.
    pub fn of(outcomes: &[CaseOutcome]) -> Summary {
        let mut labels: Vec<&'static str> = EFFECT_NAMES.to_vec();
        if let Some(k) = labels.iter().position(|n| *n == "none") {
            let none = labels.remove(k);
            labels.insert(0, none);
        }
        let rows = labels.len();
        labels.push("failed");
        let mut confusion = vec![vec![0usize; labels.len()]; rows];
        let (mut alarms, mut nones, mut both, mut pairs) = (0, 0, 0, 0);
        for o in outcomes {
            if o.truth.len() == 1 {
                let row = labels.iter().position(|l| *l == o.truth[0]);
                let col = labels.iter().position(|l| *l == o.verdict());
                if let (Some(r), Some(c)) = (row, col) {
                    confusion[r][c] += 1;
                }
            }
            if o.truth == ["none"] {
                nones += 1;
                if o.named.as_ref().is_ok_and(|n| !n.is_empty()) {
                    alarms += 1;
                }
            }
            if o.truth.len() == 2 {
                pairs += 1;
                if o.named
                    .as_ref()
                    .is_ok_and(|n| o.truth.iter().all(|t| n.iter().any(|x| x == t)))
                {
                    both += 1;
                }
            }
        }
        let correct = outcomes.iter().filter(|o| o.top1_correct()).count();
        Summary {
            labels,
            confusion,
            cases: outcomes.len(),
            top1_accuracy: correct as f64 / outcomes.len().max(1) as f64,
            false_alarms: (alarms, nones),
            both_named: (both, pairs),
            median_heldout_ratio: median(outcomes.iter().filter_map(|o| o.heldout_ratio).collect()),
            median_heldout_gap_ratio: median(
                outcomes
                    .iter()
                    .filter_map(|o| o.heldout_gap_ratio)
                    .collect(),
            ),
            median_heldout_floor_ratio: median(
                outcomes
                    .iter()
                    .filter_map(|o| o.heldout_floor_ratio)
                    .collect(),
            ),
            median_gap_channel_ratio: median(
                outcomes
                    .iter()
                    .filter_map(|o| o.heldout_gap_channel.map(|c| c.nrmse_ratio))
                    .collect(),
            ),
            median_gap_channel_floor_ratio: median(
                outcomes
                    .iter()
                    .filter_map(|o| o.heldout_gap_channel.map(|c| c.floor_ratio))
                    .collect(),
            ),
            failed: outcomes.iter().filter(|o| o.named.is_err()).count(),
            median_seconds: median(outcomes.iter().map(|o| o.seconds).collect()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::withheld::{benchmark_case, case_mix};

    #[test]
    fn a_case_without_effect_leaves_no_gap_and_one_with_an_effect_does() {
        let mix = case_mix(1, 16);
        let settings = DiagnoseSettings::default();
        let index = |name: &str| {
            mix.iter()
                .position(|effects| match effects.as_slice() {
                    [] => name == "none",
                    [(n, _)] => *n == name,
                    _ => false,
                })
                .expect("the mix holds the case")
        };
        let gap = |case: &CaseSpec| {
            let traces = case.traces_with(&case.plant_effects()).expect("the traces");
            nominal_gap(case, &traces, &settings).expect("a gap")
        };
        let none = benchmark_case(1, index("none"), 16).expect("a case");
        assert!(gap(&none) < 0.05, "{}", gap(&none));
        // Sized on the gap, the effect leaves the gap it was sized to, within the calibration's
        // tolerance and limits (4–25 floors targeted).
        let stribeck =
            calibrated_case(1, index("stribeck_friction"), 16, &settings).expect("a case");
        let left = gap(&stribeck);
        assert!(left > 1.0, "{left}");
        assert!(
            (left - stribeck.visibility).abs() < 1e-9 * left,
            "{left} {stribeck:?}"
        );
    }
}
