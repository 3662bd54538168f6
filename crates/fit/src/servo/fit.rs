//! The motor of a servo rig fitted to its logs by output error: every record replayed (closed
//! loop from its set-point, or open loop from its duty) with its own loads and controller, the
//! motor's constants moved by Levenberg–Marquardt to bring the replayed angle onto the logged
//! one.
//!
//! Parameters are fitted as logarithms (each is positive), the Jacobian by central
//! differences (the stick-slip replay is piecewise smooth). The 95 % intervals are the
//! sandwich of the Newey–West covariance of the score taken over runs of equal logged values
//! (each record's angle and speed a series: an encoder's error is one-signed for as long as
//! its count holds), raised to at least the white-noise ones.

use motor_model::{replay, ReplaySettings, ServoMotor};
use nalgebra::DMatrix;

use crate::error::FitError;
use crate::estimation::lm::{solve, LeastSquares, LmSettings, NormalEquations, Termination};
use crate::estimation::parameters::ParameterEstimate;
use crate::estimation::stats::{
    at_least, equal_runs, newey_west_run_covariance, sandwich_uncertainty, uncertainty,
};
use crate::servo::records::{Loop, ServoRecord};
use crate::servo::score::{score_records, ReplayScore};

/// Names of the servo motor's constants, in the order of the fit's parameter vector.
pub const SERVO_NAMES: [&str; 9] = ["ke", "R", "J", "Fc", "fv", "mu_m", "mu_l", "Fs", "ws"];
/// Their units.
pub const SERVO_UNITS: [&str; 9] = [
    "N·m/A",
    "Ω",
    "kg·m²",
    "N·m",
    "N·m·s/rad",
    "-",
    "-",
    "N·m",
    "rad/s",
];

/// The constants of `m` in the order of [`SERVO_NAMES`].
fn constants(m: &ServoMotor) -> [f64; 9] {
    [
        m.ke_nm_per_a,
        m.r_ohm,
        m.j_kg_m2,
        m.fc_nm,
        m.fv_nm_s_per_rad,
        m.mu_motor,
        m.mu_load,
        m.fs_nm,
        m.ws_rad_s,
    ]
}

/// The motor of constants `c` in the order of [`SERVO_NAMES`].
fn from_constants(c: [f64; 9]) -> ServoMotor {
    ServoMotor {
        ke_nm_per_a: c[0],
        r_ohm: c[1],
        j_kg_m2: c[2],
        fc_nm: c[3],
        fv_nm_s_per_rad: c[4],
        mu_motor: c[5],
        mu_load: c[6],
        fs_nm: c[7],
        ws_rad_s: c[8],
    }
}

/// Which friction the fit gives the motor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Friction {
    /// Coulomb and viscous friction (μm, μl and Fs held at 0).
    CoulombViscous,
    /// Coulomb, viscous and load-dependent friction (μm and μl fitted, Fs held at 0).
    #[default]
    LoadDependent,
    /// All of the above and a Stribeck peak at rest (Fs and ωs fitted too).
    Stribeck,
}

impl Friction {
    /// How many of [`SERVO_NAMES`], from the first, the fit moves; the rest are 0 (ωs: 1).
    fn fitted(self) -> usize {
        match self {
            Friction::CoulombViscous => 5,
            Friction::LoadDependent => 7,
            Friction::Stribeck => 9,
        }
    }
}

/// Settings of a servo fit (a builder): the records, how they are replayed, the start.
#[derive(Debug, Clone)]
pub struct ServoFit<'a> {
    records: &'a [ServoRecord],
    mode: Loop,
    friction: Friction,
    start: ServoMotor,
    lm: LmSettings,
    replay: ReplaySettings,
    search_evaluations: usize,
    speed_weight_s: Option<f64>,
}

/// Most sub-steps one replay of all the records may take in a fit: 10 times the eight XL330
/// logs' 2e5 (a fit of them takes about 6 s on 2 cores; of this many, about a minute).
const MAX_SUBSTEPS_PER_REPLAY: f64 = 2e6;

/// Relative change of the cost below which removing a friction term makes no difference.
const NEGLIGIBLE_COST: f64 = 1e-6;

/// Seed of the global search's random draws.
const SEARCH_SEED: u64 = 0x5e4b0;

