//! A reference simulator and logger written apart from `motor_model` (its own integrator,
//! quantiser and noise), so that coverage tests do not check the fits against their own code.
//!
//! Plant: Eq. (2) `E = R I + L dI/dt + k Ω`, `k I − Ts sign Ω = f Ω + J dΩ/dt`, stuck (`Ω = 0`)
//! while `|k I| ≤ Ts`; integrated by Heun's method (explicit trapezoid) on a fixed sub-step of
//! `dt / SUBSTEPS`, with each voltage jump, breakaway and speed reversal located inside its
//! sub-step (linear interpolation of the switching function) so that the step there is split.
#![allow(dead_code)]

/// Sub-steps per sample period.
pub const SUBSTEPS: usize = 40;

/// Motor parameters `[R, L, k, f, J, Ts]` (SI).
pub type Motor = [f64; 6];

/// A piecewise-constant voltage: 0 V before `levels[0].0`, then `levels[j].1` \[V\] from
/// `levels[j].0` \[s\].
pub struct Staircase {
    pub levels: Vec<(f64, f64)>,
}

impl Staircase {
    fn volts(&self, t: f64) -> f64 {
        self.levels
            .iter()
            .rev()
            .find(|(at, _)| t >= *at)
            .map_or(0.0, |l| l.1)
    }
    fn next_jump(&self, t: f64) -> Option<f64> {
        self.levels.iter().map(|l| l.0).find(|&at| at > t)
    }
}

/// True signals at `t_i = i dt`, `i = 0..n`.
pub struct Truth {
    pub voltage: Vec<f64>,
    pub current: Vec<f64>,
    pub speed: Vec<f64>,
    pub angle: Vec<f64>,
}

#[derive(Clone, Copy)]
struct State {
    i: f64,
    w: f64,
    th: f64,
}

fn deriv(m: &Motor, e: f64, x: State, moving: f64) -> State {
    let [r, l, k, f, j, ts] = *m;
    let di = (e - r * x.i - k * x.w) / l;
    if moving == 0.0 {
        State {
            i: di,
            w: 0.0,
            th: 0.0,
        }
    } else {
        State {
            i: di,
            w: (k * x.i - ts * moving - f * x.w) / j,
            th: x.w,
        }
    }
}

fn heun(m: &Motor, e: f64, x: State, h: f64, moving: f64) -> State {
    let a = deriv(m, e, x, moving);
    let p = State {
        i: x.i + h * a.i,
        w: x.w + h * a.w,
        th: x.th + h * a.th,
    };
    let b = deriv(m, e, p, moving);
    State {
        i: x.i + 0.5 * h * (a.i + b.i),
        w: x.w + 0.5 * h * (a.w + b.w),
        th: x.th + 0.5 * h * (a.th + b.th),
    }
}

/// Simulates `motor` driven by `input` from rest, sampled `n` times every `dt` \[s\].
pub fn simulate(motor: &Motor, input: &Staircase, dt: f64, n: usize) -> Truth {
    let ts = motor[5];
    let k = motor[2];
    let mut x = State {
        i: 0.0,
        w: 0.0,
        th: 0.0,
    };
    let mut moving = 0.0_f64;
    let mut out = Truth {
        voltage: Vec::with_capacity(n),
        current: Vec::with_capacity(n),
        speed: Vec::with_capacity(n),
        angle: Vec::with_capacity(n),
    };
    let h = dt / SUBSTEPS as f64;
    let mut t = 0.0;
    for s in 0..n {
        let target = s as f64 * dt;
        while t < target - 1e-15 {
            let mut end = (t + h).min(target);
            if let Some(jump) = input.next_jump(t) {
                end = end.min(jump);
            }
            let e = input.volts(0.5 * (t + end));
            let step = end - t;
            let x1 = heun(motor, e, x, step, moving);
            if moving == 0.0 && (k * x1.i).abs() > ts {
                // Breakaway inside the step: split it where |k I| reaches Ts.
                let g0 = (k * x.i).abs() - ts;
                let g1 = (k * x1.i).abs() - ts;
                let frac = (g0 / (g0 - g1)).clamp(0.0, 1.0);
                let xa = heun(motor, e, x, frac * step, 0.0);
                moving = x1.i.signum();
                x = heun(motor, e, xa, (1.0 - frac) * step, moving);
            } else if moving != 0.0 && x1.w * moving < 0.0 {
                // Reversal of the speed inside the step: stop there, then stick or slip back.
                let frac = (x.w / (x.w - x1.w)).clamp(0.0, 1.0);
                let mut xa = heun(motor, e, x, frac * step, moving);
                xa.w = 0.0;
                moving = if (k * xa.i).abs() > ts {
                    xa.i.signum()
                } else {
                    0.0
                };
                x = heun(motor, e, xa, (1.0 - frac) * step, moving);
                if moving != 0.0 && x.w * moving < 0.0 {
                    x.w = 0.0;
                    moving = 0.0;
                }
            } else {
                x = x1;
            }
            t = end;
        }
        out.voltage.push(input.volts(target));
        out.current.push(x.i);
        out.speed.push(x.w);
        out.angle.push(x.th);
    }
    out
}

