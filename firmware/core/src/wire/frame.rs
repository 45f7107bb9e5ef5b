//! Frames on the link: [`encode_frame`] turns a [`Message`] into
//! `00 COBS(postcard + CRC-32) 00`; the streaming [`Decoder`] splits a byte
//! stream at every 0x00 and gives every frame back, good or damaged.

use super::cobs::cobs_decode_nonzero;
use super::{
    cobs_decode_in_place, cobs_encode, cobs_max_len, BatchError, Crc32, Message, MessageRef,
    MAX_FRAME_LEN, MAX_MESSAGE_LEN,
};

/// Why a message could not be framed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// postcard failed or the message exceeds [`MAX_MESSAGE_LEN`]
    Serialize,
    /// the output buffer is too small
    BufferTooSmall {
        /// bytes the frame may need
        needed: usize,
        /// bytes available
        available: usize,
    },
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Serialize => write!(f, "message does not serialise into {MAX_MESSAGE_LEN} bytes"),
            Self::BufferTooSmall { needed, available } => write!(
                f,
                "frame needs up to {needed} bytes, buffer has {available}"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for EncodeError {}

/// Frames `msg`: 0x00 + COBS(postcard + CRC-32 (LE)) + 0x00. Returns the frame
/// length (both delimiters included).
///
/// # Errors
/// [`EncodeError`]; `out` of [`MAX_FRAME_LEN`] bytes always suffices.
pub fn encode_frame(msg: &Message, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_frame_ref(MessageRef::from(msg), out)
}

/// [`encode_frame`] of a borrowed message: the same bytes, nothing moved.
///
/// # Errors
/// [`EncodeError`]; `out` of [`MAX_FRAME_LEN`] bytes always suffices.
pub fn encode_frame_ref(msg: MessageRef<'_>, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut scratch = [0u8; MAX_MESSAGE_LEN + 4];
    let n = postcard::to_slice(&msg, &mut scratch[..MAX_MESSAGE_LEN])
        .map_err(|_| EncodeError::Serialize)?
        .len();
    let crc = Crc32::checksum(&scratch[..n]);
    scratch[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let payload = &scratch[..n + 4];
    let needed = cobs_max_len(payload.len()) + 2;
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall {
            needed,
            available: out.len(),
        });
    }
    out[0] = 0;
    let len = cobs_encode(payload, &mut out[1..]).ok_or(EncodeError::BufferTooSmall {
        needed,
        available: out.len(),
    })?;
    out[len + 1] = 0;
    Ok(len + 2)
}

/// Why a frame was rejected.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// invalid COBS (a group runs past the end of the frame)
    Cobs,
    /// the CRC in the frame (`expected`) differs from the CRC of its bytes (`got`)
    Crc {
        /// CRC carried by the frame
        expected: u32,
        /// CRC computed over the received bytes
        got: u32,
    },
    /// the bytes are no valid postcard [`Message`]
    Postcard,
    /// a valid message followed by extra bytes
    TrailingBytes {
        /// extra bytes
        count: usize,
    },
    /// the frame exceeds [`MAX_FRAME_LEN`]
    TooLong {
        /// [`MAX_FRAME_LEN`]
        limit: usize,
    },
    /// the frame is too short to hold a CRC, or the stream ended inside it
    Truncated,
    /// a batch whose sample data is inconsistent
    Batch(BatchError),
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Cobs => write!(f, "invalid cobs encoding"),
            Self::Crc { expected, got } => {
                write!(
                    f,
                    "crc mismatch: frame says {expected:#010x}, bytes give {got:#010x}"
                )
            }
            Self::Postcard => write!(f, "not a valid message"),
            Self::TrailingBytes { count } => write!(f, "{count} bytes after the message"),
            Self::TooLong { limit } => write!(f, "frame longer than {limit} bytes"),
            Self::Truncated => write!(f, "frame truncated"),
            Self::Batch(e) => write!(f, "inconsistent sample batch: {e:?}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}

/// What the [`Decoder`] found.
// The message is inline (no allocation in core).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, PartialEq, Debug)]
pub enum DecodeEvent {
    /// a good frame
    Frame {
        /// stream offset of its first byte
        offset: u64,
        /// bytes including the delimiter
        len: usize,
        /// the message
        message: Message,
    },
    /// a bad frame (skipped)
    Damaged {
        /// stream offset of its first byte
        offset: u64,
        /// bytes including the delimiter (if any)
        len: usize,
        /// why
        error: DecodeError,
    },
}

/// Counts kept by the [`Decoder`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct DecoderStats {
    /// good frames
    pub frames: u64,
    /// damaged frames
    pub damaged: u64,
    /// bytes in damaged frames
    pub damaged_bytes: u64,
}

