//! The capture loop: bytes from a [`SourceSpec`] into a `.jcap`, host events into its
//! `.events` sidecar, counts into a [`StreamAnalyzer`] for progress and summary.
//!
//! # What is left on disk
//!
//! - A **setup error** (unwritable output, output exists, port missing, unknown CAN
//!   interface, refused connection) leaves nothing: the output is created first (so an
//!   unwritable path fails before the device is touched) and removed again, with its
//!   sidecar, when the source cannot be opened.
//! - An **error before the first byte arrived** (a named pipe that cannot be opened)
//!   likewise removes both files.
//! - Once a byte has arrived, the files stay whatever happens (stop, error, SIGKILL): the
//!   `.jcap` is append-only and readable up to its last whole frame.
//! - A clean stop with no byte received leaves a valid empty capture (header only) and a
//!   sidecar saying when and why it stopped.
//!
//! # Stop rules
//! Ctrl-C (the caller's interrupt flag), `--duration` (wall time since the source was
//! opened), `--periods N` (the reported session has delivered sequence number
//! `ramp_samples + N·period_samples − 1`, i.e. N whole periods after the ramp-in; the
//! capture then ends with the frame that carried it, and whatever the source delivered
//! after that frame is not written, however large the chunks it reads), the board's `End`
//! message, or the end of the stream (end of file, peer closed).
//!
//! A line of an slcan or candump source that cannot be read never stops the capture: it
//! goes to the sidecar as a `bad_line` event with its line number and the stream offset
//! it came at, and into the report.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use super::jcap::{self, EventKind, EventLog, FlushPolicy, JcapEvent, JcapWriter};
use super::record::{Progress, StreamAnalyzer};
use super::report::CaptureReport;
use super::source::{RetryPolicy, SourceMsg, SourceSpec};
use super::CaptureError;

/// How often the loop wakes up to flush and check the stop rules when no byte arrives.
const POLL: Duration = Duration::from_millis(25);
/// How often the progress callback is called.
const PROGRESS_EVERY: Duration = Duration::from_millis(100);

/// When a capture stops (besides Ctrl-C and the end of the stream).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StopRule {
    /// stop after this wall time [s]
    pub duration: Option<Duration>,
    /// stop after this many whole excitation periods following the ramp-in
    pub periods: Option<u32>,
    /// keep reading after the board's `End` message (until another rule stops)
    pub ignore_end: bool,
}

/// Everything a capture needs besides its source.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureOptions {
    /// the `.jcap` to write
    pub out: std::path::PathBuf,
    /// replace an existing output (and sidecar)
    pub overwrite: bool,
    /// stop rules
    pub stop: StopRule,
    /// when bytes reach the OS and the disk
    pub flush: FlushPolicy,
    /// how a lost link is retried
    pub retry: RetryPolicy,
}

impl CaptureOptions {
    /// Options with the default flush and retry policies.
    pub fn new(out: impl Into<std::path::PathBuf>) -> Self {
        Self {
            out: out.into(),
            overwrite: false,
            stop: StopRule::default(),
            flush: FlushPolicy::default(),
            retry: RetryPolicy::default(),
        }
    }
}

/// Why a capture stopped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// Ctrl-C (or SIGTERM)
    Interrupted,
    /// `--duration` elapsed
    Duration,
    /// `--periods` whole periods arrived
    Periods,
    /// the board's `End` message arrived
    EndMessage,
    /// the source ended (detail)
    EndOfStream(String),
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Interrupted => write!(f, "interrupted"),
            Self::Duration => write!(f, "duration reached"),
            Self::Periods => write!(f, "requested periods received"),
            Self::EndMessage => write!(f, "board sent end of session"),
            Self::EndOfStream(d) => write!(f, "end of stream ({d})"),
        }
    }
}

/// Result of a capture that ran.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureOutcome {
    /// why it stopped
    pub stop: StopReason,
    /// stream bytes written to the `.jcap` [bytes]
    pub bytes: u64,
    /// wall time from opening the source to the stop [s]
    pub elapsed: Duration,
    /// the summary (same fields as `info --json`)
    pub report: CaptureReport,
}

