//! Times the localisation of one 5,000-sample step record (current and encoder speed).
//!
//! `cargo bench -p fit --bench localise`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use fit::diagnose::localise::{localise, LocaliseSettings};
use motor_model::Effects;

#[path = "../tests/common/localise_records.rs"]
mod records;

fn bench(c: &mut Criterion) {
    let sim = records::Simulated::step("high", 12.0, Effects::none(), 3);
    let recs = [sim.record()];
    let settings = LocaliseSettings::default();
    c.bench_function("localise 5000-sample record", |b| {
        b.iter(|| localise(black_box(&recs), &settings).expect("localise"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
