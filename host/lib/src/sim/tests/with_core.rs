//! Simulator tests: with the firmware core: excitation and wire types.

use super::*;

#[test]
fn simulate_excitation_uses_the_core_generator_and_raw_samples_round_trip() {
    use jointid_core::excitation::ExcitationConfig;
    let mut exc = ExcitationConfig::paper_default();
    exc.periods = 1;
    exc.ramp_samples = 200;
    let cfg = SimConfig::default();
    let out = simulate_excitation(&cfg, &exc).unwrap();
    let r = jointid_core::excitation::generate(&exc).unwrap();
    assert_eq!(out.len(), r.len());
    assert!(out
        .theta_ref
        .iter()
        .zip(&r)
        .all(|(a, b)| *a == f64::from(*b)));
    let res = cfg.sensors.angle_resolution().unwrap();
    let scale = jointid_core::wire::Scale {
        torque_nm_per_count: 1e-4,
        angle_rad_per_count: res as f32,
    };
    let raw = out.to_raw_samples(&scale, 1_000_000).unwrap();
    assert_eq!(raw.len(), out.len());
    for (k, s) in raw.iter().enumerate().step_by(97) {
        assert_eq!(s.seq, k as u32);
        assert_eq!(s.tick, 500 * k as u32);
        let u = f64::from(s.torque) * 1e-4;
        assert!((u - out.u[k]).abs() <= 0.5e-4 + 1e-12, "{k}");
        let th = f64::from(s.angle) * f64::from(scale.angle_rad_per_count);
        assert!((th - out.theta_m[k]).abs() <= 0.5 * res * 1.000_001, "{k}");
    }
    let mut wrong = exc;
    wrong.fs_hz = 1000;
    assert!(matches!(
        simulate_excitation(&cfg, &wrong),
        Err(SimError::RateMismatch { .. })
    ));
    wrong = exc;
    wrong.periods = 0;
    assert!(matches!(
        simulate_excitation(&cfg, &wrong),
        Err(SimError::Excitation(_))
    ));
}

#[test]
fn all_effects_stay_bounded_on_every_geared_plant_at_large_amplitude() {
    // 10 times the default amplitude: cubic spring ~30 times stiffer at peak, backlash and
    // friction together, full sensors; the run must stay finite and keep tracking
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.2, 2, 13), 400);
    let seed_001_plant = seed_001();
    for (kind, base) in [
        (Structure::TwoMass, vec![]),
        (Structure::ThreeMass, vec![]),
        (Structure::FourMass, vec![]),
        (Structure::TwoMass, seed_001_plant.1),
    ] {
        // the defaults on top of the plant's own effects (seed 001's on the last: its
        // stiffening spring and pure Coulomb friction, then the other effects)
        let others = Effect::all_defaults()
            .into_iter()
            .filter(|e| base.iter().all(|b| b.name() != e.name()));
        let cfg = SimConfig {
            plant: Plant::new(kind),
            effects: base.iter().copied().chain(others).collect(),
            ..SimConfig::default()
        };
        let out = simulate(&cfg, &r).unwrap();
        assert!(out.states.iter().all(|v| v.is_finite()), "{kind:?}");
        assert_eq!(out.saturated_samples, 0, "{kind:?}");
        // the slow motion (0.1 s means) stays close to that of the same plant without effects
        let linear = simulate(&ideal(Plant::new(kind), vec![]), &r).unwrap();
        let lp = |x: &[f64]| -> Vec<f64> {
            x.chunks(200)
                .map(|c| c.iter().sum::<f64>() / 200.0)
                .collect()
        };
        let e = rel_err(&lp(&out.theta_m_true), &lp(&linear.theta_m_true));
        assert!(e < 0.2, "{kind:?}: {e}");
    }
}

#[test]
fn raw_samples_refuse_what_the_wire_cannot_carry_instead_of_clamping() {
    let mut exc = jointid_core::excitation::ExcitationConfig::paper_default();
    exc.periods = 1;
    let out = simulate_excitation(&SimConfig::default(), &exc).unwrap();
    let scale = jointid_core::wire::Scale {
        torque_nm_per_count: 1.0 / 1_048_576.0,
        angle_rad_per_count: 1.0 / 1_048_576.0,
    };
    assert!(out.to_raw_samples(&scale, 1_000_000).is_ok());
    let mut big = out.clone();
    big.u[7] = 1e30;
    let err = big.to_raw_samples(&scale, 1_000_000).unwrap_err();
    assert_eq!((err.index, err.signal), (7, "u"));
    assert!(
        err.to_string()
            .starts_with("sample 7: u = 1e30 N·m is outside the wire's range"),
        "{err}"
    );
    let mut nan = out.clone();
    nan.theta_m[3] = f64::NAN;
    let err = nan.to_raw_samples(&scale, 1_000_000).unwrap_err();
    assert_eq!((err.index, err.signal), (3, "theta_m"));
    // exactly the largest count still fits, one more count does not
    let mut edge = out;
    edge.u[0] = f64::from(i32::MAX) / 1_048_576.0;
    assert_eq!(
        edge.to_raw_samples(&scale, 1_000_000).unwrap()[0].torque,
        i32::MAX
    );
    edge.u[0] += 1.0 / 1_048_576.0;
    assert!(edge.to_raw_samples(&scale, 1_000_000).is_err());
}

