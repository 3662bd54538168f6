//! The codec against its specification: round trips, garbage, corruption, line budget.

use daq_protocol::{
    encode, pack_sample, packed_len, samples_frame_len, Command, DecodeError, Decoder, EncodeError,
    ErrorCode, Frame, Mode, Reply, Sample, State, ALL_CHANNELS, LINE_BYTES_PER_S,
    MAX_BLOCK_SAMPLES, MAX_FRAME,
};
use proptest::prelude::*;

#[path = "support/vectors.rs"]
mod vectors;

/// Feeds `bytes` and collects what the decoder returned at each `00`.
fn decode_all(bytes: &[u8]) -> Vec<Result<String, DecodeError>> {
    let mut d = Decoder::<MAX_FRAME>::new();
    bytes
        .iter()
        .filter_map(|&b| d.feed(b).map(|r| r.map(|f| format!("{f:?}"))))
        .collect()
}

fn block(first: u32, channels: u8, count: usize, seed: u16) -> (Vec<u8>, Vec<Sample>) {
    let mut packed = vec![0u8; packed_len(channels, count)];
    let samples: Vec<Sample> = (0..count as u16)
        .map(|i| {
            let x = i.wrapping_mul(7919).wrapping_add(seed);
            [x & 1023, (x >> 3) & 1023, (x >> 5) & 1023, x & 4095]
        })
        .collect();
    for (i, s) in samples.iter().enumerate() {
        pack_sample(&mut packed, channels, i, s);
    }
    let _ = first;
    (packed, samples)
}

fn all_frames(packed: &[u8]) -> Vec<Frame<'_>> {
    vec![
        Frame::Command {
            seq: 0,
            command: Command::Status,
        },
        Frame::Command {
            seq: 1,
            command: Command::Configure {
                rate_hz: 1000,
                channels: ALL_CHANNELS,
            },
        },
        Frame::Command {
            seq: 2,
            command: Command::Arm {
                millivolts: 40_000,
                duration_ms: 50_000,
                mode: Mode::Record,
            },
        },
        Frame::Command {
            seq: 3,
            command: Command::Arm {
                millivolts: -2_500,
                duration_ms: 1,
                mode: Mode::Live,
            },
        },
        Frame::Command {
            seq: 4,
            command: Command::Stop,
        },
        Frame::Command {
            seq: 5,
            command: Command::Dump { from: 0, count: 0 },
        },
        Frame::Command {
            seq: 255,
            command: Command::Erase,
        },
        Frame::Reply {
            seq: 0,
            reply: Reply::Status {
                state: State::Idle,
                rate_hz: 1000,
                channels: 15,
                stored: 50_001,
            },
        },
        Frame::Reply {
            seq: 7,
            reply: Reply::Samples {
                first: 64,
                channels: ALL_CHANNELS,
                count: 32,
                packed,
            },
        },
        Frame::Reply {
            seq: 8,
            reply: Reply::End { total: 50_001 },
        },
        Frame::Reply {
            seq: 9,
            reply: Reply::Error {
                code: ErrorCode::Busy,
                command: 3,
            },
        },
        Frame::Reply {
            seq: 10,
            reply: Reply::Ack { command: 3, seq: 2 },
        },
    ]
}

#[test]
fn every_frame_round_trips_and_garbage_between_frames_is_skipped() {
    let (packed, samples) = block(64, ALL_CHANNELS, 32, 5);
    let frames = all_frames(&packed);
    let mut line = vec![0x55, 0x13, 0x00, 0xFF, 0x00]; // garbage frames
    for f in &frames {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(f, &mut buf).unwrap();
        assert_eq!(buf[n - 1], 0);
        assert!(!buf[..n - 1].contains(&0));
        line.extend_from_slice(&buf[..n]);
        line.extend_from_slice(&[0x42, 0x42, 0x00]); // garbage frame between
    }
    let got: Vec<_> = decode_all(&line)
        .into_iter()
        .filter_map(Result::ok)
        .collect();
    let want: Vec<_> = frames.iter().map(|f| format!("{f:?}")).collect();
    assert_eq!(got, want);
    // The samples come back.
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(&frames[8], &mut buf).unwrap();
    let mut d = Decoder::<MAX_FRAME>::new();
    let mut checked = false;
    for &b in &buf[..n] {
        if let Some(Ok(Frame::Reply { reply, .. })) = d.feed(b) {
            for (i, s) in samples.iter().enumerate() {
                assert_eq!(reply.sample(i), Some(*s));
            }
            assert_eq!(reply.sample(32), None);
            checked = true;
        }
    }
    assert!(checked);
}

