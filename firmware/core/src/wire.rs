//! The wire protocol between the board and the host.
//!
//! Every message is serialised with postcard, followed by the CRC-32 of those
//! bytes (IEEE 802.3 polynomial, reflected, little-endian), COBS-encoded
//! (Cheshire and Baker, "Consistent Overhead Byte Stuffing", IEEE/ACM ToN
//! 1999), and sent between two 0x00 delimiters: `00 COBS(message + CRC) 00`.
//! COBS removes every zero from the frame, so a receiver always
//! resynchronises at the next 0x00 after garbage, a lost byte or a cut link;
//! the leading 0x00 (since protocol version 2) closes whatever line noise or
//! partial frame came before, so even the first frame a receiver sees after
//! connecting late arrives intact (two zeros in a row are an empty frame,
//! which the [`Decoder`] skips). The CRC-32 rejects damaged frames (every
//! error of up to 3 bits and every burst of up to 32 bits within a frame of
//! this size, other damage with probability 1 - 2⁻³²).
//!
//! A session is: a [`SessionHeader`] (protocol version, board, sample rate,
//! timer rate, the [`ExcitationConfig`] that the host regenerates the reference
//! from, and the [`Scale`] from counts to SI units), then [`SampleBatch`]es with
//! a [`Status`] every few batches, then [`Message::End`]. The header is sent
//! again, unchanged, after every [`HEADER_INTERVAL_S`] of samples
//! ([`header_interval_samples`]): a receiver that starts late still gets
//! everything it needs to scale the samples and regenerate the reference
//! within one interval, and may scale the samples it received before it.
//! A repeated header is the same message as the first (about 52 bytes framed),
//! so old receivers read it as the session going on.
//!
//! # Sample batches
//! A batch carries up to [`BATCH_CAPACITY`] consecutive samples (consecutive
//! `seq`). The first sample's tick is stored in full; every later sample
//! stores the zigzag-LEB128 deviation of its tick step from the nominal step
//! (one byte, normally 0). Torque and angle are stored as zigzag-LEB128
//! residuals of a per-batch polynomial predictor of order 0, 1 or 2 (the
//! value, its first or its second difference), chosen per channel and batch
//! by the encoder as the one with the fewest bytes. All arithmetic wraps, so
//! every i32 input round-trips. The reference does not travel: the batch
//! carries the CRC-32 of the little-endian f32 bits of its reference samples,
//! which the host checks against its own regeneration.
//!
//! Changing any of this changes the bytes pinned by the golden test and must
//! bump [`PROTOCOL_VERSION`].

use serde::{Deserialize, Serialize};

use crate::excitation::ExcitationConfig;

#[cfg(test)]
mod test_support;

mod crc;

pub use crc::{reference_crc, Crc32};

mod cobs;

pub use cobs::{cobs_decode_in_place, cobs_encode, cobs_max_len};

mod batch;

pub use batch::{BatchBuilder, BatchError};

mod frame;

pub use frame::{
    decode_frame_body, encode_frame, encode_frame_ref, DecodeError, DecodeEvent, Decoder,
    DecoderStats, EncodeError,
};

/// Version of the wire format; the golden-bytes test pins version 2.
///
/// Version 2 adds the leading 0x00 before every frame and repeats the session
/// header every [`HEADER_INTERVAL_S`]; version 1 streams (one header, frames
/// ended by 0x00 only) decode with the same [`Decoder`].
pub const PROTOCOL_VERSION: u16 = 2;

/// Interval between two session headers of a stream [s].
///
/// One second: a receiver started late scales its first samples within 1 s,
/// holding at most 1 s of raw samples until then (32 KiB on the host at
/// 2 kHz), and a capture of at least 1 s always holds a header. The repeated
/// header (54 bytes framed) costs 52 bytes/s, 0.76 % of the seed-000 stream at
/// 2 kHz (6.9 kB/s); the leading delimiters another 34 bytes/s, 0.50 %
/// (`cargo bench -p jointid-core --features std --bench wire_load` prints both).
pub const HEADER_INTERVAL_S: u32 = 1;

/// Samples between two session headers at `sample_rate_hz` [Hz]:
/// [`HEADER_INTERVAL_S`] of samples (at least 1).
pub const fn header_interval_samples(sample_rate_hz: u32) -> u32 {
    let n = sample_rate_hz.saturating_mul(HEADER_INTERVAL_S);
    if n == 0 {
        1
    } else {
        n
    }
}