/// Streaming decoder: never panics, resynchronises at the next 0x00, reports
/// every bad frame with its byte offset and length. Empty frames (0x00
/// directly after 0x00: the leading delimiter of every frame, idle fill) are
/// skipped silently; a frame's offset is that of its first byte after the
/// leading delimiter, its length counts the closing delimiter.
pub struct Decoder {
    buf: [u8; MAX_FRAME_LEN],
    /// bytes of the current frame stored in `buf`
    stored: usize,
    /// bytes of the current frame seen (may exceed `stored` when too long)
    seen: usize,
    frame_start: u64,
    offset: u64,
    stats: DecoderStats,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl core::fmt::Debug for Decoder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Decoder")
            .field("offset", &self.offset)
            .field("pending", &self.seen)
            .field("stats", &self.stats)
            .finish()
    }
}

impl Decoder {
    /// Decoder at stream offset 0.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME_LEN],
            stored: 0,
            seen: 0,
            frame_start: 0,
            offset: 0,
            stats: DecoderStats {
                frames: 0,
                damaged: 0,
                damaged_bytes: 0,
            },
        }
    }

    /// Bytes consumed so far.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Counters.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Feeds bytes; calls `on_event` for every complete frame, good or bad.
    pub fn feed(&mut self, bytes: &[u8], mut on_event: impl FnMut(DecodeEvent)) {
        let mut rest = bytes;
        while !rest.is_empty() {
            // the bytes up to the next delimiter (or all) belong to the current frame
            let (body, delimited) = match find_zero(rest) {
                Some(z) => (&rest[..z], true),
                None => (rest, false),
            };
            // keep one byte of MAX_FRAME_LEN for the delimiter
            let room = (MAX_FRAME_LEN - 1).saturating_sub(self.stored);
            let take = body.len().min(room);
            if let Some(dst) = self.buf.get_mut(self.stored..self.stored + take) {
                dst.copy_from_slice(&body[..take]);
                self.stored += take;
            }
            self.seen += body.len();
            self.offset += body.len() as u64;
            if !delimited {
                break;
            }
            self.offset += 1;
            if self.seen > 0 {
                let event = self.finish_frame(self.seen + 1);
                on_event(event);
            }
            self.reset_frame();
            rest = &rest[body.len() + 1..];
        }
    }

    /// Ends the stream: reports an unterminated tail as [`DecodeError::Truncated`]
    /// (or `TooLong`).
    pub fn finish(&mut self, mut on_event: impl FnMut(DecodeEvent)) {
        if self.seen > 0 {
            let error = if self.seen > self.stored {
                DecodeError::TooLong {
                    limit: MAX_FRAME_LEN,
                }
            } else {
                DecodeError::Truncated
            };
            let event = self.damaged(self.seen, error);
            on_event(event);
        }
        self.reset_frame();
    }

    fn reset_frame(&mut self) {
        self.stored = 0;
        self.seen = 0;
        self.frame_start = self.offset;
    }

    fn damaged(&mut self, len: usize, error: DecodeError) -> DecodeEvent {
        self.stats.damaged += 1;
        self.stats.damaged_bytes += len as u64;
        DecodeEvent::Damaged {
            offset: self.frame_start,
            len,
            error,
        }
    }

    fn finish_frame(&mut self, len: usize) -> DecodeEvent {
        if self.seen > self.stored {
            return self.damaged(
                len,
                DecodeError::TooLong {
                    limit: MAX_FRAME_LEN,
                },
            );
        }
        let body = &mut self.buf[..self.stored];
        match cobs_decode_nonzero(body)
            .ok_or(DecodeError::Cobs)
            .and_then(|n| check_payload(&body[..n]))
        {
            Ok(message) => {
                self.stats.frames += 1;
                DecodeEvent::Frame {
                    offset: self.frame_start,
                    len,
                    message,
                }
            }
            Err(error) => self.damaged(len, error),
        }
    }
}

