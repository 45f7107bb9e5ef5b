//! Output files: the one rule every writer of jointid follows (`simulate --out`,
//! `--params-out`, `export --csv`, `fit --save`, the SVG files of `--plot`, `demo`), the
//! rule `capture` applies to its `.jcap`:
//!
//! - an existing file is refused unless overwriting was asked for (`--force`),
//!   [`OutputError::Exists`], and even then while a capture writes it (it holds the
//!   file's lock), [`OutputError::Locked`];
//! - a directory is never an output file, and the file's directory must exist and be
//!   writable; [`check_output`] says so before any work is done;
//! - the file appears whole or not at all: [`write_file`] writes a temporary file in the
//!   same directory, flushes it to disk and renames it over the target; on any failure
//!   the temporary file is removed and the target left as it was.
//!
//! - a file whose size is known before the work (`simulate --out`) must fit in the free
//!   space of its file system: [`check_room`].
//!
//! Temporary files (`DIR/.NAME.PID.tmp`) never outlive their process when it can help it:
//! those being written are listed, so that an interrupt handler (Ctrl-C, SIGTERM: the
//! command line's) removes them with [`remove_temporaries`] before the process ends; and
//! one left by a process that no longer runs (killed by SIGKILL, a power cut) is removed
//! by the next [`check_output`] or [`write_file`] of the same file, and listed for the
//! caller to report ([`take_stale_removed`]).
//!
//! A path that exists and is neither a regular file nor a directory (a terminal, a named
//! pipe, `/dev/null`, `/dev/full`) is written in place, opened for appending, without the
//! temporary file: it holds nothing to protect and cannot be replaced; so is a path that
//! names one of the process's descriptors ([`names_descriptor`]: `/dev/stdout`,
//! `/dev/fd/N`), whatever it leads to (standard output redirected to a file with `>` or
//! `>>` gets the output where the shell put it). A symbolic link to a regular file is
//! followed: the file it names is replaced, not the link.

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use super::input::path_text;

/// Why an output file cannot be (or was not) written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    /// The file exists and overwriting was not asked for.
    #[error("{}: already exists (pass --force to overwrite)", path_text(path))]
    Exists {
        /// the file
        path: PathBuf,
    },
    /// The path names a directory.
    #[error("{}: is a directory, not a file", path_text(path))]
    IsDirectory {
        /// the path
        path: PathBuf,
    },
    /// The file's directory does not exist (or is not a directory).
    #[error("{}: directory {} does not exist", path_text(path), path_text(dir))]
    NoDirectory {
        /// the file
        path: PathBuf,
        /// its directory
        dir: PathBuf,
    },
    /// The file's directory exists but a file cannot be created in it.
    #[error(
        "{}: directory {} is not writable: {}",
        path_text(path),
        path_text(dir),
        io_msg(err)
    )]
    NotWritable {
        /// the file
        path: PathBuf,
        /// its directory
        dir: PathBuf,
        /// what the operating system said
        err: io::Error,
    },
    /// The file would not fit in the free space of its file system ([`check_room`]).
    #[error(
        "{}: about {} to write, more than the {} free on the file system of {}",
        path_text(path),
        fmt_bytes(*needed),
        fmt_bytes(*free),
        path_text(dir)
    )]
    NoRoom {
        /// the file
        path: PathBuf,
        /// its directory
        dir: PathBuf,
        /// the file's expected size [bytes]
        needed: u64,
        /// the space an unprivileged user may still fill there [bytes]
        free: u64,
    },
    /// A capture is writing the file: it holds the file's exclusive lock
    /// (`jointid capture`); replacing it would drop what the capture writes.
    #[error(
        "{}: a capture is writing this file (it holds the file's lock); stop it first or \
         choose another output",
        path_text(path)
    )]
    Locked {
        /// the file
        path: PathBuf,
    },
    /// Two outputs of one command name the same file ([`check_distinct`]).
    #[error(
        "{}: is both {first} and {second}: one would replace the other; name two files",
        path_text(path)
    )]
    SameFile {
        /// the file, as the second output names it
        path: PathBuf,
        /// what the first output is (`--out`, `--report`)
        first: String,
        /// what the second output is (`--params-out`, `--plot`'s `fig-frf.svg`)
        second: String,
    },
    /// Writing, flushing or renaming failed.
    #[error("{}: {}", path_text(path), io_msg(err))]
    Io {
        /// the file
        path: PathBuf,
        /// what the operating system said (the source: a closed pipe is told by its kind)
        #[source]
        err: io::Error,
    },
}

