//! Capture: record the board's stream from a serial port, a CAN interface, an slcan CAN
//! adapter, a `candump -l` log, a TCP socket or a file, losing nothing, and say exactly
//! what arrived damaged.
//!
//! The path of the bytes:
//!
//! ```text
//! source (serial | can | slcan | candump | tcp | file) ──► live::record ──► jcap::JcapWriter  (RUN.jcap, raw bytes)
//!                                                                │      └──► jcap::EventLog    (RUN.jcap.events)
//!                                                                └─────────► record::StreamAnalyzer ──► report (progress, summary)
//! RUN.jcap ──► read_jcap ──► record::StreamAnalyzer ──► CaptureRecord (header, samples in SI, report) ──► export (CSV)
//! ```
//!
//! - [`jcap`]: the native capture file (8-byte header + the raw received bytes,
//!   append-only), its `.events` sidecar, the flush and fsync policy.
//! - [`source`]: the links bytes come from, with reconnection after a link loss.
//! - [`can`]: CAN frames into the stream bytes (the core's reassembler); [`canlog`]: the
//!   lines of slcan adapters and `candump -l` logs into CAN frames, bad lines reported.
//! - [`record`]: the one interpreter of a stream (decoder, sessions, sequence gaps,
//!   reference check, conversion to SI).
//! - [`live`]: the capture loop (stop rules, progress, setup-error rule).
//! - [`report`]: the summary (samples, gaps, damaged frames with byte offsets, overruns).
//! - [`export`]: the capture CSV of ../shared/DESIGN.md §5.
//!
//! **Architecture invariant**: the `.jcap` holds exactly the received bytes; everything
//! else (samples, gaps, SI values, reference) is derived from them on reading, so a better
//! decoder later reads old captures better. Nothing is interpolated: a gap is reported,
//! never filled.
// Units in brackets (`[s]`, `[bytes]`, `[rad]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::path::{Path, PathBuf};

use jointid_core::wire::SessionHeader;

use crate::data::{Dataset, IdData};

pub mod can;
pub mod canlog;
pub mod export;
pub mod jcap;
pub mod live;
pub mod record;
pub mod report;
pub mod source;

pub use jcap::{JcapError, JcapEvent};
pub use live::{record_capture, CaptureOptions, CaptureOutcome, StopReason, StopRule};
pub use record::{Progress, StreamAnalyzer};
pub use report::{CaptureReport, DamagedFrame, SeqGap};
pub use source::{SourceError, SourceSpec};

/// Errors of capturing, reading and exporting captures.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CaptureError {
    /// The capture file or its sidecar could not be written or read.
    #[error(transparent)]
    Jcap(#[from] JcapError),
    /// The source could not be opened or failed while reading.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// `--file` and `--out` name the same file.
    #[error("{path}: is both the input and the output")]
    SameFile {
        /// the file
        path: PathBuf,
    },
    /// The capture holds no session header, so its counts cannot be scaled to SI.
    #[error("{path}: no session header in {bytes} bytes ({samples} samples without one)")]
    NoHeader {
        /// the capture file
        path: PathBuf,
        /// stream bytes read
        bytes: u64,
        /// samples that arrived without a header
        samples: u64,
    },
    /// The session header's excitation config cannot be regenerated.
    #[error("session header: excitation cannot be regenerated: {message}")]
    Excitation {
        /// what the generator said
        message: String,
    },
    /// The capture cannot serve as uniformly sampled identification data.
    #[error("{path}: {reason}; `jointid info` lists what is missing")]
    NotUniform {
        /// the capture file
        path: PathBuf,
        /// what is wrong (gaps with the first one, too few samples)
        reason: String,
    },
    /// The session asked for is not in the capture.
    #[error(
        "{path}: no session {session} in this capture (sessions: {})",
        list_ids(available)
    )]
    NoSession {
        /// the capture file
        path: PathBuf,
        /// the session id asked for
        session: u32,
        /// the session ids the capture holds, in stream order
        available: Vec<u32>,
    },
    /// Writing an export failed, or the file exists and overwriting was not asked for.
    #[error(transparent)]
    Output(#[from] crate::data::output::OutputError),
}

