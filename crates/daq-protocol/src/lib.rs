//! Wire format of the motorid data logger (`no_std`, no allocation).
//!
//! The frames exchanged between the logger (the PIC 16F877 of the seed paper's Sec. 3,
//! emulated by `daq-emu`) and the PC over RS-232 at 115200 baud 8N1. The codec does no I/O: it
//! encodes into a caller's buffer ([`encode`]) and decodes from bytes fed to it one at a time
//! ([`Decoder::feed`]). The byte-exact specification, with test vectors, is
//! `docs/wire-format.md`; in short:
//!
//! - a frame on the line is `COBS(body) 00`: consistent overhead byte stuffing removes every
//!   zero byte from the body, so `00` marks the end of a frame and a receiver resynchronises at
//!   the next `00` after any garbage;
//! - `body = kind, seq, payload…, crc` with `crc` the CRC-32C (Castagnoli) of `kind, seq,
//!   payload` in little-endian order: every error of up to 3 bits in a body of up to 255 bytes
//!   is detected (the polynomial's Hamming distance at these lengths is at least 4), and a
//!   frame mangled otherwise — a flipped bit in the stuffing shifts or splits it — passes with
//!   probability 2⁻³² at most;
//! - `seq` counts the frames each side sends (mod 256), so the receiver sees a lost frame;
//!   sample blocks also carry the index of their first sample, so a lost block is re-requested
//!   with [`Command::Dump`];
//! - samples are packed at their real widths: 10 bits per ADC channel and 12 for the wrapping
//!   encoder counter, little-endian bit order ([`pack_sample`], [`unpack_sample`]).
//!
//! With the feature `host` (which needs `std`), [`host`] is the PC side: the acquisition state
//! machine over any byte [`host::Link`] and the [`host::Calibration`] that turns readings into a
//! record.
#![no_std]
#![warn(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

mod cobs;
mod crc;
#[cfg(feature = "host")]
pub mod host;
mod packing;

pub use cobs::{cobs_decode_in_place, cobs_encode, cobs_max_encoded_len};
pub use crc::crc32c;
pub use packing::{
    bits_per_sample, pack_sample, packed_len, unpack_sample, Sample, ADC_MAX, CHANNEL_COUNT,
    ENCODER_MODULUS,
};

/// Bits of each ADC sample (the PIC 16F877's converter).
pub const ADC_BITS: u8 = 10;
/// Bits of the encoder counter (MC4040 ripple counter; wraps).
pub const ENCODER_BITS: u8 = 12;
/// Serial line rate of the logger, in baud (the paper prints 115250: a typo for 115200).
pub const BAUD: u32 = 115_200;
/// Bytes per second the line carries at 8N1 (10 bits per byte).
pub const LINE_BYTES_PER_S: u32 = BAUD / 10;
/// Longest body (kind, seq, payload, CRC) of a frame \[bytes\].
pub const MAX_BODY: usize = 255;
/// Longest frame on the line: COBS of the longest body plus the `00` delimiter \[bytes\].
pub const MAX_FRAME: usize = cobs_max_encoded_len(MAX_BODY) + 1;
/// Most samples in one [`Reply::Samples`] block.
pub const MAX_BLOCK_SAMPLES: usize = 32;
/// Bytes a stored sample takes in the logger's flash (42 bits, padded).
pub const SAMPLE_BYTES: u32 = 6;
/// The flash of the paper's logger: 16 Mbit \[bytes\].
pub const FLASH_BYTES: u32 = 16 * 1024 * 1024 / 8;
/// Highest sample rate the logger accepts \[Hz\].
pub const MAX_RATE_HZ: u16 = 10_000;
/// The channel mask of all four channels: voltage, current, speed (ADC) and encoder.
pub const ALL_CHANNELS: u8 = 0b1111;

