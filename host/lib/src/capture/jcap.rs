//! The native capture file (`.jcap`): what it holds, how it is written so that a
//! capture killed at any moment stays readable, and how it is read back.
//!
//! # Format (version 1)
//!
//! ```text
//! offset 0   8 bytes   magic  4A 43 41 50 01 0D 0A 1A   ("JCAP", version 1, CR LF, Ctrl-Z)
//! offset 8   ...       the received byte stream, exactly as it arrived, append-only
//! ```
//!
//! There is nothing else in the file: no length, no index, no trailer. The bytes after
//! the magic are the stream the board sent (COBS frames separated by `0x00`, see
//! `jointid_core::wire`), so **stream offset = file offset − 8**, and every byte offset
//! this module and the capture report name is a stream offset. The fifth byte is the
//! format version; the CR LF and Ctrl-Z after it catch a file mangled by a text-mode
//! transfer (line-ending translation) and stop `type`-like tools from dumping binary.
//!
//! Because the file is only ever appended to, a capture killed at any moment (SIGKILL,
//! cable pulled, disk full) leaves the magic followed by a prefix of the stream; the
//! streaming decoder reads it up to its last whole frame and reports the cut frame at the
//! end as truncated.
//!
//! # Host-side events: the `.events` sidecar
//!
//! Events the host sees but the board did not send (capture start, link lost, link
//! resumed, stop, with wall time) go to a sidecar file `RUN.jcap.events`, one JSON object
//! per line (see [`JcapEvent`]). They never enter the `.jcap`, so the byte stream stays
//! exactly the received bytes and the offsets stay stream offsets. Each event carries the
//! stream offset at which it happened; a `link_resumed` event marks a decoder boundary
//! (the reader finishes the frame cut by the link loss as truncated instead of gluing its
//! head to whatever arrives after the reconnection). A missing or unreadable sidecar
//! loses only these annotations, never samples.
//!
//! # Flush and fsync policy
//!
//! [`JcapWriter`] buffers in memory and hands the bytes to the operating system (one
//! `write`) whenever the oldest buffered byte is [`FlushPolicy::max_delay`] old (50 ms by
//! default, checked at least every 25 ms by the capture loop) or the buffer holds
//! [`FlushPolicy::max_buffer`] bytes. Bytes handed to the OS survive the death of the
//! process, so a SIGKILL loses at most the last ~75 ms of the stream. The file is
//! `fsync`ed (`sync_data`) every [`FlushPolicy::sync_interval`] (1 s by default) and on
//! a clean stop, which bounds what a power cut or kernel crash can lose to about one
//! second. A write error (full disk, removed medium) stops the capture with an error that
//! names the stream offset; what was written before stays readable.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// The 8 bytes every `.jcap` file starts with (format version 1).
pub const MAGIC: [u8; 8] = *b"JCAP\x01\r\n\x1a";
/// Length of the file header [bytes]; stream offset = file offset − `HEADER_LEN`.
pub const HEADER_LEN: u64 = MAGIC.len() as u64;
/// Format version written by this module (the fifth byte of [`MAGIC`]).
pub const FORMAT_VERSION: u8 = 1;
/// Suffix appended to the capture path for the host-event sidecar.
pub const EVENTS_SUFFIX: &str = ".events";

