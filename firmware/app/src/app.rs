//! Shared application wiring (both boards). STAND-IN until firmware/core lands:
//! a counter instead of the excitation, raw little-endian words instead of frames.

use core::cell::RefCell;
use critical_section::Mutex;
use heapless::spsc::Queue;

use crate::{board, cost};

/// sample rate of the tick [Hz]
pub const SAMPLE_RATE_HZ: u32 = 2_000;
/// samples in the emulated run
pub const RUN_SAMPLES: u32 = 22_000;

/// placeholder sensor interface
pub trait Io {
    /// torque [counts]
    fn torque(&mut self) -> i32;
    /// angle [counts]
    fn angle(&mut self) -> i32;
    /// reference [rad]
    fn reference(&mut self, theta: f32);
}

struct TickState {
    io: board::Io,
    seq: u32,
}

static STATE: Mutex<RefCell<Option<TickState>>> = Mutex::new(RefCell::new(None));
static QUEUE: Mutex<RefCell<Queue<(u32, i32, i32), 256>>> = Mutex::new(RefCell::new(Queue::new()));

/// hands the sensors to the tick; call before the tick interrupt starts
pub fn install(io: board::Io) {
    critical_section::with(|cs| STATE.borrow(cs).replace(Some(TickState { io, seq: 0 })));
}

/// one 2 kHz tick: reference out, sensors in, sample queued
pub fn tick() {
    critical_section::with(|cs| {
        if let Some(s) = STATE.borrow_ref_mut(cs).as_mut() {
            if s.seq >= RUN_SAMPLES {
                return;
            }
            s.io.reference(0.0);
            let t = s.io.torque();
            let a = s.io.angle();
            let _ = QUEUE.borrow_ref_mut(cs).enqueue((s.seq, t, a));
            s.seq += 1;
        }
    });
}

/// what the idle loop should do next
pub enum Pump {
    /// more work may be waiting
    Busy,
    /// nothing queued: sleep until the next interrupt
    Idle,
    /// the run is over and everything was sent
    Done,
}

/// idle-loop step: one queued sample to the transport
pub fn pump<W: embedded_io::Write>(tx: &mut W) -> Pump {
    let item = critical_section::with(|cs| QUEUE.borrow_ref_mut(cs).dequeue());
    match item {
        Some((seq, t, a)) => {
            let t0 = board::cost_stamp();
            let mut buf = [0u8; 12];
            buf[..4].copy_from_slice(&seq.to_le_bytes());
            buf[4..8].copy_from_slice(&t.to_le_bytes());
            buf[8..].copy_from_slice(&a.to_le_bytes());
            let spent = board::cost_stamp().wrapping_sub(t0);
            cost::with(|l| {
                l.encode.add(spent);
                l.encoded_samples += 1;
            });
            let _ = tx.write_all(&buf);
            if seq + 1 == RUN_SAMPLES {
                Pump::Done
            } else {
                Pump::Busy
            }
        }
        None => Pump::Idle,
    }
}

#[cfg(feature = "nucleo-g474re")]
/// DAC code for a reference angle: 12 bits, mid-scale at 0 rad, ±π rad full scale
pub fn dac_code(theta: f32) -> u16 {
    let code = 2048.0 + theta * (2048.0 / core::f32::consts::PI);
    code.clamp(0.0, 4095.0) as u16
}
