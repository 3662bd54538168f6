//! Wire format of the motorid data logger (`no_std`, no allocation).
//!
//! This crate will own the frames exchanged between the logger (the PIC 16F877 of the seed
//! paper's Sec. 3, emulated by `daq-emu`) and the PC over RS-232 at 115200 baud: commands
//! (status, configure, arm a step test, stop, dump, erase), replies (status, sample blocks, end
//! of record, error), framing that resynchronises after garbage, a CRC, sequence numbers, and
//! sample packing at the real bit widths (three 10-bit ADC channels, a 12-bit encoder count).
//! The codec does no I/O: it encodes into a caller's buffer and decodes from bytes fed to it.
#![no_std]
#![warn(missing_docs)]

/// Bits of each ADC sample (the PIC 16F877's converter).
pub const ADC_BITS: u8 = 10;
/// Bits of the encoder counter (MC4040 ripple counter; wraps).
pub const ENCODER_BITS: u8 = 12;
/// Serial line rate of the logger, in baud (the paper prints 115250: a typo for 115200).
pub const BAUD: u32 = 115_200;
