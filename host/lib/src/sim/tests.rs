//! Tests of the whole simulator against independent constructions: seed 000 eq. (6) and (7)
//! discretised here by a separate matrix exponential, seed 001 eq. (9) written out, RK4
//! convergence, reproducibility, and the spectral fingerprint of each effect.

use super::*;
use crate::model::effects::*;
use nalgebra::{Complex, DMatrix, DVector};
use std::f64::consts::PI;

const FS: f64 = 2000.0;
const TS: f64 = 1.0 / FS;

// ---------- helpers: excitation and DFT written for the tests ----------

/// Harmonic indices of a special odd multisine up to `f_max` (seed 000 eq. (4)).
fn special_odd_lines(f_max: usize) -> Vec<usize> {
    (1..=f_max).filter(|k| k % 8 == 1 || k % 8 == 3).collect()
}

/// Odd harmonics that a special odd multisine leaves out.
fn odd_non_excited_lines(f_max: usize) -> Vec<usize> {
    (1..=f_max)
        .filter(|k| k % 2 == 1 && k % 8 != 1 && k % 8 != 3)
        .collect()
}

/// Periodic multisine on `lines` of `f0 = FS / n`, first-order Butterworth amplitudes
/// (cut-off 50 Hz), random phases, scaled to `rms` [rad], `periods` periods.
fn multisine(n: usize, lines: &[usize], rms: f64, periods: usize, seed: u64) -> Vec<f64> {
    let mut rng = sensors::Rng::new(seed, 99);
    let f0 = FS / n as f64;
    let comps: Vec<(f64, f64, f64)> = lines
        .iter()
        .map(|&k| {
            let f = k as f64 * f0;
            let amp = 1.0 / (1.0 + (f / 50.0).powi(2)).sqrt();
            (
                2.0 * PI * k as f64 / n as f64,
                amp,
                2.0 * PI * rng.uniform(),
            )
        })
        .collect();
    let one: Vec<f64> = (0..n)
        .map(|i| {
            comps
                .iter()
                .map(|(w, a, ph)| a * (w * i as f64 + ph).sin())
                .sum()
        })
        .collect();
    let s = (one.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    (0..periods * n).map(|i| one[i % n] * rms / s).collect()
}

/// Average of the last `use_periods` periods of length `n`.
fn mean_period(x: &[f64], n: usize, use_periods: usize) -> Vec<f64> {
    let p = x.len() / n;
    let mut m = vec![0.0; n];
    for q in p - use_periods..p {
        for i in 0..n {
            m[i] += x[q * n + i] / use_periods as f64;
        }
    }
    m
}

/// DFT of one period at harmonic `k`.
fn dft(x: &[f64], k: usize) -> Complex<f64> {
    let n = x.len();
    let mut acc = Complex::new(0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let a = -2.0 * PI * ((k * i) % n) as f64 / n as f64;
        acc += Complex::new(a.cos(), a.sin()) * *v;
    }
    acc / n as f64
}

fn power(x: &[f64], lines: &[usize]) -> f64 {
    lines.iter().map(|&k| dft(x, k).norm_sqr()).sum()
}

/// Relative 2-norm error `‖a − b‖ / ‖b‖`.
fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}

fn ideal(plant: Plant, effects: Vec<Effect>) -> SimConfig {
    SimConfig {
        plant,
        effects,
        sensors: SensorConfig::ideal(),
        ..SimConfig::default()
    }
}

// ---------- independent linear reference: seed 000 eq. (6), (7) ----------

/// Seed 000 eq. (6): states `x1 = θ_m r − θ_a1, x2 = θ_a1 − θ_a2, θ̇_m, θ̇_a1, θ̇_a2`.
fn eq6(p: &JointParams) -> (DMatrix<f64>, DMatrix<f64>, usize) {
    let (r, jm, j1, j2) = (p.r, p.j_m, p.j_a1, p.j_a2);
    #[rustfmt::skip]
    let a = DMatrix::from_row_slice(5, 5, &[
        0.0, 0.0, r, -1.0, 0.0,
        0.0, 0.0, 0.0, 1.0, -1.0,
        -p.k_g * r / jm, 0.0, -(p.f_m + p.d_g * r * r) / jm, p.d_g * r / jm, 0.0,
        p.k_g / j1, -p.k_a / j1, p.d_g * r / j1, -(p.d_g + p.d_a) / j1, p.d_a / j1,
        0.0, p.k_a / j2, 0.0, p.d_a / j2, -p.d_a / j2,
    ]);
    let b = DMatrix::from_row_slice(5, 1, &[0.0, 0.0, 1.0 / jm, 0.0, 0.0]);
    (a, b, 2)
}

