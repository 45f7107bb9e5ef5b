//! From received bytes to samples and a report: the one place that interprets a stream,
//! used alike by the live capture (progress, summary) and by [`super::read_jcap`].
//!
//! [`StreamAnalyzer`] feeds the bytes to `jointid_core::wire::Decoder`, keeps every
//! intact frame, lists every damaged one with its stream offset, follows session headers,
//! tracks which sequence numbers arrived (as sorted ranges, so duplicates and late
//! arrivals are recognised without a per-sample set) and remembers each batch's reference
//! CRC. It regenerates the excitation from the session header (`jointid_core::excitation`)
//! once, as ramp-in, one period and ramp-out (the signal is periodic between the ramps),
//! gives every kept sample its reference and converts its raw counts to SI with the
//! header's scale as it arrives; at [`StreamAnalyzer::finish`] it checks every batch's
//! reference CRC against slices of that period.
//!
//! Samples that arrive before any session header (a capture started late, after the
//! board's first header) are held raw and given to the session of the first header that
//! follows (the board repeats its header every second, `jointid_core::wire::
//! HEADER_INTERVAL_S`), scaled and checked like the others; only those of a session whose
//! `End` arrives before any header, or of a stream that holds no header at all, stay
//! unscaled and are counted as samples without a header.
//!
//! **Invariant**: nothing is interpolated or invented. Samples are kept exactly as they
//! arrived (each sequence number once); the report says where the holes are.

use std::sync::Arc;

use jointid_core::excitation::{Excitation, ExcitationConfig, ExcitationError};
use jointid_core::wire::{
    Crc32, DecodeError, DecodeEvent, Decoder, Message, RawSample, SessionHeader, Status,
    BATCH_CAPACITY,
};

use super::report::{
    BoardCounters, CaptureReport, DamagedFrame, ReferenceMismatch, SeqGap, SessionSummary,
};
use super::{CaptureError, CaptureRecord, CaptureSample};

/// Live counters, cheap to read after every chunk (for the progress line).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    /// stream bytes read [bytes]
    pub bytes: u64,
    /// samples of the reported session received
    pub samples: u64,
    /// highest sequence number received in the reported session
    pub last_seq: Option<u32>,
    /// holes in the sequence so far
    pub gaps: u64,
    /// samples missing in those holes
    pub missing: u64,
    /// frames rejected for a bad CRC
    pub crc_errors: u64,
    /// frames rejected for any reason (CRC included)
    pub damaged: u64,
    /// sampler overruns the board reported last
    pub overruns: u32,
}

/// One batch's bookkeeping for the reference check.
#[derive(Clone, Copy, Debug)]
struct BatchRef {
    first_seq: u32,
    len: u32,
    crc: u32,
}

/// Streaming interpreter of a capture's bytes.
#[derive(Debug)]
pub struct StreamAnalyzer {
    decoder: Decoder,
    /// stream offset at which the current decoder started
    base: u64,
    bytes: u64,
    keep_samples: bool,
    frames: u64,
    damaged: Vec<DamagedFrame>,
    crc_errors: u64,
    /// the reported session's first header
    header: Option<SessionHeader>,
    sessions: Vec<SessionSummary>,
    /// the session id asked for ([`Self::select_session`]); the first session otherwise
    wanted: Option<u32>,
    /// index into `sessions` of the reported session
    reported: Option<usize>,
    /// index into `sessions` of the session the next batch belongs to
    current: Option<usize>,
    /// sorted, disjoint, non-adjacent inclusive ranges of received sequence numbers
    ranges: Vec<(u32, u32)>,
    samples: u64,
    /// kept samples in SI, with `theta_ref` from `reference`
    kept: Vec<CaptureSample>,
    /// the reported session's reference, regenerated when its header arrives (only when
    /// samples are kept); the generator's error when it cannot be
    reference: Option<Result<Arc<Reference>, ExcitationError>>,
    batches: Vec<BatchRef>,
    duplicates: u64,
    out_of_order: u64,
    without_header: u64,
    /// batches received before any session header, held raw until one arrives
    pending: Vec<BatchRef>,
    /// their samples, in arrival order
    pending_samples: Vec<RawSample>,
    other_sessions: u64,
    board: BoardCounters,
    ended: bool,
    /// `End.seq`: samples the board took in the reported session
    end_seq: Option<u32>,
    /// stop after this many whole periods after the ramp-in (see [`Self::stop_after_periods`])
    stop_periods: Option<u32>,
    /// stream offset just after the frame that completed `stop_periods`
    cut: Option<u64>,
}

impl Default for StreamAnalyzer {
    fn default() -> Self {
        Self::new(true)
    }
}

impl StreamAnalyzer {
    /// A fresh analyzer; `keep_samples` = false keeps only counts (live capture).
    pub fn new(keep_samples: bool) -> Self {
        Self {
            decoder: Decoder::new(),
            base: 0,
            bytes: 0,
            keep_samples,
            frames: 0,
            damaged: Vec::new(),
            crc_errors: 0,
            header: None,
            sessions: Vec::new(),
            wanted: None,
            reported: None,
            current: None,
            ranges: Vec::new(),
            samples: 0,
            kept: Vec::new(),
            reference: None,
            batches: Vec::new(),
            duplicates: 0,
            out_of_order: 0,
            without_header: 0,
            pending: Vec::new(),
            pending_samples: Vec::new(),
            other_sessions: 0,
            board: BoardCounters::default(),
            ended: false,
            end_seq: None,
            stop_periods: None,
            cut: None,
        }
    }

    /// Reports the session with this id (the first one with it) instead of the first
    /// session of the stream: its samples are kept and checked, the others only counted.
    pub fn select_session(&mut self, session_id: u32) {
        self.wanted = Some(session_id);
    }