/// One sample of a capture in SI units, with the regenerated reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureSample {
    /// sample index k since the start of the ramp-in
    pub seq: u32,
    /// board timer ticks at the sampling instant (wraps) [ticks of `SessionHeader::timer_hz`]
    pub tick: u32,
    /// time since the first sample of the ramp-in, `seq / sample_rate_hz` [s]
    pub t: f64,
    /// motor-angle reference θref, regenerated from the header's excitation [rad]
    pub theta_ref: f64,
    /// motor torque reference u [N·m]
    pub u: f64,
    /// motor angle θm [rad]
    pub theta_m: f64,
}

/// Everything a capture holds, decoded: the session header, the samples that arrived (in
/// sequence order, each once, never interpolated) and the report of what did not.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureRecord {
    /// the (first) session's header
    pub header: SessionHeader,
    /// samples of that session, sorted by `seq`; holes are listed in `report.gaps`
    pub samples: Vec<CaptureSample>,
    /// counts, gaps, damaged frames, board counters
    pub report: CaptureReport,
}

impl CaptureRecord {
    /// Sample interval [s].
    pub fn sample_interval_s(&self) -> f64 {
        1.0 / f64::from(self.header.sample_rate_hz)
    }

    /// The record as identification data: u → θm with the reference, the excitation
    /// config, and the other capture facts as `meta` (the keys of the capture CSV's
    /// comments). `path` names the capture in errors.
    ///
    /// # Errors
    /// [`CaptureError::NotUniform`] when samples are missing (gaps are never filled) or
    /// fewer than two samples arrived.
    pub fn to_dataset(&self, path: &Path) -> Result<Dataset, CaptureError> {
        let r = &self.report;
        if let Some(first) = r.gaps.first() {
            return Err(CaptureError::NotUniform {
                path: path.to_path_buf(),
                reason: format!(
                    "{} gap{}, {} samples missing (first seq {}..={})",
                    r.gaps.len(),
                    if r.gaps.len() == 1 { "" } else { "s" },
                    r.missing_samples,
                    first.from,
                    first.to
                ),
            });
        }
        if self.samples.len() < 2 {
            return Err(CaptureError::NotUniform {
                path: path.to_path_buf(),
                reason: format!("{} samples, need at least 2", self.samples.len()),
            });
        }
        let meta = export::comment_pairs(self)
            .into_iter()
            .filter(|(k, _)| !crate::data::EXCITATION_KEYS.contains(k))
            .map(|(k, v)| (k.to_string(), v))
            .collect();
        Ok(Dataset {
            name: path.display().to_string(),
            data: IdData {
                ts: self.sample_interval_s(),
                u: self.samples.iter().map(|s| s.u).collect(),
                y: self.samples.iter().map(|s| s.theta_m).collect(),
                r: Some(self.samples.iter().map(|s| s.theta_ref).collect()),
            },
            t0: self.samples[0].t,
            excitation: Some(self.header.excitation),
            meta,
        })
    }
}

