//! Simulator tests: the closed-loop design of the default joint.

use super::*;

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