/// Frame kinds, the first byte of a body.
pub mod kind {
    /// [`super::Command::Status`].
    pub const STATUS: u8 = 0x01;
    /// [`super::Command::Configure`].
    pub const CONFIGURE: u8 = 0x02;
    /// [`super::Command::Arm`].
    pub const ARM: u8 = 0x03;
    /// [`super::Command::Stop`].
    pub const STOP: u8 = 0x04;
    /// [`super::Command::Dump`].
    pub const DUMP: u8 = 0x05;
    /// [`super::Command::Erase`].
    pub const ERASE: u8 = 0x06;
    /// [`super::Reply::Status`].
    pub const STATUS_REPLY: u8 = 0x81;
    /// [`super::Reply::Samples`].
    pub const SAMPLES: u8 = 0x82;
    /// [`super::Reply::End`].
    pub const END: u8 = 0x83;
    /// [`super::Reply::Error`].
    pub const ERROR: u8 = 0x84;
    /// [`super::Reply::Ack`].
    pub const ACK: u8 = 0x85;
}

/// What the logger is doing ([`Reply::Status`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum State {
    /// Waiting for a command.
    Idle = 0,
    /// Running a step test (sampling).
    Running = 1,
    /// Sending a stored record.
    Dumping = 2,
}

impl State {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(State::Idle),
            1 => Some(State::Running),
            2 => Some(State::Dumping),
            _ => None,
        }
    }
}

/// How a step test delivers its samples ([`Command::Arm`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Mode {
    /// Record to flash; the PC dumps the record afterwards (the paper's logger).
    Record = 0,
    /// Record to flash and stream each block as it is complete.
    Live = 1,
}

/// Errors the logger reports ([`Reply::Error`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ErrorCode {
    /// The command is not valid in the logger's state (e.g. arm while running).
    Busy = 1,
    /// A setting is out of range (rate, channels, duration, voltage).
    BadSetting = 2,
    /// The record does not fit in the flash.
    FlashFull = 3,
    /// A dump asked for samples past the end of the record.
    OutOfRange = 4,
    /// A frame arrived with a bad CRC or shape.
    BadFrame = 5,
}

impl ErrorCode {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            1 => Some(ErrorCode::Busy),
            2 => Some(ErrorCode::BadSetting),
            3 => Some(ErrorCode::FlashFull),
            4 => Some(ErrorCode::OutOfRange),
            5 => Some(ErrorCode::BadFrame),
            _ => None,
        }
    }
}

/// Commands, PC to logger.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Ask for a [`Reply::Status`].
    Status,
    /// Set the sample rate \[Hz\] and the channel mask (bit 0 voltage, 1 current, 2 speed,
    /// 3 encoder).
    Configure {
        /// Sample rate \[Hz\], 1 to 10,000.
        rate_hz: u16,
        /// Channel mask, non-zero, at most [`ALL_CHANNELS`].
        channels: u8,
    },
    /// Run a step test: apply `millivolts` for `duration_ms`, sampling from the step on.
    Arm {
        /// Step voltage \[mV\] (either sign).
        millivolts: i32,
        /// Test length \[ms\].
        duration_ms: u32,
        /// Record only, or also stream live.
        mode: Mode,
    },
    /// Stop a running test or dump.
    Stop,
    /// Send `count` stored samples from sample `from` (count 0: to the end), as
    /// [`Reply::Samples`] blocks, then [`Reply::End`].
    Dump {
        /// Index of the first sample.
        from: u32,
        /// Number of samples, 0 for all the rest.
        count: u32,
    },
    /// Forget the stored record.
    Erase,
}

/// Replies, logger to PC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply<'a> {
    /// The logger's state and configuration.
    Status {
        /// What it is doing.
        state: State,
        /// Sample rate \[Hz\].
        rate_hz: u16,
        /// Channel mask.
        channels: u8,
        /// Samples of the stored record.
        stored: u32,
    },
    /// A block of samples, packed ([`pack_sample`]); read them with [`Reply::sample`].
    Samples {
        /// Index of the block's first sample in the record.
        first: u32,
        /// Channel mask the samples were packed with.
        channels: u8,
        /// Number of samples, 1 to [`MAX_BLOCK_SAMPLES`].
        count: u8,
        /// The packed samples (`packed_len(channels, count)` bytes).
        packed: &'a [u8],
    },
    /// The end of a test or dump: the record holds `total` samples.
    End {
        /// Samples in the record.
        total: u32,
    },
    /// A command could not be done.
    Error {
        /// Why.
        code: ErrorCode,
        /// Kind of the command refused.
        command: u8,
    },
    /// A command was accepted.
    Ack {
        /// Kind of the command.
        command: u8,
        /// Its sequence number.
        seq: u8,
    },
}

