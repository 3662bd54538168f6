//! The servo fit and replay on the shared XL330 pendulum logs (../shared/real-data/bam_xl330
//! beside the repository): identifying the motor from all eight logs, and replaying them in
//! closed loop with the fitted motor. Without the logs the bench says so and measures nothing.

use criterion::{criterion_group, criterion_main, Criterion};
use fit::{Loop, ServoFit, ServoRecord};
use motor_model::{Controller, Load};

/// One log: the columns t, position, speed, duty, supply, temperature, goal, enable, and its
/// `# load:` and `# controller:` lines.
fn read(path: &std::path::Path) -> Option<ServoRecord> {
    let text = std::fs::read_to_string(path).ok()?;
    let mut r = ServoRecord {
        name: path.display().to_string(),
        gear: 1.0,
        ..ServoRecord::default()
    };
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); 8];
    for line in text.lines() {
        if let Some(l) = line.strip_prefix("# load:") {
            r.loads.push(l.trim().parse::<Load>().ok()?);
        } else if let Some(c) = line.strip_prefix("# controller:") {
            r.controller = Some(c.trim().parse::<Controller>().ok()?);
        } else if !line.starts_with('#') && !line.starts_with('t') {
            for (col, v) in cols.iter_mut().zip(line.split(',')) {
                col.push(v.parse().ok()?);
            }
        }
    }
    r.t_s = cols[0].clone();
    r.q_rad = cols[1].clone();
    r.w_rad_s = Some(cols[2].clone());
    r.duty = Some(cols[3].clone());
    r.supply_v = Some(cols[4].clone());
    r.goal_rad = Some(cols[6].clone());
    r.enable = Some(cols[7].iter().map(|e| *e == 1.0).collect());
    Some(r)
}

fn bench(c: &mut Criterion) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/real-data/bam_xl330");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    paths.retain(|p| p.extension().is_some_and(|e| e == "csv"));
    paths.sort();
    let records: Vec<ServoRecord> = paths.iter().filter_map(|p| read(p)).collect();
    if records.len() != 8 {
        eprintln!("skipped: the eight XL330 logs are not in {}", dir.display());
        return;
    }
    let mut group = c.benchmark_group("servo_xl330");
    group.sample_size(10);
    group.bench_function("identify_8_logs", |b| {
        b.iter(|| ServoFit::new(&records).fit().unwrap())
    });
    let motor = ServoFit::new(&records).fit().unwrap().motor;
    group.bench_function("replay_8_logs", |b| {
        b.iter(|| fit::score_records(&records, motor, Loop::Closed, Default::default()).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
