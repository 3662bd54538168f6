//! Where the CLI's results go. Every file a command writes goes through [`write_generated`] or
//! [`write_with`], and every output path a command line names is checked by [`check`] before
//! any work starts, so a bad `-o`, `--out` or `--plot` fails at once, not after a long fit.
//!
//! What a path names decides how it is written:
//! - `-`: standard output.
//! - a regular file, or a name not yet taken: replaced atomically. The bytes go to a hidden
//!   temporary file beside it (`.NAME.tmp-PID`), which is synced and renamed over the target,
//!   so the target is either the old file or the whole new one. The temporary file is removed
//!   on any error (a full disk) and when SIGINT, SIGTERM or SIGHUP ends the process, which
//!   then exits with 128 + the signal number (130, 143, 129). The old file's permissions are
//!   kept.
//! - a symbolic link: followed to its final target, which is written as above; the link stays.
//! - a character or block device, a FIFO, or an open descriptor (`/dev/stdout`, `/dev/fd/N`):
//!   opened and written directly (streamed), with no temporary file and no rename.
//! - a directory or a socket: refused as bad input (exit code 2).
//!
//! A command's report goes to standard output through [`outln!`], which returns a failure to
//! write (a full disk, a closed descriptor) as an error instead of panicking as `println!`
//! does; a reader that goes away (`| head`) still ends the process quietly by SIGPIPE.
//! Messages go to standard error through [`errln!`], which drops what cannot be written.

use std::ffi::OsString;
use std::fs::{File, OpenOptions, Permissions};
use std::io::{BufWriter, ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

use anyhow::{anyhow, Context, Result};

use crate::errors::BadInput;

/// Symbolic links followed before giving up: Linux's own limit for one path (ELOOP).
const MAX_LINKS: usize = 40;

/// An output path named on the command line, for [`check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Declared {
    /// A file the command will write (`-o FILE`); `-` is standard output.
    File {
        /// The option that named it, for the message (`-o`).
        flag: &'static str,
        /// The path as given.
        path: PathBuf,
    },
    /// A document the command writes and other commands read back (`--save-model M.json`):
    /// only a regular file is replaced or a new name taken; a symbolic link, FIFO or device of
    /// that name is refused (following it would replace another file, or wait for a reader).
    Document {
        /// The option that named it (`--save-model`).
        flag: &'static str,
        /// The path as given.
        path: PathBuf,
    },
    /// A folder the command will write files into, created if missing (`--plot DIR`).
    Dir {
        /// The option that named it (`--plot`, `--out`).
        flag: &'static str,
        /// The path as given.
        path: PathBuf,
    },
}

/// Checks that every declared output can be written: a file's folder exists and is writable
/// and the file is not a directory or socket; a folder is one (writable) or can be created.
/// The error is [`BadInput`] naming the option, the path and what is wrong.
pub fn check(outputs: &[Declared]) -> Result<()> {
    for declared in outputs {
        let (flag, path, verdict) = match declared {
            Declared::File { flag, path } => (flag, path, resolve(path).map(|_| ())),
            Declared::Document { flag, path } => (
                flag,
                path,
                match std::fs::symlink_metadata(path) {
                    Ok(meta) if !meta.file_type().is_file() => Err(not_regular(&meta)),
                    _ => resolve(path).map(|_| ()),
                },
            ),
            Declared::Dir { flag, path } => (
                flag,
                path,
                creatable_dir(path).and_then(|()| blocked_entry(path).map_or(Ok(()), Err)),
            ),
        };
        verdict.map_err(|why| BadInput(format!("{flag} {}: {why}", path.display())))?;
    }
    Ok(())
}

/// Creates the folder `dir` and any missing parents (a folder already there is fine).
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow!("cannot create {}: {e}", dir.display()))
}

/// Extensions of the files commands name themselves inside an output folder (`--plot DIR`,
/// `--out DIR`): figures, summaries.
const GENERATED_EXTENSIONS: [&str; 4] = ["svg", "png", "csv", "json"];

