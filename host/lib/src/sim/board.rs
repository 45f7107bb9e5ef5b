//! A simulated run as the byte stream a board sends: the session header (repeated after
//! every second of samples, `jointid_core::wire::header_interval_samples`), delta-coded
//! sample batches with the reference CRC, periodic `Status`, `End`, each message one frame
//! of `jointid_core::wire::encode_frame` (0x00, COBS, CRC-32, 0x00), so the capture path
//! reads a simulated run exactly as a board capture. [`encode_stream`] is the one encoder of such
//! streams on the host (the simulator's runs, the paper experiment's, the capture
//! fixtures'); the board itself runs the firmware core's sampler and transport.
//!
//! The wire carries integer counts: `u` and `θm` are rounded to the scale of
//! [`WireOptions`] (at most half a count from the simulator's value); the reader
//! regenerates the reference from the header's excitation bit-exactly and checks it
//! against every batch's CRC.
// Units in brackets (`[Hz]`, `[N·m/count]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use jointid_core::excitation::ExcitationConfig;
use jointid_core::wire::{
    encode_frame_ref, header_interval_samples, BatchBuilder, EncodeError, MessageRef, RawSample,
    Scale, SessionHeader, Status, MAX_FRAME_LEN, PROTOCOL_VERSION,
};

use super::{
    raw_sample, stream_excitation, tick_step, RunSummary, Sample, SimConfig, SimError, SimOutput,
    WireRangeError,
};

/// A message of a board stream did not fit a wire frame (a bug of the encoder's limits).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BoardStreamError {
    /// the message at `index` could not be encoded
    #[error("wire frame of message {index}: {err}")]
    Frame {
        /// 0-based index of the message in the stream
        index: usize,
        /// what the encoder said
        err: EncodeError,
    },
    /// a sample the wire's counts cannot carry (never clamped)
    #[error(transparent)]
    Range(#[from] WireRangeError),
}

/// How a simulated run is put on the wire: the session header's identity and scale, the
/// batching and the status rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WireOptions {
    /// board identifier in the header (`0x5157_0001` for the simulator)
    pub board_id: u32,
    /// session identifier in the header (the low 32 bits of the simulator seed)
    pub session_id: u32,
    /// rate of the sample timestamps [Hz]
    pub timer_hz: u32,
    /// samples per batch (2..=64)
    pub batch_len: usize,
    /// a `Status` after every this many batches (0 = never)
    pub status_every: usize,
    /// counts to SI
    pub scale: Scale,
}

/// Torque scale of a simulated run [N·m/count]: 2^-20, a power of two so that counts ×
/// scale is exact, far below the simulator's torque noise (2e-3 N·m) and with ±2048 N·m
/// of range (the controller limits u to 12 N·m).
pub const SIM_TORQUE_NM_PER_COUNT: f32 = 1.0 / 1_048_576.0;
/// Angle scale of a simulated run without encoder quantisation [rad/count]: 2^-20
/// (±2048 rad of range).
pub const SIM_IDEAL_ANGLE_RAD_PER_COUNT: f32 = 1.0 / 1_048_576.0;

impl WireOptions {
    /// The options of a simulated run of `cfg` (what `jointid simulate` writes): the angle scale is the simulated
    /// encoder's resolution `2π / counts_per_rev` (as `f32`; [`SIM_IDEAL_ANGLE_RAD_PER_COUNT`]
    /// without an encoder), the torque scale [`SIM_TORQUE_NM_PER_COUNT`], a 1 MHz timer,
    /// batches of 32 and a status every 16 batches (4 Hz at 2 kHz), as the board does.
    pub fn for_sim(cfg: &SimConfig) -> Self {
        WireOptions {
            board_id: 0x5157_0001,
            session_id: cfg.seed as u32,
            timer_hz: 1_000_000,
            batch_len: 32,
            status_every: 16,
            scale: Scale {
                torque_nm_per_count: SIM_TORQUE_NM_PER_COUNT,
                angle_rad_per_count: cfg
                    .sensors
                    .angle_resolution()
                    .map_or(SIM_IDEAL_ANGLE_RAD_PER_COUNT, |r| r as f32),
            },
        }
    }

