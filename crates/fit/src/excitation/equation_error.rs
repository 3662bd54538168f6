//! The equation-error start of an output-error fit: R and L from the electrical equation,
//! J, f and Ts from the torque equation (the inverse model), on low-passed, decimated records.

use motor_model::{central_difference, Effects, MotorParams};

use crate::current_driven::mechanical::{
    identify_inverse_model_pooled, motor_torque, AxisRecord, InverseModelSettings,
};
use crate::error::FitError;
use crate::estimation::lm::LeastSquares;
use crate::estimation::records::{ExcitedRecord, InitialState};
use crate::estimation::signal::Butterworth;
use crate::excitation::oe_problem::{check_record, OeProblem};
use crate::excitation::voltage::bad;

/// Samples per row of the equation-error start's torque equation (2b), at most \[-\].
pub(crate) const START_DECIMATION: usize = 5;

/// RK4 steps of [`equation_error_start`]'s simulations, as a multiple of the simulator's
/// default ([`Simulator::with_step_factor`]).
pub(crate) const START_STEP_FACTOR: f64 = 8.0;

/// Cut-offs tried by [`equation_error_start`], as fractions of the sample rate.
pub(crate) const START_CUTOFFS: [f64; 4] = [0.1, 0.02, 0.004, 0.0008];

