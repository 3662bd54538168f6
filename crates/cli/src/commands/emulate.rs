//! `motorid emulate --pty`: the emulated data logger served on a pseudo-terminal.

use std::io::{Read, Write};
use std::time::Duration;

use anyhow::{Context, Result};
use daq_emu::host::{Emulator, LineFaults, Plant};
use serialport::{SerialPort, TTYPort};

use crate::args::EmulateArgs;
use crate::console::outln;
use crate::errors::BadInput;
use crate::settings;

/// `ber=RATE,drop=RATE,close=BYTES,seed=N`.
fn faults(text: &str) -> Result<LineFaults> {
    let mut f = LineFaults::default();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (key, value) = item.split_once('=').ok_or_else(|| {
            BadInput(format!(
                "--faults: `{item}` is not KEY=VALUE (ber, drop, close, seed)"
            ))
        })?;
        let number = |v: &str| -> Result<f64> {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x >= 0.0)
                .ok_or_else(|| {
                    BadInput(format!("--faults {key}={v}: expected a number ≥ 0")).into()
                })
        };
        match key {
            "ber" => f.bit_error_rate = settings::probability("--faults ber", number(value)?)?,
            "drop" => f.drop_rate = settings::probability("--faults drop", number(value)?)?,
            "close" => f.close_after = Some(number(value)? as u64),
            "seed" => f.seed = number(value)? as u64,
            _ => {
                return Err(BadInput(format!(
                    "--faults: unknown key `{key}`; the keys are ber, drop, close, seed"
                ))
                .into())
            }
        }
    }
    Ok(f)
}

/// The emulated logger `motorid emulate` serves, validated from its arguments.
pub struct Settings {
    /// The simulated motor, its effects and the ADC noise.
    pub plant: Plant,
    /// Sample and send in real time instead of as fast as possible.
    pub realtime: bool,
    /// Faults on what the logger sends, if any.
    pub faults: Option<LineFaults>,
    /// No messages on standard error.
    pub quiet: bool,
}

impl Settings {
    /// The options of `a`, each checked: `--motor`, `--effect`, `--noise-lsb` ≥ 0, `--faults`.
    pub fn from_args(a: &EmulateArgs) -> Result<Settings> {
        let plant = Plant {
            motor: settings::motor(&a.motor.motor)?,
            effects: settings::effects(&a.effects)?,
            noise_lsb: a.noise_lsb,
            seed: a.seed,
            ..Plant::default()
        };
        if !(a.noise_lsb.is_finite() && a.noise_lsb >= 0.0) {
            return Err(BadInput(format!(
                "--noise-lsb {}: expected zero or more",
                a.noise_lsb
            ))
            .into());
        }
        Ok(Settings {
            plant,
            realtime: a.realtime,
            faults: a.faults.as_deref().map(faults).transpose()?,
            quiet: a.quiet,
        })
    }
}

/// Serves the emulated logger on a new pseudo-terminal until stopped (or the `close` fault).
pub fn run(a: &Settings) -> Result<()> {
    let mut emulator = Emulator::new(a.plant.clone(), a.realtime);
    if let Some(faults) = a.faults {
        emulator = emulator.with_faults(faults);
    }
    let (mut master, slave) = TTYPort::pair().context("cannot create a pseudo-terminal pair")?;
    let path = slave.name().context("the pseudo-terminal has no name")?;
    // Flushed at once ([`outln!`]): a client reads the name before connecting.
    outln!("PTY {path}")?;
    if !a.quiet {
        crate::console::errln!("emulated logger on {path} (115200 baud 8N1); Ctrl-C stops it");
    }
    // The slave stays open here, so that the master keeps working between clients.
    let _slave = slave;
    master.set_timeout(Duration::from_millis(5))?;
    let mut buf = [0u8; 4096];
    loop {
        match master.read(&mut buf) {
            Ok(n) => emulator.receive(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e).context("reading the pseudo-terminal"),
        }
        let out = emulator.run(Duration::from_millis(20));
        if let Some(error) = emulator.take_error() {
            if !a.quiet {
                crate::console::errln!("warning: the simulation refused the test: {error}");
            }
        }
        if !out.is_empty() {
            master
                .write_all(&out)
                .context("writing the pseudo-terminal")?;
        }
        if emulator.line_closed() {
            // The `close` fault: the port goes away, as when a cable is pulled.
            if !a.quiet {
                crate::console::errln!("the line is closed (--faults close): stopping");
            }
            return Ok(());
        }
    }
}
