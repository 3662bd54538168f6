//! The logger on the host: the hardware traits backed by the `motor-model` simulator and a byte
//! pipe, and [`Emulator`], the firmware on that board.
//!
//! At each step test the board simulates the armature voltage it is told to apply on the
//! configured motor (with its effects), measures it through the calibration's 0–5 V scales
//! with the ADC noise, and serves the readings sample by sample at the timer's ticks — the same
//! computation as `motorid simulate` with the same measurement settings (`motor_model::simulate`
//! and `MeasurementModel::readings`), so the records agree sample for sample. The tachometer
//! channel also carries brush-commutation ripple (not in `simulate`'s record, whose speed comes
//! from the encoder, as the paper's did).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use motor_model::{Effects, Input, ModelError, MotorParams, Readings};

use crate::firmware::Firmware;
use crate::hw::{Adc, Drive, Encoder, Flash, Timer, Uart};
use crate::FLASH_BYTES;
use daq_protocol::host::Calibration;

/// What the emulated logger is connected to.
#[derive(Debug, Clone, PartialEq)]
pub struct Plant {
    /// The motor.
    pub motor: MotorParams,
    /// Unmodelled effects switched on (SPEC section 5).
    pub effects: Effects,
    /// The conditioning and encoder.
    pub calibration: Calibration,
    /// ADC noise \[LSB\] on each analog channel.
    pub noise_lsb: f64,
    /// Seed of the first test's noise; test k (from 0) uses `seed + k`.
    pub seed: u64,
    /// Relative amplitude of the tachometer's brush-commutation ripple.
    pub tacho_ripple: f64,
    /// Commutator segments (ripple periods per revolution).
    pub commutator_segments: u32,
}

impl Default for Plant {
    /// The paper's motor, no effects, default calibration, 1 LSB of noise, seed 1, 3 % ripple
    /// at 12 segments.
    fn default() -> Self {
        Plant {
            motor: MotorParams::paper(),
            effects: Effects::none(),
            calibration: Calibration::default(),
            noise_lsb: 1.0,
            seed: 1,
            tacho_ripple: 0.03,
            commutator_segments: 12,
        }
    }
}

/// Faults the byte pipe can inject into what the logger sends, for tests of the PC side.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LineFaults {
    /// Probability that each bit is flipped.
    pub bit_error_rate: f64,
    /// Probability that each byte is lost.
    pub drop_rate: f64,
    /// Close the line (stop answering for good) after this many bytes sent.
    pub close_after: Option<u64>,
    /// Seed of the fault draws.
    pub seed: u64,
}

/// The board: peripherals backed by the simulator, a flash array, and a byte pipe.
#[derive(Debug)]
pub struct HostBoard {
    plant: Plant,
    millivolts: i32,
    tests: u64,
    readings: Readings,
    next_sample: usize,
    ticks_left: u32,
    rate_hz: u16,
    flash: Vec<u8>,
    rx: VecDeque<u8>,
    tx: Vec<u8>,
    paced: Option<Pacing>,
    /// The last error of a simulation (bad settings), reported by the emulator.
    pub error: Option<String>,
}

/// Real-time pacing: samples at the timer rate, bytes at the baud rate.
#[derive(Debug, Clone, Copy)]
struct Pacing {
    timer_start: Instant,
    /// When the transmitter is free again (each byte takes 10 bit times).
    line_free_at: Instant,
}

impl HostBoard {
    /// A board for `plant`; `paced` runs samples and bytes in real time.
    pub fn new(plant: Plant, paced: bool) -> Self {
        let now = Instant::now();
        HostBoard {
            plant,
            millivolts: 0,
            tests: 0,
            readings: Readings::default(),
            next_sample: 0,
            ticks_left: 0,
            rate_hz: 1000,
            flash: vec![0xFF; FLASH_BYTES as usize],
            rx: VecDeque::new(),
            tx: Vec::new(),
            paced: paced.then_some(Pacing {
                timer_start: now,
                line_free_at: now,
            }),
            error: None,
        }
    }

    /// Simulates and measures the test now starting: `samples` samples at `rate_hz`.
    fn prepare_test(&mut self, samples: usize) {
        let rate = f64::from(self.rate_hz);
        let volts = f64::from(self.millivolts) / 1000.0;
        let seed = self.plant.seed.wrapping_add(self.tests);
        self.tests += 1;
        let result = (|| -> Result<Readings, ModelError> {
            let mut trace = motor_model::simulate(
                &self.plant.motor,
                self.plant.effects,
                &Input::step(volts, 0.0)?,
                (samples as f64 - 0.5) / rate,
                rate,
            )?;
            let segments = f64::from(self.plant.commutator_segments);
            for (w, th) in trace.speed.iter_mut().zip(&trace.position) {
                *w *= 1.0 + self.plant.tacho_ripple * (segments * th).sin();
            }
            self.plant
                .calibration
                .measurement(self.plant.noise_lsb, seed)?
                .readings(&trace)
        })();
        match result {
            Ok(r) => self.readings = r,
            Err(e) => {
                self.error = Some(e.to_string());
                self.readings = Readings::default();
            }
        }
        self.next_sample = 0;
    }

    /// The reading of `channel` for the current sample (0 before any test).
    fn current_adc(&self, channel: usize) -> u16 {
        let i = self.next_sample;
        self.readings.adc[channel]
            .get(i)
            .map_or(0, |&c| c.min(u32::from(daq_protocol::ADC_MAX)) as u16)
    }
}