/// Seed 000 eq. (7): states of eq. (8).
fn eq7(p: &JointParams) -> (DMatrix<f64>, DMatrix<f64>, usize) {
    let (r, jm, j1, j2, jp) = (p.r, p.j_m, p.j_a1, p.j_a2, p.j_p);
    let a44 = -(p.f_m + p.d_g * r * r) / jm;
    let a55 = -(p.d_g + p.d_a + p.d_p) / j1;
    #[rustfmt::skip]
    let a = DMatrix::from_row_slice(7, 7, &[
        0.0, 0.0, 0.0, r, -1.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 1.0, -1.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0,
        -p.k_g * r / jm, 0.0, 0.0, a44, p.d_g * r / jm, 0.0, 0.0,
        p.k_g / j1, -p.k_a / j1, -p.k_p / j1, p.d_g * r / j1, a55, p.d_a / j1, p.d_p / j1,
        0.0, p.k_a / j2, 0.0, 0.0, p.d_a / j2, -p.d_a / j2, 0.0,
        0.0, 0.0, p.k_p / jp, 0.0, p.d_p / jp, 0.0, -p.d_p / jp,
    ]);
    let mut b = DMatrix::zeros(7, 1);
    b[(3, 0)] = 1.0 / jm;
    (a, b, 3)
}

/// Adds the motor-angle integrator and the current-loop lag: state `[x, θ_m, τ_a]`, input
/// the torque reference.
fn with_angle_and_lag(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    vel: usize,
    tc: f64,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = a.nrows();
    let mut f = DMatrix::zeros(n + 2, n + 2);
    f.view_mut((0, 0), (n, n)).copy_from(a);
    f.view_mut((0, n + 1), (n, 1)).copy_from(b);
    f[(n, vel)] = 1.0;
    f[(n + 1, n + 1)] = -1.0 / tc;
    let mut g = DMatrix::zeros(n + 2, 1);
    g[(n + 1, 0)] = 1.0 / tc;
    (f, g)
}

/// Matrix exponential by Taylor series with scaling and squaring (independent of nalgebra's).
fn expm_taylor(a: &DMatrix<f64>) -> DMatrix<f64> {
    let norm = a
        .row_iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let s = if norm > 0.1 {
        (norm / 0.1).log2().ceil() as i32
    } else {
        0
    };
    let b = a / 2f64.powi(s);
    let n = a.nrows();
    let mut term = DMatrix::identity(n, n);
    let mut sum = DMatrix::identity(n, n);
    for j in 1..25 {
        term = &term * &b / j as f64;
        sum += &term;
    }
    for _ in 0..s {
        sum = &sum * &sum;
    }
    sum
}

fn zoh_taylor(f: &DMatrix<f64>, g: &DMatrix<f64>, t: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = f.nrows();
    let mut aug = DMatrix::zeros(n + 1, n + 1);
    aug.view_mut((0, 0), (n, n)).copy_from(&(f * t));
    aug.view_mut((0, n), (n, 1)).copy_from(&(g * t));
    let e = expm_taylor(&aug);
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, 1)).into_owned(),
    )
}

/// Closed loop written out: P / PI on the backward difference, ideal sensors, no
/// saturation, delay `dw + φ` samples. Returns `(θ_m, u)`.
fn reference_closed_loop(
    f: &DMatrix<f64>,
    g: &DMatrix<f64>,
    c: &ControllerConfig,
    delay: (usize, f64),
    r: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let n = f.nrows();
    let ith = n - 2;
    let steps: Vec<(DMatrix<f64>, DMatrix<f64>)> = if delay.1 > 0.0 {
        vec![
            zoh_taylor(f, g, delay.1 * TS),
            zoh_taylor(f, g, (1.0 - delay.1) * TS),
        ]
    } else {
        vec![zoh_taylor(f, g, TS)]
    };
    let ki = c.kv * TS / c.ti;
    let mut z = DVector::zeros(n);
    let (mut integ, mut prev) = (0.0, 0.0);
    let (mut th, mut us) = (Vec::new(), Vec::new());
    for (k, &rk) in r.iter().enumerate() {
        let theta = z[ith];
        let e = c.kp * (rk - theta) - (theta - prev) / TS;
        prev = theta;
        integ += ki * e;
        let u = c.kv * e + integ;
        assert!(u.abs() < c.u_max);
        th.push(theta);
        us.push(u);
        let past = |lag: usize| k.checked_sub(lag).map_or(0.0, |j| us[j]);
        if steps.len() == 2 {
            z = &steps[0].0 * &z + &steps[0].1 * past(delay.0 + 1);
            z = &steps[1].0 * &z + &steps[1].1 * past(delay.0);
        } else {
            z = &steps[0].0 * &z + &steps[0].1 * past(delay.0);
        }
    }
    (th, us)
}