impl CaptureRecord {
    /// The record as identification data split at its gaps: one [`Dataset`] per gap-free
    /// run of sequence numbers, each with `t0 = seq / sample_rate_hz` of its first sample,
    /// the reference, the excitation config and the capture facts as `meta` (see
    /// [`CaptureRecord::to_dataset`]). Nothing is interpolated.
    ///
    /// # Errors
    /// [`CaptureError::NotUniform`] when fewer than two samples arrived.
    pub fn to_record(&self, path: &Path) -> Result<crate::data::Record, CaptureError> {
        if self.samples.len() < 2 {
            return Err(CaptureError::NotUniform {
                path: path.to_path_buf(),
                reason: format!("{} samples, need at least 2", self.samples.len()),
            });
        }
        let meta: std::collections::BTreeMap<String, String> = export::comment_pairs(self)
            .into_iter()
            .filter(|(k, _)| !crate::data::EXCITATION_KEYS.contains(k))
            .map(|(k, v)| (k.to_string(), v))
            .collect();
        let mut starts = vec![0];
        starts.extend(
            (1..self.samples.len())
                .filter(|&i| self.samples[i].seq != self.samples[i - 1].seq.wrapping_add(1)),
        );
        starts.push(self.samples.len());
        let pieces = starts
            .windows(2)
            .map(|w| {
                let s = &self.samples[w[0]..w[1]];
                Dataset {
                    name: path.display().to_string(),
                    data: IdData {
                        ts: self.sample_interval_s(),
                        u: s.iter().map(|x| x.u).collect(),
                        y: s.iter().map(|x| x.theta_m).collect(),
                        r: Some(s.iter().map(|x| x.theta_ref).collect()),
                    },
                    t0: s[0].t,
                    excitation: Some(self.header.excitation),
                    meta: meta.clone(),
                }
            })
            .collect();
        Ok(crate::data::Record {
            pieces,
            notes: Vec::new(),
        })
    }
}

/// Reads a `.jcap` as identification data with no gap (see [`CaptureRecord::to_dataset`]).
///
/// # Errors
/// As [`read_jcap`] and [`CaptureRecord::to_dataset`].
pub fn load_dataset(path: &Path) -> Result<Dataset, CaptureError> {
    read_jcap(path)?.to_dataset(path)
}

/// The loader `data::Loaders` uses for content starting with the jcap magic (whatever the
/// file is called, standard input included): the first session as a
/// [`crate::data::Record`], one piece per gap-free run of samples. The `.events` sidecar
/// beside a file is read when there is one.
///
/// # Errors
/// As [`read_jcap`] (the header checked on `input.bytes`), and
/// [`CaptureError::NotUniform`] when fewer than two samples arrived.
pub fn load_record(input: &crate::data::Input<'_>) -> Result<crate::data::Record, CaptureError> {
    let path = Path::new(input.name);
    jcap::check_header(path, input.bytes)?;
    let stream = &input.bytes[jcap::MAGIC.len()..];
    let events = input
        .path
        .and_then(|p| jcap::read_events(p).ok().flatten())
        .unwrap_or_default();
    let boundaries = boundaries_of(&events);
    decode_named(path, stream, &boundaries, events, None)?.to_record(path)
}

/// Decodes a byte stream as [`read_jcap`] does (no file, no events).
///
/// # Errors
/// [`CaptureError::NoHeader`] (with `path` empty) or [`CaptureError::Excitation`].
pub fn decode_stream(stream: &[u8], boundaries: &[u64]) -> Result<CaptureRecord, CaptureError> {
    decode_named(Path::new(""), stream, boundaries, Vec::new(), None)
}

/// Reads a `.jcap` capture (and its `.events` sidecar when present): the first session's
/// header, its samples in SI units with the regenerated reference, and the report.
///
/// A capture cut at any point is read up to its last whole frame; the cut frame is
/// listed as truncated in `report.damaged_frames`.
///
/// # Errors
/// [`CaptureError::Jcap`] when the file cannot be read or is no jcap file,
/// [`CaptureError::NoHeader`] when no session header arrived,
/// [`CaptureError::Excitation`] when the header's excitation cannot be regenerated.
pub fn read_jcap(path: &Path) -> Result<CaptureRecord, CaptureError> {
    read_jcap_session(path, None)
}

