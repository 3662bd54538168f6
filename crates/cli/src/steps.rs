//! Records read for the identification: step records located and mirrored, records of any
//! excitation with their voltage rebuilt, clipped samples judged by the library's policy; and
//! the calls into the identification pipelines with errors that name the files.

use std::path::Path;

use anyhow::Result;
use fit::{
    current_adc_steps, detect_initial_state, detect_rest, equation_error_start_with_initial_states,
    identify_feedforward, identify_step_pair, judge_clipping, locate_step_with, record_speed,
    voltage_input, voltage_levels, AxisRecord, ClippingVerdict, CurrentChannel,
    DetectedInitialState, ExcitedRecord, FeedforwardFit, FeedforwardSettings, FullFit,
    InitialState, LevelPrior, LmSettings, MeasuredChannels, OutputError, RecordChannel,
    SpeedRecord, StartChannels, StepInputs, StepMethod, StepPairIdentification, StepRecord,
    StepTest, WholeRecord,
};
use motor_model::{Input, MotorParams, Record};

use crate::errors::{BadInput, NotConverged};
use crate::record_csv::{read_loaded, ColumnMap, Loaded};

/// The error of a fit of `label` as the exit code sees it: the optimiser failing (it found no
/// usable minimum from the fit's own start) is a failed fit (exit 3), with the way to give a
/// start; anything else is a record or setting the method cannot take (exit 2).
fn fit_error(label: &str, e: &fit::FitError) -> anyhow::Error {
    match e {
        fit::FitError::Solver(_) => NotConverged(format!(
            "{label}: {e} — the fit found no usable minimum from its own start: give one by \
             fitting the records with identify --record … --start FILE.json (R, L, k, f, J, Ts)"
        ))
        .into(),
        _ => BadInput(format!("{label}: {e}")).into(),
    }
}

/// A step record read and located: owns the columns the [`StepTest`] borrows.
pub struct LoadedStep {
    /// File it came from.
    pub path: String,
    /// The file with the line span of its samples (`hv.csv:7-50007`), for errors.
    pub label: String,
    /// Step height \[V\] (positive: a negative step is mirrored).
    pub volts: f64,
    /// Whether the step was negative: its channels are kept with their signs reversed.
    pub mirrored: bool,
    dt: f64,
    /// Armature current from the step on \[A\].
    pub current: Vec<f64>,
    speed: Option<Vec<f64>>,
    position: Option<Vec<f64>>,
    exclude_current: Option<Vec<bool>>,
    exclude_speed: Option<Vec<bool>>,
    /// What the record leaves unknown about the step (height and instant).
    pub inputs: StepInputs,
    /// Samples of the step's level, from the step on: all of them, or those before the
    /// voltage came back down ([`fit::StepLocation::fall`]).
    rise: usize,
    /// The whole record, its voltage rebuilt as levels, for a step that comes back down (a
    /// return to 0 V): the full method fits the rise and the fall.
    pub whole: Option<LoadedExcited>,
    /// The channels the record measured (the current's ADC steps over the whole record).
    pub channels: MeasuredChannels,
}

impl LoadedStep {
    /// The identification's view of the record: from the step on, up to the voltage's return
    /// if it comes back down.
    pub fn test(&self) -> StepTest<'_> {
        fn first<T>(v: &[T], n: usize) -> &[T] {
            &v[..n.min(v.len())]
        }
        let n = self.rise;
        StepTest {
            volts: self.volts,
            t_first: 0.0,
            dt: self.dt,
            current: first(&self.current, n),
            speed: self.speed.as_deref().map(|v| first(v, n)),
            position: self.position.as_deref().map(|v| first(v, n)),
            exclude_current: self.exclude_current.as_deref().map(|v| first(v, n)),
            exclude_speed: self.exclude_speed.as_deref().map(|v| first(v, n)),
        }
    }

    /// The time of each sample fitted \[s\]: from the step on, or from the record's first
    /// sample for a step that comes back down (the full fit's sample times).
    pub fn times(&self) -> Vec<f64> {
        let n = self
            .whole
            .as_ref()
            .map_or(self.current.len(), |w| w.record.current.len());
        (0..n).map(|i| i as f64 * self.dt).collect()
    }

    /// The step-pair pipeline's view of the record: the test, its uncertain inputs and, for a
    /// step that comes back down, the whole record.
    pub fn step_record(&self) -> StepRecord<'_> {
        StepRecord {
            test: self.test(),
            inputs: self.inputs,
            whole: self.whole.as_ref().map(|w| WholeRecord {
                record: w.excited(),
                priors: &w.priors,
            }),
        }
    }
}

