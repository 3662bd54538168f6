//! `motorid acquire`: a step test through the data logger on a serial port, to a record file.

use std::io::{IsTerminal, Read, Write};
use std::time::{Duration, Instant};

use anyhow::Result;
use daq_protocol::host::{
    acquire, to_record, AcquireError, Calibration, Link, Phase, Stats, TestPlan,
};

use crate::args::AcquireArgs;
use crate::errors::BadInput;
use crate::record_csv::write_file;
use crate::settings;

/// A serial port as a [`Link`].
struct SerialLink(Box<dyn serialport::SerialPort>);

impl Link for SerialLink {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.0.write_all(bytes)?;
        self.0.flush()
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.0.set_timeout(timeout.max(Duration::from_millis(1)))?;
        match self.0.read(buf) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            Err(e) => Err(e),
        }
    }
}

fn calibration(a: &AcquireArgs) -> Result<Calibration> {
    let Some(path) = &a.calibration else {
        return Ok(Calibration::default());
    };
    let text = crate::settings::read_settings_file(path)
        .map_err(|e| BadInput(format!("{}: cannot read ({e})", path.display())))?;
    let cal: Calibration = serde_json::from_str(&text).map_err(|e| {
        BadInput(format!(
            "{}: line {}, column {}: {e}; expected {{\"voltage\": [lo, hi], \"current\": [lo, hi], \"speed\": [lo, hi], \"counts_per_rev\": N}}",
            path.display(),
            e.line(),
            e.column()
        ))
    })?;
    cal.ranges()
        .map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    if cal.counts_per_rev == 0 {
        return Err(BadInput(format!(
            "{}: counts_per_rev must be positive",
            path.display()
        ))
        .into());
    }
    Ok(cal)
}

/// Why `path` cannot be the logger's serial port, if it exists but is not a terminal device
/// (a serial port is one; `/dev/null` or a regular file is not). A path that does not exist
/// is left for the open to report.
#[cfg(unix)]
fn not_a_serial_port(path: &str) -> Option<&'static str> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let meta = std::fs::metadata(path).ok()?;
    if !meta.file_type().is_char_device() {
        return Some(if meta.is_dir() {
            "a folder"
        } else {
            "a file, not a device"
        });
    }
    // Non-blocking and without becoming the controlling terminal: only to ask what it is.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .ok()?;
    // SAFETY: isatty only inspects the descriptor, which `file` keeps open for the call.
    let terminal = unsafe { libc::isatty(file.as_raw_fd()) } == 1;
    (!terminal).then_some("a device that is not a terminal")
}

#[cfg(not(unix))]
fn not_a_serial_port(_path: &str) -> Option<&'static str> {
    None
}

/// Progress of an acquisition on standard error, with an honest time left: during the test
/// its remaining length; during the dump the samples still missing at the throughput
/// measured since its first samples arrived (once a few more blocks have).
struct Progress {
    started: Instant,
    test_s: f64,
    test_started: Option<Instant>,
    /// Samples held when the dump began.
    dump_from: Option<u64>,
    /// When the dump's first samples arrived, and how many were held then: the throughput is
    /// measured from there, without the latency of the request.
    dump_started: Option<(Instant, u64)>,
    last_shown: Option<Instant>,
    terminal: bool,
}

/// Samples to receive in the dump before its throughput is trusted for a time left (two
/// 128-sample blocks).
const THROUGHPUT_SAMPLES: u64 = 256;

impl Progress {
    fn new(test_s: f64) -> Self {
        Progress {
            started: Instant::now(),
            test_s,
            test_started: None,
            dump_from: None,
            dump_started: None,
            last_shown: None,
            terminal: std::io::stderr().is_terminal(),
        }
    }

    /// Notes when the test and the dump began.
    fn note(&mut self, stats: &Stats) {
        let now = Instant::now();
        match stats.phase {
            Phase::Setup => {}
            Phase::Test => {
                self.test_started.get_or_insert(now);
            }
            Phase::Dump => {
                let from = *self.dump_from.get_or_insert(stats.samples);
                if stats.samples > from {
                    self.dump_started.get_or_insert((now, stats.samples));
                }
            }
        }
    }

    /// What is left, in words.
    fn time_left(&self, stats: &Stats) -> String {
        match (stats.phase, self.test_started, self.dump_started) {
            (Phase::Test, Some(since), _) => {
                let left = (self.test_s - since.elapsed().as_secs_f64()).max(0.0);
                format!("test running, {left:.0} s left")
            }
            (Phase::Dump, _, Some((since, at))) => {
                let got = stats.samples.saturating_sub(at);
                let seconds = since.elapsed().as_secs_f64();
                if got < THROUGHPUT_SAMPLES || seconds <= 0.0 {
                    return "dump: measuring the throughput".into();
                }
                let rate = got as f64 / seconds;
                let left = stats.expected.saturating_sub(stats.samples) as f64 / rate;
                format!("dump at {rate:.0} samples/s, ETA {left:.1} s")
            }
            (Phase::Dump, _, None) if stats.samples >= stats.expected => "complete".into(),
            (Phase::Dump, _, None) => "dump: waiting for the first samples".into(),
            _ => "starting".into(),
        }
    }

