//! Diagnoses a simulated small servo with one withheld effect from three step records through
//! the logger: `cargo run --release -p fit --example diagnose -- [EFFECT]` (default
//! `quadratic_drag:c=2e-7`; `none` for the nominal motor).

use std::time::Instant;

use fit::diagnose::{diagnose, DiagnoseProgress, DiagnoseSettings};
use fit::equation_error_start;
use motor_model::{Effect, Effects};

#[path = "../tests/common/diagnose_records.rs"]
mod records;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let spec = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "quadratic_drag:c=2e-7".into());
    let effect: Effect = spec.parse()?;
    let records = records::servo_steps(Effects::none().with(effect))?;
    let excited = records::excited(&records);
    let t0 = Instant::now();
    let start = equation_error_start(&excited)?;
    let progress =
        |p: DiagnoseProgress| eprintln!("  {p:?} at {:.2} s", t0.elapsed().as_secs_f64());
    let d = diagnose(
        &excited,
        &[],
        &["12 V", "3 V", "0.6 V"],
        &start,
        &DiagnoseSettings::default(),
        &progress,
    )?;
    println!("truth {spec}; {}", d.heldout);
    println!(
        "named: {:?} in {:.2} s",
        d.named(),
        t0.elapsed().as_secs_f64()
    );
    records::print_stages(&d);
    Ok(())
}