/// Samples of current and speed to leave out, `None` where nothing is clipped.
pub struct ClipMasks {
    /// Current samples at an ADC rail.
    pub current: Option<Vec<bool>>,
    /// Tachometer samples at an ADC rail.
    pub speed: Option<Vec<bool>>,
}

/// Refuses a record whose clipping hides too much ([`fit::judge_clipping`]), and warns (unless
/// `quiet`) about the rest: those samples are left out of the fits.
pub fn check_clipping(shown: &str, loaded: &Loaded, quiet: bool) -> Result<ClipMasks> {
    let (warnings, masks) = judge_record_clipping(shown, loaded);
    warn(&warnings, quiet);
    masks
}

/// Largest share of a record's current samples that may read a 0 A rail while the motor turns
/// ([`crate::record_csv::Loaded::current_on_zero_rail`]) before the record is refused.
const MAX_ZERO_RAIL_SHARE: f64 = 0.01;

/// Fewest such samples that refuse a record: a few readings of a short record bias nothing
/// measurable.
const MIN_ZERO_RAIL_SAMPLES: usize = 20;

/// Writes `warnings` to standard error, one a line, unless `quiet`.
fn warn(warnings: &[String], quiet: bool) {
    if !quiet {
        for w in warnings {
            crate::console::errln!("{w}");
        }
    }
}

/// [`check_clipping`] without writing: the warnings (given before any refusal) and the masks
/// or the refusal.
fn judge_record_clipping(shown: &str, loaded: &Loaded) -> (Vec<String>, Result<ClipMasks>) {
    let report = loaded.clipping_report();
    let mut line = report.iter();
    let mut warnings = Vec::new();
    if let Some((count, first, last)) = loaded.current_on_zero_rail {
        let share = count as f64 / loaded.record.current.len().max(1) as f64;
        if share > MAX_ZERO_RAIL_SHARE && count >= MIN_ZERO_RAIL_SAMPLES {
            let refusal = BadInput(format!(
                "{shown}: {count} current samples ({:.1} %, {} to {}) read the ADC's 0 A rail while the motor turns, \
                 with readings above it around them: the current is so small on this unipolar range that its noise \
                 is clipped at 0 A, and the mean of what is left reads high (f and Ts would be biased) — record \
                 with a range that reaches below 0 A (e.g. --range-current -10,100 on simulate) or with more gain",
                100.0 * share,
                loaded.line_span(first, first + 1),
                loaded.line_span(last, last + 1),
            ));
            return (warnings, Err(refusal.into()));
        }
    }
    for (channel, mask) in loaded.clipped_channels() {
        let verdict = judge_clipping(channel, mask);
        if verdict == ClippingVerdict::Clean {
            continue;
        }
        let text = line.next().cloned().unwrap_or_default();
        if let ClippingVerdict::Refused { reason } = verdict {
            let refusal = BadInput(format!(
                "{shown}: {text}: {reason}; record again with a wider range"
            ));
            return (warnings, Err(refusal.into()));
        }
        warnings.push(format!(
            "warning: {shown}: {text}; those samples are left out of the fit"
        ));
    }
    let mask = |m: &[bool]| m.iter().any(|&x| x).then(|| m.to_vec());
    let masks = ClipMasks {
        current: mask(loaded.clipped_mask(RecordChannel::Current)),
        speed: mask(loaded.clipped_mask(RecordChannel::Speed)),
    };
    (warnings, Ok(masks))
}

