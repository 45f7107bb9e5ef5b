//! Shared application wiring, the same on both boards:
//! - the 2 kHz tick ([`tick`], called from the board's timer interrupt): next
//!   reference θ_ref(k) from the core's excitation out to the joint, torque
//!   and angle in, the sample queued;
//! - the idle loop ([`pump`]): session header, delta-coded sample batches with
//!   the reference CRC, periodic status, the end message, through the core's
//!   wire encoder to the board's link.
//!
//! The run is the seed-000 experiment ([`ExcitationConfig::paper_default`]):
//! 1 s ramp-in, 4 periods of 5000 samples, 1 s ramp-out = 24 000 samples, 12 s.

use core::cell::RefCell;
use critical_section::Mutex;
use heapless::spsc::Queue;
use static_cell::ConstStaticCell;

use jointid_core::excitation::{Excitation, ExcitationConfig, SafetyLimits};
use jointid_core::wire::{self, BatchBuilder, Message, RawSample, SessionHeader, Status};

use crate::{board, cost};

/// sample rate of the tick [Hz]
pub const SAMPLE_RATE_HZ: u32 = 2_000;
/// the excitation of a run (24 000 samples; both boards)
pub const EXCITATION: ExcitationConfig = ExcitationConfig::paper_default();
/// samples per batch frame (25 ms at 2 kHz)
const BATCH_LEN: usize = 50;
/// a status message after this many batches
const STATUS_EVERY: u32 = 20;
/// queue between the tick and the idle loop [samples] (64 ms at 2 kHz)
const QUEUE_LEN: usize = 128;
/// the excitation table holds one period
const PERIOD: usize = EXCITATION.period_samples as usize;

/// The sensors and the actuator of a board.
pub trait JointIo {
    /// sends the reference θ_ref(k) [rad] to the joint's controller
    fn set_reference(&mut self, theta_ref: f32);
    /// torque reference u(k) [counts]
    fn torque(&mut self) -> i32;
    /// motor angle θm(k) [counts]
    fn angle(&mut self) -> i32;
}

struct TickState {
    excitation: Excitation<'static>,
    io: board::Io,
    seq: u32,
    overruns: u32,
    finished: bool,
}

static TABLE: ConstStaticCell<[f32; PERIOD]> = ConstStaticCell::new([0.0; PERIOD]);
static TICK: Mutex<RefCell<Option<TickState>>> = Mutex::new(RefCell::new(None));
static QUEUE: Mutex<RefCell<Queue<(RawSample, f32), QUEUE_LEN>>> =
    Mutex::new(RefCell::new(Queue::new()));

/// Generates the excitation period and hands the board's I/O to the tick;
/// call once, before the tick interrupt starts.
pub fn install(io: board::Io) {
    let excitation =
        match Excitation::new_checked(&EXCITATION, TABLE.take(), &SafetyLimits::default_joint()) {
            Ok(e) => e,
            Err(e) => defmt::panic!("excitation refused: {}", e),
        };
    let state = TickState {
        excitation,
        io,
        seq: 0,
        overruns: 0,
        finished: false,
    };
    critical_section::with(|cs| TICK.borrow(cs).replace(Some(state)));
}

/// One tick: reference out, torque and angle in, sample queued (or counted as an overrun).
pub fn tick() {
    let stamp = board::stamp();
    critical_section::with(|cs| {
        let mut guard = TICK.borrow_ref_mut(cs);
        let Some(s) = guard.as_mut() else { return };
        let Some(theta_ref) = s.excitation.next() else {
            s.finished = true;
            return;
        };
        s.io.set_reference(theta_ref);
        let sample = RawSample {
            seq: s.seq,
            tick: stamp,
            torque: s.io.torque(),
            angle: s.io.angle(),
        };
        s.seq = s.seq.wrapping_add(1);
        if QUEUE
            .borrow_ref_mut(cs)
            .enqueue((sample, theta_ref))
            .is_err()
        {
            s.overruns += 1;
        }
    });
}

/// what the idle loop should do next
pub enum Pump {
    /// more work may be waiting
    Busy,
    /// nothing queued: sleep until the next interrupt
    Idle,
    /// the run is over and the end message was sent
    Done,
}