#[test]
fn a_diverging_run_stops_with_the_first_non_finite_sample_and_the_effects() {
    let mut exc = jointid_core::excitation::ExcitationConfig::paper_default();
    exc.periods = 1;
    // `--model nonlinear-two-mass --effect nonlinear_stiffness:k3=-1e16`
    let plant = Plant::new(Structure::TwoMass);
    let spec = crate::model::params::sim_spec(
        plant.kind,
        true,
        &["nonlinear_stiffness:k3=-1e16".to_string()],
        &plant.params,
    )
    .unwrap();
    let cfg = SimConfig {
        plant,
        effects: spec.effects.unwrap(),
        ..SimConfig::default()
    };
    let err = simulate_excitation(&cfg, &exc).unwrap_err();
    let SimError::NonFinite { index, .. } = &err else {
        panic!("{err}")
    };
    assert!(
        err.to_string()
            .starts_with(&format!("simulation not finite at sample {index} (t = ")),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains("(plant two-mass, effects: coulomb_friction:fc=0.03,fs=0.03,"),
        "{err}"
    );
}

#[test]
fn the_streamed_session_is_the_bytes_of_the_collected_run_in_constant_memory() {
    use crate::sim::board::{encode_session, stream_session, StreamError, WireOptions};
    let mut exc = jointid_core::excitation::ExcitationConfig::paper_default();
    exc.periods = 1;
    // a fractional delay longer than the ring of two samples, a nonlinear plant, the
    // seed 001 two-mass; 1 period + ramps is not a multiple of the batch of 32
    let delayed = SimConfig {
        effects: parse_effects(&["time_delay:samples=3.7", "backlash:width=2e-5"]).unwrap(),
        ..SimConfig::default()
    };
    let (plant, effects) = seed_001();
    let seed_001 = SimConfig {
        plant,
        effects,
        seed: 9,
        ..SimConfig::default()
    };
    let n = exc.total_samples().unwrap() as usize;
    assert_ne!(n % 32, 0);
    for cfg in [SimConfig::default(), delayed, seed_001] {
        let out = simulate_excitation(&cfg, &exc).unwrap();
        let opts = WireOptions::for_sim(&cfg);
        let collected = encode_session(&out, &exc, &opts).unwrap();
        let mut streamed = Vec::new();
        let mut seen = Vec::new();
        let (summary, bytes) =
            stream_session(&cfg, &exc, &opts, &mut streamed, |s| seen.push(s.u)).unwrap();
        assert!(streamed == collected, "{:?}", cfg.effects);
        assert_eq!(bytes, collected.len() as u64);
        assert_eq!(seen, out.u);
        assert_eq!(summary.samples, n);
        assert_eq!(summary.saturated_samples, out.saturated_samples);
        assert_eq!(summary.integrator, out.integrator);
        // the collector over the same loop, from a slice, agrees with the generator's run
        assert_eq!(simulate(&cfg, &out.theta_ref).unwrap(), out);
    }
    // a diverging run stops the stream with the simulator's own error
    let plant = Plant::new(Structure::TwoMass);
    let cfg = SimConfig {
        plant,
        effects: parse_effects(&["nonlinear_stiffness:k3=-1e16"]).unwrap(),
        ..SimConfig::default()
    };
    let opts = WireOptions::for_sim(&cfg);
    // (its angle leaves the wire's range hundreds of samples before it is not finite)
    let err = stream_session(&cfg, &exc, &opts, &mut Vec::new(), |_| {}).unwrap_err();
    assert!(
        matches!(err, StreamError::Sim(SimError::NonFinite { .. })),
        "{err}"
    );
    // a finite run the wire cannot carry: the first such sample
    let loose = WireOptions {
        scale: jointid_core::wire::Scale {
            torque_nm_per_count: 1e-12,
            angle_rad_per_count: 1e-3,
        },
        ..WireOptions::for_sim(&SimConfig::default())
    };
    let out = simulate_excitation(&SimConfig::default(), &exc).unwrap();
    let want = out
        .to_raw_samples(&loose.scale, loose.timer_hz)
        .unwrap_err();
    let err =
        stream_session(&SimConfig::default(), &exc, &loose, &mut Vec::new(), |_| {}).unwrap_err();
    let StreamError::Wire(crate::sim::board::BoardStreamError::Range(got)) = err else {
        panic!("{err}")
    };
    assert_eq!(got, want);
}
