//! Emulated board, end to end (../shared/DESIGN.md §8): the thumbv7em firmware
//! (`jointid-fw`, feature `mps2-an386`) runs in qemu-system-arm with
//! `-icount shift=3,align=off,sleep=off`, streams its whole run (the seed-000
//! excitation: ramp + 4 periods of 5000 samples + ramp = 24 000 samples) over
//! UART0 to a TCP listener of this test, and exits through semihosting.
//!
//! Checked against known truth, with no tolerance unless stated:
//! - the byte stream decodes with the core's `wire::Decoder` without one
//!   damaged frame; the session header comes first and the end message last,
//!   and the header comes again, unchanged, after every second of samples
//!   (`wire::header_interval_samples`, 2000 samples: 40 batches of 50);
//! - sequence numbers run 0, 1, 2, … with no gap and cover the whole run;
//! - every batch's `reference_crc` equals the CRC-32 of the excitation that
//!   the host regenerates from the header's config (the reference does not
//!   travel per sample, so this compares it bit for bit, batch by batch);
//! - the measured torque and angle are exactly what the core's simulated
//!   joint (`jointid_core::joint`, deterministic f32 code) gives when the host
//!   drives it with the same reference in the sampler's order (read, then write);
//! - sample time stamps advance by one tick period (12 500 SysTick counts at
//!   25 MHz) within 2 %;
//! - the end status reports no overrun, drop or transmit error;
//! - QEMU exits by itself with status 0 before a deadline;
//! - the firmware's cost line says it needs fewer than 1 200 instructions per
//!   tick on average for generation, sampling and encoding (the simulated
//!   joint excluded). The figure is an instruction count under `-icount`,
//!   deterministic rather than a timing: about 775 are measured, and either
//!   cost removed from the core would cross the bound again (a 984-byte batch
//!   copy per sample, +1 100; an f64 `cos` per ramp sample, +500 on average).
//!
//! A machine without qemu-system-arm or the thumbv7em target fails the test
//! with a message pointing at `.ci/setup`.

use std::time::Duration;

use jointid_core::excitation::generate;
use jointid_core::joint::{JointIo, JointParams, JointSim};
use jointid_core::sampler::{AngleInput, ReferenceOutput, TorqueInput};
use jointid_core::wire::{reference_crc, DecodeEvent, Decoder, Message, RawSample, Status};
use jointid_tests::{emulated_firmware_elf, parse_cost_line, qemu_installed, Qemu, SETUP_HINT};

/// QEMU runs the 12 s of virtual time in about 5 s; generous for a loaded CI machine
const RUN_TIMEOUT: Duration = Duration::from_secs(180);

/// everything the stream said, in order
struct Session {
    messages: Vec<Message>,
    damaged: Vec<String>,
}

fn decode(bytes: &[u8]) -> Session {
    let mut s = Session {
        messages: Vec::new(),
        damaged: Vec::new(),
    };
    let mut decoder = Decoder::new();
    let mut on_event = |e: DecodeEvent| match e {
        DecodeEvent::Frame { message, .. } => s.messages.push(message),
        DecodeEvent::Damaged { offset, len, error } => s
            .damaged
            .push(format!("byte {offset}, {len} bytes: {error:?}")),
    };
    decoder.feed(bytes, &mut on_event);
    decoder.finish(&mut on_event);
    s
}

/// The simulated joint driven as the firmware's sampler drives it: at tick k
/// read u(k) and θm(k), then write θ_ref(k).
fn host_joint_samples(reference: &[f32]) -> Vec<(i32, i32)> {
    let mut io = JointIo::new(JointSim::new(JointParams::default_joint()));
    reference
        .iter()
        .map(|&r| {
            let measured = (io.read_torque(), io.read_angle());
            io.write_reference(r);
            measured
        })
        .collect()
}

