//! No silent wrong answers, as a property: random plausible motors and record settings,
//! identified end to end through the real binary.
//!
//! Each case draws a motor (log-uniform between a small servo and the paper's motor: R
//! 0.3–10 Ω, τe = L/R 0.1 ms–1 s, k 0.01–0.2 N·m/A, R f/k² 0.05–1, τm = J/f 10 ms–20 s, Ts
//! 0.2–5 % of the stall torque k E/R at the step voltage E, 2–48 V), a record (rate 1 Hz–100 kHz,
//! duration 0.01–1000 s, either drawn independently or placed around the motor's own time
//! constants; at most `MAX_SAMPLES` samples, redrawn otherwise), a logger (10 or 12 bits, 1 LSB
//! of noise, an encoder of 500, 2000 or 8192 counts, speed from it or from a tachometer), a step of either sign, one record
//! (`identify --record`, output error) or a pair (`--high`, `--low` at E/8, each of either
//! sign), and in a third of the cases `t` or `current` rewritten in ms or mA, with the unit in
//! the header (`t[ms]`, `current[mA]`) in half of those and without it in the other half (and
//! without `simulate`'s `#` metadata, as another tool would write the file).
//!
//! It asserts the acceptance of "No silent wrong answers": a case either exits 2 or 3
//! (refused), or exits 0 with every value at most ten half-widths of its 95 % interval from
//! the truth; and over the cases that exit 0 (at least `MIN_ACCEPTED` of them), every
//! parameter's interval contains the truth in at least 90 % of them. An `identify` still
//! running after `IDENTIFY_LIMIT` is killed and counts as a failure.
//!
//! - CI: `cargo test --release -p motorid --test property_identify -- --nocapture` —
//!   `CI_CASES` cases, seeded, under a minute.
//! - Heavy: the same with `MOTORID_HEAVY=1` — `HEAVY_CASES` cases of up to `HEAVY_MAX_SAMPLES`
//!   samples (`MOTORID_CASES=N` sets another count).
//! - One case again: `MOTORID_CASE=I` runs case I alone (with `MOTORID_HEAVY=1` for the heavy
//!   sample cap); a failing case prints its shell commands, and its files are kept.
//!
//! The seeded run first found: a `t` in ms without a unit (0.072 ms steps) accepted with L 1000
//! times the truth, and a current in mA without a unit accepted with R 1000 times too small
//! (both now refused by the reader); `identify --record` of a 134-sample record at 4.3 Hz
//! running for ever (now bounded); L's intervals containing the truth in 4 of 10 accepted
//! cases, mostly where the step falls between two samples. The heavy run then found three
//! single records of 13,000–124,000 samples at 164–394 Hz running past `IDENTIFY_LIMIT` (the
//! simulation's RK4 steps followed τe, far below the sample period: the nominal model is now
//! propagated exactly), and L's and R's intervals missing on 7 and 8 of 35 accepted step
//! pairs whose step is on the first sample, taken half a period earlier (now at that sample).
//!
//! Cases are seeded by their index alone, so case I is the same whatever the count.

mod common;

use common::{motorid, motorid_within, scratch, stderr, stdout};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;

/// Cases in the CI run.
const CI_CASES: u64 = 20;
/// Cases with `MOTORID_HEAVY=1`.
const HEAVY_CASES: u64 = 200;
/// Samples per record at most in the CI run (keeps an output-error fit to seconds).
const CI_MAX_SAMPLES: f64 = 20_000.0;
/// Samples per record at most with `MOTORID_HEAVY=1`.
const HEAVY_MAX_SAMPLES: f64 = 200_000.0;
/// Seed of the whole run; case I uses `SEED + I`.
const SEED: u64 = 0x5eed_2026;
/// Accepted (exit 0) cases below which the coverage is not judged: 90 % of fewer is noise.
const MIN_ACCEPTED: usize = 10;
/// Coverage every parameter's 95 % intervals must reach over the accepted cases.
const MIN_COVERAGE: f64 = 0.90;
/// An accepted value may lie at most this many half-widths of its interval from the truth.
const MAX_HALF_WIDTHS: f64 = 10.0;
/// An `identify` still running after this long is a hang (the README's 140,001-sample
/// output-error fit takes 1.1 s; at most `HEAVY_MAX_SAMPLES` samples a record here).
const IDENTIFY_LIMIT: std::time::Duration = std::time::Duration::from_secs(60);
/// Share of the accepted cases (clean records: no effect is simulated) whose model check may
/// still say that the model misses something: the check's family-wise false-alarm rate is
/// 1 % a call, and this bound is five times that.
const MAX_MODEL_CHECK_ALARMS: f64 = 0.05;
/// The parameters, in the order of the JSON's correlation matrix.
const NAMES: [&str; 6] = ["R", "L", "k", "f", "J", "Ts"];

