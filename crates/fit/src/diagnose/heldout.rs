//! The held-out blocks of the training records and the statistics judged on them: which
//! samples each fit leaves out ([`split`]), the NRMSE of a model on them, and the training
//! statistic and fall of a refit.

use crate::diagnose::localise::floor::correlation_factor;
use crate::diagnose::report::DiagnoseSettings;
use crate::diagnose::screen::CORRELATION_LAGS;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel};

/// The records with the held-out blocks excluded (owned masks).
pub(crate) struct Split {
    pub(crate) current_masks: Vec<Vec<bool>>,
    pub(crate) speed_masks: Vec<Vec<bool>>,
    /// Per record, whether each sample is held out.
    pub(crate) held: Vec<Vec<bool>>,
}

pub(crate) fn split(records: &[ExcitedRecord<'_>], settings: &DiagnoseSettings) -> Split {
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
pub(crate) fn record_block(n: usize, settings: &DiagnoseSettings) -> usize {
    (n / (2 * settings.holdout_every.max(2))).clamp(1, settings.block_samples.max(1))
}

/// NRMSE summary over channels (SPEC section 7: each channel's, weighted by sample count) of
/// the samples `keep` selects.
pub(crate) fn nrmse_summary(
    channels: &[FittedChannel],
    keep: impl Fn(&FittedChannel, usize) -> bool,
) -> f64 {
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
pub(crate) fn channel_nrmse(
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
pub(crate) fn channel_sigma(
    sigmas: &[(usize, Channel, f64)],
    record: usize,
    channel: Channel,
) -> Option<f64> {
    sigmas
        .iter()
        .find(|(r, c, _)| *r == record && *c == channel)
        .map(|s| s.2)
}

/// Held-out squared errors per block, each channel's residual over its noise level `sigma`.
/// A block is a run of consecutive held-out samples of a record (a training record's held-out
/// block), cut every `block` samples (a validation record, held out whole).
pub(crate) fn block_sse(
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
pub(crate) fn train_statistic(
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
pub(crate) fn train_fall(
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