/// Errors reading or writing a `.jcap` file or its event sidecar.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum JcapError {
    /// The file could not be opened, created, read or written.
    #[error("{path}: {}", super::io_msg(err))]
    Io {
        /// the file concerned
        path: PathBuf,
        /// what the operating system said
        err: io::Error,
    },
    /// The output file exists and overwriting was not asked for.
    #[error("{path}: already exists (pass --force to overwrite)")]
    Exists {
        /// the file concerned
        path: PathBuf,
    },
    /// Another capture is writing the file (it holds the file's exclusive lock): replacing
    /// it would interleave two streams and truncate what the other captured.
    #[error("{path}: another capture is writing this file (it holds the file's lock); stop it first or choose another --out")]
    Locked {
        /// the file concerned
        path: PathBuf,
    },
    /// A whole `.jcap` could not be written ([`write_stream`]).
    #[error(transparent)]
    Output(#[from] crate::data::output::OutputError),
    /// Writing failed at a known place of the stream (full disk, removed medium).
    #[error("{path}: write failed at stream byte {offset}: {}", super::io_msg(err))]
    Write {
        /// the file concerned
        path: PathBuf,
        /// stream offset of the first byte that could not be written
        offset: u64,
        /// what the operating system said
        err: io::Error,
    },
    /// The file is shorter than the 8-byte header.
    #[error("{path}: too short for a jcap header ({len} of 8 bytes)")]
    Short {
        /// the file concerned
        path: PathBuf,
        /// file length [bytes]
        len: u64,
    },
    /// The first four bytes are not `JCAP`.
    #[error("{path}: not a jcap file (bad magic at byte 0)")]
    BadMagic {
        /// the file concerned
        path: PathBuf,
    },
    /// The magic is right but the version is not one this build reads.
    #[error("{path}: unsupported jcap version {version} at byte 4 (this build reads version 1)")]
    Version {
        /// the file concerned
        path: PathBuf,
        /// the version byte found
        version: u8,
    },
    /// Bytes 5..8 are not CR LF Ctrl-Z: the file went through a text-mode transfer.
    #[error("{path}: jcap header damaged at bytes 5..8 (line endings translated?)")]
    Mangled {
        /// the file concerned
        path: PathBuf,
    },
    /// A line of the event sidecar is not a valid event.
    #[error("{path}:{line}: bad event line: {message}")]
    Event {
        /// the sidecar file
        path: PathBuf,
        /// 1-based line number
        line: usize,
        /// what was wrong
        message: String,
    },
}

/// Checks the 8-byte header of a capture and returns nothing when it is version 1.
///
/// # Errors
/// [`JcapError::Short`], [`JcapError::BadMagic`], [`JcapError::Version`] or [`JcapError::Mangled`].
pub fn check_header(path: &Path, head: &[u8]) -> Result<(), JcapError> {
    let path = || path.to_path_buf();
    let n = head.len().min(4);
    if head[..n] != MAGIC[..n] {
        return Err(JcapError::BadMagic { path: path() });
    }
    if head.len() < MAGIC.len() {
        return Err(JcapError::Short {
            path: path(),
            len: head.len() as u64,
        });
    }
    if head[4] != FORMAT_VERSION {
        return Err(JcapError::Version {
            path: path(),
            version: head[4],
        });
    }
    if head[5..8] != MAGIC[5..8] {
        return Err(JcapError::Mangled { path: path() });
    }
    Ok(())
}

/// Reads a whole `.jcap` file (`-`: standard input, [`crate::data::input::read_input`])
/// and returns the stream (the bytes after the header).
///
/// # Errors
/// [`JcapError::Io`] when the file cannot be read, or a header error from [`check_header`].
pub fn read_stream(path: &Path) -> Result<Vec<u8>, JcapError> {
    let name = PathBuf::from(crate::data::input::input_name(path));
    let mut all = crate::data::input::read_input(path).map_err(|err| JcapError::Io {
        path: name.clone(),
        err,
    })?;
    check_header(&name, &all)?;
    all.drain(..MAGIC.len());
    Ok(all)
}

/// Path of the event sidecar of a capture: `RUN.jcap` → `RUN.jcap.events`.
pub fn events_path(capture: &Path) -> PathBuf {
    let mut s = capture.as_os_str().to_os_string();
    s.push(EVENTS_SUFFIX);
    PathBuf::from(s)
}

