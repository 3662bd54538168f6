//! Acceptance: where `-o`, `--out` and `--plot` write (issue "No silent wrong answers", items 1
//! and 2). A symbolic link is followed and stays a link; a FIFO or a device node is written in
//! place and stays what it was; a write that fails (`/dev/full`, a full file system) or is
//! stopped by a signal leaves the old file and no temporary file; bad paths are refused before
//! any work starts. A report that cannot be written to standard output is an error, not a
//! panic.
#![cfg(unix)]

mod common;

use std::os::unix::fs::{FileTypeExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{
    assert_bad_input, c_path, make_fifo, make_null_device, motorid, motorid_to, scratch,
    small_servo_steps, stderr, stdout,
};

/// `simulate` of a 1 V step for `duration` seconds at 1 kHz to `path`.
fn simulate_to(path: &Path, duration: &str) -> Output {
    motorid(&[
        "simulate",
        "--voltage",
        "1",
        "--duration",
        duration,
        "-o",
        path.to_str().unwrap(),
    ])
}

/// Asserts `text` is the record of a `duration_s` simulation at 1 kHz: the header and one row
/// per sample.
fn assert_record(text: &str, duration_s: f64) {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(
        lines.next(),
        Some("t[s],voltage[V],current[A],speed[rad/s],position[rad]")
    );
    let rows = (duration_s * 1000.0).round() as usize + 1;
    assert_eq!(lines.count(), rows, "rows of the record");
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn a_symlink_is_followed_and_stays_a_link() {
    let dir = scratch("out-symlink");
    std::fs::write(dir.join("real.csv"), "old\n").unwrap();
    std::os::unix::fs::symlink("real.csv", dir.join("link")).unwrap();
    let out = simulate_to(&dir.join("link"), "0.01");
    assert!(out.status.success(), "{}", stderr(&out));
    let link = std::fs::symlink_metadata(dir.join("link")).unwrap();
    assert!(link.file_type().is_symlink(), "the link was replaced");
    assert_eq!(
        std::fs::read_link(dir.join("link")).unwrap(),
        Path::new("real.csv")
    );
    assert_record(
        &std::fs::read_to_string(dir.join("real.csv")).unwrap(),
        0.01,
    );

    // A link to a name not yet taken creates its target.
    std::os::unix::fs::symlink("made.csv", dir.join("dangling")).unwrap();
    let out = simulate_to(&dir.join("dangling"), "0.01");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(dir.join("dangling"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert_record(
        &std::fs::read_to_string(dir.join("made.csv")).unwrap(),
        0.01,
    );
    assert_eq!(names(&dir), ["dangling", "link", "made.csv", "real.csv"]);
}

#[test]
fn a_fifo_is_streamed_to_its_reader() {
    let dir = scratch("out-fifo");
    let fifo = dir.join("fifo");
    make_fifo(&fifo);
    let (sent, received) = std::sync::mpsc::channel();
    {
        let fifo = fifo.clone();
        std::thread::spawn(move || sent.send(std::fs::read_to_string(fifo).unwrap()));
    }
    let out = simulate_to(&fifo, "1");
    assert!(out.status.success(), "{}", stderr(&out));
    // Should motorid never have opened the FIFO, release the reader (it then reads nothing).
    let _ = std::fs::OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(&fifo);
    // A reader still blocked now waits on a FIFO that was replaced: fail instead of hanging.
    let text = received
        .recv_timeout(Duration::from_secs(10))
        .expect("the reader of the FIFO got nothing: was the FIFO replaced?");
    assert_record(&text, 1.0);
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    assert_eq!(names(&dir), ["fifo"]);
}

#[test]
fn a_dash_writes_the_record_to_standard_output_and_no_file() {
    let dir = scratch("out-dash");
    let out = Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(["simulate", "--voltage", "1", "--duration", "1", "-o", "-"])
        .current_dir(&dir)
        .output()
        .expect("the motorid binary runs");
    assert!(out.status.success(), "{}", stderr(&out));
    assert_record(&stdout(&out), 1.0);
    assert!(names(&dir).is_empty(), "files written: {:?}", names(&dir));
}

#[test]
fn a_device_node_is_written_in_place() {
    let dir = scratch("out-device");
    let node = dir.join("null");
    let dev = match make_null_device(&node) {
        Ok(dev) => dev,
        Err(e) => {
            eprintln!("skipped: mknod of a character device is not permitted here ({e})");
            return;
        }
    };
    let out = simulate_to(&node, "1");
    assert!(out.status.success(), "{}", stderr(&out));
    let meta = std::fs::symlink_metadata(&node).unwrap();
    assert!(meta.file_type().is_char_device(), "the device was replaced");
    assert_eq!(meta.rdev(), dev);
    assert_eq!(names(&dir), ["null"]);
}

/// The full device (`/dev/full`, 1:7) as a node of its own in `dir`, so that a regression can
/// only replace that copy; `/dev/full` itself where nodes cannot be made (without that right, a
/// process cannot replace anything in `/dev` either).
fn full_device(dir: &Path) -> PathBuf {
    let node = dir.join("full");
    // SAFETY: a valid NUL-terminated path.
    let made = unsafe {
        libc::mknod(
            c_path(&node).as_ptr(),
            libc::S_IFCHR | 0o666,
            libc::makedev(1, 7),
        )
    };
    if made == 0 {
        node
    } else {
        PathBuf::from("/dev/full")
    }
}

#[test]
fn dev_full_reports_the_full_disk_and_stays_a_device() {
    let dir = scratch("out-full");
    let full = full_device(&dir);
    let before = std::fs::metadata(&full).unwrap();
    assert!(before.file_type().is_char_device());
    let out = simulate_to(&full, "1");
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("cannot write {}", full.display()))
            && err.contains("No space left on device"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    let after = std::fs::metadata(&full).unwrap();
    assert!(
        after.file_type().is_char_device(),
        "the device was replaced"
    );
    assert_eq!((after.ino(), after.rdev()), (before.ino(), before.rdev()));
    let folder = full.parent().unwrap();
    assert!(
        !names(folder).iter().any(|n| n.starts_with(".full.tmp")),
        "a temporary file was left in {}",
        folder.display()
    );
}

#[test]
fn a_report_to_a_full_standard_output_is_an_error_not_a_panic() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full here");
        return;
    }
    let dir = scratch("stdout-full");
    let [high, low] = small_servo_steps(&dir, None);
    let diagnose = [
        "diagnose",
        "--high",
        &high,
        "--low",
        &low,
        "--candidates",
        "quadratic_drag",
        "--max-effects",
        "1",
        "--quiet",
    ];
    let commands = [
        diagnose.to_vec(),
        [&diagnose[..], &["--json"]].concat(),
        vec!["identify", "--high", &high, "--low", &low, "--quiet"],
        vec!["model", "--motor", "../../fixtures/motors/small_servo.json"],
        vec!["model", "--motor", "paper", "--json"],
    ];
    for args in commands {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let out = motorid_to(&args, Stdio::from(full));
        let err = stderr(&out);
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.lines().any(
                |l| l.starts_with("error: cannot write to standard output: ")
                    && l.contains("No space left on device")
            ),
            "{args:?}: {err}"
        );
    }
}

/// Messages (progress, warnings, the error line) to a standard error that cannot be written
/// are dropped: the exit code still says how the command ended, and nothing panics (exit 101
/// before, from `eprintln!`).
#[test]
fn messages_to_a_full_standard_error_do_not_end_the_command() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full here");
        return;
    }
    let dir = scratch("stderr-full");
    let out_csv = dir.join("x.csv");
    let out_csv = out_csv.to_str().unwrap();
    for (args, code) in [
        (
            vec![
                "simulate",
                "--voltage",
                "12",
                "--duration",
                "0.1",
                "-o",
                out_csv,
            ],
            0,
        ),
        (vec!["model", "--motor", "no-such.json"], 2),
    ] {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_motorid"))
            .args(&args)
            .stderr(Stdio::from(full))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(code), "{args:?}");
    }
    assert!(Path::new(out_csv).is_file());
}