fn ramped(mut r: Vec<f64>, ramp: usize) -> Vec<f64> {
    for (i, v) in r.iter_mut().enumerate().take(ramp) {
        *v *= 0.5 - 0.5 * (PI * i as f64 / ramp as f64).cos();
    }
    r
}

// ---------- exactness of the linear path ----------

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
        Plant::new(PlantKind::FourMass),
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

// ---------- closed-loop design of the default joint ----------

/// Closed loop `θ_ref → (θ_m, u)` as a discrete state space, written out from the controller
/// equations: state `[z, θ_m[k−1], I[k−1]]`, plant `z` of [`with_angle_and_lag`].
fn closed_loop_matrices(
    f: &DMatrix<f64>,
    g: &DMatrix<f64>,
    c: &ControllerConfig,
) -> (DMatrix<f64>, DVector<f64>) {
    let (phi, gam) = zoh_taylor(f, g, TS);
    let n = f.nrows();
    let ith = n - 2;
    let ki = c.kv * TS / c.ti;
    // e = −(kp + 1/T) θ + θp / T + kp r ; u = (kv + ki) e + I
    let mut e_row = DVector::zeros(n + 2);
    e_row[ith] = -(c.kp + 1.0 / TS);
    e_row[n] = 1.0 / TS;
    let e_r = c.kp;
    let mut u_row = &e_row * (c.kv + ki);
    u_row[n + 1] += 1.0;
    let u_r = (c.kv + ki) * e_r;
    let mut a = DMatrix::zeros(n + 2, n + 2);
    let mut b = DVector::zeros(n + 2);
    a.view_mut((0, 0), (n, n)).copy_from(&phi);
    for i in 0..n {
        for j in 0..n + 2 {
            a[(i, j)] += gam[(i, 0)] * u_row[j];
        }
        b[i] = gam[(i, 0)] * u_r;
    }
    a[(n, ith)] = 1.0;
    for j in 0..n + 2 {
        a[(n + 1, j)] = ki * e_row[j];
    }
    a[(n + 1, n + 1)] += 1.0;
    b[n + 1] = ki * e_r;
    (a, b)
}

#[test]
fn default_closed_loop_is_stable_with_position_bandwidth_between_2_and_5_hz() {
    let cfg = SimConfig::default();
    let (a6, b6, vel) = eq6(&cfg.plant.params);
    let (f, g) = with_angle_and_lag(&a6, &b6, vel, cfg.controller.current_loop_tau);
    let (a, b) = closed_loop_matrices(&f, &g, &cfg.controller);
    let radius = a
        .complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max);
    assert!(radius < 0.9999, "spectral radius {radius}");
    let ith = f.nrows() - 2;
    let n = a.nrows();
    let gain = |hz: f64| {
        let z = Complex::from_polar(1.0, 2.0 * PI * hz * TS);
        let m = DMatrix::from_fn(n, n, |i, j| {
            let d = if i == j { z } else { Complex::new(0.0, 0.0) };
            d - Complex::new(a[(i, j)], 0.0)
        });
        let rhs = DVector::from_fn(n, |i, _| Complex::new(b[i], 0.0));
        m.lu().solve(&rhs).unwrap()[ith].norm()
    };
    let grid: Vec<f64> = (1..=400).map(|i| 0.05 * i as f64).collect();
    let bw = grid
        .iter()
        .copied()
        .find(|&hz| gain(hz) < std::f64::consts::FRAC_1_SQRT_2)
        .unwrap();
    let peak = grid.iter().map(|&hz| gain(hz)).fold(0.0, f64::max);
    assert!((2.0..=5.0).contains(&bw), "bandwidth {bw} Hz");
    assert!(peak < 1.6, "resonance peak {peak}");
    assert!((gain(0.01) - 1.0).abs() < 1e-3);
}

// ---------- nonlinear path ----------

