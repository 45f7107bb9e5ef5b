//! CAN link: the encoded wire frames cut into CAN data frames.
//!
//! Each CAN frame carries one header byte and up to 7 (classic CAN, 8 data
//! bytes) or 63 (CAN FD, 64 data bytes) bytes of one wire frame:
//!
//! ```text
//! byte 0: bit 7 = first fragment of a wire frame, bits 6..0 = rolling counter (mod 128)
//! bytes 1..: the next bytes of the wire frame (a 0x00 after its first byte ends it)
//! ```
//!
//! A wire frame starts with its own 0x00 delimiter (protocol version 2); the
//! reassembler keeps that leading zero and ends the frame at the next one, so
//! the reassembled stream is byte for byte the serial stream.
//!
//! The counter increases by one per CAN frame across the whole stream, so the
//! [`Reassembler`] notices a lost, repeated or reordered CAN frame, discards
//! the wire frame in progress, reports it, and restarts at the next fragment
//! marked "first". A CAN FD frame's data length must be one of 0–8, 12, 16,
//! 20, 24, 32, 48, 64: the last fragment is padded with zeros, which the
//! reassembler drops after the delimiter. Keeping COBS inside CAN costs under
//! 1 % and lets the host feed the same [`crate::wire::Decoder`] as on serial.
//!
//! # Bus load (classic CAN 2.0A, 11-bit identifier)
//! A data frame with `n` data bytes has `44 + 8n` bits (SOF 1, identifier 11,
//! RTR 1, IDE 1, r0 1, DLC 4, data 8n, CRC 15, CRC delimiter 1, ACK 2, EOF 7)
//! plus 3 bits of interframe space. Bit stuffing covers SOF to CRC (`34 + 8n`
//! bits) and adds at most one bit per 4 after the first:
//! `⌊(34 + 8n − 1)/4⌋`. Worst case: `47 + 8n + ⌊(33 + 8n)/4⌋` bits, 135 bits
//! for 8 data bytes (see [`classic_frame_bits_worst`]).

use embedded_can::{Frame, Id};

use super::{FrameSink, TxError};
use crate::wire::MAX_FRAME_LEN;

/// Wire-frame bytes per classic CAN frame (8 data bytes minus the header).
pub const CLASSIC_PAYLOAD: usize = 7;
/// Wire-frame bytes per CAN FD frame (64 data bytes minus the header).
pub const FD_PAYLOAD: usize = 63;

const FIRST: u8 = 0x80;
const COUNTER_MASK: u8 = 0x7F;

/// Smallest CAN FD data length ≥ `n` (n ≤ 64).
pub const fn fd_len(n: usize) -> usize {
    match n {
        0..=8 => n,
        9..=12 => 12,
        13..=16 => 16,
        17..=20 => 20,
        21..=24 => 24,
        25..=32 => 32,
        33..=48 => 48,
        _ => 64,
    }
}

/// Worst-case bits on the bus of one classic CAN 2.0A data frame with `n`
/// data bytes, stuffing and interframe space included (module docs).
pub const fn classic_frame_bits_worst(n: usize) -> u32 {
    let n = n as u32;
    47 + 8 * n + (33 + 8 * n) / 4
}

/// Fraction of a classic CAN bus of `bitrate` bit/s used by `frames_per_s`
/// frames of `n` data bytes, worst-case stuffing.
pub fn classic_bus_load(frames_per_s: f64, n: usize, bitrate: f64) -> f64 {
    frames_per_s * classic_frame_bits_worst(n) as f64 / bitrate
}

/// CAN frames needed for one wire frame of `len` bytes with `payload` bytes per CAN frame.
pub const fn fragments_for(len: usize, payload: usize) -> usize {
    len.div_ceil(payload)
}

/// Cuts wire frames into CAN frames.
#[derive(Clone, Debug)]
pub struct Fragmenter {
    id: Id,
    payload: usize,
    fd: bool,
    counter: u8,
}

impl Fragmenter {
    /// Classic CAN: 7 wire bytes per 8-byte frame, identifier `id`.
    pub fn classic(id: impl Into<Id>) -> Self {
        Self {
            id: id.into(),
            payload: CLASSIC_PAYLOAD,
            fd: false,
            counter: 0,
        }
    }

    /// CAN FD: 63 wire bytes per 64-byte frame, identifier `id`.
    pub fn fd(id: impl Into<Id>) -> Self {
        Self {
            id: id.into(),
            payload: FD_PAYLOAD,
            fd: true,
            counter: 0,
        }
    }

