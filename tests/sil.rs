//! Software in the loop: excitation generator → closed-loop simulator → wire encoder →
//! `.jcap` → decoder → capture CSV → parsed back, compared with the simulator's own output.
//!
//! The chain is the one `jointid simulate --out RUN.jcap` runs
//! (`jointid::sim::board::encode_session`, `jointid::capture::jcap::write_stream`), with
//! the reference taken from the firmware's generator
//! (`jointid_core::excitation::Excitation`, sample by sample as the board does) and read back by `capture::read_jcap` and `data::parse_csv` as a board
//! capture is. What must come back, and how exactly:
//! - θref: bit-exact, `f64::from` of the generator's `f32` (regenerated from the session
//!   header; every batch's reference CRC must agree);
//! - u and θm: exactly the simulator's values rounded to counts of the session scale,
//!   `round(v / scale) · scale` computed here in `f64`, so at most half a count
//!   (`0.5 · scale`, times `1 + 1e-9` for the rounding of `v / scale`) from the
//!   simulator's value; the wire carries integers, so no smaller tolerance is possible;
//! - the sample interval, the excitation config, every sample once, no damaged frame, the
//!   board's `End`.
//!
//! The binary path (`jointid simulate --out x.jcap` as a process) is tested in
//! `host/cli/tests/simulate_command.rs`, where `CARGO_BIN_EXE_jointid` exists.

use std::path::PathBuf;

use jointid::capture::{export, jcap, read_jcap};
use jointid::data::{parse_csv, ColumnMap};
use jointid::sim::board::{encode_session, WireOptions};
use jointid::sim::{parse_effects, simulate_f32, Integrator, SensorConfig, SimConfig};
use jointid_core::excitation::{Excitation, ExcitationConfig, SignalKind};

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("jointid-sil-{}-{name}", std::process::id()))
}

/// The reference exactly as the board produces it: `Excitation::next` until the end.
fn board_reference(exc: &ExcitationConfig) -> Vec<f32> {
    let mut table = vec![0.0f32; exc.period_samples as usize];
    let mut gen = Excitation::new(exc, &mut table).unwrap();
    std::iter::from_fn(|| gen.next()).collect()
}

/// `v` rounded to counts of `per` and scaled back, in f64 (what the wire may carry).
fn quantised(v: f64, per: f32) -> f64 {
    (v / f64::from(per)).round() * f64::from(per)
}