    /// The layout of a whole simulated session: batches and status as these options say,
    /// the header every second, no overruns, `End` at the end.
    pub fn layout(&self, excitation: &ExcitationConfig) -> StreamLayout {
        StreamLayout {
            batch_len: self.batch_len,
            status_every: self.status_every,
            overruns: 0,
            end: true,
            header_every: header_interval_samples(excitation.fs_hz) as usize,
        }
    }

    /// The session header for `excitation` at its sample rate.
    pub fn header(&self, excitation: &ExcitationConfig) -> SessionHeader {
        SessionHeader {
            protocol_version: PROTOCOL_VERSION,
            board_id: self.board_id,
            session_id: self.session_id,
            sample_rate_hz: excitation.fs_hz,
            timer_hz: self.timer_hz,
            excitation: *excitation,
            scale: self.scale,
        }
    }
}

/// Encodes a simulated run as the stream a board sends: session header, sample batches
/// (`BatchBuilder`, with the reference CRC), a `Status` every `opts.status_every`
/// batches, the header again after every second of samples as the board sends it
/// (`header_interval_samples`), `End`; each message one frame of
/// `jointid_core::wire::encode_frame`.
///
/// `out` must be `simulate_excitation(cfg, excitation)` (or the same reference through
/// `simulate_f32`): the reader regenerates the reference from the header and reports
/// every batch whose reference CRC differs. Samples are `out.to_raw_samples(scale,
/// timer_hz)`: `u` and `θm` rounded to counts of `opts.scale`.
///
/// # Errors
/// [`BoardStreamError::Range`] for a sample that is not finite or beyond the scale's
/// `i32` counts; [`BoardStreamError::Frame`] if a message does not fit a frame.
pub fn encode_session(
    out: &SimOutput,
    excitation: &ExcitationConfig,
    opts: &WireOptions,
) -> Result<Vec<u8>, BoardStreamError> {
    let header = opts.header(excitation);
    let raw = out.to_raw_samples(&opts.scale, opts.timer_hz)?;
    let tick_step = raw.get(1).map_or(0, |s| s.tick.wrapping_sub(raw[0].tick));
    let layout = opts.layout(excitation);
    let samples = raw.iter().zip(&out.theta_ref).map(|(s, &r)| (*s, r as f32));
    Ok(encode_stream(&header, samples, tick_step, &layout)?.bytes)
}

/// How the messages of a session follow one another after the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamLayout {
    /// samples per batch (2..=64)
    pub batch_len: usize,
    /// a `Status` after every this many batches (0 = never)
    pub status_every: usize,
    /// overruns the board reports in its status messages (constant)
    pub overruns: u32,
    /// end with an `End` message
    pub end: bool,
    /// the header again after the batch (and status) that completes every this many
    /// samples since the last header, as the board's pump does (0 = only first)
    pub header_every: usize,
}

/// What a frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameContent {
    /// the session header
    Header,
    /// samples with seq `first..first + len`
    Batch {
        /// first seq
        first: u32,
        /// number of samples
        len: u32,
    },
    /// a status message
    Status,
    /// the end message
    End,
}

/// Where one frame lies in the stream, as the decoder reports it: after the frame's
/// leading `0x00` delimiter (the byte at `offset − 1`, outside the span).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSpan {
    /// stream offset of the frame's first byte after its leading `0x00` [bytes]
    pub offset: u64,
    /// bytes including the closing `0x00` delimiter [bytes]
    pub len: u64,
    /// what it carries
    pub content: FrameContent,
}

/// An encoded session: the bytes and every frame in them, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoardStream {
    /// the stream
    pub bytes: Vec<u8>,
    /// every frame of `bytes`
    pub frames: Vec<FrameSpan>,
}