/// Writes `bytes` to `path`, a name the command made up inside an output folder (a figure, a
/// summary): only a regular file there is replaced (atomically, as [`write_with`] does) or a new
/// name taken. A symbolic link, FIFO, device or folder of that name is refused as bad input
/// naming it: unlike a path given on the command line, nobody chose it as the target, and
/// following it would replace another file or wait for a reader without end.
pub fn write_generated(path: &Path, bytes: &[u8]) -> Result<()> {
    write_generated_with(path, |out| Ok(out.write_all(bytes)?))
}

/// [`write_generated`] of what `body` produces, as [`write_with`] writes it.
pub fn write_generated_with(
    path: &Path,
    body: impl FnOnce(&mut dyn Write) -> Result<()>,
) -> Result<()> {
    in_the_way(path, std::fs::FileType::is_file, "cannot write")?;
    write_with(path, body)
}

/// Refuses `path`, a name the command made up, when something other than what `wanted` accepts
/// (never a symbolic link: it is not followed) has that name; `doing` opens the message.
fn in_the_way(path: &Path, wanted: fn(&std::fs::FileType) -> bool, doing: &str) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if !wanted(&meta.file_type()) => Err(BadInput(format!(
            "{doing} {}: {}",
            path.display(),
            not_regular(&meta)
        ))
        .into()),
        _ => Ok(()),
    }
}

/// Creates the folder `dir`, named by the command inside an output folder (a fleet's motor
/// folder), unless something other than a folder — a symbolic link (to a folder elsewhere),
/// a file — has that name: refused as bad input, as [`write_generated`] refuses a file's name.
pub fn create_generated_dir(dir: &Path) -> Result<()> {
    in_the_way(dir, std::fs::FileType::is_dir, "cannot write into")?;
    create_dir(dir)
}

/// Why an entry named by the command itself is not written: what it is, and what to do.
fn not_regular(meta: &std::fs::Metadata) -> String {
    let kind = meta.file_type();
    let what = if kind.is_symlink() {
        "a symbolic link"
    } else if kind.is_dir() {
        "a directory"
    } else {
        "not a regular file (a FIFO, a device or a socket)"
    };
    format!("it is {what}, which is not replaced: move it away or choose another folder")
}

/// The first entry of the folder `dir` (if it exists) with a name the commands write there
/// ([`GENERATED_EXTENSIONS`]) that [`write_generated`] would refuse, and why.
fn blocked_entry(dir: &Path) -> Option<String> {
    let entries = std::fs::read_dir(dir).ok()?;
    entries.flatten().find_map(|entry| {
        let path = entry.path();
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        if !GENERATED_EXTENSIONS.contains(&ext.as_str()) {
            return None;
        }
        let meta = std::fs::symlink_metadata(&path).ok()?;
        (!meta.file_type().is_file())
            .then(|| format!("{} is in the way: {}", path.display(), not_regular(&meta)))
    })
}

/// Writes what `body` produces to `path` as the module overview describes, buffered; `body`
/// may write any amount (nothing is held in memory). A failure names `path` and the cause
/// (`No space left on device`); a replaced file is then left as it was.
pub fn write_with(path: &Path, body: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let target =
        resolve(path).map_err(|why| BadInput(format!("cannot write {}: {why}", path.display())))?;
    match target {
        Target::Stdout => {
            let mut out = BufWriter::new(std::io::stdout().lock());
            body(&mut out)
                .and_then(|()| Ok(out.flush()?))
                .context(crate::console::STDOUT_FAILED)
        }
        Target::Direct(file) => {
            let file = crate::fifo::open_write(&file)
                .with_context(|| format!("cannot open {}", path.display()))?;
            let mut out = BufWriter::new(file);
            body(&mut out)
                .and_then(|()| Ok(out.flush()?))
                .with_context(|| format!("cannot write {}", path.display()))
        }
        Target::Replace(file) => {
            replace(&file, body).with_context(|| format!("cannot write {}", path.display()))
        }
    }
}

