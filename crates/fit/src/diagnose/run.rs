//! The whole diagnosis: the nominal identification, where its residual stands above the noise,
//! each candidate effect refitted jointly with the motor by output error, the candidates ranked
//! on held-out data, and the same again on top of the chosen effect (a second effect present is
//! named too).
//!
//! **Held-out data.** Every training record is cut into blocks of
//! [`DiagnoseSettings::block_samples`] samples (shorter on a record too short to lend two such
//! blocks) and every [`DiagnoseSettings::holdout_every`]-th block is left out of every fit
//! (its samples excluded, as clipped samples are) and judged on the model's prediction there
//! (the voltage jumps' instants, a nuisance of every model alike, are located on whole
//! records: see below). Records given as validation are held out whole, in addition
//! to those blocks (unless [`DiagnoseSettings::split_with_validation`] is off): an effect the
//! validation records do not excite (a cogging torque averaged out at speed, a Stribeck dip the
//! records never dwell in) is still judged on held-out samples of the records that show it. A
//! physical effect of a few parameters cannot learn the noise of the blocks it does not see, so
//! a fall of the held-out error is evidence; a fall on the training blocks alone is not (SPEC
//! section 7).
//!
//! **Voltage jumps.** The voltage column says only between which two samples a jump fell.
//! After the nominal fit each jump is moved to the instant within that sample period where the
//! nominal model fits its record best, the nominal model is refitted there, and its jumps are
//! located again beside the refit, in turn until no jump moves by more than 0.02 of a period
//! or for 6 rounds (the training records' jumps each next refit is made on moved by the
//! Gauss–Newton step of the motor and the instants together, which settles in a few rounds
//! where alternating moves a few per cent a round; by the located instants alone where that
//! step cannot be taken); the screening projects the jumps' instants out with the motor's
//! parameters: otherwise a step modelled up to a period late leaves a residual at every
//! jump that an effect acting there (a sensor lag, a saturating inductance) is credited with.
//! Every refitted candidate's jumps are located the same way beside its own model before it is
//! judged, so that each model is compared at its own best instants (a lag's lie earlier than
//! the nominal model's, which put them late to mimic it).
//!
//! **Candidates** start from the nominal motor and a small size of each effect, its shape
//! parameters from the records (the cogging period count from the residual's ripple per
//! revolution, time constants from the record span and sample period, speeds and currents from
//! their peaks). Each stage first *screens* every candidate by its score statistic at the base
//! model ([`crate::diagnose::screen`]: one linearisation, no fit); only the best
//! [`DiagnoseSettings::refits`] are refitted with the motor and judged by the verdict's tests,
//! then (up to [`DiagnoseSettings::refit_rounds`] times as many) the next ones by score in
//! place of a refit that stopped or left its effect unresolved, and any whose score promises
//! more than the refits' verdict delivered (its likelihood ratio, penalised alike): the
//! linearised score at zero size ranks effects that grow nonlinearly only roughly.
//! A refit starts where the screening's linear step points (`stepped_start`): a cogging
//! torque at the phase and amplitude of the ripple the residual holds, a drag, brush drop or
//! Stribeck excess at the size it asks for; from the start before the step when the stepped
//! one is too fast for the records' sample rate to simulate, fails, or ends above the base
//! model's training error (`RefitStart`). An effect the nominal fit absorbed into a motor
//! parameter (a sensor lag or a saturating inductance into L, a heating winding into R, a
//! Stribeck friction's static level into Ts) is also refitted from a start that splits the
//! two (`absorbed_start`), and the lower cost kept.
//! A refit whose effect's own part of the prediction is below a noise variance (its size gone
//! to zero) gives no training statistic and is not named: its fall is the motor's.
//! Every refit weights each channel by the noise level the nominal fit found for it, in one
//! stage (not reweighted by its own residuals): the refit then minimises the very cost its
//! likelihood-ratio statistic and held-out blocks measure, and cannot trade a channel the
//! effect does not touch for one it does.
//! A candidate is *not testable from these records* when its signature is lost in the base
//! model's (screening); one that is testable but whose refit leaves its parameters undetermined
//! (no interval, or one wider than a hundred times its value) reads *tested, no evidence* when
//! its screening score is below the level, *unresolved* otherwise.

use motor_model::{
    BrushDrop, CoggingTorque, CurrentSensorLag, Effect, EffectKind, Effects, InductanceSaturation,
    Input, MotorParams, QuadraticDrag, StribeckFriction, ThermalDrift, COPPER_ALPHA_PER_K,
};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

use crate::diagnose::localise::{
    correlation_factor, localise, Localisation, LocaliseSettings, ResidualChannel, ResidualRecord,
};
use crate::diagnose::screen::{BaseProjection, Screening, CORRELATION_LAGS};
use crate::diagnose::verdict::{
    rank_candidates, training_support, CandidateScore, Verdict, VerdictSettings,
};
use crate::error::{FitError, START_SERIES};
use crate::full_model::{Channel, FittedChannel, FullFit, PARAM_NAMES};
use crate::lm::LmSettings;
use crate::output_error::{
    fit_output_error, output_error_sensitivity, predict_with_step_factor, ExcitedRecord,
};
use crate::parameters::EffectEstimate;

/// Settings of [`diagnose`].
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseSettings {
    /// The candidate effects (default: all seven of SPEC section 5).
    pub candidates: Vec<EffectKind>,
    /// Effects named at most, one after the other (default 2).
    pub max_effects: usize,
    /// Block length of the split into training and held-out data \[samples\] (default 50): a
    /// training record too short to lend two held-out blocks of it gets shorter ones
    /// (`n / (2 · holdout_every)` samples); a validation record, held out whole, is cut into
    /// blocks of this length for the paired test.
    pub block_samples: usize,
    /// Every this many blocks one is held out (default 4: a quarter).
    pub holdout_every: usize,
    /// Whether the training records' blocks are held out also when validation records are
    /// given (default true: module docs).
    pub split_with_validation: bool,
    /// The ranking's settings.
    pub verdict: VerdictSettings,
    /// The localisation's settings.
    pub localise: LocaliseSettings,
    /// The solver's settings for every fit (default: the solver's, converged at a relative
    /// cost fall of 1e-8 and stopped after 200 iterations).
    pub lm: LmSettings,
    /// Whether candidates are refitted at the same time: above 1 (the default: the machine's
    /// parallelism) they share rayon's pool (one thread per core) with the simulations of
    /// their Jacobians; at 1 or 0 they are refitted one after the other.
    pub threads: usize,
    /// Candidates refitted in full at each stage, the best by their screening score (default
    /// 2; the others are reported with their score alone). At least the number of candidates
    /// refits every one.
    pub refits: usize,
    /// RK4 steps of every simulation of the diagnosis (fits, predictions, screening) this
    /// many times the simulator's default of 1/40 of the fastest time constant
    /// ([`motor_model::Simulator::with_step_factor`]; default 8: about 1e-6 of the response,
    /// far below a record's noise).
    pub step_factor: f64,
    /// A candidate is refitted only if its screening p-value is below this (default 0.05,
    /// without the multiple-test correction the verdict applies: lenient, so that a candidate
    /// whose linearisation understates it still gets its refit).
    pub screening_alpha: f64,
    /// Rounds of refits at most (default 2): from 2, when a refit of a round stops or leaves
    /// the effect's size undetermined, the next candidates by screening score whose score
    /// passed are refitted in its place, up to [`DiagnoseSettings::refits`] a round. With 1
    /// round, a drag and a brush drop both present (withheld-effect benchmark, seed 1, case
    /// 15) were screened third and fourth behind two refits that could not resolve their
    /// effects, and nothing was named. A refit that resolves its effect costs no second
    /// round. (3 rounds, measured before the verdict's tie-break, gave the same top-1
    /// accuracy as 1: the flexible cogging candidate, refitted more often, took the gaps of
    /// a Stribeck friction and a brush drop; README.) Within the same bound, a passed
    /// candidate whose screening score promises more than the verdict's refit delivered (its
    /// penalised likelihood ratio) is refitted too, one at a time.
    pub refit_rounds: usize,
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        DiagnoseSettings {
            candidates: EffectKind::ALL.to_vec(),
            max_effects: 2,
            block_samples: 50,
            holdout_every: 4,
            split_with_validation: true,
            verdict: VerdictSettings::default(),
            localise: LocaliseSettings::default(),
            lm: LmSettings {
                ftol: DIAGNOSIS_FTOL,
                xtol: DIAGNOSIS_FTOL,
                max_iters: DIAGNOSIS_MAX_ITERS,
                max_evaluations: 5 * DIAGNOSIS_MAX_ITERS,
                ..LmSettings::default()
            },
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            refits: 2,
            step_factor: 8.0,
            screening_alpha: 0.05,
            refit_rounds: 2,
        }
    }
}

/// Relative fall of the cost (and relative step) at which every fit of a diagnosis has
/// converged. Its tests resolve a tenth of a noise variance; a fit of `n` weighted residuals
/// has a cost of about `n/2`, so 1e-8 of it is below 1e-3 noise variances for records of up to
/// 10⁵ samples, and the solver's own 1e-10 only buys iterations that change no verdict.
const DIAGNOSIS_FTOL: f64 = 1e-8;
/// Iterations of every fit of a diagnosis at most: refits start from the model of the stage
/// they extend, and one that has not converged in this many is reported unresolved. Bounds
/// the time of a case. At 60, a Stribeck friction twice the Coulomb level (benchmark case
/// 139, a low step that sticks and slips) stopped unresolved at the bound and a cogging
/// torque took its gap; it converges in fewer than 200, to Tst within 0.1 % of the truth. On
/// the 160 benchmark cases 200 changed three other verdicts and no case took longer in sum
/// (README).
const DIAGNOSIS_MAX_ITERS: u64 = 200;

/// Where a diagnosis stands, for progress reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagnoseProgress {
    /// The nominal model is being fitted.
    Nominal,
    /// Stage `stage` (1 for the first effect): every candidate is being screened.
    Screening {
        /// Which effect is being looked for (1 = first).
        stage: usize,
    },
    /// Stage `stage` (1 for the first effect): `done` of `total` candidates refitted (those
    /// the screening kept).
    Candidates {
        /// Which effect is being looked for (1 = first).
        stage: usize,
        /// Candidates done.
        done: usize,
        /// Candidates in this stage.
        total: usize,
    },
}

/// How one motor parameter moved when an effect was added.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamShift {
    /// R, L, k, f, J or Ts.
    pub name: &'static str,
    /// Before (SI units).
    pub before: f64,
    /// After (SI units).
    pub after: f64,
    /// `after / before − 1`.
    pub relative: f64,
}

/// One fitted effect parameter, for reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectParam {
    /// Its symbol (e.g. `Tst`).
    pub symbol: &'static str,
    /// Its key in the effect's table (e.g. `tst`).
    pub key: &'static str,
    /// Its SI unit.
    pub unit: &'static str,
    /// The fitted value.
    pub value: f64,
    /// Its 95 % interval, if computed.
    pub ci95: Option<[f64; 2]>,
}

/// What a stage concluded about one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Assessment {
    /// Refitted, and its improvement is significant on training and held-out data.
    Significant,
    /// Tested, no significant evidence of it: its refit does not improve the data
    /// significantly, or its screening score is below the level (an absent effect whose shape
    /// parameters no refit could pin down reads so too).
    NoEvidence,
    /// Its screening score is significant, but better-scoring candidates took the refits.
    ScreenedOut,
    /// Its screening score is significant, but its refit failed or left its parameters
    /// undetermined.
    Unresolved,
    /// The records cannot determine it ([`crate::diagnose::screen`]).
    NotTestable,
}

impl Assessment {
    /// In words, for reports.
    pub fn words(self) -> &'static str {
        match self {
            Assessment::Significant => "significant",
            Assessment::NoEvidence => "tested, no evidence",
            Assessment::ScreenedOut => "screened out",
            Assessment::Unresolved => "unresolved",
            Assessment::NotTestable => "not testable from these records",
        }
    }
}

/// One candidate effect: its screening score and, when refitted with the motor, the refit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CandidateReport {
    /// The effect's name.
    pub name: &'static str,
    /// What the stage concluded about it.
    pub assessment: Assessment,
    /// Whether the records can test it (every assessment but [`Assessment::NotTestable`]).
    pub testable: bool,
    /// Whether its held-out improvement is significant (see [`Verdict`]).
    pub significant: bool,
    /// Its screening score at the stage's base model (`None` when the base model could not
    /// be linearised and every candidate was refitted).
    pub screening: Option<Screening>,
    /// p-value of its training likelihood-ratio test (see [`crate::diagnose::verdict`]).
    pub p_value: f64,
    /// One-sided p-value of its held-out improvement.
    pub heldout_p_value: f64,
    /// Its fitted parameters.
    pub params: Vec<EffectParam>,
    /// Training NRMSE (SPEC section 7, summary over channels) before and after.
    pub train_nrmse_before: f64,
    /// See `train_nrmse_before`.
    pub train_nrmse_after: f64,
    /// Held-out NRMSE before and after.
    pub heldout_nrmse_before: f64,
    /// See `heldout_nrmse_before`.
    pub heldout_nrmse_after: f64,
    /// How each motor parameter moved.
    pub motor_shift: Vec<ParamShift>,
    /// The motor after the refit.
    #[serde(skip)]
    pub motor: Option<MotorParams>,
    /// The effects after the refit (those found before, and this one).
    #[serde(skip)]
    pub effects: Effects,
    /// Why the refit failed, if it did.
    pub failure: Option<String>,
    /// Each record's voltage (training records, then validation) with its jumps where the
    /// refitted model puts them within their sample periods (empty when not refitted).
    #[serde(skip)]
    pub inputs: Vec<Option<Input>>,
    /// The refitted model's prediction of every record and channel, on those instants
    /// (empty when not refitted; [`Diagnosis::held`] says which samples are held out).
    #[serde(skip)]
    pub fitted: Vec<FittedChannel>,
}

impl CandidateReport {
    /// Takes the significance and the p-values of this candidate's row of `verdict` (its
    /// assessment becomes [`Assessment::Significant`] where significant); unranked, unchanged.
    pub(crate) fn take_rank(&mut self, verdict: &Verdict) {
        if let Some(r) = verdict.ranked.iter().find(|r| r.name == self.name) {
            self.significant = r.significant;
            self.p_value = r.p_value;
            self.heldout_p_value = r.heldout_p_value;
            if r.significant {
                self.assessment = Assessment::Significant;
            }
        }
    }
}

impl CandidateReport {
    /// Whether it was refitted (its refit's figures are set).
    pub fn refitted(&self) -> bool {
        self.motor.is_some()
    }
}

/// One stage of the search: the candidates on top of the effects found so far, and its verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stage {
    /// Effects already in the model at this stage (names).
    pub base: Vec<&'static str>,
    /// The candidates, in the order of [`DiagnoseSettings::candidates`].
    pub candidates: Vec<CandidateReport>,
    /// Their ranking and the verdict.
    pub verdict: Verdict,
    /// The prediction of every record and channel the stage starts from (the model with the
    /// effects found before), which each candidate's refit is compared with.
    #[serde(skip)]
    pub fitted_before: Vec<FittedChannel>,
}