impl Reply<'_> {
    /// Sample `i` of a [`Reply::Samples`] block (`None` past its end or for other replies).
    pub fn sample(&self, i: usize) -> Option<Sample> {
        match *self {
            Reply::Samples {
                channels,
                count,
                packed,
                ..
            } if i < usize::from(count) => Some(unpack_sample(packed, channels, i)),
            _ => None,
        }
    }
}

/// A decoded frame: its sequence number and what it says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame<'a> {
    /// A command (PC to logger).
    Command {
        /// Sequence number of the sender.
        seq: u8,
        /// The command.
        command: Command,
    },
    /// A reply (logger to PC).
    Reply {
        /// Sequence number of the sender.
        seq: u8,
        /// The reply.
        reply: Reply<'a>,
    },
}

/// Why a frame could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum EncodeError {
    /// The output buffer is too small.
    BufferTooSmall {
        /// Bytes the frame needs on the line (with its `00`).
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// A field is out of range (a block of 0 or more than [`MAX_BLOCK_SAMPLES`] samples, a
    /// packed length that does not match, an empty or unknown channel mask).
    Invalid {
        /// The field.
        field: &'static str,
        /// Its value.
        value: u32,
    },
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            EncodeError::BufferTooSmall { needed, available } => write!(
                f,
                "the frame needs {needed} bytes and the buffer has {available}"
            ),
            EncodeError::Invalid { field, value } => {
                write!(f, "{field} = {value} is out of range for a frame")
            }
        }
    }
}

/// Why bytes fed to a [`Decoder`] were not a frame. Every one of these is detected, never
/// passed on: the decoder drops the frame and waits for the next `00`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum DecodeError {
    /// More than [`MAX_FRAME`] bytes without a `00`: garbage, dropped up to the next `00`.
    Overflow,
    /// The COBS stuffing is broken (a code byte points past the end).
    Stuffing,
    /// The CRC does not match: the frame was corrupted.
    Crc,
    /// Too short to hold kind, seq and CRC.
    TooShort,
    /// A kind no one sends, or a payload of the wrong length or with invalid fields.
    Malformed,
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            DecodeError::Overflow => "more than a frame's bytes without a 00 delimiter",
            DecodeError::Stuffing => "broken COBS stuffing (a code byte points past the end)",
            DecodeError::Crc => "CRC-32C mismatch: the frame was corrupted on the line",
            DecodeError::TooShort => "too short to hold kind, sequence number and CRC",
            DecodeError::Malformed => {
                "unknown kind, or a payload of the wrong length or with invalid fields"
            }
        })
    }
}

