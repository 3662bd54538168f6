//! The PC side of the logger protocol (feature `host`, with `std`): runs a step test through a
//! [`Link`] and collects every sample, re-requesting what the line lost, and turns the samples
//! into a record of SPEC section 4 through the conditioning's [`Calibration`]. It never returns
//! a sample from a frame that failed its check. A program talking to real hardware depends on
//! this module only (the emulator, `daq-emu`, is the other end of the line).

use std::io;
use std::string::String;
use std::time::{Duration, Instant};
use std::vec::Vec;
use std::{format, vec};

use motor_model::{
    central_difference, Adc as AdcModel, MeasurementModel, ModelError, Range, Record,
};
use serde::{Deserialize, Serialize};

use crate::{
    encode, Command, Decoder, ErrorCode, Frame, Mode, Reply, Sample, State, ALL_CHANNELS,
    FLASH_BYTES, MAX_FRAME, SAMPLE_BYTES,
};

/// How the logger's readings map to SI units: the physical value at 0 V and at 5 V of each
/// conditioned analog channel (ADC codes 0 and 1023), and the encoder's counts per revolution.
/// The file format of `motorid acquire --calibration FILE.json`:
/// `{"voltage": [-50, 50], "current": [-200, 200], "speed": [-250, 250], "counts_per_rev": 2000}`
/// (V, A, rad/s; the defaults, which the emulator uses).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Armature voltage at 0 V and 5 V \[V\].
    pub voltage: [f64; 2],
    /// Armature current at 0 V and 5 V \[A\].
    pub current: [f64; 2],
    /// Tachometer speed at 0 V and 5 V \[rad/s\].
    pub speed: [f64; 2],
    /// Encoder counts per revolution (after quadrature decoding).
    pub counts_per_rev: u32,
}

impl Default for Calibration {
    fn default() -> Self {
        Calibration {
            voltage: [-50.0, 50.0],
            current: [-200.0, 200.0],
            speed: [-250.0, 250.0],
            counts_per_rev: 2000,
        }
    }
}

impl Calibration {
    /// The three analog ranges, validated.
    pub fn ranges(&self) -> Result<[Range; 3], ModelError> {
        Ok([
            Range::new(self.voltage[0], self.voltage[1])?,
            Range::new(self.current[0], self.current[1])?,
            Range::new(self.speed[0], self.speed[1])?,
        ])
    }

    /// The value \[SI\] of ADC `code` on `channel` (0 voltage, 1 current, 2 speed).
    pub fn analog(&self, channel: usize, code: u16) -> f64 {
        let r = [self.voltage, self.current, self.speed][channel.min(2)];
        AdcModel { bits: 10 }.to_value(Range { lo: r[0], hi: r[1] }, u32::from(code))
    }

    /// The angle \[rad\] of an unwrapped encoder count.
    pub fn angle(&self, count: i64) -> f64 {
        count as f64 * (std::f64::consts::TAU / f64::from(self.counts_per_rev))
    }

    /// The measurement chain of this calibration with `noise_lsb` of ADC noise and `seed`: the
    /// settings under which `motorid simulate` gives the logger's records.
    pub fn measurement(&self, noise_lsb: f64, seed: u64) -> Result<MeasurementModel, ModelError> {
        Ok(MeasurementModel::logger(
            10,
            self.ranges()?,
            noise_lsb,
            self.counts_per_rev,
            seed,
        ))
    }
}

/// A byte link to the logger.
pub trait Link {
    /// Sends `bytes`.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Receives what arrives within `timeout` into `buf`; `Ok(0)` when nothing did.
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
}

/// What to acquire.
#[derive(Debug, Clone, Copy)]
pub struct TestPlan {
    /// Step voltage \[V\].
    pub volts: f64,
    /// Test length \[s\].
    pub duration_s: f64,
    /// Sample rate \[Hz\].
    pub rate_hz: u16,
    /// Stream blocks live during the test (the rest, if any is lost, is dumped after).
    pub live: bool,
}