/// xorshift64* (Vigna 2016): a few lines, no dependency, the same stream on every platform.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        // splitmix64 of the seed, so neighbouring seeds give unrelated streams.
        let mut z = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        Rng((z ^ (z >> 31)) | 1)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + self.uniform() * (hi / lo).ln()).exp()
    }
    fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }
    fn pick<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[(self.next_u64() % items.len() as u64) as usize]
    }
}

/// A motor: R [Ω], L [H], k [N·m/A], f [N·m·s/rad], J [kg·m²], Ts [N·m], in `NAMES` order.
type Motor = [f64; 6];

/// The fastest and slowest time constants [s] of the moving motor: the roots of
/// L J s² + (L f + J R) s + (R f + k²) = 0 (the 1/σ and 1/ωn of an underdamped one).
fn time_constants(m: &Motor) -> (f64, f64) {
    let [r, l, k, f, j, _] = *m;
    let (a, b, c) = (l * j, l * f + j * r, r * f + k * k);
    let d = b * b - 4.0 * a * c;
    if d > 0.0 {
        let big = (b + d.sqrt()) / (2.0 * a);
        let small = 2.0 * c / (b + d.sqrt());
        (1.0 / big, 1.0 / small)
    } else {
        let sigma = b / (2.0 * a);
        ((a / c).sqrt().min(1.0 / sigma), 1.0 / sigma)
    }
}

/// How `t` or `current` is rewritten after `simulate`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scaling {
    None,
    /// Column index and name, and whether the header says the unit.
    Milli {
        column: usize,
        unit: &'static str,
        stated: bool,
    },
}

/// One case: the motor, what `simulate` is asked, how the file is rewritten, how identified.
struct Case {
    index: u64,
    motor: Motor,
    /// Step voltage of each record [V] (one or two: high, low).
    voltages: Vec<f64>,
    rate_hz: f64,
    duration_s: f64,
    step_at_s: f64,
    logger: Vec<String>,
    scaling: Scaling,
    /// Rate and duration drawn around the motor's time constants, not independently.
    informed: bool,
}

impl Case {
    fn draw(index: u64, max_samples: f64) -> Case {
        let mut rng = Rng::new(SEED.wrapping_add(index));
        loop {
            let r = rng.log_uniform(0.3, 10.0);
            let tau_e = rng.log_uniform(1e-4, 1.0);
            let k = rng.log_uniform(0.01, 0.2);
            let friction_share = rng.log_uniform(0.05, 1.0);
            let tau_m = rng.log_uniform(0.01, 20.0);
            let e = rng.log_uniform(2.0, 48.0);
            let f = friction_share * k * k / r;
            let ts = rng.log_uniform(0.002, 0.05) * k * e / r;
            let motor = [r, r * tau_e, k, f, tau_m * f, ts];
            let (fast, moving) = time_constants(&motor);
            // At rest the current rises with τe alone, and the low step breaks away only at
            // t0 = −τe ln(1 − R Ts/(k E/8)) (Eq. (11)): the record must outlast both.
            let breakaway = -tau_e * (1.0 - 8.0 * r * ts / (k * e)).ln();
            let slow = moving.max(tau_e) + breakaway;
            let informed = rng.chance(0.6);
            let (mut rate_hz, mut duration_s) = (0.0, 0.0);
            let mut fits = false;
            for _ in 0..50 {
                (rate_hz, duration_s) = if informed {
                    (
                        (rng.log_uniform(10.0, 300.0) / fast).clamp(1.0, 1e5),
                        (slow * rng.log_uniform(3.0, 30.0)).clamp(0.01, 1000.0),
                    )
                } else {
                    (rng.log_uniform(1.0, 1e5), rng.log_uniform(0.01, 1000.0))
                };
                let samples = (duration_s * rate_hz).floor() + 1.0;
                if (3.0..=max_samples).contains(&samples) {
                    fits = true;
                    break;
                }
            }
            if !fits {
                continue;
            }
            let step_at_s = if rng.chance(0.5) {
                0.0
            } else {
                duration_s * rng.uniform() * 0.1
            };
            let sign = |rng: &mut Rng| if rng.chance(0.5) { 1.0 } else { -1.0 };
            let mut voltages = vec![sign(&mut rng) * e];
            if rng.chance(0.5) {
                voltages.push(sign(&mut rng) * e / 8.0);
            }
            let bits = rng.pick(&["10", "12"]);
            let mut logger: Vec<String> = ["--adc-bits", bits, "--noise-lsb", "1"]
                .map(String::from)
                .to_vec();
            // Always an encoder: without one `simulate` writes the exact angle, which no
            // logger measures (and which `identify` would use before the tachometer).
            let cpr = rng.pick(&["500", "2000", "8192"]);
            let from = rng.pick(&["encoder", "encoder", "tacho"]);
            logger.extend(["--encoder-cpr", cpr, "--speed-from", from].map(String::from));
            let scaling = if rng.chance(1.0 / 3.0) {
                let (column, unit) = if rng.chance(0.5) {
                    (0, "t[ms]")
                } else {
                    (2, "current[mA]")
                };
                Scaling::Milli {
                    column,
                    unit,
                    stated: rng.chance(0.5),
                }
            } else {
                Scaling::None
            };
            return Case {
                index,
                motor,
                voltages,
                rate_hz,
                duration_s,
                step_at_s,
                logger,
                scaling,
                informed,
            };
        }
    }

