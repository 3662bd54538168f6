//! Full-model identification: R, L, k, f, J and Ts fitted jointly to whole step records.
//!
//! The model is the exact response of `motor-model` (Eq. (10) to the breakaway instant (11),
//! then the solution of (2)) for each record's measured step voltage — no approximation (32),
//! no steady-state assumption, breakaway included. Residuals are
//! `(model − measured)/σ_channel` over every sample of every channel given (current, and speed
//! and/or angle), each channel weighted by its own noise level, estimated from the record
//! ([`noise_std`]). Parameters are fitted as `θ = ln p` (all stay positive); the Jacobian is exact,
//! by forward-mode dual numbers through the same code that computes the response.

use motor_model::{Dual, Effects, MotorParams, MotorState, Real, StepResponse};
use nalgebra::{DMatrix, DVector};

use crate::error::FitError;
use crate::estimation::fitted::FullFit;
use crate::estimation::lm::{LeastSquares, LmSettings, NormalEquations};
use crate::estimation::parameters::{Parameters, MOTOR};
use crate::estimation::plausibility::RecordFacts;
use crate::estimation::records::{
    noise_floor, noise_std, Channel, ChannelQuality, FittedChannel, StepTest,
};
use crate::estimation::stats::{newey_west_lags, scaled_inverse, NeweyWest, SeriesLayout};
use crate::estimation::weighted::{quality_from_sums, WeightedProblem};
use crate::excitation::input_uncertainty::{
    bias_group_sizes, fit_with_inputs, grid_phase_score_covariance, noise_free_quantum,
    pooled_level_variance, settled_current, Nuisance, NuisanceProblem, StepInputs,
};

/// A channel's data and weight.
struct ChannelData {
    kind: Channel,
    data: Vec<f64>,
    sigma: f64,
    /// The smallest `sigma` may become ([`noise_floor`] of the fitted samples).
    floor: f64,
    /// Samples left out of the fit (`true`), if any.
    exclude: Option<Vec<bool>>,
    /// The ADC step of a current or tachometer channel read without noise
    /// ([`crate::excitation::input_uncertainty::noise_free_quantum`]); `None` for a noisy or unquantised
    /// channel and for the encoder's speed.
    noise_free_quantum: Option<f64>,
}

impl ChannelData {
    fn new(kind: Channel, data: Vec<f64>, exclude: Option<&[bool]>) -> Self {
        let exclude = exclude
            .filter(|m| m.iter().any(|&x| x))
            .map(<[bool]>::to_vec);
        let kept: Vec<f64> = match &exclude {
            Some(m) => data
                .iter()
                .zip(m)
                .filter(|(_, &x)| !x)
                .map(|(v, _)| *v)
                .collect(),
            None => Vec::new(),
        };
        let fitted = if exclude.is_some() { &kept } else { &data };
        let sigma = noise_std(fitted);
        let noise_free_quantum = match kind {
            Channel::Current | Channel::Speed => noise_free_quantum(fitted),
            Channel::EncoderSpeed => None,
        };
        ChannelData {
            kind,
            floor: noise_floor(fitted),
            data,
            sigma,
            exclude,
            noise_free_quantum,
        }
    }

    /// The measured value at sample `i`, unless it is left out.
    fn value(&self, i: usize) -> Option<f64> {
        if self.exclude.as_ref().is_some_and(|m| m[i]) {
            return None;
        }
        self.data.get(i).copied()
    }

    /// Samples fitted.
    fn fitted(&self) -> usize {
        self.exclude
            .as_ref()
            .map_or(self.data.len(), |m| m.iter().filter(|&&x| !x).count())
    }
}

struct Weighted {
    volts: f64,
    t_first: f64,
    dt: f64,
    n: usize,
    channels: Vec<ChannelData>,
    /// Offset \[A\] added to the model current from sample `settled_from` on: the settled
    /// current's quantisation error, an uncertain input (0 as estimated).
    current_offset: f64,
    /// First sample of the settled current, with the variance of its offset \[A²\], if any.
    settled: Option<(usize, f64)>,
}

