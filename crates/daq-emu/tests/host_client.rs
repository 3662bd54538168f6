//! The host side of the protocol (`daq_protocol::host`) against the emulated logger, in
//! process: every sample arrives as `motorid simulate` computes it, through a clean line and
//! through a faulty one.

use std::io;
use std::time::Duration;

use daq_emu::host::{Emulator, LineFaults, Plant};
use daq_protocol::host::{acquire, to_record, Calibration, Link, TestPlan};
use motor_model::Record;

/// The emulator as a link, in-process: what is sent is received by the firmware, which
/// then runs until it has nothing to do.
pub struct EmulatorLink {
    pub emulator: Emulator,
    pending: Vec<u8>,
}

impl EmulatorLink {
    pub fn new(emulator: Emulator) -> Self {
        EmulatorLink {
            emulator,
            pending: Vec::new(),
        }
    }
}

impl Link for EmulatorLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        if self.emulator.line_closed() {
            return Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the line is closed",
            ));
        }
        self.emulator.receive(bytes);
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], _timeout: Duration) -> io::Result<usize> {
        if self.pending.is_empty() {
            self.pending = self.emulator.run(Duration::from_secs(5));
        }
        let n = self.pending.len().min(buf.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.drain(..n);
        Ok(n)
    }
}

fn plan(volts: f64, live: bool) -> TestPlan {
    TestPlan {
        volts,
        duration_s: 2.0,
        rate_hz: 1000,
        live,
    }
}

/// What `motorid simulate` gives with the emulator's measurement settings.
fn simulated(volts: f64, seed: u64) -> Record {
    let cal = Calibration::default();
    let trace = motor_model::simulate(
        &motor_model::MotorParams::paper(),
        motor_model::Effects::none(),
        &motor_model::Input::step(volts, 0.0).unwrap(),
        2.0,
        1000.0,
    )
    .unwrap();
    cal.measurement(1.0, seed).unwrap().apply(&trace).unwrap()
}

#[test]
fn a_clean_line_gives_simulate_sample_for_sample_in_both_modes() {
    let mut link = EmulatorLink::new(Emulator::new(Plant::default(), false));
    for (k, live) in [(0u64, false), (1, true)] {
        let got = acquire(&mut link, &plan(40.0, live), |_| {}).unwrap();
        assert_eq!(got.samples.len(), 2001);
        assert_eq!(got.stats.retries, 0);
        let record = to_record(&got, &Calibration::default());
        assert_eq!(record, simulated(40.0, 1 + k), "live = {live}");
    }
}

#[test]
fn bit_errors_and_dropped_bytes_are_recovered_by_retransmission() {
    for faults in [
        LineFaults {
            bit_error_rate: 1e-3,
            seed: 3,
            ..LineFaults::default()
        },
        LineFaults {
            drop_rate: 1e-3,
            seed: 4,
            ..LineFaults::default()
        },
    ] {
        for live in [false, true] {
            let emulator = Emulator::new(Plant::default(), false).with_faults(faults);
            let mut link = EmulatorLink::new(emulator);
            let got = acquire(&mut link, &plan(40.0, live), |_| {}).unwrap();
            assert!(
                got.stats.bad_frames + got.stats.lost_frames > 0,
                "{faults:?}: no fault seen"
            );
            assert!(got.stats.retries > 0, "{faults:?}, live {live}");
            let record = to_record(&got, &Calibration::default());
            assert_eq!(
                record,
                simulated(40.0, 1),
                "{faults:?}, live {live}: a wrong sample"
            );
        }
    }
}

#[test]
fn a_line_closed_during_the_dump_is_an_error_that_says_what_was_lost() {
    let faults = LineFaults {
        close_after: Some(3000),
        ..LineFaults::default()
    };
    let emulator = Emulator::new(Plant::default(), false).with_faults(faults);
    let mut link = EmulatorLink::new(emulator);
    let err = acquire(&mut link, &plan(40.0, false), |_| {}).unwrap_err();
    let text = err.to_string();
    eprintln!("{text}");
    assert!(
        text.contains("samples not received (first missing: sample"),
        "{text}"
    );
    assert!(text.contains("nothing written"), "{text}");
}