#[test]
fn emulated_board_streams_the_whole_run_intact_and_as_the_joint_model_predicts() {
    let elf = emulated_firmware_elf().unwrap_or_else(|e| panic!("no emulated firmware: {e}"));
    assert!(
        qemu_installed(),
        "qemu-system-arm is not installed: {SETUP_HINT}"
    );
    let run = Qemu::run(&elf, RUN_TIMEOUT).unwrap_or_else(|e| panic!("emulated run failed: {e}"));
    assert!(
        run.status.success(),
        "qemu exited with {} (firmware panic or fault?); stderr:\n{}",
        run.status,
        run.stderr
    );

    let session = decode(&run.uart);
    assert!(
        session.damaged.is_empty(),
        "damaged frames: {:?}",
        session.damaged
    );
    let Some(Message::Header(header)) = session.messages.first() else {
        panic!(
            "first message is not the session header: {:?}",
            session.messages.first()
        );
    };
    assert_eq!(header.sample_rate_hz, 2000);
    assert_eq!(header.timer_hz, 25_000_000);
    assert_eq!(header.scale, JointParams::default_joint().scale());
    let reference = generate(&header.excitation).expect("the header's excitation regenerates");
    assert!(
        reference.len() >= 20_000,
        "run of {} samples is too short",
        reference.len()
    );

    // batches: seq continuity, reference CRC, samples collected
    let mut samples: Vec<RawSample> = Vec::with_capacity(reference.len());
    let mut end: Option<Status> = None;
    let mut last_status_seq = 0;
    let interval = jointid_core::wire::header_interval_samples(header.sample_rate_hz) as usize;
    let mut repeated_at = Vec::new();
    for (i, msg) in session.messages.iter().enumerate().skip(1) {
        assert!(end.is_none(), "message {i} after the end message: {msg:?}");
        match msg {
            Message::Header(h) => {
                assert_eq!(h, header, "repeated header at message {i}");
                repeated_at.push(samples.len());
            }
            Message::Batch(batch) => {
                let first = batch.first_seq() as usize;
                assert_eq!(first, samples.len(), "sequence gap before message {i}");
                let n = batch.len();
                assert!(
                    first + n <= reference.len(),
                    "batch at seq {first} runs past the excitation"
                );
                assert_eq!(
                    batch.reference_crc(),
                    reference_crc(&reference[first..first + n]),
                    "reference CRC of the batch at seq {first}"
                );
                for (k, s) in batch.samples().enumerate() {
                    assert_eq!(s.seq as usize, first + k, "seq inside the batch at {first}");
                    samples.push(s);
                }
            }
            Message::Status(st) => {
                assert!(
                    st.seq >= last_status_seq,
                    "status seq went back at message {i}"
                );
                last_status_seq = st.seq;
            }
            Message::End(st) => end = Some(*st),
        }
    }
    let end = end.expect("the stream ends with an end message");
    assert_eq!(samples.len(), reference.len(), "samples received");
    assert_eq!(
        repeated_at,
        (1..=reference.len() / interval)
            .map(|j| j * interval)
            .collect::<Vec<_>>(),
        "the header repeats after every {interval} samples"
    );
    assert_eq!(end.seq as usize, reference.len(), "samples the board took");
    assert_eq!(
        (end.overruns, end.queue_drops, end.tx_errors),
        (0, 0, 0),
        "end status {end:?}"
    );

    // time stamps: one tick period apart, small interrupt-latency jitter
    let step = header.timer_hz / header.sample_rate_hz;
    for w in samples.windows(2) {
        let dt = w[1].tick.wrapping_sub(w[0].tick);
        assert!(
            dt.abs_diff(step) <= step / 50,
            "tick step {dt} at seq {} (nominal {step})",
            w[1].seq
        );
    }

    // the measurements are the simulated joint's, bit for bit
    let expected = host_joint_samples(&reference);
    let angles: Vec<i32> = samples.iter().map(|s| s.angle).collect();
    assert!(angles.iter().any(|&a| a != angles[0]), "angle never moves");
    for (s, &(u, a)) in samples.iter().zip(&expected) {
        assert_eq!(
            (s.torque, s.angle),
            (u, a),
            "torque, angle at seq {} differ from the host model",
            s.seq
        );
    }

    // cost guard (the figure itself is printed by firmware/app/cost.sh)
    let cost = parse_cost_line(&run.stderr).unwrap_or_else(|| {
        panic!(
            "no jointid-cost line on semihosting stderr:\n{}",
            run.stderr
        )
    });
    let get = |k: &str| cost.iter().find(|(key, _)| key == k).map(|(_, v)| *v);
    assert_eq!(
        get("ticks"),
        Some(reference.len() as u64),
        "ticks measured: {cost:?}"
    );
    let mean = get("per_tick_mean").expect("per_tick_mean in the cost line");
    assert!(
        mean > 0 && mean < 1_200,
        "instructions per tick {mean} outside (0, 1200): {cost:?}"
    );
}
