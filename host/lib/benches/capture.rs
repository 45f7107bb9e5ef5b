//! Capture throughput on a synthesised one-hour 2 kHz session (the paper's excitation,
//! endless, batches of 32, status every 16 batches).
//!
//! Measured, each the best of three runs:
//! - write: the received bytes into a `.jcap` through `JcapWriter` (4 KiB chunks, the
//!   default flush policy, fsync at the end);
//! - decode: bytes → `CaptureRecord` (frames, sessions, gaps, reference regenerated and
//!   CRC-checked, SI conversion) on one thread and as `read_jcap` does it (decoders in
//!   parallel on pieces cut at frame delimiters), against the baseline of the core's bare
//!   `Decoder` on one thread in the same run;
//! - export: `CaptureRecord` → capture CSV in memory, against a baseline writing the same
//!   rows with `std::fmt`;
//! - the `jointid export` path: `read_jcap` + `export_csv` from and to files.
//!
//! Figures: MB/s of stream bytes and multiples of real time (one hour = 3600 s).
//! Targets: decode ≥ 10 000× real time; one hour exported to CSV in < 5 s.
//! Run: `cargo bench -p jointid --features test-support --bench capture`.

use std::hint::black_box;
use std::io::Write;
use std::time::{Duration, Instant};

use jointid::capture::export::write_csv;
use jointid::capture::jcap::{FlushPolicy, JcapWriter};
use jointid::capture::{decode_stream, export, read_jcap, StreamAnalyzer};
use jointid::test_support::synth::{synth_stream, SynthOptions};
use jointid_core::wire::{DecodeEvent, Decoder};

/// Synthesised duration [s]: one hour, or `JOINTID_BENCH_SECONDS` (shorter runs for
/// `valgrind --tool=callgrind`, whose instruction counts do not depend on the load).
fn seconds() -> u32 {
    std::env::var("JOINTID_BENCH_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&s| s > 0)
        .unwrap_or(3600)
}

fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut best = Duration::MAX;
    let mut out = None;
    for _ in 0..n {
        let t0 = Instant::now();
        let v = f();
        best = best.min(t0.elapsed());
        out = Some(v);
    }
    (best, out.expect("n > 0"))
}

fn line(what: &str, t: Duration, bytes: usize) {
    let s = t.as_secs_f64();
    println!(
        "{what:<44} {:>9.3} s  {:>8.1} MB/s  {:>9.0}x real time",
        s,
        bytes as f64 / s / 1e6,
        f64::from(seconds()) / s
    );
}

/// The 1-minute load average (the machine is shared; figures scale with it).
fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "unknown".into())
}