#[test]
fn generic_plant_rhs_equals_seed001_eq9_for_nonlinear_two_mass() {
    let plant = Plant::new(PlantKind::NonlinearTwoMass);
    let cfg = ideal(plant, vec![]);
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

// ---------- reproducibility, configuration ----------

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
    let cfg = SimConfig {
        effects: Effect::all_defaults(),
        ..SimConfig::default()
    };
    let json = cfg.params_json().unwrap();
    for (name, _, _) in cfg.plant.params.table() {
        assert!(json.contains(&format!("\"{name}\"")), "{name} missing");
    }
    for e in Effect::all_defaults() {
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
        plant: Plant::new(PlantKind::Rigid),
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
    for kind in PlantKind::ALL {
        let out = simulate(&ideal(Plant::new(kind), vec![]), &r).unwrap();
        let expected = if kind == PlantKind::NonlinearTwoMass {
            Integrator::ExponentialRk4 { substeps: 5 }
        } else {
            Integrator::ExactZoh
        };
        assert_eq!(out.integrator, expected, "{kind:?}");
        let err = rel_err(&out.theta_m_true, &r);
        assert!(err < 0.2, "{kind:?}: tracking error {err}");
    }
}

// ---------- fingerprints of the effects ----------

const N: usize = 2000;
const F_MAX: usize = 120;
const DEFAULT_RMS: f64 = 0.02;
const LARGE_RMS: f64 = 0.08;

/// Power at the non-excited odd lines relative to the excited lines, `(θ_m, u)`, from the
/// mean of the last two of four periods of a special odd multisine.
fn odd_distortion(effects: Vec<Effect>, rms: f64, sensors: SensorConfig) -> (f64, f64) {
    let r = multisine(N, &special_odd_lines(F_MAX), rms, 6, 7);
    let cfg = SimConfig {
        sensors,
        ..ideal(Plant::default(), effects)
    };
    let out = simulate(&cfg, &r).unwrap();
    let th = mean_period(&out.theta_m, N, 4);
    let u = mean_period(&out.u, N, 4);
    let (exc, non) = (special_odd_lines(F_MAX), odd_non_excited_lines(F_MAX));
    (
        power(&th, &non) / power(&th, &exc),
        power(&u, &non) / power(&u, &exc),
    )
}

/// Checks visibility at the default amplitude with default sensors (10× the no-effect floor)
/// and returns the ideal-sensor distortion at the default and the large amplitude.
fn fingerprint(effect: Effect) -> ((f64, f64), (f64, f64)) {
    let floor = odd_distortion(vec![], DEFAULT_RMS, SensorConfig::default());
    let seen = odd_distortion(vec![effect], DEFAULT_RMS, SensorConfig::default());
    assert!(
        seen.0 > 10.0 * floor.0 && seen.1 > 10.0 * floor.1,
        "{}: {seen:?} vs floor {floor:?}",
        effect.name()
    );
    let small = odd_distortion(vec![effect], DEFAULT_RMS, SensorConfig::ideal());
    let large = odd_distortion(vec![effect], LARGE_RMS, SensorConfig::ideal());
    (small, large)
}

#[test]
fn backlash_raises_odd_lines_more_at_small_amplitude() {
    let (small, large) = fingerprint(Effect::Backlash(Backlash::default()));
    assert!(
        small.0 > 2.0 * large.0 && small.1 > 2.0 * large.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn coulomb_friction_raises_odd_lines_more_at_small_amplitude() {
    let (small, large) = fingerprint(Effect::CoulombFriction(CoulombFriction::default()));
    assert!(
        small.0 > 2.0 * large.0 && small.1 > 2.0 * large.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn cubic_spring_raises_odd_lines_more_at_large_amplitude() {
    let (small, large) = fingerprint(Effect::NonlinearStiffness(NonlinearStiffness::default()));
    assert!(
        large.0 > 2.0 * small.0 && large.1 > 2.0 * small.1,
        "{small:?} {large:?}"
    );
}

#[test]
fn linear_plant_leaves_non_excited_lines_empty() {
    let (th, u) = odd_distortion(vec![], DEFAULT_RMS, SensorConfig::ideal());
    assert!(th < 1e-12 && u < 1e-12, "{th:e} {u:e}");
}

/// FRF `u → θ_m` at lines `1..=F_MAX` of a full multisine (all lines excited), steady state;
/// noise-free, so the ratio of the period spectra is the plant FRF.
fn frf(effects: Vec<Effect>) -> Vec<Complex<f64>> {
    let lines: Vec<usize> = (1..=F_MAX).collect();
    let r = multisine(N, &lines, DEFAULT_RMS, 5, 12);
    let out = simulate(&ideal(Plant::default(), effects), &r).unwrap();
    let th = mean_period(&out.theta_m, N, 1);
    let u = mean_period(&out.u, N, 1);
    lines.iter().map(|&k| dft(&th, k) / dft(&u, k)).collect()
}

#[test]
fn time_delay_bends_the_frf_phase_linearly_with_frequency() {
    let d = TimeDelay::default();
    let g0 = frf(vec![]);
    let gd = frf(vec![Effect::TimeDelay(d)]);
    let expected_slope = -2.0 * PI * d.samples * TS; // rad per Hz
    let (mut sxy, mut sxx) = (0.0, 0.0);
    let mut resid = Vec::new();
    for (i, (a, b)) in g0.iter().zip(&gd).enumerate() {
        let f = (i + 1) as f64 * FS / N as f64;
        let dphi = (b / a).arg();
        sxy += f * dphi;
        sxx += f * f;
        resid.push((dphi - expected_slope * f).abs());
        // the magnitude is untouched by a pure delay
        assert!((b.norm() / a.norm() - 1.0).abs() < 1e-3, "{f} Hz");
    }
    let slope = sxy / sxx;
    assert!(
        (slope / expected_slope - 1.0).abs() < 0.01,
        "slope {slope} vs {expected_slope}"
    );
    let worst = resid.iter().fold(0.0f64, |a, &b| a.max(b));
    assert!(worst < 0.01, "phase residual {worst} rad");
}

#[test]
fn extra_mode_adds_a_resonance_peak_where_there_was_none() {
    let x = ExtraMode::default();
    let before = Mechanism::new(&Plant::default(), &[]).modal_frequencies();
    let after = Mechanism::new(&Plant::default(), &[Effect::ExtraMode(x)]).modal_frequencies();
    assert_eq!(after.resonances_hz.len(), before.resonances_hz.len() + 1);
    // the new resonance: the one farthest from every old one
    let distance = |f: f64| {
        before
            .resonances_hz
            .iter()
            .map(|g| (f - g).abs())
            .fold(f64::INFINITY, f64::min)
    };
    let f_new = after
        .resonances_hz
        .iter()
        .copied()
        .max_by(|a, b| distance(*a).total_cmp(&distance(*b)))
        .unwrap();
    assert!(distance(f_new) > 5.0, "{after:?}");
    let g0 = frf(vec![]);
    let gx = frf(vec![Effect::ExtraMode(x)]);
    // compensate the double integrator: |G| ω² is flat for a rigid body
    let shaped = |g: &[Complex<f64>]| -> Vec<f64> {
        g.iter()
            .enumerate()
            .map(|(i, v)| v.norm() * ((i + 1) as f64).powi(2))
            .collect()
    };
    let (s0, sx) = (shaped(&g0), shaped(&gx));
    let is_peak = |s: &[f64], i: usize| s[i] > s[i - 1] && s[i] > s[i + 1];
    // line i is (i + 1) Hz
    let ip = (1..F_MAX - 1)
        .filter(|&i| ((i + 1) as f64 - f_new).abs() <= 1.5)
        .find(|&i| is_peak(&sx, i));
    let Some(ip) = ip else {
        panic!("no peak near {f_new} Hz: {:?}", &sx[..30])
    };
    assert!(
        (ip - 5..=ip + 5).all(|i| !is_peak(&s0, i)),
        "{:?}",
        &s0[..30]
    );
    assert!(sx[ip] > 2.0 * s0[ip], "peak {} vs {}", sx[ip], s0[ip]);
}

#[test]
fn torque_ripple_puts_energy_on_even_lines() {
    // sin(n θ + φ) with φ ≠ 0 is not an odd function of the motion: even harmonics appear
    let even: Vec<usize> = (1..=F_MAX / 2).map(|k| 2 * k).collect();
    let even_ratio = |effects: Vec<Effect>, sensors: SensorConfig| {
        let r = multisine(N, &special_odd_lines(F_MAX), DEFAULT_RMS, 6, 7);
        let out = simulate(
            &SimConfig {
                sensors,
                ..ideal(Plant::default(), effects)
            },
            &r,
        )
        .unwrap();
        let u = mean_period(&out.u, N, 4);
        power(&u, &even) / power(&u, &special_odd_lines(F_MAX))
    };
    let floor = even_ratio(vec![], SensorConfig::default());
    let seen = even_ratio(
        vec![Effect::TorqueRipple(TorqueRipple::default())],
        SensorConfig::default(),
    );
    assert!(seen > 10.0 * floor, "even lines {seen:e}, floor {floor:e}");
}

// ---------- with the firmware core: excitation and wire types ----------

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
    let raw = out.to_raw_samples(&scale, 1_000_000);
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
    for kind in [
        PlantKind::TwoMass,
        PlantKind::ThreeMass,
        PlantKind::FourMass,
        PlantKind::NonlinearTwoMass,
    ] {
        let cfg = SimConfig {
            plant: Plant::new(kind),
            effects: Effect::all_defaults(),
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