/// Records `spec` into `opts.out` until a stop rule fires; calls `on_progress` about
/// every 100 ms with the live counters and the elapsed time.
///
/// # Errors
/// [`CaptureError::Jcap`] when the output cannot be created or written,
/// [`CaptureError::Source`] when the source cannot be opened or fails for good. See the
/// module docs for what stays on disk in each case.
pub fn record_capture(
    spec: &SourceSpec,
    opts: &CaptureOptions,
    interrupt: &AtomicBool,
    mut on_progress: impl FnMut(&Progress, Duration),
) -> Result<CaptureOutcome, CaptureError> {
    if let SourceSpec::File { path } = spec {
        let same = match (
            std::fs::canonicalize(path),
            std::fs::canonicalize(&opts.out),
        ) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        };
        if same {
            return Err(CaptureError::SameFile {
                path: opts.out.clone(),
            });
        }
    }
    let events_path = jcap::events_path(&opts.out);
    let mut writer = JcapWriter::create(&opts.out, opts.overwrite, opts.flush)?;
    let remove_both = || {
        let _ = std::fs::remove_file(&opts.out);
        let _ = std::fs::remove_file(&events_path);
    };
    let mut log = match EventLog::create(&events_path, opts.overwrite) {
        Ok(l) => l,
        Err(e) => {
            drop(writer);
            let _ = std::fs::remove_file(&opts.out);
            return Err(e.into());
        }
    };
    let source = match spec.open(opts.retry) {
        Ok(s) => s,
        Err(e) => {
            drop((writer, log));
            remove_both();
            return Err(e.into());
        }
    };
    let start = Instant::now();
    log.log(&JcapEvent::now(0, EventKind::Start, source.name()))?;
    let mut an = StreamAnalyzer::new(false);
    if let Some(n) = opts.stop.periods {
        an.stop_after_periods(n);
    }
    let mut last_progress = start;
    let result: Result<StopReason, CaptureError> = loop {
        if interrupt.load(Ordering::SeqCst) {
            break Ok(StopReason::Interrupted);
        }
        let now = Instant::now();
        if opts.stop.duration.is_some_and(|d| now - start >= d) {
            break Ok(StopReason::Duration);
        }
        let msg = source.recv_timeout(POLL);
        let now = Instant::now();
        match msg {
            None => {}
            Some(SourceMsg::Data(bytes)) => {
                if let Err(e) = feed_and_append(&mut an, &mut writer, &bytes, now) {
                    break Err(e.into());
                }
            }
            Some(SourceMsg::LinkLost(why)) => {
                if let Err(e) = writer.flush() {
                    break Err(e.into());
                }
                an.boundary();
                // the sidecar is an annotation: failing to write it must not stop the capture
                let _ = log.log(&JcapEvent::now(an.bytes(), EventKind::LinkLost, why));
            }
            Some(SourceMsg::LinkResumed(what)) => {
                let _ = log.log(&JcapEvent::now(an.bytes(), EventKind::LinkResumed, what));
            }
            Some(SourceMsg::BadLine(b)) => {
                let _ = log.log(&bad_line_event(an.bytes(), b));
            }
            Some(SourceMsg::End(why)) => break Ok(StopReason::EndOfStream(why)),
            Some(SourceMsg::Failed(e)) => break Err(e.into()),
        }
        if let Err(e) = writer.tick(now) {
            break Err(e.into());
        }
        if an.cut().is_some() {
            break Ok(StopReason::Periods);
        }
        if an.ended() && !opts.stop.ignore_end {
            break Ok(StopReason::EndMessage);
        }
        if now - last_progress >= PROGRESS_EVERY {
            last_progress = now;
            on_progress(&an.progress(), now - start);
        }
    };
    let late = source.stop();
    let elapsed = start.elapsed();
    match result {
        Ok(stop) => {
            // bytes read before the stop but not yet handled still belong to the capture
            // (after a `--periods` cut, nothing of them)
            for msg in late {
                match msg {
                    SourceMsg::Data(bytes) => {
                        feed_and_append(&mut an, &mut writer, &bytes, Instant::now())?;
                    }
                    SourceMsg::BadLine(b) if an.cut().is_none() => {
                        let _ = log.log(&bad_line_event(an.bytes(), b));
                    }
                    _ => {}
                }
            }
            let received = an.bytes();
            let bytes = writer.finish()?;
            let _ = log.log(&JcapEvent::now(received, EventKind::Stop, stop.to_string()));
            on_progress(&an.progress(), elapsed);
            let mut report = an.finish_report();
            report.link_events = jcap::read_events(&opts.out)
                .ok()
                .flatten()
                .unwrap_or_default();
            Ok(CaptureOutcome {
                stop,
                bytes,
                elapsed,
                report,
            })
        }
        Err(e) => {
            let received = an.bytes();
            if received == 0 {
                drop((writer, log));
                remove_both();
            } else {
                // keep what arrived; say why it ended
                let _ = writer.finish();
                let _ = log.log(&JcapEvent::now(
                    received,
                    EventKind::Stop,
                    format!("error: {e}"),
                ));
            }
            Err(e)
        }
    }
}

/// The sidecar event of a bad slcan or candump line at stream offset `offset`.
fn bad_line_event(offset: u64, b: super::canlog::BadLine) -> JcapEvent {
    let mut e = JcapEvent::now(offset, EventKind::BadLine, b.detail);
    e.line = Some(b.line);
    e
}

/// Feeds `bytes` to the analyzer and appends them to the capture, only up to the
/// analyzer's `--periods` cut when it falls inside (or before) them: the capture then
/// ends with the whole frame that completed the requested periods.
fn feed_and_append(
    an: &mut StreamAnalyzer,
    writer: &mut JcapWriter,
    bytes: &[u8],
    now: Instant,
) -> Result<(), jcap::JcapError> {
    let before = an.bytes();
    an.feed(bytes);
    let keep = match an.cut() {
        Some(c) => {
            usize::try_from(c.saturating_sub(before)).map_or(bytes.len(), |k| k.min(bytes.len()))
        }
        None => bytes.len(),
    };
    if keep == 0 {
        return Ok(());
    }
    writer.append(&bytes[..keep], now)
}
