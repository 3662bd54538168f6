//! The step-pair identification as one call: the paper's method (Sec. 3, Eqs. (33)–(51)),
//! else — or after it — the full model started from its result or from the steady states;
//! with the policies around it that a front end must not redo: which clipped records are
//! accepted, the steady value of a settled record, which intervals are too wide to trust, and
//! the torque constant of a current-driven axis.
//!
//! Results come back as data (parameters with names, units and intervals, the route taken,
//! notes); nothing is printed.

use std::fmt;

use motor_model::{Input, MotorParams};

use crate::diagnose::localise::{Localisation, LocaliseSettings};
use crate::diagnose::localise_fit;
use crate::error::FitError;
use crate::estimation::fitted::FullFit;
use crate::estimation::lm::LmSettings;
use crate::estimation::parameters::{parameter_estimates, ParameterEstimate};
use crate::estimation::records::{ExcitedRecord, StepTest};
use crate::excitation::equation_error::electrical_equation;
use crate::excitation::input_uncertainty::{LevelPrior, StepInputs};
use crate::excitation::output_error::OutputError;
use crate::steps::full_model::identify_full_with_inputs;
use crate::steps::paper_method::{identify_paper, PaperIdentification};
use crate::steps::start::steady_state_start;

/// How a step pair is identified.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum StepMethod {
    /// The paper's method alone (Eqs. (33)–(51)); it gives no confidence intervals.
    Paper,
    /// The full model (R, L, k, f, J, Ts jointly, exact response) started from the paper's
    /// method, or from the steady states where that method does not apply.
    Full,
}

/// One step record as the pipeline reads it.
#[derive(Debug, Clone, Copy)]
pub struct StepRecord<'a> {
    /// The record from the step on: up to the return ([`crate::StepLocation::fall`]) for a
    /// step that comes back down (the paper's method and the steady states read the rise).
    pub test: StepTest<'a>,
    /// What the record leaves unknown about the step (height, instant, current LSB).
    pub inputs: StepInputs,
    /// The whole record, for a step whose voltage comes back down (a return to 0 V): the full
    /// method then models the fall too. `None` for a record that ends at its step's level.
    pub whole: Option<WholeRecord<'a>>,
}

/// The whole record of a step that comes back down, as the output-error fit reads it: the
/// voltage rebuilt as its levels (the step and the return, [`crate::voltage_levels`]) from the
/// record's first sample, at rest there.
#[derive(Debug, Clone, Copy)]
pub struct WholeRecord<'a> {
    /// The record from its first sample.
    pub record: ExcitedRecord<'a>,
    /// What the record leaves unknown about each level of `record.input` (level and start
    /// instant, [`crate::voltage_levels`]).
    pub priors: &'a [LevelPrior],
}

impl StepRecord<'_> {
    /// Whether any sample of the record is left out as clipped.
    pub fn has_clipping(&self) -> bool {
        self.test.exclude_current.is_some() || self.test.exclude_speed.is_some()
    }
}

/// Why the paper's method gave no result.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum PaperSkipped {
    /// A record has clipped samples: the method reads the whole current and its steady values.
    Clipped,
    /// The method refused the records (e.g. an underdamped response, Eqs. (35)–(37)).
    Failed(FitError),
}

impl fmt::Display for PaperSkipped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PaperSkipped::Clipped => f.write_str(
                "clipped samples: the paper's method reads the whole current and its steady values",
            ),
            PaperSkipped::Failed(e) => write!(f, "{e}"),
        }
    }
}

/// Which route the step-pair pipeline took.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum StepRoute {
    /// The paper's method alone ([`StepMethod::Paper`]).
    Paper,
    /// The full model started from the paper's result.
    FullFromPaper,
    /// The full model started from the steady states ([`steady_state_start`]): the paper's
    /// method did not apply.
    FullFromSteadyStates,
    /// The full model started from the steady states after the fit started from the paper's
    /// result was refused ([`StepPairIdentification::paper_start_refused`] says why): the
    /// paper's Eq. (33) fit can settle on a wrong pair of poles (an electrical time constant
    /// of one sample or less), and the full fit then on a wrong minimum.
    FullFromSteadyStatesAfterPaper,
}

