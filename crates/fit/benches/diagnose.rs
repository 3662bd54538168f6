//! Times the whole diagnosis (nominal fit, localisation, screening, refits, both stages) of
//! three 5,000-sample step records of a small servo with a withheld quadratic drag, from the
//! equation-error start.
//!
//! `cargo bench -p fit --bench diagnose`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use fit::diagnose::{diagnose, DiagnoseSettings};
use fit::equation_error_start;
use motor_model::{Effect, Effects};

#[path = "../tests/common/diagnose_records.rs"]
mod records;

fn bench(c: &mut Criterion) {
    let effect: Effect = "quadratic_drag:c=2e-7".parse().expect("effect");
    let recs = records::servo_steps(Effects::none().with(effect)).expect("records");
    let excited = records::excited(&recs);
    let settings = DiagnoseSettings::default();
    let mut group = c.benchmark_group("diagnose");
    group.sample_size(10);
    group.bench_function("three 5000-sample steps, withheld drag", |b| {
        b.iter(|| {
            let start = equation_error_start(black_box(&excited)).expect("start");
            let d = diagnose(
                &excited,
                &[],
                &["12 V", "3 V", "0.6 V"],
                &start,
                &settings,
                &|_| {},
            )
            .expect("diagnosis");
            assert_eq!(d.named(), ["quadratic_drag"]);
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