/// Reads `path`, finds the step and keeps the samples from it on; clipped samples are left out
/// of the fits (and a record with too many is refused).
pub fn load_step(path: &Path, map: &ColumnMap, quiet: bool) -> Result<LoadedStep> {
    step_from(path, read_loaded(path, map, true)?, quiet)
}

/// A step record read from `path` ([`load_step`]): the step found, clipped samples judged (and,
/// unless `quiet`, warned about). With [`excited_from`], one read of a file gives both views
/// (a pipe or `/dev/stdin` can be read only once).
pub fn step_from(path: &Path, loaded: Loaded, quiet: bool) -> Result<LoadedStep> {
    load_step_given(judge_step(path, loaded), quiet)
}

/// A high- and a low-voltage record read by [`load_step_pair`].
pub enum StepPair {
    /// Both records start at rest (or are taken to): their steps, high then low as given.
    Steps(Box<(LoadedStep, LoadedStep)>),
    /// A record whose first samples show a running motor, which the step methods cannot
    /// take: both records as read (high then low), and why (`file:lines: reason` of each
    /// such record).
    Moving {
        /// The two records as read.
        records: Box<[Loaded; 2]>,
        /// Which records do not start at rest, and why.
        why: String,
    },
}

/// [`load_step`] of a high- and a low-voltage record, each file read once (the two at once,
/// each on a core of its own where there are two): the warnings and errors are those of `high`
/// then `low`, in the order [`load_step`] one after the other gives them. Unless `assume_rest`,
/// a pair with a record that does not start at rest is returned as read
/// ([`StepPair::Moving`]), so that a pipe serves as a file does.
pub fn load_step_pair(
    high: &Path,
    low: &Path,
    map: &ColumnMap,
    quiet: bool,
    assume_rest: bool,
) -> Result<StepPair> {
    let (high_read, low_read) = rayon::join(
        || read_loaded(high, map, true),
        || read_loaded(low, map, true),
    );
    let (high_read, low_read) = (high_read?, low_read?);
    if !assume_rest {
        let moving: Vec<String> = [(high, &high_read), (low, &low_read)]
            .iter()
            .filter_map(|(path, l)| {
                let d = initial_state_of(&l.record)?;
                (d.state != InitialState::Rest).then(|| {
                    format!(
                        "{}: {}",
                        file_lines(&path.display().to_string(), &l.lines),
                        d.reason
                    )
                })
            })
            .collect();
        if !moving.is_empty() {
            return Ok(StepPair::Moving {
                records: Box::new([high_read, low_read]),
                why: moving.join("; "),
            });
        }
    }
    let (high_step, low_step) =
        rayon::join(|| judge_step(high, high_read), || judge_step(low, low_read));
    let high_step = load_step_given(high_step, quiet)?;
    let low_step = load_step_given(low_step, quiet)?;
    Ok(StepPair::Steps(Box::new((high_step, low_step))))
}

/// The step of a [`judge_step`] result, its warnings written first (unless
/// `quiet`).
fn load_step_given(
    (warnings, step): (Vec<String>, Result<LoadedStep>),
    quiet: bool,
) -> Result<LoadedStep> {
    warn(&warnings, quiet);
    step
}

/// [`load_step`] of a record already read from `path`, without writing: the clipping warnings
/// (given before any error that follows them) and the step or the error.
fn judge_step(path: &Path, loaded: Loaded) -> (Vec<String>, Result<LoadedStep>) {
    let shown = path.display().to_string();
    let (warnings, masks) = judge_record_clipping(&shown, &loaded);
    let step = masks.and_then(|masks| {
        let label = file_lines(&shown, &loaded.lines);
        let mut step =
            step_from_record_with(label, loaded.record, loaded.voltage_lsb, loaded.current_lsb)?;
        step.inputs.current_lsb_a = loaded.current_lsb.unwrap_or(0.0);
        step.path = shown;
        let from = loaded.lines.len() - step.current.len();
        let tachometer = step.position.is_none();
        if let Some(whole) = &mut step.whole {
            whole.exclude_current.clone_from(&masks.current);
            if tachometer {
                whole.exclude_speed.clone_from(&masks.speed);
            }
        }
        step.exclude_current = masks.current.map(|m| m[from..].to_vec());
        // The encoder speed has no ADC: only a tachometer column can be clipped.
        if tachometer {
            step.exclude_speed = masks.speed.map(|m| m[from..].to_vec());
        }
        Ok(step)
    });
    (warnings, step)
}

