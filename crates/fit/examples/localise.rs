//! Localises the residual of the nominal model on two simulated step records of a small servo
//! whose load has quadratic drag the model lacks, prints the significant findings and the
//! localisation as JSON, and times it.
//!
//! `cargo run --release -p fit --example localise [-- EFFECT]` with EFFECT one of `none`,
//! `quadratic_drag` (default), `cogging_torque`, `stribeck_friction`, `current_sensor_lag`, or
//! any `name:key=value,...` of `motorid simulate`.

use std::time::Instant;

use fit::diagnose::localise::{localise, LocaliseSettings};
use motor_model::{Effect, Effects};

#[path = "../tests/common/localise_records.rs"]
mod records;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let arg = std::env::args().nth(1);
    let effect: Effect = match arg.as_deref().unwrap_or("quadratic_drag") {
        "none" => Effect::None,
        "quadratic_drag" => "quadratic_drag:c=1e-8".parse()?,
        "cogging_torque" => "cogging_torque:amp=1e-3,n=6".parse()?,
        "stribeck_friction" => "stribeck_friction:tst=0.006,ws=5".parse()?,
        "current_sensor_lag" => "current_sensor_lag:tau=0.002".parse()?,
        other => other.parse()?,
    };
    let effects = Effects::none().with(effect);
    let sims = [
        records::Simulated::step("high 12 V", 12.0, effects, 1),
        records::Simulated::step("low 1.5 V", 1.5, effects, 2),
    ];
    let recs: Vec<_> = sims.iter().map(|s| s.record()).collect();
    let settings = LocaliseSettings::default();
    let start = Instant::now();
    let loc = localise(&recs, &settings)?;
    let elapsed = start.elapsed();
    let repeats = 20;
    let start = Instant::now();
    for _ in 0..repeats {
        std::hint::black_box(localise(&recs, &settings)?);
    }
    let per_call = start.elapsed() / repeats;
    println!("{}", serde_json::to_string_pretty(&loc)?);
    println!("effect in the data: {}", effect.name());
    for rec in &loc.records {
        for ch in &rec.channels {
            println!(
                "{} / {}: NRMSE {:.4}, floor {:.4} ({:?}, σ = {:.3e}), gap {:.4}",
                rec.name,
                ch.channel.name(),
                ch.nrmse,
                ch.floor.nrmse_floor,
                ch.floor.source,
                ch.floor.sigma,
                ch.gap
            );
        }
    }
    let findings = loc.significant_findings();
    println!("{} significant findings:", findings.len());
    for f in &findings {
        println!("- {}", f.text);
    }
    println!(
        "localised 2 records of 5,000 samples in {:.1} ms (first call), {:.2} ms per call over {repeats}",
        elapsed.as_secs_f64() * 1e3,
        per_call.as_secs_f64() * 1e3
    );
    Ok(())
}