#[test]
fn invalid_frames_are_refused_by_the_encoder() {
    let mut buf = [0u8; MAX_FRAME];
    let bad_len = Frame::Reply {
        seq: 0,
        reply: Reply::Samples {
            first: 0,
            channels: 15,
            count: 2,
            packed: &[0; 3],
        },
    };
    let e = encode(&bad_len, &mut buf).unwrap_err();
    assert!(
        matches!(
            e,
            EncodeError::Invalid {
                field: "packed bytes",
                value: 3
            }
        ),
        "{e}"
    );
    let too_many = Frame::Reply {
        seq: 0,
        reply: Reply::Samples {
            first: 0,
            channels: 1,
            count: 33,
            packed: &[0; 42],
        },
    };
    let e = encode(&too_many, &mut buf).unwrap_err();
    assert_eq!(
        e.to_string(),
        "samples in a block = 33 is out of range for a frame"
    );
    let no_channels = Frame::Command {
        seq: 0,
        command: Command::Configure {
            rate_hz: 1,
            channels: 0,
        },
    };
    assert!(encode(&no_channels, &mut buf).is_err());
    let e = encode(
        &Frame::Command {
            seq: 0,
            command: Command::Status,
        },
        &mut buf[..3],
    )
    .unwrap_err();
    assert!(
        matches!(e, EncodeError::BufferTooSmall { available: 3, .. }),
        "{e}"
    );
}

#[test]
fn a_frame_longer_than_the_buffer_is_dropped_up_to_the_next_delimiter() {
    let mut d = Decoder::<16>::new();
    let mut results = Vec::new();
    for b in core::iter::repeat_n(0x11u8, 40).chain([0u8]) {
        if let Some(r) = d.feed(b) {
            results.push(r.map(|_| ()));
        }
    }
    assert_eq!(results, [Err(DecodeError::Overflow)]);
    let mut buf = [0u8; 32];
    let n = encode(
        &Frame::Command {
            seq: 9,
            command: Command::Stop,
        },
        &mut buf,
    )
    .unwrap();
    let mut got = Vec::new();
    for &b in &buf[..n] {
        if let Some(r) = d.feed(b) {
            got.push(r.map(|f| format!("{f:?}")));
        }
    }
    let want = format!(
        "{:?}",
        Frame::Command {
            seq: 9,
            command: Command::Stop
        }
    );
    assert_eq!(got, [Ok(want)]);
}

/// Acceptance 3 of the acquisition issue: 1,000,000 frames (sample blocks, the longest and
/// most common), each with 1 to 3 bits flipped on the line, none decoded as a frame.
#[test]
fn a_million_corrupted_frames_are_all_detected() {
    let mut rng = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let mut buf = [0u8; MAX_FRAME];
    let mut undetected = 0u32;
    let mut frames = 0u32;
    let mut d = Decoder::<MAX_FRAME>::new();
    for k in 0..1_000_000u32 {
        let count = 1 + (k as usize % MAX_BLOCK_SAMPLES);
        let channels = 1 + (k % 15) as u8;
        let (packed, _) = block(k, channels, count, k as u16);
        let frame = Frame::Reply {
            seq: k as u8,
            reply: Reply::Samples {
                first: k,
                channels,
                count: count as u8,
                packed: &packed,
            },
        };
        let n = encode(&frame, &mut buf).unwrap();
        let flips = 1 + (next() % 3) as usize;
        let mut positions = [usize::MAX; 3];
        for j in 0..flips {
            // Distinct bit positions over the whole frame, delimiter included.
            loop {
                let p = (next() % (8 * n as u64)) as usize;
                if !positions.contains(&p) {
                    positions[j] = p;
                    break;
                }
            }
        }
        for &p in positions.iter().take(flips) {
            buf[p / 8] ^= 1 << (p % 8);
        }
        d.reset();
        for &b in &buf[..n] {
            if let Some(Ok(_)) = d.feed(b) {
                undetected += 1;
            }
        }
        // A flipped delimiter leaves the frame open: close it as the next frame would.
        if let Some(Ok(_)) = d.feed(0) {
            undetected += 1;
        }
        frames += 1;
    }
    assert_eq!(frames, 1_000_000);
    assert_eq!(undetected, 0);
}

