//! Simulator tests: exactness of the linear path: the simulator against seed 000 eq. (6) and (7)
//! discretised here by a separate matrix exponential.

use super::*;

#[test]
fn simulate_matches_exact_zoh_closed_loop_of_eq6_three_mass() {
    let cfg = ideal(Plant::default(), vec![]);
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.05, 1, 5), 400);
    let out = simulate(&cfg, &r).unwrap();
    assert_eq!(out.integrator, Integrator::ExactZoh);
    let (a, b, vel) = eq6(&cfg.plant.params);
    let (f, g) = with_angle_and_lag(&a, &b, vel, cfg.controller.current_loop_tau);
    let (th, u) = reference_closed_loop(&f, &g, &cfg.controller, (0, 0.0), &r);
    let (et, eu) = (rel_err(&out.theta_m, &th), rel_err(&out.u, &u));
    assert!(et < 1e-9 && eu < 1e-9, "theta {et:e}, u {eu:e}");
}

#[test]
fn simulate_matches_exact_zoh_closed_loop_of_eq7_four_mass_with_fractional_delay() {
    let cfg = ideal(
        Plant::new(Structure::FourMass),
        vec![Effect::TimeDelay(TimeDelay { samples: 2.3 })],
    );
    let r = ramped(multisine(2000, &special_odd_lines(120), 0.05, 1, 6), 400);
    let out = simulate(&cfg, &r).unwrap();
    assert_eq!(out.integrator, Integrator::ExactZoh);
    let (a, b, vel) = eq7(&cfg.plant.params);
    let (f, g) = with_angle_and_lag(&a, &b, vel, cfg.controller.current_loop_tau);
    let (th, u) = reference_closed_loop(&f, &g, &cfg.controller, (2, 0.3), &r);
    let (et, eu) = (rel_err(&out.theta_m, &th), rel_err(&out.u, &u));
    assert!(et < 1e-9 && eu < 1e-9, "theta {et:e}, u {eu:e}");
}
