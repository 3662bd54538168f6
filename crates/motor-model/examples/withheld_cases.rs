//! Prints the withheld-effect benchmark's case table for a seed: the truth behind each case
//! (effect, form, magnitude, visibility), the motor and the logger, and how long building and
//! generating the cases took.
//!
//! ```text
//! cargo run --release -p motor-model --example withheld_cases -- [SEED] [N]
//! ```

use std::time::Instant;

use motor_model::withheld::{benchmark_case, generate, CaseSpec, Form, SpeedSensor};

/// A built case with its total number of samples, or why it could not be built.
type Built = Result<(CaseSpec, usize), String>;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(160);
    let threads = std::thread::available_parallelism().map_or(1, |c| c.get());

    let start = Instant::now();
    // Cases are independent: build and generate them on every core, each thread taking every
    // `threads`-th case.
    let mut results: Vec<(usize, Built)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|w| {
                s.spawn(move || {
                    (w..n)
                        .step_by(threads)
                        .map(|i| {
                            let built = benchmark_case(seed, i, n).and_then(|case| {
                                let records = generate(&case)?;
                                let samples = records.high.t.len()
                                    + records.low.t.len()
                                    + records
                                        .validation
                                        .iter()
                                        .map(|(_, r)| r.t.len())
                                        .sum::<usize>();
                                Ok((case, samples))
                            });
                            (i, built.map_err(|e| e.to_string()))
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    let elapsed = start.elapsed();
    results.sort_by_key(|(i, _)| *i);

    println!(
        "{:>4}  {:<22} {:<5} {:<20} {:>12} {:<9} {:>6}  {:>7} {:>5} {:>4} {:>5}  {:<10}",
        "case",
        "effect",
        "form",
        "shape",
        "magnitude",
        "unit",
        "vis",
        "R ohm",
        "kHz",
        "bits",
        "noise",
        "speed"
    );
    let mut samples_total = 0;
    for (i, result) in &results {
        let (case, samples) = match result {
            Ok(ok) => ok,
            Err(e) => {
                println!("{i:>4}  error: {e}");
                continue;
            }
        };
        samples_total += samples;
        let speed = match case.measurement.speed_sensor {
            SpeedSensor::Encoder { counts_per_rev } => format!("enc {counts_per_rev}"),
            SpeedSensor::Tachometer { .. } => "tacho".to_string(),
        };
        let noise = if case.measurement.noise.ar1_pole > 0.0 {
            format!("{:.1}c", case.measurement.noise.lsb)
        } else {
            format!("{:.1}w", case.measurement.noise.lsb)
        };
        let tail = format!(
            "{:>7.3} {:>5.1} {:>4} {:>5}  {:<10}",
            case.motor.r_ohm,
            case.measurement.rate_hz / 1000.0,
            case.measurement.adc_bits,
            noise,
            speed
        );
        if case.effects.is_empty() {
            println!(
                "{i:>4}  {:<22} {:<5} {:<20} {:>12} {:<9} {:>6}  {tail}",
                "none", "-", "-", "-", "", "-"
            );
        }
        for e in &case.effects {
            let m = e.effect.magnitude(&case.motor);
            let form = match e.effect.form() {
                Form::SameShape => "a",
                Form::OtherShape => "b",
            };
            println!(
                "{i:>4}  {:<22} {:<5} {:<20} {:>12.4e} {:<9} {:>6.1}  {tail}",
                e.effect.name(),
                form,
                e.effect.form_label(),
                m.value,
                m.unit,
                e.visibility
            );
        }
    }
    println!(
        "\n{n} cases, {samples_total} samples, built and generated in {:.2} s on {threads} threads",
        elapsed.as_secs_f64()
    );
    Ok(())
}
