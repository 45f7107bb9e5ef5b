//! Helpers shared by the workspace-level tests: finding or building the
//! emulated-board firmware, running it in qemu-system-arm with a child that is
//! killed on drop, reading its UART over TCP, all under deadlines so a broken
//! firmware fails a test instead of hanging it.
//!
//! QEMU settings follow notes/embedded-feasibility.md §2: `-icount
//! shift=3,align=off,sleep=off` (deterministic; SysTick counts instructions),
//! semihosting on (defmt log on stdout, exit status, cost line on stderr),
//! UART0 as a TCP client of a listener the test opened first.

use std::io::Read;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// the firmware's target triple
pub const FIRMWARE_TARGET: &str = "thumbv7em-none-eabihf";

/// what to tell a developer whose machine lacks a tool the test needs
pub const SETUP_HINT: &str =
    "run `.ci/setup` (installs the thumbv7em-none-eabihf target and qemu-system-arm)";

/// the workspace root (the directory of the root Cargo.toml)
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lives inside the workspace")
        .to_path_buf()
}

/// Whether `rustc` has the standard library for [`FIRMWARE_TARGET`].
pub fn firmware_target_installed() -> bool {
    let out = Command::new("rustc")
        .args(["--print", "target-libdir", "--target", FIRMWARE_TARGET])
        .output();
    match out {
        Ok(o) if o.status.success() => {
            let dir = String::from_utf8_lossy(&o.stdout).trim().to_string();
            Path::new(&dir).join("libcore.rlib").exists()
                || std::fs::read_dir(&dir)
                    .map(|d| {
                        d.flatten()
                            .any(|e| e.file_name().to_string_lossy().starts_with("libcore-"))
                    })
                    .unwrap_or(false)
        }
        _ => false,
    }
}

/// Whether `qemu-system-arm` runs.
pub fn qemu_installed() -> bool {
    Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// The emulated-board firmware ELF: `FIRMWARE_ELF` when set (a relative path
/// is taken from the workspace root), otherwise built with a nested
/// `cargo build -p jointid-fw --features mps2-an386` (profile `firmware`).
///
/// # Errors
/// A message naming what is missing or the failed build command.
pub fn emulated_firmware_elf() -> Result<PathBuf, String> {
    if let Some(elf) = std::env::var_os("FIRMWARE_ELF") {
        let elf = workspace_root().join(elf);
        return if elf.is_file() {
            Ok(elf)
        } else {
            Err(format!("FIRMWARE_ELF={} is not a file", elf.display()))
        };
    }
    if !firmware_target_installed() {
        return Err(format!(
            "the {FIRMWARE_TARGET} target is not installed: {SETUP_HINT}"
        ));
    }
    let root = workspace_root();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(&root)
        .args(["build", "--manifest-path"])
        .arg(root.join("Cargo.toml"))
        .args([
            "-p",
            "jointid-fw",
            "--target",
            FIRMWARE_TARGET,
            "--profile",
            "firmware",
            "--no-default-features",
            "--features",
            "mps2-an386",
            "--message-format=json-render-diagnostics",
        ])
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run cargo to build the firmware: {e}"))?;
    if !out.status.success() {
        return Err(format!("firmware build failed ({})", out.status));
    }
    // the last compiler artifact of jointid-fw names the linked ELF
    let stdout = String::from_utf8_lossy(&out.stdout);
    stdout
        .lines()
        .filter(|l| l.contains("\"compiler-artifact\"") && l.contains("jointid-fw"))
        .filter_map(|l| json_string_field(l, "executable"))
        .next_back()
        .map(PathBuf::from)
        .ok_or_else(|| "cargo reported no executable for jointid-fw".to_string())
}

/// the value of `"key":"value"` in one line of cargo's JSON (no escapes in paths expected)
fn json_string_field(line: &str, key: &str) -> Option<String> {
    let pat = format!("\"{key}\":\"");
    let start = line.find(&pat)? + pat.len();
    let end = line[start..].find('"')? + start;
    Some(line[start..end].replace("\\\\", "\\"))
}

/// A child process killed (and reaped) when dropped.
pub struct KillOnDrop(pub Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl KillOnDrop {
    /// Waits for the child to exit, at most until `deadline`.
    ///
    /// # Errors
    /// A message when the deadline passes first (the child is then killed on drop).
    pub fn wait_until(&mut self, deadline: Instant) -> Result<ExitStatus, String> {
        loop {
            match self.0.try_wait() {
                Ok(Some(status)) => return Ok(status),
                Ok(None) if Instant::now() >= deadline => {
                    return Err("qemu did not exit before the deadline".into())
                }
                Ok(None) => thread::sleep(Duration::from_millis(20)),
                Err(e) => return Err(format!("cannot wait for qemu: {e}")),
            }
        }
    }
}

/// A running emulated board.
pub struct Qemu {
    /// the qemu-system-arm process
    pub child: KillOnDrop,
    /// collects QEMU's stdout (the raw defmt stream)
    stdout: Option<JoinHandle<Vec<u8>>>,
    /// collects QEMU's stderr (semihosting stderr: the cost line; QEMU's own errors)
    stderr: Option<JoinHandle<Vec<u8>>>,
}

/// everything a finished emulated run produced
pub struct QemuRun {
    /// QEMU's exit status (the firmware's semihosting exit code)
    pub status: ExitStatus,
    /// bytes the firmware sent on UART0
    pub uart: Vec<u8>,
    /// raw defmt stream (semihosting stdout)
    pub defmt: Vec<u8>,
    /// semihosting stderr and QEMU's messages, as text
    pub stderr: String,
}

fn drain<R: Read + Send + 'static>(mut r: R) -> JoinHandle<Vec<u8>> {
    thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = r.read_to_end(&mut buf);
        buf
    })
}

