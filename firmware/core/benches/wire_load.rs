//! Link budget of the wire format: 62 s of 2 kHz samples from the simulated
//! joint (`jointid_core::joint`) under the default special odd multisine
//! (24 periods of 2.5 s plus 1 s ramps), streamed through the real sampler,
//! queue and transmit pump, then decoded again to prove the stream lossless.
//!
//! Prints bytes per sample (framing and CRC included), UART load at 230400
//! and 921600 baud (8N1, 10 bits per byte), classic CAN load at 1 Mbit/s
//! (worst-case stuffing, 7 stream bytes per 8-byte frame), CAN FD frames per
//! second (63 stream bytes per frame), against a baseline measured in the same
//! run: one frame per sample (postcard `RawSample` + CRC-32 + COBS).
//!
//! Also states what protocol version 2 costs for a capture that starts late:
//! the session header repeated every `HEADER_INTERVAL_S` and the leading 0x00
//! delimiter of every frame, in bytes per second and as a share of the stream.
//!
//! Run: `cargo bench -p jointid-core --features std --bench wire_load`

use heapless::spsc::Queue;
use jointid_core::excitation::{crest_factor, Excitation, ExcitationConfig};
use jointid_core::joint::{JointIo, JointParams, JointSim};
use jointid_core::sampler::{Counters, PumpConfig, PumpState, Sampler, TaggedSample, TxPump};
use jointid_core::transport::can::{
    classic_frame_bits_worst, fragments_for, CLASSIC_PAYLOAD, FD_PAYLOAD,
};
use jointid_core::transport::{FrameSink, TxError};
use jointid_core::wire::{
    cobs_encode, cobs_max_len, Crc32, DecodeEvent, Decoder, Message, SessionHeader,
    HEADER_INTERVAL_S, PROTOCOL_VERSION,
};

/// Collects frame lengths and the byte stream.
#[derive(Default)]
struct Meter {
    stream: Vec<u8>,
    frame_lens: Vec<usize>,
}

impl FrameSink for Meter {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        self.stream.extend_from_slice(frame);
        self.frame_lens.push(frame.len());
        Ok(())
    }
    fn tx_errors(&self) -> u32 {
        0
    }
}

struct Load {
    bytes: usize,
    frames: usize,
    classic_frames: usize,
    classic_bits: u64,
    fd_frames: usize,
}

fn load(frame_lens: &[usize]) -> Load {
    let mut l = Load {
        bytes: 0,
        frames: frame_lens.len(),
        classic_frames: 0,
        classic_bits: 0,
        fd_frames: 0,
    };
    for &len in frame_lens {
        l.bytes += len;
        let n = fragments_for(len, CLASSIC_PAYLOAD);
        l.classic_frames += n;
        // full fragments carry 8 data bytes, the last one 1 + the rest
        let last = len - (n - 1) * CLASSIC_PAYLOAD;
        l.classic_bits += (n as u64 - 1) * classic_frame_bits_worst(8) as u64
            + classic_frame_bits_worst(1 + last) as u64;
        l.fd_frames += fragments_for(len, FD_PAYLOAD);
    }
    l
}

fn report(name: &str, l: &Load, samples: usize, seconds: f64) {
    let bps = l.bytes as f64 / seconds;
    println!("{name}");
    println!(
        "  frames {:>8}  bytes {:>9}  bytes/sample {:>6.3}  bytes/s {:>8.0}",
        l.frames,
        l.bytes,
        l.bytes as f64 / samples as f64,
        bps
    );
    println!(
        "  UART 8N1 load: {:>6.1} % at 230400 baud, {:>6.1} % at 921600 baud",
        100.0 * bps * 10.0 / 230_400.0,
        100.0 * bps * 10.0 / 921_600.0
    );
    println!(
        "  classic CAN 1 Mbit/s: {:>7.0} frames/s, worst-case load {:>6.1} %",
        l.classic_frames as f64 / seconds,
        100.0 * l.classic_bits as f64 / seconds / 1e6
    );
    println!(
        "  CAN FD (64-byte frames): {:>7.0} frames/s",
        l.fd_frames as f64 / seconds
    );
}