/// How a path is written.
#[derive(Debug, PartialEq, Eq)]
enum Target {
    Stdout,
    /// A regular file or a new name (symbolic links resolved): temporary file, then rename.
    Replace(PathBuf),
    /// A device, FIFO or open descriptor: written in place.
    Direct(PathBuf),
}

/// Whether a look-up failed because the path does not exist (a missing part, or a part that is
/// a file: `file.csv/x`); the folder checks then say which.
fn absent(e: &std::io::Error) -> bool {
    matches!(e.kind(), ErrorKind::NotFound | ErrorKind::NotADirectory)
}

/// The folder holding `path` (`.` for a bare name).
fn folder(path: &Path) -> &Path {
    path.parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// How `path` is to be written, or why it cannot be.
fn resolve(path: &Path) -> std::result::Result<Target, String> {
    if path.as_os_str() == "-" {
        return Ok(Target::Stdout);
    }
    if path.as_os_str().as_encoded_bytes().ends_with(b"/") {
        return Err("names a folder; give a file name".into());
    }
    let mut at = path.to_path_buf();
    for _ in 0..=MAX_LINKS {
        let meta = match std::fs::symlink_metadata(&at) {
            Ok(meta) => meta,
            Err(e) if absent(&e) => {
                writable_dir(folder(&at))?;
                return Ok(Target::Replace(at));
            }
            Err(e) => return Err(format!("cannot look at {}: {e}", at.display())),
        };
        let kind = meta.file_type();
        let is = |what: &str| {
            if at == path {
                format!("is {what}")
            } else {
                format!("leads to {}, {what}", at.display())
            }
        };
        if kind.is_symlink() {
            if crate::fifo::is_descriptor(&at) {
                writable(&at)?;
                return Ok(Target::Direct(at));
            }
            let to = std::fs::read_link(&at)
                .map_err(|e| format!("cannot read the link {}: {e}", at.display()))?;
            // A relative link is relative to the folder holding it; `join` keeps an absolute one.
            at = folder(&at).join(to);
        } else if kind.is_file() {
            writable_dir(folder(&at))?;
            return Ok(Target::Replace(at));
        } else if kind.is_dir() {
            return Err(format!("{}; give a file name", is("a directory")));
        } else if is_socket(&kind) {
            return Err(format!(
                "{}; give a file, a FIFO, a device or -",
                is("a socket")
            ));
        } else {
            writable(&at)?;
            return Ok(Target::Direct(at));
        }
    }
    Err(format!(
        "more than {MAX_LINKS} symbolic links to follow (a loop?)"
    ))
}

#[cfg(unix)]
fn is_socket(kind: &std::fs::FileType) -> bool {
    use std::os::unix::fs::FileTypeExt;
    kind.is_socket()
}

#[cfg(not(unix))]
fn is_socket(_: &std::fs::FileType) -> bool {
    false
}

/// Whether this process may write `path` (the kernel's answer, so a read-only file system
/// counts too).
#[cfg(unix)]
fn writable(path: &Path) -> std::result::Result<(), String> {
    use std::os::unix::ffi::OsStrExt;
    let c_path = std::ffi::CString::new(path.as_os_str().as_bytes())
        .map_err(|_| format!("{} holds a NUL byte", path.display()))?;
    // SAFETY: `c_path` is a valid NUL-terminated string that outlives the call.
    if unsafe { libc::access(c_path.as_ptr(), libc::W_OK) } == 0 {
        Ok(())
    } else {
        Err(format!(
            "{} is not writable ({})",
            path.display(),
            std::io::Error::last_os_error()
        ))
    }
}

#[cfg(not(unix))]
fn writable(_: &Path) -> std::result::Result<(), String> {
    Ok(())
}

/// `dir` exists, is a directory (after links) and is writable.
fn writable_dir(dir: &Path) -> std::result::Result<(), String> {
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => writable(dir),
        Ok(_) => Err(format!("{} is not a directory", dir.display())),
        Err(e) if e.kind() == ErrorKind::NotFound => {
            Err(format!("directory {} does not exist", dir.display()))
        }
        Err(e) => Err(format!("cannot look at {}: {e}", dir.display())),
    }
}