/// A splitmix64 generator with Box–Muller normals.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9e37_79b9_7f4a_7c15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A `bits`-bit ADC over `[lo, hi]` with Gaussian noise of `noise_lsb` LSB before conversion:
/// returns the readings and one LSB.
pub fn adc(
    values: &[f64],
    lo: f64,
    hi: f64,
    bits: u32,
    noise_lsb: f64,
    rng: &mut Rng,
) -> (Vec<f64>, f64) {
    let top = f64::from((1u32 << bits) - 1);
    let lsb = (hi - lo) / top;
    let read = values
        .iter()
        .map(|v| {
            let code = ((v + noise_lsb * lsb * rng.normal() - lo) / lsb)
                .round()
                .clamp(0.0, top);
            lo + code * lsb
        })
        .collect();
    (read, lsb)
}

/// An encoder of `cpr` counts per revolution (angle floored to a count).
pub fn encoder(angle: &[f64], cpr: u32) -> Vec<f64> {
    let q = std::f64::consts::TAU / f64::from(cpr);
    angle.iter().map(|a| (a / q).floor() * q).collect()
}

/// A measured record: quantised voltage, current and encoder angle, with the ADC steps.
pub struct Logged {
    pub voltage: Vec<f64>,
    pub current: Vec<f64>,
    pub angle: Vec<f64>,
    pub voltage_lsb: f64,
    pub current_lsb: f64,
}

/// Logs `truth` with a 10-bit ADC: the voltage over `[v_lo, v_hi]` with `voltage_noise_lsb`,
/// the current over `[0, 1.2 max I]·stretch` (or symmetric when it reverses) with `noise_lsb`,
/// and a 2000-count encoder. A range that straddles zero is moved by a random fraction of a
/// step (uniform over ±½ LSB, readings at the moved codes: no bias), so that over the runs
/// zero and the values a few steps from it sit anywhere between two codes — as the fits'
/// intervals take them to. Without it 0 V and 0 A sit exactly halfway between two codes in
/// every run and a settled current a few codes from zero (the 2.5 V level's, about 11) at
/// nearly the same place, the 5 % stretch of the range moving it by half a code: noise-free
/// quantisation errors then had the same sign in most runs.
pub fn log(
    truth: &Truth,
    (v_lo, v_hi): (f64, f64),
    voltage_noise_lsb: f64,
    noise_lsb: f64,
    stretch: f64,
    rng: &mut Rng,
) -> Logged {
    let i_max = truth.current.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let i_lo = if truth.current.iter().any(|&v| v < 0.0) {
        -1.2 * i_max * stretch
    } else {
        0.0
    };
    let mut offset = |lo: f64, hi: f64| {
        if lo < 0.0 {
            let shift = (rng.uniform() - 0.5) * (hi - lo) / 1023.0;
            (lo + shift, hi + shift)
        } else {
            (lo, hi)
        }
    };
    let (v_lo, v_hi) = offset(v_lo, v_hi);
    let (i_lo, i_hi) = offset(i_lo, 1.2 * i_max * stretch);
    let (voltage, voltage_lsb) = adc(&truth.voltage, v_lo, v_hi, 10, voltage_noise_lsb, rng);
    let (current, current_lsb) = adc(&truth.current, i_lo, i_hi, 10, noise_lsb, rng);
    Logged {
        voltage,
        current,
        angle: encoder(&truth.angle, 2000),
        voltage_lsb,
        current_lsb,
    }
}