impl Adc for HostBoard {
    fn read_adc(&mut self, channel: u8) -> u16 {
        self.current_adc(usize::from(channel.min(2)))
    }
}

impl Encoder for HostBoard {
    fn read_count(&mut self) -> u16 {
        let count = self
            .readings
            .encoder
            .get(self.next_sample)
            .copied()
            .unwrap_or(0);
        // The ripple counter keeps the low 12 bits; the latch is the last read of a sample.
        let latched = count.rem_euclid(i64::from(daq_protocol::ENCODER_MODULUS)) as u16;
        self.next_sample += 1;
        latched
    }
}

impl Drive for HostBoard {
    fn apply_millivolts(&mut self, millivolts: i32) {
        self.millivolts = millivolts;
    }
}

impl Flash for HostBoard {
    fn capacity(&self) -> u32 {
        FLASH_BYTES
    }

    fn write(&mut self, address: u32, data: &[u8]) {
        let a = address as usize;
        if let Some(dst) = self.flash.get_mut(a..a + data.len()) {
            dst.copy_from_slice(data);
        }
    }

    fn read(&mut self, address: u32, out: &mut [u8]) {
        let a = address as usize;
        match self.flash.get(a..a + out.len()) {
            Some(src) => out.copy_from_slice(src),
            None => out.fill(0xFF),
        }
    }
}

impl Uart for HostBoard {
    fn write_byte(&mut self, byte: u8) -> bool {
        if let Some(p) = &mut self.paced {
            let now = Instant::now();
            if now < p.line_free_at {
                return false;
            }
            let byte_time =
                Duration::from_secs_f64(1.0 / f64::from(daq_protocol::LINE_BYTES_PER_S));
            // An idle line does not bank time: the byte starts now at the earliest.
            p.line_free_at = p.line_free_at.max(now) + byte_time;
        }
        self.tx.push(byte);
        true
    }

    fn read_byte(&mut self) -> Option<u8> {
        self.rx.pop_front()
    }
}

impl Timer for HostBoard {
    fn start_timer(&mut self, rate_hz: u16, ticks: u32) {
        self.rate_hz = rate_hz;
        self.ticks_left = ticks;
        if let Some(p) = &mut self.paced {
            p.timer_start = Instant::now();
        }
        // The firmware takes the first sample right after this call.
        self.prepare_test(ticks as usize + 1);
    }

    fn stop_timer(&mut self) {
        self.ticks_left = 0;
    }

    fn sample_due(&mut self) -> bool {
        if self.ticks_left == 0 {
            return false;
        }
        if let Some(p) = &self.paced {
            let due = self.next_sample as f64 / f64::from(self.rate_hz.max(1));
            if p.timer_start.elapsed().as_secs_f64() < due {
                return false;
            }
        }
        self.ticks_left -= 1;
        true
    }
}

/// The logger firmware on the host board, with a byte pipe that can inject faults.
#[derive(Debug)]
pub struct Emulator {
    firmware: Firmware,
    board: HostBoard,
    faults: LineFaults,
    fault_rng: motor_model::NoiseRng,
    sent: u64,
}

impl Emulator {
    /// An emulated logger connected to `plant`; `paced` runs it in real time.
    pub fn new(plant: Plant, paced: bool) -> Self {
        Emulator {
            firmware: Firmware::new(),
            board: HostBoard::new(plant, paced),
            faults: LineFaults::default(),
            fault_rng: motor_model::NoiseRng::new(0),
            sent: 0,
        }
    }

    /// The same, with `faults` on what it sends.
    pub fn with_faults(mut self, faults: LineFaults) -> Self {
        self.fault_rng = motor_model::NoiseRng::new(faults.seed);
        self.faults = faults;
        self
    }

    /// Bytes from the PC.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.board.rx.extend(bytes);
    }

    /// Runs the firmware until it has nothing to do (unpaced: a whole test or dump at once) or
    /// for at most `budget`, and returns what it sent (after the faults).
    pub fn run(&mut self, budget: Duration) -> Vec<u8> {
        let start = Instant::now();
        loop {
            self.firmware.poll(&mut self.board);
            if self.is_idle() || start.elapsed() >= budget {
                break;
            }
            if self.board.paced.is_some() && self.board.tx.len() > 4096 {
                break;
            }
        }
        self.take_output()
    }

    /// Whether the firmware is idle with nothing to send.
    pub fn is_idle(&self) -> bool {
        self.firmware.is_quiet() && self.board.rx.is_empty() && self.board.ticks_left == 0
    }

    /// A simulation error of the last test, if any (e.g. a voltage the model refuses).
    pub fn take_error(&mut self) -> Option<String> {
        self.board.error.take()
    }

    fn take_output(&mut self) -> Vec<u8> {
        let raw = std::mem::take(&mut self.board.tx);
        let f = self.faults;
        let mut out = Vec::with_capacity(raw.len());
        for mut byte in raw {
            if f.close_after.is_some_and(|n| self.sent >= n) {
                break;
            }
            self.sent += 1;
            if f.drop_rate > 0.0 && self.fault_rng.uniform() < f.drop_rate {
                continue;
            }
            if f.bit_error_rate > 0.0 {
                for bit in 0..8 {
                    if self.fault_rng.uniform() < f.bit_error_rate {
                        byte ^= 1 << bit;
                    }
                }
            }
            out.push(byte);
        }
        out
    }

    /// Whether the line has been closed by the `close_after` fault.
    pub fn line_closed(&self) -> bool {
        self.faults.close_after.is_some_and(|n| self.sent >= n)
    }
}
