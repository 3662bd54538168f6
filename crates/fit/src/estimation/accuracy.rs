//! Accuracy against a known truth: each parameter's relative error and whether its 95 %
//! interval contains the truth, and over many identifications the median error and the
//! intervals' coverage (for simulated motors, a fleet with its `motor.json`, a benchmark).

use motor_model::MotorParams;

use crate::estimation::intervals::MotorIntervals;
use crate::estimation::records::{PARAM_NAMES, PARAM_UNITS};

/// One parameter of one identification against its truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParameterAccuracy {
    /// Name as in [`PARAM_NAMES`].
    pub name: &'static str,
    /// SI unit as in [`PARAM_UNITS`].
    pub unit: &'static str,
    /// The true value (SI units).
    pub truth: f64,
    /// The identified value (SI units).
    pub estimate: f64,
    /// `estimate/truth − 1` \[-\] ([`relative_error`]).
    pub relative_error: f64,
    /// Whether the 95 % interval contains the truth; `None` without an interval.
    pub covered: Option<bool>,
}

/// Relative error \[-\] of `estimate` against `truth`: `estimate/truth − 1` (within one
/// rounding of the ratio, 1.1e-16, of the exact value).
pub fn relative_error(estimate: f64, truth: f64) -> f64 {
    estimate / truth - 1.0
}

/// Whether `value` lies in the closed interval `[lo, hi]`.
pub fn contains(interval: [f64; 2], value: f64) -> bool {
    interval[0] <= value && value <= interval[1]
}

/// The six parameters of `estimate` against `truth` (in the order of [`PARAM_NAMES`]), with
/// the 95 % intervals `ci95` if there are any.
pub fn accuracy(
    estimate: &MotorParams,
    ci95: Option<&MotorIntervals>,
    truth: &MotorParams,
) -> Vec<ParameterAccuracy> {
    PARAM_NAMES
        .into_iter()
        .zip(PARAM_UNITS)
        .zip(estimate.values().into_iter().zip(truth.values()))
        .map(|((name, unit), (estimate, truth))| ParameterAccuracy {
            name,
            unit,
            truth,
            estimate,
            relative_error: relative_error(estimate, truth),
            covered: ci95.and_then(|c| c.get(name)).map(|c| contains(c, truth)),
        })
        .collect()
}

/// The median of `xs` (the upper one of an even count, a sample of the set), NaN ordered
/// last; `None` when empty.
pub fn median(xs: impl IntoIterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = xs.into_iter().collect();
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// One parameter over many identifications of known motors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParameterSummary {
    /// Name as in [`PARAM_NAMES`].
    pub name: &'static str,
    /// Median of `|relative error|` \[-\]; `None` without identifications.
    pub median_abs_relative_error: Option<f64>,
    /// Identifications whose 95 % interval contains the truth.
    pub covered: usize,
    /// Identifications with an interval.
    pub with_ci: usize,
}

impl ParameterSummary {
    /// Fraction \[-\] of the intervals that contain the truth (0 without intervals).
    pub fn coverage(&self) -> f64 {
        self.covered as f64 / self.with_ci.max(1) as f64
    }
}

/// Per parameter (in the order of [`PARAM_NAMES`]), the median `|relative error|` and the
/// interval coverage over `runs` (each the output of [`accuracy`]).
pub fn summarize<'a>(
    runs: impl IntoIterator<Item = &'a [ParameterAccuracy]> + Clone,
) -> Vec<ParameterSummary> {
    (0..PARAM_NAMES.len())
        .map(|k| {
            let mut errors = Vec::new();
            let (mut covered, mut with_ci) = (0, 0);
            for run in runs.clone() {
                let Some(p) = run.get(k) else { continue };
                errors.push(p.relative_error.abs());
                if let Some(c) = p.covered {
                    with_ci += 1;
                    covered += usize::from(c);
                }
            }
            ParameterSummary {
                name: PARAM_NAMES[k],
                median_abs_relative_error: median(errors),
                covered,
                with_ci,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scaled(p: &MotorParams, by: f64) -> MotorParams {
        MotorParams::from_values(p.values().map(|v| v * by)).unwrap()
    }

    #[test]
    fn relative_error_and_coverage_per_parameter() {
        let truth = MotorParams::paper();
        let est = scaled(&truth, 1.02);
        let mut ci = MotorIntervals::relative(&est, 0.1);
        // Ts, the last, with an interval too narrow to hold the truth.
        ci.ts_nm = [est.ts_nm * 0.999, est.ts_nm * 1.001];
        let acc = accuracy(&est, Some(&ci), &truth);
        assert_eq!(acc.len(), 6);
        assert_eq!(acc[0].name, "R");
        assert_eq!(acc[5].unit, "N·m");
        for a in &acc {
            assert!((a.relative_error - 0.02).abs() < 1e-12, "{a:?}");
        }
        assert_eq!(acc[0].covered, Some(true));
        assert_eq!(acc[5].covered, Some(false));
        assert!(accuracy(&est, None, &truth)
            .iter()
            .all(|a| a.covered.is_none()));
    }

    #[test]
    fn median_is_the_middle_sample() {
        assert_eq!(median([3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median([4.0, 1.0, 3.0, 2.0]), Some(3.0));
        assert_eq!(median(std::iter::empty()), None);
    }

    #[test]
    fn summary_counts_coverage_and_takes_median_of_magnitudes() {
        let truth = MotorParams::paper();
        let runs: Vec<Vec<ParameterAccuracy>> = [0.99, 1.03, 1.01]
            .iter()
            .map(|&s| {
                let est = scaled(&truth, s);
                let ci = MotorIntervals::relative(&est, 0.015);
                accuracy(&est, Some(&ci), &truth)
            })
            .collect();
        let summary = summarize(runs.iter().map(Vec::as_slice));
        assert_eq!(summary.len(), 6);
        for s in &summary {
            let med = s.median_abs_relative_error.unwrap();
            assert!((med - 0.01).abs() < 1e-9, "{s:?}");
            assert_eq!((s.covered, s.with_ci), (2, 3));
            assert!((s.coverage() - 2.0 / 3.0).abs() < 1e-12);
        }
        let none = summarize(std::iter::empty::<&[ParameterAccuracy]>());
        assert!(none
            .iter()
            .all(|s| s.median_abs_relative_error.is_none() && s.coverage() == 0.0));
    }
}
