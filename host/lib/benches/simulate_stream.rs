//! `jointid simulate` as a whole, in the library, in two parts.
//!
//! **Real-time factor.** About 620 s of signal (247 periods of the paper's excitation) run
//! as the command runs it: to a `.jcap` (`sim::board::stream_session` into
//! `capture::jcap::write_stream_with`) and to a capture CSV (`sim::stream_excitation` into
//! `data::TableWriter` through `data::output::write_file`), for the default three-mass joint
//! (linear: exact ZOH, default sensors), a linear two-mass and, for comparison, the
//! three-mass with Coulomb friction (exponential RK4). The baseline of the same run is the
//! simulation alone (`sim::stream_excitation` with nothing done with its samples: plant,
//! sensors, controller); each output is printed as signal seconds per CPU second of this
//! thread (Linux `schedstat`, summed over five runs: it counts in scheduler ticks of
//! 4 ms on some kernels) and as its CPU time over the baseline's, the figure that does not
//! depend on the machine or its load. The files are written to the temporary directory.
//!
//! **Streaming and memory.** The default linear three-mass joint under the paper's
//! excitation written as a `.jcap` through `data::output`, for about 60 s, 600 s and
//! 3600 s of signal. Streamed (`sim::board::stream_session` into
//! `capture::jcap::write_stream_with`: one sample simulated, encoded and written at a time)
//! against the in-memory path in the same run (`simulate_excitation` collects the whole run,
//! `encode_session` the whole stream, `jcap::write_stream` writes it), which is what the
//! command did before it streamed. The two files must be the same bytes. Printed per
//! length: seconds of signal per wall-clock second (best of three) and the peak resident
//! memory of the run (Linux: `VmHWM` of `/proc/self/status`, reset before each run through
//! `/proc/self/clear_refs`), and the ratios of the two paths.
//!
//! Run: `cargo bench -p jointid --features test-support --bench simulate_stream` (or
//! without the feature: this bench uses no fixture).

use std::time::Instant;

use jointid::capture::jcap::{write_stream, write_stream_with};
use jointid::data::output::write_file;
use jointid::data::{capture_csv_comments, TableWriter};
use jointid::sim::board::{encode_session, stream_session, StreamError, WireOptions};
use jointid::sim::{
    parse_effects, simulate_excitation, stream_excitation, Plant, Sample, SimConfig, Structure,
};
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

/// CPU time of this thread [s] from `/proc/thread-self/schedstat` (Linux), if readable.
fn thread_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

/// Runs of each case in the real-time factor table [-].
const RUNS: usize = 5;

/// Mean CPU time of this thread over [`RUNS`] runs of `run` [s] (the wall-clock mean when
/// the CPU time cannot be read), and the peak memory of the runs [MB].
fn cpu_per_run(mut run: impl FnMut()) -> (f64, Option<f64>) {
    let reset = reset_peak();
    let (c0, t0) = (thread_cpu_s(), Instant::now());
    for _ in 0..RUNS {
        run();
    }
    let wall = t0.elapsed().as_secs_f64();
    let cpu = c0.and_then(|c0| thread_cpu_s().map(|c1| c1 - c0));
    (
        cpu.unwrap_or(wall) / RUNS as f64,
        peak_mb().filter(|_| reset),
    )
}

/// The simulation of `cfg` on `exc`, its samples dropped (the baseline).
fn simulation_alone(cfg: &SimConfig, exc: &ExcitationConfig) {
    let mut last = 0.0;
    stream_excitation(cfg, exc, |s: &Sample<'_>| {
        last = s.u;
        Ok::<(), StreamError>(())
    })
    .expect("simulation");
    std::hint::black_box(last);
}

/// `jointid simulate --out path.jcap`, as the command writes it.
fn write_jcap(cfg: &SimConfig, exc: &ExcitationConfig, path: &std::path::Path) {
    let opts = WireOptions::for_sim(cfg);
    write_stream_with(path, true, |w| {
        match stream_session(cfg, exc, &opts, w, |_| {}) {
            Ok((_, bytes)) => Ok(bytes),
            Err(StreamError::Io(e)) => Err(e),
            Err(e) => panic!("{e}"),
        }
    })
    .expect("streamed .jcap");
}

/// `jointid simulate --out path.csv`, as the command writes it.
fn write_csv(cfg: &SimConfig, exc: &ExcitationConfig, path: &std::path::Path) {
    let comments = capture_csv_comments(Some(exc), 1.0 / cfg.sample_rate_hz, &Default::default());
    write_file(path, true, |w| {
        let mut table = TableWriter::new(w, &comments)?;
        stream_excitation(cfg, exc, |s: &Sample<'_>| {
            table
                .row([s.t_s, s.theta_ref, s.u, s.theta_m])
                .map_err(StreamError::Io)
        })
        .map_err(|e| match e {
            StreamError::Io(e) => e,
            e => panic!("{e}"),
        })?;
        table.finish()
    })
    .expect("capture CSV");
}

/// The real-time factor table (see the module's doc).
fn real_time_factors(dir: &std::path::Path) {
    let exc = ExcitationConfig {
        periods: 247,
        ..ExcitationConfig::paper_default()
    };
    let signal_s = exc.total_samples().expect("finite") as f64 / f64::from(exc.fs_hz);
    let two_mass = SimConfig {
        plant: Plant::new(Structure::TwoMass),
        ..SimConfig::default()
    };
    let coulomb = SimConfig {
        effects: parse_effects(&["coulomb_friction"]).expect("known effect"),
        ..SimConfig::default()
    };
    println!(
        "== jointid simulate, {signal_s:.1} s of signal at {} Hz: signal seconds per CPU second \
         (mean of {RUNS}), CPU time over the simulation alone's, peak memory",
        exc.fs_hz
    );
    println!(
        "{:<34} | {:>9} | {:>9} {:>7} {:>6} | {:>9} {:>7} {:>6}",
        "joint", "sim [x]", ".jcap [x]", "/ sim", "[MB]", ".csv [x]", "/ sim", "[MB]"
    );
    let mb = |m: Option<f64>| m.map_or("-".to_string(), |m| format!("{m:.1}"));
    for (name, cfg) in [
        ("three-mass (default, exact ZOH)", SimConfig::default()),
        ("two-mass (exact ZOH)", two_mass),
        ("three-mass, coulomb_friction (RK4)", coulomb),
    ] {
        let (sim, _) = cpu_per_run(|| simulation_alone(&cfg, &exc));
        let (jcap, jcap_mb) = cpu_per_run(|| write_jcap(&cfg, &exc, &dir.join("rtf.jcap")));
        let (csv, csv_mb) = cpu_per_run(|| write_csv(&cfg, &exc, &dir.join("rtf.csv")));
        println!(
            "{name:<34} | {:>9.0} | {:>9.0} {:>7.2} {:>6} | {:>9.0} {:>7.2} {:>6}",
            signal_s / sim,
            signal_s / jcap,
            jcap / sim,
            mb(jcap_mb),
            signal_s / csv,
            csv / sim,
            mb(csv_mb)
        );
    }
    println!("(targets of issue 39: the whole command at 2000x or more, a linear joint at 5000x)");
}

fn main() {
    let dir = std::env::temp_dir().join(format!("jointid-bench-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    real_time_factors(&dir);
    let cfg = SimConfig::default();
    let opts = WireOptions::for_sim(&cfg);
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
