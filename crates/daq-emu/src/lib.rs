//! Firmware core of the motorid data logger, `no_std`, emulated on the host.
//!
//! The logger of the seed paper's Sec. 3 (PIC 16F877 at 18.432 MHz, 368 bytes of RAM): a 10-bit
//! ADC sampled at 1 kHz (configurable) on voltage, current and tachometer speed, a 12-bit
//! wrapping encoder counter, records kept in a 16 Mbit flash, and serial transfer at 115200
//! baud 8N1, written against small hardware traits ([`hw`]). [`Firmware`] is the whole state;
//! its size is checked against the PIC's RAM by a test. (Encoding a sample block uses about
//! 0.5 KiB of stack for the packed samples and the frame body; a PIC port would stream the
//! frame out byte by byte instead.)
//!
//! On the host (feature `std`, the default) [`host`] backs the traits with the `motor-model`
//! simulator (effects switchable) and a byte pipe that runs unpaced or at the real baud rate.
#![cfg_attr(not(feature = "std"), no_std)]
#![warn(missing_docs)]

mod firmware;
#[cfg(feature = "std")]
pub mod host;
pub mod hw;

pub use daq_protocol::{ADC_BITS, BAUD, ENCODER_BITS, FLASH_BYTES, MAX_RATE_HZ, SAMPLE_BYTES};
pub use firmware::{Board, Firmware, MAX_COMMAND_FRAME};

/// RAM of the PIC 16F877, in bytes: the budget of the firmware core's state.
pub const PIC_RAM_BYTES: usize = 368;

#[cfg(test)]
extern crate std;

#[cfg(test)]
mod tests {
    #[test]
    fn the_firmware_state_fits_the_pic_ram() {
        let size = core::mem::size_of::<super::Firmware>();
        std::println!("firmware state: {size} bytes");
        assert!(
            size <= super::PIC_RAM_BYTES,
            "the firmware state takes {size} bytes, the PIC 16F877 has {}",
            super::PIC_RAM_BYTES
        );
    }
}
