//! CAN frames back into the serial byte stream, losing no evidence of damage.
//!
//! The board cuts each encoded wire frame into CAN frames (one header byte with a
//! "first" flag and a rolling counter, then up to 7 or 63 wire bytes; see
//! `jointid_core::transport::can`). [`CanStream`] feeds them to the core's
//! `Reassembler` and appends to the capture stream:
//!
//! - every wire frame the reassembler completes, as is (so a clean CAN capture is
//!   byte-for-byte the stream a serial capture of the same run holds);
//! - every wire frame it had to abandon (a CAN frame lost or reordered inside it, its
//!   first CAN frame lost), as **the bytes of it that did arrive**, up to and including
//!   its own delimiter, so the decoder reports it as one damaged frame at its own offset
//!   instead of it vanishing without trace;
//! - when such a frame's delimiter never arrives (the next wire frame's first CAN frame
//!   comes first, or the frame grew too long), its bytes followed by one added `0x00`.
//!
//! Repeated CAN frames (same counter twice) are dropped, as the reassembler does, and so
//! is a CAN frame that arrives after its successor (its wire frame is damaged already); FD
//! padding after a delimiter is dropped. The added `0x00` bytes are the only bytes of a
//! CAN capture that did not travel on the bus; they are counted in [`CanStats`].

use embedded_can::{Frame, Id};
use jointid_core::transport::can::{Reassembler, ReassemblyEvent};

/// Bit 7 of a fragment's header byte: first fragment of a wire frame.
const FIRST: u8 = 0x80;

/// Counts of what happened at the CAN level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CanStats {
    /// CAN data frames with the board's identifier
    pub can_frames: u64,
    /// CAN frames with another identifier (ignored)
    pub foreign: u64,
    /// repeated CAN frames (ignored)
    pub duplicates: u64,
    /// wire frames abandoned or orphaned (written as damaged frames)
    pub damaged: u64,
    /// `0x00` bytes added to close an abandoned wire frame
    pub added_delimiters: u64,
}

/// Reassembles the board's CAN frames into the capture byte stream (see the module docs).
pub struct CanStream {
    id: Option<Id>,
    re: Reassembler,
    /// bytes of the wire frame in progress, as the reassembler holds them
    partial: Vec<u8>,
    /// bytes of a wire frame whose head was lost, until its delimiter
    orphan: Vec<u8>,
    stats: CanStats,
}

impl std::fmt::Debug for CanStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CanStream")
            .field("id", &self.id)
            .field("partial", &self.partial.len())
            .field("orphan", &self.orphan.len())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

enum Ev {
    Abandon,
    /// one behind the last CAN frame taken (swapped with its successor): ignored
    Behind,
    Frame(Vec<u8>),
    Duplicate,
}

impl CanStream {
    /// A reassembler that takes the CAN frames with identifier `id` (`None`: all frames).
    pub fn new(id: Option<Id>) -> Self {
        Self {
            id,
            re: Reassembler::new(),
            partial: Vec::new(),
            orphan: Vec::new(),
            stats: CanStats::default(),
        }
    }

    /// CAN-level counts.
    pub fn stats(&self) -> CanStats {
        self.stats
    }

    /// Feeds one received CAN frame (classic or FD); appends stream bytes to `out`.
    /// Remote frames and frames with another identifier are ignored.
    pub fn push(&mut self, frame: &impl Frame, out: &mut Vec<u8>) {
        if frame.is_remote_frame() {
            return;
        }
        if self.id.is_some_and(|id| id != frame.id()) {
            self.stats.foreign += 1;
            return;
        }
        self.push_data(frame.data(), out);
    }

    /// Feeds the data bytes of one CAN frame with the board's identifier.
    pub fn push_data(&mut self, data: &[u8], out: &mut Vec<u8>) {
        self.stats.can_frames += 1;
        let first = data.first().is_some_and(|h| h & FIRST != 0);
        if first && !self.orphan.is_empty() {
            // a new wire frame begins before the orphaned tail's delimiter arrived
            self.close(true, out);
        }
        let skipped = self.re.stats().skipped;
        let mut events = Vec::new();
        self.re.push(data, |e| match e {
            ReassemblyEvent::Frame(b) => events.push(Ev::Frame(b.to_vec())),
            ReassemblyEvent::Lost {
                expected,
                got,
                discarded: 0,
            } if got == expected.wrapping_sub(2) & 0x7F => events.push(Ev::Behind),
            ReassemblyEvent::Lost { discarded, .. } | ReassemblyEvent::Malformed { discarded }
                if discarded > 0 =>
            {
                events.push(Ev::Abandon)
            }
            ReassemblyEvent::Duplicate { .. } => events.push(Ev::Duplicate),
            _ => {}
        });
        let mut completed = false;
        for e in events {
            match e {
                Ev::Duplicate => {
                    self.stats.duplicates += 1;
                    return;
                }
                // the reassembler took its successor already: its bytes cannot be placed
                Ev::Behind => return,
                // the rest of the abandoned frame may still come: a lost middle
                // fragment leaves head and tail, which stay one damaged frame
                Ev::Abandon if !first => {
                    let mut head = std::mem::take(&mut self.partial);
                    head.append(&mut self.orphan);
                    self.orphan = head;
                }
                Ev::Abandon => self.close(false, out),
                Ev::Frame(b) => {
                    out.extend_from_slice(&b);
                    self.partial.clear();
                    completed = true;
                }
            }
        }
        let body = data.get(1..).unwrap_or(&[]);
        if self.re.stats().skipped > skipped {
            // the reassembler waits for a first fragment: keep the tail as evidence
            match body.iter().position(|&b| b == 0) {
                Some(i) => {
                    self.orphan.extend_from_slice(&body[..=i]);
                    self.stats.damaged += 1;
                    out.append(&mut self.orphan);
                }
                None => self.orphan.extend_from_slice(body),
            }
        } else if !completed {
            self.partial.extend_from_slice(body);
        }
    }