/// A diagnosis (module docs).
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The nominal identification on the training data.
    pub nominal: FullFit,
    /// Why the nominal fit alone would not be a result, when the diagnosis went on anyway (a
    /// channel explained worse than by its mean, what a large unmodelled effect does; or a
    /// motor parameter the records do not determine, which leaves the prediction as good).
    pub nominal_note: Option<String>,
    /// How the held-out data were made, in words.
    pub heldout: String,
    /// Per record (training records, then validation records), whether each sample is held
    /// out.
    pub held: Vec<Vec<bool>>,
    /// Where the nominal model's residual stands above the noise, on every record.
    pub localisation: Localisation,
    /// The stages of the search (the first looks for one effect; a second, on top of the
    /// first's verdict, for another).
    pub stages: Vec<Stage>,
}

impl Diagnosis {
    /// The effects named, in the order found (empty: `none`).
    pub fn named(&self) -> Vec<&str> {
        self.stages
            .iter()
            .filter_map(|s| s.verdict.verdict.as_deref())
            .collect()
    }

    /// The motor and effects of the model with every named effect (the last stage's chosen
    /// refit); `None` when nothing is named.
    pub fn final_model(&self) -> Option<(MotorParams, Effects)> {
        self.stages.iter().rev().find_map(|s| {
            let name = s.verdict.verdict.as_deref()?;
            let c = s.candidates.iter().find(|c| c.name == name)?;
            c.motor.map(|m| (m, c.effects))
        })
    }
}

/// Why a diagnosis could not be made.
#[derive(Debug)]
#[non_exhaustive]
pub enum DiagnoseError {
    /// The records or settings are unusable.
    Fit(FitError),
    /// The nominal identification is not a result: no effect is named on top of it.
    NominalFailed(String),
}

impl std::fmt::Display for DiagnoseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DiagnoseError::Fit(e) => write!(f, "{e}"),
            DiagnoseError::NominalFailed(why) => write!(
                f,
                "the nominal identification failed ({why}): no effect can be named on top of it"
            ),
        }
    }
}

impl std::error::Error for DiagnoseError {}

impl From<FitError> for DiagnoseError {
    fn from(e: FitError) -> Self {
        DiagnoseError::Fit(e)
    }
}

/// The records with the held-out blocks excluded (owned masks).
struct Split {
    current_masks: Vec<Vec<bool>>,
    speed_masks: Vec<Vec<bool>>,
    /// Per record, whether each sample is held out.
    held: Vec<Vec<bool>>,
}