/// An I/O error as one lowercase phrase without the `(os error N)` suffix.
pub fn io_msg(e: &io::Error) -> String {
    let mut m = e.to_string();
    if let Some(i) = m.find(" (os error ") {
        m.truncate(i);
    }
    if let Some(first) = m.get(..1) {
        let lower = first.to_lowercase();
        m.replace_range(..1, &lower);
    }
    m
}

/// A size in bytes for people: `731 B`, `3.6 kB`, `36.5 TB` (decimal prefixes, three
/// significant digits).
pub fn fmt_bytes(n: u64) -> String {
    const UNITS: [&str; 6] = ["kB", "MB", "GB", "TB", "PB", "EB"];
    if n < 1000 {
        return format!("{n} B");
    }
    let mut v = n as f64;
    let mut unit = "B";
    for u in UNITS {
        if v < 1000.0 {
            break;
        }
        v /= 1000.0;
        unit = u;
    }
    let digits = if v < 10.0 {
        2
    } else if v < 100.0 {
        1
    } else {
        0
    };
    format!("{v:.digits$} {unit}")
}

/// The bytes an unprivileged user may still write on the file system that holds `dir`
/// (`statvfs`: available blocks × fragment size); `None` where that is unknown (not
/// Unix, or the call failed).
pub fn free_space(dir: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
        let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
        // SAFETY: `c` is a NUL-terminated path and `st` points to writable memory of the
        // struct's size; `statvfs` fills it completely when it returns 0.
        let rc = unsafe { libc::statvfs(c.as_ptr(), st.as_mut_ptr()) };
        if rc != 0 {
            return None;
        }
        // SAFETY: initialised by the successful call above
        let st = unsafe { st.assume_init() };
        // the field types differ between platforms (u32 on some, u64 on others)
        #[allow(clippy::unnecessary_cast)]
        Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        None
    }
}

/// Checks, before any work, that a file of about `bytes` fits at `path`: at most the free
/// space of its directory's file system ([`free_space`]). A device or pipe (a stream,
/// `/dev/stdout`) and a file system whose free space is unknown are not checked. An
/// existing file being replaced does not count as free: the new one is written beside it
/// first.
///
/// # Errors
/// [`OutputError::NoRoom`] with both figures; [`OutputError::Io`] when the path cannot be
/// examined.
pub fn check_room(path: &Path, bytes: u64) -> Result<(), OutputError> {
    let target = match existing(path)? {
        Existing::Special(_) => return Ok(()),
        Existing::File(resolved) => resolved,
        Existing::Nothing => path.to_path_buf(),
    };
    let dir = dir_of(&target);
    match free_space(&dir) {
        Some(free) if bytes > free => Err(OutputError::NoRoom {
            path: path.to_path_buf(),
            dir,
            needed: bytes,
            free,
        }),
        _ => Ok(()),
    }
}

