//! A two-mass joint as a continuous state-space model, and closed-loop records of a
//! discrete plant under a PD-like position loop: the fixtures of the subspace, grey-box and
//! prediction-error tests, whose truth is the plant itself.

use nalgebra::{DMatrix, DVector, RowDVector};

use crate::data::IdData;
use crate::ident::linalg::GaussRng;
use crate::ident::ss::{ContinuousSs, StateSpace};

/// Continuous two-mass motor-side model with angle output, states
/// `[θm, ωm, θm-θl, ωl]`: motor inertia `j1` and load inertia `j2` [kg·m²],
/// spring `k` [N·m/rad], damper `d` and motor viscous friction `fm` [N·m·s/rad].
pub fn two_mass_angle_ct(j1: f64, j2: f64, k: f64, d: f64, fm: f64) -> ContinuousSs {
    let f = DMatrix::from_row_slice(
        4,
        4,
        &[
            0.0,
            1.0,
            0.0,
            0.0, //
            0.0,
            -(fm + d) / j1,
            -k / j1,
            d / j1, //
            0.0,
            1.0,
            0.0,
            -1.0, //
            0.0,
            d / j2,
            k / j2,
            -d / j2,
        ],
    );
    let g = DVector::from_vec(vec![0.0, 1.0 / j1, 0.0, 0.0]);
    let h = RowDVector::from_vec(vec![1.0, 0.0, 0.0, 0.0]);
    ContinuousSs { f, g, h, d: 0.0 }
}

/// Continuous two-mass (order 3, velocity) or with integrator (order 4,
/// angle) motor-side model: motor J1, load J2, spring k, damper d,
/// viscous friction fm.
pub fn two_mass_ct(angle: bool) -> ContinuousSs {
    let c = two_mass_angle_ct(0.01, 0.02, 200.0, 0.02, 0.002);
    if angle {
        c
    } else {
        let keep = [1usize, 2, 3];
        ContinuousSs {
            f: DMatrix::from_fn(3, 3, |r, cc| c.f[(keep[r], keep[cc])]),
            g: DVector::from_fn(3, |r, _| c.g[keep[r]]),
            h: RowDVector::from_vec(vec![1.0, 0.0, 0.0]),
            d: 0.0,
        }
    }
}

/// Closed-loop data: PD/PI-like position loop `u = kp (r − y_meas) −
/// kd Δy_meas/Ts + v_u`, `y_meas = y + noise` (white or first-order
/// coloured), reference = filtered Gaussian noise.
pub struct LoopSpec {
    /// proportional gain [torque/output unit]
    pub kp: f64,
    /// derivative gain [torque·s/output unit]
    pub kd: f64,
    /// standard deviation of the measurement noise's white driver [output unit]
    pub noise: f64,
    /// pole of the first-order noise colouring (0: white)
    pub colour: f64,
    /// noise seed
    pub seed: u64,
    /// samples
    pub n: usize,
    /// pole of the first-order filter that smooths the reference's Gaussian noise
    pub r_smooth: f64,
    /// standard deviation of the dither added to the torque [torque unit]
    pub u_dither: f64,
}

/// The record of `plant` in the loop of `spec`, with the reference as `r`.
pub fn closed_loop(plant: &StateSpace, spec: &LoopSpec) -> IdData {
    let mut rng = GaussRng::new(spec.seed);
    let n = plant.order();
    let mut x = DVector::zeros(n);
    let mut r = 0.0;
    let mut v = 0.0;
    let mut y_prev = 0.0;
    let (mut us, mut ys, mut rs) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..spec.n {
        r = spec.r_smooth * r + (1.0 - spec.r_smooth) * rng.normal();
        let e = rng.normal() * spec.noise;
        v = spec.colour * v + e;
        let y = (&plant.c * &x)[0] + v;
        let u =
            spec.kp * (r - y) - spec.kd * (y - y_prev) / plant.ts + spec.u_dither * rng.normal();
        y_prev = y;
        us.push(u);
        ys.push(y);
        rs.push(r);
        x = &plant.a * &x + &plant.b * u;
    }
    IdData {
        ts: plant.ts,
        u: us,
        y: ys,
        r: Some(rs),
    }
}
