//! `motorid emps`: the EMPS benchmark — identify the axis on its estimation record, then
//! simulate it in its closed loop on the validation record, where unknown force pulses act.
//!
//! The benchmark's constants, its relative error and the pulse-on/off split are
//! `motor_model`'s ([`PdController::emps`], [`EMPS_PULSE_COMMAND_V`], [`relative_error_percent`],
//! [`pulse_split`]): the column `pulses_N` is 5 V of drive command, 175.75 N on the axis.
//! Simulated that way, the validation record is matched as closely as the estimation record.

use anyhow::Result;
use fit::{identify_inverse_model, InverseModelSettings};
use motor_model::{
    pulse_split, relative_error_percent, simulate_pd_axis, AxisParams, PdController,
    EMPS_DRIVE_GAIN_N_PER_V as DRIVE_GAIN_N_PER_V, EMPS_KP_PER_S, EMPS_KV_V_PER_M_S,
    EMPS_PULSE_COMMAND_V, EMPS_PULSE_FORCE_N,
};
use plotters::style::{BLACK, BLUE, RED};
use serde_json::json;

use crate::args::EmpsArgs;
use crate::console::outln;
use crate::csv_table::{read_table, Table};
use crate::errors::BadInput;
use crate::plot::{self, Panel, Series};

/// Published IDIM-LS estimates the benchmark reports: M \[kg\], Fv \[N·s/m\], Fc \[N\] and
/// the offset \[N\].
const REFERENCE: AxisParams = AxisParams {
    mass_kg: 95.1089,
    viscous_ns_per_m: 203.5034,
    coulomb_n: 20.3935,
    offset_n: -3.1648,
};

/// Each identified parameter of `axis` beside the published one ([`REFERENCE`]): name (as in
/// [`fit::MECHANICAL_NAMES`]), identified and published value, in the axis's units.
fn against_reference(axis: &AxisParams) -> [(&'static str, f64, f64); 4] {
    let r = &REFERENCE;
    let [mass, viscous, coulomb, offset] = fit::MECHANICAL_NAMES;
    [
        (mass, axis.mass_kg, r.mass_kg),
        (viscous, axis.viscous_ns_per_m, r.viscous_ns_per_m),
        (coulomb, axis.coulomb_n, r.coulomb_n),
        (offset, axis.offset_n, r.offset_n),
    ]
}

fn column<'a>(table: &'a Table, name: &str, file: &str) -> Result<&'a [f64]> {
    table.column(name).ok_or_else(|| {
        BadInput(format!(
            "{file}: no `{name}` column: is this the EMPS data?"
        ))
        .into()
    })
}

/// Where `motorid emps` reads the benchmark and what it writes, from its arguments.
pub struct Settings {
    /// Folder holding `DATA_EMPS.csv` and `DATA_EMPS_PULSES.csv`.
    pub dir: std::path::PathBuf,
    /// Folder for the figure, if one is asked for.
    pub plot: Option<std::path::PathBuf>,
    /// One JSON object instead of the report.
    pub json: bool,
}

/// The EMPS folder when `--dir` is not given: `../shared/real-data/emps` from the working
/// folder (the repository's root) if it is there, else the same folder beside the source tree
/// this binary was built in, so that `motorid emps` runs from any folder of a checkout.
fn default_dir() -> std::path::PathBuf {
    let from_cwd = std::path::PathBuf::from("../shared/real-data/emps");
    let from_source =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/real-data/emps");
    if from_cwd.join("DATA_EMPS.csv").is_file() || !from_source.join("DATA_EMPS.csv").is_file() {
        from_cwd
    } else {
        from_source
    }
}

impl Settings {
    /// The options of `a` (paths are checked when they are read).
    pub fn from_args(a: &EmpsArgs) -> Settings {
        Settings {
            dir: a.dir.clone().unwrap_or_else(default_dir),
            plot: a.plot.clone(),
            json: a.json,
        }
    }
}