impl Qemu {
    /// Starts `elf` on mps2-an386 with UART0 connected as a TCP client to `port` on 127.0.0.1.
    ///
    /// # Errors
    /// A message when qemu-system-arm cannot be started.
    pub fn start(elf: &Path, port: u16) -> Result<Self, String> {
        let mut child = Command::new("qemu-system-arm")
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
            .args(["-serial", &format!("tcp:127.0.0.1:{port}")])
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start qemu-system-arm ({SETUP_HINT}): {e}"))?;
        let stdout = child.stdout.take().map(drain);
        let stderr = child.stderr.take().map(drain);
        Ok(Self {
            child: KillOnDrop(child),
            stdout,
            stderr,
        })
    }

    /// Runs `elf` to completion: listens on 127.0.0.1:0, starts QEMU, reads
    /// UART0 until QEMU closes it, waits for the exit status; everything
    /// within `timeout`.
    ///
    /// # Errors
    /// A message naming the step that failed or timed out.
    pub fn run(elf: &Path, timeout: Duration) -> Result<QemuRun, String> {
        let deadline = Instant::now() + timeout;
        let listener = TcpListener::bind("127.0.0.1:0")
            .map_err(|e| format!("cannot listen on 127.0.0.1:0: {e}"))?;
        let port = listener.local_addr().map_err(|e| e.to_string())?.port();
        let mut qemu = Self::start(elf, port)?;
        let stream = accept_until(&listener, &mut qemu.child, deadline)?;
        let uart = read_until_closed(stream, deadline)?;
        let status = qemu.child.wait_until(deadline)?;
        let defmt = qemu
            .stdout
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        let stderr = qemu
            .stderr
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        Ok(QemuRun {
            status,
            uart,
            defmt,
            stderr: String::from_utf8_lossy(&stderr).into_owned(),
        })
    }
}

/// Accepts one connection before `deadline`, failing early if the child exits first.
fn accept_until(
    listener: &TcpListener,
    child: &mut KillOnDrop,
    deadline: Instant,
) -> Result<TcpStream, String> {
    listener.set_nonblocking(true).map_err(|e| e.to_string())?;
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                stream.set_nonblocking(false).map_err(|e| e.to_string())?;
                return Ok(stream);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if let Ok(Some(status)) = child.0.try_wait() {
                    return Err(format!("qemu exited ({status}) before connecting its UART"));
                }
                if Instant::now() >= deadline {
                    return Err("qemu did not connect its UART before the deadline".into());
                }
                thread::sleep(Duration::from_millis(10));
            }
            Err(e) => return Err(format!("accept on the UART listener failed: {e}")),
        }
    }
}

/// Reads `stream` to its end (QEMU closes it when it exits), at most until `deadline`.
fn read_until_closed(mut stream: TcpStream, deadline: Instant) -> Result<Vec<u8>, String> {
    let mut data = Vec::new();
    let mut buf = [0u8; 64 * 1024];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(format!(
                "the UART stream was still open at the deadline after {} bytes",
                data.len()
            ));
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|e| e.to_string())?;
        match stream.read(&mut buf) {
            Ok(0) => return Ok(data),
            Ok(n) => data.extend_from_slice(&buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                return Err(format!(
                    "reading the UART stream failed after {} bytes: {e}",
                    data.len()
                ))
            }
        }
    }
}

/// The numbers of the firmware's `jointid-cost key=value ...` line, by key.
pub fn parse_cost_line(stderr: &str) -> Option<Vec<(String, u64)>> {
    let line = stderr.lines().find(|l| l.starts_with("jointid-cost "))?;
    line.split_whitespace()
        .skip(1)
        .map(|kv| {
            let (k, v) = kv.split_once('=')?;
            Some((k.to_string(), v.parse().ok()?))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_line_parses_keys_and_values() {
        let got = parse_cost_line("noise\njointid-cost ticks=24000 per_tick_mean=640\n").unwrap();
        assert_eq!(
            got,
            vec![
                ("ticks".to_string(), 24000),
                ("per_tick_mean".to_string(), 640)
            ]
        );
    }

    #[test]
    fn cost_line_absent_or_malformed_is_none() {
        assert!(parse_cost_line("jointid-costs x=1").is_none());
        assert!(parse_cost_line("jointid-cost ticks=x").is_none());
    }

    #[test]
    fn json_field_reads_executable_path() {
        let line = r#"{"reason":"compiler-artifact","executable":"/t/jointid-fw","fresh":true}"#;
        assert_eq!(
            json_string_field(line, "executable").as_deref(),
            Some("/t/jointid-fw")
        );
        assert_eq!(json_string_field(line, "missing"), None);
    }
}