/// Writes a whole stream (a simulated board's, from `sim::board::encode_session`) as the
/// `.jcap` `path` under the one rule of every output file ([`crate::data::output`]: an
/// existing file only with `overwrite`, whole or not at all), removing any stale
/// `.events` sidecar of an earlier capture of that name; returns the stream bytes written.
///
/// # Errors
/// [`JcapError::Output`] naming the file, [`JcapError::Io`] naming a sidecar that cannot
/// be removed.
pub fn write_stream(path: &Path, stream: &[u8], overwrite: bool) -> Result<u64, JcapError> {
    write_stream_with(path, overwrite, |w| {
        w.write_all(stream)?;
        Ok(stream.len() as u64)
    })
}

/// [`write_stream`] with the stream written by `fill` as it is produced (e.g.
/// `sim::board::stream_session`), which returns the stream bytes it wrote: constant
/// memory for a stream of any length, the same rule (whole or not at all: an error of
/// `fill` leaves no file).
///
/// # Errors
/// As [`write_stream`]; an error of `fill` as [`JcapError::Output`].
pub fn write_stream_with(
    path: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<u64>,
) -> Result<u64, JcapError> {
    let mut written = 0;
    crate::data::output::write_file(path, overwrite, |w| {
        w.write_all(&MAGIC)?;
        written = fill(w)?;
        Ok(())
    })?;
    let stream_len = written;
    let events = events_path(path);
    match std::fs::remove_file(&events) {
        Err(err) if err.kind() != io::ErrorKind::NotFound => {
            Err(JcapError::Io { path: events, err })
        }
        _ => Ok(stream_len),
    }
}

/// When the writer hands bytes to the operating system and when it forces them to disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FlushPolicy {
    /// longest time a received byte may stay in the writer's buffer [s]
    pub max_delay: Duration,
    /// buffer size that triggers an immediate write [bytes]
    pub max_buffer: usize,
    /// interval between `fsync`s while data keeps arriving; `None` = only on a clean stop
    pub sync_interval: Option<Duration>,
}

impl Default for FlushPolicy {
    fn default() -> Self {
        Self {
            max_delay: Duration::from_millis(50),
            max_buffer: 64 * 1024,
            sync_interval: Some(Duration::from_secs(1)),
        }
    }
}

/// Append-only writer of a `.jcap` capture (see the module docs for the flush policy).
#[derive(Debug)]
pub struct JcapWriter {
    path: PathBuf,
    file: File,
    policy: FlushPolicy,
    buf: Vec<u8>,
    /// when the oldest byte now in `buf` arrived
    oldest: Option<Instant>,
    last_sync: Instant,
    unsynced: bool,
    /// stream bytes handed to the OS so far
    written: u64,
}