    /// Makes the analyzer stop at the frame that brings the reported session to
    /// `n` whole excitation periods after the ramp-in (sequence number
    /// `ramp_samples + n·period_samples − 1` received): [`Self::cut`] is then the stream
    /// offset just after that frame, and every byte fed after it is ignored.
    pub fn stop_after_periods(&mut self, n: u32) {
        self.stop_periods = Some(n);
    }

    /// The stream offset at which the stream was cut by [`Self::stop_after_periods`]:
    /// the end of the frame that completed the requested periods.
    pub fn cut(&self) -> Option<u64> {
        self.cut
    }

    /// Feeds the next received bytes; once the stream was cut (see
    /// [`Self::stop_after_periods`]) the bytes after the cut are ignored and
    /// [`Self::bytes`] is the cut offset.
    pub fn feed(&mut self, bytes: &[u8]) {
        if self.cut.is_some() {
            return;
        }
        self.bytes += bytes.len() as u64;
        // the decoder is moved out for the call so that events are handled as they come
        let mut decoder = std::mem::take(&mut self.decoder);
        decoder.feed(bytes, |e| self.on_event(e));
        self.decoder = decoder;
        if let Some(c) = self.cut {
            self.bytes = c;
            // the bytes after the cut are not part of the capture
            self.decoder = Decoder::new();
            self.base = c;
        }
    }

    /// Reserves room for `n` more kept samples.
    pub fn reserve_samples(&mut self, n: usize) {
        if self.keep_samples {
            self.kept.reserve(n);
        }
    }

    /// Marks a link interruption at the current offset: the frame cut by it is reported
    /// as truncated, and decoding starts afresh with the bytes that follow.
    pub fn boundary(&mut self) {
        self.drain_decoder();
        self.decoder = Decoder::new();
        self.base = self.bytes;
    }

    /// Stream bytes fed so far [bytes].
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The reported session's header, once it arrived.
    pub fn header(&self) -> Option<&SessionHeader> {
        self.header.as_ref()
    }

    /// True once the board's `End` message for the reported session arrived.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Highest sequence number received in the reported session.
    pub fn last_seq(&self) -> Option<u32> {
        self.ranges.last().map(|r| r.1)
    }

    /// Live counters.
    pub fn progress(&self) -> Progress {
        let gaps = self.gaps();
        Progress {
            bytes: self.bytes,
            samples: self.samples,
            last_seq: self.last_seq(),
            gaps: gaps.len() as u64,
            missing: gaps.iter().map(SeqGap::len).sum(),
            crc_errors: self.crc_errors,
            damaged: self.damaged.len() as u64,
            overruns: self.board.overruns,
        }
    }

    /// Missing sequence ranges of the reported session: before the first received sample
    /// (a session starts at seq 0), between received runs, and after the last one when
    /// the board's `End` says more samples were taken.
    pub fn gaps(&self) -> Vec<SeqGap> {
        let mut gaps = Vec::new();
        if self.header.is_some() {
            match self.ranges.first() {
                Some(&(first, _)) if first > 0 => gaps.push(SeqGap {
                    from: 0,
                    to: first - 1,
                }),
                None => {
                    if let Some(n) = self.end_seq.filter(|n| *n > 0) {
                        gaps.push(SeqGap { from: 0, to: n - 1 });
                    }
                }
                _ => {}
            }
        }
        gaps.extend(self.ranges.windows(2).map(|w| SeqGap {
            from: w[0].1 + 1,
            to: w[1].0 - 1,
        }));
        if let (Some(&(_, last)), Some(n)) = (self.ranges.last(), self.end_seq) {
            if n > last.saturating_add(1) {
                gaps.push(SeqGap {
                    from: last + 1,
                    to: n - 1,
                });
            }
        }
        gaps
    }

    fn on_event(&mut self, e: DecodeEvent) {
        if self.cut.is_some() {
            return;
        }
        match e {
            DecodeEvent::Frame {
                offset,
                len,
                message,
            } => {
                self.frames += 1;
                match &message {
                    Message::Header(h) => self.on_header(h, self.base + offset),
                    Message::Batch(b) => {
                        // decoded in one tight pass onto the stack (a checked batch
                        // holds at most BATCH_CAPACITY samples)
                        let mut raw = [RawSample::default(); BATCH_CAPACITY];
                        let mut n = 0;
                        let _ = b.for_each_sample(|s| {
                            if let Some(slot) = raw.get_mut(n) {
                                *slot = s;
                                n += 1;
                            }
                        });
                        self.on_batch(
                            b.first_seq(),
                            b.len() as u32,
                            b.reference_crc(),
                            raw[..n].iter().copied(),
                        );
                        if self.periods_complete() {
                            self.cut = Some(self.base + offset + len as u64);
                        }
                    }
                    Message::Status(s) => self.on_status(s, false),
                    Message::End(s) => self.on_status(s, true),
                }
            }
            DecodeEvent::Damaged { offset, len, error } => {
                self.on_damaged(self.base + offset, len, &error)
            }
        }
    }

    /// True when a period stop was requested and the reported session has reached it.
    fn periods_complete(&self) -> bool {
        match (self.stop_periods, self.header.as_ref(), self.last_seq()) {
            (Some(n), Some(h), Some(last))
                if self.current.is_some() && self.current == self.reported =>
            {
                let target = u64::from(h.excitation.ramp_samples)
                    + u64::from(n) * u64::from(h.excitation.period_samples);
                u64::from(last) + 1 >= target
            }
            _ => false,
        }
    }

    fn on_damaged(&mut self, offset: u64, len: usize, error: &DecodeError) {
        if matches!(error, DecodeError::Crc { .. }) {
            self.crc_errors += 1;
        }
        self.damaged.push(DamagedFrame {
            offset,
            len: len as u64,
            kind: error_kind(error).to_string(),
            error: error.to_string(),
        });
    }

