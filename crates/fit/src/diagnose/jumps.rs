//! The instants of the voltage jumps: each located within its sample period beside the model
//! being judged (alternating with the nominal refit, or by a Gauss–Newton step of the motor and
//! the instants together), and the records' inputs rebuilt at them.

use motor_model::{Effects, Input, MotorParams};
use nalgebra::DMatrix;

use crate::diagnose::base::Base;
use crate::diagnose::heldout::channel_sigma;
use crate::diagnose::report::DiagnoseSettings;
use crate::diagnose::screen::BaseProjection;
use crate::estimation::records::{Channel, ExcitedRecord};
use crate::excitation::output_error::{output_error_sensitivity, predict_with_step_factor};

/// Earliest instant a record's first voltage jump is searched at \[sample periods\].
pub(crate) const FIRST_JUMP_MARGIN: f64 = 0.02;

/// Golden-section rounds of the search for one voltage jump's instant (the bracket, one sample
/// period, shrinks to 0.618¹² ≈ 0.3 % of it).
pub(crate) const JUMP_SEARCH_ROUNDS: usize = 12;

/// Rounds at most of the nominal refit on located jump instants and their location again
/// ([`diagnose`]).
pub(crate) const NOMINAL_LOCATE_ROUNDS: usize = 6;

/// Largest move of a jump between two rounds at which they stop \[sample periods\].
pub(crate) const NOMINAL_LOCATE_SETTLED: f64 = 0.02;

/// The largest move of a voltage jump from `before` to `after` over the records of `grid`
/// \[sample periods of its record\]: infinite where a record's jumps cannot be compared (one
/// input piecewise constant and the other not, or a different number of jumps).
pub(crate) fn largest_jump_move(
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
pub(crate) fn locate_jumps(
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
pub(crate) const JUMP_DIFF_STEP: f64 = 0.05;

/// Record `k`'s weighted residuals `(simulated − measured)/σ` for `motor` with `effects` on
/// `input`, at the samples its masks keep, channel after channel: the rows
/// [`output_error_sensitivity`] gives it, each with its channel, its sample and its σ.
pub(crate) fn record_rows(
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
pub(crate) fn row_values(rows: &[(Channel, usize, f64, f64)]) -> Vec<f64> {
    rows.iter().map(|r| r.3).collect()
}

/// The base Jacobian `jacobian` (rows of `residuals`, the training records of `base`) with a
/// column for the instant of every voltage jump of a training record. The voltage column
/// tells only between which two samples a jump fell; where the records' samples are coarse
/// beside the electrical time constant, that instant, L and anything acting at the jumps (a
/// sensor lag, a saturating inductance) change the same few samples, and the screening must
/// not credit an effect with what a jump half a period earlier explains
/// ([`crate::diagnose::screen`] projects these columns out with the motor's). Unchanged when
/// the rows cannot be rebuilt exactly.
pub(crate) fn with_jump_columns(
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
pub(crate) struct JumpColumn {
    /// The record.
    pub(crate) record: usize,
    /// The jump, in the record's piecewise-constant levels.
    pub(crate) jump: usize,
    /// `∂ rows / ∂(−t)`, zero outside the record's rows.
    pub(crate) column: Vec<f64>,
}

/// The columns of the weighted residual rows of `train` for `model` (`residuals`, as
/// [`output_error_sensitivity`] gives them: [`record_rows`] record after record) in the instant
/// of every voltage jump after a record's first sample, by a backward difference of
/// [`JUMP_DIFF_STEP`] sample periods. `None` when the rows cannot be rebuilt exactly.
pub(crate) fn jump_columns(
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
pub(crate) fn jump_bracket(levels: &[(f64, f64)], j: usize, dt: f64) -> (f64, f64) {
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
pub(crate) fn jump_levels(input: &Input) -> Vec<(f64, f64)> {
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
pub(crate) fn jump_gauss_newton(
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

/// [`locate_every_jump`] on records `which` of `grid` (entry 0 is record `which.start`),
/// searched within the sample periods of `grid` (the records with their jumps where the
/// voltage column puts them); a record whose jumps stay keeps `grid`'s ([`filled_from_grid`]).
pub(crate) fn located_inputs(
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
pub(crate) fn filled_from_grid(
    located: Vec<Option<Input>>,
    grid: &[ExcitedRecord<'_>],
) -> Vec<Option<Input>> {
    located
        .into_iter()
        .zip(grid)
        .map(|(moved, r)| moved.or_else(|| Some(r.input.clone())))
        .collect()
}
