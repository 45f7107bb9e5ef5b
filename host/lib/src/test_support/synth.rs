//! Synthesised board streams with known content, for tests, benchmarks and demos.
//!
//! [`synth_stream`] produces what a board would send for a session — header, sample
//! batches with the excitation's reference CRC, periodic status, end — encoded by the
//! host's one board-stream encoder ([`crate::sim::board::encode_stream`], on the core's
//! `jointid_core::wire::encode_frame`), and says where every frame lies in the stream
//! ([`FrameSpan`]) and which samples it carries. Tests damage the
//! bytes and compute from the spans, independently of the decoder, which frames must be
//! reported damaged and which sequence numbers must go missing.
//!
//! The sample values are a deterministic function of the sequence number: the angle is
//! the reference quantised to counts plus a small pseudo-random dither, the torque a
//! pseudo-random walk; both cover the full delta-coding paths of the batch encoder.

use jointid_core::excitation::{Excitation, ExcitationConfig, SignalKind};
use jointid_core::wire::{RawSample, Scale, SessionHeader, PROTOCOL_VERSION};

use crate::sim::board::{encode_stream, StreamLayout};
pub use crate::sim::board::{FrameContent, FrameSpan};

/// What to synthesise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SynthOptions {
    /// the excitation the header announces and the reference follows
    pub excitation: ExcitationConfig,
    /// samples to send (seq 0..samples)
    pub samples: u32,
    /// samples per batch (2..=64)
    pub batch_len: usize,
    /// a `Status` after every this many batches (0 = never)
    pub status_every: usize,
    /// end with an `End` message
    pub end: bool,
    /// board identifier in the header
    pub board_id: u32,
    /// session identifier in the header
    pub session_id: u32,
    /// board timer rate [Hz]
    pub timer_hz: u32,
    /// overruns the board reports in its status messages (constant)
    pub overruns: u32,
}

impl SynthOptions {
    /// A short test session: 200 Hz, period 100 samples, ramp 50, 3 periods, all
    /// samples of the finite run, batches of 16, status every 4 batches, end message.
    pub fn small() -> Self {
        let excitation = ExcitationConfig {
            kind: SignalKind::SpecialOddMultisine,
            fs_hz: 200,
            period_samples: 100,
            max_line: 19,
            cutoff_hz: 20.0,
            rms_rad: 0.05,
            seed: 42,
            ramp_samples: 50,
            periods: 3,
        };
        Self {
            excitation,
            samples: 400,
            batch_len: 16,
            status_every: 4,
            end: true,
            board_id: 0xB0A4_D001,
            session_id: 7,
            timer_hz: 1_000_000,
            overruns: 0,
        }
    }

    /// The paper's experiment at 2 kHz, endless, for `seconds` of samples.
    pub fn paper(seconds: u32) -> Self {
        let mut excitation = ExcitationConfig::paper_default();
        excitation.periods = 0;
        Self {
            excitation,
            samples: seconds * excitation.fs_hz,
            batch_len: 32,
            status_every: 16,
            end: true,
            board_id: 0x6474_0001,
            session_id: 1,
            timer_hz: 170_000_000,
            overruns: 0,
        }
    }
}

/// A synthesised session: the bytes, the frames in them, and the truth.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthStream {
    /// the header sent first
    pub header: SessionHeader,
    /// every sample sent, in order
    pub samples: Vec<RawSample>,
    /// reference θref of every sample [rad]
    pub reference: Vec<f32>,
    /// the encoded stream
    pub bytes: Vec<u8>,
    /// every frame of `bytes`, in order
    pub frames: Vec<FrameSpan>,
}

/// Deterministic sample `seq` for reference `r` (see the module docs).
pub fn synth_sample(seq: u32, r: f32, scale: &Scale, tick_step: u32) -> RawSample {
    // SplitMix64 finaliser of the sequence number: a fixed, well-mixed dither
    let mut z = u64::from(seq).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let dither = (z & 0x7) as i32 - 3;
    let walk = ((z >> 8) & 0x3FF) as i32 - 512;
    let angle = (f64::from(r) / f64::from(scale.angle_rad_per_count)).round() as i32 + dither;
    let torque = (f64::from(r) * 4.0e4) as i32 + walk;
    RawSample {
        seq,
        tick: seq.wrapping_mul(tick_step).wrapping_add(12_345),
        torque,
        angle,
    }
}

/// Synthesises a session (see the module docs).
///
/// # Panics
/// When `opts.excitation` cannot be generated (a test's own mistake).
pub fn synth_stream(opts: &SynthOptions) -> SynthStream {
    let header = SessionHeader {
        protocol_version: PROTOCOL_VERSION,
        board_id: opts.board_id,
        session_id: opts.session_id,
        sample_rate_hz: opts.excitation.fs_hz,
        timer_hz: opts.timer_hz,
        excitation: opts.excitation,
        scale: Scale {
            torque_nm_per_count: 1.0e-3,
            angle_rad_per_count: 6.0e-6,
        },
    };
    let tick_step = opts.timer_hz / opts.excitation.fs_hz;
    let mut table = vec![0.0f32; opts.excitation.period_samples as usize];
    let mut gen = Excitation::new(&opts.excitation, &mut table).expect("valid synth excitation");
    let mut samples = Vec::with_capacity(opts.samples as usize);
    let mut reference = Vec::with_capacity(opts.samples as usize);
    for seq in 0..opts.samples {
        let r = gen.next().unwrap_or(0.0);
        samples.push(synth_sample(seq, r, &header.scale, tick_step));
        reference.push(r);
    }
    let layout = StreamLayout {
        batch_len: opts.batch_len,
        status_every: opts.status_every,
        overruns: opts.overruns,
        end: opts.end,
        // one header, as a protocol-1 board sent it: the fixtures place every frame
        header_every: 0,
    };
    let pairs = samples.iter().copied().zip(reference.iter().copied());
    let stream = encode_stream(&header, pairs, tick_step, &layout).expect("frame fits");
    SynthStream {
        header,
        samples,
        reference,
        bytes: stream.bytes,
        frames: stream.frames,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synth_stream_frames_and_their_leading_delimiters_tile_the_bytes_and_carry_every_sample_once()
    {
        let s = synth_stream(&SynthOptions::small());
        let mut at = 0;
        let mut next_seq = 0;
        for f in &s.frames {
            // each frame's leading delimiter, then its span
            assert_eq!(s.bytes[at as usize], 0, "delimiter starts each frame");
            at += 1;
            assert_eq!(f.offset, at);
            assert_eq!(
                s.bytes[(f.offset + f.len - 1) as usize],
                0,
                "delimiter ends each frame"
            );
            assert!(!s.bytes[f.offset as usize..(f.offset + f.len - 1) as usize].contains(&0));
            if let FrameContent::Batch { first, len } = f.content {
                assert_eq!(first, next_seq);
                next_seq += len;
            }
            at += f.len;
        }
        assert_eq!(at, s.bytes.len() as u64);
        assert_eq!(next_seq, 400);
        assert_eq!(s.samples.len(), 400);
    }
}