/// How the coverage runs record their tests.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Noise on the voltage channel \[LSB\].
    pub voltage_noise_lsb: f64,
    /// Noise on the current channel \[LSB\].
    pub noise_lsb: f64,
    /// Steps at a random instant within a sample period (else on a sample).
    pub subsample_step: bool,
    /// The output-error record returns to 0 V (and rests there) on a unipolar voltage range;
    /// each step record of a pair returns to 0 V after 50 s and is recorded for 100 s.
    pub return_to_zero: bool,
}

/// Per run: the run's motor (the paper's, each parameter changed by 2 % r.m.s.) and a uniform
/// number for its step instants.
fn run_motor(rng: &mut Rng) -> Motor {
    let paper = [0.3, 0.3, 0.15, 0.05, 1.0, 0.03];
    paper.map(|v| v * (1.0 + 0.02 * rng.normal()))
}

fn covered(fit: &fit::FullFit, truth: &Motor, inside: &mut [usize; 6]) {
    if std::env::var_os("COVERAGE_VERBOSE").is_some() {
        // Each parameter's error in units of its 95 % half-width (|z| > 1: a miss).
        let z: Vec<String> = fit.ci95.map_or(Vec::new(), |ci| {
            let ci = ci.named().map(|(_, c)| c);
            fit.params
                .values()
                .iter()
                .zip(truth)
                .zip(ci)
                .map(|((v, t), [lo, hi])| format!("{:+.2}", (v - t) / (0.5 * (hi - lo))))
                .collect()
        });
        let rel: Vec<String> = (0..6)
            .map(|k| format!("{:+.1e}", fit.params.values()[k] / truth[k] - 1.0))
            .collect();
        eprintln!(
            "error / half-width: {}; relative error: {}",
            z.join(" "),
            rel.join(" ")
        );
    }
    if let Some(ci) = fit.ci95.map(|ci| ci.named().map(|(_, c)| c)) {
        for k in 0..6 {
            if ci[k][0] <= truth[k] && truth[k] <= ci[k][1] {
                inside[k] += 1;
            }
        }
    }
}

/// The output-error fit's view of a whole logged record (current and encoder angle) driven by
/// `input`, sampled every `dt` \[s\].
fn excited<'a>(input: &'a motor_model::Input, dt: f64, rec: &'a Logged) -> fit::ExcitedRecord<'a> {
    fit::ExcitedRecord {
        input,
        dt,
        current: &rec.current,
        speed: None,
        position: Some(&rec.angle),
        exclude_current: None,
        exclude_speed: None,
    }
}

