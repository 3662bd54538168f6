//! The frames of the test vectors in docs/wire-format.md (shared by the codec test and the
//! `vectors` example, which prints them).

use daq_protocol::{pack_sample, Command, ErrorCode, Frame, Mode, Reply, State, ALL_CHANNELS};

/// The two packed samples of the spec's packing example.
pub fn packed_example() -> [u8; 11] {
    let mut packed = [0u8; 11];
    pack_sample(&mut packed, ALL_CHANNELS, 0, &[512, 100, 1023, 4095]);
    pack_sample(&mut packed, ALL_CHANNELS, 1, &[0, 1, 2, 3]);
    packed
}

/// Name and frame of each vector, in the spec's order.
pub fn vectors(packed: &[u8]) -> Vec<(&'static str, Frame<'_>)> {
    vec![
        (
            "status",
            Frame::Command {
                seq: 0,
                command: Command::Status,
            },
        ),
        (
            "configure",
            Frame::Command {
                seq: 1,
                command: Command::Configure {
                    rate_hz: 1000,
                    channels: 15,
                },
            },
        ),
        (
            "arm",
            Frame::Command {
                seq: 2,
                command: Command::Arm {
                    millivolts: 40_000,
                    duration_ms: 50_000,
                    mode: Mode::Record,
                },
            },
        ),
        (
            "dump",
            Frame::Command {
                seq: 3,
                command: Command::Dump { from: 0, count: 0 },
            },
        ),
        (
            "status_reply",
            Frame::Reply {
                seq: 0,
                reply: Reply::Status {
                    state: State::Idle,
                    rate_hz: 1000,
                    channels: 15,
                    stored: 50_001,
                },
            },
        ),
        (
            "samples",
            Frame::Reply {
                seq: 1,
                reply: Reply::Samples {
                    first: 0,
                    channels: 15,
                    count: 2,
                    packed,
                },
            },
        ),
        (
            "end",
            Frame::Reply {
                seq: 2,
                reply: Reply::End { total: 50_001 },
            },
        ),
        (
            "error",
            Frame::Reply {
                seq: 3,
                reply: Reply::Error {
                    code: ErrorCode::Busy,
                    command: 3,
                },
            },
        ),
    ]
}