impl TestPlan {
    /// Samples the logger takes: `rate × duration_ms / 1000 + 1`, as the firmware counts them.
    pub fn samples(&self) -> u64 {
        u64::from(self.rate_hz) * self.duration_ms() / 1000 + 1
    }

    fn duration_ms(&self) -> u64 {
        (self.duration_s * 1000.0).round() as u64
    }

    /// Refuses a test the logger cannot store: more samples than its flash holds
    /// ([`FLASH_SAMPLES`]), before anything is sent or allocated.
    pub fn check(&self) -> Result<(), AcquireError> {
        let samples = self.samples();
        if samples > FLASH_SAMPLES || self.duration_ms() > u64::from(u32::MAX) {
            return Err(AcquireError::Refused(format!(
                "{} s at {} Hz is {samples} samples; the logger's 16 Mbit flash holds at most {FLASH_SAMPLES} ({} bytes a sample): shorten the test or lower the rate",
                duration_text(self.duration_s),
                self.rate_hz,
                SAMPLE_BYTES
            )));
        }
        Ok(())
    }
}

/// Samples the logger's flash holds: 16 Mbit at [`SAMPLE_BYTES`] a sample.
pub const FLASH_SAMPLES: u64 = (FLASH_BYTES / SAMPLE_BYTES) as u64;

/// Where an acquisition stands, for progress.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Phase {
    /// Talking to the logger before the test (status, stop, configure, arm).
    #[default]
    Setup,
    /// The step test runs on the logger (live blocks may arrive).
    Test,
    /// The test is over; the samples not yet received are being dumped.
    Dump,
}

/// Counters for progress and for the report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Where the acquisition stands.
    pub phase: Phase,
    /// Bytes received.
    pub bytes: u64,
    /// Frames received intact.
    pub frames: u64,
    /// Frames dropped by the decoder (bad CRC, stuffing, shape).
    pub bad_frames: u64,
    /// Frames missing according to the sequence numbers.
    pub lost_frames: u64,
    /// Commands sent again (timeouts) and dumps re-requested.
    pub retries: u64,
    /// Samples received so far, and expected.
    pub samples: u64,
    /// Samples the test takes.
    pub expected: u64,
}

/// Why an acquisition failed; nothing is written then.
#[derive(Debug)]
pub enum AcquireError {
    /// The line failed (port closed, I/O error).
    Io(io::Error),
    /// The logger stopped answering.
    Silent(String),
    /// The logger refused a command.
    Refused(String),
    /// Samples could not be recovered.
    Lost(String),
}

impl std::fmt::Display for AcquireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AcquireError::Io(e) => write!(f, "the serial line failed: {e}"),
            AcquireError::Silent(s) | AcquireError::Refused(s) | AcquireError::Lost(s) => {
                f.write_str(s)
            }
        }
    }
}

impl std::error::Error for AcquireError {}

/// Time allowed for a reply to a command.
const REPLY_TIMEOUT: Duration = Duration::from_millis(400);
/// Attempts at a command.
const ATTEMPTS: u32 = 8;
/// Dump rounds in a row that recover nothing before the missing samples are given up. At a
/// bit-error rate of 1e-3 a full block arrives intact with probability 0.23, so one missing
/// block survives 30 rounds with probability 0.77³⁰ ≈ 4e-4; a dead line ends the rounds at
/// once (its commands go unanswered).
const STALLED_ROUNDS: u32 = 30;

/// An owned copy of a decoded reply (the decoder's frames borrow its buffer).
#[derive(Debug, Clone)]
enum Got {
    Status { state: State, stored: u32 },
    Samples { first: u32, samples: Vec<Sample> },
    End { total: u32 },
    Error { code: ErrorCode, command: u8 },
    Ack { command: u8 },
}

struct Session<'l, L: Link> {
    link: &'l mut L,
    decoder: Decoder<MAX_FRAME>,
    seq: u8,
    last_reply_seq: Option<u8>,
    stats: Stats,
    inbox: std::collections::VecDeque<Got>,
    /// When a byte last arrived (or the session began).
    last_heard: Instant,
}

