//! Simulator tests: the open-loop run driven by a given torque reference gives the closed
//! loop's true motor angle back when fed the closed loop's torque (ideal sensors).

use super::*;

/// Two periods of a 1 s multisine with a half-second ramp in [rad], default amplitude.
fn reference() -> Vec<f64> {
    let n = 2000;
    ramped(multisine(n, &special_odd_lines(60), 0.02, 2, 7), 1000)
}

/// Largest `|a − b|` over the run relative to the largest `|b|`.
fn rel_max(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let num = a
        .iter()
        .zip(b)
        .fold(0.0, |m: f64, (x, y)| m.max((x - y).abs()));
    let den = b.iter().fold(0.0, |m: f64, y| m.max(y.abs()));
    num / den
}

/// Runs the closed loop of `cfg`, drives the plant open loop with its recorded torque and
/// checks θ_m, the gearbox deflection and the motor velocity against the closed loop's
/// truth; returns the relative error of θ_m.
fn driven_reproduces_closed_loop(cfg: &SimConfig, what: &str) -> f64 {
    let r = reference();
    let out = simulate(cfg, &r).unwrap();
    assert_eq!(
        out.u, out.u_true,
        "{what}: ideal sensors record u as computed"
    );
    let start = DrivenStart::Rest {
        theta_m: out.theta_m_true[0],
    };
    let d = simulate_driven(
        &cfg.plant,
        &cfg.effects,
        cfg.controller.current_loop_tau,
        out.sample_interval_s,
        &out.u,
        &start,
    )
    .unwrap();
    assert_eq!(d.len(), r.len(), "{what}");
    assert_eq!(d.integrator, out.integrator, "{what}");
    assert_eq!(d.theta_m[0], r[0], "{what}: starts at the start angle");
    let err = rel_max(&d.theta_m, &out.theta_m_true);
    assert!(err <= 1e-9, "{what}: θ_m relative error {err:e}");
    let omega = out.state_series("omega_m").unwrap();
    let e_omega = rel_max(&d.omega_m, &omega);
    assert!(e_omega <= 1e-9, "{what}: ω_m relative error {e_omega:e}");
    let arm = out
        .state_series("theta_a1")
        .or_else(|| out.state_series("theta_a"))
        .unwrap();
    let r_gear = cfg.plant.params.r;
    let delta: Vec<f64> = (0..out.len())
        .map(|k| r_gear * out.theta_m_true[k] - arm[k])
        .collect();
    let e_delta = rel_max(&d.gearbox_deflection, &delta);
    // δ is a small difference of two angles: rounding of r θ_m − θ_a1 is relatively larger
    assert!(e_delta <= 1e-7, "{what}: δ relative error {e_delta:e}");
    err
}

#[test]
fn driven_by_the_closed_loop_torque_reproduces_the_true_motor_angle() {
    driven_reproduces_closed_loop(&ideal(Plant::default(), vec![]), "linear three-mass");
    let mut effects = Effect::all_defaults();
    effects.push(Effect::TimeDelay(TimeDelay { samples: 2.3 }));
    for e in effects {
        let cfg = ideal(Plant::default(), vec![e]);
        driven_reproduces_closed_loop(&cfg, &format!("three-mass with {e}"));
    }
    let (plant, effects) = seed_001();
    let cfg = ideal(plant, effects);
    driven_reproduces_closed_loop(&cfg, "nonlinear two-mass");
}

#[test]
fn driven_from_a_full_state_continues_the_closed_loop_run() {
    // Coulomb friction (stick–slip decided from the state) without delay: the state at
    // sample k0 is all there is to know
    let cfg = ideal(
        Plant::default(),
        vec![Effect::CoulombFriction(CoulombFriction::default())],
    );
    let r = reference();
    let out = simulate(&cfg, &r).unwrap();
    let k0 = 2500;
    let start = DrivenStart::State(out.state(k0).to_vec());
    let d = simulate_driven(&cfg.plant, &cfg.effects, 5e-4, TS, &out.u[k0..], &start).unwrap();
    let err = rel_max(&d.theta_m, &out.theta_m_true[k0..]);
    assert!(err <= 1e-9, "θ_m relative error {err:e}");
}