/// Most samples in one [`SampleBatch`].
pub const BATCH_CAPACITY: usize = 64;

/// Largest encoding of one sample: three 5-byte varints.
const MAX_SAMPLE_BYTES: usize = 15;

/// Capacity of a batch's delta-coded data [bytes].
pub const BATCH_DATA_CAPACITY: usize = BATCH_CAPACITY * MAX_SAMPLE_BYTES;

/// Largest postcard encoding of a [`Message`] [bytes] (a full worst-case batch
/// is about 990 bytes).
pub const MAX_MESSAGE_LEN: usize = 1024;

/// Largest frame on the wire: leading 0x00 + COBS(message + 4-byte CRC) + 0x00
/// delimiter [bytes].
pub const MAX_FRAME_LEN: usize = cobs_max_len(MAX_MESSAGE_LEN + 4) + 2;

/// Conversion of raw counts to SI units.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scale {
    /// torque [N·m] = torque counts · `torque_nm_per_count`
    pub torque_nm_per_count: f32,
    /// motor angle [rad] = angle counts · `angle_rad_per_count`
    pub angle_rad_per_count: f32,
}

/// First message of a session.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SessionHeader {
    /// [`PROTOCOL_VERSION`] of the sender
    pub protocol_version: u16,
    /// board identifier (for example the MCU's unique id folded to 32 bits)
    pub board_id: u32,
    /// session identifier chosen by the board
    pub session_id: u32,
    /// sample rate [Hz]
    pub sample_rate_hz: u32,
    /// rate of the timer that stamps `RawSample::tick` [Hz]
    pub timer_hz: u32,
    /// excitation the reference is generated from (regenerated by the host)
    pub excitation: ExcitationConfig,
    /// counts to SI units
    pub scale: Scale,
}

/// One sample as the board took it, in raw counts.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawSample {
    /// sample index k since the start of the ramp-in
    pub seq: u32,
    /// timer ticks at the sampling instant (wraps)
    pub tick: u32,
    /// torque reference u [counts]
    pub torque: i32,
    /// motor angle θm [counts]
    pub angle: i32,
}

/// Counters the board reports periodically and at the end.
#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// samples taken so far (the next sample's seq)
    pub seq: u32,
    /// samples lost because the sampler's queue was full
    pub overruns: u32,
    /// samples lost on the transmit side (a frame that could not be sent)
    pub queue_drops: u32,
    /// transport write errors
    pub tx_errors: u32,
}

/// Everything that travels on the link.
// No allocation in core: a batch is stored inline (about 1 KB).
#[allow(clippy::large_enum_variant)]
#[derive(Serialize, Deserialize, Clone, PartialEq, Debug)]
pub enum Message {
    /// session header, first
    Header(SessionHeader),
    /// delta-coded samples
    Batch(SampleBatch),
    /// periodic counters
    Status(Status),
    /// final counters; nothing follows
    End(Status),
}

/// A [`Message`] that borrows its content: serialises to the same bytes
/// (same variants in the same order), so a batch can be framed where it lies,
/// without moving it into a `Message` (see [`encode_frame_ref`]).
#[derive(Serialize, Clone, Copy, Debug)]
pub enum MessageRef<'m> {
    /// session header, first
    Header(&'m SessionHeader),
    /// delta-coded samples
    Batch(&'m SampleBatch),
    /// periodic counters
    Status(&'m Status),
    /// final counters; nothing follows
    End(&'m Status),
}

impl<'m> From<&'m Message> for MessageRef<'m> {
    fn from(msg: &'m Message) -> Self {
        match msg {
            Message::Header(h) => Self::Header(h),
            Message::Batch(b) => Self::Batch(b),
            Message::Status(s) => Self::Status(s),
            Message::End(s) => Self::End(s),
        }
    }
}

/// Compact, delta-coded consecutive samples (see the module docs).
#[derive(Serialize, Deserialize, Clone, PartialEq, Eq, Debug)]
pub struct SampleBatch {
    first_seq: u32,
    first_tick: u32,
    tick_step: u32,
    count: u8,
    /// bits 0–1: torque predictor order, bits 2–3: angle predictor order
    predictors: u8,
    reference_crc: [u8; 4],
    #[serde(
        serialize_with = "serialize_data",
        deserialize_with = "deserialize_data"
    )]
    data: heapless::Vec<u8, BATCH_DATA_CAPACITY>,
}