/// Index of the first 0x00 in `bytes`: eight bytes at a time (a word has a
/// zero byte iff `(w - 0x01…01) & !w & 0x80…80` is non-zero), then bytewise.
fn find_zero(bytes: &[u8]) -> Option<usize> {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let mut words = bytes.chunks_exact(8);
    let mut at = 0;
    for w in &mut words {
        let v = u64::from_le_bytes([w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]]);
        let z = v.wrapping_sub(LO) & !v & HI;
        if z != 0 {
            // the lowest flagged byte is the first zero (borrows only run upwards)
            return Some(at + (z.trailing_zeros() / 8) as usize);
        }
        at += 8;
    }
    words
        .remainder()
        .iter()
        .position(|&b| b == 0)
        .map(|i| at + i)
}

/// Decodes one COBS frame body (without delimiter), in place.
///
/// # Errors
/// Every [`DecodeError`] but `TooLong`.
pub fn decode_frame_body(body: &mut [u8]) -> Result<Message, DecodeError> {
    decode_payload(body)
}

fn decode_payload(body: &mut [u8]) -> Result<Message, DecodeError> {
    let n = cobs_decode_in_place(body).ok_or(DecodeError::Cobs)?;
    check_payload(&body[..n])
}

/// CRC, postcard and batch checks of a COBS-decoded frame.
fn check_payload(body: &[u8]) -> Result<Message, DecodeError> {
    let n = body.len();
    if n < 5 {
        return Err(DecodeError::Truncated);
    }
    let (payload, crc_bytes) = body[..n].split_at(n - 4);
    let expected = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let got = Crc32::checksum(payload);
    if expected != got {
        return Err(DecodeError::Crc { expected, got });
    }
    let (message, rest) =
        postcard::take_from_bytes::<Message>(payload).map_err(|_| DecodeError::Postcard)?;
    if !rest.is_empty() {
        return Err(DecodeError::TrailingBytes { count: rest.len() });
    }
    if let Message::Batch(batch) = &message {
        batch.check().map_err(DecodeError::Batch)?;
    }
    Ok(message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::wire::test_support::{encode, header, synthetic};
    use crate::wire::{BatchBuilder, RawSample, SessionHeader, Status};

    fn decode_all(bytes: &[u8]) -> Vec<DecodeEvent> {
        let mut dec = Decoder::new();
        let mut events = Vec::new();
        dec.feed(bytes, |e| events.push(e));
        dec.finish(|e| events.push(e));
        events
    }

    #[test]
    fn frames_round_trip_through_decoder_with_offsets() {
        let (samples, refs) = synthetic(64, 3);
        let mut builder = BatchBuilder::new(500, 64);
        for (s, r) in samples.iter().zip(&refs).take(63) {
            assert!(builder.push(*s, *r).is_none());
        }
        let batch = builder.push(samples[63], refs[63]).unwrap();
        let status = Status {
            seq: 64,
            overruns: 1,
            queue_drops: 2,
            tx_errors: 3,
        };
        let msgs = vec![
            Message::Header(header()),
            Message::Batch(batch),
            Message::Status(status),
            Message::End(status),
        ];
        let mut stream = Vec::new();
        let mut offsets = Vec::new();
        for m in &msgs {
            // the decoder places a frame after its leading delimiter
            offsets.push(stream.len() as u64 + 1);
            stream.extend(encode(m));
        }
        let events = decode_all(&stream);
        assert_eq!(events.len(), 4);
        for (i, e) in events.iter().enumerate() {
            match e {
                DecodeEvent::Frame {
                    offset,
                    len,
                    message,
                } => {
                    assert_eq!(*offset, offsets[i]);
                    assert_eq!(
                        *len as u64,
                        offsets.get(i + 1).map_or(stream.len() as u64, |o| o - 1) - offsets[i]
                    );
                    assert_eq!(message, &msgs[i]);
                }
                other => panic!("frame {i}: {other:?}"),
            }
        }
    }

    #[test]
    fn line_noise_before_the_first_frame_leaves_it_intact() {
        // a receiver that connects mid-stream sees the tail of a frame, then
        // noise without any zero, then the header: the leading delimiter
        // closes the noise as one damaged frame and the header arrives intact
        let frame = encode(&Message::Header(header()));
        assert_eq!((frame[0], frame[frame.len() - 1]), (0, 0));
        assert!(frame[1..frame.len() - 1].iter().all(|&b| b != 0));
        let noise = [0x55u8, 0xAA, 0x17, 0xFF, 0x03, 0x81, 0x42];
        let mut stream = noise.to_vec();
        stream.extend_from_slice(&frame);
        let events = decode_all(&stream);
        assert_eq!(events.len(), 2, "{events:?}");
        assert!(matches!(
            events[0],
            DecodeEvent::Damaged {
                offset: 0,
                len: 8,
                ..
            }
        ));
        assert_eq!(
            events[1],
            DecodeEvent::Frame {
                offset: noise.len() as u64 + 1,
                len: frame.len() - 1,
                message: Message::Header(header()),
            }
        );
    }

    #[test]
    fn decoder_reports_garbage_then_resynchronises() {
        let status = Status {
            seq: 5,
            ..Status::default()
        };
        let frame = encode(&Message::Status(status));
        let mut stream = vec![0x11, 0x22, 0x33, 0x00];
        stream.extend(&frame);
        stream.extend([0x00, 0x00]); // idle fill
        stream.extend(&frame[..frame.len() - 3]); // cut frame, no delimiter
        let events = decode_all(&stream);
        assert_eq!(events.len(), 3, "{events:?}");
        assert!(
            matches!(
                events[0],
                DecodeEvent::Damaged {
                    offset: 0,
                    len: 4,
                    error: DecodeError::Cobs
                }
            ),
            "{:?}",
            events[0]
        );
        assert!(
            matches!(&events[1], DecodeEvent::Frame { offset: 5, message: Message::Status(s), .. } if *s == status)
        );
        match events[2] {
            DecodeEvent::Damaged { offset, len, error } => {
                // after the fill, the cut frame's own leading delimiter
                assert_eq!(offset as usize, 4 + frame.len() + 2 + 1);
                assert_eq!(len, frame.len() - 4);
                assert_eq!(error, DecodeError::Truncated);
            }
            ref other => panic!("{other:?}"),
        }
    }

    #[test]
    fn decoder_rejects_flipped_bit_with_crc_figures() {
        let msg = Message::Status(Status {
            seq: 77,
            ..Status::default()
        });
        let mut buf = [0u8; 64];
        let mut payload = postcard::to_slice(&msg, &mut buf).unwrap().to_vec();
        let crc = Crc32::checksum(&payload);
        payload.extend(crc.to_le_bytes());
        payload[1] ^= 0x10; // flip one bit of the message, keep the CRC
        let mut frame = vec![0u8; cobs_max_len(payload.len()) + 1];
        let n = cobs_encode(&payload, &mut frame).unwrap();
        frame.truncate(n + 1);
        let events = decode_all(&frame);
        assert_eq!(
            events,
            vec![DecodeEvent::Damaged {
                offset: 0,
                len: n + 1,
                error: DecodeError::Crc {
                    expected: crc,
                    got: Crc32::checksum(&payload[..payload.len() - 4]),
                },
            }]
        );
    }

    #[test]
    fn decoder_rejects_frames_over_max_len() {
        let mut stream = vec![0x01u8; MAX_FRAME_LEN + 10];
        stream.push(0);
        let good = encode(&Message::End(Status::default()));
        stream.extend(&good);
        let events = decode_all(&stream);
        assert_eq!(events.len(), 2);
        assert_eq!(
            events[0],
            DecodeEvent::Damaged {
                offset: 0,
                len: MAX_FRAME_LEN + 11,
                error: DecodeError::TooLong {
                    limit: MAX_FRAME_LEN
                }
            }
        );
        assert!(matches!(
            events[1],
            DecodeEvent::Frame {
                message: Message::End(_),
                ..
            }
        ));
    }

    /// One corruption of the original stream at byte position `pos`.
    #[derive(Clone, Copy, Debug)]
    enum Corruption {
        Flip { pos: usize, mask: u8 },
        Drop { pos: usize },
        Insert { pos: usize, len: usize, seed: u64 },
        Truncate { pos: usize },
    }

    impl Corruption {
        fn pos(&self) -> usize {
            match *self {
                Self::Flip { pos, .. }
                | Self::Drop { pos }
                | Self::Insert { pos, .. }
                | Self::Truncate { pos } => pos,
            }
        }
    }

    fn pool_of_messages() -> Vec<(Message, Vec<u8>)> {
        let mut rng = SplitMix64::new(0xC0FFEE);
        let mut pool = Vec::new();
        let mut seq = 0u32;
        for i in 0..300u32 {
            let msg = match i % 10 {
                0 if i % 30 == 0 => Message::Header(SessionHeader {
                    session_id: i,
                    ..header()
                }),
                1 | 2 => Message::Status(Status {
                    seq: i,
                    overruns: (rng.next_u64() % 300) as u32,
                    queue_drops: 0,
                    tx_errors: (rng.next_u64() % 3) as u32,
                }),
                3 => Message::End(Status {
                    seq: i,
                    ..Status::default()
                }),
                _ => {
                    let n = if rng.next_u64().is_multiple_of(8) {
                        1 + (rng.next_u64() % 64) as usize
                    } else {
                        1 + (rng.next_u64() % 6) as usize
                    };
                    let (samples, refs) = synthetic(n, rng.next_u64());
                    let mut b = BatchBuilder::new(500, 64);
                    let mut done = None;
                    for (s, r) in samples.iter().zip(&refs) {
                        let s = RawSample {
                            seq: seq.wrapping_add(s.seq),
                            ..*s
                        };
                        done = b.push(s, *r);
                    }
                    seq = seq.wrapping_add(1000);
                    Message::Batch(done.or_else(|| b.flush()).unwrap())
                }
            };
            let frame = encode(&msg);
            pool.push((msg, frame));
        }
        pool
    }

    #[test]
    fn decoder_survives_a_million_corruptions_without_false_accepts() {
        let pool = pool_of_messages();
        let mut rng = SplitMix64::new(0xBAD5_EED5);
        let mut corruptions = 0u64;
        let mut accepted = 0u64;
        let mut clean_checked = 0u64;
        let mut damaged = 0u64;
        let mut dec = Decoder::new();
        let mut events = Vec::new();
        let mut stream = Vec::new();
        let mut bounds = Vec::new();
        let mut corrupted = Vec::new();
        while corruptions < 1_000_000 {
            // a window of 6 distinct messages
            let start = (rng.next_u64() % (pool.len() as u64 - 6)) as usize;
            let window = &pool[start..start + 6];
            stream.clear();
            bounds.clear();
            for (_, f) in window {
                bounds.push(stream.len());
                stream.extend_from_slice(f);
            }
            bounds.push(stream.len());
            let frame_of = |p: usize| bounds.partition_point(|&b| b <= p) - 1;

            // 1 to 5 corruptions, sometimes ending in a truncation
            let count = 1 + (rng.next_u64() % 5) as usize;
            let mut ops: Vec<Corruption> = (0..count)
                .map(|_| {
                    let pos = (rng.next_u64() % stream.len() as u64) as usize;
                    match rng.next_u64() % 20 {
                        0..=8 => Corruption::Flip {
                            pos,
                            mask: 1 << (rng.next_u64() % 8),
                        },
                        9..=11 => Corruption::Flip {
                            pos,
                            mask: (rng.next_u64() % 255 + 1) as u8,
                        },
                        12..=15 => Corruption::Drop { pos },
                        16..=18 => Corruption::Insert {
                            pos,
                            len: 1 + (rng.next_u64() % 12) as usize,
                            seed: rng.next_u64(),
                        },
                        _ => Corruption::Truncate { pos },
                    }
                })
                .collect();
            ops.sort_by_key(|op| op.pos());
            corruptions += ops.len() as u64;

            // apply, and mark touched frames
            let mut touched = [false; 6];
            corrupted.clear();
            let mut op_i = 0;
            'bytes: for (p, &byte) in stream.iter().enumerate() {
                let mut b = Some(byte);
                while op_i < ops.len() && ops[op_i].pos() == p {
                    touched[frame_of(p)] = true;
                    match ops[op_i] {
                        Corruption::Flip { mask, .. } => b = b.map(|x| x ^ mask),
                        Corruption::Drop { .. } => b = None,
                        Corruption::Insert { len, seed, .. } => {
                            let mut g = SplitMix64::new(seed);
                            for _ in 0..len {
                                // a third of garbage bytes are zeros
                                let v = g.next_u64();
                                corrupted.push(if v.is_multiple_of(3) {
                                    0
                                } else {
                                    (v >> 8) as u8
                                });
                            }
                        }
                        Corruption::Truncate { .. } => {
                            touched.iter_mut().skip(frame_of(p)).for_each(|t| *t = true);
                            break 'bytes;
                        }
                    }
                    op_i += 1;
                }
                corrupted.extend(b);
            }

            // decode in random-sized chunks, as a serial port delivers them
            events.clear();
            let mut rest = &corrupted[..];
            while !rest.is_empty() {
                let n = (1 + rng.next_u64() % 64).min(rest.len() as u64) as usize;
                dec.feed(&rest[..n], |e| events.push(e));
                rest = &rest[n..];
            }
            dec.finish(|e| events.push(e));

            // events tile the stream: between them only idle 0x00 bytes
            let base = dec.offset() - corrupted.len() as u64;
            let mut covered = base;
            let mut next_index = 0usize;
            let mut seen = [false; 6];
            for e in &events {
                let (offset, len) = match e {
                    DecodeEvent::Frame {
                        offset,
                        len,
                        message,
                    } => {
                        // never a corrupted frame: the message is an original,
                        // in order
                        let i = window
                            .iter()
                            .position(|(m, _)| m == message)
                            .unwrap_or_else(|| panic!("accepted a message not sent: {message:?}"));
                        assert!(i >= next_index, "message {i} out of order");
                        next_index = i + 1;
                        seen[i] = true;
                        accepted += 1;
                        (*offset, *len)
                    }
                    DecodeEvent::Damaged { offset, len, .. } => {
                        damaged += 1;
                        (*offset, *len)
                    }
                };
                assert!(offset >= covered, "overlapping events");
                let gap = &corrupted[(covered - base) as usize..(offset - base) as usize];
                assert!(
                    gap.iter().all(|&b| b == 0),
                    "unreported bytes before {offset}"
                );
                covered = offset + len as u64;
            }
            let tail = &corrupted[(covered - base) as usize..];
            assert!(tail.iter().all(|&b| b == 0), "unreported tail");

            // every intact frame whose predecessor is intact was decoded
            for j in 0..6 {
                if !touched[j] && (j == 0 || !touched[j - 1]) {
                    assert!(seen[j], "intact frame {j} lost; ops {ops:?}");
                    clean_checked += 1;
                }
            }
        }
        assert!(corruptions >= 1_000_000);
        // the loop must have exercised both paths substantially
        assert!(
            damaged > 200_000 && accepted > 200_000 && clean_checked > 200_000,
            "damaged {damaged} accepted {accepted} clean {clean_checked}"
        );
        eprintln!(
            "corruptions {corruptions}, damaged frames {damaged}, accepted {accepted}, intact frames checked {clean_checked}"
        );
    }

    #[test]
    fn find_zero_finds_the_first_zero_at_every_position_and_length() {
        for len in 0..40 {
            assert_eq!(find_zero(&vec![0x80u8; len]), None, "len {len}");
            for z in 0..len {
                let mut v: Vec<u8> = (0..len).map(|i| (i % 255 + 1) as u8).collect();
                v[z] = 0;
                if z + 3 < len {
                    v[z + 3] = 0;
                }
                assert_eq!(find_zero(&v), Some(z), "len {len}, zero at {z}");
            }
        }
    }

    #[test]
    fn decoder_gives_the_same_events_whatever_the_feed_sizes() {
        let mut stream = Vec::new();
        for (_, bytes) in pool_of_messages() {
            stream.extend_from_slice(&bytes);
            stream.extend_from_slice(&[0x31, 0x00, 0x00, 0x07]);
        }
        let whole = decode_all(&stream);
        assert!(whole
            .iter()
            .any(|e| matches!(e, DecodeEvent::Damaged { .. })));
        for step in [1, 3, 8, 77] {
            let mut d = Decoder::new();
            let mut events = Vec::new();
            for c in stream.chunks(step) {
                d.feed(c, |e| events.push(e));
            }
            d.finish(|e| events.push(e));
            assert_eq!(events, whole, "step {step}");
        }
    }
}