    /// Shows `stats`: on a terminal one line rewritten every 0.2 s, otherwise a line a second.
    fn show(&mut self, stats: &Stats, always: bool) {
        self.note(stats);
        let every = Duration::from_millis(if self.terminal { 200 } else { 1000 });
        if !always && self.last_shown.is_some_and(|t| t.elapsed() < every) {
            return;
        }
        self.last_shown = Some(Instant::now());
        let left = self.time_left(stats);
        let line = format!(
            "  {} / {} samples, {} bytes, {} frames ({} bad, {} lost), {} retries; {left} ({:.1} s)",
            stats.samples,
            stats.expected,
            stats.bytes,
            stats.frames,
            stats.bad_frames,
            stats.lost_frames,
            stats.retries,
            self.started.elapsed().as_secs_f64()
        );
        if self.terminal {
            crate::console::errprint!("\r{line}   ");
        } else {
            crate::console::errln!("{line}");
        }
    }

    /// Ends a rewritten line.
    fn finish(&self) {
        if self.terminal {
            crate::console::errln!();
        }
    }
}

/// The test `motorid acquire` runs, validated from its arguments.
pub struct Settings {
    /// Serial port of the logger.
    pub port: String,
    /// The step test: voltage \[V\], length \[s\], rate \[Hz\], live streaming.
    pub plan: TestPlan,
    /// Counts to SI units, from `--calibration` or the emulator's default.
    pub calibration: Calibration,
    /// The output record.
    pub output: std::path::PathBuf,
    /// No progress on standard error.
    pub quiet: bool,
}

impl Settings {
    /// The options of `a`, each checked: `--duration` > 0, `--rate` within the logger's,
    /// `--voltage` sane and within the calibrated range, the plan's length, and `--port` a
    /// terminal device where it exists.
    pub fn from_args(a: &AcquireArgs) -> Result<Settings> {
        if !(a.duration.is_finite() && a.duration > 0.0) {
            return Err(BadInput(format!(
                "--duration {}: expected a positive length [s]",
                settings::shown(a.duration)
            ))
            .into());
        }
        if a.rate == 0 || a.rate > daq_protocol::MAX_RATE_HZ {
            return Err(BadInput(format!(
                "--rate {}: expected 1 to {} Hz",
                a.rate,
                daq_protocol::MAX_RATE_HZ
            ))
            .into());
        }
        let volts = settings::volts("--voltage", a.voltage)?;
        let cal = calibration(a)?;
        // The voltage channel is calibrated over [lo, hi]: a step beyond it would clip, and the
        // logger would apply a voltage nobody checked.
        let [lo, hi] = cal.voltage;
        if !(lo..=hi).contains(&volts) {
            return Err(BadInput(format!(
                "--voltage {}: outside the logger's calibrated voltage range {lo} to {hi} V ({}); give a step within it",
                settings::shown(volts),
                match &a.calibration {
                    Some(path) => format!("from {}", path.display()),
                    None => "the emulator's default calibration; see --calibration".into(),
                }
            ))
            .into());
        }
        let plan = TestPlan {
            volts,
            duration_s: a.duration,
            rate_hz: a.rate,
            live: a.live,
        };
        plan.check()
            .map_err(|e| BadInput(format!("--duration: {e}")))?;
        if let Some(what) = not_a_serial_port(&a.port) {
            return Err(BadInput(format!(
                "--port {}: not a serial port ({what}); give the logger's port, e.g. /dev/ttyUSB0, or the PTY path `motorid emulate --pty` prints",
                a.port
            ))
            .into());
        }
        Ok(Settings {
            port: a.port.clone(),
            plan,
            calibration: cal,
            output: a.output.clone(),
            quiet: a.quiet,
        })
    }
}

/// Runs the test through the logger and writes the record.
pub fn run(a: &Settings) -> Result<()> {
    let (plan, cal) = (&a.plan, &a.calibration);
    let volts = plan.volts;
    let port = serialport::new(&a.port, daq_protocol::BAUD)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| BadInput(format!("--port {}: cannot open ({e})", a.port)))?;
    let mut link = SerialLink(port);
    let mut progress = Progress::new(plan.duration_s);
    let result = acquire(&mut link, plan, |stats| {
        if !a.quiet {
            progress.show(stats, false);
        }
    });
    let acquired = match result {
        Ok(acq) => acq,
        Err(e) => {
            if !a.quiet {
                progress.finish();
            }
            return Err(match e {
                AcquireError::Refused(_) => BadInput(format!("{}: {e}", a.port)).into(),
                _ => anyhow::anyhow!("{}: {e}", a.port),
            });
        }
    };
    if !a.quiet {
        progress.show(&acquired.stats, true);
        progress.finish();
    }
    let record = to_record(&acquired, cal);
    let meta = vec![
        ("source".to_string(), "motorid acquire".to_string()),
        ("port".to_string(), a.port.clone()),
        ("input".to_string(), format!("step {volts} V at 0 s")),
        ("calibration".to_string(), serde_json::to_string(cal)?),
        (
            "range_voltage".to_string(),
            format!("{},{}", cal.voltage[0], cal.voltage[1]),
        ),
        (
            "range_current".to_string(),
            format!("{},{}", cal.current[0], cal.current[1]),
        ),
    ];
    write_file(&a.output, &record, &meta)?;
    let s = &acquired.stats;
    crate::console::errln!(
        "wrote {} samples ({} s at {} Hz) to {}; {} bytes, {} frames, {} failed their check, {} lost, {} retries",
        record.t.len(),
        plan.duration_s,
        plan.rate_hz,
        a.output.display(),
        s.bytes,
        s.frames,
        s.bad_frames,
        s.lost_frames,
        s.retries
    );
    Ok(())
}