struct FullProblem {
    /// θ: the motor's six logarithms.
    parameters: Parameters,
    tests: Vec<Weighted>,
    n_residuals: usize,
    /// Per test: the step height and `t_first` as estimated, and their uncertainty.
    inputs: Vec<(f64, f64, StepInputs)>,
}

fn params_of<T: Real>(theta: &[f64], make: impl Fn(f64, usize) -> T) -> Option<[T; 6]> {
    if theta.len() != 6 || theta.iter().any(|t| !t.is_finite() || t.abs() > 700.0) {
        return None;
    }
    Some(std::array::from_fn(|i| make(theta[i], i).exp()))
}

/// Central difference of `y` on a uniform grid `dt` at index `i`, one-sided at the ends — the
/// operator of `motor_model::central_difference`, applied to data and model alike.
fn difference_at<T: Real>(window: &[T; 3], i: usize, n: usize, dt: f64) -> T {
    // window = [y_{i-1}, y_i, y_{i+1}] where they exist.
    if i == 0 {
        (window[2] - window[1]) / T::cst(dt)
    } else if i + 1 == n {
        (window[1] - window[0]) / T::cst(dt)
    } else {
        (window[2] - window[0]) / T::cst(2.0 * dt)
    }
}

impl FullProblem {
    /// Streams every residual in order: `visit(test, channel index, i, model, y, sigma)`.
    fn for_each<T: Real>(
        &self,
        params: [T; 6],
        mut visit: impl FnMut(usize, usize, usize, T, f64, f64),
    ) {
        for (k, w) in self.tests.iter().enumerate() {
            let response = StepResponse::from_values(params, w.volts);
            // Model angles at i−2, i−1, i for the encoder-speed channel, emitted one sample late.
            let mut angles = [T::cst(0.0); 3];
            let n = w.n;
            let emit_encoder =
                |i: usize,
                 window: &[T; 3],
                 visit: &mut dyn FnMut(usize, usize, usize, T, f64, f64)| {
                    for (c, ch) in w.channels.iter().enumerate() {
                        if ch.kind == Channel::EncoderSpeed {
                            if let Some(y) = ch.value(i) {
                                visit(k, c, i, difference_at(window, i, n, w.dt), y, ch.sigma);
                            }
                        }
                    }
                };
            response.for_each_sample(w.t_first, w.dt, n, |i, s: MotorState<T>| {
                for (c, ch) in w.channels.iter().enumerate() {
                    let model = match ch.kind {
                        Channel::Current => match w.settled {
                            Some((from, _)) if i >= from => s.current_a + T::cst(w.current_offset),
                            _ => s.current_a,
                        },
                        Channel::Speed => s.speed_rad_s,
                        Channel::EncoderSpeed => continue,
                    };
                    if let Some(y) = ch.value(i) {
                        visit(k, c, i, model, y, ch.sigma);
                    }
                }
                angles = [angles[1], angles[2], s.position_rad];
                // Sample i−1 now has both neighbours.
                if i >= 1 {
                    let window = if i == 1 {
                        [angles[1], angles[1], angles[2]]
                    } else {
                        angles
                    };
                    emit_encoder(i - 1, &window, &mut visit);
                }
                if i + 1 == n {
                    emit_encoder(i, &[angles[1], angles[2], angles[2]], &mut visit);
                }
            });
        }
    }

    /// Newey–West estimate of the covariance of the score `Jᵀr` at `theta`: within each channel
    /// of each test, `Σᵢ gᵢgᵢᵀ + Σₗ wₗ (gᵢgᵢ₋ₗᵀ + gᵢ₋ₗgᵢᵀ)` with `gᵢ = rᵢ ∂rᵢ/∂θ` and Bartlett
    /// weights `wₗ = 1 − l/(L+1)`; channels are taken as independent of each other.
    fn score_covariance(&self, theta: &[f64]) -> Option<DMatrix<f64>> {
        let (r, jac) = self.linear_parts(theta)?;
        self.fitted_score_covariance(&r, &jac, &scaled_inverse(&jac.tr_mul(&jac))?)
    }