impl StepRoute {
    /// The method's name in reports: `paper` or `full`.
    pub fn method_name(self) -> &'static str {
        match self {
            StepRoute::Paper => "paper",
            StepRoute::FullFromPaper
            | StepRoute::FullFromSteadyStates
            | StepRoute::FullFromSteadyStatesAfterPaper => "full",
        }
    }
}

/// Why the step-pair pipeline gave no result.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum StepPairError {
    /// [`StepMethod::Paper`] was asked for and the paper's method does not apply.
    Paper(PaperSkipped),
    /// No start for the full fit: the steady states refused the records.
    Start(FitError),
    /// The full fit refused the records.
    Full(FitError),
}

impl fmt::Display for StepPairError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepPairError::Paper(e) => write!(f, "{e}"),
            StepPairError::Start(e) | StepPairError::Full(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for StepPairError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            StepPairError::Paper(PaperSkipped::Failed(e))
            | StepPairError::Start(e)
            | StepPairError::Full(e) => Some(e),
            StepPairError::Paper(_) => None,
        }
    }
}

/// A 95 % interval wider than this fraction of the value (half-width over value) marks a
/// poorly determined parameter.
pub const POORLY_DETERMINED: f64 = 0.1;

impl ParameterEstimate {
    /// Half the 95 % interval over the value \[-\], if there is an interval.
    pub fn relative_half_width(&self) -> Option<f64> {
        self.ci95.map(|[lo, hi]| 0.5 * (hi - lo) / self.value)
    }

    /// Whether the records leave the parameter poorly determined: its
    /// [`relative_half_width`](Self::relative_half_width) exceeds [`POORLY_DETERMINED`].
    pub fn poorly_determined(&self) -> bool {
        self.relative_half_width()
            .is_some_and(|rel| rel > POORLY_DETERMINED)
    }
}

/// What the step-pair pipeline found: the paper's result (or why there is none), the full fit
/// if one ran, and the route taken.
#[derive(Debug, Clone, PartialEq)]
pub struct StepPairIdentification {
    /// The paper's method, or why it gave no result.
    pub paper: Result<PaperIdentification, PaperSkipped>,
    /// The full fit, with [`StepMethod::Full`].
    pub full: Option<FullFit>,
    /// Which route was taken.
    pub route: StepRoute,
    /// Why the full fit started from the paper's result was set aside, with
    /// [`StepRoute::FullFromSteadyStatesAfterPaper`] ([`FullFit::failure`]); `None` otherwise.
    pub paper_start_refused: Option<String>,
}

impl StepPairIdentification {
    /// The identified motor: the full fit's, else the paper's.
    pub fn params(&self) -> Option<MotorParams> {
        match (&self.full, &self.paper) {
            (Some(f), _) => Some(f.params),
            (None, Ok(p)) => Some(p.params),
            (None, Err(_)) => None,
        }
    }

    /// The identified parameters with names, units and (from the full fit) 95 % intervals.
    pub fn estimates(&self) -> Vec<ParameterEstimate> {
        let ci = self.full.as_ref().and_then(|f| f.ci95.as_ref());
        self.params()
            .map(|p| parameter_estimates(&p, ci))
            .unwrap_or_default()
    }

    /// Where the full fit's residual on the pair it was fitted to (`high`, `low` as given to
    /// [`identify_step_pair`], named by `names`) exceeds the records' own noise floor
    /// ([`localise_fit`] with [`LocaliseSettings::model_check`]): a significant finding says
    /// the records show something the motor model does not, and the intervals, which assume a
    /// complete model, do not hold the bias it leaves.
    /// Each step record is taken from its step on at its measured height (or whole, rise and
    /// return, where the full fit took it whole). `None` without a full fit.
    pub fn localise(
        &self,
        high: &StepRecord<'_>,
        low: &StepRecord<'_>,
        names: &[&str],
    ) -> Option<Result<Localisation, FitError>> {
        let full = self.full.as_ref()?;
        let steps = [high, low].map(|s| Input::Step {
            volts: s.test.volts,
            at_s: 0.0,
        });
        let records: Vec<ExcitedRecord<'_>> = match (high.whole, low.whole) {
            (Some(h), Some(l)) => vec![h.record, l.record],
            _ => [high, low]
                .iter()
                .zip(&steps)
                .map(|(s, input)| ExcitedRecord {
                    input,
                    dt: s.test.dt,
                    current: s.test.current,
                    speed: s.test.speed,
                    position: s.test.position,
                    exclude_current: s.test.exclude_current,
                    exclude_speed: s.test.exclude_speed,
                })
                .collect(),
        };
        Some(localise_fit(
            &records,
            &full.fitted,
            names,
            &LocaliseSettings::model_check(),
        ))
    }

    /// The note to give with the result, a sentence: why the full fit started from the steady
    /// states.
    pub fn note(&self) -> Option<String> {
        match (&self.paper, self.route, &self.paper_start_refused) {
            (Err(why), StepRoute::FullFromSteadyStates, _) => Some(format!(
                "the paper's method does not apply to these records ({why}); the full fit \
                 started from the steady states instead"
            )),
            (_, StepRoute::FullFromSteadyStatesAfterPaper, Some(why)) => Some(format!(
                "the full fit started from the paper's result was set aside ({why}); the one \
                 started from the steady states is given instead"
            )),
            _ => None,
        }
    }
}