    fn motor_json(&self) -> String {
        let m = &self.motor;
        format!(
            r#"{{"R": {}, "L": {}, "k": {}, "f": {}, "J": {}, "Ts": {}}}"#,
            m[0], m[1], m[2], m[3], m[4], m[5]
        )
    }

    fn summary(&self) -> String {
        let (fast, slow) = time_constants(&self.motor);
        format!(
            "case {}: {} record(s) at {:?} V, {:.4} Hz for {:.4} s (step at {:.4} s, {} samples), \
             moving time constants {:.3e}..{:.3e} s, tau_e {:.3e} s, {} draw, logger {}, scaling {:?}, motor {}",
            self.index,
            self.voltages.len(),
            self.voltages,
            self.rate_hz,
            self.duration_s,
            self.step_at_s,
            (self.duration_s * self.rate_hz).floor() + 1.0,
            fast,
            slow,
            self.motor[1] / self.motor[0],
            if self.informed {
                "informed"
            } else {
                "independent"
            },
            self.logger.join(" "),
            self.scaling,
            self.motor_json()
        )
    }
}

/// Rewrites `t` or `current` of a `simulate` record in milli-units (×1000), the header naming
/// the unit or not, as another tool would write it: without `simulate`'s `#` metadata (whose
/// ranges are in SI units). Returns the equivalent shell command.
fn rewrite_milli(from: &Path, to: &Path, column: usize, unit: &str, stated: bool) -> String {
    let text = std::fs::read_to_string(from).unwrap();
    let mut out = String::with_capacity(text.len() + text.len() / 4);
    let mut header_seen = false;
    for line in text.lines() {
        if line.starts_with('#') {
            continue;
        } else if !header_seen {
            header_seen = true;
            // Another tool's header: plain names, a unit only where the case states one.
            let mut names: Vec<&str> = line
                .split(',')
                .map(|n| n.split('[').next().unwrap_or(n))
                .collect();
            if stated {
                names[column] = unit;
            }
            out.push_str(&names.join(","));
        } else {
            let mut fields: Vec<String> = line.split(',').map(String::from).collect();
            let v: f64 = fields[column].parse().unwrap();
            fields[column] = format!("{}", v * 1000.0);
            out.push_str(&fields.join(","));
        }
        out.push('\n');
    }
    std::fs::write(to, out).unwrap();
    format!(
        "awk -F, -v OFS=, -v CONVFMT=%.17g -v c={} -v h='{}' '/^#/{{next}} !d{{d=1; gsub(/\\[[^]]*\\]/,\"\"); if(h!=\"\")$c=h; print; next}} {{$c=$c*1000; print}}' {} > {}",
        column + 1,
        if stated { unit } else { "" },
        from.display(),
        to.display()
    )
}

/// What one case gave.
struct Outcome {
    exit: Option<i32>,
    /// Per parameter: the interval contains the truth (exit 0 only).
    covered: [bool; 6],
    /// Exit 0 and the model check says the model misses something (a false alarm: the
    /// records are of the nominal model).
    alarm: bool,
    /// Problems that break the property (exit 0 far off, no interval, a panic, ...).
    violations: Vec<String>,
    /// Exit 2/3: the first line of the error; exit 0: the intervals that miss the truth.
    note: String,
    commands: String,
    seconds: f64,
}