    /// Wire bytes per CAN frame.
    pub fn payload(&self) -> usize {
        self.payload
    }

    /// Cuts `frame` (one encoded wire frame) into CAN frames handed to `emit`
    /// in order. Returns the number of CAN frames.
    ///
    /// # Errors
    /// [`TxError::Fragment`] if the frame type refuses a fragment,
    /// [`TxError::Link`] if `emit` fails; the wire frame is then incomplete
    /// and the counter has advanced past the fragments sent, so the host
    /// discards it.
    pub fn fragment<F: Frame, E>(
        &mut self,
        frame: &[u8],
        mut emit: impl FnMut(F) -> Result<(), E>,
    ) -> Result<usize, TxError> {
        let mut data = [0u8; 64];
        let mut count = 0;
        for (i, chunk) in frame.chunks(self.payload).enumerate() {
            data[0] = (self.counter & COUNTER_MASK) | if i == 0 { FIRST } else { 0 };
            data[1..1 + chunk.len()].copy_from_slice(chunk);
            let mut len = 1 + chunk.len();
            if self.fd {
                let padded = fd_len(len);
                data[len..padded].iter_mut().for_each(|b| *b = 0);
                len = padded;
            }
            self.counter = self.counter.wrapping_add(1) & COUNTER_MASK;
            let can = F::new(self.id, &data[..len]).ok_or(TxError::Fragment)?;
            emit(can).map_err(|_| TxError::Link)?;
            count += 1;
        }
        Ok(count)
    }
}

/// [`FrameSink`] over a blocking `embedded_can` transmitter.
pub struct CanSink<C: embedded_can::blocking::Can> {
    can: C,
    fragmenter: Fragmenter,
    tx_errors: u32,
    frames_sent: u64,
}

impl<C: embedded_can::blocking::Can> CanSink<C> {
    /// Sink sending through `can` with `fragmenter` (classic or FD).
    pub fn new(can: C, fragmenter: Fragmenter) -> Self {
        Self {
            can,
            fragmenter,
            tx_errors: 0,
            frames_sent: 0,
        }
    }

    /// CAN frames sent.
    pub fn can_frames_sent(&self) -> u64 {
        self.frames_sent
    }

    /// The transmitter.
    pub fn get_mut(&mut self) -> &mut C {
        &mut self.can
    }
}

impl<C: embedded_can::blocking::Can> FrameSink for CanSink<C> {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        let can = &mut self.can;
        let mut sent = 0u64;
        let result = self.fragmenter.fragment::<C::Frame, _>(frame, |f| {
            can.transmit(&f)?;
            sent += 1;
            Ok::<(), C::Error>(())
        });
        self.frames_sent += sent;
        result.map(|_| ()).inspect_err(|_| {
            self.tx_errors = self.tx_errors.saturating_add(1);
        })
    }

    fn tx_errors(&self) -> u32 {
        self.tx_errors
    }
}

/// What the [`Reassembler`] reports.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum ReassemblyEvent<'a> {
    /// a complete wire frame, delimiter included: feed it to a [`crate::wire::Decoder`]
    Frame(&'a [u8]),
    /// the counter jumped: CAN frames were lost or reordered; `discarded`
    /// bytes of a partial wire frame were dropped
    Lost {
        /// counter expected
        expected: u8,
        /// counter received
        got: u8,
        /// bytes of the partial wire frame discarded
        discarded: usize,
    },
    /// the same counter twice in a row: a repeated CAN frame, ignored
    Duplicate {
        /// its counter
        counter: u8,
    },
    /// a CAN frame with no data, or a wire frame longer than [`MAX_FRAME_LEN`] (discarded)
    Malformed {
        /// bytes discarded
        discarded: usize,
    },
}

/// Counts kept by the [`Reassembler`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct ReassemblyStats {
    /// wire frames completed
    pub frames: u64,
    /// counter gaps
    pub lost: u64,
    /// repeated CAN frames
    pub duplicates: u64,
    /// CAN frames skipped while waiting for a first fragment
    pub skipped: u64,
}

/// Host side: CAN frames back into wire frames.
pub struct Reassembler {
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
    in_frame: bool,
    last_counter: Option<u8>,
    stats: ReassemblyStats,
}

impl Default for Reassembler {
    fn default() -> Self {
        Self::new()
    }
}

