//! The 2 kHz tick and the transmit pump.
//!
//! The [`Sampler`] runs in the timer interrupt: at tick k it reads the torque
//! reference u(k) and the motor angle θm(k) through [`TorqueInput`] and
//! [`AngleInput`], writes the next excitation sample θ_ref(k) through
//! [`ReferenceOutput`], stamps sequence number k and the timer count, and
//! pushes the sample with its reference into a `heapless::spsc` queue. The
//! work per tick is bounded (one table look-up, a short f32 polynomial during
//! the ramps, one queue push); nothing allocates or panics. A full queue loses
//! the sample and counts an overrun in [`Counters`]; sequence numbers keep
//! counting, so the host sees the gap as well.
//!
//! The [`TxPump`] runs in the idle loop: it sends the [`SessionHeader`], pops
//! samples, packs them into sample batches (`SampleBatch`),
//! frames them and hands the frames to a [`FrameSink`], with a [`Status`]
//! every few batches, the header again after every
//! [`PumpConfig::header_every`] samples (so a host that starts listening late
//! can still scale the run) and [`Message::End`](crate::wire::Message::End)
//! once the excitation has finished.
//! Samples of a frame the sink could not send are counted as queue drops.

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use heapless::spsc::{Consumer, Producer};

use crate::excitation::Excitation;
use crate::transport::FrameSink;
use crate::wire::{
    encode_frame_ref, header_interval_samples, BatchBuilder, MessageRef, RawSample, SessionHeader,
    Status, MAX_FRAME_LEN,
};

/// Reads the motor torque reference u.
pub trait TorqueInput {
    /// Torque reference u(k) [counts].
    fn read_torque(&mut self) -> i32;
}

/// Reads the motor angle θm.
pub trait AngleInput {
    /// Motor angle θm(k) [counts].
    fn read_angle(&mut self) -> i32;
}

/// Drives the joint controller's reference.
pub trait ReferenceOutput {
    /// Sets the motor-angle reference θ_ref(k) [rad].
    fn write_reference(&mut self, theta_ref_rad: f32);
}

/// A sample with the reference written at the same tick, as queued.
#[derive(Clone, Copy, PartialEq, Debug, Default)]
pub struct TaggedSample {
    /// raw sample
    pub sample: RawSample,
    /// θ_ref(k) [rad]
    pub reference: f32,
}

/// Counters shared between the tick (writer) and the pump (reader).
#[derive(Debug, Default)]
pub struct Counters {
    taken: AtomicU32,
    overruns: AtomicU32,
    finished: AtomicBool,
}

impl Counters {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            taken: AtomicU32::new(0),
            overruns: AtomicU32::new(0),
            finished: AtomicBool::new(false),
        }
    }

    /// Samples taken so far (the next seq).
    pub fn taken(&self) -> u32 {
        self.taken.load(Ordering::Acquire)
    }

    /// Samples lost to a full queue.
    pub fn overruns(&self) -> u32 {
        self.overruns.load(Ordering::Acquire)
    }

    /// Whether the excitation has produced its last sample.
    pub fn is_finished(&self) -> bool {
        self.finished.load(Ordering::Acquire)
    }
}

/// What one tick did.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TickOutcome {
    /// the sample was queued
    Queued,
    /// the queue was full: the sample was lost and counted
    Overrun,
    /// the excitation has ended; nothing was sampled, the reference holds its last value
    Finished,
}

/// The tick handler: owns the excitation and the queue's producer end.
pub struct Sampler<'e, 'q> {
    excitation: Excitation<'e>,
    producer: Producer<'q, TaggedSample>,
    counters: &'q Counters,
    seq: u32,
    last_reference: f32,
}

impl<'e, 'q> Sampler<'e, 'q> {
    /// Sampler starting at seq 0 with the excitation at its first sample.
    pub fn new(
        excitation: Excitation<'e>,
        producer: Producer<'q, TaggedSample>,
        counters: &'q Counters,
    ) -> Self {
        Self {
            excitation,
            producer,
            counters,
            seq: 0,
            last_reference: 0.0,
        }
    }

