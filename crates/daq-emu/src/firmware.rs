//! The logger's firmware core: a state machine polled from the main loop, written against the
//! small hardware traits of [`crate::hw`]. It samples on the timer's ticks into flash (six bytes
//! a sample: three 10-bit ADC codes and the 12-bit encoder count in 42 bits), answers the
//! commands of `daq-protocol`, dumps stored records in blocks of 32 samples and, in live mode,
//! sends each block as soon as it is stored.

use daq_protocol::{
    encode, kind, pack_sample, packed_len, Command, Decoder, ErrorCode, Frame, Mode, Reply, Sample,
    State, ADC_MAX, ALL_CHANNELS, ENCODER_MODULUS, MAX_BLOCK_SAMPLES, MAX_FRAME, MAX_RATE_HZ,
    SAMPLE_BYTES,
};

use crate::hw::{Adc, Drive, Encoder, Flash, Timer, Uart};

/// Longest command frame on the line (Arm: 2 + 9 + 4 bytes of body, stuffed, delimited).
pub const MAX_COMMAND_FRAME: usize = 17;

/// Every peripheral the firmware drives.
pub trait Board: Adc + Encoder + Drive + Flash + Uart + Timer {}
impl<T: Adc + Encoder + Drive + Flash + Uart + Timer> Board for T {}

/// A reply waiting for the transmitter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    None,
    Ack { command: u8, seq: u8 },
    Error { code: ErrorCode, command: u8 },
    Status,
}

/// The firmware's whole RAM state (the flash array lives in the [`Flash`] peripheral).
#[derive(Debug, Clone)]
pub struct Firmware {
    /// Received bytes until a command frame is complete.
    decoder: Decoder<MAX_COMMAND_FRAME>,
    /// The frame being sent, and how much of it has gone.
    tx: [u8; MAX_FRAME],
    tx_len: u16,
    tx_sent: u16,
    /// Sequence number of the next frame sent.
    seq: u8,
    state: State,
    mode: Mode,
    rate_hz: u16,
    channels: u8,
    /// Samples the running test will take, and has taken.
    planned: u32,
    taken: u32,
    /// Samples in the stored record.
    stored: u32,
    /// Next sample to dump, and the end of the dump.
    dump_next: u32,
    dump_end: u32,
    /// Samples already streamed live.
    live_sent: u32,
    pending: Pending,
    end_pending: bool,
}

impl Default for Firmware {
    fn default() -> Self {
        Self::new()
    }
}

impl Firmware {
    /// The firmware after reset: idle, 1 kHz, all channels, no record.
    pub const fn new() -> Self {
        Firmware {
            decoder: Decoder::new(),
            tx: [0; MAX_FRAME],
            tx_len: 0,
            tx_sent: 0,
            seq: 0,
            state: State::Idle,
            mode: Mode::Record,
            rate_hz: 1000,
            channels: ALL_CHANNELS,
            planned: 0,
            taken: 0,
            stored: 0,
            dump_next: 0,
            dump_end: 0,
            live_sent: 0,
            pending: Pending::None,
            end_pending: false,
        }
    }

    /// What the logger is doing.
    pub fn state(&self) -> State {
        self.state
    }

    /// Samples in the stored record.
    pub fn stored(&self) -> u32 {
        self.stored
    }

    /// Whether nothing is left to do until a timer tick or a received byte.
    pub fn is_quiet(&self) -> bool {
        self.tx_sent == self.tx_len
            && self.pending == Pending::None
            && !self.end_pending
            && self.state != State::Dumping
            && !(self.state == State::Running && self.mode == Mode::Live && self.live_block_ready())
    }

    /// One pass of the main loop: take a sample if the timer says so, send what the UART
    /// accepts, prepare the next frame, read commands.
    pub fn poll<B: Board>(&mut self, hw: &mut B) {
        if self.state == State::Running && hw.sample_due() {
            self.take_sample(hw);
        }
        self.transmit(hw);
        if self.tx_sent == self.tx_len {
            self.prepare_frame(hw);
            self.transmit(hw);
        }
        // Read commands only when a reply can be queued.
        while self.pending == Pending::None {
            let Some(byte) = hw.read_byte() else { break };
            let command = match self.decoder.feed(byte) {
                Some(Ok(Frame::Command { seq, command })) => Some((seq, command)),
                Some(Ok(Frame::Reply { .. })) | Some(Err(_)) | None => None,
            };
            if let Some((seq, command)) = command {
                self.handle(hw, seq, command);
            }
        }
    }

    fn take_sample<B: Board>(&mut self, hw: &mut B) {
        let sample: Sample = [
            hw.read_adc(0) & ADC_MAX,
            hw.read_adc(1) & ADC_MAX,
            hw.read_adc(2) & ADC_MAX,
            hw.read_count() % ENCODER_MODULUS,
        ];
        let mut bytes = [0u8; SAMPLE_BYTES as usize];
        pack_sample(&mut bytes, ALL_CHANNELS, 0, &sample);
        hw.write(self.taken * SAMPLE_BYTES, &bytes);
        self.taken += 1;
        self.stored = self.taken;
        if self.taken == self.planned {
            self.finish_test(hw);
        }
    }

    fn finish_test<B: Board>(&mut self, hw: &mut B) {
        hw.apply_millivolts(0);
        hw.stop_timer();
        self.state = State::Idle;
        self.end_pending = true;
    }

    fn live_block_ready(&self) -> bool {
        self.taken - self.live_sent >= MAX_BLOCK_SAMPLES as u32
    }

    fn transmit<B: Board>(&mut self, hw: &mut B) {
        while self.tx_sent < self.tx_len {
            if !hw.write_byte(self.tx[usize::from(self.tx_sent)]) {
                break;
            }
            self.tx_sent += 1;
        }
    }