/// Coverage of the full step-pair fit's 95 % intervals over `runs` record pairs (40 V and
/// 2.5 V, 50 s at 1 kHz; with `return_to_zero` each back to 0 V after 50 s and recorded for
/// 100 s, fitted whole): how many runs each interval contained the truth, and the runs whose
/// fit gave intervals. The pipeline's own route ([`fit::identify_step_pair`]).
pub fn step_pair_coverage(runs: u64, cfg: Config, seed: u64) -> ([usize; 6], usize) {
    use fit::{
        identify_step_pair, locate_step_with, voltage_levels, LmSettings, StepMethod, StepRecord,
        StepTest, WholeRecord,
    };
    let dt = 1e-3;
    let hold = 50_000;
    let n = if cfg.return_to_zero { 2 * hold } else { hold } + 1;
    let mut inside = [0; 6];
    let mut with_ci = 0;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    for run in 0..runs {
        let mut rng = Rng::new(seed.wrapping_mul(1_000_003).wrapping_add(run));
        let motor = run_motor(&mut rng);
        let mut logged = Vec::new();
        for volts in [40.0, 2.5] {
            let mut shift = || {
                if cfg.subsample_step {
                    rng.uniform() * dt
                } else {
                    0.0
                }
            };
            let mut levels = vec![(shift(), volts)];
            if cfg.return_to_zero {
                levels.push((hold as f64 * dt + shift(), 0.0));
            }
            let truth = simulate(&motor, &Staircase { levels }, dt, n);
            let stretch = 1.0 + 0.05 * rng.uniform();
            let rec = log(
                &truth,
                (0.0, 1.2 * volts * stretch),
                cfg.voltage_noise_lsb,
                cfg.noise_lsb,
                stretch,
                &mut rng,
            );
            logged.push(rec);
        }
        let mut located = Vec::new();
        for rec in &logged {
            let loc = locate_step_with(&t, &rec.voltage, Some(rec.voltage_lsb)).expect("step");
            let mut inputs = loc.inputs();
            inputs.current_lsb_a = rec.current_lsb;
            let levels = loc
                .fall
                .map(|_| voltage_levels(&t, &rec.voltage, Some(rec.voltage_lsb)).expect("levels"));
            // The paper's method needs a speed: give it the encoder's central difference.
            let rise = loc.index..loc.fall.unwrap_or(n);
            let tt: Vec<f64> = (0..rise.len()).map(|i| i as f64 * dt).collect();
            let speed = motor_model::central_difference(&tt, &rec.angle[rise.clone()]);
            located.push((loc, inputs, levels, rise, speed));
        }
        let records: Vec<StepRecord> = logged
            .iter()
            .zip(&located)
            .map(|(rec, (loc, inputs, levels, rise, speed))| StepRecord {
                test: StepTest {
                    volts: loc.volts,
                    t_first: 0.0,
                    dt,
                    current: &rec.current[rise.clone()],
                    speed: Some(speed),
                    position: Some(&rec.angle[rise.clone()]),
                    exclude_current: None,
                    exclude_speed: None,
                },
                inputs: *inputs,
                whole: levels.as_ref().map(|(input, priors)| WholeRecord {
                    record: excited(input, dt, rec),
                    priors,
                }),
            })
            .collect();
        let fit = identify_step_pair(
            &records[0],
            &records[1],
            StepMethod::Full,
            LmSettings::default(),
        )
        .expect("full fit")
        .full
        .expect("a full fit");
        if fit.ci95.is_some() {
            with_ci += 1;
        }
        covered(&fit, &motor, &mut inside);
    }
    (inside, with_ci)
}

/// Coverage of the output-error fit's 95 % intervals over `runs` staircase records (40 V,
/// −20 V, 0 V, 2.5 V over 140 s; or 40 V then 0 V over 150 s with `return_to_zero`).
pub fn output_error_coverage(runs: u64, cfg: Config, seed: u64) -> ([usize; 6], usize) {
    use fit::{equation_error_start, voltage_levels, OutputError};
    let dt = 1e-3;
    let mut inside = [0; 6];
    let mut with_ci = 0;
    for run in 0..runs {
        let mut rng = Rng::new(seed.wrapping_mul(1_000_003).wrapping_add(run));
        let motor = run_motor(&mut rng);
        // Each change at its own place within a sample period (an asynchronous switch).
        let mut shift = || {
            if cfg.subsample_step {
                rng.uniform() * dt
            } else {
                0.0
            }
        };
        let (levels, duration, range) = if cfg.return_to_zero {
            (vec![(0.5, 40.0), (100.5, 0.0)], 150.0, (0.0, 48.0))
        } else {
            (
                vec![(0.5, 40.0), (40.5, -20.0), (80.5, 0.0), (100.5, 2.5)],
                140.0,
                (-48.0, 48.0),
            )
        };
        let input = Staircase {
            levels: levels.iter().map(|&(t, v)| (t + shift(), v)).collect(),
        };
        let n = (duration / dt) as usize + 1;
        let truth = simulate(&motor, &input, dt, n);
        let stretch = 1.0 + 0.05 * rng.uniform();
        let rec = log(
            &truth,
            (range.0 * stretch, range.1 * stretch),
            cfg.voltage_noise_lsb,
            cfg.noise_lsb,
            stretch,
            &mut rng,
        );
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let (u, priors) = voltage_levels(&t, &rec.voltage, Some(rec.voltage_lsb)).expect("levels");
        let records = [excited(&u, dt, &rec)];
        let start = equation_error_start(&records).expect("start");
        let fit = OutputError::new(&records, start)
            .level_priors(&[priors])
            .fit()
            .expect("output-error fit");
        if fit.ci95.is_some() {
            with_ci += 1;
        }
        covered(&fit, &motor, &mut inside);
    }
    (inside, with_ci)
}