/// The directory a file `path` goes into (`.` for a bare file name).
fn dir_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// The descriptor of this process that `path` names, if it names one: an entry `N` of
/// its descriptor directory (`/dev/fd/N`, `/proc/self/fd/N`), or a link to one
/// (`/dev/stdout` → `/proc/self/fd/1`). Told by the file system, not by the spelling.
fn descriptor_of(path: &Path) -> Option<u32> {
    let in_fd_dir = |p: &Path| -> Option<u32> {
        let n = p.file_name()?.to_str()?.parse().ok()?;
        let dir = std::fs::canonicalize(p.parent()?).ok()?;
        let ours = ["/proc/self/fd", "/dev/fd"]
            .iter()
            .filter_map(|d| std::fs::canonicalize(d).ok())
            .any(|d| d == dir);
        ours.then_some(n)
    };
    // a link to an entry (a descriptor's own link leads to `pipe:[…]`, not absolute)
    let linked = std::fs::read_link(path)
        .ok()
        .filter(|t| t.is_absolute())
        .and_then(|t| in_fd_dir(&t));
    linked.or_else(|| in_fd_dir(path))
}

/// Whether `path` names one of the process's descriptors (`/dev/stdout`, `/dev/fd/N`,
/// `/proc/self/fd/N`): written in place, whatever it leads to.
pub fn names_descriptor(path: &Path) -> bool {
    descriptor_of(path).is_some()
}

/// Whether `path` names this process's standard output (`/dev/stdout`, `/dev/fd/1`,
/// `/proc/self/fd/1`): a command writing there prints its report elsewhere.
pub fn names_standard_output(path: &Path) -> bool {
    descriptor_of(path) == Some(1)
}

/// Whether `path` is written in place ([`write_file`]): it exists and is a device or a
/// pipe, or it names a descriptor ([`names_descriptor`]).
///
/// # Errors
/// [`OutputError::IsDirectory`], [`OutputError::Io`] when the path cannot be examined.
pub fn is_stream(path: &Path) -> Result<bool, OutputError> {
    Ok(matches!(existing(path)?, Existing::Special(_)))
}

/// What an existing path is.
enum Existing {
    /// nothing there
    Nothing,
    /// a regular file (through a symlink: the file it names)
    File(PathBuf),
    /// a device, a pipe, a descriptor: written in place (the path as given: a pipe's
    /// `/dev/stdout` resolves to no file)
    Special(PathBuf),
}

fn existing(path: &Path) -> Result<Existing, OutputError> {
    let io = |err| OutputError::Io {
        path: path.to_path_buf(),
        err,
    };
    if names_descriptor(path) {
        return match std::fs::metadata(path) {
            Ok(m) if m.is_dir() => Err(OutputError::IsDirectory {
                path: path.to_path_buf(),
            }),
            Ok(_) => Ok(Existing::Special(path.to_path_buf())),
            Err(e) => Err(io(e)),
        };
    }
    match std::fs::metadata(path) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                // a dangling link: replacing it would write somewhere unexpected
                return Err(io(e));
            }
            Ok(Existing::Nothing)
        }
        Err(e) => Err(io(e)),
        Ok(m) if m.is_dir() => Err(OutputError::IsDirectory {
            path: path.to_path_buf(),
        }),
        Ok(m) if m.is_file() => Ok(Existing::File(std::fs::canonicalize(path).map_err(io)?)),
        Ok(_) => Ok(Existing::Special(path.to_path_buf())),
    }
}

/// The temporary files this process is writing: created, and renamed or removed, only
/// while the list is locked, so that [`remove_temporaries`] sees every one that exists.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Stale temporary files removed so far ([`take_stale_removed`]).
static STALE_REMOVED: Mutex<Vec<StaleTemporary>> = Mutex::new(Vec::new());