/// Identifies a step pair, the high-voltage step first: the paper's method (unless clipped
/// samples rule it out), then with [`StepMethod::Full`] the full model (fitting the step
/// heights and instants as uncertain inputs, [`identify_full_with_inputs`]) started from it, or
/// from the steady states ([`steady_state_start`]) where it does not apply — and again from
/// the steady states when the fit from the paper's result is refused
/// ([`StepRoute::FullFromSteadyStatesAfterPaper`], kept only if that fit is accepted). Records whose
/// voltage comes back down ([`StepRecord::whole`]) are fitted whole, rise and fall, by output
/// error from rest ([`OutputError::level_priors`], the levels and their instants as
/// uncertain inputs); a pair with one such record and one without is refused.
pub fn identify_step_pair(
    high: &StepRecord<'_>,
    low: &StepRecord<'_>,
    method: StepMethod,
    settings: LmSettings,
) -> Result<StepPairIdentification, StepPairError> {
    let paper = if high.has_clipping() || low.has_clipping() {
        Err(PaperSkipped::Clipped)
    } else {
        identify_paper(&high.test, &low.test, settings).map_err(PaperSkipped::Failed)
    };
    match method {
        StepMethod::Paper => match paper {
            Ok(p) => Ok(StepPairIdentification {
                paper: Ok(p),
                full: None,
                route: StepRoute::Paper,
                paper_start_refused: None,
            }),
            Err(e) => Err(StepPairError::Paper(e)),
        },
        StepMethod::Full => {
            let fit_from = |start: &MotorParams| match (high.whole, low.whole) {
                (None, None) => identify_full_with_inputs(
                    &[high.test, low.test],
                    &[high.inputs, low.inputs],
                    start,
                    settings,
                ),
                // Rise and fall: the input is piecewise constant, each level (the return's
                // included) and its instant an uncertain input as the step's are.
                (Some(h), Some(l)) => OutputError::new(&[h.record, l.record], *start)
                    .level_priors(&[h.priors.to_vec(), l.priors.to_vec()])
                    .solver(settings)
                    .fit(),
                _ => Err(FitError::BadData {
                    series: "step pair".into(),
                    reason: "one record returns to 0 V after its step and the other does not: \
                             the full method models both falls or neither — fit the two \
                             records together with identify --record (output error)"
                        .into(),
                }),
            };
            let steady = || steady_state_start(&high.test, &low.test);
            let Ok(p) = &paper else {
                let full = fit_from(&steady().map_err(StepPairError::Start)?)
                    .map_err(StepPairError::Full)?;
                return Ok(StepPairIdentification {
                    paper,
                    full: Some(full),
                    route: StepRoute::FullFromSteadyStates,
                    paper_start_refused: None,
                });
            };
            let from_paper = fit_from(&p.params);
            let refused = match &from_paper {
                Ok(f) => f.failure(),
                Err(e) => Some(e.to_string()),
            };
            // A fit from the paper's result that is not a result: the steady states are a
            // second, independent start; their fit replaces it only if it is accepted.
            let retry = refused.as_ref().and_then(|_| {
                let start = steady().ok()?;
                fit_from(&start).ok().filter(FullFit::accepted)
            });
            let (full, route, paper_start_refused) = match retry {
                Some(f) => (f, StepRoute::FullFromSteadyStatesAfterPaper, refused),
                None => (
                    from_paper.map_err(StepPairError::Full)?,
                    StepRoute::FullFromPaper,
                    None,
                ),
            };
            Ok(StepPairIdentification {
                paper,
                full: Some(full),
                route,
                paper_start_refused,
            })
        }
    }
}