impl JcapWriter {
    /// Creates `path` (refusing to replace an existing file unless `overwrite`), locks it
    /// for the writer's lifetime and writes the header.
    ///
    /// # Errors
    /// [`JcapError::Exists`], [`JcapError::Locked`] (another capture writes the file: it is
    /// left untouched) or [`JcapError::Io`]; on error nothing is left behind that this call
    /// created.
    pub fn create(path: &Path, overwrite: bool, policy: FlushPolicy) -> Result<Self, JcapError> {
        let mut file = create_capture(path, overwrite)?;
        if let Err(source) = file.write_all(&MAGIC) {
            drop(file);
            let _ = std::fs::remove_file(path);
            return Err(JcapError::Io {
                path: path.to_path_buf(),
                err: source,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            policy,
            buf: Vec::with_capacity(policy.max_buffer),
            oldest: None,
            last_sync: Instant::now(),
            unsynced: false,
            written: 0,
        })
    }

    /// Path of the file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Stream bytes accepted so far (written or buffered) [bytes].
    pub fn len(&self) -> u64 {
        self.written + self.buf.len() as u64
    }

    /// True when no stream byte has been accepted yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stream bytes already handed to the operating system [bytes].
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Appends received bytes; writes through when the buffer is full.
    ///
    /// # Errors
    /// [`JcapError::Write`] naming the stream offset that could not be written.
    pub fn append(&mut self, bytes: &[u8], now: Instant) -> Result<(), JcapError> {
        if bytes.is_empty() {
            return Ok(());
        }
        if self.oldest.is_none() {
            self.oldest = Some(now);
        }
        self.buf.extend_from_slice(bytes);
        if self.buf.len() >= self.policy.max_buffer {
            self.write_out()?;
        }
        self.tick(now)
    }

    /// Applies the time-based part of the policy; call it at least every 25 ms.
    ///
    /// # Errors
    /// [`JcapError::Write`] naming the stream offset that could not be written.
    pub fn tick(&mut self, now: Instant) -> Result<(), JcapError> {
        if let Some(oldest) = self.oldest {
            if now.saturating_duration_since(oldest) >= self.policy.max_delay {
                self.write_out()?;
            }
        }
        if let Some(every) = self.policy.sync_interval {
            if self.unsynced && now.saturating_duration_since(self.last_sync) >= every {
                self.sync(now)?;
            }
        }
        Ok(())
    }

    /// Hands every buffered byte to the operating system now.
    ///
    /// # Errors
    /// [`JcapError::Write`] naming the stream offset that could not be written.
    pub fn flush(&mut self) -> Result<(), JcapError> {
        self.write_out()
    }

    /// Writes out the buffer and forces the file to disk; consumes the writer.
    ///
    /// # Errors
    /// [`JcapError::Write`] naming the stream offset that could not be written.
    pub fn finish(mut self) -> Result<u64, JcapError> {
        self.write_out()?;
        self.sync(Instant::now())?;
        Ok(self.written)
    }

    fn write_out(&mut self) -> Result<(), JcapError> {
        self.oldest = None;
        if self.buf.is_empty() {
            return Ok(());
        }
        let mut done = 0;
        while done < self.buf.len() {
            match self.file.write(&self.buf[done..]) {
                Ok(0) => {
                    let source =
                        io::Error::new(io::ErrorKind::WriteZero, "device accepted no bytes");
                    return Err(self.write_error(done, source));
                }
                Ok(n) => done += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(source) => return Err(self.write_error(done, source)),
            }
        }
        self.written += done as u64;
        self.buf.clear();
        self.unsynced = true;
        Ok(())
    }

    fn write_error(&mut self, done: usize, source: io::Error) -> JcapError {
        self.written += done as u64;
        self.buf.drain(..done);
        JcapError::Write {
            path: self.path.clone(),
            offset: self.written,
            err: source,
        }
    }

    fn sync(&mut self, now: Instant) -> Result<(), JcapError> {
        self.last_sync = now;
        if !self.unsynced {
            return Ok(());
        }
        self.unsynced = false;
        self.file.sync_data().map_err(|source| JcapError::Write {
            path: self.path.clone(),
            offset: self.written,
            err: source,
        })
    }
}

/// What happened, in a line of the `.events` sidecar.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// the source was opened and the capture began
    Start,
    /// the link stopped delivering (device gone, connection reset)
    LinkLost,
    /// the link delivers again; the decoder starts afresh at this offset
    LinkResumed,
    /// the capture stopped (the detail says why)
    Stop,
    /// a line of an slcan or candump source could not be read, or the adapter or the bus
    /// reported an error (the detail quotes it and says what is wrong; `line` is its number)
    BadLine,
}

impl std::fmt::Display for EventKind {
    /// In words: `start`, `link lost`, `link resumed`, `stop`, `bad line`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Start => "start",
            Self::LinkLost => "link lost",
            Self::LinkResumed => "link resumed",
            Self::Stop => "stop",
            Self::BadLine => "bad line",
        })
    }
}

/// One host-side event, one JSON object per line of `RUN.jcap.events`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JcapEvent {
    /// stream offset at which the event happened [bytes]
    pub offset: u64,
    /// wall time [ms since the Unix epoch, UTC]
    pub unix_ms: i64,
    /// the same wall time, ISO 8601 UTC (`2026-11-21T09:45:05.123Z`)
    pub utc: String,
    /// what happened
    pub event: EventKind,
    /// human-readable detail (source, reason)
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub detail: String,
    /// line number in an slcan or candump source (1-based; `bad_line` events)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub line: Option<u64>,
}