/// Locks a list, whatever a thread that panicked holding it left in it.
fn locked<T>(m: &'static Mutex<T>) -> MutexGuard<'static, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The list of temporary files, held: while it lives no temporary file is created,
/// renamed or removed by [`write_file`] (an interrupt handler keeps it until the process
/// exits).
#[derive(Debug)]
pub struct TemporariesRemoved {
    _held: MutexGuard<'static, Vec<PathBuf>>,
    /// the temporary files removed
    pub removed: Vec<PathBuf>,
}

/// Removes every temporary file this process is writing (for an interrupt handler: the
/// outputs being written then never appear, and leave nothing behind); the returned
/// guard keeps new ones from being made while it lives.
pub fn remove_temporaries() -> TemporariesRemoved {
    let mut held = locked(&TEMPORARIES);
    let removed = held
        .drain(..)
        .filter(|p| std::fs::remove_file(p).is_ok())
        .collect();
    TemporariesRemoved {
        _held: held,
        removed,
    }
}

/// A temporary file of an output that a process which no longer runs left behind, removed
/// by [`check_output`] or [`write_file`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StaleTemporary {
    /// the temporary file
    pub path: PathBuf,
    /// the process that wrote it
    pub pid: u32,
    /// its size [bytes]
    pub bytes: u64,
}

impl std::fmt::Display for StaleTemporary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: removed, a temporary file of {} left by process {}, which no longer runs",
            path_text(&self.path),
            fmt_bytes(self.bytes),
            self.pid
        )
    }
}

/// The stale temporary files removed since the last call (for the caller to report).
pub fn take_stale_removed() -> Vec<StaleTemporary> {
    std::mem::take(&mut *locked(&STALE_REMOVED))
}

/// Whether process `pid` runs (Unix: `kill(pid, 0)`); `true` where that cannot be told,
/// so that nothing another process may still be writing is removed.
fn process_runs(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(p) = libc::pid_t::try_from(pid) else {
            return true;
        };
        if p <= 0 {
            return true;
        }
        // SAFETY: signal 0 sends nothing; the call only checks that the process exists
        if unsafe { libc::kill(p, 0) } == 0 {
            return true;
        }
        io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Removes the temporary files of `target` (`.NAME.PID.tmp` beside it) whose process no
/// longer runs, and one with this process's id that this process is not writing (a
/// process of the same id before it); records them for [`take_stale_removed`].
fn remove_stale_temporaries(target: &Path) {
    let Some(name) = target.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let prefix = format!(".{name}.");
    let Ok(entries) = std::fs::read_dir(dir_of(target)) else {
        return;
    };
    let held = locked(&TEMPORARIES);
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let file_name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = file_name
            .strip_prefix(&prefix)
            .and_then(|r| r.strip_suffix(".tmp"))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        let path = e.path();
        let ours = pid == std::process::id();
        if (ours && held.contains(&path)) || (!ours && process_runs(pid)) {
            continue;
        }
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.is_file() && std::fs::remove_file(&path).is_ok() {
            removed.push(StaleTemporary {
                path,
                pid,
                bytes: meta.len(),
            });
        }
    }
    drop(held);
    locked(&STALE_REMOVED).extend(removed);
}

/// Refuses to replace `file` (an existing regular file) while another process holds its
/// exclusive lock: a capture writing its `.jcap` (`jointid capture`) keeps writing
/// into the file a rename took away, and its samples would be lost.
fn check_unlocked(path: &Path, file: &Path) -> Result<(), OutputError> {
    let Ok(f) = std::fs::File::open(file) else {
        return Ok(());
    };
    match f.try_lock_shared() {
        Err(std::fs::TryLockError::WouldBlock) => Err(OutputError::Locked {
            path: path.to_path_buf(),
        }),
        _ => Ok(()),
    }
}

/// The file `path` names as an output, told apart by the file system: the file a link
/// leads to, or the new file's name in its directory resolved (`./x.csv` is `x.csv`);
/// `None` for a stream (a device, a pipe, `/dev/stdout`), which may take two outputs.
fn output_identity(path: &Path) -> Option<PathBuf> {
    match existing(path) {
        Ok(Existing::Special(_)) => None,
        Ok(Existing::File(resolved)) => Some(resolved),
        Ok(Existing::Nothing) | Err(_) => Some(
            match (std::fs::canonicalize(dir_of(path)), path.file_name()) {
                (Ok(dir), Some(name)) => dir.join(name),
                _ => path.to_path_buf(),
            },
        ),
    }
}