/// The one encoder of a board's stream: `header`, then the samples with their reference
/// `θref` [rad] in batches of `layout.batch_len` (`BatchBuilder` with tick step
/// `tick_step` [timer ticks], reference CRC), a `Status` (seq of the next sample, the
/// layout's overruns) after every `layout.status_every` batches, the header again after
/// every `layout.header_every` samples, and `End` (seq = the number of samples) when
/// `layout.end`; each message one frame of `jointid_core::wire::encode_frame`, in the
/// order the firmware's `TxPump` sends them.
///
/// Used by [`encode_session`] (a simulated run) and by the capture fixtures
/// (`crate::test_support::synth`).
///
/// # Errors
/// [`BoardStreamError::Frame`] if a message does not fit a frame.
pub fn encode_stream(
    header: &SessionHeader,
    samples: impl IntoIterator<Item = (RawSample, f32)>,
    tick_step: u32,
    layout: &StreamLayout,
) -> Result<BoardStream, BoardStreamError> {
    let mut out = BoardStream {
        bytes: Vec::new(),
        frames: Vec::new(),
    };
    let mut sink = |bytes: &[u8], span: FrameSpan| {
        out.bytes.extend_from_slice(bytes);
        out.frames.push(span);
        Ok::<(), BoardStreamError>(())
    };
    let mut enc = StreamEncoder::new(header, tick_step, layout, &mut sink)?;
    for (s, r) in samples {
        enc.push(s, r, &mut sink)?;
    }
    enc.finish(&mut sink)?;
    Ok(out)
}

/// The incremental form of [`encode_stream`] (the one encoder: `encode_stream` collects
/// it): every frame handed to a sink `(bytes, span)` as soon as it is complete, so a
/// stream of any length is encoded in constant memory.
pub struct StreamEncoder {
    header: SessionHeader,
    layout: StreamLayout,
    builder: BatchBuilder,
    buf: Vec<u8>,
    /// frames emitted [-]
    frames: usize,
    /// bytes emitted [bytes]
    offset: u64,
    batches: usize,
    since_header: usize,
    /// samples pushed
    count: u32,
    /// seq of the last sample pushed
    last_seq: u32,
}