/// Reads one session of a `.jcap` capture, as [`read_jcap`] reads the first: the
/// session with id `session` (the first one when `None`).
/// # Errors
/// As [`read_jcap`]; [`CaptureError::NoSession`] when no session has that id.
pub fn read_jcap_session(path: &Path, session: Option<u32>) -> Result<CaptureRecord, CaptureError> {
    let (stream, events) = read_jcap_parts(path)?;
    let boundaries = boundaries_of(&events);
    decode_named(&capture_name(path), &stream, &boundaries, events, session)
}

/// Reads only the report of a capture (works without a session header, and when the
/// excitation cannot be regenerated: the reference is then left unchecked).
///
/// # Errors
/// [`CaptureError::Jcap`] when the file cannot be read or is no jcap file.
pub fn read_jcap_report(
    path: &Path,
) -> Result<(CaptureReport, Option<SessionHeader>), CaptureError> {
    let (stream, events) = read_jcap_parts(path)?;
    let boundaries = boundaries_of(&events);
    Ok(report_of(&stream, &boundaries, events, None))
}

/// The report and header of every session of a capture, in stream order (one entry,
/// headerless, when no session header arrived), or of the session with id `session`
/// only. The file is read once and decoded once per session.
/// # Errors
/// [`CaptureError::Jcap`] when the file cannot be read or is no jcap file,
/// [`CaptureError::NoSession`] when `session` is given and no session has that id.
pub fn read_jcap_session_reports(
    path: &Path,
    session: Option<u32>,
) -> Result<Vec<(CaptureReport, Option<SessionHeader>)>, CaptureError> {
    let (stream, events) = read_jcap_parts(path)?;
    session_reports(&capture_name(path), &stream, events, session)
}

/// As [`read_jcap_session_reports`], for a capture already read whole (from standard
/// input): `bytes` the file, magic included, and no events sidecar; `name` names it in
/// messages.
/// # Errors
/// [`CaptureError::Jcap`] when `bytes` are no jcap file, [`CaptureError::NoSession`] as
/// [`read_jcap_session_reports`].
pub fn jcap_session_reports(
    name: &Path,
    bytes: &[u8],
    session: Option<u32>,
) -> Result<Vec<(CaptureReport, Option<SessionHeader>)>, CaptureError> {
    jcap::check_header(name, bytes)?;
    session_reports(name, &bytes[jcap::MAGIC.len()..], Vec::new(), session)
}

/// The reports of [`read_jcap_session_reports`] of the received bytes `stream`.
fn session_reports(
    path: &Path,
    stream: &[u8],
    events: Vec<JcapEvent>,
    session: Option<u32>,
) -> Result<Vec<(CaptureReport, Option<SessionHeader>)>, CaptureError> {
    let boundaries = boundaries_of(&events);
    let first = report_of(stream, &boundaries, events.clone(), None);
    let ids = session_ids(&first.0);
    if let Some(k) = session {
        if !ids.contains(&k) {
            return Err(CaptureError::NoSession {
                path: path.to_path_buf(),
                session: k,
                available: ids,
            });
        }
        return Ok(vec![report_of(stream, &boundaries, events, Some(k))]);
    }
    let first_id = first.1.map(|h| h.session_id);
    let mut out = vec![first];
    for id in ids.into_iter().filter(|id| Some(*id) != first_id) {
        out.push(report_of(stream, &boundaries, events.clone(), Some(id)));
    }
    Ok(out)
}

/// The gap-free segments of a session from its report: the runs of sequence numbers
/// between `first_seq`, the gaps and `last_seq`, with their whole excitation periods (what
/// `--segment N` picks, numbered from 1). Empty when no sample arrived.
pub fn segments_of(
    report: &CaptureReport,
    header: &SessionHeader,
) -> Vec<crate::data::SegmentInfo> {
    let (Some(first), Some(last)) = (report.first_seq, report.last_seq) else {
        return Vec::new();
    };
    let ts = 1.0 / f64::from(header.sample_rate_hz);
    let mut runs = Vec::new();
    let mut start = u64::from(first);
    for g in &report.gaps {
        if u64::from(g.from) > start {
            runs.push((start, u64::from(g.from) - start));
        }
        start = u64::from(g.to) + 1;
    }
    if u64::from(last) >= start {
        runs.push((start, u64::from(last) + 1 - start));
    }
    runs.into_iter()
        .enumerate()
        .map(|(i, (k0, n))| {
            crate::data::SegmentInfo::new(
                i + 1,
                k0 as usize,
                n as usize,
                ts,
                Some(&header.excitation),
                Some(last as usize),
            )
        })
        .collect()
}