    /// One sampling instant at timer count `tick`: read u(k) and θm(k), write
    /// θ_ref(k), queue the sample.
    pub fn tick<T, A, R>(
        &mut self,
        tick: u32,
        torque: &mut T,
        angle: &mut A,
        reference: &mut R,
    ) -> TickOutcome
    where
        T: TorqueInput + ?Sized,
        A: AngleInput + ?Sized,
        R: ReferenceOutput + ?Sized,
    {
        let Some(theta_ref) = self.excitation.next() else {
            reference.write_reference(self.last_reference);
            self.counters.finished.store(true, Ordering::Release);
            return TickOutcome::Finished;
        };
        let u = torque.read_torque();
        let theta_m = angle.read_angle();
        reference.write_reference(theta_ref);
        self.push(tick, u, theta_m, theta_ref)
    }

    /// [`tick`](Self::tick) for one device that reads both sensors and takes
    /// the reference (for example [`crate::joint::JointIo`]).
    pub fn tick_io<IO>(&mut self, tick: u32, io: &mut IO) -> TickOutcome
    where
        IO: TorqueInput + AngleInput + ReferenceOutput + ?Sized,
    {
        let Some(theta_ref) = self.excitation.next() else {
            io.write_reference(self.last_reference);
            self.counters.finished.store(true, Ordering::Release);
            return TickOutcome::Finished;
        };
        let u = io.read_torque();
        let theta_m = io.read_angle();
        io.write_reference(theta_ref);
        self.push(tick, u, theta_m, theta_ref)
    }

    fn push(&mut self, tick: u32, u: i32, theta_m: i32, theta_ref: f32) -> TickOutcome {
        self.last_reference = theta_ref;
        let tagged = TaggedSample {
            sample: RawSample {
                seq: self.seq,
                tick,
                torque: u,
                angle: theta_m,
            },
            reference: theta_ref,
        };
        self.seq = self.seq.wrapping_add(1);
        let outcome = match self.producer.enqueue(tagged) {
            Ok(()) => TickOutcome::Queued,
            Err(_) => {
                self.counters.overruns.fetch_add(1, Ordering::AcqRel);
                TickOutcome::Overrun
            }
        };
        self.counters.taken.store(self.seq, Ordering::Release);
        if self.excitation.is_finished() {
            self.counters.finished.store(true, Ordering::Release);
        }
        outcome
    }

    /// Starts the excitation's ramp-out (ends an endless run smoothly).
    pub fn request_stop(&mut self) {
        self.excitation.begin_ramp_out();
    }

    /// Samples taken so far (the next seq).
    pub fn seq(&self) -> u32 {
        self.seq
    }
}

/// State of the [`TxPump`] after a poll.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PumpState {
    /// samples were moved or frames sent
    Busy,
    /// nothing to do
    Idle,
    /// `End` was sent; the session is over
    Done,
}

/// Settings of the [`TxPump`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct PumpConfig {
    /// samples per batch (2..=[`crate::wire::BATCH_CAPACITY`])
    pub batch_len: usize,
    /// a [`Status`] after every this many batches (0 = only at the end)
    pub status_every: u32,
    /// most samples moved per [`TxPump::poll`] (bounds the time of one poll)
    pub max_samples_per_poll: usize,
    /// the session header again after the batch that completes every this many
    /// samples since the last header (0 = only at the start); the board uses
    /// [`header_interval_samples`]`(sample_rate_hz)`, one second
    pub header_every: u32,
}

impl Default for PumpConfig {
    /// Batches of 64, a status every 16 batches, the header every 2000 samples
    /// (one second at 2 kHz).
    fn default() -> Self {
        Self {
            batch_len: 64,
            status_every: 16,
            max_samples_per_poll: 128,
            header_every: header_interval_samples(2000),
        }
    }
}