/// Transmit side: owns the batch builder and the frame buffer.
pub struct Transmitter {
    builder: BatchBuilder,
    frame: [u8; wire::MAX_FRAME_LEN],
    header_sent: bool,
    done: bool,
    batches: u32,
    queue_drops: u32,
    tx_errors: u32,
}

impl Transmitter {
    /// a transmitter that starts with the session header
    pub fn new() -> Self {
        Self {
            builder: BatchBuilder::new(board::TIMER_HZ / SAMPLE_RATE_HZ, BATCH_LEN),
            frame: [0; wire::MAX_FRAME_LEN],
            header_sent: false,
            done: false,
            batches: 0,
            queue_drops: 0,
            tx_errors: 0,
        }
    }

    /// One idle-loop step: sends the header, or moves queued samples into
    /// the batch builder and sends a finished batch (plus a status every
    /// [`STATUS_EVERY`] batches), or at the end of the run the last batch and
    /// the end message.
    pub fn pump<W: embedded_io::Write>(&mut self, link: &mut W) -> Pump {
        if self.done {
            return Pump::Done;
        }
        if !self.header_sent {
            self.header_sent = true;
            self.send(link, &Message::Header(header()), 0);
            return Pump::Busy;
        }
        loop {
            let item = critical_section::with(|cs| QUEUE.borrow_ref_mut(cs).dequeue());
            let Some((sample, theta_ref)) = item else {
                break;
            };
            if let Some(batch) = self.builder.push(sample, theta_ref) {
                let n = batch.len() as u32;
                self.send(link, &Message::Batch(batch), n);
                self.batches += 1;
                if self.batches.is_multiple_of(STATUS_EVERY) {
                    self.send(link, &Message::Status(self.status()), 0);
                }
                return Pump::Busy;
            }
        }
        if critical_section::with(|cs| TICK.borrow_ref(cs).as_ref().is_some_and(|s| s.finished)) {
            if let Some(batch) = self.builder.flush() {
                let n = batch.len() as u32;
                self.send(link, &Message::Batch(batch), n);
            }
            self.send(link, &Message::End(self.status()), 0);
            self.done = true;
            return Pump::Done;
        }
        Pump::Idle
    }

    /// Encodes and writes one frame; the encoding time (tick interrupts
    /// subtracted) goes into the cost ledger when the frame carries samples.
    fn send<W: embedded_io::Write>(&mut self, link: &mut W, msg: &Message, samples: u32) {
        let (t0, in_ticks0) = (board::stamp(), cost::with(|l| l.in_ticks));
        let encoded = wire::encode_frame(msg, &mut self.frame);
        let (t1, in_ticks1) = (board::stamp(), cost::with(|l| l.in_ticks));
        let spent = u64::from(t1.wrapping_sub(t0)).saturating_sub(in_ticks1 - in_ticks0);
        match encoded {
            Ok(len) => {
                if samples > 0 {
                    cost::with(|l| {
                        l.encode.add(spent as u32);
                        l.encoded_samples += samples;
                    });
                }
                if link.write_all(&self.frame[..len]).is_err() {
                    self.tx_errors += 1;
                    self.queue_drops += samples;
                }
            }
            Err(e) => {
                defmt::error!("frame not encoded: {}", defmt::Debug2Format(&e));
                self.queue_drops += samples;
            }
        }
    }

    /// the counters as a status message
    fn status(&self) -> Status {
        let (seq, overruns) = critical_section::with(|cs| {
            TICK.borrow_ref(cs)
                .as_ref()
                .map_or((0, 0), |s| (s.seq, s.overruns))
        });
        Status {
            seq,
            overruns,
            queue_drops: self.queue_drops,
            tx_errors: self.tx_errors,
        }
    }
}

/// the session header of this board and run
fn header() -> SessionHeader {
    SessionHeader {
        protocol_version: wire::PROTOCOL_VERSION,
        board_id: board::board_id(),
        session_id: board::session_id(),
        sample_rate_hz: SAMPLE_RATE_HZ,
        timer_hz: board::TIMER_HZ,
        excitation: EXCITATION,
        scale: board::SCALE,
    }
}

#[cfg(feature = "nucleo-g474re")]
/// DAC code for a reference angle: 12 bits, mid-scale at 0 rad, ±π rad full scale
pub fn dac_code(theta: f32) -> u16 {
    let code = 2048.0 + theta * (2048.0 / core::f32::consts::PI);
    code.clamp(0.0, 4095.0) as u16
}
