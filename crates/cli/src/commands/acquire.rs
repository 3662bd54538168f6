//! `motorid acquire`: a step test through the data logger on a serial port, to a record file.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use anyhow::Result;
use daq_emu::host::Calibration;

use crate::args::AcquireArgs;
use crate::daq_client::{acquire, to_record, AcquireError, Link, Stats, TestPlan};
use crate::record_csv::write_file;
use crate::BadInput;

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
    let text = std::fs::read_to_string(path)
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

pub fn run(a: &AcquireArgs) -> Result<()> {
    if !(a.duration.is_finite() && a.duration > 0.0) {
        return Err(BadInput(format!(
            "--duration {}: expected a positive length [s]",
            a.duration
        ))
        .into());
    }
    if a.rate == 0 || a.rate > daq_emu::MAX_RATE_HZ {
        return Err(BadInput(format!(
            "--rate {}: expected 1 to {} Hz",
            a.rate,
            daq_emu::MAX_RATE_HZ
        ))
        .into());
    }
    if !a.voltage.is_finite() {
        return Err(BadInput(format!("--voltage {}: expected a number [V]", a.voltage)).into());
    }
    let cal = calibration(a)?;
    let port = serialport::new(&a.port, daq_protocol::BAUD)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| BadInput(format!("--port {}: cannot open ({e})", a.port)))?;
    let mut link = SerialLink(port);
    let plan = TestPlan {
        volts: a.voltage,
        duration_s: a.duration,
        rate_hz: a.rate,
        live: a.live,
    };
    let started = Instant::now();
    let mut last_shown = Instant::now();
    let show = |stats: &Stats| {
        let elapsed = started.elapsed().as_secs_f64();
        let done = stats.samples as f64 / stats.expected.max(1) as f64;
        let eta = if done > 0.0 {
            elapsed / done - elapsed
        } else {
            f64::NAN
        };
        eprint!(
            "\r  {} / {} samples, {} bytes, {} frames ({} bad, {} lost), {} retries, ETA {:.0} s   ",
            stats.samples, stats.expected, stats.bytes, stats.frames, stats.bad_frames, stats.lost_frames, stats.retries, eta.max(0.0)
        );
    };
    let result = acquire(&mut link, &plan, |stats| {
        if !a.quiet && last_shown.elapsed() > Duration::from_millis(200) {
            show(stats);
            last_shown = Instant::now();
        }
    });
    let acquired = match result {
        Ok(acq) => acq,
        Err(e) => {
            if !a.quiet {
                eprintln!();
            }
            return Err(match e {
                AcquireError::Refused(_) => BadInput(format!("{}: {e}", a.port)).into(),
                _ => anyhow::anyhow!("{}: {e}", a.port),
            });
        }
    };
    if !a.quiet {
        show(&acquired.stats);
        eprintln!();
    }
    let record = to_record(&acquired, &cal);
    let meta = vec![
        ("source".to_string(), "motorid acquire".to_string()),
        ("port".to_string(), a.port.clone()),
        ("input".to_string(), format!("step {} V at 0 s", a.voltage)),
        ("calibration".to_string(), serde_json::to_string(&cal)?),
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
    eprintln!(
        "wrote {} samples ({} s at {} Hz) to {}; {} bytes, {} frames, {} failed their check, {} lost, {} retries",
        record.t.len(),
        a.duration,
        a.rate,
        a.output.display(),
        s.bytes,
        s.frames,
        s.bad_frames,
        s.lost_frames,
        s.retries
    );
    Ok(())
}