/// How a whole record starts ([`fit::detect_initial_state`]), `None` where its first samples
/// cannot tell. The voltage waveform, which only a record that does not start at rest needs,
/// is rebuilt only for such a record ([`fit::detect_rest`] first).
fn initial_state_of(rec: &Record) -> Option<DetectedInitialState> {
    let channels = StartChannels {
        dt: motor_model::mean_period(&rec.t),
        current: &rec.current,
        speed: rec.speed.as_deref(),
        position: rec.position.as_deref(),
    };
    if let Some(rest) = detect_rest(&channels).ok()? {
        return Some(rest);
    }
    let input = voltage_input(&rec.t, &rec.voltage).ok()?;
    detect_initial_state(&ExcitedRecord {
        input: &input,
        dt: channels.dt,
        current: channels.current,
        speed: channels.speed,
        position: channels.position,
        exclude_current: None,
        exclude_speed: None,
    })
    .ok()
}

/// Finds the step in a record (named `shown` in errors) and keeps the samples from it on. Speed
/// (for the paper method's Ωrm) comes from the `position` column, else the `speed` column
/// ([`fit::record_speed`]); the full fit uses the encoder angle where there is one.
pub fn step_from_record(shown: String, cols: Record) -> Result<LoadedStep> {
    step_from_record_with(shown, cols, None, None)
}

/// [`step_from_record`] with the voltage's ADC step `voltage_lsb` \[V\] if known (a noise-free
/// quantised step height is known only to ±½ step), and the current's, `current_lsb` \[A\],
/// for the record's [`MeasuredChannels`] (else found from the column's values).
pub fn step_from_record_with(
    shown: String,
    cols: Record,
    voltage_lsb: Option<f64>,
    current_lsb: Option<f64>,
) -> Result<LoadedStep> {
    let loc = locate_step_with(&cols.t, &cols.voltage, voltage_lsb)
        .map_err(|e| BadInput(format!("{shown}: {e}")))?;
    let from = loc.index;
    // Eq. (1)-(2) with Coulomb friction opposing the motion are odd in (E, I, Ω, θ): a
    // negative step from rest is the mirror image of a positive one, and is fitted as such.
    let sign = if loc.volts < 0.0 { -1.0 } else { 1.0 };
    // The record's own vectors, cut and mirrored in place.
    let tail = |mut v: Vec<f64>| {
        v.drain(..from.min(v.len()));
        if sign < 0.0 {
            v.iter_mut().for_each(|x| *x = -*x);
        }
        v
    };
    let speed = record_speed(&cols.t, cols.speed.as_deref(), cols.position.as_deref());
    let channels = measured_channels(&cols, current_lsb);
    // A step that comes back down is fitted whole, from rest at the first sample, as its
    // levels; the rise alone serves the paper's method.
    let whole = match loc.fall {
        Some(_) => {
            let (input, priors) = voltage_levels(&cols.t, &cols.voltage, voltage_lsb)
                .map_err(|e| BadInput(format!("{shown}: {e}")))?;
            Some(LoadedExcited {
                path: shown.clone(),
                label: shown.clone(),
                input,
                priors,
                dt: loc.dt,
                exclude_current: None,
                exclude_speed: None,
                record: cols.clone(),
            })
        }
        None => None,
    };
    let rise = loc.fall.map_or(usize::MAX, |f| f - from);
    Ok(LoadedStep {
        rise,
        whole,
        channels,
        label: shown.clone(),
        path: shown,
        volts: sign * loc.volts,
        mirrored: sign < 0.0,
        dt: loc.dt,
        current: tail(cols.current),
        speed: speed.map(tail),
        position: cols.position.map(tail),
        exclude_current: None,
        exclude_speed: None,
        inputs: loc.inputs(),
    })
}