/// The fitted motor with its intervals and how well each record is replayed.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoFitResult {
    /// The fitted motor at the output.
    pub motor: ServoMotor,
    /// Each constant with its unit, value and 95 % interval ([`SERVO_NAMES`]; μm and μl only
    /// when fitted).
    pub estimates: Vec<ParameterEstimate>,
    /// The friction terms (from `Fc` on) the fit drove to zero: no effect left on the replay,
    /// reported as 0 without an interval (the records show none of them).
    pub at_zero: Vec<&'static str>,
    /// Why the solver stopped.
    pub termination: Termination,
    /// Accepted iterations.
    pub iterations: u64,
    /// Each record replayed with the fitted motor.
    pub scores: Vec<ReplayScore>,
    /// Mean over records of their position MAE \[rad\].
    pub mae_rad: f64,
}

/// A start for a small geared servo at its output (ke 0.5 N·m/A, R 4 Ω, J 1e-3 kg·m², Fc
/// 0.05 N·m, fv 0.01 N·m·s/rad, μm and μl 0.1, a Stribeck peak Fs 0.02 N·m below ωs
/// 0.2 rad/s): a stall torque of about 0.9 N·m at 7 V.
pub const SMALL_SERVO_START: ServoMotor = ServoMotor {
    ke_nm_per_a: 0.5,
    r_ohm: 4.0,
    j_kg_m2: 1e-3,
    fc_nm: 0.05,
    fv_nm_s_per_rad: 0.01,
    mu_motor: 0.1,
    mu_load: 0.1,
    fs_nm: 0.02,
    ws_rad_s: 0.2,
};

impl<'a> ServoFit<'a> {
    /// A fit of `records` in closed loop with load-dependent friction from
    /// [`SMALL_SERVO_START`].
    pub fn new(records: &'a [ServoRecord]) -> Self {
        ServoFit {
            records,
            mode: Loop::Closed,
            friction: Friction::default(),
            start: SMALL_SERVO_START,
            lm: LmSettings {
                max_iters: 100,
                max_evaluations: 400,
                ftol: 1e-8,
                xtol: 1e-8,
                ..LmSettings::default()
            },
            replay: ReplaySettings::default(),
            search_evaluations: 2000,
            speed_weight_s: Some(0.05),
        }
    }

    /// Replays the global search may spend before LM (0: LM from the start alone).
    pub fn search_evaluations(mut self, n: usize) -> Self {
        self.search_evaluations = n;
        self
    }

    /// Replay in closed loop (default) or open loop.
    pub fn mode(mut self, mode: Loop) -> Self {
        self.mode = mode;
        self
    }

    /// The friction model.
    pub fn friction(mut self, friction: Friction) -> Self {
        self.friction = friction;
        self
    }

    /// The motor the solver starts from.
    pub fn start(mut self, start: ServoMotor) -> Self {
        self.start = start;
        self
    }

    /// The solver's tolerances and budget.
    pub fn lm(mut self, lm: LmSettings) -> Self {
        self.lm = lm;
        self
    }

    /// The replay's sub-step.
    pub fn replay(mut self, replay: ReplaySettings) -> Self {
        self.replay = replay;
        self
    }

    fn n_params(&self) -> usize {
        self.friction.fitted()
    }

    /// The motor at `θ` (the logarithms of the fitted constants; the others absent).
    fn motor(&self, theta: &[f64]) -> ServoMotor {
        let mut c = [0.0; 9];
        c[8] = 1.0;
        for (c, t) in c.iter_mut().zip(theta) {
            *c = t.exp();
        }
        from_constants(c)
    }

    /// The speed channel's weight \[s\] in the fit: a speed error of 1 rad/s counts as a
    /// position error of this many radians (`None`: the angle alone). The angle alone leaves
    /// the damping of a P-controlled servo to the fast parts of the records; the logged speed
    /// (even the firmware's coarse estimate) carries it on every motion. Default 0.05 s: the
    /// speed's error over about ten samples of a 200 Hz log.
    pub fn speed_weight_s(mut self, weight: Option<f64>) -> Self {
        self.speed_weight_s = weight;
        self
    }

    /// The length of each series of residuals in [`ServoFit::residuals`]'s order (each
    /// record's angle, then its speed where it is fitted) and the runs of equal logged values
    /// within them ([`equal_runs`]): an encoder's count held while the output creeps, or
    /// stuck, errs the same way for the whole run.
    fn series_runs(&self) -> (Vec<usize>, Vec<usize>) {
        let (mut series, mut runs) = (Vec::new(), Vec::new());
        for record in self.records {
            series.push(record.q_rad.len());
            runs.extend(equal_runs(&record.q_rad));
            if let (Some(_), Some(w)) = (self.speed_weight_s, &record.w_rad_s) {
                series.push(w.len());
                runs.extend(equal_runs(w));
            }
        }
        (series, runs)
    }

