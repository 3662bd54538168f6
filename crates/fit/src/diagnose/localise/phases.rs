//! The phases of a record (rest, transients, steady runs, stops) from its voltage and speed.

use motor_model::Input;

use crate::diagnose::localise::channel::{mean_of, smooth};
use crate::diagnose::localise::floor::{
    PEAK_FRACTION, PEAK_LEVEL, PHASE_SMOOTHING, SETTLED_FRACTION, STOPPED_FRACTION,
    UNSETTLED_FRACTION, VOLTAGE_OFF_FRACTION,
};
use crate::diagnose::localise::types::{Phase, PhaseKind, ResidualRecord};
use crate::estimation::records::noise_std;
use crate::excitation::voltage::voltage_input;

/// Intervals collected in order, merging neighbours of one kind and dropping empty ones.
pub(crate) struct PhaseList {
    pub(crate) dt: f64,
    pub(crate) phases: Vec<Phase>,
}

impl PhaseList {
    pub(crate) fn push(&mut self, kind: PhaseKind, start: usize, end: usize) {
        if end <= start {
            return;
        }
        if let Some(last) = self.phases.last_mut() {
            if last.kind == kind && last.end == start {
                last.end = end;
                last.t_end_s = end as f64 * self.dt;
                return;
            }
        }
        self.phases.push(Phase {
            kind,
            start,
            end,
            t_start_s: start as f64 * self.dt,
            t_end_s: end as f64 * self.dt,
        });
    }

    /// Runs of `a..e` labelled by `label`.
    pub(crate) fn runs(&mut self, a: usize, e: usize, label: impl Fn(usize) -> PhaseKind) {
        let mut s = a;
        while s < e {
            let kind = label(s);
            let mut t = s + 1;
            while t < e && label(t) == kind {
                t += 1;
            }
            self.push(kind, s, t);
            s = t;
        }
    }
}