impl Reassembler {
    /// Empty reassembler; the first CAN frame sets the counter.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME_LEN],
            len: 0,
            in_frame: false,
            last_counter: None,
            stats: ReassemblyStats {
                frames: 0,
                lost: 0,
                duplicates: 0,
                skipped: 0,
            },
        }
    }

    /// Counters.
    pub fn stats(&self) -> ReassemblyStats {
        self.stats
    }

    /// Processes the data bytes of one received CAN frame.
    pub fn push(&mut self, data: &[u8], mut on_event: impl FnMut(ReassemblyEvent<'_>)) {
        let Some((&head, body)) = data.split_first() else {
            on_event(ReassemblyEvent::Malformed { discarded: 0 });
            return;
        };
        let counter = head & COUNTER_MASK;
        let first = head & FIRST != 0;
        if let Some(last) = self.last_counter {
            if counter == last {
                self.stats.duplicates += 1;
                on_event(ReassemblyEvent::Duplicate { counter });
                return;
            }
            let expected = last.wrapping_add(1) & COUNTER_MASK;
            if counter == last.wrapping_sub(1) & COUNTER_MASK {
                // one behind the last one taken: a CAN frame swapped with its
                // successor, which was taken (and reported) already; accepting
                // it now would deliver its wire frame out of order
                self.stats.lost += 1;
                on_event(ReassemblyEvent::Lost {
                    expected,
                    got: counter,
                    discarded: 0,
                });
                return;
            }
            if counter != expected {
                self.stats.lost += 1;
                let discarded = if self.in_frame { self.len } else { 0 };
                self.in_frame = false;
                self.len = 0;
                on_event(ReassemblyEvent::Lost {
                    expected,
                    got: counter,
                    discarded,
                });
            }
        }
        self.last_counter = Some(counter);
        if first {
            if self.in_frame && self.len > 0 {
                // a first fragment inside a frame: the sender gave up on the
                // previous frame (a transmit error)
                let expected = counter;
                on_event(ReassemblyEvent::Lost {
                    expected,
                    got: counter,
                    discarded: self.len,
                });
                self.stats.lost += 1;
            }
            self.in_frame = true;
            self.len = 0;
        }
        if !self.in_frame {
            self.stats.skipped += 1;
            return;
        }
        for &b in body {
            if self.len >= MAX_FRAME_LEN {
                let discarded = self.len;
                self.in_frame = false;
                self.len = 0;
                on_event(ReassemblyEvent::Malformed { discarded });
                return;
            }
            self.buf[self.len] = b;
            self.len += 1;
            // a zero as the first byte is the frame's leading delimiter
            if b == 0 && self.len > 1 {
                // delimiter: the rest of this CAN frame is padding
                let n = self.len;
                self.in_frame = false;
                self.len = 0;
                self.stats.frames += 1;
                on_event(ReassemblyEvent::Frame(&self.buf[..n]));
                return;
            }
        }
    }
}

/// In-memory CAN frame, classic (≤ 8 bytes) or FD (valid FD lengths ≤ 64):
/// tests both ends of the CAN path without a controller (no vcan is needed).
#[cfg(any(feature = "std", test))]
#[derive(Clone, Debug, PartialEq)]
pub struct MemFrame {
    /// identifier
    pub id: Id,
    /// payload [bytes]
    pub data: std::vec::Vec<u8>,
}