/// Transmit side: queue → batches → frames → sink.
pub struct TxPump<'q> {
    consumer: Consumer<'q, TaggedSample>,
    counters: &'q Counters,
    header: SessionHeader,
    builder: BatchBuilder,
    config: PumpConfig,
    header_sent: bool,
    done: bool,
    batches_since_status: u32,
    /// samples batched since the last header
    samples_since_header: u32,
    queue_drops: u32,
    frames_sent: u32,
    frame: [u8; MAX_FRAME_LEN],
}

impl<'q> TxPump<'q> {
    /// Pump for one session; the nominal tick step is `timer_hz / sample_rate_hz`.
    pub fn new(
        consumer: Consumer<'q, TaggedSample>,
        counters: &'q Counters,
        header: SessionHeader,
        config: PumpConfig,
    ) -> Self {
        let tick_step = header
            .timer_hz
            .checked_div(header.sample_rate_hz)
            .unwrap_or(0);
        Self {
            consumer,
            counters,
            header,
            builder: BatchBuilder::new(tick_step, config.batch_len),
            config,
            header_sent: false,
            done: false,
            batches_since_status: 0,
            samples_since_header: 0,
            queue_drops: 0,
            frames_sent: 0,
            frame: [0; MAX_FRAME_LEN],
        }
    }

    /// Counters as they would be reported now.
    pub fn status<S: FrameSink + ?Sized>(&self, sink: &S) -> Status {
        Status {
            seq: self.counters.taken(),
            overruns: self.counters.overruns(),
            queue_drops: self.queue_drops,
            tx_errors: sink.tx_errors(),
        }
    }

    /// Frames handed to the sink successfully.
    pub fn frames_sent(&self) -> u32 {
        self.frames_sent
    }

    /// Moves up to `max_samples_per_poll` samples and sends the frames that
    /// complete; sends `End` once the excitation has finished and the queue is
    /// empty.
    pub fn poll<S: FrameSink + ?Sized>(&mut self, sink: &mut S) -> PumpState {
        if self.done {
            return PumpState::Done;
        }
        let mut busy = false;
        if !self.header_sent {
            self.header_sent = true;
            let header = self.header;
            self.send(MessageRef::Header(&header), sink);
            busy = true;
        }
        // read before draining: the tick sets it after its last push
        let finished = self.counters.is_finished();
        let mut moved = 0;
        while moved < self.config.max_samples_per_poll {
            let Some(t) = self.consumer.dequeue() else {
                break;
            };
            moved += 1;
            // in place: the finished batch is framed where it lies
            if self.builder.push_sample(t.sample, t.reference) {
                self.send_batch(sink);
            }
        }
        busy |= moved > 0;
        if finished && self.consumer.is_empty() {
            if self.builder.finish() {
                self.send_batch(sink);
            }
            let end = self.status(sink);
            self.send(MessageRef::End(&end), sink);
            self.done = true;
            info!("session done: {} frames", self.frames_sent);
            return PumpState::Done;
        }
        if busy {
            PumpState::Busy
        } else {
            PumpState::Idle
        }
    }

    /// Sends the builder's finished batch, then a status and the repeated
    /// header if they are due.
    fn send_batch<S: FrameSink + ?Sized>(&mut self, sink: &mut S) {
        let batch = self.builder.batch();
        let len = batch.len() as u32;
        let sent = send_frame(
            MessageRef::Batch(batch),
            &mut self.frame,
            &mut self.frames_sent,
            sink,
        );
        if !sent {
            self.queue_drops = self.queue_drops.saturating_add(len);
        }
        self.batches_since_status += 1;
        if self.config.status_every > 0 && self.batches_since_status >= self.config.status_every {
            self.batches_since_status = 0;
            let status = self.status(sink);
            self.send(MessageRef::Status(&status), sink);
        }
        self.samples_since_header = self.samples_since_header.saturating_add(len);
        if self.config.header_every > 0 && self.samples_since_header >= self.config.header_every {
            self.samples_since_header = 0;
            let header = self.header;
            self.send(MessageRef::Header(&header), sink);
        }
    }

