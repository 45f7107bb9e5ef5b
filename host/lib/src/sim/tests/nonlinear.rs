//! Simulator tests: the nonlinear path: seed 001 eq. (9) written out, RK4 convergence, events.

use super::*;

#[test]
fn generic_plant_rhs_equals_seed001_eq9_for_nonlinear_two_mass() {
    let (plant, effects) = seed_001();
    let cfg = ideal(plant, effects);
    let a = assemble(&cfg);
    let p = plant.params;
    let (r, d, k1, k3, fv, fc, jm, ja) = (
        p.r,
        p.d_g,
        p.k_g,
        p.k3,
        p.f_m,
        p.f_c,
        p.j_m,
        p.j_a1 + p.j_a2,
    );
    let mut rng = sensors::Rng::new(11, 0);
    for _ in 0..100 {
        // states of eq. (8): x1 = r φm − φa, x2 = φ̇m, x3 = φ̇a; |x2| well above v_ε
        let phi_m = rng.normal();
        let x1 = 1e-4 * rng.normal();
        let x2 = (0.5 + rng.uniform()) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let x3 = r * x2 + 0.01 * rng.normal();
        let u = rng.normal();
        let mut x = [0.0; crate::model::plant::MAX_STATE];
        x[0] = phi_m;
        x[1] = r * phi_m - x1;
        x[2] = x2;
        x[3] = x3;
        x[4] = u; // current-loop output = torque on the motor
        let mut dx = [0.0; crate::model::plant::MAX_STATE];
        a.nonlinear
            .rhs(&x, integrate::Contact::Pos, 0.0, 0.0, &mut dx);
        let dx1 = r * x2 - x3;
        let spring = k1 * x1 + k3 * x1.powi(3);
        let dx2 = (-fv * x2 - fc * x2.signum() - r * d * (r * x2 - x3) - r * spring + u) / jm;
        let dx3 = (d * (r * x2 - x3) + spring) / ja;
        let got_dx1 = r * dx[0] - dx[1];
        for (got, want) in [(got_dx1, dx1), (dx[2], dx2), (dx[3], dx3)] {
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1e-6),
                "{got} vs {want}"
            );
        }
    }
}

/// Configuration with every effect on (nonlinear ones and the linear delay and extra mode).
fn all_effects(substeps: u32) -> SimConfig {
    let mut cfg = ideal(Plant::default(), Effect::all_defaults());
    cfg.integration.substeps = substeps;
    cfg
}

/// Relative 2-norm differences `(θ_m, u, gearbox deflection)` of two runs.
fn run_differences(a: &SimOutput, b: &SimOutput) -> (f64, f64, f64) {
    let defl = |o: &SimOutput| -> Vec<f64> {
        let m = o.state_series("theta_m").unwrap();
        let a = o.state_series("theta_a1").unwrap();
        m.iter().zip(&a).map(|(m, a)| m / 118.0 - a).collect()
    };
    (
        rel_err(&a.theta_m_true, &b.theta_m_true),
        rel_err(&a.u_true, &b.u_true),
        rel_err(&defl(a), &defl(b)),
    )
}

#[test]
fn all_effects_converge_to_1e6_against_an_independent_rk4_at_ten_times_the_rate() {
    // norm: relative 2-norm over the whole run, ‖x − x_ref‖₂ / ‖x_ref‖₂, of the true motor
    // angle, of u and of the gearbox deflection. The reference is a different integrator:
    // the event-aware RK4 alone (no exponential step) at 10 M substeps per sample, M the
    // default substep count. Quantisation is off: a one-count flip between the two runs
    // would dominate the difference (and noise would only add the same values to both).
    let m = IntegrationConfig::default().substeps;
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.02, 2, 8), 400);
    let coarse = simulate(&all_effects(m), &r).unwrap();
    let mut fine_cfg = all_effects(10 * m);
    fine_cfg.integration.exponential = false;
    let fine = simulate(&fine_cfg, &r).unwrap();
    assert_eq!(
        coarse.integrator,
        Integrator::ExponentialRk4 { substeps: m }
    );
    assert_eq!(fine.integrator, Integrator::Rk4 { substeps: 10 * m });
    let (e_th, e_u, e_d) = run_differences(&coarse, &fine);
    eprintln!("exponential: theta {e_th:e}, u {e_u:e}, deflection {e_d:e}");
    assert!(
        e_th < 1e-6 && e_u < 1e-6 && e_d < 1e-6,
        "exponential: theta {e_th:e}, u {e_u:e}, deflection {e_d:e}"
    );
    // the event-aware RK4 at M substeps converges too
    let mut rk_cfg = all_effects(m);
    rk_cfg.integration.exponential = false;
    let rk = simulate(&rk_cfg, &r).unwrap();
    let (e_th, e_u, e_d) = run_differences(&rk, &fine);
    assert!(
        e_th < 1e-6 && e_u < 1e-6 && e_d < 1e-6,
        "rk4: theta {e_th:e}, u {e_u:e}, deflection {e_d:e}"
    );
    // and the effects do act: the run differs from the linear one by far more than that
    let linear = simulate(&ideal(Plant::default(), vec![]), &r).unwrap();
    assert!(rel_err(&linear.u_true, &fine.u_true) > 1e-2);
}

