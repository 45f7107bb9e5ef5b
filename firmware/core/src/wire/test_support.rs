//! Messages and samples shared by the unit tests of the `wire` modules.

use super::{
    encode_frame, Message, RawSample, Scale, SessionHeader, MAX_FRAME_LEN, PROTOCOL_VERSION,
};
use crate::excitation::ExcitationConfig;
use crate::rng::SplitMix64;

pub(super) fn header() -> SessionHeader {
    SessionHeader {
        protocol_version: PROTOCOL_VERSION,
        board_id: 0x0474_0001,
        session_id: 7,
        sample_rate_hz: 2000,
        timer_hz: 1_000_000,
        excitation: ExcitationConfig::paper_default(),
        scale: Scale {
            torque_nm_per_count: 1.0 / 2048.0,
            angle_rad_per_count: core::f32::consts::TAU / (1 << 20) as f32,
        },
    }
}

pub(super) fn encode(msg: &Message) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(msg, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// Realistic 2 kHz samples: angle a sum of slow sines in 2^20 counts/rev,
/// torque with noise in 16-bit counts, ticks at 1 MHz with a little jitter.
pub(super) fn synthetic(n: usize, seed: u64) -> (Vec<RawSample>, Vec<f32>) {
    let mut rng = SplitMix64::new(seed);
    let mut samples = Vec::new();
    let mut refs = Vec::new();
    for k in 0..n {
        let t = k as f64 / 2000.0;
        let angle = 0.05 * (6.0 * t).sin() + 0.01 * (2.0 * core::f64::consts::PI * 20.0 * t).sin();
        let torque = 3000.0 * (9.0 * t).sin() + 200.0 * rng.next_gaussian_pair().0;
        let jitter = (rng.next_u64() % 3) as u32;
        samples.push(RawSample {
            seq: k as u32,
            tick: 1000 + 500 * k as u32 + jitter,
            torque: torque as i32,
            angle: (angle / core::f64::consts::TAU * (1 << 20) as f64) as i32,
        });
        refs.push(angle as f32);
    }
    (samples, refs)
}