/// Encodes the body `kind, seq, payload, crc` of `frame` into `body` and returns its length.
fn encode_body(frame: &Frame<'_>, body: &mut [u8; MAX_BODY]) -> Result<usize, EncodeError> {
    let mut w = Writer { buf: body, len: 0 };
    match *frame {
        Frame::Command { seq, command } => match command {
            Command::Status => w.head(kind::STATUS, seq),
            Command::Configure { rate_hz, channels } => {
                if channels == 0 || channels > ALL_CHANNELS {
                    return Err(EncodeError::Invalid {
                        field: "channel mask",
                        value: u32::from(channels),
                    });
                }
                w.head(kind::CONFIGURE, seq);
                w.bytes(&rate_hz.to_le_bytes());
                w.bytes(&[channels]);
            }
            Command::Arm {
                millivolts,
                duration_ms,
                mode,
            } => {
                w.head(kind::ARM, seq);
                w.bytes(&millivolts.to_le_bytes());
                w.bytes(&duration_ms.to_le_bytes());
                w.bytes(&[mode as u8]);
            }
            Command::Stop => w.head(kind::STOP, seq),
            Command::Dump { from, count } => {
                w.head(kind::DUMP, seq);
                w.bytes(&from.to_le_bytes());
                w.bytes(&count.to_le_bytes());
            }
            Command::Erase => w.head(kind::ERASE, seq),
        },
        Frame::Reply { seq, reply } => match reply {
            Reply::Status {
                state,
                rate_hz,
                channels,
                stored,
            } => {
                w.head(kind::STATUS_REPLY, seq);
                w.bytes(&[state as u8]);
                w.bytes(&rate_hz.to_le_bytes());
                w.bytes(&[channels]);
                w.bytes(&stored.to_le_bytes());
            }
            Reply::Samples {
                first,
                channels,
                count,
                packed,
            } => {
                let n = usize::from(count);
                let invalid = |field, value: usize| EncodeError::Invalid {
                    field,
                    value: u32::try_from(value).unwrap_or(u32::MAX),
                };
                if n == 0 || n > MAX_BLOCK_SAMPLES {
                    return Err(invalid("samples in a block", n));
                }
                if channels == 0 || channels > ALL_CHANNELS {
                    return Err(invalid("channel mask", usize::from(channels)));
                }
                if packed.len() != packed_len(channels, n) {
                    return Err(invalid("packed bytes", packed.len()));
                }
                w.head(kind::SAMPLES, seq);
                w.bytes(&first.to_le_bytes());
                w.bytes(&[channels, count]);
                w.bytes(packed);
            }
            Reply::End { total } => {
                w.head(kind::END, seq);
                w.bytes(&total.to_le_bytes());
            }
            Reply::Error { code, command } => {
                w.head(kind::ERROR, seq);
                w.bytes(&[code as u8, command]);
            }
            Reply::Ack { command, seq: of } => {
                w.head(kind::ACK, seq);
                w.bytes(&[command, of]);
            }
        },
    }
    let crc = crc32c(&w.buf[..w.len]);
    w.bytes(&crc.to_le_bytes());
    Ok(w.len)
}

struct Writer<'b> {
    buf: &'b mut [u8; MAX_BODY],
    len: usize,
}

impl Writer<'_> {
    fn head(&mut self, kind: u8, seq: u8) {
        self.bytes(&[kind, seq]);
    }

    /// Appends `b`; the longest body (a full sample block) fits by construction.
    fn bytes(&mut self, b: &[u8]) {
        self.buf[self.len..self.len + b.len()].copy_from_slice(b);
        self.len += b.len();
    }
}

/// Encodes `frame` for the line — `COBS(body) 00` — into `out`; returns the bytes written.
pub fn encode(frame: &Frame<'_>, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut body = [0u8; MAX_BODY];
    let len = encode_body(frame, &mut body)?;
    let needed = cobs_max_encoded_len(len) + 1;
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall {
            needed,
            available: out.len(),
        });
    }
    let n = cobs_encode(&body[..len], out);
    out[n] = 0;
    Ok(n + 1)
}

fn le_u16(b: &[u8]) -> u16 {
    u16::from_le_bytes([b[0], b[1]])
}