/// `dir` is a writable directory, or can be created: its nearest existing ancestor is one.
fn creatable_dir(dir: &Path) -> std::result::Result<(), String> {
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => return writable(dir),
        Ok(_) => return Err("exists and is not a directory".into()),
        Err(e) if !absent(&e) => return Err(e.to_string()),
        Err(_) if std::fs::symlink_metadata(dir).is_ok() => {
            return Err("is a symbolic link to nothing".into())
        }
        Err(_) => {}
    }
    for ancestor in dir.ancestors().skip(1) {
        let ancestor = if ancestor.as_os_str().is_empty() {
            Path::new(".")
        } else {
            ancestor
        };
        match std::fs::metadata(ancestor) {
            Ok(meta) if meta.is_dir() => return writable(ancestor),
            Ok(_) => return Err(format!("{} is not a directory", ancestor.display())),
            Err(e) if absent(&e) => {}
            Err(e) => return Err(format!("cannot look at {}: {e}", ancestor.display())),
        }
    }
    Err("no existing folder to create it in".into())
}

/// Writes `target` through a temporary file beside it, renamed over it once complete.
fn replace(target: &Path, body: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let name = target
        .file_name()
        .ok_or_else(|| anyhow!("{}: not a file name", target.display()))?;
    let mut temp_name = OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".tmp-{}", std::process::id()));
    let old_permissions = std::fs::metadata(target).ok().map(|m| m.permissions());
    let temp = TempFile::create(folder(target).join(temp_name), old_permissions)?;
    {
        let mut out = BufWriter::new(&temp.file);
        body(&mut out)?;
        out.flush()?;
    }
    temp.file.sync_all()?;
    temp.rename_onto(target)
}

/// Temporary files being written, removed by the signal handler if the process is stopped.
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The pending list; a panic elsewhere does not make it unusable.
fn pending() -> MutexGuard<'static, Vec<PathBuf>> {
    PENDING.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A temporary file, registered in [`PENDING`] while it exists; dropped without
/// [`TempFile::rename_onto`], it is removed.
struct TempFile {
    path: PathBuf,
    file: File,
    renamed: bool,
}

impl TempFile {
    fn create(path: PathBuf, permissions: Option<Permissions>) -> Result<Self> {
        remove_on_signals()?;
        // Registered before it exists: a signal at any moment after creation finds it.
        pending().push(path.clone());
        let open = || OpenOptions::new().write(true).create_new(true).open(&path);
        // `create_new` never follows a link planted at the name; a leftover of this name can
        // only be an earlier process's with the same id.
        let file = match open() {
            Err(e) if e.kind() == ErrorKind::AlreadyExists => {
                std::fs::remove_file(&path).and_then(|()| open())
            }
            other => other,
        };
        let file = match file {
            Ok(file) => file,
            Err(e) => {
                pending().retain(|p| p != &path);
                return Err(anyhow!(e));
            }
        };
        let temp = TempFile {
            path,
            file,
            renamed: false,
        };
        if let Some(permissions) = permissions {
            temp.file.set_permissions(permissions)?;
        }
        Ok(temp)
    }

    fn rename_onto(mut self, target: &Path) -> Result<()> {
        // Under the lock: the signal handler either removes the file before the rename or
        // finds it gone from the list, never a renamed-away path.
        let mut list = pending();
        std::fs::rename(&self.path, target)?;
        list.retain(|p| p != &self.path);
        self.renamed = true;
        Ok(())
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.renamed {
            let mut list = pending();
            let _ = std::fs::remove_file(&self.path);
            list.retain(|p| p != &self.path);
        }
    }
}