    fn on_header(&mut self, h: &SessionHeader, offset: u64) {
        let idx = match self
            .sessions
            .iter()
            .position(|s| s.board_id == h.board_id && s.session_id == h.session_id)
        {
            Some(i) => i,
            None => {
                self.sessions.push(SessionSummary {
                    board_id: h.board_id,
                    session_id: h.session_id,
                    offset,
                    samples: 0,
                });
                self.sessions.len() - 1
            }
        };
        if self.header.is_none() && self.wanted.is_none_or(|w| w == h.session_id) {
            self.header = Some(*h);
            self.reported = Some(idx);
            if self.keep_samples {
                self.reference = Some(Reference::new(&h.excitation).map(Arc::new));
            }
        }
        let first = self.current.is_none();
        self.current = Some(idx);
        if first {
            self.adopt_pending();
        }
    }

    /// Gives the batches held since the start of the stream to the session that just
    /// announced itself, in arrival order, as if they had followed its header.
    fn adopt_pending(&mut self) {
        let batches = std::mem::take(&mut self.pending);
        let samples = std::mem::take(&mut self.pending_samples);
        let mut at = 0usize;
        for b in batches {
            let n = b.len as usize;
            self.without_header -= u64::from(b.len);
            let raw = samples.get(at..at + n).unwrap_or(&[]);
            at += n;
            self.on_batch(b.first_seq, b.len, b.crc, raw.iter().copied());
        }
    }

    fn on_batch(
        &mut self,
        first_seq: u32,
        len: u32,
        crc: u32,
        samples: impl Iterator<Item = RawSample>,
    ) {
        let n = u64::from(len);
        match self.current {
            None => {
                // held raw until a header says how to scale them
                self.without_header += n;
                self.pending.push(BatchRef {
                    first_seq,
                    len,
                    crc,
                });
                self.pending_samples.extend(samples);
            }
            Some(i) => {
                self.sessions[i].samples += n;
                if self.reported != Some(i) {
                    self.other_sessions += n;
                } else {
                    self.batches.push(BatchRef {
                        first_seq,
                        len,
                        crc,
                    });
                    self.on_samples(samples);
                }
            }
        }
    }

    fn on_status(&mut self, s: &Status, end: bool) {
        if end && self.current.is_none() {
            // a session ended before any header: its samples stay without one
            self.pending.clear();
            self.pending_samples.clear();
        }
        if self.current.is_some() && self.current == self.reported {
            self.board = counters(s);
            if end {
                self.ended = true;
                self.end_seq = Some(s.seq);
            }
        }
    }

    /// Applies a chunk decoded apart (see [`decode_chunk`]) as if its bytes had been fed.
    fn apply(&mut self, chunk: Chunk) {
        self.bytes += chunk.bytes;
        self.base = self.bytes;
        self.frames += chunk.frames;
        for piece in chunk.pieces {
            match piece {
                Piece::Header(h, offset) => self.on_header(&h, offset),
                Piece::Batch {
                    first_seq,
                    len,
                    crc,
                    samples,
                } => self.on_batch(first_seq, len, crc, chunk.samples[samples].iter().copied()),
                Piece::Status(s, end) => self.on_status(&s, end),
                Piece::Damaged { offset, len, error } => self.on_damaged(offset, len, &error),
            }
        }
    }

