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
    encode_frame, header_interval_samples, BatchBuilder, EncodeError, Message, RawSample, Scale,
    SessionHeader, Status, MAX_FRAME_LEN, PROTOCOL_VERSION,
};

use super::{SimConfig, SimOutput, WireRangeError};

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
    let layout = StreamLayout {
        batch_len: opts.batch_len,
        status_every: opts.status_every,
        overruns: 0,
        end: true,
        header_every: header_interval_samples(excitation.fs_hz) as usize,
    };
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
    let mut buf = vec![0u8; MAX_FRAME_LEN];
    let mut push = |out: &mut BoardStream, msg: &Message, content: FrameContent| {
        let index = out.frames.len();
        let n =
            encode_frame(msg, &mut buf).map_err(|err| BoardStreamError::Frame { index, err })?;
        // the span starts after the frame's leading delimiter, as the decoder sees it
        out.frames.push(FrameSpan {
            offset: out.bytes.len() as u64 + 1,
            len: n as u64 - 1,
            content,
        });
        out.bytes.extend_from_slice(&buf[..n]);
        Ok::<(), BoardStreamError>(())
    };
    push(&mut out, &Message::Header(*header), FrameContent::Header)?;
    let mut builder = BatchBuilder::new(tick_step, layout.batch_len);
    let status = |seq: u32| Status {
        seq,
        overruns: layout.overruns,
        queue_drops: 0,
        tx_errors: 0,
    };
    let mut batches = 0usize;
    let mut since_header = 0usize;
    let mut count = 0u32;
    let mut samples = samples.into_iter().peekable();
    while let Some((s, r)) = samples.next() {
        count += 1;
        let last = samples.peek().is_none();
        let full = builder.push(s, r);
        for b in full
            .into_iter()
            .chain(if last { builder.flush() } else { None })
        {
            let content = FrameContent::Batch {
                first: b.first_seq(),
                len: b.len() as u32,
            };
            push(&mut out, &Message::Batch(b), content)?;
            batches += 1;
            if layout.status_every > 0 && batches.is_multiple_of(layout.status_every) {
                push(
                    &mut out,
                    &Message::Status(status(s.seq.wrapping_add(1))),
                    FrameContent::Status,
                )?;
            }
            since_header += content_len(content);
            if layout.header_every > 0 && since_header >= layout.header_every {
                since_header = 0;
                push(&mut out, &Message::Header(*header), FrameContent::Header)?;
            }
        }
    }
    if layout.end {
        push(&mut out, &Message::End(status(count)), FrameContent::End)?;
    }
    Ok(out)
}

/// Samples of a batch frame (0 for the others).
fn content_len(content: FrameContent) -> usize {
    match content {
        FrameContent::Batch { len, .. } => len as usize,
        _ => 0,
    }
}