/// A tmpfs mounted for the test, unmounted when dropped.
struct Mounted(PathBuf);

impl Drop for Mounted {
    fn drop(&mut self) {
        // SAFETY: a valid NUL-terminated path.
        unsafe { libc::umount2(c_path(&self.0).as_ptr(), libc::MNT_DETACH) };
    }
}

#[test]
fn a_full_file_system_leaves_the_old_file_and_no_temporary_file() {
    let root = scratch("out-fullfs");
    let dir = root.join("small");
    std::fs::create_dir_all(&dir).unwrap();
    let (source, fstype, options) = (c"tmpfs", c"tmpfs", c"size=64k");
    // SAFETY: valid NUL-terminated strings; `data` is the option string tmpfs expects.
    let mounted = unsafe {
        libc::mount(
            source.as_ptr(),
            c_path(&dir).as_ptr(),
            fstype.as_ptr(),
            0,
            options.as_ptr().cast(),
        )
    };
    if mounted != 0 {
        eprintln!(
            "skipped: cannot mount a small tmpfs here ({})",
            std::io::Error::last_os_error()
        );
        return;
    }
    let _mounted = Mounted(dir.clone());
    let target = dir.join("rec.csv");
    std::fs::write(&target, "old\n").unwrap();
    // 5001 samples, about 250 kB: four times what the file system holds.
    let out = simulate_to(&target, "5");
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(err.contains(target.to_str().unwrap()), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "old\n");
    assert_eq!(names(&dir), ["rec.csv"]);
}

