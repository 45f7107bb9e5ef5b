//! What a capture holds and what arrived damaged: the summary `capture`, `info` and
//! `export` print, and the JSON they emit with `--json`.
//!
//! The report never smooths anything over. Missing sequence numbers are listed as
//! [`SeqGap`] ranges, every frame the decoder rejected is listed with its stream byte
//! offset and length ([`DamagedFrame`]), and the board's own counters (sampler overruns,
//! queue drops, transmit errors) are passed on as the board reported them last.
//! Byte offsets are offsets into the received stream (`.jcap` file offset − 8).

use std::fmt;

use serde::{Deserialize, Serialize};

use super::jcap::JcapEvent;

/// A run of sequence numbers that never arrived, inclusive at both ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SeqGap {
    /// first missing sequence number
    pub from: u32,
    /// last missing sequence number
    pub to: u32,
}

impl SeqGap {
    /// Number of missing samples in the gap.
    pub fn len(&self) -> u64 {
        u64::from(self.to) - u64::from(self.from) + 1
    }

    /// Always false: a gap holds at least one sequence number.
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// A frame the decoder rejected.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DamagedFrame {
    /// stream offset of the frame's first byte [bytes]
    pub offset: u64,
    /// bytes skipped, including the `0x00` delimiter when there was one [bytes]
    pub len: u64,
    /// short machine-readable kind: `cobs`, `crc`, `postcard`, `too_long`, `truncated`, ...
    pub kind: String,
    /// what was wrong, as the decoder said it
    pub error: String,
}

/// A batch whose samples arrived but whose reference CRC disagrees with the reference the
/// host regenerated from the session header: the board and the host do not run the same
/// excitation, or the batch was altered in a way its frame CRC did not catch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReferenceMismatch {
    /// sequence number of the batch's first sample
    pub first_seq: u32,
    /// samples in the batch
    pub len: u32,
    /// CRC the board sent
    pub board_crc: u32,
    /// CRC of the regenerated reference
    pub host_crc: u32,
}

/// One session header seen in the stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionSummary {
    /// board identifier from the header
    pub board_id: u32,
    /// session identifier from the header
    pub session_id: u32,
    /// stream offset of the first header of this session [bytes]
    pub offset: u64,
    /// samples received while this session was current
    pub samples: u64,
}

/// The board's last reported counters (from `Status` and `End` messages).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BoardCounters {
    /// sampler ticks whose sample could not be queued in time
    pub overruns: u32,
    /// samples dropped because the transmit queue was full
    pub queue_drops: u32,
    /// transmit errors the board saw
    pub tx_errors: u32,
}

/// Summary of a capture: counts, gaps, damaged frames, board counters.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CaptureReport {
    /// board identifier of the reported session (`None` before a header arrived)
    pub board_id: Option<u32>,
    /// the reported session (the first one in the stream)
    pub session_id: Option<u32>,
    /// stream bytes read [bytes]
    pub bytes: u64,
    /// frames decoded intact (all sessions)
    pub frames: u64,
    /// samples of the reported session that arrived (duplicates not counted)
    pub samples: u64,
    /// lowest sequence number received
    pub first_seq: Option<u32>,
    /// highest sequence number received
    pub last_seq: Option<u32>,
    /// sequence numbers that never arrived, in order
    pub gaps: Vec<SeqGap>,
    /// total number of missing samples (sum over `gaps`)
    pub missing_samples: u64,
    /// frames the decoder rejected, in stream order
    pub damaged_frames: Vec<DamagedFrame>,
    /// sampler overruns the board reported last (same as `board.overruns`)
    pub overruns: u32,
    /// all counters the board reported last
    pub board: BoardCounters,
    /// samples whose sequence number had already arrived (kept once)
    pub duplicates: u64,
    /// samples that arrived out of order behind a later one (kept, sorted)
    pub out_of_order: u64,
    /// batches whose reference CRC disagrees with the regenerated reference
    pub reference_mismatches: Vec<ReferenceMismatch>,
    /// samples no session header can scale (not kept): those of a stream without any
    /// header, or of a session whose `End` came before any header; samples received
    /// before the first header of their session are scaled with it and not counted here
    pub samples_without_header: u64,
    /// samples of sessions other than the reported one (not kept)
    pub samples_other_sessions: u64,
    /// every session header seen
    pub sessions: Vec<SessionSummary>,
    /// the board's `End` message for the reported session arrived
    pub ended: bool,
    /// host-side events (start, link lost/resumed, stop), from the `.events` sidecar
    pub link_events: Vec<JcapEvent>,
}

impl CaptureReport {
    /// True when nothing is missing, damaged or inconsistent (and no line of an slcan or
    /// candump source was bad).
    pub fn is_clean(&self) -> bool {
        self.bad_lines().count() == 0
            && self.gaps.is_empty()
            && self.damaged_frames.is_empty()
            && self.reference_mismatches.is_empty()
            && self.duplicates == 0
            && self.board == BoardCounters::default()
    }

    /// The `bad_line` events: lines of an slcan or candump source that could not be read,
    /// error replies of the adapter, CAN error frames.
    pub fn bad_lines(&self) -> impl Iterator<Item = &JcapEvent> {
        self.link_events
            .iter()
            .filter(|e| e.event == super::jcap::EventKind::BadLine)
    }

    /// Frames whose CRC did not match.
    pub fn crc_errors(&self) -> usize {
        self.damaged_frames
            .iter()
            .filter(|d| d.kind == "crc")
            .count()
    }
}