/// Checks, before any work, that no two of one command's outputs name the same file
/// (`--out x.csv --params-out ./x.csv`, `--report` inside the `--plot` directory under a
/// figure's name): with `--force` one would replace the other and the command would say
/// it wrote both. Each output is `(what, path)`, `what` naming it in the message.
///
/// # Errors
/// [`OutputError::SameFile`] naming the file and both outputs.
pub fn check_distinct(outputs: &[(String, PathBuf)]) -> Result<(), OutputError> {
    let mut seen: Vec<(&str, PathBuf)> = Vec::new();
    for (what, path) in outputs {
        let Some(id) = output_identity(path) else {
            continue;
        };
        if let Some((first, _)) = seen.iter().find(|(_, other)| *other == id) {
            return Err(OutputError::SameFile {
                path: path.clone(),
                first: (*first).to_string(),
                second: what.clone(),
            });
        }
        seen.push((what, id));
    }
    Ok(())
}

/// Checks, before any work, that `path` can be written under the rule of this module:
/// not a directory, its directory exists and takes a new file, and it does not exist
/// unless `overwrite`. Stale temporary files of `path` are removed first.
///
/// # Errors
/// [`OutputError::IsDirectory`], [`OutputError::NoDirectory`],
/// [`OutputError::NotWritable`], [`OutputError::Exists`].
pub fn check_output(path: &Path, overwrite: bool) -> Result<(), OutputError> {
    let target = match existing(path)? {
        Existing::Special(_) => return Ok(()),
        Existing::File(_) if !overwrite => {
            return Err(OutputError::Exists {
                path: path.to_path_buf(),
            })
        }
        Existing::File(resolved) => {
            check_unlocked(path, &resolved)?;
            resolved
        }
        Existing::Nothing => path.to_path_buf(),
    };
    let dir = dir_of(&target);
    if !dir.is_dir() {
        return Err(OutputError::NoDirectory {
            path: path.to_path_buf(),
            dir,
        });
    }
    remove_stale_temporaries(&target);
    // the honest test of "writable": create (and remove) a file there
    let probe = temp_path(&target);
    // created and removed while the list is locked: an interrupt cannot leave it behind
    let _list = locked(&TEMPORARIES);
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(f) => {
            drop(f);
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(err) => Err(OutputError::NotWritable {
            path: path.to_path_buf(),
            dir,
            err,
        }),
    }
}