/// Runs the whole chain for `cfg` and `exc`, checks what comes back, returns the
/// integrator the simulator used.
fn round_trip(name: &str, cfg: &SimConfig, exc: &ExcitationConfig) -> Integrator {
    let reference = board_reference(exc);
    assert_eq!(
        reference.len() as u64,
        exc.total_samples().unwrap(),
        "the generator ends after ramp-in, periods and ramp-out"
    );
    let sim = simulate_f32(cfg, &reference).unwrap();
    let opts = WireOptions::for_sim(cfg);
    let stream = encode_session(&sim, exc, &opts).unwrap();
    let path = temp(&format!("{name}.jcap"));
    assert_eq!(
        jcap::write_stream(&path, &stream, true).unwrap(),
        stream.len() as u64
    );
    let file = std::fs::read(&path).unwrap();
    assert_eq!(file[..8], jcap::MAGIC, "{name}: the jcap header");
    assert_eq!(
        file[8..],
        stream[..],
        "{name}: the jcap holds the stream as is"
    );

    let rec = read_jcap(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let r = &rec.report;
    assert!(r.is_clean(), "{name}: {r:?}");
    assert!(r.ended, "{name}: the End message arrived");
    assert_eq!(r.samples, sim.len() as u64);
    assert_eq!(rec.header, opts.header(exc));
    assert!(
        r.frames > sim.len() as u64 / 32,
        "{name}: batches, status, end"
    );

    let mut csv = Vec::new();
    export::write_csv(&rec, &mut csv).unwrap();
    let ds = parse_csv(
        std::str::from_utf8(&csv).unwrap(),
        "sil.csv",
        &ColumnMap::capture(),
    )
    .unwrap();
    assert_eq!(ds.excitation, Some(*exc));
    assert_eq!(ds.data.ts, sim.sample_interval_s);
    assert_eq!(ds.t0, 0.0);
    assert_eq!(ds.data.len(), sim.len());

    let back_ref = ds.data.r.as_ref().unwrap();
    for (k, &g) in reference.iter().enumerate() {
        assert_eq!(
            back_ref[k].to_bits(),
            f64::from(g).to_bits(),
            "{name}: θref[{k}]"
        );
        assert_eq!(sim.theta_ref[k].to_bits(), f64::from(g).to_bits());
    }
    let (tq, ang) = (
        opts.scale.torque_nm_per_count,
        opts.scale.angle_rad_per_count,
    );
    let half = |per: f32| 0.5 * f64::from(per) * (1.0 + 1e-9);
    let mut worst = (0.0f64, 0.0f64);
    for k in 0..sim.len() {
        assert_eq!(ds.data.u[k], quantised(sim.u[k], tq), "{name}: u[{k}]");
        assert_eq!(
            ds.data.y[k],
            quantised(sim.theta_m[k], ang),
            "{name}: θm[{k}]"
        );
        worst.0 = worst.0.max((ds.data.u[k] - sim.u[k]).abs());
        worst.1 = worst.1.max((ds.data.y[k] - sim.theta_m[k]).abs());
    }
    assert!(worst.0 <= half(tq), "{name}: u off by {:e}", worst.0);
    assert!(worst.1 <= half(ang), "{name}: θm off by {:e}", worst.1);
    // the signals are not trivially zero: the loop moved
    assert!(sim.u.iter().any(|&u| u.abs() > 1e3 * f64::from(tq)));
    sim.integrator
}

fn one_period() -> ExcitationConfig {
    ExcitationConfig {
        periods: 1,
        ..ExcitationConfig::paper_default()
    }
}

#[test]
fn sil_linear_three_mass_comes_back_from_the_wire_as_simulated() {
    let cfg = SimConfig {
        seed: 11,
        ..SimConfig::default()
    };
    let exc = one_period();
    assert_eq!(round_trip("linear", &cfg, &exc), Integrator::ExactZoh);
    // the encoder's angle counts are the simulated encoder's counts
    let res = cfg.sensors.angle_resolution().unwrap();
    assert!(
        (f64::from(WireOptions::for_sim(&cfg).scale.angle_rad_per_count) / res - 1.0).abs() < 1e-7
    );
}

#[test]
fn sil_effects_with_rk4_come_back_from_the_wire_as_simulated() {
    let cfg = SimConfig {
        effects: parse_effects(&[
            "backlash:width=3e-5",
            "coulomb_friction",
            "time_delay",
            "torque_ripple",
        ])
        .unwrap(),
        seed: 5,
        ..SimConfig::default()
    };
    let exc = ExcitationConfig {
        kind: SignalKind::RandomOddMultisine,
        seed: 77,
        ..one_period()
    };
    let integrator = round_trip("effects", &cfg, &exc);
    // the nonlinear path ran (the default is the exponential RK4 stepper)
    assert!(
        matches!(
            integrator,
            Integrator::Rk4 { .. } | Integrator::ExponentialRk4 { .. }
        ),
        "{integrator:?}"
    );
}

#[test]
fn sil_ideal_sensors_noise_excitation_comes_back_from_the_wire_as_simulated() {
    let cfg = SimConfig {
        sensors: SensorConfig::ideal(),
        ..SimConfig::default()
    };
    let exc = ExcitationConfig {
        kind: SignalKind::BandLimitedNoise,
        ..one_period()
    };
    assert_eq!(round_trip("ideal", &cfg, &exc), Integrator::ExactZoh);
}