/// Relative differences `(θ_m, u, deflection)` of the default stepper from the event-aware
/// RK4 at ten times its substeps, for `effects` under the convergence test's excitation.
fn converged(effects: Vec<Effect>) -> (f64, f64, f64) {
    let m = IntegrationConfig::default().substeps;
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.02, 2, 8), 400);
    let mut cfg = ideal(Plant::default(), effects.clone());
    cfg.integration.substeps = m;
    let coarse = simulate(&cfg, &r).unwrap();
    assert_eq!(
        coarse.integrator,
        Integrator::ExponentialRk4 { substeps: m }
    );
    cfg.integration.substeps = 10 * m;
    cfg.integration.exponential = false;
    let d = run_differences(&coarse, &simulate(&cfg, &r).unwrap());
    eprintln!(
        "{effects:?}: theta {:.2e}, u {:.2e}, deflection {:.2e}",
        d.0, d.1, d.2
    );
    d
}

#[test]
fn each_nonlinear_effect_converges_to_1e6_alone_and_behind_a_fractional_delay() {
    // the delay (1.5 samples) switches the input inside every sample, which the stepper
    // takes in one step; friction, backlash, cubic spring and ripple each alone with it
    let delay = Effect::TimeDelay(TimeDelay::default());
    for e in Effect::all_defaults() {
        if matches!(e, Effect::TimeDelay(_) | Effect::ExtraMode(_)) {
            continue;
        }
        for effects in [vec![e], vec![e, delay]] {
            let (e_th, e_u, e_d) = converged(effects.clone());
            assert!(
                e_th < 1e-6 && e_u < 1e-6 && e_d < 1e-6,
                "{effects:?}: theta {e_th:e}, u {e_u:e}, deflection {e_d:e}"
            );
        }
    }
}

#[test]
fn stick_slip_events_inside_a_sample_are_not_stepped_over() {
    // a small Stribeck bump (F_s just above F_c) keeps the motor creeping near zero speed:
    // the speed dips through zero and back within one sample and a stuck motor's torque
    // peaks above breakaway between the sample instants; a step that only looked at its end
    // state missed those stops and breakaways (8e-5 before the in-step checks)
    for (fs, v_stribeck) in [(0.031, 0.1), (0.04, 1.0)] {
        let c = CoulombFriction {
            fc: 0.03,
            fs,
            v_stribeck,
            ..CoulombFriction::default()
        };
        let (e_th, e_u, e_d) = converged(vec![Effect::CoulombFriction(c)]);
        assert!(
            e_th < 1e-6 && e_u < 1e-6 && e_d < 1e-6,
            "F_s {fs}, v_s {v_stribeck}: theta {e_th:e}, u {e_u:e}, deflection {e_d:e}"
        );
    }
}

#[test]
fn rk4_on_linear_plant_agrees_with_exact_path() {
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.02, 1, 9), 400);
    let exact = simulate(&ideal(Plant::default(), vec![]), &r).unwrap();
    let mut cfg = ideal(Plant::default(), vec![]);
    cfg.integration.force_rk4 = true;
    let rk = simulate(&cfg, &r).unwrap();
    assert_eq!(rk.integrator, Integrator::Rk4 { substeps: 5 });
    let e = rel_err(&rk.theta_m_true, &exact.theta_m_true);
    assert!(e < 1e-8, "{e:e}");
}

#[test]
fn asymmetric_friction_sets_each_directions_speed_and_breakaway() {
    // a rigid motor (J 0.01 kg·m², f_m 0.05 N·m·s/rad) driven open loop by a constant
    // torque: forward it settles at (u − F_c)/f_m, backward at (u + F_c−)/(f_m + f_v−);
    // between −F_c− and F_c it stays stuck
    let mut plant = Plant::new(Structure::Rigid);
    plant.params.j_m = 0.01;
    plant.params.j_a1 = 0.0;
    plant.params.j_a2 = 0.0;
    plant.params.f_m = 0.05;
    let effects: Vec<Effect> = vec![
        "coulomb_friction:fc=0.1,fs=0.1,fc_neg=0.3,fv_neg_extra=0.15"
            .parse()
            .unwrap(),
    ];
    let run = |u: f64| {
        let u = vec![u; 4000];
        let out =
            simulate_driven(&plant, &effects, 1e-9, 1e-3, &u, &DrivenStart::default()).unwrap();
        *out.omega_m.last().unwrap()
    };
    assert!((run(0.2) - 0.1 / 0.05).abs() < 1e-6, "{}", run(0.2));
    assert!((run(-0.5) + 0.2 / 0.2).abs() < 1e-6, "{}", run(-0.5));
    assert_eq!(run(-0.25), 0.0);
    assert_eq!(run(0.09), 0.0);
}