/// Acceptance 4: live streaming of 1 kHz × 4 channels in blocks of 32 samples leaves at least
/// 25 % of 115200 baud 8N1 free (the wire spec states 182 bytes per block of 32 samples,
/// 5.69 bytes per sample, 49.4 % of the line).
#[test]
fn live_streaming_leaves_a_quarter_of_the_line_free() {
    let per_block = samples_frame_len(ALL_CHANNELS, MAX_BLOCK_SAMPLES);
    assert_eq!(per_block, 182);
    // And the encoder agrees with the formula, whatever the bytes.
    let (packed, _) = block(0, ALL_CHANNELS, 32, 77);
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(
        &Frame::Reply {
            seq: 1,
            reply: Reply::Samples {
                first: 123_456,
                channels: ALL_CHANNELS,
                count: 32,
                packed: &packed,
            },
        },
        &mut buf,
    )
    .unwrap();
    assert_eq!(n, per_block);
    let bytes_per_s = per_block as f64 * 1000.0 / MAX_BLOCK_SAMPLES as f64;
    let used = bytes_per_s / f64::from(LINE_BYTES_PER_S);
    assert!(used <= 0.75, "{:.1} % of the line", 100.0 * used);
    assert!((used - 0.4937).abs() < 0.0001, "{used}");
}

/// The byte-exact vectors of docs/wire-format.md are what the encoder writes.
#[test]
fn wire_spec_vectors_match_the_encoder() {
    let spec = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/wire-format.md"
    ))
    .unwrap();
    let packed = vectors::packed_example();
    let vectors = vectors::vectors(&packed);
    for (name, frame) in vectors {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(&frame, &mut buf).unwrap();
        let hex: Vec<String> = buf[..n].iter().map(|b| format!("{b:02x}")).collect();
        let line = format!("{name:<13}{}", hex.join(" "));
        assert!(
            spec.contains(&line),
            "docs/wire-format.md lacks the vector\n{line}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]
    /// Arbitrary bytes never make the decoder panic, and everything it accepts re-encodes to
    /// the same bytes.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..700)) {
        let mut d = Decoder::<MAX_FRAME>::new();
        for b in bytes {
            if let Some(Ok(frame)) = d.feed(b) {
                let mut buf = [0u8; MAX_FRAME];
                prop_assert!(encode(&frame, &mut buf).is_ok());
            }
        }
    }

    /// Every command round-trips.
    #[test]
    fn commands_round_trip(seq in any::<u8>(), mv in any::<i32>(), ms in any::<u32>(), from in any::<u32>(), count in any::<u32>(), rate in any::<u16>(), ch in 1u8..=15) {
        for command in [
            Command::Arm { millivolts: mv, duration_ms: ms, mode: Mode::Live },
            Command::Dump { from, count },
            Command::Configure { rate_hz: rate, channels: ch },
        ] {
            let frame = Frame::Command { seq, command };
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(&frame, &mut buf).unwrap();
            prop_assert_eq!(decode_all(&buf[..n]), vec![Ok(format!("{frame:?}"))]);
        }
    }
}
