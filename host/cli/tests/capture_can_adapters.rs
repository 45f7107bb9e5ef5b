//! End-to-end tests of `jointid capture --candump LOG` and `--slcan PORT`: a simulated run
//! (`jointid simulate`) cut into CAN frames by the core's fragmenter, written as a
//! `candump -l` log and as slcan lines over a socat pty pair, with lost, repeated and
//! swapped CAN frames and bad lines put in. What must arrive, and what must be reported,
//! is computed here from where the faults were put; the samples are compared with the
//! export of the undamaged run, bit for bit.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use embedded_can::{Frame as _, Id, StandardId};
use jointid_core::transport::can::{Fragmenter, MemFrame};
use jointid_core::wire::{DecodeEvent, Decoder, Message};
use serde_json::Value;

mod common;
use common::{json_of, tmpdir, BIN};

/// One wire frame of the simulated stream: its bytes (both delimiters) and its samples.
struct Wire {
    offset: usize,
    bytes: Vec<u8>,
    seqs: std::ops::Range<u32>,
}

/// The stream of a simulated run (`jointid simulate`), its wire frames and the exported
/// rows of the undamaged run, by sample index.
struct Run {
    wires: Vec<Wire>,
    rows: BTreeMap<u64, String>,
}

fn simulate(dir: &Path) -> Run {
    let jcap = dir.join("sim.jcap");
    let o = jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--periods",
        "2",
        "--out",
        jcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stream = std::fs::read(&jcap).unwrap()[8..].to_vec();
    // protocol 2: every wire frame is 0x00, its COBS body, 0x00
    let mut wires = Vec::new();
    let mut start = 0;
    while start < stream.len() {
        assert_eq!(stream[start], 0, "a wire frame starts with its delimiter");
        let end = start + 1 + stream[start + 1..].iter().position(|&b| b == 0).unwrap();
        let bytes = stream[start..=end].to_vec();
        let mut seqs = 0..0;
        Decoder::new().feed(&bytes, |e| {
            if let DecodeEvent::Frame {
                message: Message::Batch(b),
                ..
            } = e
            {
                seqs = b.first_seq()..b.first_seq() + b.len() as u32;
            }
        });
        wires.push(Wire {
            offset: start,
            bytes,
            seqs,
        });
        start = end + 1;
    }
    let rows = export_rows(dir, &jcap);
    Run { wires, rows }
}

fn jointid(args: &[&str]) -> Output {
    common::jointid(args)
}

/// `jointid export JCAP --csv`: the data rows keyed by sample index (t · fs), as text.
fn export_rows(dir: &Path, jcap: &Path) -> BTreeMap<u64, String> {
    let csv = dir.join(format!(
        "{}.csv",
        jcap.file_stem().unwrap().to_str().unwrap()
    ));
    let o = jointid(&[
        "export",
        jcap.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut fs = 0.0;
    let mut rows = BTreeMap::new();
    for line in text.lines() {
        if let Some(v) = line.strip_prefix("# sample_rate_hz=") {
            fs = v.trim().parse().unwrap();
        }
        if line.starts_with('#') || line.starts_with('t') {
            continue;
        }
        let t: f64 = line.split(',').next().unwrap().parse().unwrap();
        rows.insert((t * fs).round() as u64, line.to_string());
    }
    assert!(fs > 0.0, "the capture CSV names its sample rate");
    rows
}

fn board_id() -> Id {
    Id::Standard(StandardId::new(0x101).unwrap())
}

/// The faults put on the bus, and what they must cost.
struct Damaged {
    /// CAN frames as they arrive
    frames: Vec<MemFrame>,
    /// wire frames damaged, in stream order
    hit: Vec<usize>,
}

/// Cuts the run into CAN frames and damages it: the second CAN frame of one batch is
/// lost, the first of another, two CAN frames of a third arrive swapped, and CAN frames
/// of two more batches are repeated (harmless).
fn damage(run: &Run, fd: bool) -> Damaged {
    let mut frag = if fd {
        Fragmenter::fd(board_id())
    } else {
        Fragmenter::classic(board_id())
    };
    let mut per_wire: Vec<Vec<MemFrame>> = Vec::new();
    for w in &run.wires {
        let mut cans = Vec::new();
        frag.fragment(&w.bytes, |f: MemFrame| {
            cans.push(f);
            Ok::<(), ()>(())
        })
        .unwrap();
        per_wire.push(cans);
    }
    let long: Vec<usize> = (0..run.wires.len())
        .filter(|&i| !run.wires[i].seqs.is_empty() && per_wire[i].len() >= 3)
        .collect();
    assert!(long.len() > 40, "{} long batches", long.len());
    let (mid, head, swap, rep1, rep2) = (long[5], long[12], long[20], long[26], long[33]);
    let mut frames = Vec::new();
    for (i, cans) in per_wire.iter().enumerate() {
        let mut c = cans.clone();
        if i == mid {
            c.remove(1);
        } else if i == head {
            c.remove(0);
        } else if i == swap {
            c.swap(1, 2);
        } else if i == rep1 {
            c.insert(0, c[0].clone());
        } else if i == rep2 {
            let last = c[c.len() - 1].clone();
            c.push(last);
        }
        frames.extend(c);
    }
    Damaged {
        frames,
        hit: vec![mid, head, swap],
    }
}

fn hex(data: &[u8]) -> String {
    data.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02X}");
        s
    })
}

