//! Helpers shared by the end-to-end tests: run the real `motorid` binary.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

pub fn motorid(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(args)
        .output()
        .expect("the motorid binary runs")
}

/// Runs `motorid` with `args`, its standard output connected to `stdout` (a file, `/dev/full`):
/// the output's `stdout` is empty.
pub fn motorid_to(args: &[&str], stdout: std::process::Stdio) -> Output {
    Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(args)
        .stdout(stdout)
        .output()
        .expect("the motorid binary runs")
}

/// Runs `motorid` with `args`, `input` written to its standard input through a pipe, which
/// (unlike a file, which `/dev/stdin` opens afresh) can be read only once.
pub fn motorid_fed(args: &[&str], input: Vec<u8>) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the motorid binary runs");
    let mut pipe = child.stdin.take().expect("piped stdin");
    // Written meanwhile, and closed when done: a child that stops reading does not block it.
    let writer = std::thread::spawn(move || std::io::Write::write_all(&mut pipe, &input));
    let out = child.wait_with_output().expect("waiting for motorid");
    writer.join().expect("the writer thread").ok();
    out
}

/// Runs `motorid` with `args`, killed after `limit`: `None` if it had not finished by then.
pub fn motorid_within(args: &[&str], limit: std::time::Duration) -> Option<Output> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the motorid binary runs");
    // Drain the pipes meanwhile, or a chatty child blocks on a full pipe and looks hung.
    let mut out_pipe = child.stdout.take().expect("piped stdout");
    let mut err_pipe = child.stderr.take().expect("piped stderr");
    let out_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        std::io::Read::read_to_end(&mut out_pipe, &mut buf).ok();
        buf
    });
    let err_reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        std::io::Read::read_to_end(&mut err_pipe, &mut buf).ok();
        buf
    });
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("waiting for motorid") {
            break Some(status);
        }
        if started.elapsed() > limit {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let stdout = out_reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    status.map(|status| Output {
        status,
        stdout,
        stderr,
    })
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Bad input: exit code 2, a one-line error that mentions `needle`, never a panic.
pub fn assert_bad_input(args: &[&str], needle: &str) {
    let out = motorid(args);
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(
        err.contains(needle),
        "{args:?}: `{err}` should mention `{needle}`"
    );
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: not one line: {err}"
    );
}

/// A test's own scratch directory, removed with everything in it when dropped (after a passing
/// test and after a failed assertion alike). `MOTORID_KEEP_SCRATCH=1` keeps it to look at.
pub struct Scratch(tempfile::TempDir);

impl Scratch {
    /// Keeps the directory and its files after the test, e.g. those of a failing case.
    pub fn keep(&mut self) {
        self.0.disable_cleanup(true);
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

/// A new, empty scratch directory named after `name` under the system's temporary directory.
pub fn scratch(name: &str) -> Scratch {
    let keep = std::env::var("MOTORID_KEEP_SCRATCH").is_ok_and(|v| v == "1");
    let dir = tempfile::Builder::new()
        .prefix(&format!("motorid-cli-{name}-"))
        .disable_cleanup(keep)
        .tempdir()
        .expect("a scratch directory can be made");
    if keep {
        eprintln!("scratch directory kept: {}", dir.path().display());
    }
    Scratch(dir)
}

/// The paper's motor (Sec. 4.1) by parameter name: R, L, k, f, J, Ts (SI units).
pub const PAPER_TRUTH: [(&str, f64); 6] = [
    ("R", 0.3),
    ("L", 0.3),
    ("k", 0.15),
    ("f", 0.05),
    ("J", 1.0),
    ("Ts", 0.03),
];

/// `fixtures/motors/small_servo.json` by parameter name: R, L, k, f, J, Ts (SI units).
pub const SMALL_SERVO_TRUTH: [(&str, f64); 6] = [
    ("R", 2.0),
    ("L", 0.002),
    ("k", 0.05),
    ("f", 0.0004),
    ("J", 2e-5),
    ("Ts", 0.004),
];

/// The paper's logger as `simulate` options: 10-bit ADC, 1 LSB noise, 2000-count encoder,
/// speed from the encoder.
pub const LOGGER: [&str; 8] = [
    "--adc-bits",
    "10",
    "--noise-lsb",
    "1",
    "--encoder-cpr",
    "2000",
    "--speed-from",
    "encoder",
];

/// `motorid simulate -o path ARGS...`, which must succeed.
pub fn simulate_to(path: &std::path::Path, args: &[&str]) {
    let mut all = vec!["simulate", "-o", path.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = motorid(&all);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
}

/// The 95 % interval `[lo, hi]` of parameter `name` in a `--json` report.
pub fn interval(report: &serde_json::Value, name: &str) -> (f64, f64) {
    let ci = &report["parameters"][name]["ci95"];
    (
        ci[0].as_f64().unwrap_or(f64::NAN),
        ci[1].as_f64().unwrap_or(f64::NAN),
    )
}

/// Every parameter's 95 % interval in a `--json` report contains its `truth`.
pub fn assert_truth_in_intervals(report: &serde_json::Value, truth: &[(&str, f64)]) {
    for &(name, value) in truth {
        let (lo, hi) = interval(report, name);
        assert!(
            lo <= value && value <= hi,
            "{name}: [{lo}, {hi}] misses {value}"
        );
    }
}

/// A high (12 V) and a low (3 V) step of `fixtures/motors/small_servo.json`, 0.6 s at 5 kHz
/// through [`LOGGER`] (seeds 1 and 2), with `effect` (if any) in the plant, written into `dir`:
/// their paths.
pub fn small_servo_steps(dir: &std::path::Path, effect: Option<&str>) -> [String; 2] {
    [("12", "1"), ("3", "2")].map(|(volts, seed)| {
        let path = dir.join(format!("s{volts}.csv"));
        let mut args = vec![
            "--motor",
            "../../fixtures/motors/small_servo.json",
            "--voltage",
            volts,
            "--duration",
            "0.6",
            "--rate",
            "5000",
            "--seed",
            seed,
            "--quiet",
        ];
        args.extend(LOGGER);
        if let Some(e) = effect {
            args.extend(["--effect", e]);
        }
        simulate_to(&path, &args);
        path.to_str().unwrap().to_string()
    })
}

/// `path` as a C string, for the libc calls of the tests.
#[cfg(unix)]
pub fn c_path(path: &Path) -> std::ffi::CString {
    use std::os::unix::ffi::OsStrExt;
    std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap()
}

/// Makes a FIFO at `path`.
#[cfg(unix)]
pub fn make_fifo(path: &Path) {
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c_path(path).as_ptr(), 0o644) }, 0);
}

/// Makes a copy of the null device (1:3) at `path`: its device number, or why it cannot be
/// made here (mknod of a character device needs the right to).
#[cfg(unix)]
pub fn make_null_device(path: &Path) -> Result<libc::dev_t, std::io::Error> {
    let dev = libc::makedev(1, 3);
    // SAFETY: a valid NUL-terminated path.
    if unsafe { libc::mknod(c_path(path).as_ptr(), libc::S_IFCHR | 0o666, dev) } == 0 {
        Ok(dev)
    } else {
        Err(std::io::Error::last_os_error())
    }
}