    /// Decodes a whole stream with up to `threads` decoders working on disjoint pieces
    /// of at least `min_piece` bytes and applies the results in stream order; the outcome
    /// equals [`Self::feed`] of the bytes with a [`Self::boundary`] at each of
    /// `boundaries` (stream offsets). On an analyzer that was already fed, it does exactly
    /// that, sequentially.
    ///
    /// The stream is cut only right after a `0x00` delimiter, where a sequential decoder
    /// holds no partial frame, so each piece decodes exactly as it would in sequence.
    pub fn feed_parallel(
        &mut self,
        stream: &[u8],
        boundaries: &[u64],
        threads: usize,
        min_piece: usize,
    ) {
        if self.bytes > 0 {
            let mut at = 0usize;
            for &b in boundaries {
                let b = (b as usize).clamp(at, stream.len());
                self.feed(&stream[at..b]);
                self.boundary();
                at = b;
            }
            self.feed(&stream[at..]);
            return;
        }
        let mut cuts = vec![0usize];
        let mut segment_ends: Vec<usize> = boundaries
            .iter()
            .map(|&b| (b as usize).min(stream.len()))
            .collect();
        segment_ends.push(stream.len());
        let mut start = 0usize;
        for end in segment_ends {
            if end < start {
                continue;
            }
            let seg = &stream[start..end];
            let pieces = threads.max(1).min(seg.len() / min_piece.max(1)).max(1);
            for k in 1..pieces {
                let nominal = seg.len() * k / pieces;
                if let Some(z) = seg[nominal..].iter().position(|&b| b == 0) {
                    let cut = start + nominal + z + 1;
                    if cut > *cuts.last().unwrap_or(&0) && cut < end {
                        cuts.push(cut);
                    }
                }
            }
            if end > *cuts.last().unwrap_or(&0) {
                cuts.push(end);
            }
            start = end;
        }
        // every cut is a decoder restart; those inside a segment follow a delimiter and
        // so change nothing, those at link boundaries end the cut frame as truncated
        let base = self.bytes;
        let spans: Vec<(usize, usize)> = cuts.windows(2).map(|w| (w[0], w[1])).collect();
        std::thread::scope(|scope| {
            let per = spans.len().div_ceil(threads.max(1));
            let handles: Vec<_> = spans
                .chunks(per.max(1))
                .map(|group| {
                    scope.spawn(move || {
                        group
                            .iter()
                            .map(|&(a, b)| decode_chunk(&stream[a..b], base + a as u64))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            // applied in stream order as each thread is done, while later ones still run
            for h in handles {
                for c in h.join().expect("a decoder thread never panics") {
                    self.apply(c);
                }
            }
        });
        self.decoder = Decoder::new();
        self.base = self.bytes;
    }

    /// A batch's samples: those that continue the highest range in order (the usual
    /// case) in one tight loop with the scale converted once; the others one by one.
    fn on_samples(&mut self, samples: impl Iterator<Item = RawSample>) {
        let scale = self.header.filter(|_| self.keep_samples).map(|h| {
            (
                f64::from(h.sample_rate_hz),
                f64::from(h.scale.torque_nm_per_count),
                f64::from(h.scale.angle_rad_per_count),
            )
        });
        let reference = match &self.reference {
            Some(Ok(r)) => Some(Arc::clone(r)),
            _ => None,
        };
        let reference = reference.as_deref();
        for s in samples {
            let seq = s.seq;
            match self.ranges.last_mut() {
                Some(last) if last.1.checked_add(1) == Some(seq) => {
                    last.1 = seq;
                    self.samples += 1;
                    if let Some((rate, tq, an)) = scale {
                        self.kept.push(CaptureSample {
                            seq,
                            tick: s.tick,
                            t: f64::from(seq) / rate,
                            theta_ref: reference.map_or(0.0, |r| f64::from(r.at(u64::from(seq)))),
                            u: f64::from(s.torque) * tq,
                            theta_m: f64::from(s.angle) * an,
                        });
                    }
                }
                _ => self.on_sample(s, reference),
            }
        }
    }

    fn on_sample(&mut self, s: RawSample, reference: Option<&Reference>) {
        let seq = s.seq;
        // fast path: the next one in order
        match self.ranges.last_mut() {
            Some(last) if last.1.checked_add(1) == Some(seq) => last.1 = seq,
            Some(last) if seq > last.1 => self.ranges.push((seq, seq)),
            None => self.ranges.push((seq, seq)),
            Some(_) => {
                if !self.insert_late(seq) {
                    self.duplicates += 1;
                    return;
                }
                self.out_of_order += 1;
            }
        }
        self.samples += 1;
        if self.keep_samples {
            // kept samples belong to the reported session, whose header is known
            if let Some(h) = &self.header {
                self.kept.push(CaptureSample {
                    seq,
                    tick: s.tick,
                    t: f64::from(seq) / f64::from(h.sample_rate_hz),
                    theta_ref: reference.map_or(0.0, |r| f64::from(r.at(u64::from(seq)))),
                    u: f64::from(s.torque) * f64::from(h.scale.torque_nm_per_count),
                    theta_m: f64::from(s.angle) * f64::from(h.scale.angle_rad_per_count),
                });
            }
        }
    }

    /// Inserts a sequence number below the highest one; false if it was already there.
    fn insert_late(&mut self, seq: u32) -> bool {
        // first range whose end is >= seq
        let i = self.ranges.partition_point(|r| r.1 < seq);
        if i < self.ranges.len() && self.ranges[i].0 <= seq {
            return false;
        }
        let joins_prev = i > 0 && self.ranges[i - 1].1 + 1 == seq;
        let joins_next = i < self.ranges.len() && self.ranges[i].0 == seq + 1;
        match (joins_prev, joins_next) {
            (true, true) => {
                self.ranges[i - 1].1 = self.ranges[i].1;
                self.ranges.remove(i);
            }
            (true, false) => self.ranges[i - 1].1 = seq,
            (false, true) => self.ranges[i].0 = seq,
            (false, false) => self.ranges.insert(i, (seq, seq)),
        }
        true
    }

    fn drain_decoder(&mut self) {
        let mut decoder = std::mem::take(&mut self.decoder);
        decoder.finish(|e| self.on_event(e));
        self.decoder = decoder;
    }

    /// Ends the stream: reports a truncated tail, checks the reference, builds the report
    /// and, when a session header arrived and samples were kept, the record.
    ///
    /// # Errors
    /// [`CaptureError::Excitation`] when the session header's excitation config cannot be
    /// regenerated ([`Self::finish_report`] still gives the report).
    pub fn finish(mut self) -> Result<(CaptureReport, Option<CaptureRecord>), CaptureError> {
        self.drain_decoder();
        let mut report = self.report_without_reference();
        let Some(header) = self.header else {
            return Ok((report, None));
        };
        if !self.kept.is_sorted_by_key(|s| s.seq) {
            self.kept.sort_by_key(|s| s.seq);
        }
        if !self.batches.is_sorted_by_key(|b| b.first_seq) {
            self.batches.sort_by_key(|b| b.first_seq);
        }
        report.reference_mismatches = self.check_reference(&header.excitation)?;
        if !self.keep_samples {
            return Ok((report, None));
        }
        let samples = std::mem::take(&mut self.kept);
        Ok((
            report.clone(),
            Some(CaptureRecord {
                header,
                samples,
                report,
            }),
        ))
    }

    /// Like [`Self::finish`] but only the report; a reference that cannot be regenerated
    /// is left unchecked instead of failing.
    pub fn finish_report(mut self) -> CaptureReport {
        self.keep_samples = false;
        self.drain_decoder();
        let mut report = self.report_without_reference();
        if let Some(h) = self.header {
            self.batches.sort_by_key(|b| b.first_seq);
            if let Ok(mismatches) = self.check_reference(&h.excitation) {
                report.reference_mismatches = mismatches;
            }
        }
        report
    }

    fn report_without_reference(&self) -> CaptureReport {
        let gaps = self.gaps();
        let session = self.reported.and_then(|i| self.sessions.get(i));
        CaptureReport {
            board_id: session.map(|s| s.board_id),
            session_id: session.map(|s| s.session_id),
            bytes: self.bytes,
            frames: self.frames,
            samples: self.samples,
            first_seq: self.ranges.first().map(|r| r.0),
            last_seq: self.last_seq(),
            missing_samples: gaps.iter().map(SeqGap::len).sum(),
            gaps,
            damaged_frames: self.damaged.clone(),
            overruns: self.board.overruns,
            board: self.board,
            duplicates: self.duplicates,
            out_of_order: self.out_of_order,
            reference_mismatches: Vec::new(),
            samples_without_header: self.without_header,
            samples_other_sessions: self.other_sessions,
            sessions: self.sessions.clone(),
            ended: self.ended,
            link_events: Vec::new(),
        }
    }

    /// Regenerates the reference up to the highest received sequence number in one pass,
    /// checks each batch's CRC and returns the reference of every kept sample (in `kept`
    /// order, which is sorted by sequence number). Memory stays proportional to the kept
    /// samples, not to the length of the run.
    fn check_reference(
        &mut self,
        cfg: &ExcitationConfig,
    ) -> Result<Vec<ReferenceMismatch>, CaptureError> {
        let Some(last) = self.last_seq() else {
            return Ok(Vec::new());
        };
        // the reference the kept samples were given, or a fresh one
        let fresh;
        let (reference, kept_filled) = match &self.reference {
            Some(Ok(r)) => (&**r, true),
            Some(Err(e)) => {
                return Err(CaptureError::Excitation {
                    message: e.to_string(),
                })
            }
            None => {
                fresh = Reference::new(cfg).map_err(|e| CaptureError::Excitation {
                    message: e.to_string(),
                })?;
                (&fresh, false)
            }
        };
        let last = u64::from(last);
        let mut mismatches = Vec::new();
        for b in &self.batches {
            // a batch is checked over its samples up to the highest received seq
            let from = u64::from(b.first_seq);
            let to = (from + u64::from(b.len)).min(last + 1);
            let host_crc = reference.crc(from, to);
            if host_crc != b.crc {
                mismatches.push(ReferenceMismatch {
                    first_seq: b.first_seq,
                    len: b.len,
                    board_crc: b.crc,
                    host_crc,
                });
            }
        }
        if self.keep_samples && !kept_filled {
            for s in &mut self.kept {
                s.theta_ref = f64::from(reference.at(u64::from(s.seq)));
            }
        }
        mismatches.sort_by_key(|m| m.first_seq);
        Ok(mismatches)
    }
}

/// The reference θref(k) of a session, regenerated once: the ramp-in, one period (the
/// signal between the ramps is periodic, bit for bit: `Excitation::next` returns the
/// period's table unscaled there), and for a finite run the ramp-out; 0 after the end,
/// where the generator is silent. Memory: one period and two ramps, whatever the length
/// of the run.
#[derive(Debug)]
struct Reference {
    /// one period, k mod N [rad]
    period: Vec<f32>,
    /// the same as little-endian bytes, for CRCs over slices
    period_bytes: Vec<u8>,
    /// the first R samples [rad]
    ramp_in: Vec<f32>,
    /// start of the ramp-out and its R samples [rad] (finite runs)
    ramp_out: Option<(u64, Vec<f32>)>,
}

impl Reference {
    fn new(cfg: &ExcitationConfig) -> Result<Self, ExcitationError> {
        let n = cfg.period_samples as usize;
        let r = cfg.ramp_samples as u64;
        let mut table = vec![0.0f32; n];
        let ramp_in: Vec<f32> = {
            let mut gen = Excitation::new(cfg, &mut table)?;
            (0..r).map(|_| gen.next().unwrap_or(0.0)).collect()
        };
        let ramp_out = match cfg.total_samples() {
            Some(total) => {
                // the ramp-out of sample `start + i` weighs table[(start + i) mod N] by the
                // falling ramp's i-th factor: an endless generator of the same table, ramped
                // out at a point past its ramp-in with the same phase, gives it bit for bit
                let start = total - r;
                let endless = ExcitationConfig { periods: 0, ..*cfg };
                let mut t2 = vec![0.0f32; n];
                let mut g2 = Excitation::new(&endless, &mut t2)?;
                let n64 = n.max(1) as u64;
                let at = r + (start.saturating_sub(r)) % n64;
                for _ in 0..at {
                    g2.next();
                }
                g2.begin_ramp_out();
                let out: Vec<f32> = (0..r).map(|_| g2.next().unwrap_or(0.0)).collect();
                Some((start, out))
            }
            None => None,
        };
        let period_bytes = table.iter().flat_map(|x| x.to_le_bytes()).collect();
        Ok(Self {
            period: table,
            period_bytes,
            ramp_in,
            ramp_out,
        })
    }

    /// θref(k) [rad], as the k-th `Excitation::next` (0 after the end).
    fn at(&self, k: u64) -> f32 {
        if k < self.ramp_in.len() as u64 {
            return self.ramp_in[k as usize];
        }
        if let Some((start, out)) = &self.ramp_out {
            if k >= *start {
                return out.get((k - start) as usize).copied().unwrap_or(0.0);
            }
        }
        if self.period.is_empty() {
            return 0.0;
        }
        self.period[(k % self.period.len() as u64) as usize]
    }

    /// First sample of the ramp-out (or never).
    fn plain_end(&self) -> u64 {
        self.ramp_out.as_ref().map_or(u64::MAX, |(s, _)| *s)
    }

    /// CRC-32 of the little-endian f32 bits of θref(from..to).
    fn crc(&self, from: u64, to: u64) -> u32 {
        let mut c = Crc32::new();
        let n = self.period.len() as u64;
        let mut k = from;
        while k < to {
            if k < self.ramp_in.len() as u64 || k >= self.plain_end() || n == 0 {
                c.update(&self.at(k).to_le_bytes());
                k += 1;
                continue;
            }
            // a run inside the periodic part, up to the period's end or the ramp-out
            let i = k % n;
            let run = (to.min(self.plain_end()) - k).min(n - i);
            c.update(&self.period_bytes[(4 * i) as usize..(4 * (i + run)) as usize]);
            k += run;
        }
        c.finish()
    }
}

/// A decoded frame reduced to what the analyzer needs; a batch's samples live in
/// [`Chunk::samples`].
#[derive(Debug)]
enum Piece {
    Header(SessionHeader, u64),
    Batch {
        first_seq: u32,
        len: u32,
        crc: u32,
        samples: std::ops::Range<usize>,
    },
    Status(Status, bool),
    Damaged {
        offset: u64,
        len: usize,
        error: DecodeError,
    },
}

/// What one decoder found in one piece of the stream.
#[derive(Debug)]
struct Chunk {
    bytes: u64,
    frames: u64,
    pieces: Vec<Piece>,
    samples: Vec<RawSample>,
}

/// Decodes `bytes` (stream offset `base`) with a fresh decoder, finishing at the end.
fn decode_chunk(bytes: &[u8], base: u64) -> Chunk {
    let mut c = Chunk {
        bytes: bytes.len() as u64,
        frames: 0,
        pieces: Vec::new(),
        samples: Vec::with_capacity(bytes.len() / 4),
    };
    let mut d = Decoder::new();
    let mut on = |e: DecodeEvent| match e {
        DecodeEvent::Frame {
            offset, message, ..
        } => {
            c.frames += 1;
            c.pieces.push(match message {
                Message::Header(h) => Piece::Header(h, base + offset),
                Message::Batch(b) => {
                    let from = c.samples.len();
                    // the decoder checked the batch: all its samples arrive
                    let _ = b.for_each_sample(|s| c.samples.push(s));
                    Piece::Batch {
                        first_seq: b.first_seq(),
                        len: b.len() as u32,
                        crc: b.reference_crc(),
                        samples: from..c.samples.len(),
                    }
                }
                Message::Status(s) => Piece::Status(s, false),
                Message::End(s) => Piece::Status(s, true),
            });
        }
        DecodeEvent::Damaged { offset, len, error } => c.pieces.push(Piece::Damaged {
            offset: base + offset,
            len,
            error,
        }),
    };
    d.feed(bytes, &mut on);
    d.finish(&mut on);
    c
}

fn counters(s: &Status) -> BoardCounters {
    BoardCounters {
        overruns: s.overruns,
        queue_drops: s.queue_drops,
        tx_errors: s.tx_errors,
    }
}

/// Short machine-readable name of a decode error.
pub fn error_kind(e: &DecodeError) -> &'static str {
    match e {
        DecodeError::Cobs => "cobs",
        DecodeError::Crc { .. } => "crc",
        DecodeError::Postcard => "postcard",
        DecodeError::TooLong { .. } => "too_long",
        DecodeError::Truncated => "truncated",
        DecodeError::TrailingBytes { .. } => "trailing_bytes",
        DecodeError::Batch(_) => "batch",
        #[allow(unreachable_patterns)]
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::synth::{synth_stream, FrameContent, SynthOptions, SynthStream};

    fn decode(bytes: &[u8], chunk: usize) -> (CaptureReport, CaptureRecord) {
        let mut an = StreamAnalyzer::new(true);
        for c in bytes.chunks(chunk.max(1)) {
            an.feed(c);
        }
        let (report, record) = an.finish().unwrap();
        (report, record.unwrap())
    }

    fn batch_frames(s: &SynthStream) -> Vec<usize> {
        (0..s.frames.len())
            .filter(|&i| matches!(s.frames[i].content, FrameContent::Batch { .. }))
            .collect()
    }

    #[test]
    fn analyzer_recovers_every_sample_bit_exact_whatever_the_chunking() {
        let s = synth_stream(&SynthOptions::small());
        for chunk in [1, 7, 64, 1 << 20] {
            let (report, rec) = decode(&s.bytes, chunk);
            assert!(report.is_clean(), "chunk {chunk}: {report}");
            assert!(report.ended);
            assert_eq!(report.samples, 400);
            assert_eq!(report.frames as usize, s.frames.len());
            assert_eq!(rec.samples.len(), 400);
            let sc = s.header.scale;
            for (got, (raw, r)) in rec.samples.iter().zip(s.samples.iter().zip(&s.reference)) {
                assert_eq!(got.seq, raw.seq);
                assert_eq!(got.tick, raw.tick);
                assert_eq!(got.theta_ref, f64::from(*r));
                assert_eq!(
                    got.u,
                    f64::from(raw.torque) * f64::from(sc.torque_nm_per_count)
                );
                assert_eq!(
                    got.theta_m,
                    f64::from(raw.angle) * f64::from(sc.angle_rad_per_count)
                );
                assert_eq!(got.t, f64::from(raw.seq) / 200.0);
            }
        }
    }

    #[test]
    fn analyzer_reports_a_flipped_bit_at_its_frame_offset_and_the_lost_seqs_as_a_gap() {
        let s = synth_stream(&SynthOptions::small());
        let i = batch_frames(&s)[5];
        let f = s.frames[i];
        let mut bytes = s.bytes.clone();
        let at = (f.offset + f.len / 2) as usize;
        // flip a bit that does not create a delimiter
        let mask = if bytes[at] ^ 0x10 != 0 { 0x10 } else { 0x01 };
        bytes[at] ^= mask;
        let (report, rec) = decode(&bytes, 100);
        assert_eq!(report.damaged_frames.len(), 1);
        assert_eq!(report.damaged_frames[0].offset, f.offset);
        assert_eq!(report.damaged_frames[0].len, f.len);
        let FrameContent::Batch { first, len } = f.content else {
            unreachable!()
        };
        assert_eq!(
            report.gaps,
            vec![SeqGap {
                from: first,
                to: first + len - 1
            }]
        );
        assert_eq!(report.missing_samples, u64::from(len));
        assert_eq!(rec.samples.len(), 400 - len as usize);
        assert!(rec
            .samples
            .iter()
            .all(|x| x.seq < first || x.seq >= first + len));
    }

    #[test]
    fn analyzer_reports_head_and_tail_gaps_from_the_header_and_end_message() {
        let s = synth_stream(&SynthOptions::small());
        let b = batch_frames(&s);
        let (first, last) = (s.frames[b[0]], s.frames[*b.last().unwrap()]);
        // drop the first and the last batch frames entirely (delimiters included)
        let mut bytes = Vec::new();
        for f in &s.frames {
            if *f != first && *f != last {
                bytes.extend_from_slice(&s.bytes[f.offset as usize..(f.offset + f.len) as usize]);
            }
        }
        let (report, _) = decode(&bytes, 333);
        let FrameContent::Batch { len: l0, .. } = first.content else {
            unreachable!()
        };
        let FrameContent::Batch { first: f1, .. } = last.content else {
            unreachable!()
        };
        assert_eq!(
            report.gaps,
            vec![
                SeqGap {
                    from: 0,
                    to: l0 - 1
                },
                SeqGap { from: f1, to: 399 }
            ]
        );
        assert!(report.damaged_frames.is_empty());
    }

    #[test]
    fn analyzer_keeps_duplicates_once_and_sorts_late_batches() {
        let s = synth_stream(&SynthOptions::small());
        let b = batch_frames(&s);
        let span = |i: usize| {
            let f = s.frames[i];
            &s.bytes[f.offset as usize..(f.offset + f.len) as usize]
        };
        let mut bytes = Vec::new();
        for i in 0..s.frames.len() {
            if i == b[3] {
                continue; // moved after b[4]
            }
            bytes.extend_from_slice(span(i));
            if i == b[4] {
                bytes.extend_from_slice(span(b[3]));
                bytes.extend_from_slice(span(b[2])); // a duplicate
            }
        }
        let (report, rec) = decode(&bytes, 50);
        assert!(report.gaps.is_empty(), "{report}");
        assert_eq!(report.duplicates, 16);
        assert_eq!(report.out_of_order, 16);
        assert_eq!(report.samples, 400);
        let seqs: Vec<u32> = rec.samples.iter().map(|x| x.seq).collect();
        assert_eq!(seqs, (0..400).collect::<Vec<_>>());
        assert!(report.reference_mismatches.is_empty());
    }

    #[test]
    fn analyzer_flags_every_batch_when_the_reference_differs_from_the_header() {
        let opts = SynthOptions::small();
        let s = synth_stream(&opts);
        let mut other = opts;
        other.excitation.seed = 43;
        let o = synth_stream(&other);
        // the header of `o` (seed 43) with the batches of `s` (seed 42)
        let h = o.frames[0];
        let mut bytes = o.bytes[..h.len as usize].to_vec();
        bytes.extend_from_slice(&s.bytes[s.frames[0].len as usize..]);
        let (report, _) = decode(&bytes, 4096);
        assert_eq!(report.reference_mismatches.len(), batch_frames(&s).len());
        assert!(report.damaged_frames.is_empty());
    }

    /// Issue 13 item 1: a capture that starts anywhere in a stream whose header repeats
    /// keeps every sample after its first whole frame, scaled and with its reference, as
    /// the capture of the whole stream has it, whatever the reading path.
    #[test]
    fn r13_samples_before_the_first_header_seen_are_scaled_when_it_arrives() {
        use crate::sim::board::{encode_stream, StreamLayout};
        let s = synth_stream(&SynthOptions::small());
        let layout = StreamLayout {
            batch_len: 16,
            status_every: 4,
            overruns: 0,
            end: true,
            header_every: 100,
        };
        let tick_step = s.samples[1].tick.wrapping_sub(s.samples[0].tick);
        let pairs = s.samples.iter().copied().zip(s.reference.iter().copied());
        let stream = encode_stream(&s.header, pairs, tick_step, &layout).unwrap();
        let headers = stream
            .frames
            .iter()
            .filter(|f| f.content == FrameContent::Header)
            .count();
        assert_eq!(headers, 4, "at the start and after seq 111, 207, 303");
        let (_, full) = decode(&stream.bytes, 4096);
        assert_eq!(full.samples.len(), 400);
        let last_header = stream
            .frames
            .iter()
            .rfind(|f| f.content == FrameContent::Header)
            .unwrap();
        for cut in (3..last_header.offset as usize).step_by(41) {
            let late = &stream.bytes[cut..];
            for chunk in [7, 4096] {
                let (report, rec) = decode(late, chunk);
                assert_eq!(report.samples_without_header, 0, "cut {cut}");
                // only the batch the cut fell into is lost: a frame whose body starts
                // at or after the cut is whole
                let first = stream
                    .frames
                    .iter()
                    .find_map(|f| match f.content {
                        FrameContent::Batch { first, .. } if f.offset as usize >= cut => {
                            Some(first as usize)
                        }
                        _ => None,
                    })
                    .unwrap();
                assert_eq!(rec.samples[0].seq as usize, first, "cut {cut}");
                assert_eq!(rec.samples, full.samples[first..], "cut {cut}");
                assert!(report.reference_mismatches.is_empty(), "cut {cut}");
            }
            let mut an = StreamAnalyzer::new(true);
            an.feed_parallel(late, &[], 3, 64);
            let (report, rec) = an.finish().unwrap();
            assert_eq!(report.samples_without_header, 0, "parallel, cut {cut}");
            let rec = rec.unwrap();
            let first = rec.samples[0].seq as usize;
            assert_eq!(rec.samples, full.samples[first..], "parallel, cut {cut}");
        }
    }

    #[test]
    fn analyzer_counts_samples_without_header_and_of_other_sessions_apart() {
        let opts = SynthOptions::small();
        let s = synth_stream(&opts);
        let mut second = opts;
        second.session_id = 8;
        let t = synth_stream(&second);
        // s without its header, then t complete, then s complete
        let mut bytes = s.bytes[s.frames[0].len as usize..].to_vec();
        bytes.extend_from_slice(&t.bytes);
        bytes.extend_from_slice(&s.bytes);
        let (report, rec) = decode(&bytes, 4096);
        assert_eq!(report.samples_without_header, 400);
        assert_eq!(report.session_id, Some(8));
        assert_eq!(report.samples, 400);
        assert_eq!(report.samples_other_sessions, 400);
        assert_eq!(report.sessions.len(), 2);
        assert_eq!(
            report.sessions[1].offset,
            // the header of the second `s`, after its leading delimiter
            (s.bytes.len() - s.frames[0].len as usize + t.bytes.len()) as u64 + s.frames[0].offset
        );
        assert_eq!(rec.header.session_id, 8);
    }

    #[test]
    fn boundary_reports_the_cut_frame_as_truncated_and_decodes_what_follows() {
        let s = synth_stream(&SynthOptions::small());
        let f = s.frames[batch_frames(&s)[2]];
        let cut = (f.offset + 5) as usize;
        let mut an = StreamAnalyzer::new(true);
        an.feed(&s.bytes[..cut]);
        an.boundary();
        // the link comes back in the middle of the next frame
        let g = s.frames[batch_frames(&s)[4]];
        let resume = (g.offset + 3) as usize;
        an.feed(&s.bytes[resume..]);
        let (report, _) = an.finish().unwrap();
        assert_eq!(report.damaged_frames.len(), 2, "{report}");
        assert_eq!(report.damaged_frames[0].offset, f.offset);
        assert_eq!(report.damaged_frames[0].kind, "truncated");
        assert_eq!(report.damaged_frames[0].len, 5);
        assert_eq!(report.damaged_frames[1].offset, cut as u64);
        assert_eq!(report.damaged_frames[1].len, g.len - 3);
        let FrameContent::Batch { first, .. } = f.content else {
            unreachable!()
        };
        let FrameContent::Batch { first: g0, len: gl } = g.content else {
            unreachable!()
        };
        assert_eq!(
            report.gaps,
            vec![SeqGap {
                from: first,
                to: g0 + gl - 1
            }]
        );
    }

    #[test]
    fn insert_late_merges_ranges_on_both_sides() {
        let mut an = StreamAnalyzer::new(false);
        an.ranges = vec![(0, 3), (5, 7), (10, 10)];
        assert!(an.insert_late(4));
        assert_eq!(an.ranges, vec![(0, 7), (10, 10)]);
        assert!(an.insert_late(9));
        assert_eq!(an.ranges, vec![(0, 7), (9, 10)]);
        assert!(!an.insert_late(6));
        assert!(an.insert_late(8));
        assert_eq!(an.ranges, vec![(0, 10)]);
    }

    #[test]
    fn parallel_decoding_equals_sequential_on_damaged_streams_with_link_boundaries() {
        let mut opts = SynthOptions::small();
        opts.samples = 3000;
        opts.excitation.periods = 40;
        let s = synth_stream(&opts);
        // damage: flip bits in every 7th frame, cut 3 bytes out of every 11th, glue
        // garbage in front of every 13th, then a second session and a truncated tail
        let mut bytes = Vec::new();
        for (i, f) in s.frames.iter().enumerate() {
            let mut fr = s.bytes[f.offset as usize..(f.offset + f.len) as usize].to_vec();
            let mid = fr.len() / 2;
            if i % 7 == 3 {
                fr[mid] ^= if fr[mid] ^ 0x08 != 0 { 0x08 } else { 0x02 };
            }
            if i % 11 == 5 && fr.len() > 8 {
                fr.drain(mid..mid + 3);
            }
            if i % 13 == 6 {
                fr.splice(0..0, [0x77, 0x00, 0x66]);
            }
            bytes.extend_from_slice(&fr);
        }
        let mut other = opts;
        other.session_id = 9;
        other.samples = 100;
        bytes.extend_from_slice(&synth_stream(&other).bytes);
        bytes.extend_from_slice(&s.bytes[s.frames[5].offset as usize..][..9]);
        let boundaries = [
            s.frames[40].offset + 3,
            s.frames[40].offset + 3,
            s.frames[90].offset + 1,
            bytes.len() as u64 - 4,
        ];

        let mut seq = StreamAnalyzer::new(true);
        let mut at = 0usize;
        for &b in &boundaries {
            seq.feed(&bytes[at..b as usize]);
            seq.boundary();
            at = b as usize;
        }
        seq.feed(&bytes[at..]);
        let (want_report, want_record) = seq.finish().unwrap();
        assert!(want_report.damaged_frames.len() > 40, "{want_report}");
        assert!(!want_report.gaps.is_empty());
        for (threads, piece) in [(1, 1 << 20), (2, 64), (3, 200), (8, 1)] {
            let mut par = StreamAnalyzer::new(true);
            par.feed_parallel(&bytes, &boundaries, threads, piece);
            let (report, record) = par.finish().unwrap();
            assert_eq!(report, want_report, "threads {threads}, piece {piece}");
            assert_eq!(record, want_record, "threads {threads}, piece {piece}");
        }
    }

    #[test]
    fn reference_equals_the_generator_sample_by_sample_with_ramps() {
        let base = ExcitationConfig {
            period_samples: 200,
            max_line: 40,
            ramp_samples: 150,
            periods: 3,
            ..ExcitationConfig::paper_default()
        };
        // finite (ramp-in, periods, ramp-out, silence) and endless
        for cfg in [base, ExcitationConfig { periods: 0, ..base }] {
            let mut table = vec![0.0f32; cfg.period_samples as usize];
            let mut gen = Excitation::new(&cfg, &mut table).unwrap();
            let want: Vec<f32> = (0..1200).map(|_| gen.next().unwrap_or(0.0)).collect();
            let r = Reference::new(&cfg).unwrap();
            for (k, w) in want.iter().enumerate() {
                assert_eq!(
                    r.at(k as u64).to_bits(),
                    w.to_bits(),
                    "k {k}, periods {}",
                    cfg.periods
                );
            }
            for (from, len) in [
                (0, 64),
                (140, 32),
                (190, 64),
                (349, 5),
                (600, 64),
                (690, 32),
                (1100, 64),
            ] {
                assert_eq!(
                    r.crc(from as u64, (from + len) as u64),
                    jointid_core::wire::reference_crc(&want[from..from + len]),
                    "batch {from}+{len}"
                );
            }
        }
    }
}
