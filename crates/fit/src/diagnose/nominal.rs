//! The nominal model a diagnosis starts from: its fit to the training records
//! ([`fit_nominal`]), the localisation of its residual ([`localise_fit`]), and whether it is
//! usable as a base (an electrical time constant the records can simulate, channels it
//! explains).

use motor_model::{EffectKind, Effects, MotorParams};

use crate::diagnose::localise::{
    localise, Localisation, LocaliseSettings, ResidualChannel, ResidualRecord,
};
use crate::diagnose::report::DiagnoseSettings;
use crate::diagnose::starts::integrated_angle;
use crate::error::FitError;
use crate::estimation::fitted::FullFit;
use crate::estimation::parameters::EffectEstimate;
use crate::estimation::records::{Channel, ExcitedRecord, FittedChannel, PARAM_NAMES};
use crate::excitation::output_error::fit_output_error;

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
pub(crate) fn diagnosable(refusal: &crate::Refusal, kind: Option<EffectKind>) -> bool {
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

/// NRMSE of a training channel at or above which the base model is taken not to explain it: a
/// refit that leaves it worse than a constant (NRMSE above 1), but by no more than
/// `1 − UNEXPLAINED_CHANNEL` above the base model, is not refused for it.
pub(crate) const UNEXPLAINED_CHANNEL: f64 = 0.95;

/// Whether a nominal fit is one the diagnosis builds on: accepted, or converged and refused
/// only for what [`diagnosable`] allows a nominal model.
pub(crate) fn usable_nominal(fit: &FullFit) -> bool {
    fit.failure().is_none()
        || (fit.termination.converged()
            && fit.refusal.as_ref().is_some_and(|r| diagnosable(r, None)))
}

/// Whether a refit determines the effect's size: every fitted parameter has an interval no
/// wider than a hundred times its value.
pub(crate) fn determined(estimates: &[EffectEstimate]) -> bool {
    !estimates.is_empty()
        && estimates.iter().all(|e| {
            e.ci95
                .is_some_and(|[lo, hi]| (hi - lo).is_finite() && hi - lo <= 100.0 * e.value.abs())
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