    /// Stacked residuals `q_replayed − q_logged` of every record, with the record each
    /// begins at; `None` where a replay fails (the solver rejects the step).
    fn residuals(&self, theta: &[f64]) -> Option<Vec<f64>> {
        self.residuals_of(self.motor(theta))
    }

    /// [`ServoFit::residuals`] of `motor`.
    fn residuals_of(&self, motor: ServoMotor) -> Option<Vec<f64>> {
        let mut out = Vec::new();
        for record in self.records {
            let run = record.run(self.mode).ok()?;
            let trace = replay(&record.rig(motor), &run, self.replay).ok()?;
            let q = &trace.q_rad;
            out.extend(q.iter().zip(&record.q_rad).map(|(s, m)| s - m));
            if let (Some(tw), Some(w)) = (self.speed_weight_s, &record.w_rad_s) {
                // A firmware's speed is an estimate over the last sample interval, not the
                // speed at the stamp: compare it with the replay's mean speed over the same
                // interval (the replay's own speed at the first stamp).
                let t = &record.t_s;
                out.extend((0..t.len()).map(|k| {
                    let replayed = if k == 0 {
                        trace.w_rad_s[0]
                    } else {
                        (q[k] - q[k - 1]) / (t[k] - t[k - 1])
                    };
                    tw * (replayed - w[k])
                }));
            }
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// Residuals and their Jacobian by central differences in `θ`.
    fn jacobian(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        const H: f64 = 1e-3;
        let r = self.residuals(theta)?;
        let mut jac = DMatrix::zeros(r.len(), theta.len());
        for k in 0..theta.len() {
            let mut up = theta.to_vec();
            let mut down = theta.to_vec();
            up[k] += H;
            down[k] -= H;
            let (ru, rd) = (self.residuals(&up)?, self.residuals(&down)?);
            for (i, (a, b)) in ru.iter().zip(&rd).enumerate() {
                jac[(i, k)] = (a - b) / (2.0 * H);
            }
        }
        Some((r, jac))
    }

    /// Runs the fit. Refuses records without an input or without samples, a start that is not
    /// a valid motor, and a fit whose replay fails at its start.
    pub fn fit(&self) -> Result<ServoFitResult, FitError> {
        if self.records.is_empty() {
            return Err(FitError::BadData {
                series: "servo records".into(),
                reason: "no record given".into(),
            });
        }
        for record in self.records {
            record.run(self.mode)?;
            if record.q_rad.len() < 2 || record.q_rad.len() != record.t_s.len() {
                return Err(FitError::BadData {
                    series: record.name.clone(),
                    reason: "fewer than two samples of position, or not one per time stamp".into(),
                });
            }
        }
        self.start
            .validate()
            .map_err(FitError::model("start parameters"))?;
        let substeps: f64 = self
            .records
            .iter()
            .flat_map(|r| r.t_s.windows(2))
            .map(|w| ((w[1] - w[0]) / self.replay.max_step_s).ceil())
            .sum();
        if substeps > MAX_SUBSTEPS_PER_REPLAY {
            return Err(FitError::BadData {
                series: "servo records".into(),
                reason: format!(
                    "one replay of the records takes {substeps:.0} sub-steps of {} s, and a fit replays them thousands of times (at most {MAX_SUBSTEPS_PER_REPLAY:.0} a replay): are the time stamps in seconds? Fit a shorter stretch of the logs",
                    self.replay.max_step_s
                ),
            });
        }
        // A size of 0 has no logarithm: the search starts such a term small instead.
        let theta0: Vec<f64> = constants(&self.start)[..self.n_params()]
            .iter()
            .map(|v| v.max(1e-6).ln())
            .collect();
        let start = self.motor(&theta0);
        for record in self.records {
            let run = record.run(self.mode)?;
            replay(&record.rig(start), &run, self.replay).map_err(|e| FitError::BadData {
                series: record.name.clone(),
                reason: format!(
                    "the replay from the fit's start fails ({e}): check the loads, the controller and the input columns"
                ),
            })?;
        }
        let theta0 = self.global_search(&theta0);
        let report = solve(self, &theta0, self.lm)?;
        let motor = self.motor(&report.params);
        let (estimates, at_zero) = self.estimates(&report.params);
        let scores = score_records(self.records, motor, self.mode, self.replay)?;
        let mae_rad = scores.iter().map(|s| s.mae_rad).sum::<f64>() / scores.len() as f64;
        Ok(ServoFitResult {
            motor,
            estimates,
            at_zero,
            termination: report.termination,
            iterations: report.iterations,
            scores,
            mae_rad,
        })
    }

    /// The best `θ` a CMA-ES search finds from `theta0` within [`ServoFit::search_evaluations`]
    /// replays (seeded, so a fit is repeatable): the replayed angle of a stick-slip rig is a
    /// rough function of the constants, with local minima that a gradient method from one
    /// start stops in; the search leaves LM a start in the right basin.
    fn global_search(&self, theta0: &[f64]) -> Vec<f64> {
        if self.search_evaluations == 0 {
            return theta0.to_vec();
        }
        let objective = |x: &cmaes::DVector<f64>| -> f64 {
            self.residuals(x.as_slice())
                .map_or(f64::MAX, |r| r.iter().map(|v| v * v).sum::<f64>())
        };
        let built = cmaes::CMAESOptions::new(theta0.to_vec(), 1.0)
            .max_function_evals(self.search_evaluations)
            .seed(SEARCH_SEED)
            .build(objective);
        let Ok(mut search) = built else {
            return theta0.to_vec();
        };
        search.run_parallel();
        search
            .overall_best_individual()
            .map_or_else(|| theta0.to_vec(), |b| b.point.as_slice().to_vec())
    }

    /// The constants with 95 % intervals at `theta` (module docs).
    fn estimates(&self, theta: &[f64]) -> (Vec<ParameterEstimate>, Vec<&'static str>) {
        let mut at_zero = vec![false; theta.len()];
        let half = self.jacobian(theta).and_then(|(r, jac)| {
            // A friction term the fit drove towards zero, whose removal changes the replay's
            // cost by less than [`NEGLIGIBLE_COST`]: its column of the Jacobian all but
            // vanishes and its logarithm has no interval. It is reported at zero, and the
            // others' intervals are those of the fit without it.
            let cost = r.iter().map(|v| v * v).sum::<f64>();
            for (k, zero) in at_zero.iter_mut().enumerate().skip(3) {
                let mut c = constants(&self.motor(theta));
                c[k] = 0.0;
                let without = self.residuals_of(from_constants(c))?;
                let cost0 = without.iter().map(|v| v * v).sum::<f64>();
                *zero = (cost0 - cost).abs() <= NEGLIGIBLE_COST * cost;
            }
            let kept: Vec<usize> = (0..theta.len()).filter(|&k| !at_zero[k]).collect();
            let jac = jac.select_columns(&kept);
            let normal = NormalEquations::from_jacobian(r.clone(), &jac);
            let white = uncertainty(&normal)?;
            let (series, runs) = self.series_runs();
            let score = newey_west_run_covariance(&r, &jac, &series, &runs)?;
            let hac = sandwich_uncertainty(&normal, &score)?;
            let kept_half = at_least(hac, &white)?.ci95_half_width;
            let mut half = vec![f64::NAN; theta.len()];
            for (k, h) in kept.iter().zip(kept_half) {
                half[*k] = h;
            }
            Some(half)
        });
        let values = constants(&self.motor(theta));
        let estimates = (0..self.n_params())
            .map(|k| ParameterEstimate {
                name: SERVO_NAMES[k],
                unit: SERVO_UNITS[k],
                value: if at_zero[k] { 0.0 } else { values[k] },
                // An interval reaching 0 or infinity in a positive constant is none.
                ci95: half
                    .as_ref()
                    .and_then(|h| h.get(k))
                    .map(|h| [(theta[k] - h).exp(), (theta[k] + h).exp()])
                    .filter(|[lo, hi]| *lo > 0.0 && hi.is_finite()),
            })
            .collect();
        let zero = (0..self.n_params())
            .filter(|&k| at_zero[k])
            .map(|k| SERVO_NAMES[k])
            .collect();
        (estimates, zero)
    }
}

impl LeastSquares for ServoFit<'_> {
    fn n_params(&self) -> usize {
        ServoFit::n_params(self)
    }

    fn cost(&self, p: &[f64]) -> Option<f64> {
        self.residuals(p)
            .map(|r| 0.5 * r.iter().map(|v| v * v).sum::<f64>())
    }

    fn normal_equations(&self, p: &[f64]) -> Option<NormalEquations> {
        self.jacobian(p)
            .map(|(r, jac)| NormalEquations::from_jacobian(r, &jac))
    }
}