impl<L: Link> Session<'_, L> {
    fn send(&mut self, command: Command) -> Result<(), AcquireError> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(
            &Frame::Command {
                seq: self.seq,
                command,
            },
            &mut buf,
        )
        .map_err(|e| AcquireError::Refused(format!("cannot encode {command:?}: {e:?}")))?;
        self.seq = self.seq.wrapping_add(1);
        // A leading 00 ends any garbage the logger holds, so this frame starts clean.
        let mut out = Vec::with_capacity(n + 1);
        out.push(0);
        out.extend_from_slice(&buf[..n]);
        self.link.send(&out).map_err(AcquireError::Io)
    }

    /// Reads from the line for up to `timeout`, queueing whole replies; returns whether any
    /// arrived.
    fn pump(&mut self, timeout: Duration) -> Result<bool, AcquireError> {
        let mut buf = [0u8; 4096];
        let n = self
            .link
            .recv(&mut buf, timeout)
            .map_err(AcquireError::Io)?;
        self.stats.bytes += n as u64;
        if n > 0 {
            self.last_heard = Instant::now();
        }
        let before = self.inbox.len();
        for &b in &buf[..n] {
            match self.decoder.feed(b) {
                None => {}
                // A frame that failed its check, or a command (nothing the logger sends).
                Some(Err(_)) | Some(Ok(Frame::Command { .. })) => self.stats.bad_frames += 1,
                Some(Ok(Frame::Reply { seq, reply })) => {
                    self.stats.frames += 1;
                    if let Some(last) = self.last_reply_seq {
                        let gap = seq.wrapping_sub(last).wrapping_sub(1);
                        if gap < 128 {
                            self.stats.lost_frames += u64::from(gap);
                        }
                    }
                    self.last_reply_seq = Some(seq);
                    let got = match reply {
                        Reply::Status { state, stored, .. } => Got::Status { state, stored },
                        Reply::Samples { first, count, .. } => Got::Samples {
                            first,
                            samples: (0..usize::from(count))
                                .filter_map(|i| reply.sample(i))
                                .collect(),
                        },
                        Reply::End { total } => Got::End { total },
                        Reply::Error { code, command } => Got::Error { code, command },
                        Reply::Ack { command, .. } => Got::Ack { command },
                    };
                    self.inbox.push_back(got);
                }
            }
        }
        Ok(self.inbox.len() > before)
    }

    /// [`Session::pump`] for up to 50 ms, then every queued reply taken from the inbox: the
    /// sample blocks stored into `samples`, the others returned in order, with whether any
    /// reply arrived.
    fn pump_samples(
        &mut self,
        samples: &mut [Option<Sample>],
    ) -> Result<(bool, Vec<Got>), AcquireError> {
        let heard = self.pump(Duration::from_millis(50))?;
        let mut others = Vec::new();
        while let Some(got) = self.inbox.pop_front() {
            match got {
                Got::Samples {
                    first,
                    samples: block,
                } => store(samples, &mut self.stats, first, &block),
                other => others.push(other),
            }
        }
        Ok((heard, others))
    }

    /// Sends `command` until `accept` takes a reply (other replies are kept in the inbox for
    /// later), retrying on timeouts.
    fn request<T>(
        &mut self,
        command: Command,
        mut accept: impl FnMut(&Got) -> Option<Result<T, AcquireError>>,
    ) -> Result<T, AcquireError> {
        for attempt in 0..ATTEMPTS {
            if attempt > 0 {
                self.stats.retries += 1;
            }
            self.send(command)?;
            let deadline = Instant::now() + REPLY_TIMEOUT;
            while Instant::now() < deadline {
                self.pump(Duration::from_millis(20))?;
                let mut keep = std::collections::VecDeque::new();
                let mut result = None;
                while let Some(got) = self.inbox.pop_front() {
                    if result.is_none() {
                        if let Some(r) = accept(&got) {
                            result = Some(r);
                            continue;
                        }
                    }
                    keep.push_back(got);
                }
                self.inbox = keep;
                if let Some(r) = result {
                    return r;
                }
            }
        }
        Err(AcquireError::Silent(format!(
            "the logger timed out: no reply to {command:?} after {ATTEMPTS} attempts of {} ms, nothing heard for {:.1} s ({} bytes, {} frames received)",
            REPLY_TIMEOUT.as_millis(),
            self.last_heard.elapsed().as_secs_f64(),
            self.stats.bytes,
            self.stats.frames
        )))
    }
}