    /// The series of every residual in the order of `for_each` (one per channel of each
    /// test, as `score_covariance_of` takes them), with that accumulator's lags; a channel read
    /// without noise is left out (its covariance is its quantiser's,
    /// [`ChannelData::noise_free_quantum`]).
    fn series_layout(&self) -> SeriesLayout {
        let first: Vec<usize> = self
            .tests
            .iter()
            .scan(0, |at, w| {
                let here = *at;
                *at += w.channels.len();
                Some(here)
            })
            .collect();
        let lags = self
            .tests
            .iter()
            .flat_map(|w| w.channels.iter().map(|_| newey_west_lags(w.n).max(1)))
            .collect();
        let mut series = Vec::with_capacity(self.n_residuals);
        self.for_each([1.0; 6], |k, c, _, _: f64, _, _| {
            let noisy = self.tests[k].channels[c].noise_free_quantum.is_none();
            series.push(noisy.then_some(first[k] + c));
        });
        SeriesLayout { series, lags }
    }
}

impl LeastSquares for FullProblem {
    fn n_params(&self) -> usize {
        6
    }

    fn cost(&self, theta: &[f64]) -> Option<f64> {
        let params = params_of::<f64>(theta, |v, _| v)?;
        let mut cost = 0.0;
        self.for_each(params, |_, _, _, m, y, sigma| {
            let r = (m - y) / sigma;
            cost += r * r;
        });
        cost.is_finite().then_some(0.5 * cost)
    }

    fn normal_equations(&self, theta: &[f64]) -> Option<NormalEquations> {
        let params = params_of::<Dual<6>>(theta, Dual::variable)?;
        let mut jtj = [[0.0; 6]; 6];
        let mut jtr = [0.0; 6];
        let mut cost = 0.0;
        self.for_each(params, |_, _, _, m, y, sigma| {
            let inv = 1.0 / sigma;
            let r = (m.v - y) * inv;
            let g = m.d.map(|d| d * inv);
            cost += r * r;
            for a in 0..6 {
                jtr[a] += g[a] * r;
                for b in a..6 {
                    jtj[a][b] += g[a] * g[b];
                }
            }
        });
        let m = DMatrix::from_fn(6, 6, |a, b| if a <= b { jtj[a][b] } else { jtj[b][a] });
        Some(NormalEquations {
            jtj: m,
            jtr: DVector::from_row_slice(&jtr),
            cost: 0.5 * cost,
            n_residuals: self.n_residuals,
        })
    }
}

/// Relative step of the central difference in a step height.
const VOLTS_DIFF_STEP: f64 = 1e-5;
/// Step of the central difference in a step instant, as a fraction of the sample period.
const DELAY_DIFF_STEP: f64 = 1e-3;

impl FullProblem {
    /// The test and input (0: step height, 1: `t_first`, 2: settled-current offset) of
    /// nuisance `j`.
    fn nuisance_slots(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for (k, (_, _, u)) in self.inputs.iter().enumerate() {
            if u.volts_variance_v2 > 0.0 {
                out.push((k, 0));
            }
            if u.delay_variance_s2 > 0.0 {
                out.push((k, 1));
            }
            if self.tests[k].settled.is_some() {
                out.push((k, 2));
            }
        }
        out
    }
}

impl NuisanceProblem for FullProblem {
    fn nuisances(&self) -> Vec<Nuisance> {
        let slots = self.nuisance_slots();
        let level_tests: Vec<usize> = slots
            .iter()
            .filter(|(_, slot)| *slot == 0)
            .map(|(k, _)| *k)
            .collect();
        let groups = bias_group_sizes(
            &level_tests
                .iter()
                .map(|&k| {
                    let u = self.inputs[k].2;
                    (u.volts_bias_variance_v2, u.volts_bias_code)
                })
                .collect::<Vec<_>>(),
        );
        let group_of = |k: usize| {
            level_tests
                .iter()
                .position(|&t| t == k)
                .map_or(1, |i| groups[i])
        };
        slots
            .into_iter()
            .map(|(k, slot)| {
                let w = &self.tests[k];
                let (volts, t_first, u) = self.inputs[k];
                if slot == 0 {
                    Nuisance {
                        value: w.volts,
                        prior_mean: volts,
                        prior_variance: pooled_level_variance(
                            u.volts_variance_v2,
                            u.volts_bias_variance_v2,
                            group_of(k),
                        ),
                        step: VOLTS_DIFF_STEP * volts.abs().max(1e-3),
                    }
                } else if slot == 2 {
                    let variance = w.settled.map_or(0.0, |(_, v)| v);
                    Nuisance {
                        value: w.current_offset,
                        prior_mean: 0.0,
                        prior_variance: variance,
                        step: 1e-3 * variance.sqrt(),
                    }
                } else {
                    Nuisance {
                        value: w.t_first,
                        prior_mean: t_first,
                        prior_variance: u.delay_variance_s2,
                        step: DELAY_DIFF_STEP * w.dt,
                    }
                }
            })
            .collect()
    }

