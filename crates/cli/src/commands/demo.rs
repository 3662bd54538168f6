//! `motorid demo`: the paper's example, end to end, against its printed tables.

use anyhow::Result;
use motor_model::{Derived, Effects, Input, MotorParams, Simulator, StepResponse};

use crate::args::DemoArgs;
use crate::commands::simulate;
use crate::paper_values::{
    compare, HIGH_VOLTAGE_V, LOGGER_RATE_HZ, LOW_VOLTAGE_V, TABLE_1, TABLE_2, TEST_LENGTH_S,
};
use crate::record_csv;

fn mark(same: bool) -> &'static str {
    if same {
        "="
    } else {
        "≠"
    }
}

pub fn run(a: &DemoArgs) -> Result<()> {
    let motor = MotorParams::paper();
    let d = Derived::new(&motor);
    println!("motorid demo — the simulated motor of the paper's Sec. 4.1");
    println!(
        "R = {} ohm, L = {} H, k = {} N·m/A, f = {} N·m·s/rad, J = {} kg·m², Ts = {} N·m\n",
        motor.r_ohm,
        motor.l_henry,
        motor.k_nm_per_a,
        motor.f_nms_per_rad,
        motor.j_kgm2,
        motor.ts_nm
    );

    println!("Table 1 — derived constants, Eqs. (16)-(26)");
    println!(
        "  {:<6} {:>12} {:>12}    {:<8}",
        "", "motorid", "paper", "unit"
    );
    let ours = |key: &str| match key {
        "KE" => d.k_e,
        "Ks" => d.k_s,
        "wn" => d.omega_n,
        "zeta" => d.zeta,
        "sigma" => d.sigma,
        "wa" => d.omega_a,
        "tau_m" => d.tau_m,
        "tau_e" => d.tau_e,
        "alpha" => d.alpha.unwrap_or(f64::NAN),
        "gamma" => d.gamma.unwrap_or(f64::NAN),
        _ => d.i0,
    };
    for (key, printed, unit) in TABLE_1 {
        let (text, same) = compare(ours(key), printed);
        let note = if key == "wa" && !same {
            "  (paper's typo: 0.3381 for 0.3881, cf. its Table 3)"
        } else {
            ""
        };
        println!(
            "  {key:<6} {text:>12} {} {printed:<10} {unit:<8}{note}",
            mark(same)
        );
    }

    println!("\nTable 2 — values at t = {TEST_LENGTH_S} s (exact response; RK4 stick-slip simulation beside it)");
    let mut records = Vec::new();
    for (e, rows) in [
        (HIGH_VOLTAGE_V, &TABLE_2[0..2]),
        (LOW_VOLTAGE_V, &TABLE_2[2..4]),
    ] {
        let exact = StepResponse::new(&motor, e).at(TEST_LENGTH_S);
        let input = Input::step(e, 0.0)?;
        let sim = Simulator::new(motor, Effects::none(), input.clone())?
            .run(TEST_LENGTH_S, LOGGER_RATE_HZ)?;
        let last = sim.t.len() - 1;
        for (i, (test, qty, printed, unit)) in rows.iter().enumerate() {
            let (value, simulated) = if i == 0 {
                (exact.current_a, sim.current[last])
            } else {
                (exact.speed_rad_s, sim.speed[last])
            };
            let (text, same) = compare(value, printed);
            println!(
                "  {test:<11} {qty:<3} {text:>9} {} {printed:<7} {unit:<6} (exact {value:.6}, simulated {simulated:.6})",
                mark(same)
            );
        }
        records.push((e, input, sim));
    }
    let t0_high = StepResponse::new(&motor, HIGH_VOLTAGE_V).breakaway_time();
    let t0_low = StepResponse::new(&motor, LOW_VOLTAGE_V).breakaway_time();
    println!(
        "\nBreakaway, Eq. (11): t0 = {:.4} ms at {HIGH_VOLTAGE_V} V, {:.4} ms at {LOW_VOLTAGE_V} V",
        t0_high.unwrap_or(f64::NAN) * 1e3,
        t0_low.unwrap_or(f64::NAN) * 1e3
    );
    println!("Identification (the paper's method and the full model) will follow in this demo.");

    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
        for (e, input, trace) in records {
            let record = motor_model::MeasurementModel::default().apply(&trace)?;
            let path = dir.join(format!("paper_{e}V.csv"));
            record_csv::write_file(
                &path,
                &record,
                &simulate::metadata(&motor, &Effects::none(), &input),
            )?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