/// Installs, once, a thread that on SIGINT, SIGTERM or SIGHUP removes the pending temporary
/// files and exits with 128 + the signal number. Installed only once a file is written, so
/// commands that write none keep the default signal actions.
#[cfg(unix)]
fn remove_on_signals() -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    use signal_hook::iterator::Signals;
    static INSTALLED: std::sync::OnceLock<std::result::Result<(), String>> =
        std::sync::OnceLock::new();
    let installed = INSTALLED.get_or_init(|| {
        let (ready, registered) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("remove-temp-files".into())
            .spawn(move || {
                let mut signals = match Signals::new([SIGINT, SIGTERM, SIGHUP]) {
                    Ok(signals) => signals,
                    Err(e) => {
                        let _ = ready.send(Err(e.to_string()));
                        return;
                    }
                };
                let _ = ready.send(Ok(()));
                if let Some(signal) = signals.forever().next() {
                    // The lock is held until the exit: no write can rename a file after this.
                    let list = pending();
                    for path in list.iter() {
                        let _ = std::fs::remove_file(path);
                    }
                    std::process::exit(128 + signal);
                }
            })
            .map_err(|e| e.to_string())?;
        // Wait until the handlers are in place, so that no signal can miss a file.
        registered.recv().map_err(|e| e.to_string())?
    });
    installed
        .clone()
        .map_err(|e| anyhow!("cannot set up the removal of temporary files on signals: {e}"))
}

#[cfg(not(unix))]
fn remove_on_signals() -> Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A new, empty directory removed with its contents when the test ends.
    fn scratch(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("motorid-output-{name}-"))
            .tempdir()
            .unwrap()
    }

    #[test]
    fn links_are_followed_to_their_final_target() {
        let tmp = scratch("links");
        let dir = tmp.path();
        let file = dir.join("real.csv");
        std::fs::write(&file, "old").unwrap();
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("real.csv", dir.join("one")).unwrap();
            std::os::unix::fs::symlink(dir.join("one"), dir.join("two")).unwrap();
            std::os::unix::fs::symlink("missing.csv", dir.join("dangling")).unwrap();
            std::os::unix::fs::symlink("loop", dir.join("loop")).unwrap();
            assert_eq!(
                resolve(&dir.join("two")),
                Ok(Target::Replace(dir.join("real.csv")))
            );
            assert_eq!(
                resolve(&dir.join("dangling")),
                Ok(Target::Replace(dir.join("missing.csv")))
            );
            let err = resolve(&dir.join("loop")).unwrap_err();
            assert!(err.contains("symbolic links"), "{err}");
            assert_eq!(
                resolve(Path::new("/dev/stdout")).map(|t| matches!(t, Target::Direct(_))),
                Ok(true)
            );
        }
        assert_eq!(resolve(Path::new("-")), Ok(Target::Stdout));
        assert_eq!(resolve(&file), Ok(Target::Replace(file.clone())));
        let err = resolve(dir).unwrap_err();
        assert!(err.contains("is a directory"), "{err}");
        let err = resolve(&dir.join("no/such.csv")).unwrap_err();
        assert!(err.contains("does not exist"), "{err}");
        let err = resolve(&file.join("x.csv")).unwrap_err();
        assert!(err.contains("is not a directory"), "{err}");
    }

    #[test]
    fn folders_must_exist_as_folders_or_be_creatable() {
        let tmp = scratch("folders");
        let dir = tmp.path();
        let file = dir.join("file");
        std::fs::write(&file, "x").unwrap();
        assert_eq!(creatable_dir(dir), Ok(()));
        assert_eq!(creatable_dir(&dir.join("a/b/c")), Ok(()));
        assert!(creatable_dir(&file)
            .unwrap_err()
            .contains("not a directory"));
        assert!(creatable_dir(&file.join("sub"))
            .unwrap_err()
            .contains("is not a directory"));
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary_file() {
        let tmp = scratch("failed");
        let dir = tmp.path();
        let file = dir.join("rec.csv");
        std::fs::write(&file, "old").unwrap();
        let err = write_with(&file, |out| {
            out.write_all(b"new, half")?;
            Err(anyhow!("the record failed halfway"))
        })
        .unwrap_err();
        assert!(format!("{err:#}").contains("cannot write"), "{err:#}");
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
        assert!(!pending().iter().any(|p| p.starts_with(dir)));
        write_generated(&file, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "new");
        assert_eq!(std::fs::read_dir(dir).unwrap().count(), 1);
    }
}
