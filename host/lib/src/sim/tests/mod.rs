//! Tests of the whole simulator against independent constructions: seed 000 eq. (6) and (7)
//! discretised here by a separate matrix exponential, seed 001 eq. (9) written out, RK4
//! convergence, reproducibility, and the spectral fingerprint of each effect, one file per
//! subject; the helpers and the independent linear reference are here.

use super::*;
use crate::model::effects::*;
use nalgebra::{Complex, DMatrix, DVector};
use std::f64::consts::PI;

mod closed_loop;
mod config;
mod driven;
mod exact_linear;
mod fingerprints;
mod nonlinear;
mod with_core;

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

/// Seed 001's nonlinear two-mass with default `k3`, `F_c`: the two-mass and the two effects
/// of the `nonlinear-two-mass` alias ([`crate::model::params::sim_spec`]).
fn seed_001() -> (Plant, Vec<Effect>) {
    let plant = Plant::new(Structure::TwoMass);
    let spec = crate::model::params::sim_spec(plant.kind, true, &[], &plant.params).unwrap();
    (plant, spec.effects.unwrap())
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