/// An analog channel of a record, as the clipping policy names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum RecordChannel {
    /// The armature voltage: the fits take it as known.
    Voltage,
    /// The armature current.
    Current,
    /// The tachometer speed (an encoder has no ADC rail).
    Speed,
}

/// Largest fraction of the current or the speed that may sit on an ADC rail before the record
/// is refused.
pub const MAX_CLIPPED_FRACTION: f64 = 0.25;
/// Largest fraction of the voltage that may be clipped: the fits take the voltage as known.
pub const MAX_CLIPPED_VOLTAGE: f64 = 0.01;

impl RecordChannel {
    /// Largest fraction \[-\] of the channel's samples that may be clipped.
    pub fn max_clipped_fraction(self) -> f64 {
        match self {
            RecordChannel::Voltage => MAX_CLIPPED_VOLTAGE,
            RecordChannel::Current | RecordChannel::Speed => MAX_CLIPPED_FRACTION,
        }
    }
}

/// What the clipping policy makes of one channel.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum ClippingVerdict {
    /// No sample at a rail.
    Clean,
    /// Some samples at a rail: they are left out of the fits.
    LeftOut,
    /// Too much of the channel at a rail: the record is refused.
    Refused {
        /// Why, in words (`the fits need the applied voltage`, …).
        reason: &'static str,
    },
}

/// The clipping policy for `channel` whose samples at an ADC rail are marked in `mask`: clean,
/// left out of the fits, or refused beyond [`RecordChannel::max_clipped_fraction`].
pub fn judge_clipping(channel: RecordChannel, mask: &[bool]) -> ClippingVerdict {
    let clipped = mask.iter().filter(|&&x| x).count();
    if clipped == 0 {
        return ClippingVerdict::Clean;
    }
    let fraction = clipped as f64 / mask.len().max(1) as f64;
    if fraction > channel.max_clipped_fraction() {
        ClippingVerdict::Refused {
            reason: match channel {
                RecordChannel::Voltage => "the fits need the applied voltage",
                RecordChannel::Current | RecordChannel::Speed => "too much of the record is lost",
            },
        }
    } else {
        ClippingVerdict::LeftOut
    }
}

/// The steady value of a settled record is the median of its last `1/STEADY_TAIL_PARTS`.
pub const STEADY_TAIL_PARTS: usize = 10;

/// The steady value of a settled channel (unit of `samples`): the median of its last tenth
/// (at least one sample; the upper median of an even count). `None` for an empty channel.
pub fn steady_value(samples: &[f64]) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let n = samples.len();
    let mut tail = samples[n - (n / STEADY_TAIL_PARTS).max(1)..].to_vec();
    let mid = tail.len() / 2;
    Some(*tail.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// Where a current-driven axis's torque constant came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum TorqueConstantSource {
    /// Given by the user.
    Given,
    /// Estimated from the armature voltage equation (2a).
    VoltageEquation,
}

impl TorqueConstantSource {
    /// The source in words, for reports (`given`, `voltage equation (2a)`).
    pub fn text(self) -> &'static str {
        match self {
            TorqueConstantSource::Given => "given",
            TorqueConstantSource::VoltageEquation => "voltage equation (2a)",
        }
    }
}

/// Why no torque constant could be chosen.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum TorqueConstantError {
    /// The given constant is not a positive finite number.
    NotPositive(f64),
    /// The voltage equation (2a) refused the record.
    VoltageEquation(FitError),
    /// Neither a constant nor a voltage to estimate it from.
    Missing,
}

impl fmt::Display for TorqueConstantError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TorqueConstantError::NotPositive(k) => {
                write!(f, "torque constant {k}: expected a positive number")
            }
            TorqueConstantError::VoltageEquation(e) => write!(f, "{e}"),
            TorqueConstantError::Missing => {
                f.write_str("no torque constant and no voltage to estimate it from")
            }
        }
    }
}