    /// Encodes `reply` into the transmit buffer.
    fn send(&mut self, reply: Reply<'_>) {
        let frame = Frame::Reply {
            seq: self.seq,
            reply,
        };
        // Every reply fits MAX_FRAME by construction; a failure would only drop this frame,
        // which the PC sees as a gap in the sequence numbers.
        let n = encode(&frame, &mut self.tx).unwrap_or(0);
        self.tx_len = n as u16;
        self.tx_sent = 0;
        self.seq = self.seq.wrapping_add(1);
    }

    /// A block of stored samples `[from, from + count)` as a Samples frame.
    fn send_block<B: Board>(&mut self, hw: &mut B, from: u32, count: u32) {
        let mut packed = [0u8; packed_len(ALL_CHANNELS, MAX_BLOCK_SAMPLES)];
        let mask = self.channels;
        let used = packed_len(mask, count as usize);
        for i in 0..count {
            let mut raw = [0u8; SAMPLE_BYTES as usize];
            hw.read((from + i) * SAMPLE_BYTES, &mut raw);
            let all = daq_protocol::unpack_sample(&raw, ALL_CHANNELS, 0);
            pack_sample(&mut packed[..used], mask, i as usize, &all);
        }
        self.send(Reply::Samples {
            first: from,
            channels: mask,
            count: count as u8,
            packed: &packed[..used],
        });
    }

    fn prepare_frame<B: Board>(&mut self, hw: &mut B) {
        match core::mem::replace(&mut self.pending, Pending::None) {
            Pending::Ack { command, seq } => return self.send(Reply::Ack { command, seq }),
            Pending::Error { code, command } => return self.send(Reply::Error { code, command }),
            Pending::Status => {
                return self.send(Reply::Status {
                    state: self.state,
                    rate_hz: self.rate_hz,
                    channels: self.channels,
                    stored: self.stored,
                })
            }
            Pending::None => {}
        }
        if self.mode == Mode::Live && (self.state == State::Running || self.end_pending) {
            let ready = self.taken - self.live_sent;
            let block = MAX_BLOCK_SAMPLES as u32;
            if ready >= block || (self.end_pending && ready > 0) {
                let count = ready.min(block);
                let from = self.live_sent;
                self.live_sent += count;
                return self.send_block(hw, from, count);
            }
        }
        if self.state == State::Dumping {
            if self.dump_next < self.dump_end {
                let count = (self.dump_end - self.dump_next).min(MAX_BLOCK_SAMPLES as u32);
                let from = self.dump_next;
                self.dump_next += count;
                return self.send_block(hw, from, count);
            }
            self.state = State::Idle;
            self.end_pending = true;
        }
        if self.end_pending {
            self.end_pending = false;
            self.send(Reply::End { total: self.stored });
        }
    }

    fn handle<B: Board>(&mut self, hw: &mut B, seq: u8, command: Command) {
        let ack = |k: u8| Pending::Ack { command: k, seq };
        let refuse = |code, k: u8| Pending::Error { code, command: k };
        let busy = self.state != State::Idle;
        self.pending = match command {
            Command::Status => Pending::Status,
            Command::Configure { rate_hz, channels } => {
                if busy {
                    refuse(ErrorCode::Busy, kind::CONFIGURE)
                } else if rate_hz == 0 || rate_hz > MAX_RATE_HZ || channels == 0 {
                    refuse(ErrorCode::BadSetting, kind::CONFIGURE)
                } else {
                    self.rate_hz = rate_hz;
                    self.channels = channels;
                    ack(kind::CONFIGURE)
                }
            }
            Command::Arm {
                millivolts,
                duration_ms,
                mode,
            } => {
                let samples = u64::from(self.rate_hz) * u64::from(duration_ms) / 1000 + 1;
                if busy {
                    refuse(ErrorCode::Busy, kind::ARM)
                } else if duration_ms == 0 {
                    refuse(ErrorCode::BadSetting, kind::ARM)
                } else if samples * u64::from(SAMPLE_BYTES) > u64::from(hw.capacity()) {
                    refuse(ErrorCode::FlashFull, kind::ARM)
                } else {
                    self.mode = mode;
                    self.planned = samples as u32;
                    self.taken = 0;
                    self.stored = 0;
                    self.live_sent = 0;
                    self.end_pending = false;
                    self.state = State::Running;
                    hw.apply_millivolts(millivolts);
                    hw.start_timer(self.rate_hz, self.planned - 1);
                    // The first sample is the step instant itself.
                    self.take_sample(hw);
                    ack(kind::ARM)
                }
            }
            Command::Stop => {
                match self.state {
                    State::Running => {
                        self.planned = self.taken;
                        self.finish_test(hw);
                    }
                    State::Dumping => {
                        self.state = State::Idle;
                        self.end_pending = true;
                    }
                    State::Idle => {}
                }
                ack(kind::STOP)
            }
            Command::Dump { from, count } => {
                // A dump asked for again (its Ack lost) replaces the one under way.
                if self.state == State::Running {
                    refuse(ErrorCode::Busy, kind::DUMP)
                } else if from > self.stored {
                    refuse(ErrorCode::OutOfRange, kind::DUMP)
                } else {
                    let end = if count == 0 {
                        self.stored
                    } else {
                        from.saturating_add(count).min(self.stored)
                    };
                    self.dump_next = from;
                    self.dump_end = end;
                    self.state = State::Dumping;
                    ack(kind::DUMP)
                }
            }
            Command::Erase => {
                if busy {
                    refuse(ErrorCode::Busy, kind::ERASE)
                } else {
                    self.stored = 0;
                    self.taken = 0;
                    ack(kind::ERASE)
                }
            }
        };
    }
}
