//! Times the fitting core: the fit of Eq. (33), the paper's method, and the full
//! identification of two 50,000-sample records (noise-free and through a 10-bit logger).
//!
//! `cargo bench -p fit --bench fits`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use fit::{fit_33, identify_full, identify_paper, LmSettings, Params33, Record33, StepTest};
use motor_model::{MeasurementModel, MotorParams, StepResponse};

struct Rec {
    volts: f64,
    current: Vec<f64>,
    speed: Vec<f64>,
    position: Option<Vec<f64>>,
}

/// The paper's test: 50 s of a step of `volts`, sampled at `rate` Hz.
fn record(volts: f64, rate: f64, logger: bool, seed: u64) -> Rec {
    let motor = MotorParams::paper();
    let trace = StepResponse::new(&motor, volts)
        .trace(0.0, 50.0, rate)
        .unwrap();
    if !logger {
        return Rec {
            volts,
            current: trace.current,
            speed: trace.speed,
            position: None,
        };
    }
    let r = MeasurementModel::paper_logger(&trace, seed)
        .apply(&trace)
        .unwrap();
    Rec {
        volts,
        current: r.current,
        speed: r.speed.unwrap(),
        position: r.position,
    }
}

fn test_of(r: &Rec) -> StepTest<'_> {
    StepTest {
        volts: r.volts,
        t_first: 0.0,
        dt: 50.0 / (r.current.len() - 1) as f64,
        current: &r.current,
        speed: Some(&r.speed),
        position: r.position.as_deref(),
        exclude_current: None,
        exclude_speed: None,
    }
}

fn eq33(c: &mut Criterion) {
    let mut group = c.benchmark_group("fit_33");
    for rate in [100.0, 1000.0] {
        let hv = record(40.0, rate, false, 0);
        let n = hv.current.len();
        let last = hv.current[n - 1];
        let y: Vec<f64> = hv.current.iter().map(|v| v / last).collect();
        let rec = Record33 {
            t_first: 0.0,
            dt: 1.0 / rate,
            normalized_current: &y,
        };
        let start = Params33 {
            alpha: 3.0,
            sigma: 0.4,
            omega_a: 0.3,
        };
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| fit_33(black_box(&rec), start, LmSettings::default()).unwrap())
        });
    }
    group.finish();
}

fn identification(c: &mut Criterion) {
    let mut group = c.benchmark_group("identify_two_50k_records");
    group.sample_size(10);
    for (label, logger) in [("noise_free", false), ("logger_10bit_encoder", true)] {
        let (hv, lv) = (
            record(40.0, 1000.0, logger, 1),
            record(2.5, 1000.0, logger, 2),
        );
        let tests = [test_of(&hv), test_of(&lv)];
        let paper = identify_paper(&tests[0], &tests[1], LmSettings::default()).unwrap();
        group.bench_function(BenchmarkId::new("paper_method", label), |b| {
            b.iter(|| {
                identify_paper(black_box(&tests[0]), &tests[1], LmSettings::default()).unwrap()
            })
        });
        group.bench_function(BenchmarkId::new("full_method", label), |b| {
            b.iter(|| {
                identify_full(black_box(&tests), &paper.params, LmSettings::default()).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, eq33, identification);
criterion_main!(benches);
