//! Times the exact step response on a grid and the stick-slip simulation (the nominal model
//! propagated exactly and by RK4, and RK4 with cogging).
//!
//! `cargo bench -p motor-model --bench responses`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use motor_model::{Effect, Effects, Input, MotorParams, Simulator, StepResponse};

fn analytic_current(c: &mut Criterion) {
    let motor = MotorParams::paper();
    let step = StepResponse::new(&motor, 40.0);
    let mut group = c.benchmark_group("analytic_current");
    for n in [1_000usize, 10_000, 50_000] {
        let mut out = vec![0.0; n];
        let dt = 50.0 / n as f64;
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("grid", n), &n, |b, _| {
            b.iter(|| step.fill_current(black_box(0.0), black_box(dt), &mut out))
        });
        group.bench_with_input(BenchmarkId::new("pointwise", n), &n, |b, _| {
            b.iter(|| {
                for (i, o) in out.iter_mut().enumerate() {
                    *o = step.at(black_box(i as f64 * dt)).current_a;
                }
            })
        });
    }
    group.finish();
}

fn ode_simulation(c: &mut Criterion) {
    let motor = MotorParams::paper();
    let mut group = c.benchmark_group("ode_simulation_1kHz");
    group.sample_size(20);
    for seconds in [5.0, 50.0] {
        let sim = Simulator::new(motor, Effects::none(), Input::step(40.0, 0.0).unwrap()).unwrap();
        group.throughput(Throughput::Elements((seconds * 1000.0) as u64));
        // Exact propagation (what `run` does for a nominal step) beside RK4 on the same model.
        group.bench_with_input(BenchmarkId::new("nominal", seconds), &seconds, |b, &s| {
            b.iter(|| sim.run(black_box(s), 1000.0).unwrap())
        });
        let rk4 = sim.clone().integrated();
        group.bench_with_input(
            BenchmarkId::new("nominal_rk4", seconds),
            &seconds,
            |b, &s| b.iter(|| rk4.run(black_box(s), 1000.0).unwrap()),
        );
    }
    let cogging: Effect = "cogging_torque:amp=0.01,n=6".parse().unwrap();
    let sim = Simulator::new(
        motor,
        Effects::none().with(cogging),
        Input::sine(0.1, 0.05).unwrap(),
    )
    .unwrap();
    group.bench_function("appendix_d_sine_with_cogging/50", |b| {
        b.iter(|| sim.run(black_box(50.0), 1000.0).unwrap())
    });
    group.finish();
}

criterion_group!(benches, analytic_current, ode_simulation);
criterion_main!(benches);
