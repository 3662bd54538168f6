//! Named FIFOs given as files: opening one waits until another program opens its other end,
//! which to a user looks like a hang. These opens say on standard error what they wait for
//! when the other end is not there yet (Ctrl-C still stops them), and open at once when it is.
//! Open descriptors (`/dev/fd/N`, `/proc/…/fd/N`, as `<(…)` gives) are pipes whose other end
//! exists: they are opened as they are, without a word.

use std::fs::File;
use std::path::Path;

/// `/dev/fd/N`, `/proc/self/fd/N`, `/proc/PID/fd/N`: a link naming an open descriptor (a pipe,
/// a terminal), which must be opened as such, not followed by name.
pub fn is_descriptor(path: &Path) -> bool {
    path.parent().is_some_and(|fd| {
        fd == Path::new("/dev/fd") || (fd.ends_with("fd") && fd.starts_with("/proc"))
    })
}

/// Whether `path` names a FIFO by name (links followed; not an open descriptor).
#[cfg(unix)]
fn is_named_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    !is_descriptor(path) && std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

/// How long an open waits silently for the other end before saying so \[ms\].
#[cfg(unix)]
const QUIET_WAIT_MS: i32 = 200;

/// Opens `path` for reading. A named FIFO with no writer yet is announced first
/// ("waiting for a program to write to it"), then waited for.
pub fn open_read(path: &Path) -> std::io::Result<File> {
    #[cfg(unix)]
    if is_named_fifo(path) {
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::OpenOptionsExt;
        // Opened without waiting, only to see whether a writer is there (data or its end come
        // within the quiet wait); kept open until the real open below has returned, so a
        // writer that it let through is never left without a reader.
        let probe = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)?;
        let mut poll = libc::pollfd {
            fd: probe.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: `poll` points at one valid pollfd whose descriptor `probe` keeps open.
        let ready = unsafe { libc::poll(&mut poll, 1, QUIET_WAIT_MS) } > 0;
        if !ready {
            crate::console::errln!(
                "{} is a FIFO: waiting for a program to write to it (Ctrl-C to stop)",
                path.display()
            );
        }
        let file = File::open(path);
        drop(probe);
        return file;
    }
    File::open(path)
}

/// Opens `path` (a device, FIFO or open descriptor) for writing in place. A named FIFO with no
/// reader yet is announced first ("waiting for a program to read it"), then waited for.
pub fn open_write(path: &Path) -> std::io::Result<File> {
    let open = || std::fs::OpenOptions::new().write(true).open(path);
    #[cfg(unix)]
    if is_named_fifo(path) {
        use std::os::unix::fs::OpenOptionsExt;
        // Without waiting, a FIFO that no program reads refuses the open (ENXIO).
        let probe = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path);
        match probe {
            Err(e) if e.raw_os_error() == Some(libc::ENXIO) => crate::console::errln!(
                "{} is a FIFO: waiting for a program to read it (Ctrl-C to stop)",
                path.display()
            ),
            Err(e) => return Err(e),
            Ok(probe) => {
                let file = open();
                drop(probe);
                return file;
            }
        }
    }
    open()
}