impl JcapEvent {
    /// An event stamped with the current wall time.
    pub fn now(offset: u64, event: EventKind, detail: impl Into<String>) -> Self {
        let unix_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_millis() as i64)
            .unwrap_or(0);
        Self {
            offset,
            unix_ms,
            utc: utc_string(unix_ms),
            event,
            detail: detail.into(),
            line: None,
        }
    }
}

/// Formats milliseconds since the Unix epoch as ISO 8601 UTC with milliseconds.
pub fn utc_string(unix_ms: i64) -> String {
    let secs = unix_ms.div_euclid(1000);
    let ms = unix_ms.rem_euclid(1000);
    let days = secs.div_euclid(86_400);
    let sod = secs.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{ms:03}Z",
        sod / 3600,
        (sod / 60) % 60,
        sod % 60
    )
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (era arithmetic on 400-year cycles).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    // shift the epoch to 0000-03-01 so that leap days fall at the end of a year
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097); // day of era [0, 146096]
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365; // year of era [0, 399]
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100); // day of year from March 1 [0, 365]
    let mp = (5 * doy + 2) / 153; // month from March [0, 11]
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

/// Opens `path` for writing: a new file, or (with `overwrite`) a truncated old one.
///
/// A capture file is locked exclusively (an advisory lock, released when the file is
/// closed, also when the process dies) before anything is truncated or written: a second
/// capture into the same file is refused with [`JcapError::Locked`] and the first one's
/// bytes stay as they were. On a file system without locks the file is written unlocked.
fn create_capture(path: &Path, overwrite: bool) -> Result<File, JcapError> {
    let file = if overwrite {
        // no truncation yet: the file may be another capture's, locked
        OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
    } else {
        OpenOptions::new().write(true).create_new(true).open(path)
    };
    let file = file.map_err(|err| match err.kind() {
        io::ErrorKind::AlreadyExists if is_locked(path) => JcapError::Locked {
            path: path.to_path_buf(),
        },
        io::ErrorKind::AlreadyExists => JcapError::Exists {
            path: path.to_path_buf(),
        },
        _ => JcapError::Io {
            path: path.to_path_buf(),
            err,
        },
    })?;
    let io_err = |err| JcapError::Io {
        path: path.to_path_buf(),
        err,
    };
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(JcapError::Locked {
                path: path.to_path_buf(),
            })
        }
        Err(std::fs::TryLockError::Error(e)) if e.kind() == io::ErrorKind::Unsupported => {}
        Err(std::fs::TryLockError::Error(e)) => return Err(io_err(e)),
    }
    // a device or pipe (`/dev/null`) has nothing to truncate, and refuses to be
    if overwrite && file.metadata().map_err(io_err)?.is_file() {
        file.set_len(0).map_err(io_err)?;
    }
    Ok(file)
}

/// True when another open file description holds the lock of the existing file `path`.
fn is_locked(path: &Path) -> bool {
    File::open(path).is_ok_and(|f| matches!(f.try_lock(), Err(std::fs::TryLockError::WouldBlock)))
}

/// Opens `path` (the `.events` sidecar) for writing: a new file, or (with `overwrite`) a
/// truncated old one.
fn create_output(path: &Path, overwrite: bool) -> Result<File, JcapError> {
    let mut opts = OpenOptions::new();
    opts.write(true);
    if overwrite {
        opts.create(true).truncate(true);
    } else {
        opts.create_new(true);
    }
    opts.open(path).map_err(|source| {
        if source.kind() == io::ErrorKind::AlreadyExists {
            JcapError::Exists {
                path: path.to_path_buf(),
            }
        } else {
            JcapError::Io {
                path: path.to_path_buf(),
                err: source,
            }
        }
    })
}

/// Append-only writer of the `.events` sidecar; every event is written and flushed at once.
#[derive(Debug)]
pub struct EventLog {
    path: PathBuf,
    file: File,
}

