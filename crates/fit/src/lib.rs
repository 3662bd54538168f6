//! Identification of DC motor parameters by Levenberg–Marquardt (through `argmin`).
//!
//! - [`LevenbergMarquardt`]: an `argmin` solver for problems that supply their normal
//!   equations ([`LeastSquares`]); every result carries its [`Termination`].
//! - [`fit_33`]: the fit of the paper's Eq. (33) to a normalised high-voltage current.
//! - [`uncertainty`]: covariance, 95 % intervals (Student t, as MATLAB's `nlparci`) and
//!   correlations; [`student_t_quantile`].
//! - [`OutputError`]: R, L, k, f, J, Ts (and any effects') from records of any voltage
//!   waveform, by output error through the stick-slip simulator; one settings value for all
//!   that is known of the records.
//! - [`identify_full_with_inputs`], [`OutputError::level_priors`]: the step heights,
//!   levels and instants as measured inputs whose uncertainty enters the intervals
//!   ([`estimate_level`], [`StepInputs`], [`LevelPrior`]).
//! - [`OutputError::initial_states`]: records that do not start at rest, each
//!   started at rest, in the steady state of its first level (Eqs. (4), (5)) or from a free
//!   initial current and speed ([`InitialState`], [`detect_initial_state`]).
//! - [`OutputError::effects`]: the motor's six parameters and those of a set of
//!   unmodelled effects (SPEC section 5) in one output-error fit, each named with its unit and
//!   interval ([`EffectEstimate`]); every fit returns its fitted traces ([`FittedChannel`]).
//!
//! - [`RecordKind`]: what a set of records can identify from the channels it measured;
//!   [`identify_feedforward`]: kS, kV, kA (and J, f, Ts with R and k known) from voltage and
//!   speed alone.
//!
//! - [`diagnose`]: the sim-to-real diagnosis; [`diagnose::localise`] says where a model still
//!   disagrees with the records, against the records' own noise floor.
//!
//! It does no I/O: records come in as slices, results go out as values.
//!
//! ```
//! use fit::{fit_33, LmSettings, Params33, Record33};
//! use motor_model::paper::normalized_current_33;
//!
//! let truth = Params33 { alpha: 4.99, sigma: 0.525, omega_a: 0.388 };
//! let y: Vec<f64> = (0..5000)
//!     .map(|i| normalized_current_33(truth.alpha, truth.sigma, truth.omega_a, i as f64 * 0.01))
//!     .collect();
//! let record = Record33 { t_first: 0.0, dt: 0.01, normalized_current: &y };
//! let start = Params33 { alpha: 3.0, sigma: 0.4, omega_a: 0.3 };
//! let fit = fit_33(&record, start, LmSettings::default()).unwrap();
//! assert!(fit.report.termination.converged());
//! assert!((fit.params.sigma - 0.525).abs() < 1e-9);
//! ```
#![warn(missing_docs)]

mod current_driven;
pub mod diagnose;
mod error;
mod estimation;
mod excitation;
mod servo;
mod steps;
mod voltage_speed;

pub use current_driven::mechanical::{
    identify_inverse_model, identify_inverse_model_pooled, motor_torque, AxisRecord, FittedTorque,
    InverseModelSettings, MechanicalFit, OffsetStatus, MECHANICAL_NAMES, MECHANICAL_UNITS_LINEAR,
    MECHANICAL_UNITS_ROTARY,
};
pub use error::FitError;
pub use estimation::checks::{
    check_settled, check_settled_for, check_step_test, MIN_SAMPLES, SETTLED_FRACTION,
};
pub use estimation::clipping::{find_clipping, MIN_CLIPPED_RUN};
pub use estimation::fitted::FullFit;
pub use estimation::intervals::MotorIntervals;
pub use estimation::lm::{
    accepted_steps, solve, LeastSquares, LevenbergMarquardt, LmReport, LmSettings, NormalEquations,
    Termination,
};
pub use estimation::parameters::EffectEstimate;
pub use estimation::records::ExcitedRecord;
pub use estimation::records::{
    noise_std, Channel, ChannelQuality, FittedChannel, StepTest, PARAM_NAMES, PARAM_UNITS,
};
pub use estimation::records::{FittedInitialState, InitialState};
pub use estimation::refusal::Refusal;
pub use estimation::signal::{decimate, Butterworth};
pub use estimation::stats::{
    equal_runs, newey_west_lags, newey_west_run_covariance, newey_west_score_covariance,
    sandwich_uncertainty, student_t_quantile, uncertainty, NeweyWest, Uncertainty,
};
pub use excitation::equation_error::{
    electrical_equation, equation_error_start, equation_error_start_with_initial_states,
};
pub use excitation::initial_state::{
    detect_initial_state, detect_rest, DetectedInitialState, StartChannels,
};
pub use excitation::input_uncertainty::{
    estimate_level, quantisation_bias_variance, LevelEstimate, LevelPrior, StepInputs, VoltageScale,
};
pub use excitation::output_error::{predict_output_error, OutputError};
pub use excitation::voltage::{voltage_input, voltage_levels};
pub use servo::{
    replay_record, score, score_records, Friction, Loop, ReplayScore, ServoFit, ServoFitResult,
    ServoRecord, SERVO_NAMES, SERVO_UNITS, SMALL_SERVO_START,
};
pub use steps::full_model::{identify_full, identify_full_with_inputs};
pub use steps::model33::{fit_33, Fit33, Params33, Record33};
pub use steps::paper_method::{
    from_high_voltage, identify_paper, speed_check_c8, suggested_low_voltage_45,
    tau_m_as_printed_37, with_low_voltage, HighVoltageResult, PaperIdentification, SpeedCheck,
    SteadyValues, TwoTestFriction, C8_MAX_RATIO,
};
pub use steps::start::steady_state_start;
pub use steps::steady_fit::{fit_apparent_resistance, SteadyFit};
pub use steps::step_location::{locate_step, locate_step_with, StepLocation};
pub use voltage_speed::feedforward::{identify_feedforward, EXPLAINED_RATIO};
pub use voltage_speed::model::{
    FeedforwardFit, FeedforwardParams, FeedforwardSettings, MechanicalFromFeedforward, SpeedRecord,
    TauE, VoltageSpeedModel, FEEDFORWARD_NAMES, FEEDFORWARD_UNITS,
};
pub use voltage_speed::record_kind::{
    current_adc_steps, CurrentChannel, CurrentUnused, Drive, KindRefusal, KnownConstant,
    KnownConstants, MeasuredChannels, RecordKind, RecordSet, MIN_CURRENT_ADC_STEPS,
};
pub use voltage_speed::simulation::{simulate_feedforward, simulate_voltage_speed};

pub use estimation::accuracy::{
    accuracy, contains, median, relative_error, summarize, ParameterAccuracy, ParameterSummary,
};
pub use estimation::parameters::{parameter_estimates, ParameterEstimate};
pub use estimation::speed::{encoder_speed, record_speed, ENCODER_SPEED_BASE_S};
pub use steps::pipeline::{
    identify_step_pair, judge_clipping, steady_value, torque_constant, ClippingVerdict,
    PaperSkipped, RecordChannel, StepMethod, StepPairError, StepPairIdentification, StepRecord,
    StepRoute, TorqueConstantError, TorqueConstantSource, WholeRecord, MAX_CLIPPED_FRACTION,
    MAX_CLIPPED_VOLTAGE, POORLY_DETERMINED, STEADY_TAIL_PARTS,
};
