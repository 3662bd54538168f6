//! Command-line syntax. Only this module and `main` know clap.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// Identify the parameters of a DC servomotor and its load from step responses, simulate
/// it exactly, and find where a model and a measurement disagree.
#[derive(Debug, Parser)]
#[command(name = "motorid", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print a motor's derived constants, Eqs. (16)-(25): KE, Ks, wn, zeta, sigma, wa, ...
    Model(ModelArgs),
    /// Simulate a motor (exact analytic step or stick-slip ODE with effects) to a record CSV.
    Simulate(Box<SimulateArgs>),
    /// Identify R, L, k, f, J, Ts: from a high- and a low-voltage step record, from records of any
    /// voltage waveform (--record), a current-driven axis (--input current), Ts from steady tests,
    /// or a whole fleet (--batch).
    Identify(IdentifyArgs),
    /// Run the paper's example end to end and compare with its printed tables.
    Demo(DemoArgs),
    /// Monte Carlo check of the identification: errors and CI coverage over many noisy records.
    Montecarlo(MontecarloArgs),
    /// Write a fleet of simulated motors (folders with motor.json, high.csv, low.csv) for
    /// `identify --batch`.
    Fleet(FleetArgs),
    /// Serve the emulated data logger (the paper's PIC logger, on the simulated motor) on a
    /// pseudo-terminal: prints `PTY /dev/pts/N`, then serves until stopped.
    Emulate(EmulateArgs),
    /// Run a step test through the data logger on a serial port and write the record.
    Acquire(AcquireArgs),
    /// The EMPS benchmark (real data): identify the axis, then simulate it in closed loop on the
    /// record with unmodelled force pulses and report where the model disagrees.
    Emps(EmpsArgs),
    /// Replay servo logs with a model file (--model, from `identify --save-model`): closed loop
    /// from `goal` when the model has a controller, else open loop; position MAE and RMSE.
    Replay(ReplayArgs),
    /// Find where the identified model and the records disagree, which unmodelled effect causes
    /// it, how large it is, and how far the gap shrinks once it is in the model.
    Diagnose(DiagnoseArgs),
}