/// The pair with the higher step first (the paper's method needs it: Eq. (33) is the high-voltage
/// approximation), and a note when the records were given the other way round.
pub fn in_order(hv: LoadedStep, lv: LoadedStep) -> (LoadedStep, LoadedStep, Option<String>) {
    if lv.volts > hv.volts {
        let note = format!(
            "--high {} steps to {:.4} V, below --low {} at {:.4} V: taken the other way round",
            hv.label, hv.volts, lv.label, lv.volts
        );
        (lv, hv, Some(note))
    } else {
        (hv, lv, None)
    }
}

/// [`fit::identify_step_pair`] on a high- and a low-voltage step record, errors naming both.
pub fn identify_pair(
    hv: &LoadedStep,
    lv: &LoadedStep,
    method: StepMethod,
) -> Result<StepPairIdentification> {
    identify_step_pair(
        &hv.step_record(),
        &lv.step_record(),
        method,
        LmSettings::default(),
    )
    .map_err(|e| {
        let label = format!("{} / {}", hv.label, lv.label);
        match &e {
            // Settled records whose steady states give no motor (k or Ts ≤ 0): valid data the
            // nominal model cannot explain, a failed identification, not bad input.
            fit::StepPairError::Start(f @ fit::FitError::Model { .. }) => NotConverged(format!(
                "{label}: {f} — the records' steady states do not follow the motor model (Eqs. (4), (5)) with \
                 positive parameters: an unmodelled effect (a brush voltage drop, a drag that grows with speed) \
                 does this; motorid diagnose names it"
            ))
            .into(),
            fit::StepPairError::Start(f) | fit::StepPairError::Full(f) => fit_error(&label, f),
            _ => BadInput(format!("{label}: {e}")).into(),
        }
    })
}

/// A record of any excitation, read and checked: owns what [`ExcitedRecord`] borrows.
pub struct LoadedExcited {
    /// File it came from.
    pub path: String,
    /// The file with the line span of its samples, for errors.
    pub label: String,
    /// The record (SI units).
    pub record: Record,
    /// The voltage waveform rebuilt from the voltage column, time from the first sample.
    pub input: Input,
    /// What the record leaves unknown about each level of `input` (empty for a replayed one).
    pub priors: Vec<LevelPrior>,
    dt: f64,
    exclude_current: Option<Vec<bool>>,
    exclude_speed: Option<Vec<bool>>,
}

impl LoadedExcited {
    /// The identification's view of the record.
    pub fn excited(&self) -> ExcitedRecord<'_> {
        ExcitedRecord {
            input: &self.input,
            dt: self.dt,
            current: &self.record.current,
            speed: self.record.speed.as_deref(),
            position: self.record.position.as_deref(),
            exclude_current: self.exclude_current.as_deref(),
            exclude_speed: self.exclude_speed.as_deref(),
        }
    }

    /// The voltage-and-speed identification's view of the record (its current, if any, is
    /// not used), starting at rest or in steady motion as `at_rest` says
    /// ([`SpeedRecord::at_rest`]).
    pub fn speed_record(&self, at_rest: Option<bool>) -> SpeedRecord<'_> {
        SpeedRecord {
            input: &self.input,
            dt: self.dt,
            speed: self.record.speed.as_deref(),
            position: self.record.position.as_deref(),
            exclude: self.exclude_speed.as_deref(),
            priors: &self.priors,
            at_rest,
        }
    }
}

/// Reads a record of a current-driven axis (current and position; voltage optional) and checks
/// that the position filter's `cutoff_hz` is below half its sample rate.
pub fn load_axis_record(path: &Path, map: &ColumnMap, cutoff_hz: f64) -> Result<Record> {
    let rec = crate::record_csv::read_mapped(path, map, false)?;
    if rec.position.is_none() {
        return Err(BadInput(format!("{}: no position column: --input current fits J, f, Ts from the position (map it with --columns position=HEADER)", path.display())).into());
    }
    // Each record's own rate: a pooled fit's refusal would not say which file.
    let rate_hz = 1.0 / motor_model::mean_period(&rec.t);
    if !(cutoff_hz > 0.0 && cutoff_hz < 0.5 * rate_hz) {
        return Err(BadInput(format!(
            "{}: --cutoff {} Hz is not below half its sample rate ({:.4} Hz): give a lower --cutoff, or records sampled faster",
            path.display(),
            cutoff_hz,
            0.5 * rate_hz
        ))
        .into());
    }
    Ok(rec)
}