impl std::error::Error for TorqueConstantError {}

/// The torque (or force) constant of a current-driven axis \[N·m/A or N/A, per unit of the
/// current\]: `given` if any (positive), else from the voltage equation (2a) on `record` (with
/// the derivatives low-passed at `cutoff_fraction` of the sample rate), if it has a voltage.
pub fn torque_constant(
    given: Option<f64>,
    record: Option<&ExcitedRecord<'_>>,
    cutoff_fraction: f64,
) -> Result<(f64, TorqueConstantSource), TorqueConstantError> {
    match (given, record) {
        (Some(k), _) if k.is_finite() && k > 0.0 => Ok((k, TorqueConstantSource::Given)),
        (Some(k), _) => Err(TorqueConstantError::NotPositive(k)),
        (None, Some(r)) => {
            let [_, _, k] = electrical_equation(std::slice::from_ref(r), cutoff_fraction)
                .map_err(TorqueConstantError::VoltageEquation)?;
            Ok((k, TorqueConstantSource::VoltageEquation))
        }
        (None, None) => Err(TorqueConstantError::Missing),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimation::intervals::MotorIntervals;
    use crate::estimation::records::PARAM_NAMES;
    use motor_model::{Input, MotorState, StepResponse};

    const RATE_HZ: f64 = 100.0;

    struct Columns {
        volts: f64,
        current: Vec<f64>,
        speed: Vec<f64>,
    }

    fn exact(motor: &MotorParams, volts: f64) -> Columns {
        let n = (50.0 * RATE_HZ) as usize + 1;
        let mut s = vec![MotorState::default(); n];
        StepResponse::new(motor, volts).fill(0.0, 1.0 / RATE_HZ, &mut s);
        Columns {
            volts,
            current: s.iter().map(|x| x.current_a).collect(),
            speed: s.iter().map(|x| x.speed_rad_s).collect(),
        }
    }

    fn record<'a>(c: &'a Columns, exclude: Option<&'a [bool]>) -> StepRecord<'a> {
        StepRecord {
            test: StepTest {
                volts: c.volts,
                t_first: 0.0,
                dt: 1.0 / RATE_HZ,
                current: &c.current,
                speed: Some(&c.speed),
                position: None,
                exclude_current: exclude,
                exclude_speed: None,
            },
            inputs: StepInputs::default(),
            whole: None,
        }
    }

    #[test]
    fn full_method_starts_from_the_paper_and_recovers_the_motor() {
        let truth = MotorParams::paper();
        let (hv, lv) = (exact(&truth, 40.0), exact(&truth, 2.5));
        let (high, low) = (record(&hv, None), record(&lv, None));
        let paper = identify_step_pair(&high, &low, StepMethod::Paper, LmSettings::default())
            .expect("the paper's method applies");
        assert_eq!(paper.route, StepRoute::Paper);
        assert!(paper.full.is_none() && paper.note().is_none());
        assert!(paper.estimates().iter().all(|e| e.ci95.is_none()));
        let full = identify_step_pair(&high, &low, StepMethod::Full, LmSettings::default())
            .expect("the full fit runs");
        assert_eq!(full.route, StepRoute::FullFromPaper);
        assert_eq!(full.route.method_name(), "full");
        let estimates = full.estimates();
        let names: Vec<&str> = estimates.iter().map(|e| e.name).collect();
        assert_eq!(names, PARAM_NAMES);
        for (e, t) in estimates.iter().zip(truth.values()) {
            assert!(((e.value - t) / t).abs() < 1e-6, "{e:?}");
            assert!(e.ci95.is_some() && !e.poorly_determined(), "{e:?}");
        }
    }

    /// A record of a step of `volts` at t = 0 back to 0 V in the middle of the period before
    /// the sample at 50 s (where the fall's instant is expected), 100 s at [`RATE_HZ`], exact.
    fn returning(motor: &MotorParams, volts: f64) -> motor_model::Trace {
        let input = Input::piecewise(&[(0.0, volts), (50.0 - 0.5 / RATE_HZ, 0.0)]).unwrap();
        motor_model::simulate(motor, motor_model::Effects::none(), &input, 100.0, RATE_HZ).unwrap()
    }

    #[test]
    fn a_step_back_to_zero_is_fitted_whole_rise_and_fall() {
        let truth = MotorParams::paper();
        let traces = [returning(&truth, 40.0), returning(&truth, 2.5)];
        let levels: Vec<_> = traces
            .iter()
            .map(|tr| crate::voltage_levels(&tr.t, &tr.voltage, None).unwrap())
            .collect();
        let mut records = Vec::new();
        for (tr, (input, priors)) in traces.iter().zip(&levels) {
            let loc = crate::locate_step(&tr.t, &tr.voltage).unwrap();
            let fall = loc.fall.expect("the voltage comes back down");
            assert_eq!((loc.index, fall), (0, (50.0 * RATE_HZ) as usize));
            let rise = loc.index..fall;
            records.push(StepRecord {
                test: StepTest {
                    volts: loc.volts,
                    t_first: 0.0,
                    dt: loc.dt,
                    current: &tr.current[rise.clone()],
                    speed: Some(&tr.speed[rise]),
                    position: None,
                    exclude_current: None,
                    exclude_speed: None,
                },
                inputs: loc.inputs(),
                whole: Some(WholeRecord {
                    record: ExcitedRecord {
                        input,
                        dt: loc.dt,
                        current: &tr.current,
                        speed: Some(&tr.speed),
                        position: None,
                        exclude_current: None,
                        exclude_speed: None,
                    },
                    priors,
                }),
            });
        }
        // The paper's method reads the rise: as on records that hold the step.
        let (mut hv, mut lv) = (exact(&truth, 40.0), exact(&truth, 2.5));
        for c in [&mut hv, &mut lv] {
            c.current.truncate(records[0].test.current.len());
            c.speed.truncate(records[0].test.current.len());
        }
        let (high, low) = (record(&hv, None), record(&lv, None));
        let held = identify_step_pair(&high, &low, StepMethod::Paper, LmSettings::default())
            .unwrap()
            .paper
            .unwrap();
        let result = identify_step_pair(
            &records[0],
            &records[1],
            StepMethod::Full,
            LmSettings::default(),
        )
        .expect("the full fit runs");
        assert_eq!(result.route, StepRoute::FullFromPaper);
        let paper = result.paper.as_ref().unwrap();
        for (a, b) in paper.params.values().iter().zip(held.params.values()) {
            assert!(((a - b) / b).abs() < 1e-9, "{a} vs {b}");
        }
        let full = result.full.as_ref().unwrap();
        assert!(full.accepted(), "{:?}", full.failure());
        // Fitted whole: every sample of both records, the fall's included.
        let fitted: usize = full.fitted.iter().map(|c| c.samples.len()).sum();
        assert_eq!(fitted, 2 * 2 * traces[0].t.len());
        for (e, t) in result.estimates().iter().zip(truth.values()) {
            assert!(((e.value - t) / t).abs() < 1e-5, "{e:?} vs {t}");
            assert!(e.ci95.is_some(), "{e:?}");
        }
        // One record back to 0 V and one held: refused, not half-modelled.
        let err = identify_step_pair(&records[0], &low, StepMethod::Full, LmSettings::default())
            .expect_err("a mixed pair");
        assert!(err.to_string().contains("identify --record"), "{err}");
    }

    #[test]
    fn clipping_rules_out_the_paper_method_and_the_full_fit_starts_from_steady_states() {
        let truth = MotorParams::paper();
        let (hv, lv) = (exact(&truth, 40.0), exact(&truth, 2.5));
        let mut mask = vec![false; hv.current.len()];
        mask[100..110].iter_mut().for_each(|m| *m = true);
        let (high, low) = (record(&hv, Some(&mask)), record(&lv, None));
        let err = identify_step_pair(&high, &low, StepMethod::Paper, LmSettings::default())
            .expect_err("clipped samples rule out the paper's method");
        assert_eq!(err, StepPairError::Paper(PaperSkipped::Clipped));
        assert!(err.to_string().starts_with("clipped samples"));
        let full = identify_step_pair(&high, &low, StepMethod::Full, LmSettings::default())
            .expect("the full fit runs on the rest");
        assert_eq!(full.route, StepRoute::FullFromSteadyStates);
        assert!(full
            .note()
            .is_some_and(|n| n.contains(&PaperSkipped::Clipped.to_string())));
        let p = full.params().expect("a result");
        assert!(
            ((p.r_ohm - truth.r_ohm) / truth.r_ohm).abs() < 1e-4,
            "{p:?}"
        );
    }

    #[test]
    fn mismatched_channels_are_an_error_not_a_panic() {
        let truth = MotorParams::paper();
        let (hv, mut lv) = (exact(&truth, 40.0), exact(&truth, 2.5));
        lv.speed.truncate(10);
        let (high, low) = (record(&hv, None), record(&lv, None));
        for method in [StepMethod::Paper, StepMethod::Full] {
            assert!(identify_step_pair(&high, &low, method, LmSettings::default()).is_err());
        }
    }

    #[test]
    fn clipping_policy_by_channel() {
        let mask = |clipped: usize, of: usize| (0..of).map(|i| i < clipped).collect::<Vec<_>>();
        assert_eq!(
            judge_clipping(RecordChannel::Current, &mask(0, 100)),
            ClippingVerdict::Clean
        );
        assert_eq!(
            judge_clipping(RecordChannel::Current, &mask(25, 100)),
            ClippingVerdict::LeftOut
        );
        assert!(matches!(
            judge_clipping(RecordChannel::Speed, &mask(26, 100)),
            ClippingVerdict::Refused { .. }
        ));
        assert_eq!(
            judge_clipping(RecordChannel::Voltage, &mask(1, 100)),
            ClippingVerdict::LeftOut
        );
        assert_eq!(
            judge_clipping(RecordChannel::Voltage, &mask(2, 100)),
            ClippingVerdict::Refused {
                reason: "the fits need the applied voltage"
            }
        );
        assert_eq!(
            judge_clipping(RecordChannel::Current, &[]),
            ClippingVerdict::Clean
        );
    }

    #[test]
    fn steady_value_is_the_median_of_the_last_tenth() {
        let mut v: Vec<f64> = (0..100).map(f64::from).collect();
        v[95] = 1e9;
        // Last tenth: 90..99 with one outlier; the upper median of ten samples.
        assert_eq!(steady_value(&v), Some(96.0));
        assert_eq!(steady_value(&[7.0]), Some(7.0));
        assert_eq!(steady_value(&[]), None);
    }

    #[test]
    fn poorly_determined_beyond_ten_percent() {
        let p = MotorParams::paper();
        let mut ci = MotorIntervals::relative(&p, 0.05);
        // f known to ±20 % only.
        ci.f_nms_per_rad = [p.f_nms_per_rad * 0.8, p.f_nms_per_rad * 1.2];
        let e = parameter_estimates(&p, Some(&ci));
        let poor: Vec<&str> = e
            .iter()
            .filter(|e| e.poorly_determined())
            .map(|e| e.name)
            .collect();
        assert_eq!(poor, ["f"]);
        assert!((e[3].relative_half_width().unwrap() - 0.2).abs() < 1e-12);
        assert!(parameter_estimates(&p, None)
            .iter()
            .all(|e| !e.poorly_determined()));
    }

    #[test]
    fn torque_constant_given_or_from_the_voltage_equation() {
        assert_eq!(
            torque_constant(Some(0.2), None, 0.05),
            Ok((0.2, TorqueConstantSource::Given))
        );
        assert_eq!(
            torque_constant(Some(-1.0), None, 0.05),
            Err(TorqueConstantError::NotPositive(-1.0))
        );
        assert_eq!(
            torque_constant(None, None, 0.05),
            Err(TorqueConstantError::Missing)
        );
        let truth = MotorParams::paper();
        let trace = StepResponse::new(&truth, 40.0)
            .trace(0.0, 50.0, RATE_HZ)
            .unwrap();
        let input = Input::step(40.0, 0.0).unwrap();
        let record = ExcitedRecord {
            input: &input,
            dt: 1.0 / RATE_HZ,
            current: &trace.current,
            speed: None,
            position: Some(&trace.position),
            exclude_current: None,
            exclude_speed: None,
        };
        let (k, source) = torque_constant(None, Some(&record), 0.2).unwrap();
        assert_eq!(source, TorqueConstantSource::VoltageEquation);
        assert!(
            ((k - truth.k_nm_per_a) / truth.k_nm_per_a).abs() < 0.02,
            "{k}"
        );
    }
}
