//! `jointid simulate` as a whole, in the library: the default linear three-mass joint under
//! the paper's excitation written as a `.jcap` through `data::output`, for about 60 s, 600 s
//! and 3600 s of signal. Streamed (`sim::board::stream_session` into
//! `capture::jcap::write_stream_with`: one sample simulated, encoded and written at a time)
//! against the in-memory path in the same run (`simulate_excitation` collects the whole run,
//! `encode_session` the whole stream, `jcap::write_stream` writes it), which is what the
//! command did before it streamed. The two files must be the same bytes.
//!
//! Printed per length: seconds of signal per wall-clock second (best of three) and the peak
//! resident memory of the run (Linux: `VmHWM` of `/proc/self/status`, reset before each run
//! through `/proc/self/clear_refs`), and the ratios of the two paths.
//!
//! Run: `cargo bench -p jointid --features test-support --bench simulate_stream`.

use std::time::Instant;

use jointid::capture::jcap::{write_stream, write_stream_with};
use jointid::sim::board::{encode_session, stream_session, StreamError, WireOptions};
use jointid::sim::{simulate_excitation, SimConfig};
use jointid_core::excitation::ExcitationConfig;

/// Peak resident memory of this process since the last [`reset_peak`] [MB], if readable.
fn peak_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Resets the peak resident memory to the current (Linux ≥ 4.0); false when it cannot.
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Best of three runs of `run`: (wall [s], peak memory of the runs [MB]).
fn best_of_three(mut run: impl FnMut()) -> (f64, Option<f64>) {
    let mut best = f64::INFINITY;
    let reset = reset_peak();
    for _ in 0..3 {
        let t0 = Instant::now();
        run();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, peak_mb().filter(|_| reset))
}

fn main() {
    let cfg = SimConfig::default();
    let opts = WireOptions::for_sim(&cfg);
    let dir = std::env::temp_dir().join(format!("jointid-bench-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    println!("== jointid simulate --out RUN.jcap, default linear three-mass joint, 2 kHz");
    println!(
        "{:>9} | {:>12} {:>10} | {:>12} {:>10} | {:>7} {:>7}",
        "signal", "stream [x]", "peak [MB]", "memory [x]", "peak [MB]", "speed", "memory"
    );
    // 2.5 s periods plus 1 s ramps in and out; every streamed run first, so that the
    // allocator holds none of the in-memory runs' pages while they are measured
    let excitations = [23u32, 239, 1439].map(|periods| ExcitationConfig {
        periods,
        ..ExcitationConfig::paper_default()
    });
    let path = |i: usize, kind: &str| dir.join(format!("{kind}{i}.jcap"));
    let streamed: Vec<(f64, Option<f64>)> = (0..3)
        .map(|i| {
            best_of_three(|| {
                write_stream_with(&path(i, "s"), true, |w| {
                    match stream_session(&cfg, &excitations[i], &opts, w, |_| {}) {
                        Ok((_, bytes)) => Ok(bytes),
                        Err(StreamError::Io(e)) => Err(e),
                        Err(e) => panic!("{e}"),
                    }
                })
                .expect("streamed .jcap");
            })
        })
        .collect();
    for (i, exc) in excitations.iter().enumerate() {
        let (t_stream, m_stream) = streamed[i];
        let (t_mem, m_mem) = best_of_three(|| {
            let out = simulate_excitation(&cfg, exc).expect("valid configuration");
            let stream = encode_session(&out, exc, &opts).expect("wire stream");
            write_stream(&path(i, "c"), &stream, true).expect("collected .jcap");
        });
        let same = std::fs::read(path(i, "s")).ok() == std::fs::read(path(i, "c")).ok();
        assert!(
            same,
            "{} periods: the two paths wrote different bytes",
            exc.periods
        );
        let signal_s = exc.total_samples().expect("finite") as f64 / f64::from(exc.fs_hz);
        let mb = |m: Option<f64>| m.map_or("-".to_string(), |m| format!("{m:.1}"));
        let ratio = match (m_stream, m_mem) {
            (Some(a), Some(b)) => format!("{:.1}", b / a),
            _ => "-".to_string(),
        };
        println!(
            "{:>7.0} s | {:>12.0} {:>10} | {:>12.0} {:>10} | {:>6.2}x {:>6}x",
            signal_s,
            signal_s / t_stream,
            mb(m_stream),
            signal_s / t_mem,
            mb(m_mem),
            t_mem / t_stream,
            ratio
        );
    }
    println!("(stream/memory: signal seconds per wall second; speed and memory: in-memory over streamed)");
    let _ = std::fs::remove_dir_all(&dir);
}