/// The phases of a record, from its voltage levels and its measured speed and current
/// (moving averages over five samples).
pub(crate) fn detect_phases(rec: &ResidualRecord, n: usize) -> Vec<Phase> {
    let dt = rec.dt;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let starts: Option<Vec<usize>> = match voltage_input(&t, rec.voltage) {
        Ok(Input::Piecewise { times_s, .. }) => Some(
            times_s
                .iter()
                .map(|ts| ((ts / dt).round() as usize).min(n))
                .collect(),
        ),
        _ => None,
    };
    let h = PHASE_SMOOTHING;
    let w = rec.speed.map(|s| smooth(s, h));
    let cur = rec.current.map(|c| smooth(c, h));
    let v_max = rec.voltage.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let w_max = w
        .as_deref()
        .map_or(0.0, |w| w.iter().fold(0.0f64, |m, v| m.max(v.abs())));
    let w_thr = STOPPED_FRACTION * w_max;
    let stopped = |i: usize| w.as_deref().is_some_and(|w| w[i].abs() <= w_thr);
    let mut list = PhaseList {
        dt,
        phases: Vec::new(),
    };
    let Some(starts) = starts else {
        // No levels: label by motion only.
        list.runs(0, n, |i| {
            let on = rec.voltage[i].abs() > VOLTAGE_OFF_FRACTION * v_max;
            match (w.is_some(), stopped(i), on) {
                (true, true, true) => PhaseKind::Sticking,
                (true, true, false) => PhaseKind::Rest,
                _ => PhaseKind::Moving,
            }
        });
        return list.phases;
    };
    // Noise of the smoothed signals, for the settled tolerance.
    let noise =
        |x: Option<&[f64]>| x.map_or(0.0, |x| 3.0 * noise_std(x) / ((2 * h + 1) as f64).sqrt());
    let (w_noise, i_noise) = (noise(rec.speed), noise(rec.current));
    for (j, &a) in starts.iter().enumerate() {
        let e = starts.get(j + 1).copied().unwrap_or(n).min(n);
        if e <= a {
            continue;
        }
        let level = mean_of(&rec.voltage[a..e]);
        if level.abs() <= VOLTAGE_OFF_FRACTION * v_max {
            list.runs(a, e, |i| {
                if w.is_none() || stopped(i) {
                    PhaseKind::Rest
                } else {
                    PhaseKind::Settling
                }
            });
            continue;
        }
        let tail = |x: &[f64], from: usize| mean_of(&x[from + (e - from) * 9 / 10..e]);
        let mut i = a;
        if let Some(w) = w.as_deref() {
            if stopped(a) {
                let b = (a..e).find(|&k| !stopped(k)).unwrap_or(e);
                list.push(PhaseKind::BeforeBreakaway, a, b);
                i = b;
            } else {
                let w_ss = tail(w, a);
                if w[a] * w_ss < 0.0 && w_ss.abs() > w_thr {
                    let z = (a..e)
                        .find(|&k| w[k] * w_ss > 0.0 && w[k].abs() >= 0.2 * w_ss.abs())
                        .unwrap_or(e);
                    list.runs(a, z, |k| {
                        if stopped(k) {
                            PhaseKind::Sticking
                        } else {
                            PhaseKind::Reversal
                        }
                    });
                    i = z;
                }
            }
        }
        if i >= e {
            continue;
        }
        let w_ss = w.as_deref().map(|w| tail(w, i));
        let i_ss = cur.as_deref().map(|c| tail(c, i));
        let settled = |k: usize| {
            let ok_w = match (w.as_deref(), w_ss) {
                (Some(w), Some(ss)) => (w[k] - ss).abs() <= SETTLED_FRACTION * ss.abs() + w_noise,
                _ => true,
            };
            let ok_i = match (cur.as_deref(), i_ss) {
                (Some(c), Some(ss)) => (c[k] - ss).abs() <= SETTLED_FRACTION * ss.abs() + i_noise,
                _ => true,
            };
            ok_w && ok_i
        };
        // The earliest start of a suffix with at most 1 % of its samples unsettled (a noise
        // spike alone does not end a steady state).
        let (mut s, mut unsettled) = (e, 0usize);
        for k in (i..e).rev() {
            if !settled(k) {
                unsettled += 1;
            }
            if unsettled as f64 <= UNSETTLED_FRACTION * (e - k) as f64 {
                s = k;
            }
        }
        let sgn = level.signum();
        let peak = cur.as_deref().zip(i_ss).and_then(|(c, ss)| {
            let (p, top) = (i..e)
                .map(|k| (k, sgn * c[k]))
                .fold((i, f64::NEG_INFINITY), |b, x| if x.1 > b.1 { x } else { b });
            let base = sgn * ss;
            let notable = top - base > PEAK_FRACTION * base.abs() + i_noise;
            (notable && p < e - (e - i) / 10).then(|| {
                let half = base + PEAK_LEVEL * (top - base);
                let mut lo = p;
                while lo > i && sgn * c[lo - 1] >= half {
                    lo -= 1;
                }
                let mut hi = p + 1;
                while hi < e && sgn * c[hi] >= half {
                    hi += 1;
                }
                (lo, hi)
            })
        });
        let rise_end = match peak {
            Some((lo, _)) => lo,
            None => match (w.as_deref(), w_ss, cur.as_deref(), i_ss) {
                (Some(w), Some(ss), _, _) => {
                    (i..e).find(|&k| w[k].abs() >= 0.9 * ss.abs()).unwrap_or(e)
                }
                (_, _, Some(c), Some(ss)) => {
                    (i..e).find(|&k| sgn * c[k] >= 0.9 * sgn * ss).unwrap_or(e)
                }
                _ => i,
            },
        };
        list.push(PhaseKind::Rise, i, rise_end);
        let after = match peak {
            Some((lo, hi)) => {
                list.push(PhaseKind::Peak, lo, hi);
                hi
            }
            None => rise_end,
        };
        let steady_from = s.max(after);
        list.push(PhaseKind::Settling, after, steady_from);
        list.push(PhaseKind::Steady, steady_from, e);
    }
    list.phases
}