    fn set_nuisance(&mut self, j: usize, value: f64) {
        if let Some(&(k, slot)) = self.nuisance_slots().get(j) {
            let (_, t_first, u) = self.inputs[k];
            let w = &mut self.tests[k];
            match slot {
                0 => w.volts = value,
                // The instant stays in the period its uniform prior spans (±√(3V)).
                1 => {
                    let half = (3.0 * u.delay_variance_s2).sqrt();
                    w.t_first = value.min(t_first + half).max(t_first - half).max(0.0);
                }
                _ => w.current_offset = value,
            }
        }
    }

    fn linear_parts(&self, theta: &[f64]) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let params = params_of::<Dual<6>>(theta, Dual::variable)?;
        let mut r = Vec::with_capacity(self.n_residuals);
        let mut rows: Vec<[f64; 6]> = Vec::with_capacity(self.n_residuals);
        self.for_each(params, |_, _, _, m, y, sigma| {
            r.push((m.v - y) / sigma);
            rows.push(m.d.map(|d| d / sigma));
        });
        let jac = DMatrix::from_fn(rows.len(), 6, |i, j| rows[i][j]);
        Some((r, jac))
    }

    fn residual_vector(&self, theta: &[f64]) -> Option<Vec<f64>> {
        let params = params_of::<f64>(theta, |v, _| v)?;
        let mut r = Vec::with_capacity(self.n_residuals);
        self.for_each(params, |_, _, _, m, y, sigma| r.push((m - y) / sigma));
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    /// The score covariance of the residuals `r` with Jacobian columns `jac` (θ and inputs
    /// alike): Newey–West within each channel of each test, except for a channel read without
    /// noise ([`ChannelData::noise_free_quantum`]), whose error is fixed by the signal and by
    /// where the ADC's grid sits — held for seconds on a settling tail and largely absorbed by
    /// the parameters, so the residuals cannot show it: that channel enters as its quantiser on
    /// the model's values averaged over the grid's place
    /// ([`crate::excitation::input_uncertainty::grid_phase_score_covariance`]).
    fn score_covariance_of(&self, r: &[f64], jac: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let p = jac.ncols();
        if r.len() != jac.nrows() {
            return None;
        }
        // One accumulator per (test, channel): the residuals stream interleaved across
        // channels, in the order of `for_each` (any parameters give the same order). A
        // noise-free channel keeps its rows and the model's values for the grid instead.
        let mut series: Vec<Vec<NeweyWest>> = self
            .tests
            .iter()
            .map(|w| w.channels.iter().map(|_| NeweyWest::new(p, w.n)).collect())
            .collect();
        let mut held: Vec<Vec<(Vec<usize>, Vec<f64>)>> = self
            .tests
            .iter()
            .map(|w| w.channels.iter().map(|_| Default::default()).collect())
            .collect();
        let mut row = 0;
        let mut score = vec![0.0; p];
        self.for_each([1.0; 6], |k, c, _, _: f64, y, sigma| {
            if self.tests[k].channels[c].noise_free_quantum.is_some() {
                if let Some(&ri) = r.get(row) {
                    let (rows, model) = &mut held[k][c];
                    rows.push(row);
                    model.push(y + sigma * ri);
                }
            } else if let (Some(&ri), Some(nw)) = (r.get(row), series[k].get_mut(c)) {
                for (j, g) in score.iter_mut().enumerate() {
                    *g = ri * jac[(row, j)];
                }
                nw.push(&score);
            }
            row += 1;
        });
        if row != r.len() {
            return None;
        }
        let mut total = DMatrix::zeros(p, p);
        for (w, (nws, held)) in self.tests.iter().zip(series.iter().zip(&held)) {
            for (ch, (nw, (rows, model))) in w.channels.iter().zip(nws.iter().zip(held)) {
                match ch.noise_free_quantum {
                    Some(q) => {
                        let rows = jac.select_rows(rows.iter());
                        total += grid_phase_score_covariance(model, q, rows.as_view(), ch.sigma);
                    }
                    None => total += nw.finish()?,
                }
            }
        }
        Some(total)
    }
}

