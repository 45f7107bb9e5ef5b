//! End-to-end tests of `jointid capture`, `info` and `export`, run on the built binary.
//!
//! Every stream is synthesised with the core's encoder from known samples
//! (`jointid::test_support::synth`), so what must arrive, and what must be reported damaged
//! after a fault is injected, is computed here from where the frames lie and where the
//! fault was put, not from the decoder under test.

use std::collections::BTreeMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use jointid::test_support::synth::{
    synth_stream, FrameContent, FrameSpan, SynthOptions, SynthStream,
};
use serde_json::Value;

mod common;
use common::{jointid, json_of, tmpdir, BIN};

fn small() -> SynthStream {
    synth_stream(&SynthOptions::small())
}

fn batches(s: &SynthStream) -> Vec<FrameSpan> {
    s.frames
        .iter()
        .copied()
        .filter(|f| matches!(f.content, FrameContent::Batch { .. }))
        .collect()
}

fn seqs_of(f: &FrameSpan) -> std::ops::Range<u32> {
    match f.content {
        FrameContent::Batch { first, len } => first..first + len,
        _ => 0..0,
    }
}

fn bytes_of<'a>(s: &'a SynthStream, f: &FrameSpan) -> &'a [u8] {
    &s.bytes[f.offset as usize..(f.offset + f.len) as usize]
}