/// The samples not received: how many, and the first.
fn missing(samples: &[Option<Sample>]) -> (usize, usize) {
    let count = samples.iter().filter(|x| x.is_none()).count();
    (count, samples.iter().position(Option::is_none).unwrap_or(0))
}

/// The samples of a test and the counters of the transfer.
#[derive(Debug, Clone)]
pub struct Acquired {
    /// Every sample of the test, in order.
    pub samples: Vec<Sample>,
    /// Sample rate \[Hz\].
    pub rate_hz: u16,
    /// Transfer counters.
    pub stats: Stats,
}

/// The logger's refusal of `what`.
fn refused<T>(what: &str, code: ErrorCode) -> Result<T, AcquireError> {
    let why = match code {
        ErrorCode::Busy => "busy with another test or dump (stop it, or wait)",
        ErrorCode::BadSetting => {
            "a setting is out of range (rate 1–10,000 Hz, a non-zero duration of at least 1 ms)"
        }
        ErrorCode::FlashFull => {
            "the record does not fit in the 16 Mbit flash (6 bytes a sample: at most 349,525 samples; shorten the test or lower the rate)"
        }
        ErrorCode::OutOfRange => "it asked for samples past the end of the record",
        ErrorCode::BadFrame => "the command arrived damaged",
    };
    Err(AcquireError::Refused(format!(
        "the logger refused {what}: {why}"
    )))
}

/// Stores a block of samples from index `first`.
fn store(samples: &mut [Option<Sample>], stats: &mut Stats, first: u32, block: &[Sample]) {
    for (k, sample) in block.iter().enumerate() {
        if let Some(slot) = samples.get_mut(first as usize + k) {
            if slot.is_none() {
                stats.samples += 1;
            }
            *slot = Some(*sample);
        }
    }
}