/// Identifies R, L, k, f, J, Ts from `tests` (at least one; the paper uses a high- and a
/// low-voltage step), starting from `start` (e.g. the paper method's result). The step heights
/// and instants are taken as exact: see [`identify_full_with_inputs`] for measured ones.
pub fn identify_full(
    tests: &[StepTest<'_>],
    start: &MotorParams,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    identify_full_with_inputs(tests, &[], start, settings)
}

/// [`identify_full`] with what each test leaves unknown about its input (`inputs`, one per test,
/// or empty for exact inputs): the step height's variance, and the step instant's expected
/// delay before the first sample and its variance. The fit moves these inputs where the records
/// put them and widens the intervals by what remains unknown (see [`crate::StepInputs`]).
pub fn identify_full_with_inputs(
    tests: &[StepTest<'_>],
    inputs: &[StepInputs],
    start: &MotorParams,
    settings: LmSettings,
) -> Result<FullFit, FitError> {
    if !inputs.is_empty() && inputs.len() != tests.len() {
        return Err(FitError::BadData {
            series: "step inputs".into(),
            reason: format!(
                "{} input uncertainties for {} tests: give one per test, or none",
                inputs.len(),
                tests.len()
            ),
        });
    }
    if let Some((k, _)) = inputs.iter().enumerate().find(|(_, u)| {
        ![u.volts_variance_v2, u.delay_variance_s2]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
            || !u.delay_s.is_finite()
    }) {
        return Err(FitError::BadData {
            series: format!("test {} inputs", k + 1),
            reason: "variances must be finite and ≥ 0, the delay finite".into(),
        });
    }
    // The start is checked where it becomes θ (before any record is read).
    let parameters = Parameters::nominal();
    let theta0 = parameters.encode(start, &Effects::none())?;
    if tests.is_empty() {
        return Err(FitError::BadData {
            series: "step tests".into(),
            reason: "no test given".into(),
        });
    }
    let mut weighted = Vec::new();
    let mut n_residuals = 0;
    for (k, t) in tests.iter().enumerate() {
        crate::estimation::checks::check_step_test(&format!("test {}", k + 1), t)?;
        let n = t.current.len();
        let mut channels = vec![ChannelData::new(
            Channel::Current,
            t.current.to_vec(),
            t.exclude_current,
        )];
        match (t.position, t.speed) {
            (Some(angle), _) => {
                let times: Vec<f64> = (0..n).map(|i| t.t_first + i as f64 * t.dt).collect();
                let data = motor_model::central_difference(&times, angle);
                channels.push(ChannelData::new(
                    Channel::EncoderSpeed,
                    data,
                    t.exclude_speed,
                ));
            }
            (None, Some(speed)) => {
                channels.push(ChannelData::new(
                    Channel::Speed,
                    speed.to_vec(),
                    t.exclude_speed,
                ));
            }
            (None, None) => {}
        }
        n_residuals += channels.iter().map(ChannelData::fitted).sum::<usize>();
        let input = inputs.get(k).copied().unwrap_or_default();
        weighted.push(Weighted {
            volts: t.volts,
            t_first: t.t_first + input.delay_s,
            dt: t.dt,
            n,
            current_offset: 0.0,
            // A current read without noise enters the score covariance whole, by its grid's
            // place, and gets no settled offset: the offset's first sample is where the
            // readings last changed code, so it would take up the held code's error exactly
            // where the grid puts it (biasing f and J, and leaving Ts far inside an interval
            // that counts the code as unknown).
            settled: match channels[0].noise_free_quantum {
                Some(_) => None,
                None => settled_current(t.current, input.current_lsb_a),
            },
            channels,
        });
    }
    let inputs = weighted
        .iter()
        .zip(
            inputs
                .iter()
                .copied()
                .chain(std::iter::repeat(StepInputs::default())),
        )
        .map(|(w, u)| (w.volts, w.t_first, u))
        .collect();
    let mut problem = FullProblem {
        parameters,
        tests: weighted,
        n_residuals,
        inputs,
    };
    fit_with_inputs(&mut problem, &theta0, settings)
}

fn channel_quality(problem: &FullProblem, values: [f64; MOTOR]) -> Vec<ChannelQuality> {
    let mut sums: Vec<Vec<(f64, f64)>> = problem
        .tests
        .iter()
        .map(|w| vec![(0.0, 0.0); w.channels.len()])
        .collect();
    let means: Vec<Vec<f64>> = problem
        .tests
        .iter()
        .map(|w| {
            w.channels
                .iter()
                .map(|c| {
                    (0..c.data.len()).filter_map(|i| c.value(i)).sum::<f64>()
                        / c.fitted().max(1) as f64
                })
                .collect()
        })
        .collect();
    problem.for_each(values, |k, c, _, m, y, _| {
        let (sse, sst) = &mut sums[k][c];
        *sse += (m - y).powi(2);
        *sst += (y - means[k][c]).powi(2);
    });
    let mut out = Vec::new();
    for (k, w) in problem.tests.iter().enumerate() {
        for (c, ch) in w.channels.iter().enumerate() {
            let (sse, sst) = sums[k][c];
            out.push(quality_from_sums(
                k,
                ch.kind,
                ch.sigma,
                sse,
                sst,
                ch.fitted(),
            ));
        }
    }
    out
}

impl WeightedProblem for FullProblem {
    fn parameters(&self) -> &Parameters {
        &self.parameters
    }

    fn fitted_channels(&self, theta: &[f64]) -> Vec<FittedChannel> {
        let Some(params) = params_of::<f64>(theta, |v, _| v) else {
            return Vec::new();
        };
        let mut out: Vec<Vec<FittedChannel>> = self
            .tests
            .iter()
            .enumerate()
            .map(|(k, w)| {
                w.channels
                    .iter()
                    .map(|ch| FittedChannel {
                        record: k,
                        channel: ch.kind,
                        samples: Vec::with_capacity(ch.fitted()),
                        measured: Vec::with_capacity(ch.fitted()),
                        model: Vec::with_capacity(ch.fitted()),
                    })
                    .collect()
            })
            .collect();
        self.for_each(params, |k, c, i, m, y, _| {
            let f = &mut out[k][c];
            f.samples.push(i);
            f.measured.push(y);
            f.model.push(m);
        });
        out.into_iter().flatten().collect()
    }

    fn sigmas_mut(&mut self) -> Vec<(&mut f64, f64)> {
        self.tests
            .iter_mut()
            .flat_map(|w| w.channels.iter_mut().map(|c| (&mut c.sigma, c.floor)))
            .collect()
    }

    fn channel_quality(&self, theta: &[f64]) -> Vec<ChannelQuality> {
        params_of::<f64>(theta, |v, _| v).map_or_else(Vec::new, |v| channel_quality(self, v))
    }

    fn score_covariance(&self, theta: &[f64]) -> Option<DMatrix<f64>> {
        FullProblem::score_covariance(self, theta)
    }

    fn series_layout(&self) -> SeriesLayout {
        FullProblem::series_layout(self)
    }

    fn facts(&self) -> RecordFacts {
        let mut facts = RecordFacts::default();
        for w in &self.tests {
            facts.add(
                w.dt,
                w.n,
                w.channels.iter().map(|c| (c.kind, c.data.as_slice())),
            );
        }
        facts
    }
}