/// `(offset, len)` of each damaged frame in a report.
fn damaged(v: &Value) -> Vec<(u64, u64)> {
    v["damaged_frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| (d["offset"].as_u64().unwrap(), d["len"].as_u64().unwrap()))
        .collect()
}

fn gaps(v: &Value) -> Vec<(u64, u64)> {
    v["gaps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| (g["from"].as_u64().unwrap(), g["to"].as_u64().unwrap()))
        .collect()
}

/// Inclusive ranges of the sorted sequence numbers in `lost`, merged.
fn ranges(mut lost: Vec<u32>) -> Vec<(u64, u64)> {
    lost.sort_unstable();
    let mut out: Vec<(u64, u64)> = Vec::new();
    for s in lost {
        match out.last_mut() {
            Some(r) if r.1 + 1 == u64::from(s) => r.1 += 1,
            _ => out.push((u64::from(s), u64::from(s))),
        }
    }
    out
}

/// Parses a capture CSV: comments and rows.
fn read_csv(path: &Path) -> (BTreeMap<String, String>, Vec<[f64; 4]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut meta = BTreeMap::new();
    let mut rows = Vec::new();
    let mut header_seen = false;
    for line in text.lines() {
        if let Some(c) = line.strip_prefix("# ") {
            let (k, v) = c.split_once('=').unwrap();
            meta.insert(k.to_string(), v.to_string());
        } else if !header_seen {
            assert_eq!(line, "t,theta_ref,u,theta_m");
            header_seen = true;
        } else {
            let v: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
            rows.push([v[0], v[1], v[2], v[3]]);
        }
    }
    (meta, rows)
}

/// Checks that the CSV rows are exactly the synthesised samples whose seq is not in `lost`.
/// `jointid export <jcap> --csv <csv>` must succeed; the CSV read back
fn export_csv(jcap: &Path, csv: &Path) -> (BTreeMap<String, String>, Vec<[f64; 4]>) {
    let e = jointid(&[
        "export",
        jcap.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    read_csv(csv)
}

fn assert_rows_match(s: &SynthStream, rows: &[[f64; 4]], lost: &[u32]) {
    let fs = f64::from(s.header.sample_rate_hz);
    let tq = f64::from(s.header.scale.torque_nm_per_count);
    let an = f64::from(s.header.scale.angle_rad_per_count);
    let expected: Vec<[f64; 4]> = s
        .samples
        .iter()
        .zip(&s.reference)
        .filter(|(x, _)| !lost.contains(&x.seq))
        .map(|(x, r)| {
            [
                f64::from(x.seq) / fs,
                f64::from(*r),
                f64::from(x.torque) * tq,
                f64::from(x.angle) * an,
            ]
        })
        .collect();
    assert_eq!(rows.len(), expected.len());
    for (i, (got, want)) in rows.iter().zip(&expected).enumerate() {
        assert_eq!(got, want, "row {i}");
    }
}

fn wait_until(what: &str, timeout: Duration, mut ok: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !ok() {
        assert!(t0.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn events(jcap: &Path) -> String {
    let mut p = jcap.as_os_str().to_os_string();
    p.push(".events");
    std::fs::read_to_string(PathBuf::from(p)).unwrap_or_default()
}

fn file_len(p: &Path) -> u64 {
    std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
}

fn wait_exit(child: &mut Child, timeout: Duration) -> Output {
    let t0 = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            panic!("jointid capture did not stop");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut stdout = Vec::new();
    let mut stderr = Vec::new();
    use std::io::Read;
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

#[test]
fn capture_from_file_keeps_every_sample_in_order_bit_exact() {
    let dir = tmpdir("file");
    let s = small();
    let stream = dir.join("stream.bin");
    std::fs::write(&stream, &s.bytes).unwrap();
    let out = dir.join("run.jcap");
    let v = json_of(&jointid(&[
        "capture",
        "--file",
        stream.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["samples"], 400);
    assert_eq!(v["gaps"], serde_json::json!([]));
    assert_eq!(v["damaged_frames"], serde_json::json!([]));
    assert_eq!(v["overruns"], 0);
    assert_eq!(v["ended"], true);
    assert_eq!(v["reference_mismatches"], serde_json::json!([]));
    assert_eq!(v["bytes"], s.bytes.len());
    // the file is the 8-byte header and then exactly the received bytes
    let raw = std::fs::read(&out).unwrap();
    assert_eq!(&raw[..8], b"JCAP\x01\r\n\x1a");
    assert_eq!(&raw[8..], &s.bytes[..]);

    let info = json_of(&jointid(&["info", out.to_str().unwrap(), "--json"]));
    for key in [
        "samples",
        "gaps",
        "damaged_frames",
        "overruns",
        "first_seq",
        "last_seq",
        "frames",
    ] {
        assert_eq!(info[key], v[key], "{key}");
    }
    assert_eq!(info["header"]["session_id"], 7);

    let csv = dir.join("run.csv");
    let (meta, rows) = export_csv(&out, &csv);
    assert_rows_match(&s, &rows, &[]);
    let x = s.header.excitation;
    for (k, want) in [
        ("kind", "special_odd_multisine".to_string()),
        ("fs_hz", x.fs_hz.to_string()),
        ("period_samples", x.period_samples.to_string()),
        ("max_line", x.max_line.to_string()),
        ("cutoff_hz", x.cutoff_hz.to_string()),
        ("rms_rad", x.rms_rad.to_string()),
        ("seed", x.seed.to_string()),
        ("ramp_samples", x.ramp_samples.to_string()),
        ("periods", x.periods.to_string()),
        ("sample_interval_s", "0.005".to_string()),
        ("board_id", s.header.board_id.to_string()),
        ("session_id", "7".to_string()),
        ("gaps", "none".to_string()),
    ] {
        assert_eq!(meta.get(k), Some(&want), "# {k}");
    }
    // every analysis command reads the capture directly through the .jcap loader
    let mut a = json_of(&jointid(&["analyze", out.to_str().unwrap(), "--json"]));
    let mut b = json_of(&jointid(&["analyze", csv.to_str().unwrap(), "--json"]));
    for v in [&mut a, &mut b] {
        v.as_object_mut().unwrap().remove("file");
    }
    assert!(a == b, "analyze reads the .jcap as it reads its CSV export");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn capture_reports_exactly_the_injected_faults_and_keeps_every_intact_frame() {
    let dir = tmpdir("faults");
    let s = small();
    let b = batches(&s);
    // faults on batches 2 (bit flip), 6 (3 bytes dropped), 10 (garbage inside),
    // 14 (garbage without delimiter glued in front), a garbage frame of its own
    // after batch 17, and the stream cut in the middle of the last batch
    let (flip, drop, inside, glued, after, cut) =
        (b[2], b[6], b[10], b[14], b[17], *b.last().unwrap());
    let mut bytes = Vec::new();
    let mut want_damaged = Vec::new();
    let mut lost = Vec::new();
    for f in &s.frames {
        let at = bytes.len() as u64;
        let mut frame = bytes_of(&s, f).to_vec();
        let mid = frame.len() / 2;
        if *f == flip {
            frame[mid] ^= if frame[mid] ^ 0x04 != 0 { 0x04 } else { 0x01 };
            want_damaged.push((at, f.len));
        } else if *f == drop {
            frame.drain(mid..mid + 3);
            want_damaged.push((at, f.len - 3));
        } else if *f == inside {
            frame.splice(mid..mid, [0x55, 0xAA, 0x13, 0x37, 0x42]);
            want_damaged.push((at, f.len + 5));
        } else if *f == glued {
            frame.splice(0..0, [0xDE, 0xAD]);
            want_damaged.push((at, f.len + 2));
        } else if *f == cut {
            frame.truncate(6);
            want_damaged.push((at, 6));
            bytes.extend_from_slice(&frame);
            lost.extend(seqs_of(f));
            break;
        } else {
            bytes.extend_from_slice(&frame);
            if *f == after {
                want_damaged.push((bytes.len() as u64, 3));
                bytes.extend_from_slice(&[0x11, 0x22, 0x00]);
            }
            continue;
        }
        lost.extend(seqs_of(f));
        bytes.extend_from_slice(&frame);
    }
    let stream = dir.join("damaged.bin");
    std::fs::write(&stream, &bytes).unwrap();
    let out = dir.join("run.jcap");
    let v = json_of(&jointid(&[
        "capture",
        "--file",
        stream.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(damaged(&v), want_damaged);
    assert_eq!(
        v["damaged_frames"].as_array().unwrap().last().unwrap()["kind"],
        "truncated"
    );
    // the cut last batch is not known to be missing (nothing after it says so)
    let tail = seqs_of(&cut);
    let interior: Vec<u32> = lost.iter().copied().filter(|q| !tail.contains(q)).collect();
    assert_eq!(gaps(&v), ranges(interior));
    assert_eq!(v["samples"].as_u64().unwrap(), 400 - lost.len() as u64);
    assert_eq!(v["ended"], false);

    let csv = dir.join("run.csv");
    let (meta, rows) = export_csv(&out, &csv);
    assert_rows_match(&s, &rows, &lost);
    let listed: Vec<String> = gaps(&v).iter().map(|(a, b)| format!("{a}..{b}")).collect();
    assert_eq!(meta["gaps"], listed.join(";"));
    assert_eq!(meta["damaged_frames"], want_damaged.len().to_string());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn capture_killed_midway_leaves_a_file_read_up_to_its_last_whole_frame() {
    let dir = tmpdir("sigkill");
    let s = small();
    let fifo = dir.join("board.fifo");
    mkfifo(&fifo);
    let out = dir.join("run.jcap");
    let mut child = spawn_file_capture(&[], &fifo, &out, &[], Stdio::null);
    // send everything up to the middle of batch 15, then nothing more
    let b = batches(&s);
    let cut_frame = b[15];
    let cut = (cut_frame.offset + 4) as usize;
    let mut w = OpenOptions::new().write(true).open(&fifo).unwrap();
    w.write_all(&s.bytes[..cut]).unwrap();
    w.flush().unwrap();
    // the flush policy hands the bytes to the OS within ~75 ms, without any stop
    wait_until("the bytes on disk", Duration::from_secs(5), || {
        file_len(&out) == 8 + cut as u64
    });
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    drop(w);
    assert!(
        !events(&out).contains("\"stop\""),
        "a killed capture logs no stop"
    );

    let v = json_of(&jointid(&["info", out.to_str().unwrap(), "--json"]));
    let whole: u32 = b[..15].iter().map(|f| seqs_of(f).len() as u32).sum();
    assert_eq!(v["samples"].as_u64().unwrap(), u64::from(whole));
    assert_eq!(v["last_seq"].as_u64().unwrap(), u64::from(whole - 1));
    assert_eq!(damaged(&v), vec![(cut_frame.offset, 4)]);
    assert_eq!(v["damaged_frames"][0]["kind"], "truncated");
    assert_eq!(v["gaps"], serde_json::json!([]));

    let csv = dir.join("run.csv");
    let (_, rows) = export_csv(&out, &csv);
    let lost: Vec<u32> = (whole..400).collect();
    assert_rows_match(&s, &rows, &lost);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A socat pty pair: bytes written to `a` come out of `b`.
struct Socat {
    child: Child,
    a: PathBuf,
    b: PathBuf,
}

impl Socat {
    fn start(dir: &Path) -> Self {
        let (a, b) = (dir.join("ttyA"), dir.join("ttyB"));
        let child = Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("socat is installed");
        wait_until("socat's ptys", Duration::from_secs(5), || {
            a.exists() && b.exists()
        });
        Self { child, a, b }
    }

    /// Ends socat the way an unplugged adapter ends: its ptys hang up and vanish.
    fn unplug(mut self) {
        let _ = Command::new("kill")
            .arg(self.child.id().to_string())
            .status();
        let _ = self.child.wait();
        wait_until("the ptys to vanish", Duration::from_secs(5), || {
            !self.b.exists()
        });
    }
}

impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// creates the named pipe that stands in for the board's byte stream
fn mkfifo(path: &Path) {
    assert!(Command::new("mkfifo").arg(path).status().unwrap().success());
}

/// starts `jointid [global] capture --file <fifo> --out <out> [extra]` with stdout and
/// stderr both set to `stdio()`
fn spawn_file_capture(
    global: &[&str],
    fifo: &Path,
    out: &Path,
    extra: &[&str],
    stdio: fn() -> Stdio,
) -> Child {
    Command::new(BIN)
        .args(global)
        .args([
            "capture",
            "--file",
            fifo.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .stdout(stdio())
        .stderr(stdio())
        .spawn()
        .unwrap()
}

fn spawn_serial_capture(port: &Path, out: &Path) -> Child {
    Command::new(BIN)
        .args([
            "capture",
            "--serial",
            port.to_str().unwrap(),
            "--baud",
            "921600",
            "--out",
            out.to_str().unwrap(),
            "--json",
            "--duration",
            "30",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn capture_from_serial_pty_keeps_every_sample_in_order_bit_exact() {
    let dir = tmpdir("serial");
    let s = small();
    let socat = Socat::start(&dir);
    let out = dir.join("run.jcap");
    let mut child = spawn_serial_capture(&socat.b, &out);
    wait_until(
        "the capture to open the port",
        Duration::from_secs(5),
        || events(&out).contains("\"start\""),
    );
    let mut a = OpenOptions::new().write(true).open(&socat.a).unwrap();
    for chunk in s.bytes.chunks(97) {
        a.write_all(chunk).unwrap();
    }
    let v = json_of(&wait_exit(&mut child, Duration::from_secs(20)));
    assert_eq!(v["stop"], "board sent end of session");
    assert_eq!(v["samples"], 400);
    assert_eq!(v["gaps"], serde_json::json!([]));
    assert_eq!(v["damaged_frames"], serde_json::json!([]));
    assert_eq!(&std::fs::read(&out).unwrap()[8..], &s.bytes[..]);
    let csv = dir.join("run.csv");
    assert_rows_match(&s, &export_csv(&out, &csv).1, &[]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn capture_survives_the_serial_device_vanishing_and_records_the_gap() {
    let dir = tmpdir("replug");
    let s = small();
    let b = batches(&s);
    let (x, y) = (b[8], b[12]);
    // the cable is pulled 5 bytes into batch 8 and plugged back 2 bytes into batch 12
    let (cut1, cut2) = ((x.offset + 5) as usize, (y.offset + 2) as usize);
    let socat = Socat::start(&dir);
    let port = socat.b.clone();
    let out = dir.join("run.jcap");
    let mut child = spawn_serial_capture(&port, &out);
    wait_until(
        "the capture to open the port",
        Duration::from_secs(5),
        || events(&out).contains("\"start\""),
    );
    let mut a = OpenOptions::new().write(true).open(&socat.a).unwrap();
    a.write_all(&s.bytes[..cut1]).unwrap();
    wait_until("part 1 on disk", Duration::from_secs(5), || {
        file_len(&out) == 8 + cut1 as u64
    });
    drop(a);
    socat.unplug();
    wait_until("link lost", Duration::from_secs(5), || {
        events(&out).contains("link_lost")
    });
    let socat = Socat::start(&dir);
    wait_until("link resumed", Duration::from_secs(10), || {
        events(&out).contains("link_resumed")
    });
    let mut a = OpenOptions::new().write(true).open(&socat.a).unwrap();
    a.write_all(&s.bytes[cut2..]).unwrap();
    let v = json_of(&wait_exit(&mut child, Duration::from_secs(20)));

    // the file kept part 1 and part 2, back to back, exactly as received
    let mut want = s.bytes[..cut1].to_vec();
    want.extend_from_slice(&s.bytes[cut2..]);
    assert_eq!(&std::fs::read(&out).unwrap()[8..], &want[..]);
    // the frame cut by the loss is truncated; the one cut by the return is damaged
    assert_eq!(damaged(&v), vec![(x.offset, 5), (cut1 as u64, y.len - 2)]);
    assert_eq!(v["damaged_frames"][0]["kind"], "truncated");
    assert_eq!(
        gaps(&v),
        vec![(u64::from(seqs_of(&x).start), u64::from(seqs_of(&y).end - 1))]
    );
    let lost = (seqs_of(&y).end - seqs_of(&x).start) as u64;
    assert_eq!(v["samples"].as_u64().unwrap(), 400 - lost);
    let kinds: Vec<&str> = v["link_events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["event"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["start", "link_lost", "link_resumed", "stop"]);
    assert_eq!(v["link_events"][1]["offset"], cut1);
    // `info` reads the same from the file and its sidecar
    let info = json_of(&jointid(&["info", out.to_str().unwrap(), "--json"]));
    assert_eq!(info["damaged_frames"], v["damaged_frames"]);
    assert_eq!(info["gaps"], v["gaps"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs a capture that must fail at setup: exit 2, one line naming `names`, no file.
fn assert_setup_error(args: &[&str], out: &Path, names: &str) {
    let o = jointid(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(
        err.starts_with("jointid: error: ") && err.contains(names),
        "{err} should name {names}"
    );
    assert!(!out.exists(), "{} left behind", out.display());
    let mut ev = out.as_os_str().to_os_string();
    ev.push(".events");
    assert!(!PathBuf::from(ev).exists());
}

#[test]
fn capture_setup_errors_exit_2_with_one_line_and_leave_no_file() {
    let dir = tmpdir("errors");
    let out = dir.join("run.jcap");
    let o = out.to_str().unwrap();
    assert_setup_error(
        &["capture", "--serial", "/dev/ttyNOSUCH9", "--out", o],
        &out,
        "serial port /dev/ttyNOSUCH9: no such file or directory",
    );
    assert_setup_error(
        &["capture", "--can", "nosuchcan7", "--out", o],
        &out,
        "can interface nosuchcan7: no such interface",
    );
    assert_setup_error(
        &[
            "capture",
            "--file",
            dir.join("missing.bin").to_str().unwrap(),
            "--out",
            o,
        ],
        &out,
        "missing.bin: no such file or directory",
    );
    // --tcp-listen on an address another program holds
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = held.local_addr().unwrap().to_string();
    assert_setup_error(
        &["capture", "--tcp-listen", &addr, "--out", o],
        &out,
        &format!("tcp {addr}: address already in use"),
    );
    drop(held);
    let unwritable = dir.join("no/such/dir/run.jcap");
    assert_setup_error(
        &[
            "capture",
            "--file",
            "/dev/null",
            "--out",
            unwritable.to_str().unwrap(),
        ],
        &unwritable,
        "no/such/dir/run.jcap: no such file or directory",
    );
    // with --json the error is a JSON object on stdout, still exit 2, still no file
    let j = jointid(&[
        "--json",
        "capture",
        "--serial",
        "/dev/ttyNOSUCH9",
        "--out",
        o,
    ]);
    assert_eq!(j.status.code(), Some(2));
    let v: Value = serde_json::from_slice(&j.stdout).unwrap();
    assert_eq!(
        v["error"],
        "serial port /dev/ttyNOSUCH9: no such file or directory"
    );
    assert!(!out.exists());
    // a refused TCP connection (port 1 on loopback has no listener)
    assert_setup_error(
        &["capture", "--tcp", "127.0.0.1:1", "--out", o],
        &out,
        "tcp 127.0.0.1:1",
    );
    // an existing capture is never replaced without --force
    std::fs::write(&out, b"precious").unwrap();
    let r = jointid(&["capture", "--file", "/dev/null", "--out", o]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("already exists"));
    assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    // not even with --force when the output is the input
    let r = jointid(&["capture", "--file", o, "--out", o, "--force"]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("is both the input and the output"));
    assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_and_export_name_the_problem_of_a_bad_capture_file() {
    let dir = tmpdir("badfile");
    // a file is read by its content: a capture CSV without rows is one, named so; a
    // capture of another version is refused at its version byte
    let p = dir.join("not.jcap");
    std::fs::write(&p, b"t,theta_ref,u,theta_m\n").unwrap();
    let o = jointid(&["info", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not.jcap: 0 data rows"), "{err}");
    std::fs::write(&p, b"JCAP\x02\r\n\x1a").unwrap();
    let o = jointid(&["info", p.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("not.jcap: unsupported jcap version 2 at byte 4"),
        "{err}"
    );
    // a capture with no session header cannot be exported, and says why
    let s = small();
    let headless = dir.join("headless.jcap");
    let mut bytes = b"JCAP\x01\r\n\x1a".to_vec();
    bytes.extend_from_slice(&s.bytes[s.frames[0].len as usize..]);
    std::fs::write(&headless, bytes).unwrap();
    let csv = dir.join("x.csv");
    let o = jointid(&[
        "export",
        headless.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no session header"));
    assert!(!csv.exists());
    // info still describes it
    let v = json_of(&jointid(&["info", headless.to_str().unwrap(), "--json"]));
    assert_eq!(v["samples_without_header"], 400);
    assert_eq!(v["header"], Value::Null);
    // and the analysis commands refuse it through the .jcap loader, naming why
    let o = jointid(&["analyze", headless.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no session header"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `info` on every input the analysis commands read, not only a `.jcap` (it said "not a
/// jcap file (bad magic at byte 0)" of all of them): a capture CSV (samples, rate,
/// excitation from its comments, segments), the same on standard input, a `.jcap` on
/// standard input, a MAT-file, a CSV with a column mapping and a gap (two segments, the
/// samples missing, `--strict` exits 1), and a CSV without capture columns and without a
/// mapping (its columns and rows, and the flags that read it). `--session` is a capture's.
#[test]
fn info_describes_every_input_the_analysis_commands_read() {
    let dir = tmpdir("info-data");
    let p = |name: &str| dir.join(name).display().to_string();
    json_of(&jointid(&[
        "simulate",
        "--model",
        "two-mass",
        "--periods",
        "2",
        "--out",
        &p("run.jcap"),
        "--json",
    ]));
    json_of(&jointid(&[
        "export",
        &p("run.jcap"),
        "--csv",
        &p("run.csv"),
        "--mat",
        &p("run.mat"),
        "--json",
    ]));
    let text = |args: &[&str], stdin: Option<&str>| -> (Option<i32>, String) {
        let mut cmd = Command::new(BIN);
        cmd.args(args);
        if let Some(f) = stdin {
            cmd.stdin(std::fs::File::open(f).unwrap());
        }
        let o = cmd.output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).into_owned() + &err,
        )
    };
    for (args, stdin, format) in [
        (vec!["info", &p("run.csv")], None, "capture CSV"),
        (vec!["info", "-"], Some(p("run.csv")), "capture CSV"),
        (vec!["info", &p("run.mat")], None, "MATLAB file (v5)"),
    ] {
        let (code, out) = text(&args, stdin.as_deref());
        assert_eq!(code, Some(0), "{args:?}: {out}");
        for want in [
            format!("format      {format}"),
            "samples     14000 at 2000 Hz".to_string(),
            "excitation  special_odd_multisine fs=2000 Hz N=5000".to_string(),
            "segments    1 gap-free".to_string(),
            "14000 samples, 2 whole periods".to_string(),
        ] {
            assert!(out.contains(&want), "{args:?}: no `{want}` in {out}");
        }
    }
    let (code, out) = text(&["info", "-"], Some(&p("run.jcap")));
    assert_eq!(code, Some(0), "{out}");
    assert!(out.starts_with("standard input\nboard "), "{out}");
    // a mapped CSV with a gap of 3 samples after its 5th row
    let mut csv = String::from("time;force;pos\n");
    for k in (0..12).filter(|k| !(5..8).contains(k)) {
        csv.push_str(&format!("{};{};{}\n", f64::from(k) * 0.01, k % 3, k));
    }
    std::fs::write(p("mapped.csv"), csv).unwrap();
    let mapped = ["--time", "time", "--input", "force", "--output", "pos"];
    let mapped_csv = p("mapped.csv");
    let mut args = vec!["info", mapped_csv.as_str()];
    args.extend(mapped);
    let (code, out) = text(&args, None);
    assert_eq!(code, Some(0), "{out}");
    for want in [
        "format      CSV",
        "columns     time, force, pos",
        "read        time time, input force, output pos, reference none",
        "samples     9 at 100 Hz",
        "with 1 gap(s), 3 samples missing",
        "excitation  not stated",
        "segments    2 gap-free",
    ] {
        assert!(out.contains(want), "no `{want}` in {out}");
    }
    args.push("--strict");
    assert_eq!(text(&args, None).0, Some(1));
    let v = json_of(&jointid(&[
        "info",
        &p("mapped.csv"),
        "--time",
        "time",
        "--input",
        "force",
        "--output",
        "pos",
        "--json",
    ]));
    assert_eq!(v["missing_samples"], 3, "{v}");
    assert_eq!(v["segments"].as_array().unwrap().len(), 2, "{v}");
    // without the mapping: its columns and rows, and how to read it
    let (code, out) = text(&["info", &p("mapped.csv")], None);
    assert_eq!(code, Some(0), "{out}");
    assert!(
        out.contains("columns     time, force, pos")
            && out.contains("rows        9")
            && out.contains("--time COL --input COL --output COL"),
        "{out}"
    );
    let (code, out) = text(&["info", &p("run.csv"), "--session", "2"], None);
    assert_eq!(code, Some(2), "{out}");
    assert!(out.contains("only a capture has sessions"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn capture_stops_by_itself_after_the_requested_periods_or_duration() {
    let dir = tmpdir("stops");
    let s = small();
    let x = s.header.excitation;
    // --periods 2: seq ramp + 2N - 1 = 249 ends the capture while the pipe stays open
    let fifo = dir.join("board.fifo");
    mkfifo(&fifo);
    let out = dir.join("periods.jcap");
    let mut child = spawn_file_capture(
        &[],
        &fifo,
        &out,
        &["--periods", "2", "--json"],
        Stdio::piped,
    );
    let target = x.ramp_samples + 2 * x.period_samples - 1;
    let last = batches(&s)
        .into_iter()
        .find(|f| seqs_of(f).contains(&target))
        .unwrap();
    let mut w = OpenOptions::new().write(true).open(&fifo).unwrap();
    w.write_all(&s.bytes[..(last.offset + last.len) as usize])
        .unwrap();
    let v = json_of(&wait_exit(&mut child, Duration::from_secs(10)));
    drop(w);
    assert_eq!(v["stop"], "requested periods received");
    assert_eq!(
        v["last_seq"].as_u64().unwrap(),
        u64::from(seqs_of(&last).end - 1)
    );
    assert!(v["last_seq"].as_u64().unwrap() >= u64::from(target));

    // --duration 0.4 on a silent pipe: a valid, empty capture and a stop event
    let fifo2 = dir.join("silent.fifo");
    mkfifo(&fifo2);
    let out2 = dir.join("silent.jcap");
    let t0 = Instant::now();
    let v = json_of(&jointid(&[
        "capture",
        "--file",
        fifo2.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
        "--duration",
        "0.4",
        "--json",
    ]));
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(400) && took < Duration::from_secs(5),
        "{took:?}"
    );
    assert_eq!(v["stop"], "duration reached");
    assert_eq!(v["samples"], 0);
    assert_eq!(std::fs::read(&out2).unwrap(), b"JCAP\x01\r\n\x1a");
    assert!(events(&out2).contains("\"stop\""));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 13 item 3: a recorded stream read from a regular file arrives in large chunks;
/// `--periods N` must still end the capture at the frame that completes the N-th whole
/// period after the ramp, keep nothing after it and leave no truncated frame.
#[test]
fn capture_periods_from_a_regular_file_ends_at_the_frame_completing_the_last_period() {
    let dir = tmpdir("periods-file");
    let s = small();
    let x = s.header.excitation;
    let stream = dir.join("stream.bin");
    std::fs::write(&stream, &s.bytes).unwrap();
    for n in [1u32, 2] {
        let out = dir.join(format!("p{n}.jcap"));
        let o = jointid(&[
            "capture",
            "--file",
            stream.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--periods",
            &n.to_string(),
            "--strict",
            "--json",
        ]);
        let v = json_of(&o);
        let target = x.ramp_samples + n * x.period_samples - 1;
        let last = batches(&s)
            .into_iter()
            .find(|f| seqs_of(f).contains(&target))
            .unwrap();
        assert_eq!(v["stop"], "requested periods received");
        assert_eq!(
            v["last_seq"].as_u64(),
            Some(u64::from(seqs_of(&last).end - 1))
        );
        assert_eq!(v["samples"].as_u64(), Some(u64::from(seqs_of(&last).end)));
        assert_eq!(v["damaged_frames"], serde_json::json!([]));
        let end = (last.offset + last.len) as usize;
        assert_eq!(v["bytes"].as_u64(), Some(end as u64));
        let raw = std::fs::read(&out).unwrap();
        assert_eq!(&raw[8..], &s.bytes[..end], "cut at the end of that frame");
        let info = jointid(&["info", out.to_str().unwrap(), "--strict", "--json"]);
        assert_eq!(
            info.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&info.stdout)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 13 item 4: a capture holding two sessions (the board restarted with another
/// excitation); `export --session K` writes session K, `info` reports every session and
/// `info --session K` that one.
#[test]
fn export_and_info_serve_every_session_of_a_capture() {
    let dir = tmpdir("sessions");
    let s = small();
    let mut second = SynthOptions::small();
    second.session_id = 8;
    second.samples = 300;
    second.excitation.seed = 43;
    let t = synth_stream(&second);
    let jcap = dir.join("two.jcap");
    let mut bytes = b"JCAP\x01\r\n\x1a".to_vec();
    bytes.extend_from_slice(&s.bytes);
    bytes.extend_from_slice(&t.bytes);
    std::fs::write(&jcap, &bytes).unwrap();
    let j = jcap.to_str().unwrap();

    // export: the first session by default (with a note naming the others), any by id
    let csv7 = dir.join("s7.csv");
    let e = jointid(&["export", j, "--csv", csv7.to_str().unwrap()]);
    assert_eq!(
        e.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&e.stderr)
    );
    let note = String::from_utf8_lossy(&e.stderr);
    assert!(
        note.contains("2 sessions") && note.contains("--session"),
        "{note}"
    );
    let (meta, rows) = read_csv(&csv7);
    assert_eq!(meta["session_id"], "7");
    assert_rows_match(&s, &rows, &[]);
    let csv8 = dir.join("s8.csv");
    let e = jointid(&[
        "export",
        j,
        "--session",
        "8",
        "--csv",
        csv8.to_str().unwrap(),
        "--strict",
    ]);
    assert_eq!(
        e.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&e.stderr)
    );
    let (meta, rows) = read_csv(&csv8);
    assert_eq!(meta["session_id"], "8");
    assert_eq!(meta["seed"], "43");
    assert_rows_match(&t, &rows, &[]);
    // a session that is not there: exit 2, naming it and the ones there are, no CSV
    let csv9 = dir.join("s9.csv");
    let e = jointid(&[
        "export",
        j,
        "--session",
        "9",
        "--csv",
        csv9.to_str().unwrap(),
    ]);
    assert_eq!(e.status.code(), Some(2));
    let msg = String::from_utf8_lossy(&e.stderr);
    assert!(msg.contains("session 9") && msg.contains("7, 8"), "{msg}");
    assert!(!csv9.exists());

    // info: every session with its header and its own report
    let v = json_of(&jointid(&["info", j, "--json"]));
    let per = v["per_session"].as_array().expect("per_session");
    assert_eq!(per.len(), 2);
    for (p, (id, n, seed)) in per.iter().zip([(7, 400, 42), (8, 300, 43)]) {
        assert_eq!(p["session_id"], id);
        assert_eq!(p["header"]["session_id"], id);
        assert_eq!(p["header"]["excitation"]["seed"], seed);
        assert_eq!(p["samples"], n);
        assert_eq!(p["last_seq"], n - 1);
        assert_eq!(p["gaps"], serde_json::json!([]));
        assert_eq!(p["ended"], true);
    }
    let v = json_of(&jointid(&["info", j, "--session", "8", "--json"]));
    assert_eq!(v["session_id"], 8);
    assert_eq!(v["header"]["session_id"], 8);
    assert_eq!(v["samples"], 300);
    assert_eq!(v["per_session"].as_array().map(Vec::len), Some(1));
    let text = jointid(&["info", j]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains("session 7") && text.contains("session 8"),
        "{text}"
    );
    let e = jointid(&["info", j, "--session", "9"]);
    assert_eq!(e.status.code(), Some(2));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn capture_stops_cleanly_on_ctrl_c_with_the_summary_and_a_complete_file() {
    let dir = tmpdir("sigint");
    let s = small();
    let fifo = dir.join("board.fifo");
    mkfifo(&fifo);
    let out = dir.join("run.jcap");
    let mut child = spawn_file_capture(&["--json"], &fifo, &out, &[], Stdio::piped);
    let half = batches(&s)[12];
    let cut = (half.offset + half.len) as usize;
    let mut w = OpenOptions::new().write(true).open(&fifo).unwrap();
    w.write_all(&s.bytes[..cut]).unwrap();
    wait_until("the bytes on disk", Duration::from_secs(5), || {
        file_len(&out) == 8 + cut as u64
    });
    let int = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(int.success());
    let v = json_of(&wait_exit(&mut child, Duration::from_secs(10)));
    drop(w);
    assert_eq!(v["stop"], "interrupted");
    let whole: u32 = batches(&s)[..13]
        .iter()
        .map(|f| seqs_of(f).len() as u32)
        .sum();
    assert_eq!(v["samples"].as_u64().unwrap(), u64::from(whole));
    assert_eq!(v["damaged_frames"], serde_json::json!([]));
    assert!(events(&out).contains("\"detail\":\"interrupted\""));
    assert_eq!(&std::fs::read(&out).unwrap()[8..], &s.bytes[..cut]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 37 item 1: a second capture into a file another capture is writing (both with
/// `--force`) is refused before it truncates anything, naming the file and the lock; the
/// first capture keeps every byte it receives, before and after the refused attempt.
#[test]
fn a_second_capture_into_a_file_being_captured_is_refused_and_the_first_loses_nothing() {
    let dir = tmpdir("locked");
    let s = small();
    let fifo = dir.join("board.fifo");
    mkfifo(&fifo);
    let out = dir.join("c.jcap");
    let mut first = spawn_file_capture(&["--json"], &fifo, &out, &["--force"], Stdio::piped);
    let half = batches(&s)[12];
    let cut = (half.offset + half.len) as usize;
    let mut w = OpenOptions::new().write(true).open(&fifo).unwrap();
    w.write_all(&s.bytes[..cut]).unwrap();
    wait_until("the first half on disk", Duration::from_secs(5), || {
        file_len(&out) == 8 + cut as u64
    });
    // the second capture reads a recorded stream of its own into the same file
    let other = dir.join("other.bin");
    std::fs::write(&other, &s.bytes).unwrap();
    let second = jointid(&[
        "capture",
        "--file",
        other.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--force",
    ]);
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "stderr: {err}");
    assert_eq!(
        err.trim_end(),
        format!(
            "jointid: error: {}: another capture is writing this file (it holds the file's \
             lock); stop it first or choose another --out",
            out.display()
        )
    );
    assert_eq!(file_len(&out), 8 + cut as u64, "the refused capture wrote");
    // nor does any other writer replace it (a variant of item 1): `simulate --out c.jcap
    // --force` renamed its file over the capture's, which wrote on into the lost file and
    // exited 0
    let o = out.to_str().unwrap();
    for args in [
        vec![
            "simulate",
            "--model",
            "two-mass",
            "--periods",
            "1",
            "--out",
            o,
            "--force",
        ],
        vec!["export", other.to_str().unwrap(), "--csv", o, "--force"],
    ] {
        let r = jointid(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(
            err.trim_end(),
            format!(
                "jointid: error: {o}: a capture is writing this file (it holds the file's \
                 lock); stop it first or choose another output"
            ),
            "{args:?}"
        );
        assert_eq!(
            file_len(&out),
            8 + cut as u64,
            "{args:?} touched the capture"
        );
    }
    w.write_all(&s.bytes[cut..]).unwrap();
    drop(w);
    let v = json_of(&wait_exit(&mut first, Duration::from_secs(10)));
    assert_eq!(v["samples"].as_u64().unwrap(), s.samples.len() as u64);
    assert_eq!(&std::fs::read(&out).unwrap()[8..], &s.bytes[..]);
    // once the first capture has stopped, the file may be replaced again
    json_of(&jointid(&[
        "capture",
        "--file",
        other.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--force",
        "--json",
    ]));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn export_refuses_a_capture_whose_scale_makes_samples_not_finite() {
    use jointid::sim::board::{encode_stream, StreamLayout};
    use jointid_core::wire::{RawSample, Scale, SessionHeader, PROTOCOL_VERSION};
    let dir = tmpdir("inf-scale");
    let excitation = SynthOptions::small().excitation;
    let header = SessionHeader {
        protocol_version: PROTOCOL_VERSION,
        board_id: 1,
        session_id: 2,
        sample_rate_hz: excitation.fs_hz,
        timer_hz: 1_000_000,
        excitation,
        scale: Scale {
            torque_nm_per_count: 1e-3,
            angle_rad_per_count: f32::INFINITY,
        },
    };
    let r = jointid_core::excitation::generate(&excitation).unwrap();
    let samples = r.iter().enumerate().map(|(k, &r)| {
        (
            RawSample {
                seq: k as u32,
                tick: 5000 * k as u32,
                torque: 1,
                angle: 1,
            },
            r,
        )
    });
    let layout = StreamLayout {
        batch_len: 16,
        status_every: 4,
        overruns: 0,
        end: true,
        header_every: 0,
    };
    let stream = encode_stream(&header, samples, 5000, &layout).unwrap();
    let jcap = dir.join("inf.jcap");
    jointid::capture::jcap::write_stream(&jcap, &stream.bytes, false).unwrap();
    let csv = dir.join("inf.csv");
    let o = jointid(&[
        "export",
        jcap.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(csv.to_str().unwrap()), "{err}");
    assert!(
        err.contains("data row 1 (sample 0): theta_m = inf is not a finite number"),
        "{err}"
    );
    assert!(!csv.exists());
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        1,
        "only the capture"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The rows of a capture CSV keyed by their time `t` [s] as bits (exact match).
fn rows_by_t(rows: &[[f64; 4]]) -> BTreeMap<u64, [f64; 4]> {
    rows.iter().map(|r| (r[0].to_bits(), *r)).collect()
}

/// Issue 13 item 1: a capture that starts after the board's first session header
/// (`tail -c +9 run.jcap | tail -c +20000 > late.raw`) keeps every sample after the cut,
/// scaled with the header the board repeats, and exports exactly the rows of the whole
/// run for those samples; the `.jcap` replayed through `capture --file` (magic included)
/// reads as the original.
#[test]
fn r13_late_start_capture_scales_every_sample_after_the_cut() {
    let dir = tmpdir("late");
    let run = dir.join("run.jcap");
    let o = jointid(&["simulate", "--periods", "2", "--out", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, full) = export_csv(&run, &dir.join("run.csv"));
    let full = rows_by_t(&full);
    let bytes = std::fs::read(&run).unwrap();
    // `tail -c +9 | tail -c +20000`: drop the 8-byte magic, then 19,999 stream bytes
    let late_raw = dir.join("late.raw");
    std::fs::write(&late_raw, &bytes[8 + 19_999..]).unwrap();
    let late = dir.join("late.jcap");
    let v = json_of(&jointid(&[
        "capture",
        "--file",
        late_raw.to_str().unwrap(),
        "--out",
        late.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["samples_without_header"], 0, "{v}");
    let samples = v["samples"].as_u64().unwrap();
    let first = v["first_seq"].as_u64().unwrap();
    assert!(first > 0 && samples > 0, "{v}");
    // the cut loses one frame at most; everything after it is kept
    assert_eq!(first + samples, full.len() as u64, "{v}");
    let (_, rows) = export_csv(&late, &dir.join("late.csv"));
    assert_eq!(rows.len() as u64, samples);
    for r in &rows {
        assert_eq!(full.get(&r[0].to_bits()), Some(r), "row at t = {}", r[0]);
    }
    // the whole .jcap, its magic included, replayed as a raw file
    let replay = dir.join("replay.jcap");
    let v = json_of(&jointid(&[
        "capture",
        "--file",
        run.to_str().unwrap(),
        "--out",
        replay.to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(v["damaged_frames"], serde_json::json!([]), "{v}");
    assert_eq!(v["samples"], full.len() as u64, "{v}");
    assert_eq!(std::fs::read(&replay).unwrap(), bytes);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 13 item 19: `capture --tcp-listen` waits for the board to connect (QEMU with
/// `-serial tcp:HOST:PORT`), records what it sends and stops at its end message.
#[test]
fn capture_tcp_listen_records_the_board_that_connects() {
    let dir = tmpdir("listen");
    let s = small();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let addr = format!("127.0.0.1:{port}");
    let out = dir.join("run.jcap");
    let mut child = Command::new(BIN)
        .args(["capture", "--tcp-listen", &addr, "--out"])
        .arg(&out)
        .arg("--json")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // listening once the port can no longer be bound (a probe connection would be taken
    // for the board)
    wait_until("the capture listens", Duration::from_secs(10), || {
        std::net::TcpListener::bind(&addr).is_err()
    });
    let mut board = std::net::TcpStream::connect(&addr).unwrap();
    board.write_all(&s.bytes).unwrap();
    let o = wait_exit(&mut child, Duration::from_secs(20));
    drop(board);
    let v = json_of(&o);
    assert_eq!(v["samples"], 400, "{v}");
    assert_eq!(v["ended"], true);
    assert_eq!(v["damaged_frames"], serde_json::json!([]));
    let raw = std::fs::read(&out).unwrap();
    assert_eq!(&raw[8..], &s.bytes[..]);
    let _ = std::fs::remove_dir_all(&dir);
}