#[test]
fn driven_refuses_a_non_finite_torque_naming_its_sample() {
    let mut u = vec![0.01; 20];
    u[7] = f64::NAN;
    let plant = Plant::default();
    let err = simulate_driven(&plant, &[], 5e-4, TS, &u, &DrivenStart::default()).unwrap_err();
    assert!(
        matches!(err, SimError::BadTorque { index: 7, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("sample 7"), "{err}");
    u[7] = f64::INFINITY;
    let effects = [Effect::CoulombFriction(CoulombFriction::default())];
    let err = simulate_driven(&plant, &effects, 5e-4, TS, &u, &DrivenStart::default());
    assert!(matches!(err, Err(SimError::BadTorque { index: 7, .. })));
}

#[test]
fn driven_with_no_torque_gives_an_empty_run_after_checking_the_configuration() {
    let plant = Plant::default();
    let d = simulate_driven(&plant, &[], 5e-4, TS, &[], &DrivenStart::default()).unwrap();
    assert!(d.is_empty() && d.omega_m.is_empty() && d.gearbox_deflection.is_empty());
    assert_eq!(d.sample_interval_s, TS);
    let err = simulate_driven(&plant, &[], 0.0, TS, &[], &DrivenStart::default()).unwrap_err();
    assert!(
        matches!(err, SimError::InvalidParameter { ref name, .. } if name == "current_loop_tau"),
        "{err:?}"
    );
    let rigid = Plant::new(Structure::Rigid);
    let backlash = [Effect::Backlash(Backlash::default())];
    let err = simulate_driven(&rigid, &backlash, 5e-4, TS, &[], &DrivenStart::default());
    assert!(matches!(err, Err(SimError::NeedsGearbox { .. })));
}

#[test]
fn driven_refuses_a_start_state_that_does_not_fit_the_plant() {
    let plant = Plant::default();
    let start = DrivenStart::State(vec![0.0; 5]);
    let err = simulate_driven(&plant, &[], 5e-4, TS, &[0.0], &start).unwrap_err();
    let text = err.to_string();
    assert!(
        matches!(err, SimError::BadStart(_)) && text.contains("7 (theta_m"),
        "{text}"
    );
    let mut x = vec![0.0; 7];
    x[3] = f64::NAN;
    let err = simulate_driven(&plant, &[], 5e-4, TS, &[0.0], &DrivenStart::State(x));
    assert!(
        err.unwrap_err().to_string().contains("omega_m = NaN"),
        "names the component"
    );
}

/// The grounded mass (issue 36 item 7): under a constant torque `u` it settles at the
/// spring's static deflection `u / k_0` (no gearbox), from a start at rest away from the frame's
/// zero it swings back towards 0 (the frame stays put: its spring, not the start, sets the
/// rest angle), and its mechanism resonates at the default 5.0 Hz with no anti-resonance.
#[test]
fn the_grounded_mass_settles_at_its_static_deflection_and_swings_about_the_frame() {
    let plant = Plant::new(Structure::Grounded);
    let modal = Mechanism::new(&plant, &[]).modal_frequencies();
    assert_eq!(modal.anti_resonances_hz, Vec::<f64>::new());
    assert_eq!(modal.resonances_hz.len(), 1);
    assert!((modal.resonances_hz[0] - 5.0).abs() < 0.02, "{modal:?}");
    let p = plant.params;
    let ts = 5e-4;
    let u = vec![0.5; 40_000];
    let out = simulate_driven(&plant, &[], 5e-4, ts, &u, &DrivenStart::default()).unwrap();
    let last = *out.theta_m.last().unwrap();
    let static_angle = 0.5 / p.k_0;
    assert!(
        (last / static_angle - 1.0).abs() < 0.01,
        "{last} vs {static_angle}"
    );
    let away = simulate_driven(
        &plant,
        &[],
        5e-4,
        ts,
        &vec![0.0; 40_000],
        &DrivenStart::Rest { theta_m: 0.01 },
    )
    .unwrap();
    let end = away.theta_m[30_000..]
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(end < 1e-3 * 0.01, "still {end} rad from the frame's zero");
}