fn main() {
    let cfg = ExcitationConfig {
        periods: 24,
        ..ExcitationConfig::paper_default()
    };
    let total = cfg.total_samples().unwrap() as usize;
    let seconds = total as f64 / cfg.fs_hz as f64;
    let params = JointParams::default_joint();
    let mut io = JointIo::new(JointSim::new(params));
    let header = SessionHeader {
        protocol_version: PROTOCOL_VERSION,
        board_id: 0xB0A2_D001,
        session_id: 1,
        sample_rate_hz: cfg.fs_hz,
        timer_hz: 1_000_000,
        excitation: cfg,
        scale: io.sim.scale(),
    };
    let mut table = vec![0.0f32; cfg.period_samples as usize];
    let exc = Excitation::new(&cfg, &mut table).unwrap();
    let peaks = cfg.peaks().unwrap();
    println!(
        "excitation: peak {:.4} rad, crest factor {:.2}, peak velocity {:.1} rad/s \
         ({:.1} with the ramp bound)",
        peaks.angle_rad,
        crest_factor(exc.period()),
        peaks.velocity_rad_s,
        peaks.velocity_with_ramp_rad_s
    );
    let mut queue: Queue<TaggedSample, 256> = Queue::new();
    let (producer, consumer) = queue.split();
    let counters = Counters::new();
    let mut sampler = Sampler::new(exc, producer, &counters);
    let mut pump = TxPump::new(consumer, &counters, header, PumpConfig::default());
    let mut meter = Meter::default();
    let mut raw = Vec::with_capacity(total);
    let mut k = 0u32;
    loop {
        sampler.tick_io(500u32.wrapping_mul(k), &mut io);
        k += 1;
        if k.is_multiple_of(16) && pump.poll(&mut meter) == PumpState::Done {
            break;
        }
        if k as usize > total + 100 {
            while pump.poll(&mut meter) != PumpState::Done {}
            break;
        }
    }

    // decode: lossless check, and the baseline of one frame per sample
    let mut dec = Decoder::new();
    let mut damaged = 0;
    let mut end = None;
    // batches per (torque order, angle order) the encoder chose
    let mut orders = [[0usize; 3]; 3];
    let mut data_bytes = 0usize;
    // framed bytes of the repeated headers (each with its leading delimiter)
    let (mut headers, mut repeat_bytes) = (0usize, 0usize);
    dec.feed(&meter.stream, |e| match e {
        DecodeEvent::Frame { message, len, .. } => match message {
            Message::Header(_) => {
                headers += 1;
                if headers > 1 {
                    repeat_bytes += len + 1;
                }
            }
            Message::Batch(b) => {
                let (t, a) = b.predictor_orders();
                orders[t as usize][a as usize] += 1;
                data_bytes += b.data_len();
                raw.extend(b.samples());
            }
            Message::End(s) => end = Some(s),
            _ => {}
        },
        DecodeEvent::Damaged { .. } => damaged += 1,
    });
    assert_eq!(damaged, 0);
    assert_eq!(raw.len(), total, "samples decoded");
    assert!(raw.iter().enumerate().all(|(i, s)| s.seq as usize == i));
    let end = end.expect("End frame");
    assert_eq!((end.overruns, end.queue_drops), (0, 0));

    let mut baseline = Vec::with_capacity(total);
    let mut buf = [0u8; 64];
    let mut enc = [0u8; 80];
    for s in &raw {
        let n = postcard::to_slice(s, &mut buf[..]).unwrap().len();
        let crc = Crc32::checksum(&buf[..n]);
        buf[n..n + 4].copy_from_slice(&crc.to_le_bytes());
        assert!(cobs_max_len(n + 4) < enc.len());
        baseline.push(cobs_encode(&buf[..n + 4], &mut enc).unwrap() + 1);
    }

    let t: Vec<i32> = raw.iter().map(|s| s.torque).collect();
    let a: Vec<i32> = raw.iter().map(|s| s.angle).collect();
    let range = |v: &[i32]| (*v.iter().min().unwrap(), *v.iter().max().unwrap());
    println!(
        "wire_load: {total} samples, {seconds:.1} s at {} Hz, {} lines, rms {} rad; \
         torque counts {:?}, angle counts {:?} (2^20/rev)",
        cfg.fs_hz,
        cfg.line_count(),
        cfg.rms_rad,
        range(&t),
        range(&a)
    );
    println!(
        "predictor orders chosen per batch (torque x angle, 0 = value, 1 = first, \
         2 = second difference): {orders:?}; delta-coded data {:.3} bytes/sample",
        data_bytes as f64 / total as f64
    );
    let ours = load(&meter.frame_lens);
    report(
        "batched (64 samples/batch, status every 16 batches, header every 1 s + end)",
        &ours,
        total,
        seconds,
    );
    let stream_bps = ours.bytes as f64 / seconds;
    let repeat_bps = repeat_bytes as f64 / seconds;
    let delim_bps = ours.frames as f64 / seconds;
    println!(
        "session header repeated every {HEADER_INTERVAL_S} s ({} repeats of {} bytes): \
         {repeat_bps:.1} bytes/s, {:.2} % of the stream",
        headers - 1,
        repeat_bytes / (headers - 1).max(1),
        100.0 * repeat_bps / stream_bps
    );
    println!(
        "leading 0x00 before every frame: {delim_bps:.1} bytes/s, {:.2} % of the stream; \
         together {:.1} bytes/s, {:.2} %",
        100.0 * delim_bps / stream_bps,
        repeat_bps + delim_bps,
        100.0 * (repeat_bps + delim_bps) / stream_bps
    );
    let base = load(&baseline);
    report("baseline: one frame per sample", &base, total, seconds);
    println!(
        "ratio batched / baseline bytes: {:.3}",
        ours.bytes as f64 / base.bytes as f64
    );
}
