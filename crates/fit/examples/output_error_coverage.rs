//! Coverage of the output-error intervals on a noisy staircase of the paper's motor:
//! `cargo run --release -p fit --example output_error_coverage [RUNS]` prints each run's
//! relative errors and how many 95 % intervals contained the truth.
use fit::{equation_error_start, identify_output_error, voltage_input, ExcitedRecord, LmSettings};
use motor_model::{Effects, Input, MeasurementModel, MotorParams, Simulator};
fn main() {
    let truth = MotorParams::paper();
    let u = Input::piecewise(&[(0.5, 40.0), (40.5, -20.0), (80.5, 0.0), (100.5, 2.5)]).unwrap();
    let trace = Simulator::new(truth, Effects::none(), u)
        .unwrap()
        .run(140.0, 1000.0)
        .unwrap();
    let mut inside = [0; 6];
    let runs: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20);
    for seed in 0..runs {
        let rec = MeasurementModel::paper_logger(&trace, seed)
            .apply(&trace)
            .unwrap();
        let input = voltage_input(&rec.t, &rec.voltage).unwrap();
        let r = [ExcitedRecord {
            input: &input,
            dt: 1e-3,
            current: &rec.current,
            speed: None,
            position: rec.position.as_deref(),
            exclude_current: None,
            exclude_speed: None,
        }];
        let t0 = std::time::Instant::now();
        let start = equation_error_start(&r).unwrap();
        let fit = identify_output_error(&r, &start, LmSettings::default()).unwrap();
        let ci = fit.ci95.unwrap();
        let errs: Vec<String> = fit
            .params
            .values()
            .iter()
            .zip(truth.values())
            .enumerate()
            .map(|(k, (g, w))| {
                if ci[k][0] <= w && w <= ci[k][1] {
                    inside[k] += 1;
                }
                format!("{:+.4}%", 100.0 * (g - w) / w)
            })
            .collect();
        println!(
            "seed {seed}: {} ({} iterations, {:.2} s)",
            errs.join(" "),
            fit.iterations,
            t0.elapsed().as_secs_f64()
        );
    }
    for (name, n) in fit::PARAM_NAMES.iter().zip(inside) {
        println!("{name}: {n}/{runs} intervals contain the truth");
    }
}