impl fmt::Display for CaptureReport {
    /// Human-readable summary, one fact per line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let opt = |v: Option<u32>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
        writeln!(
            f,
            "board {}  session {}  ({} session header{} seen)",
            self.board_id
                .map_or_else(|| "-".to_string(), |b| format!("{b:#010x}")),
            opt(self.session_id),
            self.sessions.len(),
            if self.sessions.len() == 1 { "" } else { "s" }
        )?;
        writeln!(f, "bytes            {}", self.bytes)?;
        writeln!(
            f,
            "frames           {} intact, {} damaged",
            self.frames,
            self.damaged_frames.len()
        )?;
        writeln!(
            f,
            "samples          {} (seq {}..{})",
            self.samples,
            opt(self.first_seq),
            opt(self.last_seq)
        )?;
        writeln!(
            f,
            "gaps             {} ({} samples missing)",
            self.gaps.len(),
            self.missing_samples
        )?;
        for g in self.gaps.iter().take(20) {
            writeln!(f, "  seq {}..={} ({} missing)", g.from, g.to, g.len())?;
        }
        if self.gaps.len() > 20 {
            writeln!(f, "  ... {} more (see --json)", self.gaps.len() - 20)?;
        }
        for d in self.damaged_frames.iter().take(20) {
            writeln!(
                f,
                "  damaged at byte {} ({} bytes): {}",
                d.offset, d.len, d.error
            )?;
        }
        if self.damaged_frames.len() > 20 {
            writeln!(
                f,
                "  ... {} more (see --json)",
                self.damaged_frames.len() - 20
            )?;
        }
        writeln!(
            f,
            "board counters   overruns {}, queue drops {}, tx errors {}",
            self.board.overruns, self.board.queue_drops, self.board.tx_errors
        )?;
        if self.duplicates > 0 || self.out_of_order > 0 {
            writeln!(
                f,
                "duplicates       {}, out of order {}",
                self.duplicates, self.out_of_order
            )?;
        }
        if !self.reference_mismatches.is_empty() {
            writeln!(
                f,
                "reference        {} batches disagree with the regenerated excitation (first at seq {})",
                self.reference_mismatches.len(),
                self.reference_mismatches[0].first_seq
            )?;
        }
        if self.samples_without_header > 0 {
            writeln!(
                f,
                "no header        {} samples have no session header to scale them (none arrived for their session)",
                self.samples_without_header
            )?;
        }
        if self.samples_other_sessions > 0 {
            writeln!(
                f,
                "other sessions   {} samples not reported here",
                self.samples_other_sessions
            )?;
        }
        for e in &self.link_events {
            if matches!(
                e.event,
                super::jcap::EventKind::LinkLost | super::jcap::EventKind::LinkResumed
            ) {
                writeln!(
                    f,
                    "  {} {} at byte {} {}",
                    e.utc, e.event, e.offset, e.detail
                )?;
            }
        }
        let bad = self.bad_lines().count();
        if bad > 0 {
            writeln!(f, "bad lines        {bad} (not read, capture went on)")?;
            for e in self.bad_lines().take(20) {
                writeln!(
                    f,
                    "  line {} (at byte {}): {}",
                    e.line.map_or_else(|| "-".to_string(), |l| l.to_string()),
                    e.offset,
                    e.detail
                )?;
            }
            if bad > 20 {
                writeln!(f, "  ... {} more (see --json)", bad - 20)?;
            }
        }
        write!(
            f,
            "end message      {}",
            if self.ended {
                "received"
            } else {
                "not received"
            }
        )
    }
}

/// Missing ranges between consecutive sorted, de-duplicated sequence numbers.
pub fn gaps_in(sorted_seqs: impl IntoIterator<Item = u32>) -> Vec<SeqGap> {
    let mut gaps = Vec::new();
    let mut prev: Option<u32> = None;
    for s in sorted_seqs {
        if let Some(p) = prev {
            if s > p + 1 {
                gaps.push(SeqGap {
                    from: p + 1,
                    to: s - 1,
                });
            }
        }
        prev = Some(s);
    }
    gaps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_in_lists_each_missing_run_inclusive() {
        let g = gaps_in([0, 1, 2, 5, 6, 10]);
        assert_eq!(
            g,
            vec![SeqGap { from: 3, to: 4 }, SeqGap { from: 7, to: 9 }]
        );
        assert_eq!(g.iter().map(SeqGap::len).sum::<u64>(), 5);
        assert!(gaps_in([7]).is_empty());
        assert!(gaps_in([0, 1, 2]).is_empty());
    }

    #[test]
    fn report_serialises_the_promised_json_fields() {
        let r = CaptureReport {
            samples: 10,
            gaps: vec![SeqGap { from: 3, to: 4 }],
            damaged_frames: vec![DamagedFrame {
                offset: 120,
                len: 23,
                kind: "crc".into(),
                error: "crc mismatch".into(),
            }],
            overruns: 2,
            ..CaptureReport::default()
        };
        let v: serde_json::Value = serde_json::to_value(&r).unwrap();
        assert_eq!(v["samples"], 10);
        assert_eq!(v["gaps"][0]["from"], 3);
        assert_eq!(v["gaps"][0]["to"], 4);
        assert_eq!(v["damaged_frames"][0]["offset"], 120);
        assert_eq!(v["damaged_frames"][0]["len"], 23);
        assert_eq!(v["damaged_frames"][0]["error"], "crc mismatch");
        assert_eq!(v["overruns"], 2);
        let back: CaptureReport = serde_json::from_value(v).unwrap();
        assert_eq!(back, r);
        assert_eq!(r.crc_errors(), 1);
        assert!(!r.is_clean());
    }
}
