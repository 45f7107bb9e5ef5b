//! Simulator tests: reproducibility and configuration checks.

use super::*;

#[test]
fn runs_are_bit_reproducible_and_the_seed_changes_the_noise() {
    let r = multisine(2000, &special_odd_lines(120), 0.02, 1, 10);
    let mut cfg = SimConfig {
        effects: Effect::all_defaults(),
        ..SimConfig::default()
    };
    let a = simulate(&cfg, &r).unwrap();
    let b = simulate(&cfg, &r).unwrap();
    assert_eq!(a, b);
    cfg.seed = 2;
    let c = simulate(&cfg, &r).unwrap();
    assert_ne!(a.u, c.u);
    // noise is there and has the configured size
    let noise: Vec<f64> = a.u.iter().zip(&a.u_true).map(|(m, t)| m - t).collect();
    let std = (noise.iter().map(|v| v * v).sum::<f64>() / noise.len() as f64).sqrt();
    assert!(
        (std / cfg.sensors.u_noise_std - 1.0).abs() < 0.1,
        "u noise std {std}"
    );
    let res = cfg.sensors.angle_resolution().unwrap();
    let dev = a
        .theta_m
        .iter()
        .zip(&a.theta_m_true)
        .map(|(m, t)| (m - t).abs())
        .fold(0.0, f64::max);
    assert!(dev < 0.5 * res + 6.0 * cfg.sensors.theta_noise_std, "{dev}");
}

#[test]
fn params_json_lists_every_parameter() {
    // the asymmetric friction keys are written when given (absent, the law is symmetric)
    let effects: Vec<Effect> = Effect::all_defaults()
        .into_iter()
        .map(|e| match e {
            Effect::CoulombFriction(c) => {
                Effect::CoulombFriction(crate::model::effects::CoulombFriction {
                    fc_neg: Some(c.fc),
                    fv_neg_extra: Some(0.0),
                    ..c
                })
            }
            other => other,
        })
        .collect();
    let cfg = SimConfig {
        effects: effects.clone(),
        ..SimConfig::default()
    };
    let json = cfg.params_json().unwrap();
    for (name, _, _) in cfg.plant.params.table() {
        assert!(json.contains(&format!("\"{name}\"")), "{name} missing");
    }
    for e in effects {
        assert!(json.contains(&format!("\"effect\": \"{}\"", e.name())));
        for key in e.keys() {
            assert!(json.contains(&format!("\"{key}\"")), "{key} missing");
        }
    }
    for key in [
        "kp",
        "kv",
        "ti",
        "u_max",
        "current_loop_tau",
        "counts_per_rev",
        "seed",
        "substeps",
    ] {
        assert!(json.contains(&format!("\"{key}\"")), "{key} missing");
    }
    let back: SimConfig = serde_json::from_str(&json).unwrap();
    assert_eq!(back, cfg);
}

#[test]
fn validate_rejects_bad_parameters_and_combinations() {
    let mut cfg = SimConfig::default();
    cfg.plant.params.j_a2 = 0.0;
    let err = simulate(&cfg, &[0.0]).unwrap_err();
    assert!(err.to_string().starts_with("parameter `J_a2` = 0"), "{err}");
    let cfg = SimConfig {
        plant: Plant::new(Structure::Rigid),
        effects: vec![Effect::Backlash(Backlash::default())],
        ..SimConfig::default()
    };
    assert!(matches!(
        simulate(&cfg, &[0.0]),
        Err(SimError::NeedsGearbox { .. })
    ));
    let cfg = SimConfig {
        effects: vec![Effect::Backlash(Backlash::default()); 2],
        ..SimConfig::default()
    };
    assert!(matches!(
        simulate(&cfg, &[0.0]),
        Err(SimError::DuplicateEffect("backlash"))
    ));
    let err = simulate(&SimConfig::default(), &[0.0, f64::NAN]).unwrap_err();
    assert!(matches!(err, SimError::BadReference { index: 1, .. }));
    let cfg = SimConfig {
        effects: vec![Effect::ExtraMode(ExtraMode::default()); 5],
        ..SimConfig::default()
    };
    assert!(simulate(&cfg, &[0.0]).is_ok(), "8 bodies are allowed");
    let cfg = SimConfig {
        effects: vec![Effect::ExtraMode(ExtraMode::default()); 6],
        ..SimConfig::default()
    };
    assert!(matches!(
        simulate(&cfg, &[0.0]),
        Err(SimError::TooManyBodies { bodies: 9, .. })
    ));
}

#[test]
fn every_plant_kind_runs_and_tracks_a_slow_reference() {
    let n = 4000;
    let r: Vec<f64> = (0..n)
        .map(|i| 0.05 * (1.0 - (2.0 * PI * 0.5 * i as f64 * TS).cos()))
        .collect();
    let plants = Structure::ALL
        .map(|kind| (Plant::new(kind), vec![]))
        .into_iter()
        .chain([seed_001()]);
    for (plant, effects) in plants {
        let kind = (plant.kind, effects.len());
        let out = simulate(&ideal(plant, effects), &r).unwrap();
        let expected = if kind.1 > 0 {
            Integrator::ExponentialRk4 { substeps: 5 }
        } else {
            Integrator::ExactZoh
        };
        assert_eq!(out.integrator, expected, "{kind:?}");
        let err = rel_err(&out.theta_m_true, &r);
        assert!(err < 0.2, "{kind:?}: tracking error {err}");
    }
}