fn run_case(case: &Case, dir: &Path) -> Outcome {
    let started = std::time::Instant::now();
    let motor_path = dir.join("motor.json");
    std::fs::write(&motor_path, case.motor_json()).unwrap();
    let mut commands = format!(
        "cat > {} <<'EOF'\n{}\nEOF\n",
        motor_path.display(),
        case.motor_json()
    );
    let mut violations = Vec::new();
    let mut records = Vec::new();
    for (n, volts) in case.voltages.iter().enumerate() {
        let raw = dir.join(format!("rec{n}.csv"));
        let rate = format!("{}", case.rate_hz);
        let duration = format!("{}", case.duration_s);
        let step_at = format!("{}", case.step_at_s);
        let voltage = format!("{volts}");
        let seed = format!("{}", case.index * 2 + n as u64 + 1);
        let mut args: Vec<&str> = vec![
            "simulate",
            "--motor",
            motor_path.to_str().unwrap(),
            "--voltage",
            &voltage,
            "--duration",
            &duration,
            "--rate",
            &rate,
            "--step-at",
            &step_at,
            "--seed",
            &seed,
            "-o",
            raw.to_str().unwrap(),
        ];
        args.extend(case.logger.iter().map(String::as_str));
        writeln!(commands, "motorid {}", args.join(" ")).unwrap();
        let out = motorid(&args);
        if !out.status.success() {
            violations.push(format!(
                "simulate failed ({:?}): {}",
                out.status.code(),
                stderr(&out).trim()
            ));
            return Outcome {
                exit: None,
                covered: [false; 6],
                alarm: false,
                violations,
                note: String::new(),
                commands,
                seconds: started.elapsed().as_secs_f64(),
            };
        }
        let path = match case.scaling {
            Scaling::None => raw,
            Scaling::Milli {
                column,
                unit,
                stated,
            } => {
                let scaled = dir.join(format!("rec{n}_milli.csv"));
                let shell = rewrite_milli(&raw, &scaled, column, unit, stated);
                writeln!(commands, "{shell}").unwrap();
                scaled
            }
        };
        records.push(path.to_str().unwrap().to_owned());
    }
    let mut args: Vec<&str> = vec!["identify"];
    if let [high, low] = &records[..] {
        args.extend(["--high", high, "--low", low]);
    } else {
        args.extend(["--record", &records[0]]);
    }
    args.extend(["--json", "--quiet"]);
    writeln!(commands, "motorid {}", args.join(" ")).unwrap();
    let Some(out) = motorid_within(&args, IDENTIFY_LIMIT) else {
        violations.push(format!(
            "identify still running after {} s: killed",
            IDENTIFY_LIMIT.as_secs()
        ));
        return Outcome {
            exit: None,
            covered: [false; 6],
            alarm: false,
            violations,
            note: String::new(),
            commands,
            seconds: started.elapsed().as_secs_f64(),
        };
    };
    let exit = out.status.code();
    let err = stderr(&out);
    let mut covered = [false; 6];
    let mut alarm = false;
    let mut note = String::new();
    if err.contains("panicked") {
        violations.push(format!("panicked: {}", err.trim()));
    }
    match exit {
        Some(0) => {
            let v: Value = serde_json::from_str(&stdout(&out)).unwrap_or(Value::Null);
            // A check not made (records too short to localise) says why, and is no alarm.
            match v["model_check"]["made"].as_bool() {
                Some(made) => alarm = made && v["model_check"]["model_misses"] == true,
                None => violations.push(format!(
                    "exit 0 without a model check: {}",
                    v["model_check"]
                )),
            }
            if alarm {
                write!(note, " model check: {};", v["model_check"]["findings"][0]).unwrap();
            }
            for (i, name) in NAMES.iter().enumerate() {
                let p = &v["parameters"][name];
                let truth = case.motor[i];
                let value = p["value"].as_f64();
                let ci = p["ci95"].as_array().and_then(|ci| match &ci[..] {
                    [lo, hi] => Some((lo.as_f64()?, hi.as_f64()?)),
                    _ => None,
                });
                match (value, ci) {
                    (Some(value), Some((lo, hi))) if lo <= hi => {
                        covered[i] = lo <= truth && truth <= hi;
                        let half = 0.5 * (hi - lo);
                        if !covered[i] {
                            write!(
                                note,
                                " {name} {:+.3e} rel, {:.1} half-widths;",
                                value / truth - 1.0,
                                (value - truth).abs() / half
                            )
                            .unwrap();
                        }
                        // Written so that a NaN value counts as off.
                        let within = (value - truth).abs() <= MAX_HALF_WIDTHS * half;
                        if !within {
                            violations.push(format!(
                                "exit 0 with {name} = {value:e} [{lo:e}, {hi:e}], truth {truth:e}: \
                                 {:.1} half-widths off",
                                (value - truth).abs() / half
                            ));
                        }
                    }
                    _ => violations.push(format!(
                        "exit 0 without a value and interval for {name}: {p}"
                    )),
                }
            }
        }
        Some(2) | Some(3) => note = err.lines().last().unwrap_or("").chars().take(240).collect(),
        other => violations.push(format!("exit {other:?}: {}", err.trim())),
    }
    Outcome {
        exit,
        covered,
        alarm,
        violations,
        note,
        commands,
        seconds: started.elapsed().as_secs_f64(),
    }
}

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