/// The distinct session ids of a report's sessions, in stream order.
pub fn session_ids(report: &CaptureReport) -> Vec<u32> {
    let mut ids: Vec<u32> = Vec::new();
    for s in &report.sessions {
        if !ids.contains(&s.session_id) {
            ids.push(s.session_id);
        }
    }
    ids
}

fn list_ids(ids: &[u32]) -> String {
    if ids.is_empty() {
        return "none".to_string();
    }
    ids.iter()
        .map(u32::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

fn report_of(
    stream: &[u8],
    boundaries: &[u64],
    events: Vec<JcapEvent>,
    session: Option<u32>,
) -> (CaptureReport, Option<SessionHeader>) {
    let mut an = StreamAnalyzer::new(false);
    if let Some(k) = session {
        an.select_session(k);
    }
    an.feed_parallel(stream, boundaries, decode_threads(), PARALLEL_PIECE);
    let header = an.header().copied();
    let mut report = an.finish_report();
    report.link_events = events;
    (report, header)
}

/// The received bytes of the capture `path` (`-`: standard input, without events) and
/// its events.
fn read_jcap_parts(path: &Path) -> Result<(Vec<u8>, Vec<JcapEvent>), CaptureError> {
    let stream = jcap::read_stream(path)?;
    if crate::data::input::is_stdin(path) {
        return Ok((stream, Vec::new()));
    }
    // a broken sidecar costs the annotations, never the samples
    let events = jcap::read_events(path).ok().flatten().unwrap_or_default();
    Ok((stream, events))
}

/// How messages name the capture `path` (`standard input` for `-`).
fn capture_name(path: &Path) -> PathBuf {
    PathBuf::from(crate::data::input::input_name(path))
}

/// Stream offsets at which the link was lost (decoder restarts there).
fn boundaries_of(events: &[JcapEvent]) -> Vec<u64> {
    let mut b: Vec<u64> = events
        .iter()
        .filter(|e| e.event == jcap::EventKind::LinkLost)
        .map(|e| e.offset)
        .collect();
    b.sort_unstable();
    b.dedup();
    b
}

/// Smallest piece of a stream worth a decoder thread of its own [bytes].
const PARALLEL_PIECE: usize = 1 << 20;

/// Decoder threads for reading a capture: the cores there are, at most 8.
fn decode_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().min(8))
}

fn decode_named(
    path: &Path,
    stream: &[u8],
    boundaries: &[u64],
    events: Vec<JcapEvent>,
    session: Option<u32>,
) -> Result<CaptureRecord, CaptureError> {
    let mut an = StreamAnalyzer::new(true);
    if let Some(k) = session {
        an.select_session(k);
    }
    // about 5.4 bytes per sample on the wire: reserve once instead of doubling
    an.reserve_samples(stream.len() / 4);
    an.feed_parallel(stream, boundaries, decode_threads(), PARALLEL_PIECE);
    let (report, record) = an.finish()?;
    match record {
        Some(mut r) => {
            r.report.link_events = events;
            Ok(r)
        }
        None if session.is_some() => Err(CaptureError::NoSession {
            path: path.to_path_buf(),
            session: session.unwrap_or(0),
            available: session_ids(&report),
        }),
        None => Err(CaptureError::NoHeader {
            path: path.to_path_buf(),
            bytes: report.bytes,
            samples: report.samples_without_header,
        }),
    }
}

pub(crate) use crate::data::output::io_msg;
