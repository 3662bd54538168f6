//! The hardware the firmware drives, as small traits: a microcontroller port implements them
//! on its registers; the host emulator ([`crate::host`], feature `std`) on the `motor-model`
//! simulator and a byte pipe.

/// The 10-bit ADC behind the 0–5 V conditioning of voltage (channel 0), current (1) and
/// tachometer speed (2).
pub trait Adc {
    /// Converts `channel` now; the code is 0–1023.
    fn read_adc(&mut self, channel: u8) -> u16;
}

/// The quadrature encoder's 12-bit ripple counter (MC4040), latched by the 74HC374 buffers.
pub trait Encoder {
    /// The latched count, 0–4095 (it wraps).
    fn read_count(&mut self) -> u16;
}

/// The power stage that applies the test voltage to the armature.
pub trait Drive {
    /// Applies `millivolts` (0: off).
    fn apply_millivolts(&mut self, millivolts: i32);
}

/// The record store (the paper's 16 Mbit Dallas DS1270).
pub trait Flash {
    /// Capacity \[bytes\].
    fn capacity(&self) -> u32;
    /// Writes `data` at `address`.
    fn write(&mut self, address: u32, data: &[u8]);
    /// Reads `out.len()` bytes from `address`.
    fn read(&mut self, address: u32, out: &mut [u8]);
}

/// The serial port (115200 baud 8N1).
pub trait Uart {
    /// Queues `byte` for sending; `false` if the transmitter is busy (try again later).
    fn write_byte(&mut self, byte: u8) -> bool;
    /// A received byte, if one is waiting.
    fn read_byte(&mut self) -> Option<u8>;
}

/// The sample timer.
pub trait Timer {
    /// Starts `ticks` ticks at `rate_hz` (a count-down timer); the sample of the start
    /// itself is the caller's.
    fn start_timer(&mut self, rate_hz: u16, ticks: u32);
    /// Stops ticking.
    fn stop_timer(&mut self);
    /// Whether a tick has come since the last call (a sample is due).
    fn sample_due(&mut self) -> bool;
}