fn main() {
    println!(
        "load average before: {} (cores: {})",
        load(),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let t0 = Instant::now();
    let secs = seconds();
    let s = synth_stream(&SynthOptions::paper(secs));
    let n = s.bytes.len();
    println!(
        "synthesised {secs} s at 2 kHz: {} samples, {} frames, {:.1} MB ({:.2} bytes/sample) in {:.1} s",
        s.samples.len(),
        s.frames.len(),
        n as f64 / 1e6,
        n as f64 / s.samples.len() as f64,
        t0.elapsed().as_secs_f64()
    );
    let dir = std::env::temp_dir().join(format!("jointid-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let jcap = dir.join("hour.jcap");

    let (t_write, _) = best_of(3, || {
        let _ = std::fs::remove_file(&jcap);
        let mut w = JcapWriter::create(&jcap, false, FlushPolicy::default()).expect("create");
        let now = Instant::now();
        for chunk in s.bytes.chunks(4096) {
            w.append(chunk, now).expect("append");
        }
        w.finish().expect("finish")
    });

    let (t_base, frames) = best_of(3, || {
        let mut d = Decoder::new();
        let mut frames = 0u64;
        d.feed(&s.bytes, |e| {
            if let DecodeEvent::Frame { message, .. } = e {
                black_box(&message);
                frames += 1;
            }
        });
        d.finish(|_| {});
        frames
    });
    assert_eq!(frames as usize, s.frames.len());

    let (t_seq, _) = best_of(3, || {
        let mut an = StreamAnalyzer::new(true);
        an.reserve_samples(n / 4);
        an.feed(&s.bytes);
        an.finish().expect("decodes").1.expect("has a header")
    });
    let (t_decode, record) = best_of(3, || decode_stream(&s.bytes, &[]).expect("decodes"));
    if std::env::var_os("JOINTID_BENCH_DECODE_ONLY").is_some() {
        for _ in 0..5 {
            black_box(decode_stream(&s.bytes, &[]).expect("decodes"));
        }
        return;
    }
    assert_eq!(record.samples.len(), s.samples.len());
    assert!(record.report.is_clean(), "{}", record.report);

    let (t_fmt, csv_len) = best_of(3, || {
        let mut out = Vec::with_capacity(600 << 20);
        out.write_all(export::comment_lines(&record).as_bytes())
            .expect("vec");
        out.write_all(b"t,theta_ref,u,theta_m\n").expect("vec");
        for x in &record.samples {
            writeln!(out, "{},{},{},{}", x.t, x.theta_ref, x.u, x.theta_m).expect("vec");
        }
        out.len()
    });
    let (t_csv, csv) = best_of(3, || {
        let mut out = Vec::with_capacity(600 << 20);
        write_csv(&record, &mut out).expect("vec");
        out
    });
    // both print shortest round-trip numbers (zmij picks exponent form for some values,
    // so lengths differ slightly); what matters is that every value reads back exactly
    let text = std::str::from_utf8(&csv).expect("ascii");
    for (row, x) in text
        .lines()
        .skip_while(|l| l.starts_with('#'))
        .skip(1)
        .zip(&record.samples)
    {
        let v: Vec<f64> = row.split(',').map(|c| c.parse().expect("number")).collect();
        assert_eq!(v, [x.t, x.theta_ref, x.u, x.theta_m]);
    }
    let (csv_len, fmt_len) = (csv.len(), csv_len);
    drop(csv);

    let csv_path = dir.join("hour.csv");
    let (t_cmd, rows) = best_of(3, || {
        let r = read_jcap(&jcap).expect("read");
        export::export_csv(&r, &csv_path, true).expect("export");
        r.samples.len()
    });
    assert_eq!(rows, s.samples.len());

    println!();
    line("write .jcap (JcapWriter, 4 KiB chunks)", t_write, n);
    line("decode: core Decoder alone (baseline)", t_base, n);
    line("decode: bytes -> CaptureRecord, one thread", t_seq, n);
    line("decode: bytes -> CaptureRecord (read_jcap)", t_decode, n);
    println!(
        "{:<44} {:>9.2}x the baseline's time (one thread: {:.2}x)",
        "  record / bare decoder",
        t_decode.as_secs_f64() / t_base.as_secs_f64(),
        t_seq.as_secs_f64() / t_base.as_secs_f64()
    );
    line("csv: std::fmt rows (baseline)", t_fmt, n);
    line("csv: write_csv", t_csv, n);
    println!(
        "{:<44} {:>9.2}x faster than the baseline",
        "  write_csv vs std::fmt",
        t_fmt.as_secs_f64() / t_csv.as_secs_f64()
    );
    line("jointid export path: read_jcap + export_csv", t_cmd, n);
    println!();
    let decode_x = f64::from(seconds()) / t_decode.as_secs_f64();
    println!(
        "target decode >= 10000x real time: {decode_x:.0}x ({})",
        if decode_x >= 10_000.0 {
            "met"
        } else {
            "NOT met"
        }
    );
    println!(
        "target one hour exported to CSV in < 5 s: {:.2} s ({}); CSV {:.0} MB (std::fmt: {:.0} MB)",
        t_cmd.as_secs_f64(),
        if t_cmd < Duration::from_secs(5) {
            "met"
        } else {
            "NOT met"
        },
        csv_len as f64 / 1e6,
        fmt_len as f64 / 1e6
    );
    println!("load average after: {}", load());
    let _ = std::fs::remove_dir_all(&dir);
}