/// A start for [`OutputError`](crate::OutputError) by equation error: the measured signals, low-passed
/// forward and backward (zero phase, 4th-order Butterworth), are put into the model's
/// equations, which are linear in the parameters: Eq. (2a) `E = R I + L dI/dt + k Ω` gives R, L,
/// k by least squares over every sample, and Eq. (2b) `k I = J dΩ/dt + f Ω + Ts sign Ω` the
/// rest (the inverse model of [`crate::identify_inverse_model`] on the motor torque `k I`, the
/// angle filtered five times harder). Derivatives of noisy signals bias such estimates towards
/// zero unless the filter is narrow, and a narrow filter distorts fast motors: so the estimate
/// is made at cut-offs of 1/10, 1/50, 1/250 and 1/1250 of the sample rate and the one whose
/// simulation fits the records best (output-error cost) is returned. Values the records cannot
/// resolve (an L below one sample, no friction seen) are replaced by small positive ones; a J
/// the torque equation gives as ≤ 0 (a torque ripple the regression does not hold, or too
/// little acceleration) by the best, by the same cost, of mechanical time constants
/// J / (f + k²/R) of 1/1000 to 1 times the longest record.
pub fn equation_error_start(records: &[ExcitedRecord<'_>]) -> Result<MotorParams, FitError> {
    equation_error_start_with_initial_states(records, &[])
}

/// [`equation_error_start`] for records whose simulations start from `initial` (as in
/// [`OutputError::initial_states`](crate::OutputError::initial_states)): the cut-off is chosen on the output-error
/// cost of those simulations, free states at the records' first samples.
pub fn equation_error_start_with_initial_states(
    records: &[ExcitedRecord<'_>],
    initial: &[InitialState],
) -> Result<MotorParams, FitError> {
    let mut problem = OeProblem::new(records, &Effects::none(), f64::INFINITY)?;
    problem.set_initial_states(initial, &Effects::none())?;
    // Telling four starts apart by their cost needs no more than noise-level accuracy.
    problem.step_factor = START_STEP_FACTOR;
    let mut best: Option<(f64, MotorParams)> = None;
    let mut first_error = None;
    for fraction in START_CUTOFFS {
        let starts = match equation_error_estimate(records, fraction) {
            Ok(starts) => starts,
            Err(e) => {
                first_error.get_or_insert(e);
                continue;
            }
        };
        for start in starts {
            if problem.set_step_for(&start, &Effects::none()).is_none() {
                first_error.get_or_insert(bad(
                    "records",
                    format!(
                        "the equation-error estimate (R {:.3e} Ω, L {:.3e} H) has a time constant far below the sample period",
                        start.r_ohm, start.l_henry
                    ),
                ));
                continue;
            }
            let theta = problem.with_state_guesses(start.values().iter().map(|v| v.ln()).collect());
            debug_assert_eq!(theta.len(), problem.parameters.len());
            let cost = problem.cost(&theta).unwrap_or(f64::INFINITY);
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                best = Some((cost, start));
            }
        }
    }
    match (best, first_error) {
        (Some((_, start)), _) => Ok(start),
        (None, Some(e)) => Err(e),
        (None, None) => Err(bad("records", "no start could be estimated".into())),
    }
}

/// R \[Ω\], L \[H\] and k \[N·m/A\] from Eq. (2a) `E = R I + L dI/dt + k Ω` by least squares
/// over every sample of `records`, the current and angle low-passed forward and backward (zero
/// phase, 4th-order Butterworth) at `fraction` of the sample rate and differentiated by central
/// differences. The torque constant of a drive that closes its own current loop follows from
/// its armature voltage this way (`motorid identify --input current` without
/// `--torque-constant`). An L the records cannot resolve (≤ 0) is replaced by half a sample's
/// worth, `R dt/2`.
pub fn electrical_equation(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<[f64; 3], FitError> {
    electrical_estimate(records, fraction).map(|(x, _)| x)
}

/// [`electrical_equation`], also returning each record's sample period and angle.
#[allow(clippy::type_complexity)]
pub(crate) fn electrical_estimate(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<([f64; 3], Vec<(f64, Vec<f64>)>), FitError> {
    let domain = |reason: String| FitError::MethodDomain {
        equation: "voltage equation (2a)",
        reason,
    };
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    let mut per_record = Vec::new();
    for (k, rec) in records.iter().enumerate() {
        check_record(k, rec)?;
        let n = rec.current.len();
        let dt = rec.dt;
        if n < crate::estimation::checks::MIN_SAMPLES || dt.is_nan() || dt <= 0.0 {
            return Err(bad(
                format!("record {}", k + 1),
                format!("{n} samples, period {dt} s: too short for a start"),
            ));
        }
        let times: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let position: Vec<f64> = match (rec.position, rec.speed) {
            (Some(p), _) => p.to_vec(),
            (None, Some(w)) => {
                // The angle as the running trapezoid integral of the tachometer speed.
                let mut theta = Vec::with_capacity(n);
                let mut acc = 0.0;
                theta.push(0.0);
                for i in 1..n {
                    acc += 0.5 * (w[i] + w[i - 1]) * dt;
                    theta.push(acc);
                }
                theta
            }
            (None, None) => {
                return Err(domain(format!(
                    "record {} has neither speed nor position: k, f and J need one of them",
                    k + 1
                )))
            }
        };
        let filter = Butterworth::low_pass(4, fraction / dt, 1.0 / dt)?;
        let i_f = filter.filtfilt(rec.current);
        let th_f = filter.filtfilt(&position);
        let w_f = central_difference(&times, &th_f);
        let di = central_difference(&times, &i_f);
        for j in 0..n {
            let e = rec.input.volts_at(times[j]);
            let row = nalgebra::Vector3::new(i_f[j], di[j], w_f[j]);
            ata += row * row.transpose();
            atb += row * e;
        }
        per_record.push((dt, position));
    }
    let x = ata.cholesky().map(|c| c.solve(&atb)).ok_or_else(|| {
        domain(
            "the voltage equation is singular: does the motor move, and does the voltage vary?"
                .into(),
        )
    })?;
    let (r, mut l, k) = (x[0], x[1], x[2]);
    let span = records
        .iter()
        .map(|r| r.dt * r.current.len() as f64)
        .fold(0.0, f64::max);
    if !(r > 0.0 && k > 0.0 && r.is_finite() && k.is_finite()) {
        return Err(domain(format!(
            "R = {r:.4e} Ω, k = {k:.4e} N·m/A from the voltage equation: either the records show too little \
             motion to tell R I from k Ω (the longest lasts {span:.4e} s: record until the speed settles), or the \
             current or speed sign is reversed"
        )));
    }
    let dt_min = per_record.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    if !(l > 0.0 && l.is_finite()) {
        l = 0.5 * r * dt_min;
    }
    Ok(([r, l, k], per_record))
}

/// One equation-error estimate with the electrical signals low-passed at `fraction` of the
/// sample rate (the angle at a fifth of that, with decimation by 5, or less on records too
/// short for twenty rows at 5): one start, or several differing only in J when the torque
/// equation leaves J unresolved.
pub(crate) fn equation_error_estimate(
    records: &[ExcitedRecord<'_>],
    fraction: f64,
) -> Result<Vec<MotorParams>, FitError> {
    let domain = |reason: String| FitError::MethodDomain {
        equation: "equation-error start (Eq. (2))",
        reason,
    };
    let ([r, l, k], per_record) = electrical_estimate(records, fraction)?;
    // The mechanical side on the motor torque k I: one inverse model over every record (each
    // filtered on its own, samples at rest left out), so that its error is the real one.
    let torques: Vec<Vec<f64>> = records
        .iter()
        .map(|rec| motor_torque(k, rec.current))
        .collect();
    let axis: Vec<AxisRecord<'_>> = per_record
        .iter()
        .zip(&torques)
        .map(|((dt, position), torque)| AxisRecord {
            dt: *dt,
            torque,
            position,
        })
        .collect();
    let dt_max = per_record.iter().map(|(dt, _)| *dt).fold(0.0_f64, f64::max);
    // Accelerations are second differences of a quantised angle: filter harder than the
    // electrical side and average by decimation, or the noise in the acceleration regressor
    // biases J towards zero. Every START_DECIMATION-th sample, or as many as the shortest
    // record leaves twenty rows at (a 0.1 s step at 1 kHz has 101 samples); a record too
    // short even for every sample is refused with the count every sample would need.
    let shortest = per_record
        .iter()
        .map(|(_, position)| position.len())
        .min()
        .unwrap_or(0);
    let decimation = (1..=START_DECIMATION)
        .rev()
        .find(|&d| shortest >= crate::current_driven::mechanical::min_samples(d))
        .unwrap_or(1);
    let settings = InverseModelSettings {
        position_cutoff_hz: 0.2 * fraction / dt_max,
        position_filter_order: 4,
        decimation,
        // Eq. (2b) has no offset; with one, a record that never reverses cannot tell it from
        // Ts (a 40 V step gave Ts = 2443 N·m against an offset of −2443 N·m).
        fit_offset: false,
    };
    let mechanical = identify_inverse_model_pooled(&axis, settings)
        .map_err(|e| domain(format!("the torque equation (2b): {e}")))?;
    let motor_model::AxisParams {
        mass_kg: j,
        viscous_ns_per_m: f,
        coulomb_n: ts,
        ..
    } = mechanical.axis;
    let f = if f > 0.0 { f } else { 1e-3 * k * k / r };
    let peak_torque = records
        .iter()
        .flat_map(|r| r.current.iter())
        .fold(0.0f64, |m, i| m.max((k * i).abs()));
    let ts = if ts > 0.0 { ts } else { 1e-3 * peak_torque };
    let motor = |j: f64| {
        MotorParams::new(r, l, k, f, j, ts)
            .map_err(FitError::model("equation-error start (Eq. (2))"))
    };
    if j > 0.0 && j.is_finite() {
        return Ok(vec![motor(j)?]);
    }
    // A J the torque equation cannot resolve (a torque ripple or a load the regression does
    // not hold, against too little acceleration): one J per mechanical time constant
    // J / (f + k²/R) of UNRESOLVED_J_SPANS times the longest record, for the caller's costs.
    let span = records
        .iter()
        .map(|r| r.dt * r.current.len().saturating_sub(1) as f64)
        .fold(0.0, f64::max);
    let damping = f + k * k / r;
    let starts: Vec<MotorParams> = UNRESOLVED_J_SPANS
        .iter()
        .filter_map(|share| motor(share * span * damping).ok())
        .collect();
    if starts.is_empty() {
        return Err(domain(format!(
            "J = {j:.4e} kg·m² from the torque equation: the records show too little acceleration"
        )));
    }
    Ok(starts)
}

/// Mechanical time constants tried by [`equation_error_start`] when the torque equation
/// gives no positive J, as shares of the longest record \[-\].
pub(crate) const UNRESOLVED_J_SPANS: [f64; 4] = [1e-3, 1e-2, 1e-1, 1.0];