/// `--cutoff` of `--input current` when not given \[Hz\]: the inverse model's zero-phase
/// position filter.
pub const DEFAULT_CUTOFF_HZ: f64 = 100.0;
/// `--decimation` of `--input current` when not given.
pub const DEFAULT_DECIMATION: usize = 10;

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// High-voltage step record (CSV: t, voltage, current and speed or position).
    #[arg(long, value_name = "HV.csv", requires = "low")]
    pub high: Option<PathBuf>,
    /// Low-voltage step record.
    #[arg(long, value_name = "LV.csv", requires = "high")]
    pub low: Option<PathBuf>,
    /// Further training records of any voltage waveform (repeatable).
    #[arg(long = "record", value_name = "FILE.csv")]
    pub records: Vec<PathBuf>,
    /// Records held out whole to judge the candidates on, beside the blocks of the training
    /// records that are held out in any case (repeatable).
    #[arg(long = "validate", value_name = "FILE.csv")]
    pub validate: Vec<PathBuf>,
    /// Candidate effects, comma-separated (default: all seven: stribeck_friction,
    /// cogging_torque, current_sensor_lag, thermal_drift, quadratic_drag, brush_drop,
    /// inductance_saturation).
    #[arg(long, value_name = "NAME,...", value_delimiter = ',')]
    pub candidates: Vec<String>,
    /// Effects named at most, one on top of the other.
    #[arg(long, default_value_t = 2)]
    pub max_effects: usize,
    /// Header names of the record columns, as in `identify`.
    #[arg(long, value_name = "t=NAME,voltage=NAME,...")]
    pub columns: Option<String>,
    /// What drives the axis: voltage steps (the motor's six parameters and effects), or a
    /// drive with a current loop (--record files of current and position: the inverse model's
    /// torque residual is diagnosed, as `identify --input current`).
    #[arg(long, value_enum, default_value = "voltage")]
    pub input: DriveArg,
    /// With --input current: torque (force) per unit of the current column [N·m/A or N/A].
    #[arg(long, value_name = "K")]
    pub torque_constant: Option<f64>,
    /// With --input current: cut-off of the zero-phase position filter [Hz] (default 100).
    #[arg(long, value_name = "HZ")]
    pub cutoff: Option<f64>,
    /// With --input current: decimation factor of the parallel filtering (default 10).
    #[arg(long, value_name = "N")]
    pub decimation: Option<usize>,
    /// With --input current: rotary axis (rad) or linear axis (m) (default rotary).
    #[arg(long, value_enum)]
    pub axis: Option<AxisArg>,
    /// Write figures (SVG and PNG): the residual of each record and channel before and after
    /// the chosen effect.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// No progress on standard error.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct EmulateArgs {
    /// Serve on a new pseudo-terminal pair (the only transport so far).
    #[arg(long, required = true)]
    pub pty: bool,
    /// The motor on the logger.
    #[command(flatten)]
    pub motor: MotorArg,
    /// Unmodelled effect NAME:key=value,... (repeatable), as in `simulate`.
    #[arg(long = "effect", value_name = "NAME:KEY=VALUE,...")]
    pub effects: Vec<String>,
    /// Sample and send in real time (1 kHz, 115200 baud) instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Noise seed of the first test; test k uses SEED + k.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// ADC noise [LSB].
    #[arg(long, default_value_t = 1.0)]
    pub noise_lsb: f64,
    /// Faults on what the logger sends: ber=RATE,drop=RATE,close=BYTES,seed=N.
    #[arg(long, value_name = "KEY=VALUE,...")]
    pub faults: Option<String>,
    /// No messages on standard error.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct AcquireArgs {
    /// Serial port of the logger (e.g. /dev/ttyUSB0, or the PTY printed by `motorid emulate`).
    #[arg(long, value_name = "PATH")]
    pub port: String,
    /// Step voltage [V].
    #[arg(long, value_name = "VOLTS", allow_hyphen_values = true)]
    pub voltage: f64,
    /// Test length [s].
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub duration: f64,
    /// Sample rate [Hz].
    #[arg(long, value_name = "HZ", default_value_t = 1000)]
    pub rate: u16,
    /// Stream the samples live during the test (what is lost is dumped afterwards).
    #[arg(long)]
    pub live: bool,
    /// Calibration JSON: {"voltage": [V at 0 V, V at 5 V], "current": [A, A], "speed": [rad/s,
    /// rad/s], "counts_per_rev": N}; default: the emulator's.
    #[arg(long, value_name = "FILE.json")]
    pub calibration: Option<PathBuf>,
    /// Output record CSV (a file is replaced atomically, never left partial; a FIFO or device is
    /// written directly).
    #[arg(short = 'o', long = "output", value_name = "FILE.csv")]
    pub output: PathBuf,
    /// No progress on standard error.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct FleetArgs {
    /// Folder to write the motors into (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Number of motors.
    #[arg(long, default_value_t = 200)]
    pub motors: usize,
    /// Each parameter is the base motor's times a factor in [1/SPREAD, SPREAD] (log-uniform).
    #[arg(long, default_value_t = 1.5)]
    pub spread: f64,
    /// The base motor.
    #[command(flatten)]
    pub motor: MotorArg,
    /// High-voltage step [V].
    #[arg(long, default_value_t = 40.0, allow_hyphen_values = true)]
    pub high_voltage: f64,
    /// Low-voltage step [V].
    #[arg(long, default_value_t = 2.5, allow_hyphen_values = true)]
    pub low_voltage: f64,
    /// Seed of the parameter draws and of the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// No progress messages.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct EmpsArgs {
    /// Folder holding DATA_EMPS.csv and DATA_EMPS_PULSES.csv (default: shared/real-data/emps
    /// beside the repository, found from the working folder or from the source tree this
    /// binary was built in).
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Write the figure emps_pulses.svg (position error with and without the pulses in the
    /// model, above the pulse force) into this folder.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Accepted as on every command; this one writes nothing on standard error but errors.
    #[arg(long, short = 'q')]
    #[allow(dead_code)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct MontecarloArgs {
    #[command(flatten)]
    pub motor: MotorArg,
    /// Number of record pairs (high- and low-voltage step) to simulate and identify.
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// High-voltage step [V].
    #[arg(long, default_value_t = 40.0)]
    pub high_voltage: f64,
    /// Low-voltage step [V].
    #[arg(long, default_value_t = 2.5)]
    pub low_voltage: f64,
    /// Record length [s].
    #[arg(long, default_value_t = 50.0)]
    pub duration: f64,
    /// Sample rate [Hz].
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// ADC resolution [bits].
    #[arg(long, default_value_t = 10)]
    pub adc_bits: u8,
    /// Noise on the analog channels [LSB].
    #[arg(long, default_value_t = 1.0)]
    pub noise_lsb: f64,
    /// Encoder counts per revolution (speed from the encoder, as the paper did).
    #[arg(long, default_value_t = 2000)]
    pub encoder_cpr: u32,
    /// First noise seed; run i uses seeds derived from it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise on the voltage channel [LSB] (default: --noise-lsb).
    #[arg(long)]
    pub voltage_noise_lsb: Option<f64>,
    /// Put each step at a random instant within the sample period before its first sample
    /// (a real logger's step falls between samples), instead of on a sample.
    #[arg(long)]
    pub subsample_step: bool,
    /// Relative standard deviation of a random change of every motor parameter per run (runs
    /// differ even without noise), e.g. 0.02.
    #[arg(long, default_value_t = 0.0)]
    pub motor_spread: f64,
    /// Stretch every conditioning range by a random 0-5 % per record, so that a level's place
    /// between two ADC codes differs from run to run (required with --noise-lsb 0 or
    /// --voltage-noise-lsb 0: without noise the runs would otherwise share one quantisation
    /// error).
    #[arg(long)]
    pub vary_range: bool,
    /// Return each step to 0 V after --duration (at a random instant within a sample period
    /// with --subsample-step) and record as long again: each record ends at 0 V, on a voltage
    /// range whose lower rail is 0 V; the full method fits the rise and the fall.
    #[arg(long)]
    pub return_to_zero: bool,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// No progress on standard error (errors are still reported).
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// The paper's method: fit of Eq. (33), then Eqs. (34)-(51).
    Paper,
    /// All six parameters fitted jointly to both records with the exact model.
    Full,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DriveArg {
    /// The armature voltage is the input (the paper's step tests).
    Voltage,
    /// The drive controls the current: the torque is k times the current.
    Current,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AxisArg {
    /// Angles in rad.
    Rotary,
    /// Positions in m.
    Linear,
}

#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// High-voltage step record (CSV: t, voltage, current and speed or position).
    #[arg(long, value_name = "HV.csv", requires = "low")]
    pub high: Option<PathBuf>,
    /// Low-voltage step record, where Coulomb friction shows.
    #[arg(long, value_name = "LV.csv", requires = "high")]
    pub low: Option<PathBuf>,
    /// Identification method.
    #[arg(long, value_enum, default_value = "full")]
    pub method: MethodArg,
    /// Steady-state records at several voltages: fit the apparent-resistance law (8), Ts by (9).
    #[arg(long, value_name = "FILE.csv", num_args = 1.., conflicts_with_all = ["high", "low"])]
    pub steady: Vec<PathBuf>,
    /// Known armature resistance R [ohm]: for --steady (Sec. 2.2 assumes it known), or with
    /// --torque-constant for J, f, Ts from --record files of voltage and speed only.
    #[arg(long, value_name = "OHM")]
    pub resistance: Option<f64>,
    /// Torque constant k [N·m/A] (N/A for a linear axis): known k for --steady; with
    /// --resistance, J, f, Ts from --record files of voltage and speed only; for --input
    /// current, the torque (force) per unit of the current column (EMPS: 35.15 N per volt of vir).
    #[arg(long, value_name = "K")]
    pub torque_constant: Option<f64>,
    /// What drives the axis: voltage steps (all six parameters), or a drive with a current loop
    /// (J, f, Ts and a load offset from current and position, any motion, open or closed loop).
    #[arg(long, value_enum, default_value = "voltage")]
    pub input: DriveArg,
    /// Records of any voltage waveform (staircase, PRBS, sine, reversals; repeatable): all six
    /// parameters by simulating each record (output error); without a current column (voltage
    /// and an encoder or tachometer only), kS, kV, kA, and J, f, Ts given --resistance and
    /// --torque-constant. With --input current: records of a current-driven axis, pooled.
    #[arg(long, value_name = "FILE.csv", conflicts_with_all = ["high", "low", "steady"])]
    pub record: Vec<PathBuf>,
    /// Start of the --record fit: `paper` or FILE.json (default: estimated from the records by
    /// equation error).
    #[arg(long, value_name = "paper|FILE.json")]
    pub start: Option<String>,
    /// Write figures (SVG): measured and model for each channel of each record, residuals
    /// beneath; the apparent-resistance law for --steady.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// No progress messages or warnings on standard error (errors are still reported).
    #[arg(long, short = 'q')]
    pub quiet: bool,
    /// Identify every motor folder under DIR in parallel (high.csv + low.csv: step method;
    /// other *.csv: output error; motor.json, if present, is the truth to compare with) and
    /// write DIR/summary.csv and DIR/summary.json.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["high", "low", "steady", "record"])]
    pub batch: Option<PathBuf>,
    /// With --batch: a motor folder still fitting after this long is set aside as an error
    /// row of the summary, and the batch goes on [s; default 600].
    #[arg(
        long,
        value_name = "SECONDS",
        requires = "batch",
        allow_negative_numbers = true
    )]
    pub folder_limit: Option<f64>,
    /// Column names of a file from another tool: t=HEADER,current=HEADER,position=HEADER,...;
    /// a unit in brackets where the file's header has none (speed=speed_rpm[rpm], t=time[ms])
    #[arg(long, value_name = "NAME=HEADER,...")]
    pub columns: Option<String>,
    /// Rotary axis (rad: kg·m², N·m·s/rad, N·m) or linear axis (m: kg, N·s/m, N).
    #[arg(long, value_enum, default_value = "rotary")]
    pub axis: AxisArg,
    /// Cut-off of the zero-phase position filter for --input current [Hz].
    #[arg(long, value_name = "HZ", default_value_t = DEFAULT_CUTOFF_HZ)]
    pub cutoff: f64,
    /// Decimation factor of the parallel filtering for --input current.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_DECIMATION)]
    pub decimation: usize,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
    /// How each record's simulation starts (--record, and step records that do not start at
    /// rest): `auto` tells from the first samples; `rest`; `steady` (the steady state of the
    /// first voltage level, Eqs. (4), (5)); `free` (initial current and speed fitted: a slice
    /// of a longer run).
    #[arg(long, value_enum, default_value = "auto")]
    pub initial_state: InitialStateArg,
    #[command(flatten)]
    pub rig: RigArgs,
    /// Servo logs: fit on the recorded duty (open loop) instead of replaying the position loop
    /// from `goal` (closed loop, the default when the records have a controller and a goal).
    #[arg(long)]
    pub open_loop: bool,
    /// Servo logs: the gearbox's friction: Coulomb and viscous; with the load-dependent part
    /// (growing with the torque through the mesh); or with a Stribeck peak at rest too.
    #[arg(long, value_enum, default_value = "load-dependent")]
    pub friction: FrictionArg,
    /// Servo logs: held-out records, replayed with the identified model and scored (not fitted;
    /// repeatable).
    #[arg(long, value_name = "FILE.csv", requires = "record")]
    pub validate: Vec<PathBuf>,
    /// Servo logs: write the identified model (motor, gearing, loads, controller) as a model
    /// file for `replay --model` and `simulate --model`.
    #[arg(long, value_name = "M.json")]
    pub save_model: Option<PathBuf>,
}