/// Waits for the end of the running test (storing live blocks), then dumps what is missing.
fn collect<L: Link>(
    s: &mut Session<'_, L>,
    plan: &TestPlan,
    samples: &mut [Option<Sample>],
    progress: &mut impl FnMut(&Stats),
) -> Result<(), AcquireError> {
    let expected = samples.len() as u64;
    // The test runs: live blocks arrive, or nothing until the end. Wait for the End, asking
    // for the status now and then (progress, and in case the End is lost).
    let test_time = Duration::from_secs_f64(plan.duration_s.max(0.0));
    let started = Instant::now();
    let mut last_status = Instant::now();
    let mut finished = false;
    let mut silent_since = Instant::now();
    s.stats.phase = Phase::Test;
    while !finished {
        let (heard, others) = s.pump_samples(samples)?;
        if heard {
            silent_since = Instant::now();
        }
        for got in others {
            match got {
                Got::End { total } => {
                    if u64::from(total) != expected {
                        return Err(AcquireError::Lost(format!(
                            "the logger ended the test after {total} of {expected} samples (stopped?) — nothing written"
                        )));
                    }
                    finished = true;
                }
                Got::Status { state, stored }
                    if state == State::Idle && u64::from(stored) == expected =>
                {
                    finished = true;
                }
                _ => {}
            }
        }
        progress(&s.stats);
        if !finished && last_status.elapsed() > Duration::from_millis(500) {
            s.send(Command::Status)?;
            last_status = Instant::now();
        }
        if silent_since.elapsed()
            > Duration::from_secs(5) + test_time.saturating_sub(started.elapsed())
        {
            return Err(AcquireError::Silent(format!(
                "the logger timed out during the test: no reply for {:.1} s ({} of {expected} samples received, {} bytes) — nothing written",
                silent_since.elapsed().as_secs_f64(),
                s.stats.samples,
                s.stats.bytes
            )));
        }
    }
    // Dump what is missing (everything in record mode), from the first missing sample to the
    // last, until nothing is; give up after rounds that recover nothing.
    s.stats.phase = Phase::Dump;
    let mut stalled = 0;
    let mut round = 0u64;
    while stalled < STALLED_ROUNDS {
        let Some(from) = samples.iter().position(Option::is_none) else {
            break;
        };
        let last = samples.iter().rposition(Option::is_none).unwrap_or(from);
        if round > 0 {
            s.stats.retries += 1;
        }
        round += 1;
        let before = s.stats.samples;
        let count = if last + 1 == samples.len() {
            0
        } else {
            (last + 1 - from) as u32
        };
        let acked = s.request(
            Command::Dump {
                from: from as u32,
                count,
            },
            |g| match g {
                Got::Ack { command } if *command == crate::kind::DUMP => Some(Ok(())),
                Got::Error { code, command } if *command == crate::kind::DUMP => {
                    Some(refused("the dump", *code))
                }
                _ => None,
            },
        );
        match acked {
            Ok(()) => {}
            // A logger that stopped answering: say so, rather than that samples were lost.
            Err(AcquireError::Silent(why)) => {
                let (count, first) = missing(samples);
                return Err(AcquireError::Silent(format!(
                    "{why}; {count} of {expected} samples not received (first missing: sample {first}) — nothing written"
                )));
            }
            Err(e) => return Err(e),
        }
        let mut silent_since = Instant::now();
        loop {
            let (heard, others) = s.pump_samples(samples)?;
            if heard {
                silent_since = Instant::now();
            }
            let ended = others.iter().any(|got| matches!(got, Got::End { .. }));
            progress(&s.stats);
            // The round is over at its End, or when every sample asked for is here (the End
            // may be the frame that was lost), or after 2 s of silence.
            let complete = samples[from..=last].iter().all(Option::is_some);
            if ended || complete || silent_since.elapsed() > Duration::from_secs(2) {
                break;
            }
        }
        if s.stats.samples == before {
            stalled += 1;
        } else {
            stalled = 0;
        }
    }
    Ok(())
}