impl EventLog {
    /// Creates the sidecar (replacing an old one only if `overwrite`).
    ///
    /// # Errors
    /// [`JcapError::Exists`] or [`JcapError::Io`].
    pub fn create(path: &Path, overwrite: bool) -> Result<Self, JcapError> {
        let file = create_output(path, overwrite)?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Path of the sidecar.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one event as a single JSON line, written with one `write` call.
    ///
    /// # Errors
    /// [`JcapError::Io`] when the line cannot be written.
    pub fn log(&mut self, event: &JcapEvent) -> Result<(), JcapError> {
        let mut line = serde_json::to_vec(event).expect("an event always serialises");
        line.push(b'\n');
        self.file
            .write_all(&line)
            .and_then(|()| self.file.flush())
            .map_err(|source| JcapError::Io {
                path: self.path.clone(),
                err: source,
            })
    }
}

/// Reads the event sidecar of a capture; `Ok(None)` when there is none.
///
/// A last line without its newline (the process died while writing it) is ignored.
///
/// # Errors
/// [`JcapError::Io`] when the sidecar exists but cannot be read, [`JcapError::Event`]
/// for a complete line that is not an event.
pub fn read_events(capture: &Path) -> Result<Option<Vec<JcapEvent>>, JcapError> {
    let path = events_path(capture);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(JcapError::Io { path, err: source }),
    };
    let complete = match text.rfind('\n') {
        Some(i) => &text[..=i],
        None => "",
    };
    let mut events = Vec::new();
    for (i, line) in complete.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let event = serde_json::from_str(line).map_err(|e| JcapError::Event {
            path: path.clone(),
            line: i + 1,
            message: e.to_string(),
        })?;
        events.push(event);
    }
    Ok(Some(events))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("jointid-jcap-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn writer_round_trips_bytes_exactly_after_the_magic() {
        let dir = tmp("roundtrip");
        let path = dir.join("run.jcap");
        let mut w = JcapWriter::create(&path, false, FlushPolicy::default()).unwrap();
        let data: Vec<u8> = (0..200_000u32).map(|i| (i * 7 + i / 13) as u8).collect();
        let t0 = Instant::now();
        for chunk in data.chunks(777) {
            w.append(chunk, t0).unwrap();
        }
        assert_eq!(w.len(), data.len() as u64);
        assert_eq!(w.finish().unwrap(), data.len() as u64);
        let raw = std::fs::read(&path).unwrap();
        assert_eq!(&raw[..8], b"JCAP\x01\r\n\x1a");
        assert_eq!(read_stream(&path).unwrap(), data);
    }

    #[test]
    fn writer_hands_bytes_to_the_os_once_max_delay_has_passed() {
        let dir = tmp("delay");
        let path = dir.join("run.jcap");
        let policy = FlushPolicy {
            max_delay: Duration::from_millis(50),
            max_buffer: 1 << 20,
            sync_interval: None,
        };
        let mut w = JcapWriter::create(&path, false, policy).unwrap();
        let t0 = Instant::now();
        w.append(b"abc\0", t0).unwrap();
        // still buffered: nothing past the header on disk
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 8);
        w.tick(t0 + Duration::from_millis(49)).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 8);
        w.tick(t0 + Duration::from_millis(50)).unwrap();
        // on disk without finish(): a process killed now keeps these bytes
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 12);
        assert_eq!(w.written(), 4);
        std::mem::forget(w); // as if killed: no finish, no drop
        assert_eq!(read_stream(&path).unwrap(), b"abc\0");
    }

    #[test]
    fn writer_writes_through_when_the_buffer_fills() {
        let dir = tmp("full");
        let path = dir.join("run.jcap");
        let policy = FlushPolicy {
            max_delay: Duration::from_secs(3600),
            max_buffer: 100,
            sync_interval: None,
        };
        let mut w = JcapWriter::create(&path, false, policy).unwrap();
        let t0 = Instant::now();
        w.append(&[1; 99], t0).unwrap();
        assert_eq!(w.written(), 0);
        w.append(&[2; 1], t0).unwrap();
        assert_eq!(w.written(), 100);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 108);
    }

    #[test]
    fn create_refuses_an_existing_file_unless_overwrite() {
        let dir = tmp("exists");
        let path = dir.join("run.jcap");
        std::fs::write(&path, b"precious").unwrap();
        let err = JcapWriter::create(&path, false, FlushPolicy::default()).unwrap_err();
        assert!(matches!(err, JcapError::Exists { .. }), "{err}");
        assert!(
            err.to_string().contains("run.jcap: already exists"),
            "{err}"
        );
        assert_eq!(std::fs::read(&path).unwrap(), b"precious");
        JcapWriter::create(&path, true, FlushPolicy::default())
            .unwrap()
            .finish()
            .unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), MAGIC);
    }

    #[test]
    fn create_in_a_missing_directory_fails_and_creates_nothing() {
        let dir = tmp("missing");
        let path = dir.join("no/such/dir/run.jcap");
        let err = JcapWriter::create(&path, false, FlushPolicy::default()).unwrap_err();
        assert!(matches!(err, JcapError::Io { .. }), "{err}");
        assert!(!dir.join("no").exists());
    }

    #[test]
    fn check_header_names_each_kind_of_bad_header() {
        let p = Path::new("x.jcap");
        assert!(check_header(p, &MAGIC).is_ok());
        assert!(matches!(
            check_header(p, b"JCA"),
            Err(JcapError::Short { len: 3, .. })
        ));
        assert!(matches!(
            check_header(p, b"PK\x03\x04abcd"),
            Err(JcapError::BadMagic { .. })
        ));
        assert!(matches!(
            check_header(p, b"PK"),
            Err(JcapError::BadMagic { .. })
        ));
        assert!(matches!(
            check_header(p, b"JCAP\x02\r\n\x1a"),
            Err(JcapError::Version { version: 2, .. })
        ));
        assert!(matches!(
            check_header(p, b"JCAP\x01\n\x1a\x00"),
            Err(JcapError::Mangled { .. })
        ));
    }

    #[test]
    fn utc_string_matches_known_dates() {
        assert_eq!(utc_string(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29 (leap day of a year divisible by 400) 12:34:56.789
        assert_eq!(utc_string(951_827_696_789), "2000-02-29T12:34:56.789Z");
        // 2026-11-21 09:45:05.123
        assert_eq!(utc_string(1_795_254_305_123), "2026-11-21T09:45:05.123Z");
        assert_eq!(utc_string(-1), "1969-12-31T23:59:59.999Z");
    }

    #[test]
    fn event_log_round_trips_and_ignores_a_half_written_last_line() {
        let dir = tmp("events");
        let cap = dir.join("run.jcap");
        let mut log = EventLog::create(&events_path(&cap), false).unwrap();
        let a = JcapEvent::now(0, EventKind::Start, "serial /dev/ttyACM0 at 921600 baud");
        let b = JcapEvent::now(4096, EventKind::LinkLost, "");
        log.log(&a).unwrap();
        log.log(&b).unwrap();
        drop(log);
        let mut f = OpenOptions::new()
            .append(true)
            .open(events_path(&cap))
            .unwrap();
        f.write_all(br#"{"offset":5000,"unix_ms""#).unwrap();
        assert_eq!(read_events(&cap).unwrap().unwrap(), vec![a, b]);
        assert_eq!(read_events(&dir.join("other.jcap")).unwrap(), None);
    }

    #[test]
    fn read_events_names_the_bad_line() {
        let dir = tmp("badevents");
        let cap = dir.join("run.jcap");
        std::fs::write(
            events_path(&cap),
            "{\"offset\":1,\"unix_ms\":0,\"utc\":\"\",\"event\":\"start\"}\nnonsense\n",
        )
        .unwrap();
        let err = read_events(&cap).unwrap_err();
        assert!(
            err.to_string()
                .contains("run.jcap.events:2: bad event line"),
            "{err}"
        );
    }
}