/// The friction of a servo's gearbox.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FrictionArg {
    /// Coulomb and viscous.
    Coulomb,
    /// Coulomb, viscous and load-dependent.
    LoadDependent,
    /// Coulomb, viscous, load-dependent and a Stribeck peak at rest.
    Stribeck,
}

/// How a record's simulation starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InitialStateArg {
    /// Detected from the record's first samples.
    Auto,
    /// At rest: no current, no speed.
    Rest,
    /// In the steady state of the first voltage level.
    Steady,
    /// Initial current and speed fitted with the motor.
    Free,
}

/// Which motor: `paper` (the paper's Sec. 4.1 motor) or a JSON file with keys R, L, k, f, J,
/// Ts in SI units.
#[derive(Debug, Args)]
pub struct MotorArg {
    /// `paper` or FILE.json with {"R": ohm, "L": H, "k": N·m/A, "f": N·m·s/rad, "J": kg·m², "Ts": N·m}
    #[arg(long, default_value = "paper", value_name = "paper|FILE.json")]
    pub motor: String,
}

#[derive(Debug, Args)]
pub struct ModelArgs {
    #[command(flatten)]
    pub motor: MotorArg,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Accepted as on every command; this one writes nothing on standard error but errors.
    #[arg(long, short = 'q')]
    #[allow(dead_code)]
    pub quiet: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SolverArg {
    /// Exact closed-form step response (steps without effects only).
    Analytic,
    /// Stick-slip simulation (any waveform, effects): the nominal model under a step,
    /// staircase or PRBS propagated exactly, anything else integrated by RK4.
    Ode,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SpeedFromArg {
    /// Tachometer: the true speed through the analog channel (noise, ADC).
    Tacho,
    /// Central difference of the (quantised) encoder angle.
    Encoder,
    /// No speed column.
    None,
}

#[derive(Debug, Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub motor: MotorArg,
    /// Step voltage [V] (either sign).
    #[arg(long, value_name = "VOLTS", allow_hyphen_values = true)]
    pub voltage: Option<f64>,
    /// Sine input AMP,FREQ: amplitude [V] and frequency [Hz] (Appendix D: 0.1,0.05).
    #[arg(long, value_name = "AMP,FREQ", allow_hyphen_values = true)]
    pub sine: Option<String>,
    /// Staircase TIME:VOLTS,... : each level [V] holds from its time [s] (0 V before the first),
    /// e.g. 0.5:40,40.5:-20,80.5:0,100.5:2.5 (a reversal, a coast, a low-voltage breakaway).
    #[arg(long, value_name = "T:V,...", allow_hyphen_values = true)]
    pub levels: Option<String>,
    /// Pseudo-random binary sequence VOLTS,BIT[,SEED]: ±VOLTS, the sign drawn every BIT
    /// seconds, from --step-at on.
    #[arg(long, value_name = "VOLTS,BIT[,SEED]", allow_hyphen_values = true)]
    pub prbs: Option<String>,
    /// Instant of the step [s]; samples before it are pre-trigger samples at 0 V.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "S",
        allow_hyphen_values = true
    )]
    pub step_at: f64,
    /// Record length [s].
    #[arg(
        long,
        default_value_t = 50.0,
        value_name = "S",
        allow_hyphen_values = true
    )]
    pub duration: f64,
    /// Sample rate [Hz].
    #[arg(
        long,
        default_value_t = 1000.0,
        value_name = "HZ",
        allow_hyphen_values = true
    )]
    pub rate: f64,
    /// Solver: `analytic` for a nominal step, `ode` otherwise (default: analytic when it applies).
    #[arg(long, value_enum)]
    pub solver: Option<SolverArg>,
    /// Unmodelled effect NAME:key=value,... (repeatable), e.g. cogging_torque:amp=0.01,n=6.
    #[arg(long = "effect", value_name = "NAME:KEY=VALUE,...")]
    pub effects: Vec<String>,
    #[command(flatten)]
    pub measurement: MeasurementArgs,
    /// Output CSV (t[s],voltage[V],current[A],speed[rad/s],position[rad] after `#` metadata
    /// lines); `-` or absent: standard output.
    #[arg(short = 'o', long = "output", value_name = "FILE.csv")]
    pub output: Option<PathBuf>,
    /// No progress or summary on standard error (errors are still reported).
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// The measurement chain: how the logger sees the plant.
#[derive(Debug, Args)]
pub struct MeasurementArgs {
    /// ADC resolution [bits] for the analog channels (the paper's logger: 10); none = exact.
    #[arg(long, value_name = "BITS")]
    pub adc_bits: Option<u8>,
    /// Voltage channel range LO,HI [V] mapped onto the ADC (default: the signal ±20 %).
    #[arg(long, value_name = "LO,HI", allow_hyphen_values = true)]
    pub range_voltage: Option<String>,
    /// Current channel range LO,HI [A].
    #[arg(long, value_name = "LO,HI", allow_hyphen_values = true)]
    pub range_current: Option<String>,
    /// Tachometer channel range LO,HI [rad/s].
    #[arg(long, value_name = "LO,HI", allow_hyphen_values = true)]
    pub range_speed: Option<String>,
    /// White noise on every analog channel, standard deviation in ADC LSBs (needs --adc-bits).
    #[arg(long, value_name = "LSB", allow_hyphen_values = true)]
    pub noise_lsb: Option<f64>,
    /// Encoder counts per revolution after quadrature decoding; none = exact angle.
    #[arg(long, value_name = "COUNTS")]
    pub encoder_cpr: Option<u32>,
    /// Source of the speed column.
    #[arg(long, value_enum, default_value = "tacho")]
    pub speed_from: SpeedFromArg,
    /// Seed of the noise: the same seed gives the same record.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Also write the two simulated records (40 V and 2.5 V) into this folder.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Accepted as on every command; this one writes nothing on standard error but errors.
    #[arg(long, short = 'q')]
    #[allow(dead_code)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The model file (`identify --save-model`).
    #[arg(long, value_name = "M.json")]
    pub model: PathBuf,
    /// Servo logs to replay (repeatable).
    #[arg(long, value_name = "FILE.csv", required = true)]
    pub record: Vec<PathBuf>,
    #[command(flatten)]
    pub rig: RigArgs,
    /// Replay from the recorded duty or voltage (open loop) even where the model has a
    /// controller and the record a goal (a model identified with --open-loop replays so anyway).
    #[arg(long)]
    pub open_loop: bool,
    /// Write figures: logged and replayed position and their difference, per record.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// No progress messages or warnings on standard error.
    #[arg(long, short = 'q')]
    pub quiet: bool,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// The rig of servo logs, as `identify` and `replay` take it.
#[derive(Debug, Args)]
pub struct RigArgs {
    /// Servo logs: a known load on the output, not fitted (repeatable): pendulum:m=KG,l=M[,arm=KG]
    /// (q = 0 hanging down), inertia:j=KG_M2, spring:k=NM_PER_RAD[,q0=RAD], constant:t=NM. A
    /// record's own `# load:` lines win.
    #[arg(long, value_name = "KIND:KEY=VALUE,...")]
    pub load: Vec<String>,
    /// Servo logs: the servo's own position loop, p:kp=..,gain=..,max_duty=..,
    /// pd:kp=..,kd=..,gain=..,max_duty=.. or a preset (dynamixel-xl330:kp=N). A record's own
    /// `# controller:` line wins.
    #[arg(long, value_name = "KIND:KEY=VALUE,...")]
    pub controller: Option<String>,
    /// Servo logs: positions are on the output of an N:1 gearbox (the motor's own constants are
    /// reported beside the output's). A record's own `# gear:` line wins.
    #[arg(long, value_name = "N")]
    pub gear: Option<f64>,
}