#[test]
fn a_signal_during_a_long_write_leaves_the_old_file_and_no_temporary_file() {
    let dir = scratch("out-signal");
    let target = dir.join("rec.csv");
    for (signal, code) in [(libc::SIGTERM, 143), (libc::SIGINT, 130)] {
        std::fs::write(&target, "old\n").unwrap();
        // 2 000 001 samples, about 110 MB: the temporary file exists for about 2 s.
        let mut child = Command::new(env!("CARGO_BIN_EXE_motorid"))
            .args(["simulate", "--voltage", "1", "--duration", "2000"])
            .args(["--rate", "1000", "-o"])
            .arg(&target)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let temp = dir.join(format!(".rec.csv.tmp-{}", child.id()));
        let started = Instant::now();
        while !temp.exists() {
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "no temporary file {} after 60 s",
                temp.display()
            );
            assert!(
                child.try_wait().unwrap().is_none(),
                "motorid ended before its temporary file was seen"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        // SAFETY: sending a signal to our own child, which has not been waited for.
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(code), "signal {signal}: {status:?}");
        assert!(!temp.exists(), "signal {signal}: {} left", temp.display());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old\n");
        assert_eq!(names(&dir), ["rec.csv"]);
    }
}

#[test]
fn bad_output_paths_are_refused_before_any_work() {
    let dir = scratch("out-refused");
    let file = dir.join("file");
    std::fs::write(&file, "not a folder\n").unwrap();
    let (d, f) = (dir.to_str().unwrap(), file.to_str().unwrap());
    let missing = dir.join("no/such/rec.csv");
    let sim = ["simulate", "--voltage", "1", "--duration", "0.01", "-o"];
    assert_bad_input(&[&sim[..], &[d]].concat(), "is a directory");
    assert_bad_input(
        &[&sim[..], &[missing.to_str().unwrap()]].concat(),
        "does not exist",
    );
    std::os::unix::fs::symlink(".", dir.join("to-dir")).unwrap();
    assert_bad_input(
        &[&sim[..], &[dir.join("to-dir").to_str().unwrap()]].concat(),
        "a directory",
    );
    // Before the port is opened: no such port here.
    assert_bad_input(
        &[
            "acquire",
            "--port",
            "/no/such/port",
            "--voltage",
            "1",
            "--duration",
            "1",
            "-o",
            d,
        ],
        "is a directory",
    );
    assert_bad_input(&["fleet", "--out", f, "--motors", "1"], "--out");
    assert_bad_input(&["emps", "--plot", f], "not a directory");

    // identify prints its table before plotting, and demo its tables before writing the
    // records: empty standard output shows the check came first.
    let (hv, lv) = (dir.join("hv.csv"), dir.join("lv.csv"));
    for (volts, path) in [("40", &hv), ("2.5", &lv)] {
        let out = motorid(&[
            "simulate",
            "--voltage",
            volts,
            "--duration",
            "5",
            "-o",
            path.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    for args in [
        vec![
            "identify",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
            "--plot",
            f,
        ],
        vec!["demo", "--out", f],
        vec![
            "diagnose",
            "--high",
            hv.to_str().unwrap(),
            "--low",
            lv.to_str().unwrap(),
            "--plot",
            f,
        ],
    ] {
        let out = motorid(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(&format!("{f}: exists and is not a directory")),
            "{args:?}: {err}"
        );
        assert_eq!(stdout(&out), "", "{args:?} worked before refusing");
    }
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "not a folder\n");
}

/// Spawns `motorid args` with stderr piped and returns the child with the first line it
/// writes there, read within ten seconds (`None` if none came).
fn spawn_with_first_error_line(args: &[&str]) -> (std::process::Child, Option<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_motorid"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the motorid binary runs");
    let err = child.stderr.take().expect("piped stderr");
    let (sent, received) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut err = std::io::BufReader::new(err);
        let mut line = String::new();
        let _ = std::io::BufRead::read_line(&mut err, &mut line);
        let _ = sent.send(line);
        // Drained to the end: a closed pipe would stop the child at its next line.
        let _ = std::io::copy(&mut err, &mut std::io::sink());
    });
    (child, received.recv_timeout(Duration::from_secs(10)).ok())
}