/// The torque (force) `k I` of each record of a current-driven axis, `k` per unit of the
/// current column.
pub fn axis_torques(recs: &[Record], k: f64) -> Vec<Vec<f64>> {
    recs.iter()
        .map(|r| fit::motor_torque(k, &r.current))
        .collect()
}

/// The inverse model's view of each record: its period, its torque (from [`axis_torques`])
/// and its position.
pub fn axis_records<'a>(recs: &'a [Record], torques: &'a [Vec<f64>]) -> Vec<AxisRecord<'a>> {
    recs.iter()
        .zip(torques)
        .map(|(r, torque)| AxisRecord {
            dt: motor_model::mean_period(&r.t),
            torque,
            position: r.position.as_deref().unwrap_or_default(),
        })
        .collect()
}

/// Reads a record of any voltage waveform for the output-error fit.
pub fn load_excited(path: &Path, map: &ColumnMap, quiet: bool) -> Result<LoadedExcited> {
    excited_from(path, read_loaded(path, map, true)?, quiet)
}

/// A record of any voltage waveform read from `path` ([`load_excited`]): its voltage rebuilt,
/// clipped samples judged (and, unless `quiet`, warned about).
pub fn excited_from(path: &Path, loaded: Loaded, quiet: bool) -> Result<LoadedExcited> {
    let shown = path.display().to_string();
    let masks = check_clipping(&shown, &loaded, quiet)?;
    let label = file_lines(&shown, &loaded.lines);
    let header_line = loaded.lines.first().map_or(1, |l| l.saturating_sub(1));
    let rec = loaded.record;
    if rec.speed.is_none() && rec.position.is_none() {
        return Err(BadInput(format!(
            "{shown}:{header_line}: neither speed nor position: k, f, J and Ts need one of them"
        ))
        .into());
    }
    let (input, priors) = voltage_levels(&rec.t, &rec.voltage, loaded.voltage_lsb)
        .map_err(|e| BadInput(format!("{label}: {e}")))?;
    if input.peak_volts() == 0.0 {
        return Err(BadInput(format!(
            "{label}: the voltage is 0 V throughout: nothing drives the motor"
        ))
        .into());
    }
    let dt = motor_model::mean_period(&rec.t);
    Ok(LoadedExcited {
        path: shown,
        label,
        input,
        priors,
        dt,
        exclude_current: masks.current,
        exclude_speed: if rec.position.is_some() {
            None
        } else {
            masks.speed
        },
        record: rec,
    })
}

/// `file:a-b`: a file and the lines of its samples, for errors about a whole record.
pub fn file_lines(shown: &str, lines: &[usize]) -> String {
    format!(
        "{shown}:{}-{}",
        lines.first().copied().unwrap_or(0),
        lines.last().copied().unwrap_or(0)
    )
}

/// The output-error fit of `loaded` from `start`, or from the equation-error start when none is
/// given; errors name `label`, and a failed start adds `start_hint`. Each record starts from
/// the state its first samples show. Returns the start used and the fit.
pub fn fit_excited(
    loaded: &[LoadedExcited],
    start: Option<MotorParams>,
    label: &str,
    start_hint: &str,
) -> Result<(MotorParams, FullFit)> {
    fit_excited_from(loaded, None, start, label, start_hint).map(|f| (f.start, f.full))
}

/// An output-error fit with how each record's simulation started.
pub struct ExcitedFit {
    /// The start of the fit.
    pub start: MotorParams,
    /// The fit.
    pub full: FullFit,
    /// Each record's initial state and why: detected from its first samples, or given.
    pub initial: Vec<DetectedInitialState>,
}