fn split(records: &[ExcitedRecord<'_>], settings: &DiagnoseSettings) -> Split {
    let every = settings.holdout_every.max(2);
    let mut out = Split {
        current_masks: Vec::new(),
        speed_masks: Vec::new(),
        held: Vec::new(),
    };
    for r in records {
        let n = r.current.len();
        let block = record_block(n, settings);
        let held: Vec<bool> = (0..n).map(|i| (i / block) % every == every - 1).collect();
        let merge = |m: Option<&[bool]>| -> Vec<bool> {
            (0..n).map(|i| held[i] || m.is_some_and(|m| m[i])).collect()
        };
        out.current_masks.push(merge(r.exclude_current));
        out.speed_masks.push(merge(r.exclude_speed));
        out.held.push(held);
    }
    out
}

/// Block length of a training record of `n` samples \[samples\]:
/// [`DiagnoseSettings::block_samples`], shortened on a record too short for two held-out blocks
/// of it (every record then lends at least two blocks to the held-out data: an effect only a
/// short record shows is judged on it too).
fn record_block(n: usize, settings: &DiagnoseSettings) -> usize {
    (n / (2 * settings.holdout_every.max(2))).clamp(1, settings.block_samples.max(1))
}

/// NRMSE summary over channels (SPEC section 7: each channel's, weighted by sample count) of
/// the samples `keep` selects.
fn nrmse_summary(channels: &[FittedChannel], keep: impl Fn(&FittedChannel, usize) -> bool) -> f64 {
    let (mut weighted, mut count) = (0.0, 0usize);
    for (nrmse, samples) in channels.iter().filter_map(|ch| channel_nrmse(ch, &keep)) {
        weighted += nrmse * samples as f64;
        count += samples;
    }
    if count == 0 {
        f64::NAN
    } else {
        weighted / count as f64
    }
}

/// One channel's NRMSE over the samples `keep` selects, with their count; `None` when fewer
/// than two are kept or the measurement is constant over them.
fn channel_nrmse(
    ch: &FittedChannel,
    keep: impl Fn(&FittedChannel, usize) -> bool,
) -> Option<(f64, usize)> {
    let idx: Vec<usize> = (0..ch.samples.len())
        .filter(|&j| keep(ch, ch.samples[j]))
        .collect();
    if idx.len() < 2 {
        return None;
    }
    let mean = idx.iter().map(|&j| ch.measured[j]).sum::<f64>() / idx.len() as f64;
    let sst: f64 = idx.iter().map(|&j| (ch.measured[j] - mean).powi(2)).sum();
    let sse: f64 = idx
        .iter()
        .map(|&j| (ch.measured[j] - ch.model[j]).powi(2))
        .sum();
    (sst > 0.0).then(|| ((sse / sst).sqrt(), idx.len()))
}

/// The noise level `sigmas` gives record `record`'s `channel` (see [`channel_scales`]).
fn channel_sigma(sigmas: &[(usize, Channel, f64)], record: usize, channel: Channel) -> Option<f64> {
    sigmas
        .iter()
        .find(|(r, c, _)| *r == record && *c == channel)
        .map(|s| s.2)
}

/// Held-out squared errors per block, each channel's residual over its noise level `sigma`.
/// A block is a run of consecutive held-out samples of a record (a training record's held-out
/// block), cut every `block` samples (a validation record, held out whole).
fn block_sse(
    channels: &[FittedChannel],
    sigmas: &[(usize, Channel, f64)],
    held: &[Vec<bool>],
    block: usize,
) -> Vec<f64> {
    use std::collections::BTreeMap;
    // Each held-out sample's block number within its record.
    let numbers: Vec<Vec<usize>> = held
        .iter()
        .map(|h| {
            let (mut number, mut run) = (0usize, 0usize);
            h.iter()
                .enumerate()
                .map(|(i, &is_held)| {
                    if is_held {
                        let starts_run = i == 0 || !h[i - 1];
                        if (starts_run && i > 0) || run == block.max(1) {
                            number += 1;
                            run = 0;
                        }
                        run += 1;
                    }
                    number
                })
                .collect()
        })
        .collect();
    let mut sums: BTreeMap<(usize, usize), f64> = BTreeMap::new();
    for ch in channels {
        let sigma = channel_sigma(sigmas, ch.record, ch.channel).unwrap_or(1.0);
        for (j, &i) in ch.samples.iter().enumerate() {
            if held.get(ch.record).is_some_and(|h| h[i]) {
                *sums.entry((ch.record, numbers[ch.record][i])).or_default() +=
                    ((ch.measured[j] - ch.model[j]) / sigma).powi(2);
            }
        }
    }
    sums.into_values().collect()
}

/// The training likelihood-ratio statistic of a refit (see [`crate::diagnose::verdict`]): the
/// fall of the weighted squared error over the training samples from `before` to `after`,
/// divided by the sample-weighted correlation factor `1 + 2 Σ ρₖ²` of the residuals after.
fn train_statistic(
    before: &[FittedChannel],
    after: &[FittedChannel],
    sigmas: &[(usize, Channel, f64)],
    held: &[Vec<bool>],
) -> Option<f64> {
    train_fall(before, after, sigmas, held).map(|(fall, factor)| fall / factor)
}

/// The parts of [`train_statistic`]: the fall of the weighted squared error over the training
/// samples \[noise variances\] and the sample-weighted correlation factor of the residuals
/// after.
fn train_fall(
    before: &[FittedChannel],
    after: &[FittedChannel],
    sigmas: &[(usize, Channel, f64)],
    held: &[Vec<bool>],
) -> Option<(f64, f64)> {
    let (mut fall, mut factor_sum, mut count) = (0.0, 0.0, 0usize);
    for a in after {
        let b = before
            .iter()
            .find(|b| b.record == a.record && b.channel == a.channel)?;
        let sigma = channel_sigma(sigmas, a.record, a.channel).unwrap_or(1.0);
        let train: Vec<usize> = (0..a.samples.len())
            .filter(|&j| !held.get(a.record).is_some_and(|h| h[a.samples[j]]))
            .collect();
        // A channel too short for every lag of the correlation factor (a record of a few
        // dozen samples) takes a quarter of its length in lags, rather than no statistic.
        let lags = if train.len() > CORRELATION_LAGS + 1 {
            CORRELATION_LAGS
        } else {
            train.len() / 4
        };
        if lags == 0 || b.model.len() != a.model.len() {
            continue;
        }
        let e: Vec<f64> = train
            .iter()
            .map(|&j| (a.measured[j] - a.model[j]) / sigma)
            .collect();
        let sse_after: f64 = e.iter().map(|v| v * v).sum();
        let sse_before: f64 = train
            .iter()
            .map(|&j| ((b.measured[j] - b.model[j]) / sigma).powi(2))
            .sum();
        let factor = correlation_factor(&e, lags);
        fall += sse_before - sse_after;
        factor_sum += factor * e.len() as f64;
        count += e.len();
    }
    (count > 0).then(|| (fall, factor_sum / count as f64))
}

/// Earliest instant a record's first voltage jump is searched at \[sample periods\].
const FIRST_JUMP_MARGIN: f64 = 0.02;
/// Golden-section rounds of the search for one voltage jump's instant (the bracket, one sample
/// period, shrinks to 0.618¹² ≈ 0.3 % of it).
const JUMP_SEARCH_ROUNDS: usize = 12;
/// Rounds at most of the nominal refit on located jump instants and their location again
/// ([`diagnose`]).
const NOMINAL_LOCATE_ROUNDS: usize = 6;
/// Largest move of a jump between two rounds at which they stop \[sample periods\].
const NOMINAL_LOCATE_SETTLED: f64 = 0.02;

/// The largest move of a voltage jump from `before` to `after` over the records of `grid`
/// \[sample periods of its record\]: infinite where a record's jumps cannot be compared (one
/// input piecewise constant and the other not, or a different number of jumps).
fn largest_jump_move(
    before: &[Option<Input>],
    after: &[Option<Input>],
    grid: &[ExcitedRecord<'_>],
) -> f64 {
    let times = |input: Option<&Input>| {
        let times: Vec<f64> =
            input.map_or(Vec::new(), |i| jump_levels(i).iter().map(|l| l.0).collect());
        (!times.is_empty()).then_some(times)
    };
    let mut largest: f64 = 0.0;
    for ((b, a), r) in before.iter().zip(after).zip(grid) {
        match (times(b.as_ref()), times(a.as_ref())) {
            (Some(tb), Some(ta)) if tb.len() == ta.len() => {
                for (x, y) in tb.iter().zip(&ta) {
                    largest = largest.max((x - y).abs() / r.dt.max(f64::MIN_POSITIVE));
                }
            }
            (None, None) if b == a => {}
            _ => return f64::INFINITY,
        }
    }
    largest
}

/// Record `k`'s piecewise-constant voltage with every jump moved, one after the other, to the
/// instant within the sample period before its first sample at which `motor` fits the record
/// best (weighted squared error of its channels, `sigmas` as in [`channel_scales`]), by a
/// golden-section search of [`JUMP_SEARCH_ROUNDS`] rounds per jump. A logger's clock is not
/// tied to the step: the voltage column tells only between which two samples a jump fell, and
/// a model whose step comes up to a period late leaves a residual at every jump that an effect
/// acting there (a sensor lag, a saturating inductance) would be named for. `None` when the
/// voltage is not piecewise constant or nothing could be simulated.
fn locate_jumps(
    k: usize,
    record: &ExcitedRecord<'_>,
    motor: &MotorParams,
    effects: &Effects,
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> Option<Input> {
    let mut levels = jump_levels(record.input);
    if levels.is_empty() {
        return None;
    }
    let dt = record.dt;
    let cost = |levels: &[(f64, f64)]| -> Option<f64> {
        let input = Input::piecewise(levels).ok()?;
        let r = ExcitedRecord {
            input: &input,
            ..*record
        };
        let fitted = predict_with_step_factor(&[r], motor, effects, step_factor).ok()?;
        let mut sse = 0.0;
        for ch in &fitted {
            let sigma = channel_sigma(sigmas, k, ch.channel).unwrap_or(1.0);
            sse += ch
                .measured
                .iter()
                .zip(&ch.model)
                .map(|(y, m)| ((y - m) / sigma).powi(2))
                .sum::<f64>();
        }
        sse.is_finite().then_some(sse)
    };
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    let mut any = false;
    for j in 0..levels.len() {
        // The level a record starts at is not a jump.
        if levels[j].0 <= 0.0 {
            continue;
        }
        let (mut a, mut b) = jump_bracket(&levels, j, dt);
        if b - a <= 0.0 {
            continue;
        }
        let at = |x: f64| -> f64 {
            let mut trial = levels.clone();
            trial[j].0 = x;
            cost(&trial).unwrap_or(f64::INFINITY)
        };
        let (mut c, mut d) = (b - golden * (b - a), a + golden * (b - a));
        let (mut fc, mut fd) = (at(c), at(d));
        let end = b;
        let f_end = at(end);
        if !(fc.is_finite() || fd.is_finite() || f_end.is_finite()) {
            return None;
        }
        for _ in 0..JUMP_SEARCH_ROUNDS {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - golden * (b - a);
                fc = at(c);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + golden * (b - a);
                fd = at(d);
            }
        }
        let (best, f_best) = if fc < fd { (c, fc) } else { (d, fd) };
        // At the bracket's end unless inside is better: the end is the first sample showing
        // the jump, where a level put earlier ([`jump_bracket`]) does not start.
        let at_best = if f_best < f_end { best } else { end };
        if (at_best - levels[j].0).abs() > 1e-9 * dt {
            levels[j].0 = at_best;
            any = true;
        }
    }
    any.then(|| Input::piecewise(&levels).ok()).flatten()
}

/// [`locate_jumps`] on records `which` of `records` for `motor` with `effects` (entry 0 is
/// record `which.start`; `None` where a record's jumps stay).
pub(crate) fn locate_every_jump(
    records: &[ExcitedRecord<'_>],
    which: std::ops::Range<usize>,
    motor: &MotorParams,
    effects: &Effects,
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> Vec<Option<Input>> {
    which
        .map(|k| locate_jumps(k, &records[k], motor, effects, sigmas, step_factor))
        .collect()
}

/// Shift of a voltage jump's instant for its sensitivity column \[sample periods\].
const JUMP_DIFF_STEP: f64 = 0.05;

/// Record `k`'s weighted residuals `(simulated − measured)/σ` for `motor` with `effects` on
/// `input`, at the samples its masks keep, channel after channel: the rows
/// [`output_error_sensitivity`] gives it, each with its channel, its sample and its σ.
fn record_rows(
    k: usize,
    record: &ExcitedRecord<'_>,
    input: &Input,
    (motor, effects): (&MotorParams, &Effects),
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> Option<Vec<(Channel, usize, f64, f64)>> {
    let r = ExcitedRecord { input, ..*record };
    let fitted = predict_with_step_factor(&[r], motor, effects, step_factor).ok()?;
    let mut rows = Vec::new();
    for ch in &fitted {
        let sigma = channel_sigma(sigmas, k, ch.channel)?;
        let mask = match ch.channel {
            Channel::Current => record.exclude_current,
            Channel::Speed | Channel::EncoderSpeed => record.exclude_speed,
        };
        for (j, &i) in ch.samples.iter().enumerate() {
            if !mask.is_some_and(|m| m.get(i).copied().unwrap_or(false)) {
                rows.push((ch.channel, i, sigma, (ch.model[j] - ch.measured[j]) / sigma));
            }
        }
    }
    Some(rows)
}

/// The values of [`record_rows`] alone.
fn row_values(rows: &[(Channel, usize, f64, f64)]) -> Vec<f64> {
    rows.iter().map(|r| r.3).collect()
}

/// Cogging period counts screened with their full signature at most, beside the angle
/// search's: the best by [`cogging_prefilter`].
const COGGING_SCREENED: usize = 4;

/// The cogging period counts whose full signature the screening computes on top of `base`:
/// the angle search's ([`ripple_periods`]) and the best [`COGGING_SCREENED`] others by
/// [`cogging_prefilter`]; every N of [`cogging_counts`] when that cannot be built.
fn cogging_screened(
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    projection: &BaseProjection,
    localisation: &Localisation,
    settings: &DiagnoseSettings,
) -> Vec<u32> {
    let first = ripple_periods(localisation);
    let max_harmonic = settings.localise.max_harmonic;
    match cogging_prefilter(base, sigmas, projection, max_harmonic, settings.step_factor) {
        Some(ranked) => std::iter::once(first)
            .chain(
                ranked
                    .into_iter()
                    .filter(|&n| n != first)
                    .take(COGGING_SCREENED),
            )
            .collect(),
        None => cogging_counts(first, max_harmonic),
    }
}

/// Sub-steps of the linear response per sample at most, so that the probe `sin Nθ` turns at
/// most half a radian per sub-step where it can.
const PROBE_SUBSTEPS: usize = 16;

/// The period counts N = 1..=`max_harmonic` ranked by the score of an approximate cogging
/// signature (best first), or `None` when it cannot be built. The signature of a small load
/// torque `A sin(Nθ + φ)` is the response of the base motor linearised along its own
/// trajectory — `L δİ = −R δI − k δΩ`, `J δΩ̇ = k δI − f δΩ − u`, `δθ̇ = δΩ` (SPEC (2)) — to
/// the probes `u = sin Nθ(t)` and `u = cos Nθ(t)` while the rotor turns (held at rest while
/// it sticks), advanced exactly over each sub-step (a matrix exponential) and read where the
/// records' channels are (the current, the speed, or the central difference of the angle for
/// an encoder). One such response costs a fraction of a simulation, so every N is looked at;
/// the best few are screened with the full signature ([`candidate_starts`]). The base
/// model's other effects are left out of the linearisation: it ranks N, it does not test.
fn cogging_prefilter(
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    projection: &BaseProjection,
    max_harmonic: u32,
    step_factor: f64,
) -> Option<Vec<u32>> {
    use nalgebra::{Matrix3, Matrix4, Vector3};
    let m = &base.motor;
    let (r, l, k, f, j) = (m.r_ohm, m.l_henry, m.k_nm_per_a, m.f_nms_per_rad, m.j_kgm2);
    // Each training record's rows and the base trajectory they are read along.
    let mut layouts = Vec::with_capacity(base.train.len());
    for (idx, rec) in base.train.iter().enumerate() {
        let rows = record_rows(
            idx,
            rec,
            rec.input,
            (&base.motor, &base.effects),
            sigmas,
            step_factor,
        )?;
        let n = rec.current.len();
        let trace = motor_model::Simulator::new(*m, base.effects, rec.input.clone())
            .and_then(|s| s.with_step_factor(step_factor))
            .and_then(|s| s.run((n as f64 - 0.5) * rec.dt, 1.0 / rec.dt))
            .ok()?;
        if trace.t.len() != n {
            return None;
        }
        layouts.push((rows, trace, rec.dt));
    }
    let total: usize = layouts.iter().map(|(rows, _, _)| rows.len()).sum();
    // The propagator of one sub-step of each record: Φ and the input column Γ, from the
    // exponential of the augmented matrix [[A, B], [0, 0]] h.
    let propagator = |h: f64| -> (Matrix3<f64>, Vector3<f64>) {
        let a = Matrix4::new(
            -r / l,
            -k / l,
            0.0,
            0.0,
            k / j,
            -f / j,
            0.0,
            -1.0 / j,
            0.0,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ) * h;
        let e = a.exp();
        (
            e.fixed_view::<3, 3>(0, 0).into_owned(),
            e.fixed_view::<3, 1>(0, 3).into_owned(),
        )
    };
    let scored: Vec<(u32, f64)> = (1..=max_harmonic.max(1))
        .into_par_iter()
        .filter_map(|order| {
            let nf = f64::from(order);
            let mut columns = DMatrix::zeros(total, 2);
            let mut at = 0;
            for (rows, trace, dt) in &layouts {
                let n = trace.t.len();
                let turn = trace
                    .position
                    .windows(2)
                    .map(|w| (w[1] - w[0]).abs())
                    .fold(0.0_f64, f64::max);
                let sub = ((nf * turn / 0.5).ceil() as usize).clamp(1, PROBE_SUBSTEPS);
                let h = dt / sub as f64;
                let (phi, gamma) = propagator(h);
                for (c, shift) in [(0usize, 0.0), (1, std::f64::consts::FRAC_PI_2)] {
                    let mut x = Vector3::zeros();
                    let mut states = Vec::with_capacity(n);
                    states.push(x);
                    for i in 1..n {
                        if trace.stuck[i] && trace.stuck[i - 1] {
                            x = Vector3::new(x[0], 0.0, 0.0);
                        } else {
                            for q in 0..sub {
                                let w = (q as f64 + 0.5) / sub as f64;
                                let th = trace.position[i - 1]
                                    + w * (trace.position[i] - trace.position[i - 1]);
                                x = phi * x + gamma * (nf * th + shift).sin();
                            }
                        }
                        if !x.iter().all(|v| v.is_finite()) {
                            return None;
                        }
                        states.push(x);
                    }
                    let angle: Vec<f64> = states.iter().map(|x| x[2]).collect();
                    let encoder = motor_model::central_difference(&trace.t, &angle);
                    for (row, (channel, i, sigma, _)) in rows.iter().enumerate() {
                        let value = match channel {
                            Channel::Current => states[*i][0],
                            Channel::Speed => states[*i][1],
                            Channel::EncoderSpeed => encoder[*i],
                        };
                        columns[(at + row, c)] = value / sigma;
                    }
                }
                at += rows.len();
            }
            let score = projection.score(&columns);
            (score.testable && score.statistic.is_finite()).then_some((order, score.statistic))
        })
        .collect();
    let mut scored = scored;
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    Some(scored.into_iter().map(|(order, _)| order).collect())
}

/// The base Jacobian `jacobian` (rows of `residuals`, the training records of `base`) with a
/// column for the instant of every voltage jump of a training record. The voltage column
/// tells only between which two samples a jump fell; where the records' samples are coarse
/// beside the electrical time constant, that instant, L and anything acting at the jumps (a
/// sensor lag, a saturating inductance) change the same few samples, and the screening must
/// not credit an effect with what a jump half a period earlier explains
/// ([`crate::diagnose::screen`] projects these columns out with the motor's). Unchanged when
/// the rows cannot be rebuilt exactly.
fn with_jump_columns(
    jacobian: DMatrix<f64>,
    residuals: &[f64],
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> DMatrix<f64> {
    let model = (&base.motor, &base.effects);
    let Some(columns) = jump_columns(residuals, base.train, model, sigmas, step_factor) else {
        return jacobian;
    };
    if columns.is_empty() {
        return jacobian;
    }
    let p = jacobian.ncols();
    let mut out = jacobian.resize_horizontally(p + columns.len(), 0.0);
    for (c, col) in columns.iter().enumerate() {
        out.column_mut(p + c).copy_from_slice(&col.column);
    }
    out
}

/// The derivative of a record's weighted residual rows in the instant of one of its voltage
/// jumps, taken earlier (see [`jump_columns`]).
struct JumpColumn {
    /// The record.
    record: usize,
    /// The jump, in the record's piecewise-constant levels.
    jump: usize,
    /// `∂ rows / ∂(−t)`, zero outside the record's rows.
    column: Vec<f64>,
}

/// The columns of the weighted residual rows of `train` for `model` (`residuals`, as
/// [`output_error_sensitivity`] gives them: [`record_rows`] record after record) in the instant
/// of every voltage jump after a record's first sample, by a backward difference of
/// [`JUMP_DIFF_STEP`] sample periods. `None` when the rows cannot be rebuilt exactly.
fn jump_columns(
    residuals: &[f64],
    train: &[ExcitedRecord<'_>],
    model: (&MotorParams, &Effects),
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> Option<Vec<JumpColumn>> {
    let mut rows: Vec<Vec<f64>> = Vec::with_capacity(train.len());
    for (k, r) in train.iter().enumerate() {
        rows.push(row_values(&record_rows(
            k,
            r,
            r.input,
            model,
            sigmas,
            step_factor,
        )?));
    }
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    let same = flat.len() == residuals.len()
        && flat
            .iter()
            .zip(residuals)
            .all(|(a, b)| (a - b).abs() <= 1e-6 * (1.0 + b.abs()));
    if !same {
        return None;
    }
    let mut columns: Vec<JumpColumn> = Vec::new();
    let mut offset = 0;
    for (k, r) in train.iter().enumerate() {
        let levels = jump_levels(r.input);
        let h = JUMP_DIFF_STEP * r.dt;
        for j in 0..levels.len() {
            // The level a record starts at is not a jump.
            if levels[j].0 <= 0.0 {
                continue;
            }
            // Earlier by `h`, or later where that would reach the level before (a first jump
            // within `h` of the record's start): `sign` keeps the column `∂ rows / ∂(−t)`.
            let before = j.checked_sub(1).map_or(0.0, |i| levels[i].0.max(0.0));
            let sign = if levels[j].0 - h > before { 1.0 } else { -1.0 };
            let mut shifted = levels.clone();
            shifted[j].0 -= sign * h;
            let Some(moved) = Input::piecewise(&shifted)
                .ok()
                .and_then(|input| record_rows(k, r, &input, model, sigmas, step_factor))
                .map(|v| row_values(&v))
            else {
                continue;
            };
            if moved.len() != rows[k].len() {
                continue;
            }
            let mut column = vec![0.0; residuals.len()];
            for (i, (a, b)) in moved.iter().zip(&rows[k]).enumerate() {
                column[offset + i] = sign * (a - b) / h;
            }
            columns.push(JumpColumn {
                record: k,
                jump: j,
                column,
            });
        }
        offset += rows[k].len();
    }
    Some(columns)
}

/// Where jump `j` of `levels` (a record's voltage as the voltage column puts it: each jump on
/// the first sample showing it, as [`crate::voltage_input`] gives it, or half a period before
/// it, as [`crate::voltage_levels`] does) can have fallen: within the sample period before the
/// first sample showing it, and half a period after the jump before, or, for the first, just
/// after the record's start (a step on the first sample after the trigger can fall anywhere
/// before it; the level a record starts at is not a jump). `(lo, hi)` \[s\]; empty when
/// `lo ≥ hi`. Taken from the level's own start instead of that sample, a jump put half a
/// period early could not reach the later half of its period: `motorid diagnose` located a
/// step on a sample instant (a logger that steps on its clock) half a period early, and the
/// nominal fit bent L by 9 % to match.
fn jump_bracket(levels: &[(f64, f64)], j: usize, dt: f64) -> (f64, f64) {
    // The nearest sample to a quarter of a period after the level's start: the first sample
    // showing it for either convention, within a quarter period of a time column's jitter.
    let hi = (levels[j].0 / dt + 0.25).round() * dt;
    let after = match j.checked_sub(1).and_then(|i| levels.get(i)) {
        Some(l) if l.0 > 0.0 => l.0 + 0.5 * dt,
        _ => FIRST_JUMP_MARGIN * dt,
    };
    ((hi - dt).max(after), hi)
}

/// A piecewise-constant voltage's levels `(instant [s], volts [V])`; empty for other inputs.
fn jump_levels(input: &Input) -> Vec<(f64, f64)> {
    match input {
        Input::Piecewise { times_s, volts } => {
            times_s.iter().copied().zip(volts.iter().copied()).collect()
        }
        Input::Step { volts, at_s } => vec![(*at_s, *volts)],
        _ => Vec::new(),
    }
}

/// The training records' voltage jumps moved by one Gauss–Newton step of the nominal fit of
/// `motor` and those instants together, the motor's columns projected out
/// ([`BaseProjection::step`]): the move that accounts for how the motor's parameters follow
/// the instants. Locating the jumps beside a fixed model and refitting it in turn zig-zags
/// where both change the same few samples (a step's first samples when `L/R` is near the
/// sample period): a step late and an `L` short of the truth move each other a few per cent a
/// round. Each jump stays within its bracket on `grid` (the sample period before the first
/// sample showing it). `None` where the step cannot be taken (a record is returned unchanged
/// when none of its jumps moved).
fn jump_gauss_newton(
    train: &[ExcitedRecord<'_>],
    grid: &[ExcitedRecord<'_>],
    motor: &MotorParams,
    sigmas: &[(usize, Channel, f64)],
    step_factor: f64,
) -> Option<Vec<Option<Input>>> {
    let none = Effects::none();
    let lin = output_error_sensitivity(train, motor, &none, sigmas, None, step_factor).ok()?;
    let columns = jump_columns(&lin.residuals, train, (motor, &none), sigmas, step_factor)?;
    if columns.is_empty() {
        return None;
    }
    let projection = BaseProjection::new(&lin.residuals, &lin.jacobian, &lin.series)?;
    let signatures = |cols: &[&JumpColumn]| {
        let mut m = DMatrix::zeros(lin.residuals.len(), cols.len());
        for (c, col) in cols.iter().enumerate() {
            m.column_mut(c).copy_from_slice(&col.column);
        }
        m
    };
    // Every jump at once; where their columns are not testable together (a jump whose samples
    // are all held out, two jumps the records cannot tell apart), those testable alone.
    let mut used: Vec<&JumpColumn> = columns.iter().collect();
    let step = match projection.step(&signatures(&used)) {
        Some(step) => step,
        None => {
            used.retain(|c| projection.step(&signatures(&[*c])).is_some());
            projection.step(&signatures(&used))?
        }
    };
    let mut levels: Vec<Vec<(f64, f64)>> = train.iter().map(|r| jump_levels(r.input)).collect();
    for (col, delta) in used.iter().zip(step.iter()) {
        let (k, j) = (col.record, col.jump);
        let (Some(r), Some(g)) = (train.get(k), grid.get(k)) else {
            continue;
        };
        let bracket = jump_levels(g.input);
        if j >= bracket.len() {
            continue;
        }
        let (lo, hi) = jump_bracket(&bracket, j, r.dt);
        // The column is the derivative in −t: the rows follow r − c·Δt.
        let now = levels[k][j].0;
        let moved = (now - delta).clamp(lo.min(hi), hi);
        if moved.is_finite() {
            levels[k][j].0 = moved;
        }
    }
    Some(
        levels
            .iter()
            .zip(train)
            .map(|(l, r)| {
                if l.is_empty() {
                    Some(r.input.clone())
                } else {
                    Input::piecewise(l).ok()
                }
            })
            .collect(),
    )
}

/// `records` with record `k`'s input replaced by `inputs[k]` where that is given.
pub(crate) fn with_inputs<'a>(
    records: &[ExcitedRecord<'a>],
    inputs: &'a [Option<Input>],
) -> Vec<ExcitedRecord<'a>> {
    records
        .iter()
        .enumerate()
        .map(|(k, r)| match inputs.get(k).and_then(Option::as_ref) {
            Some(input) => ExcitedRecord { input, ..*r },
            None => *r,
        })
        .collect()
}

/// The scale each channel's residual is measured in: for a training record's channel the
/// level the nominal fit weighted it by (its residual RMS there); for a validation record's
/// channel, which no fit weighted, the nominal model's residual RMS on it. Without the second,
/// a validation channel would count in its own unit (A², (rad/s)²), its held-out errors would
/// not compare with the training ones nor with the parameter penalty, and a speed channel
/// would outweigh every current channel.
fn channel_scales(nominal: &FullFit, fitted: &[FittedChannel]) -> Vec<(usize, Channel, f64)> {
    let mut sigmas: Vec<(usize, Channel, f64)> = nominal
        .quality
        .iter()
        .map(|q| (q.test, q.channel, q.noise_std))
        .collect();
    for ch in fitted {
        if sigmas
            .iter()
            .any(|(r, c, _)| *r == ch.record && *c == ch.channel)
        {
            continue;
        }
        let rms = ch.residual_rms();
        if rms.is_finite() && rms > 0.0 {
            sigmas.push((ch.record, ch.channel, rms));
        }
    }
    sigmas
}

/// How many alternatives the screening picked `kind`'s fixed shape from by looking at the
/// residual: for a cogging torque, the period counts it screened ([`cogging_counts`]); for a
/// brush drop, whose knee current is not fitted, the knees of [`candidate_starts`] the
/// screening chose among; otherwise 1. Without the factor the shape that best matches the
/// noise of an effect-free record would be named an effect more often than α allows.
fn shapes_searched(
    kind: EffectKind,
    localisation: &Localisation,
    settings: &LocaliseSettings,
    records: &[ExcitedRecord<'_>],
) -> usize {
    match kind {
        EffectKind::CoggingTorque => {
            cogging_counts(ripple_periods(localisation), settings.max_harmonic).len()
        }
        EffectKind::BrushDrop => brush_knee_scales(records).len().max(1),
        _ => 1,
    }
}

/// The cogging period count the localisation's angle search points to: that of the channel
/// whose angle ripple is most significant, 6 when no channel was searched.
fn ripple_periods(localisation: &Localisation) -> u32 {
    localisation
        .records
        .iter()
        .flat_map(|r| &r.channels)
        .filter_map(|c| c.angle_ripple.as_ref())
        .min_by(|a, b| a.p_value.total_cmp(&b.p_value))
        .map_or(6, |a| a.periods_per_rev.max(1))
}

/// The cogging period counts N \[periods per revolution\] the screening looks at: `first` (the
/// angle search's, [`ripple_periods`]), then every other N from 1 to `max_harmonic`. The
/// angle search alone picks N from the residual against the angle on every record, the
/// validation records that do not excite the cogging among them, with a regression of
/// constant amplitude, while the ripple a cogging torque leaves falls as `1/(J N Ω)` with
/// speed and shows mostly where the motor turns slowly: a start at its N is refitted at the
/// wrong period count and falls to zero, and another effect acting at low speed (a Stribeck
/// friction) takes the gap. The screening ranks every N by the cogging's signature on the
/// training records ([`cogging_prefilter`]) and screens the best in full
/// ([`cogging_screened`]).
fn cogging_counts(first: u32, max_harmonic: u32) -> Vec<u32> {
    let mut counts = vec![first.max(1)];
    counts.extend((1..=max_harmonic.max(1)).filter(|&n| n != first.max(1)));
    counts
}

/// The current scales \[A\] a brush drop's knee is started from: each record's peak |I|,
/// largest first, those within a factor [`BRUSH_SCALE_RATIO`] of a larger one left out. The
/// knee is not fitted, and a knee far above the currents a record runs at makes the drop a
/// resistance there (`Vb/I_knee`, which R already spans): a step at a few times the breakaway
/// voltage runs hundreds of times below the high step's peak current.
fn brush_knee_scales(records: &[ExcitedRecord<'_>]) -> Vec<f64> {
    let mut peaks: Vec<f64> = records
        .iter()
        .map(peak_current)
        .filter(|p| p.is_finite() && *p > 0.0)
        .collect();
    peaks.sort_by(|a, b| b.total_cmp(a));
    let mut scales: Vec<f64> = Vec::new();
    for p in peaks {
        if scales
            .last()
            .is_none_or(|&last| last > BRUSH_SCALE_RATIO * p)
        {
            scales.push(p);
        }
    }
    scales
}

/// Peak currents within this factor of each other give one brush-knee start.
const BRUSH_SCALE_RATIO: f64 = 3.0;

/// Stribeck speeds the screening starts from, as fractions of the slowest record's peak speed
/// (the fit moves Ωs; the screening keeps the start whose signature explains most of the
/// residual, so that a refit does not start a decade away from a dip near Ω = 0).
const STRIBECK_START_FRACTIONS: [f64; 3] = [0.03, 0.1, 0.3];

/// Saturation currents the screening also starts from, as fractions of the records' peak
/// current (beside [`candidate_start`]'s twice that peak): far above the currents a record
/// runs at, the fall of L is `∝ I²` whatever its size, while a saturation current within them
/// gives an inductance that falls near `I = 0` and then holds — a shape the `I²` signature
/// does not span, so that the screening would miss it and a refit start a decade away.
const SATURATION_START_FRACTIONS: [f64; 3] = [0.1, 0.3, 1.0];

/// The starts of `kind` on `motor` the screening chooses among: [`candidate_start`]; for a
/// Stribeck friction also Stribeck speeds at [`STRIBECK_START_FRACTIONS`] of the slowest
/// record's peak speed; for a brush drop also the drop and knee of [`candidate_start`] scaled
/// to each smaller current scale of [`brush_knee_scales`]; for an inductance saturation also
/// saturation currents at [`SATURATION_START_FRACTIONS`] of the peak; for a cogging torque the period
/// counts `cogging` (the angle search's first; none given: that one alone).
fn candidate_starts(
    kind: EffectKind,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
    localisation: &Localisation,
    cogging: &[u32],
) -> Vec<Effect> {
    let first = candidate_start(kind, motor, records, localisation);
    if let (Effect::CoggingTorque(c), false) = (first, cogging.is_empty()) {
        return cogging
            .iter()
            .map(|&n| {
                Effect::CoggingTorque(CoggingTorque {
                    periods_per_rev: n,
                    ..c
                })
            })
            .collect();
    }
    let mut starts = vec![first];
    if let Effect::BrushDrop(b) = first {
        let scales = brush_knee_scales(records);
        if let Some(&top) = scales.first() {
            starts.extend(scales[1..].iter().map(|&i| {
                Effect::BrushDrop(BrushDrop {
                    drop_v: b.drop_v * i / top,
                    knee_current_a: b.knee_current_a * i / top,
                })
            }));
        }
    }
    if let Effect::StribeckFriction(s) = first {
        let (w_slowest, _) = records_peak_speeds(records);
        if w_slowest.is_finite() && w_slowest > 0.0 {
            starts.extend(STRIBECK_START_FRACTIONS.iter().map(|&x| {
                Effect::StribeckFriction(StribeckFriction {
                    stribeck_speed_rad_s: x * w_slowest,
                    ..s
                })
            }));
        }
    }
    if let Effect::InductanceSaturation(sat) = first {
        let i_max = records_peak_current(records);
        starts.extend(SATURATION_START_FRACTIONS.iter().map(|&x| {
            Effect::InductanceSaturation(InductanceSaturation {
                saturation_current_a: x * i_max,
                ..sat
            })
        }));
    }
    starts
}

/// The running trapezoidal integral of `speed` \[rad/s\] sampled every `dt` \[s\]: the angle
/// \[rad\] turned since the first sample.
fn integrated_angle(speed: &[f64], dt: f64) -> Vec<f64> {
    let mut theta = 0.0;
    let mut out = Vec::with_capacity(speed.len());
    for (i, w) in speed.iter().enumerate() {
        if i > 0 {
            theta += 0.5 * (speed[i - 1] + w) * dt;
        }
        out.push(theta);
    }
    out
}

/// A record's peak |I| \[A\].
fn peak_current(r: &ExcitedRecord<'_>) -> f64 {
    r.current.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// The records' peak |I| \[A\], at least 1 µA: the current scale the starts of
/// [`candidate_start`] and [`candidate_starts`] are taken from.
fn records_peak_current(records: &[ExcitedRecord<'_>]) -> f64 {
    records
        .iter()
        .map(peak_current)
        .fold(0.0_f64, f64::max)
        .max(1e-6)
}

/// A record's peak |Ω| \[rad/s\] (from its speed, else its angle's differences).
fn peak_speed(r: &ExcitedRecord<'_>) -> Option<f64> {
    r.speed
        .map(|s| s.iter().fold(0.0_f64, |m, v| m.max(v.abs())))
        .or_else(|| {
            r.position.map(|p| {
                p.windows(2)
                    .map(|w| ((w[1] - w[0]) / r.dt).abs())
                    .fold(0.0_f64, f64::max)
            })
        })
}

/// The slowest and the fastest of the records' peak |Ω| \[rad/s\] ([`peak_speed`]); `(∞, 0)`
/// when no record has a speed or an angle.
fn records_peak_speeds(records: &[ExcitedRecord<'_>]) -> (f64, f64) {
    records
        .iter()
        .filter_map(peak_speed)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), w| {
            (lo.min(w), hi.max(w))
        })
}

/// A small starting size of `kind` on `motor`, its shape from the records.
fn candidate_start(
    kind: EffectKind,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
    localisation: &Localisation,
) -> Effect {
    let peak = |f: &dyn Fn(&ExcitedRecord<'_>) -> Option<f64>| {
        records.iter().filter_map(f).fold(0.0_f64, f64::max)
    };
    let w_max = peak(&peak_speed).max(1e-3);
    let i_max = records_peak_current(records);
    let dt = records.iter().map(|r| r.dt).fold(f64::INFINITY, f64::min);
    let span = peak(&|r| Some(r.current.len() as f64 * r.dt));
    match kind {
        EffectKind::StribeckFriction => Effect::StribeckFriction(StribeckFriction {
            static_torque_nm: 1.5 * motor.ts_nm,
            stribeck_speed_rad_s: 0.05 * w_max,
        }),
        EffectKind::CoggingTorque => Effect::CoggingTorque(CoggingTorque {
            amplitude_nm: 0.1 * motor.ts_nm.max(1e-3 * motor.k_nm_per_a * i_max),
            periods_per_rev: ripple_periods(localisation),
            phase_rad: 0.3,
        }),
        // A tenth of the sample period or of L/R, whichever is shorter: small beside anything
        // a record resolves, and beside the rise of a current whose L/R is below the sample
        // period, so that the screening's signature is the lag's at zero size (the simulator
        // advances the filter exactly, so no time constant of it bounds the step).
        EffectKind::CurrentSensorLag => Effect::CurrentSensorLag(CurrentSensorLag {
            tau_f_s: 0.1 * dt.min(motor.l_henry / motor.r_ohm),
        }),
        EffectKind::ThermalDrift => {
            // A rise of a few kelvin over the records' span at their mean copper loss.
            let loss = records
                .iter()
                .map(|r| {
                    r.current.iter().map(|i| i * i).sum::<f64>() / r.current.len().max(1) as f64
                })
                .fold(0.0_f64, f64::max)
                * motor.r_ohm;
            let rth = 5.0 / loss.max(1e-9);
            Effect::ThermalDrift(ThermalDrift {
                thermal_resistance_k_per_w: rth,
                thermal_capacity_j_per_k: span.max(dt) / rth,
                alpha_per_k: COPPER_ALPHA_PER_K,
            })
        }
        EffectKind::QuadraticDrag => Effect::QuadraticDrag(QuadraticDrag {
            c_nms2_per_rad2: 0.1 * motor.f_nms_per_rad / w_max,
        }),
        EffectKind::BrushDrop => Effect::BrushDrop(BrushDrop {
            drop_v: 0.02 * motor.r_ohm * i_max,
            knee_current_a: 0.05 * i_max,
        }),
        EffectKind::InductanceSaturation => Effect::InductanceSaturation(InductanceSaturation {
            saturation_current_a: 2.0 * i_max,
            min_ratio: 0.9,
        }),
    }
}

/// Least sum of squares \[noise variances\] that a refitted effect's own part of the prediction
/// (the refit with and without the effect) must reach for its fall to be credited to it.
const EFFECT_PART_MIN: f64 = 1.0;

/// Sum over every sample of `a`'s channels of the squared difference from `b`'s, each over its
/// channel's noise level in `sigmas` \[noise variances\].
fn weighted_difference(
    a: &[FittedChannel],
    b: &[FittedChannel],
    sigmas: &[(usize, Channel, f64)],
) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let sigma = channel_sigma(sigmas, x.record, x.channel).unwrap_or(1.0);
            x.model
                .iter()
                .zip(&y.model)
                .map(|(p, q)| ((p - q) / sigma).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Share of the base model's L/R a sensor lag's absorbed start gives the lag
/// ([`absorbed_start`]).
const LAG_SPLIT: f64 = 0.5;

/// How many times the rise of [`candidate_start`]'s thermal drift a thermal drift's absorbed
/// start ([`absorbed_start`]) heats by (the same time constant).
const THERMAL_ABSORBED_RISE: f64 = 10.0;

/// An inductance saturation's absorbed start ([`absorbed_start`]): its saturation current
/// \[share of the training records' peak current\] and its ratio `r`.
const SATURATION_ABSORBED: (f64, f64) = (0.3, 0.5);

/// Share of the base model's Ts a Stribeck friction's absorbed start keeps as the sliding
/// friction Ts ([`absorbed_start`]).
const STRIBECK_SPLIT: f64 = 0.5;

/// A refitted Stribeck speed is taken as one the records visit between these multiples of the
/// slowest and the fastest record's peak speed ([`stribeck_within_records`]).
const STRIBECK_VISITED: (f64, f64) = (1e-3, 1e3);

/// Whether `fit`'s Stribeck friction falls at a speed `records` visit
/// ([`STRIBECK_VISITED`]): not a step of friction at rest (Ωs → 0) nor a constant level
/// (Ωs → ∞), the two ends a refit from the base model's single level runs to.
fn stribeck_within_records(fit: &FullFit, records: &[ExcitedRecord<'_>]) -> bool {
    let Some(Effect::StribeckFriction(s)) = fit.effects.get(EffectKind::StribeckFriction) else {
        return false;
    };
    let (slowest, fastest) = records_peak_speeds(records);
    s.stribeck_speed_rad_s >= STRIBECK_VISITED.0 * slowest
        && s.stribeck_speed_rad_s <= STRIBECK_VISITED.1 * fastest
}

/// A start for `kind` beside the model that absorbed it, where the effect trades against a
/// motor parameter the base fit has already moved to mimic it (from the base model, growing
/// the effect alone only adds to what that parameter does):
/// - a sensor lag: L cut by [`LAG_SPLIT`] and the lag given that share of L/R (a first-order
///   sensor after a first-order electrical response delays the current by about the sum of
///   their time constants, which a model without the sensor gives its L/R alone);
/// - an inductance saturation ([`SATURATION_ABSORBED`]): L0 raised so that the saturating
///   inductance, averaged over the training records' current weighted by how fast it moves
///   (where L acts), is the base model's L;
/// - a thermal drift (`start`'s heating, [`THERMAL_ABSORBED_RISE`] times its rise): R0 lowered
///   so that the heated resistance, averaged over the training records weighted by I² (the
///   drop R·I squared, as the fit weighs it), is the base model's R — the base fit took a
///   winding that heats for one at its mean temperature;
/// - a Stribeck friction (`start`'s Stribeck speed): the base model's Ts kept as the static
///   level Tst and Ts cut to [`STRIBECK_SPLIT`] of it — a fit without the fall of friction
///   with speed sets its one level where the records break away and crawl, which is Tst.
///
/// `None` for the other effects, or when the motor would not be one.
fn absorbed_start(
    kind: EffectKind,
    start: Effect,
    motor: &MotorParams,
    records: &[ExcitedRecord<'_>],
) -> Option<(MotorParams, Effect)> {
    let with = |r_ohm: f64, l_henry: f64| with_electrical(motor, r_ohm, l_henry);
    let with_l = |l_henry: f64| with(motor.r_ohm, l_henry);
    match kind {
        EffectKind::ThermalDrift => {
            let Effect::ThermalDrift(heat) = start else {
                return None;
            };
            let heat = ThermalDrift {
                thermal_resistance_k_per_w: THERMAL_ABSORBED_RISE * heat.thermal_resistance_k_per_w,
                thermal_capacity_j_per_k: heat.thermal_capacity_j_per_k / THERMAL_ABSORBED_RISE,
                ..heat
            };
            let tau = heat.thermal_resistance_k_per_w * heat.thermal_capacity_j_per_k;
            let (mut weighted, mut weight) = (0.0, 0.0);
            for r in records {
                // Each record starts at the ambient temperature; ΔT advanced over each sample
                // period as the exact solution for that period's copper loss, taken in the
                // base model's R (without the heating's own rise of R: second order here).
                let decay = (-r.dt / tau).exp();
                let mut rise = 0.0;
                for &i in r.current {
                    let factor = 1.0 + heat.alpha_per_k * rise;
                    weighted += i * i * factor;
                    weight += i * i;
                    let steady = i * i * motor.r_ohm * heat.thermal_resistance_k_per_w;
                    rise = steady + (rise - steady) * decay;
                }
            }
            let mean = weighted / weight;
            (mean.is_finite() && mean > 0.0).then_some(())?;
            Some((
                with(motor.r_ohm / mean, motor.l_henry)?,
                Effect::ThermalDrift(heat),
            ))
        }
        EffectKind::CurrentSensorLag => Some((
            with_l(motor.l_henry * (1.0 - LAG_SPLIT))?,
            Effect::CurrentSensorLag(CurrentSensorLag {
                tau_f_s: LAG_SPLIT * motor.l_henry / motor.r_ohm,
            }),
        )),
        EffectKind::InductanceSaturation => {
            let (share, ratio) = SATURATION_ABSORBED;
            let sat = InductanceSaturation {
                saturation_current_a: share * records_peak_current(records),
                min_ratio: ratio,
            };
            let (mut weighted, mut weight) = (0.0, 0.0);
            for r in records {
                for w in r.current.windows(2) {
                    let moved = (w[1] - w[0]).abs();
                    weighted += moved * sat.factor(0.5 * (w[0] + w[1]));
                    weight += moved;
                }
            }
            let mean = weighted / weight;
            (mean.is_finite() && mean > 0.0).then_some(())?;
            Some((
                with_l(motor.l_henry / mean)?,
                Effect::InductanceSaturation(sat),
            ))
        }
        EffectKind::StribeckFriction => {
            let Effect::StribeckFriction(stribeck) = start else {
                return None;
            };
            let sliding = MotorParams::new(
                motor.r_ohm,
                motor.l_henry,
                motor.k_nm_per_a,
                motor.f_nms_per_rad,
                motor.j_kgm2,
                STRIBECK_SPLIT * motor.ts_nm,
            )
            .ok()?;
            Some((
                sliding,
                Effect::StribeckFriction(StribeckFriction {
                    static_torque_nm: motor.ts_nm,
                    ..stribeck
                }),
            ))
        }
        _ => None,
    }
}

/// [`locate_every_jump`] on records `which` of `grid` (entry 0 is record `which.start`),
/// searched within the sample periods of `grid` (the records with their jumps where the
/// voltage column puts them); a record whose jumps stay keeps `grid`'s ([`filled_from_grid`]).
fn located_inputs(
    grid: &[ExcitedRecord<'_>],
    which: std::ops::Range<usize>,
    motor: &MotorParams,
    effects: &Effects,
    sigmas: &[(usize, Channel, f64)],
    settings: &DiagnoseSettings,
) -> Vec<Option<Input>> {
    let located = locate_every_jump(
        grid,
        which.clone(),
        motor,
        effects,
        sigmas,
        settings.step_factor,
    );
    filled_from_grid(located, &grid[which])
}

/// `located` (one entry per record of `grid`, `None` where a record's jumps stay) with every
/// `None` replaced by that record's own voltage: every entry `Some`, as [`with_inputs`] takes
/// them to replace every record's voltage.
fn filled_from_grid(located: Vec<Option<Input>>, grid: &[ExcitedRecord<'_>]) -> Vec<Option<Input>> {
    located
        .into_iter()
        .zip(grid)
        .map(|(moved, r)| moved.or_else(|| Some(r.input.clone())))
        .collect()
}

/// Whether a converged fit refused for `refusal` still gives a model the diagnosis can judge
/// by its prediction (`kind`: the effect refitted; `None` for the nominal fit): refused only
/// because the records do not determine every parameter (no intervals, or one too wide) — a
/// motor parameter (an L whose time constant is far below the sample period, an f far below
/// the electrical damping k²/R), or the effect's own (a thermal drift whose time constant is
/// far longer than the records, whose heating rate they still show). The prediction is the
/// same whatever the undetermined parameter's value within its interval, so the effect is
/// there or not all the same; the report keeps the intervals there are, and a refit whose
/// effect parameters are undetermined is named only when its held-out improvement is
/// significant. A nominal model that explains a channel worse than its mean is what a large
/// unmodelled effect does, and is diagnosed too. Any other refusal (parameters no motor could
/// have) is not a model to build on.
fn diagnosable(refusal: &crate::Refusal, kind: Option<EffectKind>) -> bool {
    match refusal {
        crate::Refusal::NoIntervals | crate::Refusal::Vanished { .. } => true,
        crate::Refusal::WorseThanConstant { .. } => kind.is_none(),
        crate::Refusal::Undetermined { parameter, .. } => {
            PARAM_NAMES.contains(parameter)
                || kind.is_some_and(|k| k.params().iter().any(|p| p.symbol == *parameter))
        }
        _ => false,
    }
}

/// L/R \[sample periods\] the nominal fit of [`diagnose`] starts again from when it ran L/R
/// below it.
const SLOWEST_START_L_OVER_R: f64 = 0.5;

/// `motor` with its L raised so that L/R is [`SLOWEST_START_L_OVER_R`] of the longest sample
/// period of `records`; `None` when it is that long already (or would not be a motor).
fn slower_electrical(motor: &MotorParams, records: &[ExcitedRecord<'_>]) -> Option<MotorParams> {
    let dt = records.iter().map(|r| r.dt).fold(0.0, f64::max);
    let l_henry = SLOWEST_START_L_OVER_R * dt * motor.r_ohm;
    (l_henry > motor.l_henry).then_some(())?;
    with_electrical(motor, motor.r_ohm, l_henry)
}

/// `motor` with R \[Ω\] and L \[H\] replaced (`None` if that is no motor).
fn with_electrical(motor: &MotorParams, r_ohm: f64, l_henry: f64) -> Option<MotorParams> {
    MotorParams::new(
        r_ohm,
        l_henry,
        motor.k_nm_per_a,
        motor.f_nms_per_rad,
        motor.j_kgm2,
        motor.ts_nm,
    )
    .ok()
}

/// NRMSE of a training channel at or above which the base model is taken not to explain it: a
/// refit that leaves it worse than a constant (NRMSE above 1), but by no more than
/// `1 − UNEXPLAINED_CHANNEL` above the base model, is not refused for it.
const UNEXPLAINED_CHANNEL: f64 = 0.95;

/// Whether a nominal fit is one the diagnosis builds on: accepted, or converged and refused
/// only for what [`diagnosable`] allows a nominal model.
fn usable_nominal(fit: &FullFit) -> bool {
    fit.failure().is_none()
        || (fit.termination.converged()
            && fit.refusal.as_ref().is_some_and(|r| diagnosable(r, None)))
}

/// Whether a refit determines the effect's size: every fitted parameter has an interval no
/// wider than a hundred times its value.
fn determined(estimates: &[EffectEstimate]) -> bool {
    !estimates.is_empty()
        && estimates.iter().all(|e| {
            e.ci95
                .is_some_and(|[lo, hi]| (hi - lo).is_finite() && hi - lo <= 100.0 * e.value.abs())
        })
}

/// Everything one stage needs about the model it starts from.
struct Base<'a> {
    motor: MotorParams,
    effects: Effects,
    /// Its prediction on every sample of every record (training and held out).
    fitted: Vec<FittedChannel>,
    train: &'a [ExcitedRecord<'a>],
    all: &'a [ExcitedRecord<'a>],
    /// `all` with every voltage jump where the voltage column puts it (on the first sample
    /// that shows it), the bracket a refit's jumps are located in.
    grid: &'a [ExcitedRecord<'a>],
}

/// Identifies the motor on `records`, localises its residual and looks for the unmodelled
/// effects among [`DiagnoseSettings::candidates`] (module docs). `validation` records, if any,
/// are held out whole; otherwise blocks of `records` are. `start` is the start of the nominal
/// fit (e.g. [`crate::equation_error_start`]). `names` label the records in the localisation
/// (training first, then validation). `progress` is called as the work advances.
pub fn diagnose(
    records: &[ExcitedRecord<'_>],
    validation: &[ExcitedRecord<'_>],
    names: &[&str],
    start: &MotorParams,
    settings: &DiagnoseSettings,
    progress: &(dyn Fn(DiagnoseProgress) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    if records.is_empty() {
        return Err(FitError::BadData {
            series: "records".into(),
            reason: "no record given".into(),
        }
        .into());
    }
    // The channels and masks must align before the held-out blocks are merged into the masks.
    let shown = super::record_names(names, records.len() + validation.len());
    for (r, name) in records.iter().chain(validation).zip(&shown) {
        crate::checks::check_aligned(name, r.channels())?;
        crate::checks::check_current_varies(name, r.current)?;
    }
    // The training records: whole, or with their held-out blocks excluded.
    let masks =
        (validation.is_empty() || settings.split_with_validation).then(|| split(records, settings));
    let train: Vec<ExcitedRecord<'_>> = match &masks {
        Some(m) => records
            .iter()
            .enumerate()
            .map(|(k, r)| ExcitedRecord {
                exclude_current: Some(&m.current_masks[k]),
                exclude_speed: Some(&m.speed_masks[k]),
                ..*r
            })
            .collect(),
        None => records.to_vec(),
    };
    // Every record the held-out error is judged on, and which samples of each are held out.
    let all: Vec<ExcitedRecord<'_>> = records.iter().chain(validation).copied().collect();
    let held: Vec<Vec<bool>> = match &masks {
        Some(m) => m.held.clone(),
        None => records
            .iter()
            .map(|r| vec![false; r.current.len()])
            .collect(),
    }
    .into_iter()
    .chain(validation.iter().map(|r| vec![true; r.current.len()]))
    .collect();
    let blocks = || {
        format!(
            "every {}th block of {} samples of each record held out ({} %; shorter blocks on \
             a record under {} samples, so that it lends two)",
            settings.holdout_every.max(2),
            settings.block_samples.max(1),
            100 / settings.holdout_every.max(2),
            2 * settings.holdout_every.max(2) * settings.block_samples.max(1)
        )
    };
    let heldout = match (&masks, validation.len()) {
        (Some(_), 0) => format!("no validation record: {}", blocks()),
        (Some(_), n) => format!("{n} validation record(s) held out whole, and {}", blocks()),
        (None, n) => format!("{n} validation record(s) held out whole"),
    };

    progress(DiagnoseProgress::Nominal);
    let predict_nominal = |records: &[ExcitedRecord<'_>], motor: &MotorParams| {
        predict_with_step_factor(records, motor, &Effects::none(), settings.step_factor)
    };
    let nominal = fit_nominal(&train, start, settings, None)?;
    // A nominal fit that ran L/R below what the records show may have stopped in a wrong
    // minimum there (the current's rise lost, the rest bent to match): refitted from L/R at
    // [`SLOWEST_START_L_OVER_R`] sample periods, the one with the lower training NRMSE kept.
    let nominal = match slower_electrical(&nominal.params, &train) {
        Some(slower) => match fit_nominal(&train, &slower, settings, None) {
            Ok(second)
                if usable_nominal(&second)
                    && (!usable_nominal(&nominal)
                        || nrmse_summary(&second.fitted, |_, _| true)
                            < nrmse_summary(&nominal.fitted, |_, _| true)) =>
            {
                second
            }
            _ => nominal,
        },
        None => nominal,
    };
    // A channel the nominal model explains worse than its mean is what an unmodelled effect
    // can do, and a motor parameter the records do not determine leaves the prediction the
    // diagnosis works on as good as any value of it would: diagnosed, and said
    // (`nominal_note`). Any other failure stops here.
    let nominal_note = match nominal.failure() {
        None => None,
        Some(why) if !usable_nominal(&nominal) => return Err(DiagnoseError::NominalFailed(why)),
        Some(_) => nominal.refusal.as_ref().map(ToString::to_string),
    };
    let nominal_all = predict_nominal(&all, &nominal.params)?;
    // Each voltage jump moved to where, within its sample period, the nominal model puts it
    // (the voltage column says only between which two samples it fell), then the nominal
    // model refitted on those instants: from here on every fit and test uses them.
    let sigmas = channel_scales(&nominal, &nominal_all);
    let grid = all.clone();
    let located = locate_every_jump(
        &all,
        0..all.len(),
        &nominal.params,
        &Effects::none(),
        &sigmas,
        settings.step_factor,
    );
    let train_grid = train;
    // The nominal model refitted on the located instants and its jumps located again, in
    // turn, until they stop moving. The early samples of a step tie L to the step's instant:
    // located beside a fixed model, a step comes out late and L short, and each round moves
    // them only a little, so the training records' jumps the refit is made on next are moved
    // by the joint Gauss–Newton step ([`jump_gauss_newton`]) instead; the instants kept are
    // those located beside the last refit, as every candidate's are beside its own.
    // A record whose jumps could not move keeps its own.
    let any_moved = located.iter().any(Option::is_some);
    let mut inputs = filled_from_grid(located, &grid);
    let mut fit_at = inputs.clone();
    let mut nominal = nominal;
    let n_train = train_grid.len();
    // The last accepted round's noise scales, its validation records' located jumps, and its
    // training records' when it located them (not when the joint step moved them): the
    // training jumps are located once, beside the model the rounds end on.
    struct RoundEnd {
        sigmas: Vec<(usize, Channel, f64)>,
        valid: Vec<Option<Input>>,
        train_located: Option<Vec<Option<Input>>>,
    }
    let mut last_round: Option<RoundEnd> = None;
    if any_moved {
        for round in 0..NOMINAL_LOCATE_ROUNDS {
            let train_now = with_inputs(&train_grid, &fit_at);
            // A refit that fails after the first keeps the model of the round before.
            let refit = match fit_nominal(&train_now, &nominal.params, settings, None) {
                Ok(refit) => refit,
                Err(e) if round == 0 => return Err(e.into()),
                Err(_) => break,
            };
            // The refit on the located instants replaces the model only when it is a result
            // too.
            nominal = match (refit.failure(), refit.termination.converged()) {
                (None, _) => refit,
                (Some(_), true) if nominal_note.is_some() => refit,
                _ => break,
            };
            let all_now = with_inputs(&grid, &fit_at);
            let sigmas = channel_scales(&nominal, &predict_nominal(&all_now, &nominal.params)?);
            let none = Effects::none();
            let valid = located_inputs(
                &grid,
                n_train..grid.len(),
                &nominal.params,
                &none,
                &sigmas,
                settings,
            );
            let (train_next, train_located) = match jump_gauss_newton(
                &train_now,
                &grid[..n_train],
                &nominal.params,
                &sigmas,
                settings.step_factor,
            ) {
                Some(stepped) => (stepped, None),
                None => {
                    let located = located_inputs(
                        &grid,
                        0..n_train,
                        &nominal.params,
                        &none,
                        &sigmas,
                        settings,
                    );
                    (located.clone(), Some(located))
                }
            };
            let next: Vec<Option<Input>> = train_next
                .into_iter()
                .chain(valid.iter().cloned())
                .collect();
            let moved = largest_jump_move(&fit_at, &next, &grid);
            fit_at = next;
            last_round = Some(RoundEnd {
                sigmas,
                valid,
                train_located,
            });
            if moved < NOMINAL_LOCATE_SETTLED {
                break;
            }
        }
    }
    if let Some(RoundEnd {
        sigmas,
        valid,
        train_located,
    }) = last_round
    {
        let train_located = train_located.unwrap_or_else(|| {
            located_inputs(
                &grid,
                0..n_train,
                &nominal.params,
                &Effects::none(),
                &sigmas,
                settings,
            )
        });
        inputs = train_located.into_iter().chain(valid).collect();
    }
    let train: Vec<ExcitedRecord<'_>> = with_inputs(&train_grid, &inputs);
    let all: Vec<ExcitedRecord<'_>> = with_inputs(&grid, &inputs);
    let nominal_all = predict_nominal(&all, &nominal.params)?;
    // The noise level of each channel, as the nominal fit weighted it: the same for every
    // candidate, so that their held-out errors compare.
    let sigmas = channel_scales(&nominal, &nominal_all);
    let localisation = localise_fit(&all, &nominal_all, names, &settings.localise)?;

    // A stage's records carry the jump instants of the model it starts from: the nominal
    // model's for the first, the chosen refit's for the next (one slot per stage, filled once).
    let stage_inputs: Vec<std::cell::OnceCell<Vec<Option<Input>>>> =
        (0..settings.max_effects.max(1))
            .map(|_| Default::default())
            .collect();
    let stage_records: Vec<std::cell::OnceCell<(Vec<ExcitedRecord<'_>>, Vec<ExcitedRecord<'_>>)>> =
        (0..settings.max_effects.max(1))
            .map(|_| Default::default())
            .collect();
    let mut stages: Vec<Stage> = Vec::new();
    let mut base = Base {
        motor: nominal.params,
        effects: Effects::none(),
        fitted: nominal_all,
        train: &train,
        all: &all,
        grid: &grid,
    };
    for stage_no in 1..=settings.max_effects.max(1) {
        let kinds: Vec<EffectKind> = settings
            .candidates
            .iter()
            .copied()
            .filter(|k| base.effects.get(*k).is_none())
            .collect();
        if kinds.is_empty() {
            break;
        }
        let stage = run_stage(
            stage_no,
            &kinds,
            &base,
            &held,
            &sigmas,
            &localisation,
            settings,
            progress,
        );
        let chosen = stage.verdict.verdict.clone();
        let next = chosen.as_ref().and_then(|name| {
            stage
                .candidates
                .iter()
                .find(|c| c.name == name.as_str())
                .and_then(|c| c.motor.map(|m| (m, c.effects, c.inputs.clone())))
        });
        stages.push(stage);
        let Some((motor, effects, inputs)) = next else {
            break;
        };
        // The next stage starts from the model with the chosen effect, on its jump instants.
        let (Some(slot), Some(records)) = (
            stage_inputs.get(stage_no - 1),
            stage_records.get(stage_no - 1),
        ) else {
            break;
        };
        let inputs = slot.get_or_init(|| inputs);
        let (train_now, all_now) =
            records.get_or_init(|| (with_inputs(&train, inputs), with_inputs(&all, inputs)));
        let fitted = predict_with_step_factor(all_now, &motor, &effects, settings.step_factor)?;
        base = Base {
            motor,
            effects,
            fitted,
            train: train_now,
            all: all_now,
            grid: &grid,
        };
    }
    Ok(Diagnosis {
        nominal,
        nominal_note,
        heldout,
        held,
        localisation,
        stages,
    })
}

/// The nominal model (no effect) fitted by output error to `records` from `from`, with
/// `settings`' solver and RK4 step, each channel weighted by its level in `sigmas` or, without,
/// by its own residual.
pub(crate) fn fit_nominal(
    records: &[ExcitedRecord<'_>],
    from: &MotorParams,
    settings: &DiagnoseSettings,
    sigmas: Option<&[(usize, Channel, f64)]>,
) -> Result<FullFit, FitError> {
    fit_output_error(
        records,
        &[],
        &[],
        from,
        &Effects::none(),
        settings.lm,
        settings.step_factor,
        sigmas,
    )
}

/// The localisation ([`localise`]) of a fit's residual on the records it was fitted to:
/// `fitted` are the fit's channels ([`crate::FullFit::fitted`], `record` indexing `all`), the
/// records give the voltage, current, speed and angle that place each sample in its phase,
/// operating region and shaft angle (a record without an encoder gets the integral of its
/// tachometer speed). A channel with samples left out of the fit (clipped at a rail) is not
/// localised. `names` label the records (`record k` where missing).
///
/// `motorid identify` runs it on every accepted fit: a significant finding means the records
/// show what the model does not (an unmodelled effect), so the intervals, which assume a
/// complete model, do not hold the bias it leaves.
pub fn localise_fit(
    all: &[ExcitedRecord<'_>],
    fitted: &[FittedChannel],
    names: &[&str],
    settings: &LocaliseSettings,
) -> Result<Localisation, FitError> {
    let voltages: Vec<Vec<f64>> = all
        .iter()
        .map(|r| {
            (0..r.current.len())
                .map(|i| r.input.volts_at(i as f64 * r.dt))
                .collect()
        })
        .collect();
    let speeds: Vec<Option<Vec<f64>>> = all
        .iter()
        .map(|r| {
            r.speed.map(<[f64]>::to_vec).or_else(|| {
                r.position.map(|p| {
                    let t: Vec<f64> = (0..p.len()).map(|i| i as f64 * r.dt).collect();
                    motor_model::central_difference(&t, p)
                })
            })
        })
        .collect();
    // A record without an encoder still turns: its angle is the running integral of its
    // speed (trapezoids from 0 at the first sample, where the motor starts), so that ripple
    // locked to the rotation is searched there too. The tachometer's noise integrates to a
    // random walk of σ_Ω dt √n, far below a cogging period over a record.
    let angles: Vec<Option<Vec<f64>>> = all
        .iter()
        .map(|r| match (r.position, r.speed) {
            (None, Some(w)) => Some(integrated_angle(w, r.dt)),
            _ => None,
        })
        .collect();
    let shown = super::record_names(names, all.len());
    let records: Vec<ResidualRecord<'_>> = all
        .iter()
        .enumerate()
        .map(|(k, r)| ResidualRecord {
            name: &shown[k],
            dt: r.dt,
            voltage: &voltages[k],
            current: Some(r.current),
            speed: speeds[k].as_deref(),
            angle: r.position.or(angles[k].as_deref()),
            channels: fitted
                .iter()
                .filter(|c| c.record == k && c.samples.len() == r.current.len())
                .map(|c| ResidualChannel {
                    kind: c.channel,
                    measured: &c.measured,
                    model: &c.model,
                })
                .collect(),
        })
        .collect();
    localise(&records, settings)
}

/// A candidate's report, its held-out block errors and its training likelihood-ratio
/// statistic (empty and `None` when it was not refitted, or its refit failed).
type Refit = (CandidateReport, Vec<f64>, Option<f64>);

/// A candidate's [`Refit`] as [`rank_candidates`] scores it, against the held-out blocks'
/// squared errors before (`sse_before`); `searched` as [`CandidateScore::searched`].
fn refit_score<'a>(
    (report, sse, statistic): &'a Refit,
    searched: usize,
    sse_before: &'a [f64],
) -> CandidateScore<'a> {
    CandidateScore {
        name: report.name,
        extra_params: report.params.len(),
        testable: report.testable,
        train_statistic: *statistic,
        searched,
        heldout_sse_before: sse_before,
        heldout_sse_after: sse,
    }
}

/// The screening of `kinds` on top of `base` (see [`crate::diagnose::screen`]), in their
/// order, each with the start its refit begins from (of [`candidate_starts`], the testable one
/// of largest statistic): `None` for a candidate whose signature could not be simulated, and
/// for every one when the base model cannot be linearised (those are refitted unscreened, from
/// [`candidate_start`]).
fn screen_stage(
    kinds: &[EffectKind],
    base: &Base<'_>,
    sigmas: &[(usize, Channel, f64)],
    localisation: &Localisation,
    settings: &DiagnoseSettings,
) -> Vec<(Option<Screening>, RefitStart)> {
    let factor = settings.step_factor;
    let projection =
        output_error_sensitivity(base.train, &base.motor, &base.effects, sigmas, None, factor)
            .ok()
            .and_then(|lin| {
                let jacobian =
                    with_jump_columns(lin.jacobian.clone(), &lin.residuals, base, sigmas, factor);
                BaseProjection::new(&lin.residuals, &jacobian, &lin.series)
            });
    let Some(projection) = projection else {
        return kinds
            .iter()
            .map(|&kind| {
                (
                    None,
                    RefitStart::plain(candidate_start(kind, &base.motor, base.train, localisation)),
                )
            })
            .collect();
    };
    let cogging = if kinds.contains(&EffectKind::CoggingTorque) {
        cogging_screened(base, sigmas, &projection, localisation, settings)
    } else {
        Vec::new()
    };
    // Every candidate's starts at once on rayon's pool (a kind of one start alone would
    // leave a core idle).
    kinds
        .par_iter()
        .map(|&kind| {
            let starts = candidate_starts(kind, &base.motor, base.train, localisation, &cogging);
            let scored: Vec<(Option<Screening>, RefitStart)> = starts
                .par_iter()
                .map(|&effect| {
                    let effects = base.effects.with(effect);
                    let sig = output_error_sensitivity(
                        base.train,
                        &base.motor,
                        &effects,
                        sigmas,
                        Some(kind),
                        factor,
                    )
                    .ok();
                    let start = RefitStart {
                        stepped: sig.as_ref().map_or(effect, |sig| {
                            stepped_start(effect, base.motor.ts_nm, &sig.jacobian, &projection)
                        }),
                        plain: effect,
                    };
                    let score = sig.map(|sig| {
                        let score = projection.score(&sig.jacobian);
                        if asks_for_negative_size(kind, &sig.jacobian, &projection) {
                            Screening {
                                statistic: 0.0,
                                p_value: 1.0,
                                ..score
                            }
                        } else {
                            score
                        }
                    });
                    (score, start)
                })
                .collect();
            // The first start unless another is testable with a larger statistic.
            let rank = |x: &Option<Screening>| {
                x.filter(|s| s.testable)
                    .map_or(f64::NEG_INFINITY, |s| s.statistic)
            };
            let (score, start) = scored
                .iter()
                .copied()
                .reduce(|best, next| {
                    if rank(&next.0) > rank(&best.0) {
                        next
                    } else {
                        best
                    }
                })
                .unwrap_or((None, RefitStart::plain(starts[0])));
            // A fixed shape picked as the best of several (a cogging torque's period count)
            // has its screening p-value multiplied by their number (Bonferroni), so that the
            // best of the noise does not take a refit from an effect present.
            let searched = shapes_searched(kind, localisation, &settings.localise, base.train);
            let score = score.map(|s| Screening {
                p_value: (s.p_value * searched as f64).min(1.0),
                ..s
            });
            (score, start)
        })
        .collect()
}

/// Where a candidate's refit begins: the screening's linear step from a start of
/// [`candidate_starts`] ([`stepped_start`]), and that start itself, which the refit falls
/// back to when the step lands where the records' sample rate cannot simulate (a brush drop
/// grown a hundredfold puts a resistance `Vb/I_knee` in series that makes `L/R` far shorter
/// than a sample period).
#[derive(Debug, Clone, Copy)]
struct RefitStart {
    /// The stepped start.
    stepped: Effect,
    /// The start before the step.
    plain: Effect,
}

impl RefitStart {
    /// A start without a step.
    fn plain(effect: Effect) -> Self {
        RefitStart {
            stepped: effect,
            plain: effect,
        }
    }
}

/// Whether the residual asks `kind`, an effect of one parameter whose response is
/// proportional to it at small sizes (a sensor lag's `τf`, a drag's `c`, a brush drop's `Vb`),
/// for a size below zero: the screening's linear step from zero size ([`BaseProjection::step`]
/// of its signature) is negative. No size of such an effect explains that residual (a current
/// read *ahead* of the model is no lag, a drag that pushes is no drag), so its screening is
/// one-sided: statistic 0, and the refit goes to a candidate that could explain the residual.
fn asks_for_negative_size(
    kind: EffectKind,
    signatures: &DMatrix<f64>,
    projection: &BaseProjection,
) -> bool {
    let one_sided = matches!(
        kind,
        EffectKind::CurrentSensorLag | EffectKind::QuadraticDrag | EffectKind::BrushDrop
    );
    one_sided
        && signatures.ncols() == 1
        && size_step(signatures, projection).is_some_and(|d| d < 0.0)
}

/// The screening's linear step ([`BaseProjection::step`]) of an effect's first parameter, its
/// size, on that parameter's signature column alone; `None` without columns or when that
/// column is not testable.
fn size_step(signatures: &DMatrix<f64>, projection: &BaseProjection) -> Option<f64> {
    if signatures.ncols() == 0 {
        return None;
    }
    projection
        .step(&signatures.columns(0, 1).into_owned())
        .map(|step| step[0])
}

/// Largest factor by which [`stepped_start`] grows or shrinks an effect's size \[-\]: the
/// linear step of a size far from the start's is a guide, not a value.
const SIZE_STEP_LIMIT: f64 = 1e3;

/// The refit start of `effect` moved by the screening's Gauss–Newton step
/// ([`BaseProjection::step`], in the fit's coordinates of its parameters, from `signatures`,
/// their Jacobian columns at the start) where the step is exact in the effect's signature
/// space, which its response spans to first order in its size:
/// - a cogging torque `A sin(Nθ + φ)`, `θ = (ln A, φ)`: its columns `A s(φ)` and `A c(φ)`
///   span the ripple at every phase, so the stepped signature `A (1 + δ₁) s + A δ₂ c` is the
///   ripple `A' sin(Nθ + φ + ψ)` with `A' = A hypot(1 + δ₁, δ₂)` and `ψ = atan2(δ₂, 1 + δ₁)`.
///   A refit from the start's phase collapses to `A → 0` when the ripple present is more
///   than a quarter period away (its first steps shrink `A` before they turn φ);
/// - an effect whose load or drop is proportional to its first parameter (the drag's `c`,
///   the brush drop's `Vb`, the Stribeck excess `Tst − Ts`), `θ₁` its logarithm: the step
///   of that column alone gives the size `v (1 + δ)` the residual asks for (kept when `1 + δ`
///   is not positive: the residual asks for the opposite sign), within a factor
///   [`SIZE_STEP_LIMIT`]. The fit's own first step moves `ln v` by `δ`, which overshoots
///   `e^δ/(1 + δ)` times, and is refused and damped over several iterations.
///
/// Other effects keep their start.
fn stepped_start(
    effect: Effect,
    motor_ts: f64,
    signatures: &DMatrix<f64>,
    projection: &BaseProjection,
) -> Effect {
    let grow = |delta: f64| -> Option<f64> {
        let m = 1.0 + delta;
        (m.is_finite() && m > 0.0).then(|| m.clamp(1.0 / SIZE_STEP_LIMIT, SIZE_STEP_LIMIT))
    };
    let size_factor = || size_step(signatures, projection).and_then(grow);
    match effect {
        Effect::CoggingTorque(c) => {
            let Some(step) = projection.step(signatures) else {
                return effect;
            };
            let &[d_ln_a, d_phase] = step.as_slice() else {
                return effect;
            };
            let (along, across) = (1.0 + d_ln_a, d_phase);
            let gain = along.hypot(across);
            if gain > 0.0 && gain.is_finite() {
                Effect::CoggingTorque(CoggingTorque {
                    amplitude_nm: c.amplitude_nm * gain.min(SIZE_STEP_LIMIT),
                    phase_rad: (c.phase_rad + across.atan2(along))
                        .rem_euclid(std::f64::consts::TAU),
                    ..c
                })
            } else {
                effect
            }
        }
        Effect::QuadraticDrag(d) => size_factor().map_or(effect, |m| {
            Effect::QuadraticDrag(QuadraticDrag {
                c_nms2_per_rad2: d.c_nms2_per_rad2 * m,
            })
        }),
        Effect::StribeckFriction(f) if f.static_torque_nm > motor_ts => {
            size_factor().map_or(effect, |m| {
                Effect::StribeckFriction(StribeckFriction {
                    static_torque_nm: motor_ts + (f.static_torque_nm - motor_ts) * m,
                    ..f
                })
            })
        }
        Effect::BrushDrop(b) => size_factor().map_or(effect, |m| {
            Effect::BrushDrop(BrushDrop {
                drop_v: b.drop_v * m,
                ..b
            })
        }),
        _ => effect,
    }
}

/// One stage: every candidate screened, the best [`DiagnoseSettings::refits`] refitted on top
/// of `base` (in parallel), then ranked.
#[allow(clippy::too_many_arguments)]
fn run_stage(
    stage_no: usize,
    kinds: &[EffectKind],
    base: &Base<'_>,
    held: &[Vec<bool>],
    sigmas: &[(usize, Channel, f64)],
    localisation: &Localisation,
    settings: &DiagnoseSettings,
    progress: &(dyn Fn(DiagnoseProgress) + Sync),
) -> Stage {
    let block = settings.block_samples.max(1);
    let train_mask = |ch: &FittedChannel, i: usize| !held.get(ch.record).is_some_and(|h| h[i]);
    let held_mask = |ch: &FittedChannel, i: usize| held.get(ch.record).is_some_and(|h| h[i]);
    let train_before = nrmse_summary(&base.fitted, train_mask);
    let heldout_before = nrmse_summary(&base.fitted, held_mask);
    let sse_before = block_sse(&base.fitted, sigmas, held, block);
    progress(DiagnoseProgress::Screening { stage: stage_no });
    let (screens, starts): (Vec<Option<Screening>>, Vec<RefitStart>) =
        screen_stage(kinds, base, sigmas, localisation, settings)
            .into_iter()
            .unzip();
    // The level each candidate is judged at: α over every candidate the records can test
    // (the screened-out ones included: the screening looked at the same data).
    let family = screens
        .iter()
        .filter(|x| x.is_none_or(|s| s.testable))
        .count()
        .max(1);
    let level = settings.verdict.alpha / family as f64;
    // The candidates refitted: the best testable ones by their penalised score whose score
    // passes the screening level, and any the screening could not score.
    let penalty = settings.verdict.penalty_per_param;
    let searched: Vec<usize> = kinds
        .iter()
        .map(|&kind| shapes_searched(kind, localisation, &settings.localise, base.train))
        .collect();
    let mut passed: Vec<usize> = (0..kinds.len())
        .filter(|&k| screens[k].is_some_and(|s| s.testable && s.p_value < settings.screening_alpha))
        .collect();
    // A shape picked as the best of `s` (a cogging torque's period count) also pays `2 ln s`,
    // the Bonferroni factor on its p-value as a statistic of two degrees of freedom: the best
    // of many period counts scores above a single one's χ² on noise alone, and would take a
    // refit from the effect present.
    let promise = |k: usize| {
        screens[k].map_or(f64::NEG_INFINITY, |s| {
            s.penalised(penalty) - 2.0 * (searched[k] as f64).ln()
        })
    };
    passed.sort_by(|a, b| promise(*b).total_cmp(&promise(*a)));
    let per_round = settings.refits.max(1);
    passed.truncate(per_round * settings.refit_rounds.max(1));
    // The first round: the best `refits` by score, and any the screening could not score.
    let mut refit_set: Vec<usize> = (0..kinds.len())
        .filter(|&k| screens[k].is_none() || passed[..passed.len().min(per_round)].contains(&k))
        .collect();
    refit_set.sort_unstable();
    let screen_of = |k: usize| screens[k];
    // The report of a candidate not refitted, or whose refit failed.
    let unfitted =
        |k: usize, effects: Effects, assessment: Assessment, why: Option<String>| CandidateReport {
            name: kinds[k].name(),
            assessment,
            testable: assessment != Assessment::NotTestable,
            significant: false,
            screening: screen_of(k),
            p_value: 1.0,
            heldout_p_value: 1.0,
            params: Vec::new(),
            train_nrmse_before: train_before,
            train_nrmse_after: f64::NAN,
            heldout_nrmse_before: heldout_before,
            heldout_nrmse_after: f64::NAN,
            motor_shift: Vec::new(),
            motor: None,
            effects,
            failure: why,
            inputs: Vec::new(),
            fitted: Vec::new(),
        };
    // Without the evidence of a refit, the screening score speaks: no evidence below the
    // level, evidence the refit could not resolve above it.
    let by_score = |k: usize, otherwise: Assessment| match screen_of(k) {
        Some(s) if !s.testable => Assessment::NotTestable,
        Some(s) if s.p_value >= level => Assessment::NoEvidence,
        _ => otherwise,
    };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = std::sync::atomic::AtomicUsize::new(refit_set.len());
    progress(DiagnoseProgress::Candidates {
        stage: stage_no,
        done: 0,
        total: refit_set.len(),
    });
    // A refit worse than a constant on training channels the base model explains no better
    // ([`UNEXPLAINED_CHANNEL`]: a low step's encoder speed that is mostly its counts) has not
    // found a wrong minimum there: when every channel it is refused for is one of those and
    // nothing else refuses it (motor, intervals, effect), the tests judge it as any other.
    let base_as_bad = |fit: &FullFit, kind: EffectKind| {
        let unexplained = |q: &crate::ChannelQuality| {
            let before = base
                .fitted
                .iter()
                .find(|ch| ch.record == q.test && ch.channel == q.channel)
                .and_then(|ch| channel_nrmse(ch, train_mask))
                .map_or(f64::NAN, |(nrmse, _)| nrmse);
            let after = 1.0 - q.nrmse_fit_percent / 100.0;
            before >= UNEXPLAINED_CHANNEL && after <= before + (1.0 - UNEXPLAINED_CHANNEL)
        };
        matches!(fit.refusal, Some(crate::Refusal::WorseThanConstant { .. }))
            && fit
                .quality
                .iter()
                .filter(|q| q.nrmse_fit_percent < 0.0)
                .all(unexplained)
            && fit
                .refusal_beside_channels
                .as_ref()
                .is_none_or(|r| diagnosable(r, Some(kind)))
    };
    let refit = |k: usize| -> Refit {
        let kind = kinds[k];
        // In the weights the base model was fitted and every candidate is judged in (the
        // nominal fit's channel levels): a refit reweighted by its own residuals would
        // minimise another cost than the one its likelihood-ratio test and held-out blocks
        // measure, and could trade a channel the effect does not touch for one it does.
        let fit_on = |train: &[ExcitedRecord<'_>], motor: &MotorParams, start: Effect| {
            fit_output_error(
                train,
                &[],
                &[],
                motor,
                &base.effects.with(start),
                settings.lm,
                settings.step_factor,
                Some(sigmas),
            )
        };
        let accept = |fit: FullFit| match (&fit.refusal, fit.failure()) {
            (_, None) => Ok(fit),
            (Some(r), Some(_))
                if fit.termination.converged()
                    && (diagnosable(r, Some(kind)) || base_as_bad(&fit, kind)) =>
            {
                Ok(fit)
            }
            (_, Some(why)) => Err(why),
        };
        // The refit's prediction with every jump located beside the refitted model, as the
        // base model's are beside it: each model is judged at its own best instants.
        // With the effect's own part of that prediction, in noise variances.
        let judged = |fit: FullFit| {
            let inputs = located_inputs(
                base.grid,
                0..base.grid.len(),
                &fit.params,
                &fit.effects,
                sigmas,
                settings,
            );
            let all = with_inputs(base.all, &inputs);
            let predict = |effects: &Effects| {
                predict_with_step_factor(&all, &fit.params, effects, settings.step_factor)
                    .map_err(|e| e.to_string())
            };
            let pred = predict(&fit.effects)?;
            let part = weighted_difference(&pred, &predict(&fit.effects.without(kind))?, sigmas);
            drop(all);
            Ok((fit, pred, inputs, part))
        };
        let RefitStart { stepped, plain } = starts[k];
        let refit_from = |start: Effect| {
            fit_on(base.train, &base.motor, start)
                .map_err(|e| e.to_string())
                .and_then(accept)
                .and_then(judged)
        };
        // Whether the plain start has been fitted already (the stepped one cannot be, or is it).
        let (outcome, plain_tried) = match fit_on(base.train, &base.motor, stepped) {
            Err(FitError::BadData { series, .. }) if series == START_SERIES && stepped != plain => {
                (fit_on(base.train, &base.motor, plain), true)
            }
            other => (other, stepped == plain),
        };
        let outcome = outcome.map_err(|e| e.to_string()).and_then(accept);
        // An effect the base fit absorbed into a motor parameter (a sensor lag into L, its
        // jumps placed late to match a current rising at once; a saturation into a mean L; a
        // heating winding into a mean R) is a saddle there: the effect grown alone only adds
        // to what the parameter does. It is also refitted from a start that splits the two,
        // on the jumps located beside that start, and the lower cost kept.
        // A Stribeck friction refitted to a speed the records visit has split its levels
        // already: the split start is for one whose Ωs ran off to 0 or infinity.
        let split_needed = match (&outcome, kind) {
            (Ok(fit), EffectKind::StribeckFriction) => !stribeck_within_records(fit, base.train),
            _ => true,
        };
        let absorbed = split_needed
            .then(|| absorbed_start(kind, plain, &base.motor, base.train))
            .flatten();
        let outcome = match absorbed {
            Some((motor, start)) => {
                // The training records' alone: the split start's refit is made on them.
                let inputs = located_inputs(
                    base.grid,
                    0..base.train.len(),
                    &motor,
                    &base.effects.with(start),
                    sigmas,
                    settings,
                );
                let train = with_inputs(base.train, &inputs);
                let split = fit_on(&train, &motor, start)
                    .map_err(|e| e.to_string())
                    .and_then(accept);
                match (outcome, split) {
                    (Ok(a), Ok(b)) => Ok(if b.cost < a.cost { b } else { a }),
                    (Err(_), Ok(b)) => Ok(b),
                    (a, Err(_)) => a,
                }
            }
            None => outcome,
        }
        .and_then(judged);
        // A refit from the stepped start that fails, or ends above the base model's training
        // error (in a worse minimum than the one beside which it started), is retried from
        // the plain start, and the larger fall kept.
        let fall = |pred: &[FittedChannel]| {
            train_fall(&base.fitted, pred, sigmas, held).map_or(f64::NEG_INFINITY, |f| f.0)
        };
        let outcome = match outcome {
            Ok(first) if !plain_tried && fall(&first.1) < 0.0 => match refit_from(plain) {
                Ok(second) if fall(&second.1) > fall(&first.1) => Ok(second),
                _ => Ok(first),
            },
            Err(why) if !plain_tried => refit_from(plain).map_err(|_| why),
            other => other,
        };
        let report = match outcome {
            Ok((fit, pred, inputs, part)) => {
                let own: Vec<EffectEstimate> = fit
                    .effect_estimates
                    .iter()
                    .filter(|e| e.effect == kind)
                    .cloned()
                    .collect();
                let sse = block_sse(&pred, sigmas, held, block);
                // An effect whose own part of the prediction is below a noise variance (its
                // size gone to zero) gives no statistic: the fall is the motor's refit alone.
                let statistic = (part >= EFFECT_PART_MIN)
                    .then(|| train_statistic(&base.fitted, &pred, sigmas, held))
                    .flatten();
                let motor_shift = PARAM_NAMES
                    .iter()
                    .zip(base.motor.values())
                    .zip(fit.params.values())
                    .map(|((name, b), a)| ParamShift {
                        name,
                        before: b,
                        after: a,
                        relative: a / b - 1.0,
                    })
                    .collect();
                // A refit that leaves the effect's parameters undetermined cannot name it:
                // the screening score says whether that is for want of the effect.
                let assessment = if determined(&own) {
                    Assessment::NoEvidence
                } else {
                    by_score(k, Assessment::Unresolved)
                };
                (
                    CandidateReport {
                        params: own
                            .iter()
                            .map(|e| EffectParam {
                                symbol: e.symbol,
                                key: e.key,
                                unit: e.unit,
                                value: e.value,
                                ci95: e.ci95,
                            })
                            .collect(),
                        train_nrmse_after: nrmse_summary(&pred, train_mask),
                        heldout_nrmse_after: nrmse_summary(&pred, held_mask),
                        motor_shift,
                        motor: Some(fit.params),
                        inputs,
                        fitted: pred.clone(),
                        ..unfitted(k, fit.effects, assessment, None)
                    },
                    sse,
                    statistic,
                )
            }
            Err(why) => (
                unfitted(
                    k,
                    base.effects.with(starts[k].stepped),
                    by_score(k, Assessment::Unresolved),
                    Some(why),
                ),
                Vec::new(),
                None,
            ),
        };
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(DiagnoseProgress::Candidates {
            stage: stage_no,
            done: d,
            total: total.load(std::sync::atomic::Ordering::Relaxed),
        });
        report
    };
    // The refits in parallel on rayon's pool, which the output-error Jacobians inside them
    // share (one thread per core, no threads started within threads); one after the other
    // with `threads` ≤ 1. A refit that panics is reported as stopped, not propagated.
    let guarded = |k: usize| -> (usize, Refit) {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| refit(k)))
            .unwrap_or_else(|_| {
                (
                    unfitted(
                        k,
                        base.effects,
                        by_score(k, Assessment::Unresolved),
                        Some("the refit stopped unexpectedly".into()),
                    ),
                    Vec::new(),
                    None,
                )
            });
        (k, result)
    };
    let run_round = |set: &[usize]| -> Vec<(usize, Refit)> {
        if settings.threads > 1 {
            set.par_iter().map(|&k| guarded(k)).collect()
        } else {
            set.iter().map(|&k| guarded(k)).collect()
        }
    };
    let mut refitted: Vec<(usize, Refit)> = run_round(&refit_set);
    // Further rounds while a refit of the last one could not be judged (it stopped, or left
    // the effect's size undetermined although its screening score passed): the next passed
    // candidates by score take their place, so that a refit that fails from its start does
    // not hide an effect that scored a little lower.
    let mut next = per_round.min(passed.len());
    loop {
        let unjudged = refitted
            .iter()
            .filter(|(_, (c, _, _))| c.motor.is_none() || c.assessment == Assessment::Unresolved)
            .count();
        let judged = refitted.len() - unjudged;
        if judged >= per_round || next >= passed.len() || unjudged == 0 {
            break;
        }
        let take = (per_round - judged).min(passed.len() - next);
        let round: Vec<usize> = passed[next..next + take].to_vec();
        next += take;
        total.fetch_add(round.len(), std::sync::atomic::Ordering::Relaxed);
        refitted.extend(run_round(&round));
    }
    // Then, one at a time, a passed candidate not yet refitted whose screening score promises
    // more than the training data support the verdict of the refits so far (its penalised
    // likelihood ratio, the same χ² units): the linearised score ranks the candidates, and
    // once a refit shows what the top one delivers, one promising more may explain the gap
    // better (an exact drag screened below a Stribeck friction that, refitted, explained
    // less: benchmark case 83). Bounded by the refits the rounds allow.
    let bound = per_round * settings.refit_rounds.max(1);
    while refitted.len() < bound && next < passed.len() {
        // Every candidate, as the final ranking sees it (the same level `α / m`): those not
        // refitted without a statistic or held-out blocks, which names none of them.
        let scores: Vec<CandidateScore<'_>> = (0..kinds.len())
            .map(|k| match refitted.iter().find(|(j, _)| *j == k) {
                Some((_, r)) => refit_score(r, searched[k], &sse_before),
                None => CandidateScore {
                    name: kinds[k].name(),
                    extra_params: 0,
                    testable: screens[k].is_none_or(|s| s.testable),
                    train_statistic: None,
                    searched: searched[k],
                    heldout_sse_before: &sse_before,
                    heldout_sse_after: &[],
                },
            })
            .collect();
        let verdict = rank_candidates(&scores, &settings.verdict);
        let Some(delivered) = verdict.verdict.as_deref().and_then(|name| {
            scores
                .iter()
                .find(|c| c.name == name)
                .map(|c| training_support(c, penalty))
        }) else {
            break;
        };
        let k = passed[next];
        let promised = promise(k);
        if refitted.iter().any(|(j, _)| *j == k) {
            next += 1;
            continue;
        }
        if promised <= delivered {
            break;
        }
        next += 1;
        total.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        refitted.extend(run_round(&[k]));
    }
    // Every candidate in the order given: refitted, or reported with its screening score.
    let results: Vec<Refit> = (0..kinds.len())
        .map(|k| match refitted.iter().position(|(j, _)| *j == k) {
            Some(at) => refitted.swap_remove(at).1,
            None => (
                unfitted(
                    k,
                    base.effects.with(starts[k].stepped),
                    by_score(k, Assessment::ScreenedOut),
                    None,
                ),
                Vec::new(),
                None,
            ),
        })
        .collect();
    let scores: Vec<CandidateScore<'_>> = results
        .iter()
        .zip(&searched)
        .map(|(r, &searched)| refit_score(r, searched, &sse_before))
        .collect();
    let verdict = rank_candidates(&scores, &settings.verdict);
    let mut candidates: Vec<CandidateReport> = results.into_iter().map(|(c, _, _)| c).collect();
    for c in &mut candidates {
        c.take_rank(&verdict);
    }
    Stage {
        base: base.effects.list().iter().map(Effect::name).collect(),
        candidates,
        verdict,
        fitted_before: base.fitted.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output_error::voltage_input;
    use motor_model::{MeasurementModel, Record};

    #[test]
    fn a_first_jump_after_the_starting_level_is_searched_down_to_the_records_start() {
        let dt = 1e-3;
        // A record's voltage as its column reads it: 0 V from its start, the step on sample 1,
        // a reversal on sample 30.
        let levels = [(0.0, 0.0), (dt, 6.0), (30.0 * dt, -6.0)];
        // The step can have fallen anywhere in the first sample period (it was searched only
        // in its second half: half a period after the level at 0 s, taken for a jump).
        let (lo, hi) = jump_bracket(&levels, 1, dt);
        assert!((lo - FIRST_JUMP_MARGIN * dt).abs() < 1e-15, "{lo}");
        assert_eq!(hi, dt);
        // A later jump: within the period before its sample, half a period after the one
        // before.
        let (lo, hi) = jump_bracket(&levels, 2, dt);
        assert!(
            (lo - 29.0 * dt).abs() < 1e-15 && hi == 30.0 * dt,
            "{lo} {hi}"
        );
        let close = [(0.0, 0.0), (dt, 6.0), (1.2 * dt, -6.0)];
        let (lo, _) = jump_bracket(&close, 2, dt);
        assert!((lo - 1.5 * dt).abs() < 1e-15, "{lo}");
    }

    #[test]
    fn a_brush_knee_is_started_at_every_distinct_current_scale() {
        let input = Input::step(1.0, 0.0).expect("a step");
        let currents = [vec![0.0, 20.0, 10.0], vec![0.1, -0.2, 0.15], vec![0.3, 0.1]];
        let records: Vec<ExcitedRecord<'_>> = currents
            .iter()
            .map(|current| ExcitedRecord {
                input: &input,
                dt: 1e-3,
                current,
                speed: None,
                position: None,
                exclude_current: None,
                exclude_speed: None,
            })
            .collect();
        // 20 A, then 0.3 A (0.2 A is within a factor 3 of it).
        assert_eq!(brush_knee_scales(&records), vec![20.0, 0.3]);
        assert_eq!(brush_knee_scales(&records[..1]), vec![20.0]);
    }

    /// The servo of the diagnosis examples (R 2 Ω, L 2 mH, k 0.05, f 4e-4, J 2e-5, Ts 4 mN·m)
    /// under 12 V, 3 V and 0.6 V steps of 1 s at 5 kHz through the paper's logger, with
    /// `effects`.
    fn servo_records(effects: Effects) -> (MotorParams, Vec<(Input, Record)>) {
        let motor = MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3).unwrap();
        let records = [12.0, 3.0, 0.6]
            .iter()
            .enumerate()
            .map(|(k, &volts)| {
                let input = Input::step(volts, 0.05).unwrap();
                let trace = motor_model::simulate(&motor, effects, &input, 1.0, 5e3).unwrap();
                let record = MeasurementModel::paper_logger(&trace, 30 + k as u64)
                    .apply(&trace)
                    .unwrap();
                (voltage_input(&record.t, &record.voltage).unwrap(), record)
            })
            .collect();
        (motor, records)
    }

    /// The records of [`servo_records`] as the diagnosis takes them (encoder angle, 5 kHz).
    fn excited_of(records: &[(Input, Record)]) -> Vec<ExcitedRecord<'_>> {
        records
            .iter()
            .map(|(input, r)| ExcitedRecord {
                input,
                dt: 2e-4,
                current: &r.current,
                speed: None,
                position: r.position.as_deref(),
                exclude_current: None,
                exclude_speed: None,
            })
            .collect()
    }

    /// The nominal `motor`'s prediction of `excited` and each channel's residual level.
    fn nominal_of(
        excited: &[ExcitedRecord<'_>],
        motor: &MotorParams,
    ) -> (Vec<FittedChannel>, Vec<(usize, Channel, f64)>) {
        let fitted = predict_with_step_factor(excited, motor, &Effects::none(), 8.0).unwrap();
        let sigmas = fitted
            .iter()
            .map(|ch| (ch.record, ch.channel, ch.residual_rms()))
            .collect();
        (fitted, sigmas)
    }

    #[test]
    fn the_screening_step_turns_a_cogging_start_to_the_phase_present() {
        // A 20-per-revolution ripple at φ = 2.5 rad, screened from the start's φ = 0.3 rad
        // (more than a quarter period away, where a refit collapses to A → 0): the stepped
        // start has the phase present to within 0.3 rad and the amplitude within a factor 2.
        let present = CoggingTorque {
            amplitude_nm: 2e-3,
            periods_per_rev: 20,
            phase_rad: 2.5,
        };
        let (motor, records) = servo_records(Effects::none().with(Effect::CoggingTorque(present)));
        let excited = excited_of(&records);
        let (_, sigmas) = nominal_of(&excited, &motor);
        let lin = output_error_sensitivity(&excited, &motor, &Effects::none(), &sigmas, None, 8.0)
            .unwrap();
        let projection = BaseProjection::new(&lin.residuals, &lin.jacobian, &lin.series).unwrap();
        let start = Effect::CoggingTorque(CoggingTorque {
            amplitude_nm: 2e-4,
            phase_rad: 0.3,
            ..present
        });
        let sig = output_error_sensitivity(
            &excited,
            &motor,
            &Effects::none().with(start),
            &sigmas,
            Some(EffectKind::CoggingTorque),
            8.0,
        )
        .unwrap();
        let Effect::CoggingTorque(moved) =
            stepped_start(start, motor.ts_nm, &sig.jacobian, &projection)
        else {
            panic!("not a cogging torque");
        };
        let off = (moved.phase_rad - present.phase_rad + std::f64::consts::PI)
            .rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!(off.abs() < 0.3, "{moved:?}");
        let ratio = moved.amplitude_nm / present.amplitude_nm;
        assert!((0.5..2.0).contains(&ratio), "{moved:?}");
    }

    #[test]
    fn the_cogging_prefilter_ranks_the_period_count_present_among_those_screened() {
        // A cogging torque of 20 periods per revolution at half the Coulomb torque, the
        // nominal motor as the base: its signature at N = 20 must be among the few the
        // screening refits in full.
        for n in [7u32, 20] {
            let cogging = Effect::CoggingTorque(CoggingTorque {
                amplitude_nm: 2e-3,
                periods_per_rev: n,
                phase_rad: 0.4,
            });
            let (motor, records) = servo_records(Effects::none().with(cogging));
            let excited = excited_of(&records);
            let (fitted, sigmas) = nominal_of(&excited, &motor);
            let base = Base {
                motor,
                effects: Effects::none(),
                fitted,
                train: &excited,
                all: &excited,
                grid: &excited,
            };
            let lin =
                output_error_sensitivity(&excited, &motor, &Effects::none(), &sigmas, None, 8.0)
                    .unwrap();
            let projection = BaseProjection::new(&lin.residuals, &lin.jacobian, &lin.series)
                .expect("a linearisation");
            let ranked = cogging_prefilter(&base, &sigmas, &projection, 64, 8.0)
                .expect("a ranking of the period counts");
            assert_eq!(ranked.len(), 64);
            let at = ranked.iter().position(|&m| m == n);
            assert!(
                at.is_some_and(|at| at < COGGING_SCREENED),
                "N = {n} ranked {at:?}: {:?}",
                &ranked[..8]
            );
        }
    }

    #[test]
    fn a_size_only_effect_asked_for_a_negative_size_screens_at_zero() {
        // A base of a line, a residual `± 3 x²` beside it, and the signature `x²` of one
        // parameter: the residual `simulated − measured` asks for the size `∓ 3`.
        let n = 200;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let base = DMatrix::from_fn(n, 2, |i, j| if j == 0 { x[i] } else { 1.0 });
        let signature = DMatrix::from_fn(n, 1, |i, _| x[i] * x[i]);
        for (sign, negative) in [(1.0, true), (-1.0, false)] {
            // The part of `sign · 3 x²` a line cannot explain.
            let y = DMatrix::from_fn(n, 1, |i, _| sign * 3.0 * x[i] * x[i]);
            let fit = base.clone().svd(true, true).solve(&y, 1e-12).unwrap();
            let r = (y - &base * fit).as_slice().to_vec();
            let projection = BaseProjection::new(&r, &base, &[n]).unwrap();
            for kind in [
                EffectKind::CurrentSensorLag,
                EffectKind::QuadraticDrag,
                EffectKind::BrushDrop,
            ] {
                assert_eq!(
                    asks_for_negative_size(kind, &signature, &projection),
                    negative,
                    "{kind:?}, residual {sign} · 3 x²"
                );
            }
            // A cogging torque's phase turns its sign: never one-sided.
            assert!(!asks_for_negative_size(
                EffectKind::CoggingTorque,
                &signature,
                &projection
            ));
        }
    }

    #[test]
    fn a_short_training_record_lends_two_held_out_blocks_and_each_run_is_a_block() {
        let settings = DiagnoseSettings::default();
        // 4 blocks of 50 held out one in four: a record under 400 samples gets shorter ones.
        assert_eq!(record_block(5000, &settings), 50);
        assert_eq!(record_block(400, &settings), 50);
        assert_eq!(record_block(112, &settings), 14);
        let n = 112;
        let block = record_block(n, &settings);
        let held: Vec<bool> = (0..n).map(|i| (i / block) % 4 == 3).collect();
        assert_eq!(held.iter().filter(|&&h| h).count(), 28);
        // A training record's held-out runs are its blocks; a validation record, held out
        // whole, is cut every `block_samples`.
        let channel = |record: usize, n: usize| FittedChannel {
            record,
            channel: Channel::Current,
            samples: (0..n).collect(),
            measured: vec![1.0; n],
            model: vec![0.0; n],
        };
        let sigmas = [(0, Channel::Current, 1.0), (1, Channel::Current, 1.0)];
        let sse = block_sse(
            &[channel(0, n), channel(1, 120)],
            &sigmas,
            &[held, vec![true; 120]],
            settings.block_samples,
        );
        assert_eq!(sse, vec![14.0, 14.0, 50.0, 50.0, 20.0]);
    }

    #[test]
    fn a_channel_shorter_than_the_correlation_lags_still_gives_a_training_statistic() {
        // 20 training samples, fewer than the 25 lags + 1: the fall is counted, with a
        // quarter of the length in lags, not dropped (which read p = 1 on records of a few
        // dozen samples).
        let channel = |model: f64| FittedChannel {
            record: 0,
            channel: Channel::Current,
            samples: (0..20).collect(),
            measured: (0..20)
                .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
                .collect(),
            model: vec![model; 20],
        };
        let sigmas = [(0, Channel::Current, 1.0)];
        let (fall, factor) = train_fall(
            &[channel(1.0)],
            &[channel(0.0)],
            &sigmas,
            &[vec![false; 20]],
        )
        .expect("a statistic");
        // Before: residuals 0 and -2 (sum of squares 40); after: ±1 (20).
        assert_eq!(fall, 20.0);
        assert!(factor >= 1.0);
    }
}