#[test]
fn a_fifo_nobody_opens_is_announced_not_silently_waited_on() {
    // `simulate -o FIFO` with no reader, and `identify --record FIFO` with no writer, waited
    // in open() without a word: to a user, a hang.
    let dir = scratch("fifo-wait");
    let fifo = dir.join("fifo");
    make_fifo(&fifo);
    let path = fifo.to_str().unwrap();
    let (mut writer, line) =
        spawn_with_first_error_line(&["simulate", "--voltage", "1", "--duration", "1", "-o", path]);
    let line = line.unwrap_or_default();
    assert!(
        line.contains("waiting for a program to read it"),
        "{line:?}"
    );
    // The wait ends when a reader comes, and the record arrives whole.
    let text = std::fs::read_to_string(&fifo).unwrap();
    assert!(writer.wait().unwrap().success());
    assert_record(&text, 1.0);

    let (mut reader, line) = spawn_with_first_error_line(&["identify", "--record", path]);
    let line = line.unwrap_or_default();
    assert!(
        line.contains("waiting for a program to write to it"),
        "{line:?}"
    );
    std::fs::write(&fifo, &text).unwrap();
    let status = reader.wait().unwrap();
    // Read as the same record in a file is.
    let file = dir.join("record.csv");
    std::fs::write(&file, &text).unwrap();
    let from_file = motorid(&["identify", "--record", file.to_str().unwrap()]);
    assert_eq!(
        status.code(),
        from_file.status.code(),
        "{}",
        stderr(&from_file)
    );
}

/// `fleet --out DIR` names its motor folders and their records itself: a symbolic link in
/// the way (to a user's file, or to a folder elsewhere) is refused (exit 2), its target left
/// as it was, where the record used to replace the link's target.
#[test]
fn a_fleet_does_not_follow_links_in_the_names_it_makes() {
    let dir = scratch("fleet_links");
    let victim = dir.join("victim.csv");
    std::fs::write(&victim, "keep me").unwrap();
    let out = dir.join("fleet");
    std::fs::create_dir_all(out.join("motor_001")).unwrap();
    std::os::unix::fs::symlink(&victim, out.join("motor_001").join("high.csv")).unwrap();
    let fleet = out.to_str().unwrap();
    let run = common::motorid(&["fleet", "--out", fleet, "--motors", "2"]);
    assert_eq!(run.status.code(), Some(2), "{}", common::stderr(&run));
    assert!(
        common::stderr(&run).contains("high.csv: it is a symbolic link, which is not replaced"),
        "{}",
        common::stderr(&run)
    );
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let linked = dir.join("linked");
    std::fs::create_dir(&linked).unwrap();
    std::os::unix::fs::symlink(&elsewhere, linked.join("motor_001")).unwrap();
    let run = common::motorid(&["fleet", "--out", linked.to_str().unwrap(), "--motors", "2"]);
    assert_eq!(run.status.code(), Some(2), "{}", common::stderr(&run));
    assert_eq!(std::fs::read_dir(&elsewhere).unwrap().count(), 0);
}