    /// Writes the abandoned partial frame (or the orphaned tail) with an added delimiter.
    fn close(&mut self, orphan: bool, out: &mut Vec<u8>) {
        let buf = if orphan {
            &mut self.orphan
        } else {
            &mut self.partial
        };
        if buf.is_empty() {
            return;
        }
        out.append(buf);
        out.push(0);
        self.stats.damaged += 1;
        self.stats.added_delimiters += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::StreamAnalyzer;
    use crate::test_support::synth::{synth_stream, FrameContent, SynthOptions};
    use embedded_can::StandardId;
    use jointid_core::transport::can::{Fragmenter, MemFrame as Mem};

    fn board_id() -> Id {
        Id::Standard(StandardId::new(0x101).unwrap())
    }

    /// The synthesised stream cut into CAN frames; `owner[i]` = wire frame of CAN frame i.
    fn fragments(
        fd: bool,
    ) -> (
        crate::test_support::synth::SynthStream,
        Vec<Mem>,
        Vec<usize>,
    ) {
        let mut opts = SynthOptions::small();
        opts.batch_len = 64;
        let s = synth_stream(&opts);
        let mut fr = if fd {
            Fragmenter::fd(board_id())
        } else {
            Fragmenter::classic(board_id())
        };
        let (mut frames, mut owner) = (Vec::new(), Vec::new());
        for (w, f) in s.frames.iter().enumerate() {
            // the whole wire frame: its leading delimiter lies just before the span
            let bytes = &s.bytes[f.offset as usize - 1..(f.offset + f.len) as usize];
            fr.fragment(bytes, |m: Mem| {
                frames.push(m);
                owner.push(w);
                Ok::<(), ()>(())
            })
            .unwrap();
        }
        (s, frames, owner)
    }

    fn run(frames: &[Mem]) -> Vec<u8> {
        let mut cs = CanStream::new(Some(board_id()));
        let mut out = Vec::new();
        for f in frames {
            cs.push(f, &mut out);
        }
        out
    }

    #[test]
    fn can_stream_of_a_clean_bus_is_the_serial_stream_classic_and_fd() {
        for fd in [false, true] {
            let (s, frames, _) = fragments(fd);
            assert_eq!(run(&frames), s.bytes, "fd {fd}");
        }
    }

    #[test]
    fn can_stream_ignores_repeats_and_foreign_identifiers() {
        let (s, frames, _) = fragments(false);
        let other = Id::Standard(StandardId::new(0x555).unwrap());
        let mut noisy = Vec::new();
        for (i, f) in frames.iter().enumerate() {
            noisy.push(f.clone());
            if i % 7 == 3 {
                noisy.push(f.clone());
                noisy.push(Mem {
                    id: other,
                    data: vec![0x80, 0, 0, 0],
                });
            }
        }
        assert_eq!(run(&noisy), s.bytes);
    }

    #[test]
    fn can_stream_turns_a_lost_can_frame_into_one_damaged_frame_at_its_offset() {
        for fd in [false, true] {
            let (s, frames, owner) = fragments(fd);
            // batch wire frames that span at least three CAN frames
            let spans: Vec<usize> = (0..s.frames.len())
                .filter(|&w| {
                    matches!(s.frames[w].content, FrameContent::Batch { .. })
                        && owner.iter().filter(|&&o| o == w).count() >= 3
                })
                .collect();
            assert!(spans.len() >= 2, "fd {fd}: need long batches");
            // lose a middle fragment of one batch and the first fragment of another
            let (mid_w, head_w) = (spans[0], spans[spans.len() - 1]);
            let mid_i = owner.iter().position(|&o| o == mid_w).unwrap() + 1;
            let head_i = owner.iter().position(|&o| o == head_w).unwrap();
            let kept: Vec<Mem> = frames
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != mid_i && *i != head_i)
                .map(|(_, f)| f.clone())
                .collect();
            let out = run(&kept);
            let mut an = StreamAnalyzer::new(false);
            an.feed(&out);
            let report = an.finish_report();
            // the lost wire frames are damaged, each reported once; all others intact
            assert_eq!(report.damaged_frames.len(), 2, "fd {fd}: {report}");
            assert_eq!(report.frames as usize, s.frames.len() - 2);
            // the first damaged frame starts where the stream had reached the batch
            assert_eq!(report.damaged_frames[0].offset, s.frames[mid_w].offset);
            // head and tail of it arrived, one CAN payload is missing
            let payload = if fd { 63 } else { 7 };
            assert_eq!(report.damaged_frames[0].len, s.frames[mid_w].len - payload);
            // the other is its tail (its first CAN payload, leading delimiter included,
            // is lost) from where the stream had reached its wire frame: the span's
            // offset less its leading delimiter, less the payload lost from `mid_w`
            let tail_len = s.frames[head_w].len + 1 - payload;
            let head_at = s.frames[head_w].offset - 1 - payload;
            assert_eq!(report.damaged_frames[1].len, tail_len);
            assert_eq!(report.damaged_frames[1].offset, head_at);
            let lost = |w: usize| match s.frames[w].content {
                FrameContent::Batch { len, .. } => u64::from(len),
                _ => 0,
            };
            assert_eq!(report.missing_samples, lost(mid_w) + lost(head_w));
        }
    }