/// Identifies the axis on the estimation record, simulates both records in closed loop and
/// reports the gaps with and without the force pulses.
pub fn run(a: &Settings) -> Result<()> {
    let est_path = a.dir.join("DATA_EMPS.csv");
    let val_path = a.dir.join("DATA_EMPS_PULSES.csv");
    let (est, val) = (read_table(&est_path)?, read_table(&val_path)?);
    let (est_name, val_name) = (
        est_path.display().to_string(),
        val_path.display().to_string(),
    );
    let t = column(&est, "time_s", &est_name)?;
    let dt = motor_model::mean_period(t);
    let force: Vec<f64> = column(&est, "vir_controller_output_V", &est_name)?
        .iter()
        .map(|v| DRIVE_GAIN_N_PER_V * v)
        .collect();
    let fit = identify_inverse_model(
        dt,
        &force,
        column(&est, "qm_motor_position_m", &est_name)?,
        InverseModelSettings::default(),
    )
    .map_err(|e| BadInput(format!("{est_name}: {e}")))?;
    let axis = fit.axis;
    let pd = PdController::emps();

    // Simulate each record in closed loop from its reference; the validation one without and
    // with its force pulses.
    let simulate =
        |table: &Table, name: &str, pulses: bool| -> Result<(f64, f64, Vec<f64>, Vec<f64>)> {
            let qm = column(table, "qm_motor_position_m", name)?;
            let qg = column(table, "qg_reference_position_m", name)?;
            let vir = column(table, "vir_controller_output_V", name)?;
            // The pulses enter as drive command (see the module docs): force gτ·p on the axis, and
            // part of the recorded command.
            let disturbance: Option<Vec<f64>> = if pulses {
                Some(
                    column(table, "pulses_N", name)?
                        .iter()
                        .map(|p| DRIVE_GAIN_N_PER_V * p)
                        .collect(),
                )
            } else {
                None
            };
            let (q, controller_force) =
                simulate_pd_axis(&axis, &pd, qg, disturbance.as_deref(), dt, qm[0])
                    .map_err(|e| BadInput(e.to_string()))?;
            let applied: Vec<f64> = match &disturbance {
                Some(d) => controller_force.iter().zip(d).map(|(f, p)| f + p).collect(),
                None => controller_force,
            };
            let measured_force: Vec<f64> = vir.iter().map(|v| DRIVE_GAIN_N_PER_V * v).collect();
            Ok((
                relative_error_percent(qm, &q),
                relative_error_percent(&measured_force, &applied),
                q,
                applied,
            ))
        };
    let (est_pos, est_force, _, _) = simulate(&est, &est_name, false)?;
    let (val_pos, val_force, q_val, _) = simulate(&val, &val_name, false)?;
    let (val_pos_p, val_force_p, q_val_p, _) = simulate(&val, &val_name, true)?;

    // Where it hurts: position error near the pulses and away from them.
    let pulses = column(&val, "pulses_N", &val_name)?;
    let qm = column(&val, "qm_motor_position_m", &val_name)?;
    // While a pulse is on, the PD loop holds the axis off its reference by about
    // F/(gτ kp kv); that is where an unmodelled pulse shows.
    let near: Vec<bool> = pulses.iter().map(|p| *p != 0.0).collect();
    let without = pulse_split(qm, &q_val, &near);
    let with = pulse_split(qm, &q_val_p, &near);
    let (near_no, far_no) = (without.rms_on, without.rms_off);
    let (near_with, far_with) = (with.rms_on, with.rms_off);
    let near_fraction = without.fraction_on;

    if let Some(dir) = &a.plot {
        crate::output::create_dir(dir)?;
        let t_val = column(&val, "time_s", &val_name)?;
        let to_mm =
            |q: &[f64]| -> Vec<f64> { qm.iter().zip(q).map(|(m, s)| 1e3 * (m - s)).collect() };
        let (err_without, err_with) = (to_mm(&q_val), to_mm(&q_val_p));
        let pulse_force: Vec<f64> = pulses.iter().map(|p| DRIVE_GAIN_N_PER_V * p).collect();
        let written = plot::time_series(
            &dir.join("emps_pulses"),
            "EMPS validation record: measured minus simulated position",
            t_val,
            &[
                Panel {
                    y_label: "position error [mm]",
                    series: vec![
                        Series {
                            label: "pulses unmodelled",
                            values: &err_without,
                            color: RED,
                        },
                        Series {
                            label: "pulses in the model",
                            values: &err_with,
                            color: BLUE,
                        },
                    ],
                },
                Panel {
                    y_label: "pulse force [N]",
                    series: vec![Series {
                        label: &format!(
                            "pulses ({EMPS_PULSE_COMMAND_V} V of command x {DRIVE_GAIN_N_PER_V} N/V)"
                        ),
                        values: &pulse_force,
                        color: BLACK,
                    }],
                },
            ],
        )?;
        if !a.json {
            for path in written {
                outln!("wrote {}", path.display())?;
            }
        }
    }
    if a.json {
        let report = json!({
            "identified": against_reference(&axis).iter().map(|&(name, value, r)| json!({
                "name": name, "value": value, "reference": r, "relative_difference": value / r - 1.0,
            })).collect::<Vec<_>>(),
            "estimation_record": {"position_relerr_percent": est_pos, "force_relerr_percent": est_force},
            "validation_record": {
                "without_pulses": {"position_relerr_percent": val_pos, "force_relerr_percent": val_force,
                                    "position_rms_pulse_on_m": near_no, "position_rms_pulse_off_m": far_no},
                "with_pulses": {"position_relerr_percent": val_pos_p, "force_relerr_percent": val_force_p,
                                 "position_rms_pulse_on_m": near_with, "position_rms_pulse_off_m": far_with},
                "fraction_of_time_pulse_on": near_fraction,
                "pulse_force_n": EMPS_PULSE_FORCE_N,
            },
        });
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(());
    }
    outln!("EMPS — identified on {est_name} (force = {DRIVE_GAIN_N_PER_V} × vir), inverse model:")?;
    for (name, v, r) in against_reference(&axis) {
        outln!(
            "  {name:<6} {v:>10.4}   published IDIM-LS {r:>10.4}   ({:+.2} %)",
            100.0 * (v / r - 1.0)
        )?;
    }
    outln!("closed-loop simulation (PD: kp = {EMPS_KP_PER_S} 1/s, kv = {EMPS_KV_V_PER_M_S} V/(m/s)), relative errors 100·‖x − x̂‖/‖x‖:")?;
    outln!("  estimation record:                 position {est_pos:.4} %, force {est_force:.2} %")?;
    outln!(
        "  validation record, pulses unmodelled: position {val_pos:.4} %, force {val_force:.2} %"
    )?;
    outln!("  validation record, pulses added:      position {val_pos_p:.4} %, force {val_force_p:.2} %  (pulses as {EMPS_PULSE_COMMAND_V} V of drive command = {EMPS_PULSE_FORCE_N} N: the recorded vir jumps by ±{EMPS_PULSE_COMMAND_V} at each edge)")?;
    outln!(
        "where it hurts: position RMS error while a pulse is on ({:.0} % of the time) {:.3e} m with the pulses unmodelled, {:.3e} m with them; while off {:.3e} m / {:.3e} m",
        100.0 * near_fraction, near_no, near_with, far_no, far_with
    )?;
    Ok(())
}