/// `DIR/.NAME.PID.tmp`: the temporary file beside `target`.
fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    dir_of(target).join(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes `path` under the rule of this module: `write` fills a buffered temporary file
/// in the same directory, which is flushed, synced and renamed to `path` only when
/// `write` succeeded; an existing regular file is replaced only if `overwrite`. A device,
/// a pipe or a descriptor ([`is_stream`]) is written in place, as `write` goes: what it
/// got before a failure stays there.
///
/// # Errors
/// As [`check_output`], and [`OutputError::Io`] when writing, flushing or renaming
/// fails (the temporary file is removed then, `path` untouched).
pub fn write_file(
    path: &Path,
    overwrite: bool,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), OutputError> {
    let io_err = |err| OutputError::Io {
        path: path.to_path_buf(),
        err,
    };
    let target = match existing(path)? {
        Existing::Special(dev) => {
            // appending: a descriptor the shell opened with `>>` keeps what it holds
            let file = std::fs::OpenOptions::new()
                .append(true)
                .open(dev)
                .map_err(io_err)?;
            let mut w = io::BufWriter::with_capacity(1 << 16, file);
            write(&mut w).map_err(io_err)?;
            return w.into_inner().map(drop).map_err(|e| io_err(e.into_error()));
        }
        Existing::File(_) if !overwrite => {
            return Err(OutputError::Exists {
                path: path.to_path_buf(),
            })
        }
        Existing::File(resolved) => {
            check_unlocked(path, &resolved)?;
            resolved
        }
        Existing::Nothing => path.to_path_buf(),
    };
    let dir = dir_of(&target);
    if !dir.is_dir() {
        return Err(OutputError::NoDirectory {
            path: path.to_path_buf(),
            dir,
        });
    }
    remove_stale_temporaries(&target);
    let tmp = temp_path(&target);
    let written = (|| {
        let file = {
            let mut list = locked(&TEMPORARIES);
            let file = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&tmp)?;
            list.push(tmp.clone());
            file
        };
        let mut w = io::BufWriter::with_capacity(1 << 16, file);
        write(&mut w)?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()
    })();
    // renamed or removed while listed: an interrupt meanwhile waits for it
    let mut list = locked(&TEMPORARIES);
    let result = written.map_err(io_err).and_then(|()| {
        if overwrite {
            return std::fs::rename(&tmp, &target).map_err(io_err);
        }
        // no overwrite: a link fails when the name appeared meanwhile
        match std::fs::hard_link(&tmp, &target) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Err(OutputError::Exists {
                path: path.to_path_buf(),
            }),
            // a file system without hard links: check, then rename
            Err(_) if target.exists() => Err(OutputError::Exists {
                path: path.to_path_buf(),
            }),
            Err(_) => std::fs::rename(&tmp, &target).map_err(io_err),
        }
    });
    // after a rename the temporary name is gone; after a link or a failure it goes now
    let _ = std::fs::remove_file(&tmp);
    list.retain(|p| p != &tmp);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An output's name that is not UTF-8 is given losslessly in every refusal (`\xHH`,
    /// as `--json` and the input messages give it), not as U+FFFD.
    #[cfg(unix)]
    #[test]
    fn an_output_name_that_is_not_utf8_is_named_losslessly() {
        use std::os::unix::ffi::OsStrExt;
        let path = PathBuf::from(std::ffi::OsStr::from_bytes(b"/no/such/dir/r\xe9sultat.csv"));
        let dir = path.parent().unwrap().to_path_buf();
        for e in [
            OutputError::Exists { path: path.clone() },
            OutputError::NoDirectory {
                path: path.clone(),
                dir: dir.clone(),
            },
            OutputError::Io {
                path: path.clone(),
                err: io::Error::from(io::ErrorKind::BrokenPipe),
            },
        ] {
            let m = e.to_string();
            assert!(m.starts_with("/no/such/dir/r\\xE9sultat.csv: "), "{m}");
            assert!(!m.contains('\u{FFFD}'), "{m}");
        }
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("jointid-output-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn check_room_refuses_a_file_larger_than_the_free_space_but_not_a_stream() {
        let dir = tmp("room");
        let p = dir.join("run.csv");
        check_room(&p, 1000).unwrap();
        let err = check_room(&p, u64::MAX).unwrap_err();
        let OutputError::NoRoom { needed, free, .. } = &err else {
            panic!("{err}")
        };
        assert_eq!(*needed, u64::MAX);
        assert!(*free < u64::MAX, "{err}");
        let msg = err.to_string();
        assert!(
            msg.starts_with(&format!(
                "{}: about 18.4 EB to write, more than the ",
                p.display()
            )),
            "{msg}"
        );
        assert!(msg.contains("free on the file system of"), "{msg}");
        assert!(leftovers(&dir).is_empty());
        // a device is a stream: no size to check
        check_room(Path::new("/dev/null"), u64::MAX).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn fmt_bytes_gives_three_significant_digits_with_a_decimal_prefix() {
        assert_eq!(fmt_bytes(731), "731 B");
        assert_eq!(fmt_bytes(3_612), "3.61 kB");
        assert_eq!(fmt_bytes(36_500_000_000_000), "36.5 TB");
        assert_eq!(fmt_bytes(540_000_000_000), "540 GB");
    }

    #[test]
    fn an_existing_file_is_kept_unless_overwrite_is_asked_for() {
        let dir = tmp("exists");
        let p = dir.join("m.json");
        std::fs::write(&p, "precious").unwrap();
        let err = check_output(&p, false).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "{}: already exists (pass --force to overwrite)",
                p.display()
            )
        );
        let err = write_file(&p, false, |w| w.write_all(b"new")).unwrap_err();
        assert!(matches!(err, OutputError::Exists { .. }), "{err}");
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "precious");
        check_output(&p, true).unwrap();
        write_file(&p, true, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new");
        // a new file needs no overwrite
        write_file(&dir.join("n.json"), false, |w| w.write_all(b"n")).unwrap();
        let mut left = leftovers(&dir);
        left.sort();
        assert_eq!(left, ["m.json", "n.json"]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_failed_write_leaves_nothing_behind_and_the_old_file_intact() {
        let dir = tmp("fail");
        let p = dir.join("run.csv");
        let err = write_file(&p, false, |w| {
            w.write_all(b"t,u\n0,1\n")?;
            Err(io::Error::other("the simulation diverged"))
        })
        .unwrap_err();
        assert!(
            err.to_string().ends_with("the simulation diverged"),
            "{err}"
        );
        assert!(leftovers(&dir).is_empty(), "{:?}", leftovers(&dir));
        std::fs::write(&p, "old").unwrap();
        write_file(&p, true, |_| Err(io::Error::other("no"))).unwrap_err();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(leftovers(&dir), ["run.csv"]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn directories_missing_directories_and_devices() {
        let dir = tmp("dirs");
        let err = check_output(&dir, true).unwrap_err();
        assert!(matches!(err, OutputError::IsDirectory { .. }), "{err}");
        assert!(err.to_string().ends_with("is a directory, not a file"));
        let p = dir.join("no/such/m.json");
        let err = check_output(&p, false).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "{}: directory {} does not exist",
                p.display(),
                dir.join("no/such").display()
            )
        );
        let err = write_file(&p, false, |w| w.write_all(b"x")).unwrap_err();
        assert!(matches!(err, OutputError::NoDirectory { .. }), "{err}");
        // a device is written in place, without --force
        check_output(Path::new("/dev/null"), false).unwrap();
        write_file(Path::new("/dev/null"), false, |w| w.write_all(b"x")).unwrap();
        assert!(is_stream(Path::new("/dev/null")).unwrap());
        assert!(!is_stream(&dir.join("none.csv")).unwrap());
        // a descriptor, whatever it leads to (a pipe's resolves to no file)
        for (p, descriptor, stdout) in [
            ("/dev/stdout", true, true),
            ("/dev/fd/1", true, true),
            ("/proc/self/fd/1", true, true),
            ("/dev/stderr", true, false),
            ("/dev/fd/12", true, false),
            ("/dev/fd/../fd/1", true, true),
            ("/dev/fd/", false, false),
            ("/dev/fd/x", false, false),
            ("/dev/null", false, false),
            ("out/dev/stdout", false, false),
        ] {
            assert_eq!(names_descriptor(Path::new(p)), descriptor, "{p}");
            assert_eq!(names_standard_output(Path::new(p)), stdout, "{p}");
        }
        assert!(is_stream(Path::new("/dev/stderr")).unwrap());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[cfg(unix)]
    #[test]
    fn a_read_only_directory_is_named() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tmp("ro");
        let ro = dir.join("ro");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        let p = ro.join("m.json");
        // root may write anyway; then there is nothing to check
        if std::fs::write(ro.join("probe"), "x").is_err() {
            let err = check_output(&p, false).unwrap_err();
            assert!(
                err.to_string().starts_with(&format!(
                    "{}: directory {} is not writable: ",
                    p.display(),
                    ro.display()
                )),
                "{err}"
            );
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