#[cfg(any(feature = "std", test))]
impl Frame for MemFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() > 64 || fd_len(data.len()) != data.len() {
            return None;
        }
        Some(Self {
            id: id.into(),
            data: data.to_vec(),
        })
    }
    fn new_remote(_: impl Into<Id>, _: usize) -> Option<Self> {
        None
    }
    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }
    fn is_remote_frame(&self) -> bool {
        false
    }
    fn id(&self) -> Id {
        self.id
    }
    fn dlc(&self) -> usize {
        self.data.len()
    }
    fn data(&self) -> &[u8] {
        &self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::wire::{
        encode_frame, BatchBuilder, DecodeEvent, Decoder, Message, RawSample, Status,
    };
    use embedded_can::StandardId;

    fn id() -> StandardId {
        StandardId::new(0x321).unwrap()
    }

    /// A realistic mix of wire frames with unique messages.
    fn messages() -> Vec<Message> {
        let mut rng = SplitMix64::new(11);
        let mut out = Vec::new();
        let mut seq = 0u32;
        for i in 0..400u32 {
            if i % 9 == 0 {
                out.push(Message::Status(Status {
                    seq: i,
                    ..Status::default()
                }));
                continue;
            }
            let n = 2 + (rng.next_u64() % 63) as usize;
            let mut b = BatchBuilder::new(500, 64);
            let mut done = None;
            for k in 0..n {
                let s = RawSample {
                    seq,
                    tick: seq * 500,
                    torque: (rng.next_u64() % 4000) as i32 - 2000,
                    angle: (k * k) as i32 * 40,
                };
                seq += 1;
                done = b.push(s, k as f32);
            }
            out.push(Message::Batch(done.or_else(|| b.flush()).unwrap()));
        }
        out
    }

    fn encode(m: &Message) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(m, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    /// Fragments all messages, perturbs the CAN stream, reassembles and
    /// decodes; checks that nothing false is accepted and that every wire
    /// frame whose fragments all arrived in order is decoded.
    fn run(fd: bool, seed: u64) -> (usize, usize, ReassemblyStats) {
        let msgs = messages();
        let mut frag = if fd {
            Fragmenter::fd(id())
        } else {
            Fragmenter::classic(id())
        };
        // (wire frame index, CAN frame)
        let mut can: Vec<(usize, MemFrame)> = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            let bytes = encode(m);
            let n = frag
                .fragment::<MemFrame, ()>(&bytes, |f| {
                    assert!(f.dlc() <= if fd { 64 } else { 8 });
                    can.push((i, f));
                    Ok(())
                })
                .unwrap();
            assert_eq!(n, fragments_for(bytes.len(), frag.payload()));
        }
        let mut rng = SplitMix64::new(seed);
        let mut touched = vec![false; msgs.len()];
        let mut channel: Vec<MemFrame> = Vec::new();
        let mut i = 0;
        let mut dups = 0;
        while i < can.len() {
            match rng.next_u64() % 100 {
                0 | 1 => touched[can[i].0] = true, // dropped
                2 | 3 => {
                    // duplicated back to back: harmless
                    channel.push(can[i].1.clone());
                    channel.push(can[i].1.clone());
                    dups += 1;
                }
                4 if i + 1 < can.len() => {
                    // swapped with the next one
                    touched[can[i].0] = true;
                    touched[can[i + 1].0] = true;
                    channel.push(can[i + 1].1.clone());
                    channel.push(can[i].1.clone());
                    i += 1;
                }
                _ => channel.push(can[i].1.clone()),
            }
            i += 1;
        }
        let mut re = Reassembler::new();
        let mut dec = Decoder::new();
        let mut decoded = Vec::new();
        let mut lost_reports = 0;
        for f in &channel {
            re.push(f.data(), |e| match e {
                ReassemblyEvent::Frame(bytes) => dec.feed(bytes, |d| {
                    if let DecodeEvent::Frame { message, .. } = d {
                        decoded.push(message)
                    }
                }),
                ReassemblyEvent::Lost { .. } => lost_reports += 1,
                _ => {}
            });
        }
        // nothing false, in order
        let mut next = 0;
        for m in &decoded {
            let pos = msgs[next..].iter().position(|x| x == m).unwrap_or_else(|| {
                panic!("decoded a message that was not sent, or out of order: {m:?} after {next}")
            });
            next += pos + 1;
        }
        // every untouched wire frame arrives
        let intact = touched.iter().filter(|t| !**t).count();
        for (j, m) in msgs.iter().enumerate() {
            if !touched[j] {
                assert!(decoded.contains(m), "intact wire frame {j} lost");
            }
        }
        assert!(lost_reports > 0);
        assert_eq!(re.stats().duplicates, dups);
        (decoded.len(), intact, re.stats())
    }

    #[test]
    fn classic_can_reassembly_survives_drops_duplicates_and_swaps() {
        let (decoded, intact, stats) = run(false, 1);
        assert!(decoded >= intact && intact > 100, "{decoded} {intact}");
        assert!(stats.lost > 10);
    }

    #[test]
    fn can_fd_reassembly_survives_drops_duplicates_and_swaps() {
        let (decoded, intact, stats) = run(true, 2);
        assert!(decoded >= intact && intact > 200, "{decoded} {intact}");
        assert!(stats.lost > 5);
    }

    #[test]
    fn fd_fragments_use_valid_lengths_and_padding_is_dropped() {
        let frame = encode(&Message::End(Status::default()));
        let mut frag = Fragmenter::fd(id());
        let mut out: Vec<MemFrame> = Vec::new();
        frag.fragment::<MemFrame, ()>(&frame, |f| {
            out.push(f);
            Ok(())
        })
        .unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].dlc(), fd_len(frame.len() + 1));
        let mut re = Reassembler::new();
        let mut got = Vec::new();
        re.push(out[0].data(), |e| {
            if let ReassemblyEvent::Frame(b) = e {
                got.extend_from_slice(b)
            }
        });
        assert_eq!(got, frame);
    }

    #[test]
    fn lost_fragment_discards_partial_frame_and_reports_it() {
        let frame = encode(&Message::Status(Status {
            seq: u32::MAX,
            overruns: 0xFFFF_FFF0,
            queue_drops: 0x0FFF_FFFF,
            tx_errors: 0x7FFF_FFFF,
        }));
        assert!(frame.len() > 14);
        let mut frag = Fragmenter::classic(id());
        let mut can: Vec<MemFrame> = Vec::new();
        for _ in 0..2 {
            frag.fragment::<MemFrame, ()>(&frame, |f| {
                can.push(f);
                Ok(())
            })
            .unwrap();
        }
        let per = fragments_for(frame.len(), CLASSIC_PAYLOAD);
        can.remove(1); // second fragment of the first wire frame
        let mut re = Reassembler::new();
        let mut events = Vec::new();
        for f in &can {
            re.push(f.data(), |e| {
                events.push(match e {
                    ReassemblyEvent::Frame(b) => format!("frame {}", b.len()),
                    other => format!("{other:?}"),
                })
            });
        }
        assert_eq!(
            events,
            vec![
                "Lost { expected: 1, got: 2, discarded: 7 }".to_string(),
                format!("frame {}", frame.len()),
            ]
        );
        assert_eq!(re.stats().skipped as usize, per - 2);
    }

    #[test]
    fn classic_frame_bits_match_the_worst_case_formula() {
        // 8 data bytes: 111 bits + 24 stuff bits
        assert_eq!(classic_frame_bits_worst(8), 135);
        // 0 data bytes: 47 bits + 8 stuff bits
        assert_eq!(classic_frame_bits_worst(0), 55);
        // 1000 frames/s of 8 bytes at 1 Mbit/s: 13.5 %
        assert!((classic_bus_load(1000.0, 8, 1e6) - 0.135).abs() < 1e-12);
    }

    /// Blocking CAN bus in memory that refuses chosen transmissions.
    struct MemBus {
        sent: Vec<MemFrame>,
        calls: u32,
        fail_on: Vec<u32>,
    }

    impl embedded_can::blocking::Can for MemBus {
        type Frame = MemFrame;
        type Error = embedded_can::ErrorKind;
        fn transmit(&mut self, frame: &MemFrame) -> Result<(), Self::Error> {
            self.calls += 1;
            if self.fail_on.contains(&self.calls) {
                return Err(embedded_can::ErrorKind::Acknowledge);
            }
            self.sent.push(frame.clone());
            Ok(())
        }
        fn receive(&mut self) -> Result<MemFrame, Self::Error> {
            Err(embedded_can::ErrorKind::Other)
        }
    }

    #[test]
    fn can_sink_counts_failed_frames_and_host_recovers() {
        let bus = MemBus {
            sent: Vec::new(),
            calls: 0,
            fail_on: vec![5, 30],
        };
        let mut sink = CanSink::new(bus, Fragmenter::classic(id()));
        let msgs: Vec<Message> = messages().into_iter().take(20).collect();
        let mut delivered = Vec::new();
        for m in &msgs {
            if sink.send_frame(&encode(m)).is_ok() {
                delivered.push(m.clone());
            }
        }
        assert_eq!(sink.tx_errors(), 2);
        assert_eq!(delivered.len(), 18);
        assert_eq!(sink.can_frames_sent() as usize, sink.get_mut().sent.len());
        let mut re = Reassembler::new();
        let mut dec = Decoder::new();
        let mut decoded = Vec::new();
        for f in &sink.get_mut().sent {
            re.push(f.data(), |e| {
                if let ReassemblyEvent::Frame(b) = e {
                    dec.feed(b, |d| {
                        if let DecodeEvent::Frame { message, .. } = d {
                            decoded.push(message)
                        }
                    })
                }
            });
        }
        assert_eq!(decoded, delivered);
    }
}
