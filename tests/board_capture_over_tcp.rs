//! Emulated board → `jointid` capture over TCP, end to end.
//!
//! The thumbv7em firmware runs the seed-000 experiment under qemu-system-arm
//! (mps2-an386, deterministic icount); its UART0 is a TCP server that holds the guest
//! until a client connects, so not one byte is sent before the capture listens. The
//! capture runs the same library path as `jointid capture --tcp HOST:PORT`
//! (`jointid::capture::record_capture`; the binary's own tests live in
//! `host/cli/tests/capture_info_export_commands.rs`), stops at the board's end message, and
//! the `.jcap` is read back with `read_jcap`: every sample must be there once, in order,
//! with no damaged frame, and the reference regenerated from the session header must equal, bit for bit,
//! the one the board used (per-batch reference CRC, and sample by sample against
//! `jointid_core::excitation::generate`).

use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use jointid::capture::{
    read_jcap, record_capture, CaptureError, CaptureOptions, SourceError, SourceSpec, StopReason,
};
use jointid_tests::{emulated_firmware_elf, KillOnDrop, SETUP_HINT};

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

#[test]
fn emulated_board_capture_over_tcp_is_complete_in_order_and_bit_exact() {
    let elf = emulated_firmware_elf().unwrap_or_else(|e| panic!("{e}"));
    let port = free_port();
    let _qemu = KillOnDrop(
        Command::new("qemu-system-arm")
            .args([
                "-machine",
                "mps2-an386",
                "-cpu",
                "cortex-m4",
                "-nographic",
                "-monitor",
                "none",
            ])
            .args(["-icount", "shift=3,align=off,sleep=off"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .args([
                "-serial",
                &format!("tcp:127.0.0.1:{port},server=on,wait=on"),
            ])
            .arg("-kernel")
            .arg(&elf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start qemu-system-arm ({SETUP_HINT}): {e}")),
    );
    let dir = std::env::temp_dir().join(format!("jointid-qemu-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out: PathBuf = dir.join("board.jcap");
    let mut opts = CaptureOptions::new(&out);
    opts.stop.duration = Some(Duration::from_secs(120));
    let spec = SourceSpec::Tcp {
        addr: format!("127.0.0.1:{port}"),
    };
    let interrupt = AtomicBool::new(false);
    // QEMU needs a moment to listen; a refused connection is a setup error that
    // leaves no file behind, so simply try again
    let t0 = Instant::now();
    let outcome = loop {
        match record_capture(&spec, &opts, &interrupt, |_, _| {}) {
            Err(CaptureError::Source(SourceError::Tcp { .. }))
                if t0.elapsed() < Duration::from_secs(10) =>
            {
                assert!(!out.exists());
                std::thread::sleep(Duration::from_millis(50));
            }
            r => break r.expect("capture from the emulated board"),
        }
    };
    assert_eq!(outcome.stop, StopReason::EndMessage, "{}", outcome.report);
    assert!(outcome.report.is_clean(), "{}", outcome.report);

    let rec = read_jcap(&out).expect("read the capture back");
    let cfg = rec.header.excitation;
    let total = cfg
        .total_samples()
        .expect("the board runs a finite experiment") as usize;
    assert!(rec.report.is_clean(), "{}", rec.report);
    assert!(rec.report.ended);
    assert_eq!(rec.samples.len(), total);
    assert!(rec
        .samples
        .iter()
        .enumerate()
        .all(|(k, s)| s.seq as usize == k));
    let reference = jointid_core::excitation::generate(&cfg).unwrap();
    for (s, r) in rec.samples.iter().zip(&reference) {
        assert_eq!(s.theta_ref, f64::from(*r), "seq {}", s.seq);
    }
    // the file holds exactly what the live capture counted
    assert_eq!(std::fs::metadata(&out).unwrap().len(), 8 + outcome.bytes);
    assert_eq!(outcome.report.samples, total as u64);
    let _ = std::fs::remove_dir_all(&dir);
}