#[test]
fn identify_is_right_within_its_intervals_or_refuses() {
    let heavy = std::env::var("MOTORID_HEAVY").is_ok_and(|v| v == "1");
    let max_samples = if heavy {
        HEAVY_MAX_SAMPLES
    } else {
        CI_MAX_SAMPLES
    };
    let indices: Vec<u64> = match env_u64("MOTORID_CASE") {
        Some(i) => vec![i],
        None => (0..env_u64("MOTORID_CASES").unwrap_or(if heavy { HEAVY_CASES } else { CI_CASES }))
            .collect(),
    };
    let mut root = scratch("property");
    let started = std::time::Instant::now();
    let mut failures = Vec::new();
    let mut exits = std::collections::BTreeMap::<String, usize>::new();
    let mut accepted = 0usize;
    let mut covered = [0usize; 6];
    let mut alarms = 0usize;
    for &index in &indices {
        let case = Case::draw(index, max_samples);
        let dir = root.join(format!("case{index}"));
        std::fs::create_dir_all(&dir).unwrap();
        let outcome = run_case(&case, &dir);
        *exits.entry(format!("{:?}", outcome.exit)).or_default() += 1;
        eprintln!(
            "{}\n  exit {:?} in {:.2} s: {}",
            case.summary(),
            outcome.exit,
            outcome.seconds,
            outcome.note
        );
        if outcome.exit == Some(0) {
            accepted += 1;
            alarms += usize::from(outcome.alarm);
            if outcome.alarm {
                eprintln!("  model check flagged it; reproduce:\n{}", outcome.commands);
            }
            for (n, c) in covered.iter_mut().zip(outcome.covered) {
                *n += usize::from(c);
            }
        }
        if outcome.violations.is_empty() {
            std::fs::remove_dir_all(&dir).ok();
        } else {
            failures.push(format!(
                "{}\n  {}\n  reproduce:\n{}",
                case.summary(),
                outcome.violations.join("\n  "),
                outcome.commands
            ));
        }
    }
    eprintln!(
        "{} cases in {:.1} s; exits {exits:?}; accepted {accepted}",
        indices.len(),
        started.elapsed().as_secs_f64()
    );
    let mut coverage_failures = Vec::new();
    for (name, n) in NAMES.iter().zip(covered) {
        let share = n as f64 / accepted.max(1) as f64;
        eprintln!("  {name}: {n} of {accepted} intervals contain the truth");
        if accepted >= MIN_ACCEPTED && share < MIN_COVERAGE {
            coverage_failures.push(format!(
                "{name}: {n} of {accepted} intervals contain the truth, below {MIN_COVERAGE}"
            ));
        }
    }
    eprintln!("  model check: {alarms} of {accepted} accepted cases flagged (false alarms)");
    if alarms as f64 > MAX_MODEL_CHECK_ALARMS * accepted as f64 {
        coverage_failures.push(format!(
            "the model check flagged {alarms} of {accepted} accepted cases of the nominal model, above {MAX_MODEL_CHECK_ALARMS}"
        ));
    }
    if accepted < MIN_ACCEPTED {
        eprintln!("coverage not judged: fewer than {MIN_ACCEPTED} accepted cases");
    }
    if !failures.is_empty() {
        root.keep();
    }
    assert!(
        failures.is_empty() && coverage_failures.is_empty(),
        "{} of {} cases broke the property (files kept under {}):\n{}\n{}",
        failures.len(),
        indices.len(),
        root.display(),
        failures.join("\n"),
        coverage_failures.join("\n")
    );
}