/// [`fit_excited`] with every record's simulation started from `initial` if given
/// (`--initial-state`), else from the state its first samples show
/// ([`fit::detect_initial_state`]).
pub fn fit_excited_from(
    loaded: &[LoadedExcited],
    initial: Option<InitialState>,
    start: Option<MotorParams>,
    label: &str,
    start_hint: &str,
) -> Result<ExcitedFit> {
    let records: Vec<ExcitedRecord> = loaded.iter().map(LoadedExcited::excited).collect();
    let chosen = loaded
        .iter()
        .zip(&records)
        .map(|(l, r)| match initial {
            Some(state) => Ok(DetectedInitialState {
                state,
                reason: format!("given (--initial-state {})", state.name()),
            }),
            None => detect_initial_state(r).map_err(|e| BadInput(format!("{}: {e}", l.label))),
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let states: Vec<InitialState> = chosen.iter().map(|c| c.state).collect();
    let start = match start {
        Some(s) => s,
        None => equation_error_start_with_initial_states(&records, &states)
            .map_err(|e| BadInput(format!("{label}: {e}{start_hint}")))?,
    };
    let priors: Vec<Vec<LevelPrior>> = loaded.iter().map(|l| l.priors.clone()).collect();
    let (start, full) = OutputError::new(&records, start)
        .level_priors(&priors)
        .initial_states(&states)
        .fit_with_friction_restart()
        .map_err(|e| fit_error(label, &e))?;
    Ok(ExcitedFit {
        start,
        full,
        initial: chosen,
    })
}

/// kS, kV, kA (and τe where the records show it) of `loaded` from voltage and speed alone
/// ([`fit::identify_feedforward`]), with the back-EMF constant `torque_constant` \[N·m/A\]
/// where it is given, each record starting as `initial` says (`None`: as its speed shows;
/// `steady` and `free` alike: in steady motion at a fitted speed, the only motion the model
/// without current starts from); errors name `label`.
pub fn fit_voltage_speed(
    loaded: &[LoadedExcited],
    torque_constant: Option<f64>,
    initial: Option<fit::InitialState>,
    label: &str,
) -> Result<FeedforwardFit> {
    let at_rest = initial.map(|s| s == fit::InitialState::Rest);
    let records: Vec<SpeedRecord> = loaded.iter().map(|l| l.speed_record(at_rest)).collect();
    let settings = FeedforwardSettings {
        torque_constant,
        ..FeedforwardSettings::default()
    };
    identify_feedforward(&records, settings).map_err(|e| fit_error(label, &e))
}

/// The channels `rec` measured, for [`fit::RecordKind::decide`]: the current's range in ADC
/// steps (of `current_lsb` \[A\] from the `# measurement:` metadata, else from the column's own
/// values).
pub fn measured_channels(rec: &Record, current_lsb: Option<f64>) -> MeasuredChannels {
    MeasuredChannels {
        voltage: !rec.voltage.is_empty(),
        current: if rec.current.is_empty() {
            CurrentChannel::Absent
        } else {
            CurrentChannel::Present {
                adc_steps: current_adc_steps(&rec.current, current_lsb),
            }
        },
        position: rec.position.is_some(),
        tachometer: rec.speed.is_some(),
    }
}

/// The channels every one of `each` measured (a current in all of them, its coarsest range).
pub fn common_channels(each: &[MeasuredChannels]) -> MeasuredChannels {
    let all = |f: fn(&MeasuredChannels) -> bool| each.iter().all(f);
    let current = each.iter().try_fold(f64::INFINITY, |m, c| match c.current {
        CurrentChannel::Present { adc_steps } => Some(m.min(adc_steps)),
        CurrentChannel::Absent => None,
    });
    MeasuredChannels {
        voltage: all(|c| c.voltage),
        current: current.map_or(CurrentChannel::Absent, |adc_steps| {
            CurrentChannel::Present { adc_steps }
        }),
        position: all(|c| c.position),
        // Either speed serves the voltage-and-speed fit, record by record.
        tachometer: all(|c| c.position || c.tachometer),
    }
}
