//! Three step records of a small servo through the paper's logger, for the diagnosis's
//! examples and bench: 12 V, 3 V and 0.6 V, each 1 s at 5 kHz (5,001 samples), the step at 50 ms;
//! and the examples' table of every candidate of every stage.

#![allow(dead_code)]

use fit::diagnose::Diagnosis;
use fit::{voltage_input, ExcitedRecord};
use motor_model::{Effects, Input, MeasurementModel, MotorParams, Record};

/// Sample period \[s\].
pub const DT_S: f64 = 2e-4;

/// The servo: R 2 Ω, L 2 mH, k 0.05 N·m/A, f 4e-4 N·m·s/rad, J 2e-5 kg·m², Ts 4 mN·m.
pub fn servo() -> MotorParams {
    MotorParams::new(2.0, 2e-3, 0.05, 4e-4, 2e-5, 4e-3).expect("valid motor")
}

/// The three records of the servo with `effects` (logger seeds 10, 11, 12), each with the
/// voltage waveform rebuilt from its measured voltage.
pub fn servo_steps(effects: Effects) -> Result<Vec<(Input, Record)>, Box<dyn std::error::Error>> {
    let motor = servo();
    let mut records = Vec::new();
    for (k, volts) in [12.0, 3.0, 0.6].iter().enumerate() {
        let input = Input::step(*volts, 0.05)?;
        let trace = motor_model::simulate(&motor, effects, &input, 1.0, 1.0 / DT_S)?;
        let record = MeasurementModel::paper_logger(&trace, 10 + k as u64).apply(&trace)?;
        let input = voltage_input(&record.t, &record.voltage)?;
        records.push((input, record));
    }
    Ok(records)
}

/// The records as the diagnosis takes them (current and encoder angle).
pub fn excited(records: &[(Input, Record)]) -> Vec<ExcitedRecord<'_>> {
    records
        .iter()
        .map(|(input, r)| ExcitedRecord {
            input,
            dt: DT_S,
            current: &r.current,
            speed: None,
            position: r.position.as_deref(),
            exclude_current: None,
            exclude_speed: None,
        })
        .collect()
}

/// Prints every candidate of every stage of `d`: its assessment, screening score, refit p-value,
/// training and held-out NRMSE before and after, and fitted parameters.
pub fn print_stages(d: &Diagnosis) {
    for stage in &d.stages {
        println!(
            "stage on top of {:?}: verdict {:?}, ambiguous with {:?}",
            stage.base, stage.verdict.verdict, stage.verdict.ambiguous_with
        );
        for c in &stage.candidates {
            println!(
                "  {:<22} {:<31} score {:>10.2e} p {:.2e}  train {:.4}→{:.4}  held-out {:.4}→{:.4}  {:?} {}",
                c.name,
                c.assessment.words(),
                c.screening.map_or(f64::NAN, |s| s.statistic),
                c.p_value,
                c.train_nrmse_before,
                c.train_nrmse_after,
                c.heldout_nrmse_before,
                c.heldout_nrmse_after,
                c.params.iter().map(|p| (p.symbol, p.value)).collect::<Vec<_>>(),
                c.failure.as_deref().unwrap_or("")
            );
        }
    }
}
