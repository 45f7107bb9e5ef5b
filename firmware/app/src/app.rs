//! Shared application wiring, the same on both boards:
//! - [`start`] generates the excitation period, splits the sample queue, hands
//!   the core's `Sampler` (producer end) to the tick and returns the core's
//!   `TxPump` (consumer end) wrapped in a [`Streamer`] for the idle loop;
//! - [`tick`], called from the board's 2 kHz timer interrupt: the core's
//!   `Sampler::tick_io` reads u(k) and θm(k), writes θ_ref(k), queues the sample;
//! - [`Streamer::poll`], called from the idle loop: the core's `TxPump` sends
//!   the session header, delta-coded batches with the reference CRC, a status
//!   every few batches and the end message through the board's link.
//!
//! Cost: the tick and every poll are timed with the board's [`board::stamp`];
//! a poll's time excludes the link (the UART write) and the tick interrupts
//! that preempted it, so what is left is dequeuing, batching and encoding.
//!
//! The run is the seed-000 experiment ([`ExcitationConfig::paper_default`]):
//! 1 s ramp-in, 4 periods of 5000 samples, 1 s ramp-out = 24 000 samples, 12 s.

use core::cell::RefCell;
use critical_section::Mutex;
use heapless::spsc::Queue;
use static_cell::ConstStaticCell;

use jointid_core::excitation::{Excitation, ExcitationConfig, SafetyLimits};
use jointid_core::sampler::{Counters, PumpConfig, PumpState, Sampler, TaggedSample, TxPump};
use jointid_core::transport::{FrameSink, TxError};
use jointid_core::wire::{self, SessionHeader};

use crate::{board, cost};

/// sample rate of the tick [Hz]
pub const SAMPLE_RATE_HZ: u32 = 2_000;
/// The excitation of a run, the same on both boards: the seed-000 experiment
/// ([`ExcitationConfig::paper_default`]): 1 s ramp-in, 4 periods of 5000
/// samples, 1 s ramp-out = 24 000 samples (12 s).
pub const EXCITATION: ExcitationConfig = ExcitationConfig::paper_default();
/// samples per batch frame (25 ms at 2 kHz)
const BATCH_LEN: usize = 50;
/// a status message after this many batches (every 0.5 s)
const STATUS_EVERY: u32 = 20;
/// queue between the tick and the idle loop (64 ms at 2 kHz)
const QUEUE_LEN: usize = 128;
/// the excitation table holds one period
const PERIOD: usize = EXCITATION.period_samples as usize;

struct Tick {
    sampler: Sampler<'static, 'static>,
    io: board::Io,
}

static TABLE: ConstStaticCell<[f32; PERIOD]> = ConstStaticCell::new([0.0; PERIOD]);
static QUEUE: ConstStaticCell<Queue<TaggedSample, QUEUE_LEN>> = ConstStaticCell::new(Queue::new());
static COUNTERS: Counters = Counters::new();
static TICK: Mutex<RefCell<Option<Tick>>> = Mutex::new(RefCell::new(None));

/// Generates the excitation (checked against the default joint limits), hands
/// the sampler and the board's I/O to the tick and returns the idle loop's
/// side. Call once, before the tick interrupt starts.
pub fn start<S: FrameSink>(io: board::Io, link: S) -> Streamer<S> {
    let excitation =
        match Excitation::new_checked(&EXCITATION, TABLE.take(), &SafetyLimits::default_joint()) {
            Ok(e) => e,
            Err(e) => defmt::panic!("excitation refused: {}", e),
        };
    let (producer, consumer) = QUEUE.take().split();
    let sampler = Sampler::new(excitation, producer, &COUNTERS);
    critical_section::with(|cs| TICK.borrow(cs).replace(Some(Tick { sampler, io })));
    let config = PumpConfig {
        batch_len: BATCH_LEN,
        status_every: STATUS_EVERY,
        max_samples_per_poll: QUEUE_LEN,
        // the session header again every second, for a host that starts late
        header_every: wire::header_interval_samples(SAMPLE_RATE_HZ),
    };
    Streamer {
        pump: TxPump::new(consumer, &COUNTERS, header(), config),
        link: TimedLink { link, spent: 0 },
    }
}

/// One 2 kHz tick at timer count `stamp` (the board's interrupt calls it).
pub fn tick(stamp: u32) {
    critical_section::with(|cs| {
        if let Some(t) = TICK.borrow_ref_mut(cs).as_mut() {
            t.sampler.tick_io(stamp, &mut t.io);
        }
    });
}

/// The idle loop's side: the core's transmit pump and the board's link.
pub struct Streamer<S> {
    pump: TxPump<'static>,
    link: TimedLink<S>,
}

impl<S: FrameSink> Streamer<S> {
    /// One idle-loop step (see `TxPump::poll`), timed into the cost ledger.
    pub fn poll(&mut self) -> PumpState {
        let (t0, ticks0, link0) = (board::stamp(), cost::with(|l| l.in_ticks), self.link.spent);
        let state = self.pump.poll(&mut self.link);
        let (t1, ticks1) = (board::stamp(), cost::with(|l| l.in_ticks));
        let other = (ticks1 - ticks0) + (self.link.spent - link0);
        let spent = u64::from(t1.wrapping_sub(t0)).saturating_sub(other);
        cost::with(|l| l.pump.add(spent as u32));
        state
    }

    /// the counters as the end message reported them
    pub fn status(&self) -> wire::Status {
        self.pump.status(&self.link)
    }
}

/// A link that keeps the time spent inside it, tick interrupts excluded [board stamp units].
struct TimedLink<S> {
    link: S,
    spent: u64,
}

impl<S: FrameSink> FrameSink for TimedLink<S> {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        let (t0, ticks0) = (board::stamp(), cost::with(|l| l.in_ticks));
        let r = self.link.send_frame(frame);
        let (t1, ticks1) = (board::stamp(), cost::with(|l| l.in_ticks));
        self.spent += u64::from(t1.wrapping_sub(t0)).saturating_sub(ticks1 - ticks0);
        r
    }

    fn tx_errors(&self) -> u32 {
        self.link.tx_errors()
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
        scale: board::scale(),
    }
}

#[cfg(feature = "nucleo-g474re")]
/// DAC code for a reference angle: 12 bits, mid-scale at 0 rad, ±π rad full scale
pub fn dac_code(theta: f32) -> u16 {
    let code = 2048.0 + theta * (2048.0 / core::f32::consts::PI);
    code.clamp(0.0, 4095.0) as u16
}
