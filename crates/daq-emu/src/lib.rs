//! Firmware core of the motorid data logger, `no_std`, emulated on the host.
//!
//! This crate will own the logger of the seed paper's Sec. 3 (PIC 16F877 at 18.432 MHz,
//! 368 bytes of RAM): a 10-bit ADC sampled at 1 kHz on voltage, current and tachometer speed,
//! a 12-bit wrapping encoder counter, records kept in a 16 Mbit flash, and serial transfer at
//! 115200 baud, written against small hardware traits. On the host (feature `std`) the traits
//! are backed by the `motor-model` simulator and a paced byte pipe.
#![cfg_attr(not(feature = "std"), no_std)]
#![warn(missing_docs)]

pub use daq_protocol::{ADC_BITS, BAUD, ENCODER_BITS};

/// RAM of the PIC 16F877, in bytes: the budget of the firmware core's state.
pub const PIC_RAM_BYTES: usize = 368;
