//! Prints the test vectors of docs/wire-format.md: `cargo run -p daq-protocol --example vectors`.

#[path = "../tests/support/vectors.rs"]
mod vectors;

use daq_protocol::{encode, MAX_FRAME};

fn main() {
    let packed = vectors::packed_example();
    for (name, frame) in vectors::vectors(&packed) {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(&frame, &mut buf).expect("the vectors are valid frames");
        let hex: Vec<String> = buf[..n].iter().map(|b| format!("{b:02x}")).collect();
        println!("{name:<13}{}", hex.join(" "));
    }
}