fn le_u32(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// Parses a decoded body (CRC already checked and removed).
fn parse(body: &[u8]) -> Result<Frame<'_>, DecodeError> {
    let (kind, seq, p) = (body[0], body[1], &body[2..]);
    let expect = |n: usize| {
        if p.len() == n {
            Ok(())
        } else {
            Err(DecodeError::Malformed)
        }
    };
    let command = |command| Ok(Frame::Command { seq, command });
    let reply = |reply| Ok(Frame::Reply { seq, reply });
    match kind {
        kind::STATUS => expect(0).and_then(|()| command(Command::Status)),
        kind::CONFIGURE => {
            expect(3)?;
            let channels = p[2];
            if channels == 0 || channels > ALL_CHANNELS {
                return Err(DecodeError::Malformed);
            }
            command(Command::Configure {
                rate_hz: le_u16(p),
                channels,
            })
        }
        kind::ARM => {
            expect(9)?;
            let mode = match p[8] {
                0 => Mode::Record,
                1 => Mode::Live,
                _ => return Err(DecodeError::Malformed),
            };
            command(Command::Arm {
                millivolts: le_u32(p) as i32,
                duration_ms: le_u32(&p[4..]),
                mode,
            })
        }
        kind::STOP => expect(0).and_then(|()| command(Command::Stop)),
        kind::DUMP => {
            expect(8)?;
            command(Command::Dump {
                from: le_u32(p),
                count: le_u32(&p[4..]),
            })
        }
        kind::ERASE => expect(0).and_then(|()| command(Command::Erase)),
        kind::STATUS_REPLY => {
            expect(8)?;
            let state = State::from_u8(p[0]).ok_or(DecodeError::Malformed)?;
            reply(Reply::Status {
                state,
                rate_hz: le_u16(&p[1..]),
                channels: p[3],
                stored: le_u32(&p[4..]),
            })
        }
        kind::SAMPLES => {
            if p.len() < 6 {
                return Err(DecodeError::Malformed);
            }
            let (channels, count) = (p[4], p[5]);
            let n = usize::from(count);
            if n == 0
                || n > MAX_BLOCK_SAMPLES
                || channels == 0
                || channels > ALL_CHANNELS
                || p.len() != 6 + packed_len(channels, n)
            {
                return Err(DecodeError::Malformed);
            }
            reply(Reply::Samples {
                first: le_u32(p),
                channels,
                count,
                packed: &p[6..],
            })
        }
        kind::END => expect(4).and_then(|()| reply(Reply::End { total: le_u32(p) })),
        kind::ERROR => {
            expect(2)?;
            let code = ErrorCode::from_u8(p[0]).ok_or(DecodeError::Malformed)?;
            reply(Reply::Error {
                code,
                command: p[1],
            })
        }
        kind::ACK => expect(2).and_then(|()| {
            reply(Reply::Ack {
                command: p[0],
                seq: p[1],
            })
        }),
        _ => Err(DecodeError::Malformed),
    }
}

/// A frame decoder: feed it the bytes from the line, one at a time; at each `00` it returns
/// the frame it completed or why there was none. `N` is its buffer: [`MAX_FRAME`] for any
/// frame; a logger that only receives commands can use less (commands are at most 17 bytes
/// on the line).
#[derive(Debug, Clone)]
pub struct Decoder<const N: usize> {
    buf: [u8; N],
    len: usize,
    /// Dropping bytes until the next `00` after an overflow.
    skipping: bool,
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Decoder {
            buf: [0; N],
            len: 0,
            skipping: false,
        }
    }

    /// Forgets any partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.skipping = false;
    }

    /// Takes one byte from the line. Returns `None` inside a frame; at a `00`, the frame (which
    /// borrows the decoder's buffer until the next call) or the reason there is none. An empty
    /// frame (two `00` in a row) is skipped silently.
    pub fn feed(&mut self, byte: u8) -> Option<Result<Frame<'_>, DecodeError>> {
        if byte != 0 {
            if self.skipping {
                return None;
            }
            if self.len == N {
                self.skipping = true;
                self.len = 0;
                return Some(Err(DecodeError::Overflow));
            }
            self.buf[self.len] = byte;
            self.len += 1;
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.skipping) || len == 0 {
            return None;
        }
        Some(Self::finish(&mut self.buf[..len]))
    }

    fn finish(encoded: &mut [u8]) -> Result<Frame<'_>, DecodeError> {
        let n = cobs_decode_in_place(encoded).ok_or(DecodeError::Stuffing)?;
        if n < 6 {
            return Err(DecodeError::TooShort);
        }
        let body = &encoded[..n];
        let (data, crc) = body.split_at(n - 4);
        if crc32c(data) != le_u32(crc) {
            return Err(DecodeError::Crc);
        }
        parse(data)
    }
}

/// Bytes one live-streamed sample block takes on the line: the frame of `count` samples of
/// `channels`, stuffed and delimited \[bytes\].
pub fn samples_frame_len(channels: u8, count: usize) -> usize {
    // kind, seq, first (4), channels, count, packed, crc (4)
    let body = 2 + 4 + 2 + packed_len(channels, count) + 4;
    cobs_max_encoded_len(body) + 1
}