/// Checks a capture of the damaged run: exactly the samples of the hit wire frames are
/// missing, as gaps; each hit wire frame is one damaged frame, the first at its offset;
/// every other sample is the undamaged run's, bit for bit; the bad lines are those given.
fn check(dir: &Path, run: &Run, d: &Damaged, v: &Value, out: &Path, bad_lines: &[u64]) {
    let lost: Vec<u32> = d
        .hit
        .iter()
        .flat_map(|&w| run.wires[w].seqs.clone())
        .collect();
    let total = run.rows.len() as u64;
    assert_eq!(v["samples"].as_u64().unwrap(), total - lost.len() as u64);
    let gaps: Vec<(u64, u64)> = v["gaps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| (g["from"].as_u64().unwrap(), g["to"].as_u64().unwrap()))
        .collect();
    let want: Vec<(u64, u64)> = d
        .hit
        .iter()
        .map(|&w| {
            let s = &run.wires[w].seqs;
            (u64::from(s.start), u64::from(s.end - 1))
        })
        .collect();
    assert_eq!(gaps, want);
    let damaged = v["damaged_frames"].as_array().unwrap();
    assert_eq!(damaged.len(), d.hit.len(), "{damaged:?}");
    assert_eq!(
        damaged[0]["offset"].as_u64().unwrap(),
        run.wires[d.hit[0]].offset as u64 + 1,
        "the first damaged frame is where its wire frame was"
    );
    let got_lines: Vec<u64> = v["link_events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["event"] == "bad_line")
        .map(|e| e["line"].as_u64().unwrap())
        .collect();
    assert_eq!(got_lines, bad_lines);
    // every sample that arrived is the undamaged run's, bit for bit
    let rows = export_rows(dir, out);
    assert_eq!(rows.len() as u64, total - lost.len() as u64);
    for (k, row) in &rows {
        assert_eq!(Some(row), run.rows.get(k), "sample {k}");
    }
    for s in lost {
        assert!(!rows.contains_key(&u64::from(s)), "lost sample {s} present");
    }
    // `info` reads the same from the file and its sidecar
    let info = json_of(&jointid(&["info", out.to_str().unwrap(), "--json"]));
    assert_eq!(info["gaps"], v["gaps"]);
    assert_eq!(info["damaged_frames"], v["damaged_frames"]);
    assert_eq!(info["link_events"], v["link_events"]);
}

#[test]
fn candump_log_replays_with_the_damage_reported_and_every_intact_sample_bit_exact() {
    let dir = tmpdir("candump");
    let run = simulate(&dir);
    let d = damage(&run, true);
    // FD frames as candump -l writes them, with a remote frame, a frame of another
    // device, a line that is no frame and a bus error frame among them
    let mut log = String::new();
    let mut line = 0u64;
    let mut bad = Vec::new();
    for (i, f) in d.frames.iter().enumerate() {
        let t = 1_700_000_000.0 + i as f64 * 1e-4;
        match i {
            10 => {
                log.push_str("(1700000000.000500) can0 101#R\n");
                log.push_str("(1700000000.000501) can0 7FF#0011\n");
                line += 2;
            }
            200 => {
                log.push_str("this line is not a frame\n");
                line += 1;
                bad.push(line);
            }
            300 => {
                log.push_str("(1700000000.030000) can0 20000004#0004000000000000\n");
                line += 1;
                bad.push(line);
            }
            _ => {}
        }
        writeln!(log, "({t:.6}) can0 101##1{}", hex(f.data())).unwrap();
        line += 1;
    }
    let path = dir.join("bus.log");
    std::fs::write(&path, &log).unwrap();
    let out = dir.join("run.jcap");
    let o = jointid(&[
        "capture",
        "--candump",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let v = json_of(&o);
    assert_eq!(v["stop"], "board sent end of session");
    check(&dir, &run, &d, &v, &out, &bad);
    // the summary names the bad lines by number
    let text = jointid(&["info", out.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("bad lines        2"), "{text}");
    assert!(
        text.contains(&format!("line {} (at byte", bad[0]))
            && text.contains("`this line is not a frame`: expected `(SECONDS.MICROS)"),
        "{text}"
    );
    // --strict fails a capture with bad lines
    let o = jointid(&[
        "capture",
        "--candump",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--force",
        "--strict",
        "--quiet",
    ]);
    assert_eq!(o.status.code(), Some(1));
    // a log that cannot be read is a setup error that leaves no capture
    let missing = dir.join("missing.log");
    let out2 = dir.join("none.jcap");
    let o = jointid(&[
        "capture",
        "--candump",
        missing.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("missing.log"), "{err}");
    assert!(!out2.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A socat pty pair, `a` the adapter's side and `b` the port the capture opens.
struct Socat {
    child: Child,
    a: PathBuf,
    b: PathBuf,
}

impl Socat {
    /// `None` when socat is not installed.
    fn start(dir: &Path) -> Option<Self> {
        let (a, b) = (dir.join("ttyA"), dir.join("ttyB"));
        let child = Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .ok()?;
        wait_until("socat's ptys", Duration::from_secs(5), || {
            a.exists() && b.exists()
        });
        Some(Self { child, a, b })
    }
}

impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn wait_until(what: &str, timeout: Duration, mut ok: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !ok() {
        assert!(t0.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Reads from the adapter's side of the pty until `want` has arrived (nonblocking).
fn read_until(port: &mut std::fs::File, want: &[u8], timeout: Duration) -> Vec<u8> {
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    wait_until("the adapter commands", timeout, || {
        match port.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) => panic!("reading the pty: {e}"),
        }
        got.windows(want.len()).any(|w| w == want)
    });
    got
}

#[cfg(target_os = "linux")]
#[test]
fn slcan_over_a_pty_records_the_damage_and_every_intact_sample_bit_exact() {
    use std::os::unix::fs::OpenOptionsExt;
    let dir = tmpdir("slcan");
    let Some(socat) = Socat::start(&dir) else {
        eprintln!(
            "skipped: socat is not installed (the slcan adapter is played over a socat pty pair)"
        );
        return;
    };
    let run = simulate(&dir);
    let d = damage(&run, false);
    let out = dir.join("run.jcap");
    let child = Command::new(BIN)
        .args([
            "capture",
            "--slcan",
            socat.b.to_str().unwrap(),
            "--slcan-bitrate",
            "1000000",
            "--slcan-data-bitrate",
            "5000000",
            "--out",
            out.to_str().unwrap(),
            "--json",
            "--duration",
            "60",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // O_NONBLOCK: the test must not hang when a command never comes
    let mut adapter_in = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(0o4000)
        .open(&socat.a)
        .unwrap();
    let mut adapter = std::fs::OpenOptions::new()
        .write(true)
        .open(&socat.a)
        .unwrap();
    let commands = read_until(&mut adapter_in, b"O\r", Duration::from_secs(10));
    assert_eq!(commands, b"C\rS8\rY5\rO\r");
    // replies: BEL to `C` (the channel was closed already: not an error), OK, OK, OK
    let mut text = b"\x07\r\r\r".to_vec();
    let mut line = 4u64;
    let mut bad = Vec::new();
    for (i, f) in d.frames.iter().enumerate() {
        match i {
            100 => {
                text.extend_from_slice(b"r1010\rt7FF20011\r");
                line += 2;
            }
            400 => {
                text.extend_from_slice(b"t10G8\r");
                line += 1;
                bad.push(line);
            }
            600 => {
                text.push(0x07);
                line += 1;
                bad.push(line);
            }
            _ => {}
        }
        // every other frame with a millisecond timestamp
        let stamp = if i % 2 == 0 {
            format!("{:04X}", i % 60_000)
        } else {
            String::new()
        };
        write!(
            WriteString(&mut text),
            "t101{}{}{stamp}\r",
            f.dlc(),
            hex(f.data())
        )
        .unwrap();
        line += 1;
    }
    for chunk in text.chunks(509) {
        adapter.write_all(chunk).unwrap();
    }
    let mut child = child;
    let o = wait_exit(&mut child, Duration::from_secs(30));
    let v = json_of(&o);
    assert_eq!(v["stop"], "board sent end of session");
    check(&dir, &run, &d, &v, &out, &bad);
    // the capture closed the channel
    let rest = read_until(&mut adapter_in, b"C\r", Duration::from_secs(5));
    assert_eq!(rest, b"C\r");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `write!` into a byte vector.
struct WriteString<'a>(&'a mut Vec<u8>);

impl std::fmt::Write for WriteString<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0.extend_from_slice(s.as_bytes());
        Ok(())
    }
}

fn wait_exit(child: &mut Child, timeout: Duration) -> Output {
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > timeout {
            let _ = child.kill();
            panic!("jointid capture did not stop");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let (mut stdout, mut stderr) = (Vec::new(), Vec::new());
    if let Some(mut o) = child.stdout.take() {
        o.read_to_end(&mut stdout).unwrap();
    }
    if let Some(mut e) = child.stderr.take() {
        e.read_to_end(&mut stderr).unwrap();
    }
    Output {
        status: child.wait().unwrap(),
        stdout,
        stderr,
    }
}