impl StreamEncoder {
    /// Starts the stream: the header frame goes to `sink`.
    ///
    /// # Errors
    /// [`BoardStreamError::Frame`] (as `E`), or what `sink` returns.
    pub fn new<E: From<BoardStreamError>>(
        header: &SessionHeader,
        tick_step: u32,
        layout: &StreamLayout,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<StreamEncoder, E> {
        let mut enc = StreamEncoder {
            header: *header,
            layout: *layout,
            builder: BatchBuilder::new(tick_step, layout.batch_len),
            buf: vec![0u8; MAX_FRAME_LEN],
            frames: 0,
            offset: 0,
            batches: 0,
            since_header: 0,
            count: 0,
            last_seq: 0,
        };
        enc.frame(MessageRef::Header(header), FrameContent::Header, sink)?;
        Ok(enc)
    }

    /// Bytes handed to the sink so far [bytes].
    pub fn bytes(&self) -> u64 {
        self.offset
    }

    /// One frame of `msg` to `sink`.
    fn frame<E: From<BoardStreamError>>(
        &mut self,
        msg: MessageRef<'_>,
        content: FrameContent,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<(), E> {
        let index = self.frames;
        let n = encode_frame_ref(msg, &mut self.buf)
            .map_err(|err| BoardStreamError::Frame { index, err })?;
        self.emit(n, content, sink)
    }

    /// The frame of `n` bytes in `buf` to `sink`.
    fn emit<E>(
        &mut self,
        n: usize,
        content: FrameContent,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<(), E> {
        // the span starts after the frame's leading delimiter, as the decoder sees it
        let span = FrameSpan {
            offset: self.offset + 1,
            len: n as u64 - 1,
            content,
        };
        self.frames += 1;
        self.offset += n as u64;
        sink(&self.buf[..n], span)
    }

    fn status(&self, seq: u32) -> Status {
        Status {
            seq,
            overruns: self.layout.overruns,
            queue_drops: 0,
            tx_errors: 0,
        }
    }

    /// The batch the builder just finished (framed where it lies, not moved), then the
    /// status and the header when due.
    fn batch<E: From<BoardStreamError>>(
        &mut self,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<(), E> {
        let b = self.builder.batch();
        let content = FrameContent::Batch {
            first: b.first_seq(),
            len: b.len() as u32,
        };
        let index = self.frames;
        let n = encode_frame_ref(MessageRef::Batch(b), &mut self.buf)
            .map_err(|err| BoardStreamError::Frame { index, err })?;
        self.emit(n, content, sink)?;
        self.batches += 1;
        let every = self.layout.status_every;
        if every > 0 && self.batches.is_multiple_of(every) {
            let st = self.status(self.last_seq.wrapping_add(1));
            self.frame(MessageRef::Status(&st), FrameContent::Status, sink)?;
        }
        self.since_header += content_len(content);
        if self.layout.header_every > 0 && self.since_header >= self.layout.header_every {
            self.since_header = 0;
            let h = self.header;
            self.frame(MessageRef::Header(&h), FrameContent::Header, sink)?;
        }
        Ok(())
    }

    /// Sample `s` with its reference `r` [rad]; a batch frame when it completes one.
    ///
    /// # Errors
    /// [`BoardStreamError::Frame`] (as `E`), or what `sink` returns.
    pub fn push<E: From<BoardStreamError>>(
        &mut self,
        s: RawSample,
        r: f32,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<(), E> {
        self.count += 1;
        self.last_seq = s.seq;
        if self.builder.push_sample(s, r) {
            self.batch(sink)
        } else {
            Ok(())
        }
    }

    /// Ends the stream: the last partial batch, then `End` when the layout asks for it;
    /// returns the bytes handed to the sink [bytes].
    ///
    /// # Errors
    /// [`BoardStreamError::Frame`] (as `E`), or what `sink` returns.
    pub fn finish<E: From<BoardStreamError>>(
        mut self,
        sink: &mut impl FnMut(&[u8], FrameSpan) -> Result<(), E>,
    ) -> Result<u64, E> {
        if self.builder.finish() {
            self.batch(sink)?;
        }
        if self.layout.end {
            let st = self.status(self.count);
            self.frame(MessageRef::End(&st), FrameContent::End, sink)?;
        }
        Ok(self.offset)
    }
}

/// Why a streamed session stopped ([`stream_session`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StreamError {
    /// the simulation (its first non-finite sample and the effects, or its configuration)
    #[error(transparent)]
    Sim(#[from] SimError),
    /// the wire (a sample it cannot carry, or a frame)
    #[error(transparent)]
    Wire(#[from] BoardStreamError),
    /// the writer
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// Simulates `cfg` on `excitation` and writes the board's stream to `w` as it goes
/// ([`super::stream_excitation`], [`StreamEncoder`]): the bytes [`encode_session`] gives
/// for `simulate_excitation(cfg, excitation)`, in memory independent of the length.
/// Each simulated sample also goes to `each` (e.g. for statistics). Returns the run's
/// summary and the stream bytes written [bytes]. As with the whole run, a simulation that
/// is not finite is reported before a sample the wire cannot carry (the run goes on,
/// unwritten, after such a sample).
///
/// # Errors
/// [`StreamError`]: the simulation's, the wire's (nothing clamped), the writer's.
pub fn stream_session(
    cfg: &SimConfig,
    excitation: &ExcitationConfig,
    opts: &WireOptions,
    w: &mut dyn std::io::Write,
    mut each: impl FnMut(&Sample<'_>),
) -> Result<(RunSummary, u64), StreamError> {
    let header = opts.header(excitation);
    let step = tick_step(opts.timer_hz, 1.0 / cfg.sample_rate_hz);
    // as encode_session: the step between the first two samples' ticks
    let two = excitation.total_samples().is_some_and(|n| n >= 2);
    let tick = if two { step as u32 } else { 0 };
    let layout = opts.layout(excitation);
    let mut sink = |bytes: &[u8], _: FrameSpan| w.write_all(bytes).map_err(StreamError::Io);
    let mut enc = StreamEncoder::new(&header, tick, &layout, &mut sink)?;
    // a sample the wire cannot carry ends the stream, but the run goes on unwritten: a
    // run that then diverges reports its first non-finite sample, as the whole run did
    let mut range: Option<WireRangeError> = None;
    let summary = stream_excitation(cfg, excitation, |s: &Sample<'_>| {
        each(s);
        if range.is_some() {
            return Ok(());
        }
        match raw_sample(s.k, s.u, s.theta_m, &opts.scale, step) {
            Ok(raw) => enc.push(raw, s.theta_ref as f32, &mut sink),
            Err(e) => {
                range = Some(e);
                Ok(())
            }
        }
    })?;
    if let Some(e) = range {
        return Err(BoardStreamError::Range(e).into());
    }
    let bytes = enc.finish(&mut sink)?;
    Ok((summary, bytes))
}

/// Samples of a batch frame (0 for the others).
fn content_len(content: FrameContent) -> usize {
    match content {
        FrameContent::Batch { len, .. } => len as usize,
        _ => 0,
    }
}
