//! Fuzz target: arbitrary bytes into the frame decoder (`cargo +nightly fuzz run decoder` from
//! crates/daq-protocol). It must never panic, and every frame it accepts must re-encode.
#![no_main]

use daq_protocol::{encode, Decoder, MAX_FRAME};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut decoder = Decoder::<MAX_FRAME>::new();
    for &b in data {
        if let Some(Ok(frame)) = decoder.feed(b) {
            let mut out = [0u8; MAX_FRAME];
            assert!(encode(&frame, &mut out).is_ok());
        }
    }
});
