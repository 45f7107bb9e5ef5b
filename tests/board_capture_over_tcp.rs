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

/// Whether a socket of this process listens on loopback `port`, read from the kernel's
/// table (`/proc/net/tcp`: local address `0100007F:PPPP`, state `0A` = LISTEN, the
/// socket's inode in column 10) and this process's descriptors (`socket:[INODE]`): a
/// listener of another process on the same port is not the capture's.
fn is_listening(port: u16) -> bool {
    let local = format!("0100007F:{port:04X}");
    let inodes: Vec<String> = std::fs::read_to_string("/proc/net/tcp")
        .expect("/proc/net/tcp (these tests run on Linux)")
        .lines()
        .skip(1)
        .filter_map(|line| {
            let f: Vec<&str> = line.split_whitespace().collect();
            (f.len() > 9 && f[1] == local && f[3] == "0A").then(|| format!("socket:[{}]", f[9]))
        })
        .collect();
    !inodes.is_empty()
        && std::fs::read_dir("/proc/self/fd")
            .expect("/proc/self/fd")
            .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
            .any(|l| inodes.iter().any(|i| l.as_os_str() == i.as_str()))
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

/// Issue 13 item 19: the firmware README's recipe as written. `jointid capture
/// --tcp-listen 127.0.0.1:PORT` listens (here through the same library path), then
/// `JOINTID_SERIAL=tcp:127.0.0.1:PORT cargo fw-qemu-run` runs the cargo runner
/// (`firmware/app/runner.sh`), whose QEMU connects to the capture as a client; the
/// capture stops at the board's end message with every sample, bit exact.
#[test]
fn r19_readme_recipe_qemu_connects_to_a_listening_capture() {
    let elf = emulated_firmware_elf().unwrap_or_else(|e| panic!("{e}"));
    let dir = std::env::temp_dir().join(format!("jointid-qemu-listen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out: PathBuf = dir.join("board.jcap");
    let mut opts = CaptureOptions::new(&out);
    opts.stop.duration = Some(Duration::from_secs(120));
    // a port free when probed can be taken before the capture binds it (another test's
    // QEMU server or any process on this machine): then another port
    for attempt in 1.. {
        match listen_and_run_board(&elf, &opts) {
            Err(e) if attempt < 5 && port_taken(&e) => continue,
            r => {
                let outcome = r.expect("capture from the emulated board");
                assert_eq!(outcome.stop, StopReason::EndMessage, "{}", outcome.report);
                assert!(outcome.report.is_clean(), "{}", outcome.report);
                break;
            }
        }
    }
    let rec = read_jcap(&out).expect("read the capture back");
    let cfg = rec.header.excitation;
    let total = cfg.total_samples().expect("a finite experiment") as usize;
    assert!(rec.report.is_clean() && rec.report.ended, "{}", rec.report);
    assert_eq!(rec.samples.len(), total);
    let reference = jointid_core::excitation::generate(&cfg).unwrap();
    for (k, (s, r)) in rec.samples.iter().zip(&reference).enumerate() {
        assert_eq!(s.seq as usize, k);
        assert_eq!(s.theta_ref, f64::from(*r), "seq {k}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs the README's recipe once on a fresh port: the capture listens, the cargo runner's
/// QEMU connects to it; the capture's outcome.
fn listen_and_run_board(
    elf: &std::path::Path,
    opts: &CaptureOptions,
) -> Result<jointid::capture::CaptureOutcome, CaptureError> {
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let spec = SourceSpec::TcpListen { addr: addr.clone() };
    let interrupt = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let capture = scope.spawn(|| record_capture(&spec, opts, &interrupt, |_, _| {}));
        // listening once the kernel lists the port as listening: neither a probe
        // connection (the capture would take it for the board) nor a probe bind (the
        // capture's own bind fails while the probe holds the port)
        let t0 = Instant::now();
        while !is_listening(port) {
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "capture never listened"
            );
            if capture.is_finished() {
                // its bind failed: no board to start
                return capture.join().expect("capture thread");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let runner = jointid_tests::workspace_root().join("firmware/app/runner.sh");
        let _qemu = KillOnDrop(
            Command::new(&runner)
                .arg(elf)
                .env("JOINTID_SERIAL", format!("tcp:{addr}"))
                .env("JOINTID_QEMU_TIMEOUT", "120")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap_or_else(|e| {
                    panic!("cannot start {} ({SETUP_HINT}): {e}", runner.display())
                }),
        );
        capture.join().expect("capture thread")
    })
}

/// Whether `e` is the capture's bind refused on a port another socket took.
fn port_taken(e: &CaptureError) -> bool {
    matches!(e, CaptureError::Source(SourceError::Tcp { err, .. })
        if err.kind() == std::io::ErrorKind::AddrInUse)
}