/// Runs `plan` on the logger behind `link`; `progress` is called as data arrives.
pub fn acquire<L: Link>(
    link: &mut L,
    plan: &TestPlan,
    mut progress: impl FnMut(&Stats),
) -> Result<Acquired, AcquireError> {
    plan.check()?;
    let expected = plan.samples();
    let mut s = Session {
        link,
        decoder: Decoder::new(),
        seq: 0,
        last_reply_seq: None,
        stats: Stats {
            expected,
            ..Stats::default()
        },
        inbox: Default::default(),
        last_heard: Instant::now(),
    };
    // Where the logger stands: stop anything left running.
    s.request(Command::Status, |g| match g {
        Got::Status { .. } => Some(Ok(())),
        _ => None,
    })?;
    s.request(Command::Stop, |g| match g {
        Got::Ack { command } if *command == crate::kind::STOP => Some(Ok(())),
        _ => None,
    })?;
    s.inbox.clear();
    s.request(
        Command::Configure {
            rate_hz: plan.rate_hz,
            channels: ALL_CHANNELS,
        },
        |g| match g {
            Got::Ack { command } if *command == crate::kind::CONFIGURE => Some(Ok(())),
            Got::Error { code, command } if *command == crate::kind::CONFIGURE => {
                Some(refused("the configuration", *code))
            }
            _ => None,
        },
    )?;
    let millivolts = (plan.volts * 1000.0).round();
    if !(millivolts.is_finite() && millivolts.abs() <= f64::from(i32::MAX)) {
        return Err(AcquireError::Refused(format!(
            "{} V is beyond the logger's range",
            plan.volts
        )));
    }
    let mut armed_once = false;
    s.request(
        Command::Arm {
            millivolts: millivolts as i32,
            duration_ms: plan.duration_ms() as u32,
            mode: if plan.live { Mode::Live } else { Mode::Record },
        },
        |g| match g {
            Got::Ack { command } if *command == crate::kind::ARM => Some(Ok(())),
            // An Arm whose Ack was lost, sent again, finds the test running.
            Got::Error {
                code: ErrorCode::Busy,
                command,
            } if *command == crate::kind::ARM && armed_once => Some(Ok(())),
            Got::Error { code, command } if *command == crate::kind::ARM => {
                armed_once = true;
                if *code == ErrorCode::Busy {
                    None
                } else {
                    Some(refused("the step test", *code))
                }
            }
            _ => None,
        },
    )?;
    let mut samples: Vec<Option<Sample>> = vec![None; expected as usize];
    match collect(&mut s, plan, &mut samples, &mut progress) {
        Ok(()) => {}
        Err(AcquireError::Io(e)) => {
            let (count, first) = missing(&samples);
            return Err(AcquireError::Lost(format!(
                "the serial line failed ({e}) with {count} of {expected} samples not received (first missing: sample {first}) — nothing written"
            )));
        }
        Err(e) => return Err(e),
    }
    let missing: Vec<usize> = (0..samples.len())
        .filter(|&i| samples[i].is_none())
        .collect();
    if let (Some(first), Some(last)) = (missing.first(), missing.last()) {
        return Err(AcquireError::Lost(format!(
            "{} of {expected} samples could not be recovered (first missing: sample {first}, last: {last}; {} frames failed their check, {} were lost) — nothing written",
            missing.len(),
            s.stats.bad_frames,
            s.stats.lost_frames
        )));
    }
    Ok(Acquired {
        samples: samples.into_iter().flatten().collect(),
        rate_hz: plan.rate_hz,
        stats: s.stats,
    })
}

/// The record of SPEC section 4 from a test's samples: times `i/rate`, voltage and current
/// through the calibration, the encoder unwrapped into an angle, the speed its central
/// difference (as the paper computed it; the tachometer is too noisy).
pub fn to_record(acquired: &Acquired, calibration: &Calibration) -> Record {
    let dt = 1.0 / f64::from(acquired.rate_hz);
    let n = acquired.samples.len();
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let modulus = i64::from(crate::ENCODER_MODULUS);
    let mut unwrapped = Vec::with_capacity(n);
    let mut last: Option<(i64, i64)> = None;
    for s in &acquired.samples {
        let raw = i64::from(s[3]);
        let value = match last {
            None => {
                if raw >= modulus / 2 {
                    raw - modulus
                } else {
                    raw
                }
            }
            Some((prev_raw, prev)) => {
                let step = (raw - prev_raw).rem_euclid(modulus);
                prev + if step >= modulus / 2 {
                    step - modulus
                } else {
                    step
                }
            }
        };
        last = Some((raw, value));
        unwrapped.push(value);
    }
    let position: Vec<f64> = unwrapped.iter().map(|&c| calibration.angle(c)).collect();
    let channel = |c: usize| -> Vec<f64> {
        acquired
            .samples
            .iter()
            .map(|s| calibration.analog(c, s[c]))
            .collect()
    };
    Record {
        voltage: channel(0),
        current: channel(1),
        speed: Some(central_difference(&t, &position)),
        position: Some(position),
        t,
        clipped: [0; 3],
    }
}

/// A test length for a message: as given up to 1e9 s, beyond that only its order.
fn duration_text(duration_s: f64) -> String {
    if duration_s.abs() <= 1e9 {
        format!("{duration_s}")
    } else {
        format!("{duration_s:.0e}")
    }
}