/// Serialises the batch data as a byte string. In postcard that is the same
/// bytes as the default sequence of `u8` (varint length, then the bytes), but
/// one copy instead of one serializer call per byte.
fn serialize_data<S: serde::Serializer>(
    data: &heapless::Vec<u8, BATCH_DATA_CAPACITY>,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.serialize_bytes(data)
}

/// Reads the batch data written by [`serialize_data`]: in postcard a byte
/// string is the same bytes as a sequence of `u8`, and it arrives as one
/// borrowed slice (one copy) instead of one deserializer call per byte.
fn deserialize_data<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<heapless::Vec<u8, BATCH_DATA_CAPACITY>, D::Error> {
    struct DataVisitor;
    impl<'de> serde::de::Visitor<'de> for DataVisitor {
        type Value = heapless::Vec<u8, BATCH_DATA_CAPACITY>;

        fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            write!(f, "at most {BATCH_DATA_CAPACITY} bytes of sample data")
        }

        fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Self::Value, E> {
            heapless::Vec::from_slice(v).map_err(|_| E::invalid_length(v.len(), &self))
        }

        fn visit_seq<A: serde::de::SeqAccess<'de>>(
            self,
            mut seq: A,
        ) -> Result<Self::Value, A::Error> {
            let mut out = heapless::Vec::new();
            while let Some(b) = seq.next_element::<u8>()? {
                out.push(b)
                    .map_err(|_| serde::de::Error::invalid_length(out.len() + 1, &self))?;
            }
            Ok(out)
        }
    }
    deserializer.deserialize_bytes(DataVisitor)
}

#[cfg(test)]
mod tests {
    use super::test_support::{encode, header};
    use super::*;
    use crate::rng::SplitMix64;

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    #[test]
    fn golden_frames_are_pinned() {
        // One frame of each message type. A change here is a wire-format
        // change: bump PROTOCOL_VERSION and update the host.
        assert_eq!(PROTOCOL_VERSION, 2);
        let mut builder = BatchBuilder::new(500, 4);
        let samples = [
            RawSample {
                seq: 100,
                tick: 50_000,
                torque: -1200,
                angle: 300_000,
            },
            RawSample {
                seq: 101,
                tick: 50_500,
                torque: -1190,
                angle: 300_150,
            },
            RawSample {
                seq: 102,
                tick: 51_001,
                torque: -1185,
                angle: 300_290,
            },
            RawSample {
                seq: 103,
                tick: 51_500,
                torque: -1187,
                angle: 300_420,
            },
        ];
        let refs = [0.001f32, 0.0015, 0.002, 0.0025];
        let mut batch = None;
        for (s, r) in samples.iter().zip(refs) {
            batch = builder.push(*s, r);
        }
        let status = Status {
            seq: 104,
            overruns: 0,
            queue_drops: 0,
            tx_errors: 1,
        };
        let got = [
            hex(&encode(&Message::Header(header()))),
            hex(&encode(&Message::Batch(batch.unwrap()))),
            hex(&encode(&Message::Status(status))),
            hex(&encode(&Message::End(status))),
        ];
        assert_eq!(got, GOLDEN, "got {got:#?}");
    }

    const GOLDEN: [&str; 4] = [
        "00010c028180d02307d00fc0843d07d00f8827b002011248420ad7a33ca5a796afd6ddd706d00f0401010a3adb0fc936c9f7accc00",
        "00140164d08603f403040924d440930fdf12c0cf240e14ac02020a13010313f881efc500",
        "00030268010601074b773500",
        "00030368010601b762170800",
    ];

    #[test]
    fn header_interval_is_one_second_of_samples_and_never_zero() {
        assert_eq!(header_interval_samples(2000), 2000 * HEADER_INTERVAL_S);
        assert_eq!(header_interval_samples(0), 1);
        assert_eq!(header_interval_samples(u32::MAX), u32::MAX);
    }

    #[test]
    fn worst_case_batch_fits_max_frame_len() {
        let mut rng = SplitMix64::new(9);
        let mut builder = BatchBuilder::new(0, BATCH_CAPACITY);
        let mut batch = None;
        for k in 0..BATCH_CAPACITY {
            let s = RawSample {
                seq: k as u32,
                tick: rng.next_u64() as u32,
                torque: rng.next_u64() as i32,
                angle: rng.next_u64() as i32,
            };
            batch = builder.push(s, 1.0);
        }
        let frame = encode(&Message::Batch(batch.unwrap()));
        assert!(frame.len() <= MAX_FRAME_LEN, "{}", frame.len());
        assert!(frame.len() > 900);
    }
}