    /// Encodes and sends one message; `false` if it was lost.
    fn send<S: FrameSink + ?Sized>(&mut self, msg: MessageRef<'_>, sink: &mut S) -> bool {
        send_frame(msg, &mut self.frame, &mut self.frames_sent, sink)
    }
}

/// Encodes `msg` into `frame` and hands it to `sink`; counts it in
/// `frames_sent` if it went out, `false` if it was lost.
fn send_frame<S: FrameSink + ?Sized>(
    msg: MessageRef<'_>,
    frame: &mut [u8; MAX_FRAME_LEN],
    frames_sent: &mut u32,
    sink: &mut S,
) -> bool {
    match encode_frame_ref(msg, frame) {
        Ok(n) => match sink.send_frame(&frame[..n]) {
            Ok(()) => {
                *frames_sent = frames_sent.wrapping_add(1);
                true
            }
            Err(e) => {
                warn!("frame lost: {}", e as u8);
                false
            }
        },
        // cannot happen: MAX_FRAME_LEN holds every message; counted as lost
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::{generate, ExcitationConfig, SignalKind};
    use crate::transport::TxError;
    use crate::wire::{reference_crc, DecodeEvent, Decoder, Message, Scale, PROTOCOL_VERSION};
    use heapless::spsc::Queue;

    /// Fake joint: torque and angle are known functions of the last reference
    /// and the sample index, so every decoded value can be checked.
    #[derive(Default)]
    struct FakeJoint {
        k: i32,
        last_ref: f32,
        refs: Vec<f32>,
    }

    impl TorqueInput for FakeJoint {
        fn read_torque(&mut self) -> i32 {
            self.k += 1;
            -3 * self.k + (self.last_ref * 1e4) as i32
        }
    }
    impl AngleInput for FakeJoint {
        fn read_angle(&mut self) -> i32 {
            (self.last_ref * 1e6) as i32 + 7
        }
    }
    impl ReferenceOutput for FakeJoint {
        fn write_reference(&mut self, theta_ref_rad: f32) {
            self.last_ref = theta_ref_rad;
            self.refs.push(theta_ref_rad);
        }
    }

    /// Sink into a Vec that fails every `fail_every`-th frame (0 = never).
    struct VecSink {
        bytes: Vec<u8>,
        frames: u32,
        fail_every: u32,
        errors: u32,
    }

    impl FrameSink for VecSink {
        fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
            self.frames += 1;
            if self.fail_every > 0 && self.frames.is_multiple_of(self.fail_every) {
                self.errors += 1;
                return Err(TxError::Link);
            }
            self.bytes.extend_from_slice(frame);
            Ok(())
        }
        fn tx_errors(&self) -> u32 {
            self.errors
        }
    }

    fn small_config() -> ExcitationConfig {
        ExcitationConfig {
            kind: SignalKind::SpecialOddMultisine,
            period_samples: 1000,
            max_line: 60,
            ramp_samples: 200,
            periods: 3,
            ..ExcitationConfig::paper_default()
        }
    }

    fn header(cfg: ExcitationConfig) -> SessionHeader {
        SessionHeader {
            protocol_version: PROTOCOL_VERSION,
            board_id: 1,
            session_id: 2,
            sample_rate_hz: cfg.fs_hz,
            timer_hz: 1_000_000,
            excitation: cfg,
            scale: Scale {
                torque_nm_per_count: 1e-3,
                angle_rad_per_count: 1e-6,
            },
        }
    }

    /// Runs a session; the pump is polled every `poll_every` ticks.
    fn run(poll_every: u32, fail_every: u32) -> (Vec<DecodeEvent>, Vec<f32>, VecSink) {
        run_with(poll_every, fail_every, PumpConfig::default())
    }

    /// [`run`] with the pump's settings.
    fn run_with(
        poll_every: u32,
        fail_every: u32,
        config: PumpConfig,
    ) -> (Vec<DecodeEvent>, Vec<f32>, VecSink) {
        let cfg = small_config();
        let mut table = [0.0f32; 1000];
        let exc = Excitation::new(&cfg, &mut table).unwrap();
        let mut queue: Queue<TaggedSample, 128> = Queue::new();
        let (producer, consumer) = queue.split();
        let counters = Counters::new();
        let mut sampler = Sampler::new(exc, producer, &counters);
        let mut pump = TxPump::new(consumer, &counters, header(cfg), config);
        let mut joint = FakeJoint::default();
        let mut sink = VecSink {
            bytes: Vec::new(),
            frames: 0,
            fail_every,
            errors: 0,
        };
        let mut state = PumpState::Idle;
        for k in 0..10_000u32 {
            // a little jitter on the 500-tick step
            let outcome = sampler.tick_io(500 * k + k % 3, &mut joint);
            assert_eq!(outcome == TickOutcome::Finished, k >= 3400);
            if k % poll_every == 0 {
                state = pump.poll(&mut sink);
            }
        }
        while state != PumpState::Done {
            state = pump.poll(&mut sink);
        }
        let mut events = Vec::new();
        let mut dec = Decoder::new();
        dec.feed(&sink.bytes, |e| events.push(e));
        dec.finish(|e| events.push(e));
        (events, joint.refs, sink)
    }

    /// Checks the decoded session against the fake joint; returns (samples
    /// decoded, the End status).
    fn check_session(events: &[DecodeEvent], refs: &[f32]) -> (usize, Status) {
        let cfg = small_config();
        let expected_refs = generate(&cfg).unwrap();
        // the reference written at each tick is the excitation, then held at 0
        assert_eq!(&refs[..3400], &expected_refs[..]);
        assert!(refs[3400..].iter().all(|&r| r == 0.0));
        let mut decoded = 0;
        let mut end = None;
        let mut statuses = 0;
        for (i, e) in events.iter().enumerate() {
            let DecodeEvent::Frame { message, .. } = e else {
                panic!("damaged frame {e:?}");
            };
            match message {
                Message::Header(h) => {
                    // the first frame, then repeated unchanged
                    assert!(i == 0 || matches!(events[0], DecodeEvent::Frame { .. }));
                    assert_eq!(*h, header(cfg));
                }
                Message::Batch(b) => {
                    let k0 = b.first_seq() as usize;
                    assert_eq!(
                        b.reference_crc(),
                        reference_crc(&expected_refs[k0..k0 + b.len()])
                    );
                    for s in b.samples() {
                        let k = s.seq as usize;
                        // reads at tick k see the reference of tick k-1
                        let prev = if k == 0 { 0.0 } else { expected_refs[k - 1] };
                        assert_eq!(s.angle, (prev * 1e6) as i32 + 7);
                        assert_eq!(s.torque, -3 * (k as i32 + 1) + (prev * 1e4) as i32);
                        assert_eq!(s.tick, 500 * k as u32 + k as u32 % 3);
                        decoded += 1;
                    }
                }
                Message::Status(_) => statuses += 1,
                Message::End(s) => {
                    assert_eq!(i, events.len() - 1);
                    end = Some(*s);
                }
            }
        }
        assert!(statuses > 0);
        (decoded, end.expect("no End frame"))
    }

    #[test]
    fn session_streams_every_sample_when_polled_often() {
        let (events, refs, _) = run(8, 0);
        let (decoded, end) = check_session(&events, &refs);
        assert_eq!(decoded, 3400);
        assert_eq!(
            end,
            Status {
                seq: 3400,
                overruns: 0,
                queue_drops: 0,
                tx_errors: 0
            }
        );
    }

    #[test]
    fn header_is_repeated_after_the_batch_completing_each_interval() {
        let config = PumpConfig {
            header_every: 500,
            ..PumpConfig::default()
        };
        let (events, refs, _) = run_with(8, 0, config);
        let (decoded, _) = check_session(&events, &refs);
        assert_eq!(decoded, 3400);
        // batches of 64: 8 batches (512 samples) reach 500, so a header follows
        // the batches ending at seq 511, 1023, ... 3071 (after a status if one is due)
        let mut next_seq = 0u32;
        let mut repeats = Vec::new();
        for (i, e) in events.iter().enumerate() {
            match e {
                DecodeEvent::Frame {
                    message: Message::Header(_),
                    ..
                } if i > 0 => repeats.push(next_seq),
                DecodeEvent::Frame {
                    message: Message::Batch(b),
                    ..
                } => next_seq = b.first_seq() + b.len() as u32,
                _ => {}
            }
        }
        assert_eq!(repeats, (1..=6).map(|j| 512 * j).collect::<Vec<u32>>());
        // header_every = 0: the header only at the start
        let once = PumpConfig {
            header_every: 0,
            ..PumpConfig::default()
        };
        let (events, _, _) = run_with(8, 0, once);
        let headers = events
            .iter()
            .filter(|e| {
                matches!(
                    e,
                    DecodeEvent::Frame {
                        message: Message::Header(_),
                        ..
                    }
                )
            })
            .count();
        assert_eq!(headers, 1);
    }

    #[test]
    fn overruns_are_counted_and_reported_when_polled_rarely() {
        // queue holds 127; polling every 300 ticks loses samples
        let (events, refs, _) = run(300, 0);
        let (decoded, end) = check_session(&events, &refs);
        assert!(end.overruns > 1000, "{end:?}");
        assert_eq!(decoded as u32 + end.overruns, 3400);
        assert_eq!(end.seq, 3400);
    }

    #[test]
    fn failed_frames_count_as_tx_errors_and_queue_drops() {
        let (events, refs, sink) = run(8, 7);
        let (decoded, end) = check_session(&events, &refs);
        assert!(sink.errors > 0);
        // the End frame itself was sent; its count includes all earlier failures
        assert_eq!(end.tx_errors, sink.errors);
        assert_eq!(decoded as u32 + end.queue_drops, 3400);
        assert!(end.queue_drops > 0);
    }

    #[test]
    fn joint_session_is_lossless_under_six_bytes_per_sample() {
        use crate::joint::{JointIo, JointParams, JointSim};
        let cfg = ExcitationConfig::paper_default();
        let mut table = vec![0.0f32; 5000];
        let exc = Excitation::new(&cfg, &mut table).unwrap();
        let mut queue: Queue<TaggedSample, 64> = Queue::new();
        let (producer, consumer) = queue.split();
        let counters = Counters::new();
        let mut sampler = Sampler::new(exc, producer, &counters);
        let mut io = JointIo::new(JointSim::new(JointParams::default_joint()));
        let hdr = SessionHeader {
            scale: io.sim.scale(),
            ..header(cfg)
        };
        let mut pump = TxPump::new(consumer, &counters, hdr, PumpConfig::default());
        let mut sink = VecSink {
            bytes: Vec::new(),
            frames: 0,
            fail_every: 0,
            errors: 0,
        };
        let mut k = 0u32;
        while pump.poll(&mut sink) != PumpState::Done {
            for _ in 0..32 {
                sampler.tick_io(500 * k, &mut io);
                k += 1;
            }
        }
        let total = cfg.total_samples().unwrap() as usize;
        let refs = generate(&cfg).unwrap();
        let mut dec = Decoder::new();
        let mut seq = 0usize;
        dec.feed(&sink.bytes, |e| match e {
            DecodeEvent::Frame {
                message: Message::Batch(b),
                ..
            } => {
                assert_eq!(b.first_seq() as usize, seq);
                assert_eq!(b.reference_crc(), reference_crc(&refs[seq..seq + b.len()]));
                seq += b.len();
            }
            DecodeEvent::Frame { .. } => {}
            DecodeEvent::Damaged { .. } => panic!("damaged frame"),
        });
        assert_eq!(seq, total);
        let per_sample = sink.bytes.len() as f64 / total as f64;
        assert!(per_sample < 6.0, "{per_sample} bytes per sample");
    }
}