    #[test]
    fn can_stream_reports_a_wire_frame_with_two_swapped_can_frames_once_and_adds_nothing() {
        for fd in [false, true] {
            let (s, frames, owner) = fragments(fd);
            let long: Vec<usize> = (0..s.frames.len())
                .filter(|&w| {
                    matches!(s.frames[w].content, FrameContent::Batch { .. })
                        && owner.iter().filter(|&&o| o == w).count() >= 3
                })
                .collect();
            // the second and third CAN frames of one batch arrive the wrong way round;
            // the second CAN frame of the next long batch is lost
            let (w, w2) = (long[0], long[1]);
            let i = owner.iter().position(|&o| o == w).unwrap() + 1;
            let j = owner.iter().position(|&o| o == w2).unwrap() + 1;
            let mut damaged = frames.clone();
            let lost = damaged.remove(j);
            damaged.swap(i, i + 1);
            let out = run(&damaged);
            let mut an = StreamAnalyzer::new(false);
            an.feed(&out);
            let report = an.finish_report();
            assert_eq!(report.damaged_frames.len(), 2, "fd {fd}: {report}");
            assert_eq!(report.damaged_frames[0].offset, s.frames[w].offset);
            assert_eq!(report.frames as usize, s.frames.len() - 2);
            // the late CAN frame's bytes are dropped, none is written twice or elsewhere
            let late = damaged[i + 1].data.len() as u64 - 1;
            assert_eq!(report.damaged_frames[0].len, s.frames[w].len - late);
            let missing = lost.data.len() as u64 - 1;
            assert_eq!(report.damaged_frames[1].len, s.frames[w2].len - missing);
            assert_eq!(
                out.len() as u64,
                s.bytes.len() as u64 - late - missing,
                "fd {fd}"
            );
        }
    }

    #[test]
    fn can_stream_closes_a_frame_whose_delimiter_was_lost_with_one_added_zero() {
        let (s, frames, owner) = fragments(false);
        let w = (0..s.frames.len())
            .find(|&w| {
                matches!(s.frames[w].content, FrameContent::Batch { .. })
                    && owner.iter().filter(|&&o| o == w).count() >= 3
            })
            .unwrap();
        let last_i = owner.iter().rposition(|&o| o == w).unwrap();
        let kept: Vec<Mem> = frames
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != last_i)
            .map(|(_, f)| f.clone())
            .collect();
        let mut cs = CanStream::new(Some(board_id()));
        let mut out = Vec::new();
        for f in &kept {
            cs.push(f, &mut out);
        }
        assert_eq!(cs.stats().added_delimiters, 1);
        assert_eq!(cs.stats().damaged, 1);
        let mut an = StreamAnalyzer::new(false);
        an.feed(&out);
        let report = an.finish_report();
        assert_eq!(report.damaged_frames.len(), 1, "{report}");
        let arrived = s.frames[w].len - frames[last_i].data.len() as u64 + 1;
        assert_eq!(report.damaged_frames[0].offset, s.frames[w].offset);
        assert_eq!(report.damaged_frames[0].len, arrived + 1);
        assert_eq!(report.frames as usize, s.frames.len() - 1);
    }
}
