//! The friction-compensated FRF behind the linear start of a model with Coulomb friction.
//!
//! **Why.** The frequency-domain linear start ([`super::run::linear_start`]) fits the
//! structure to the FRF at the excited lines. Coulomb friction `F_c sgn(ω_m)` is a torque
//! periodic with the excitation, so it has components at the excited lines themselves and
//! bends the FRF there, not only at the non-excited ones. At the paper's 0.02 rad RMS on
//! the default three-mass joint with `F_c` = 0.03 N·m (`jointid simulate --effect
//! coulomb_friction:fc=0.03,fs=0.03 --seed 4`), the fit to the measured FRF gives
//! `J_m` = 1.1e-4 kg·m² (truth 1e-3), `k_g` = 6.4e4 N·m/rad (1.275e5) and a lag of
//! 6.6 ms (0.5 ms) at a cost 2.55 times the noise's; the nonlinear fit started there ends
//! at a validation FIT of 30 %.
//!
//! **What.** The friction is taken off the torque before the FRF:
//! `u_c(k) = u(k) − F̂_c s(k)`, with `s` the friction law the model integrates
//! ([`crate::model::effects::CoulombFriction::torque`], its Stribeck shape scaled to `F̂_c`)
//! at the motor velocity over the interval the torque acts in: the backward difference
//! `(θ_m(k+d) − θ_m(k+d−1))/T`, `d` = 1 + the current loop's lag in samples (the torque
//! held over `[k, k+1)` reaches the motor one lag later). The velocity is not low-passed:
//! the motor's velocity at these amplitudes holds most of its energy above any rigid-body
//! cut-off, and the sign of the 8 Hz low-passed velocity differs from the true one on
//! 30 % of the samples. A count that did not change gives `s = 0` (a stuck or slow motor,
//! whose friction is not `±F_c`). The reference stays the instrument, so the FRF of
//! `u_c → θ_m` is the linear structure's.
//!
//! **`F̂_c`** by inverse dynamics with parallel filtering done on the sign itself:
//! `LP(u) = J LP(θ̈_m) + F̂_c LP(s) + offset`, every signal through the same zero-phase
//! low-pass (8 Hz, where the joint moves as one body), `s` from the raw velocity as above.
//! The viscous term is left out: at these amplitudes `LP(ω_m)` and `LP(s)` trade against
//! each other and the regression with both takes `F_v` negative and `F_c` 60 % high, past
//! the compensation's window (on the case above the start stays in the truth's basin for
//! `F̂_c` within 0.02–0.04 N·m). (Step 2 of the automatic start regresses on the sign of
//! the low-passed velocity and finds 0.0012 N·m there.)
//!
//! **Which `d`**: 1, 2 and 3 (lags of 0–2 samples) are tried, or the held lag's; the one
//! whose compensated FRF the structure fits at the lowest cost (relative to the noise) is
//! kept, and the compensation only when that cost is clearly below the uncompensated FRF's
//! (by twice its spread for a right model). On the case above, with [`SHARE`] of the level:
//! cost 1.16 against 2.55, and the nonlinear fit from that start ends in 6 iterations at
//! `J_m` 1.003e-3, `k_g` 1.270e5, `d_g` 75, `F_c` 0.0301, lag 0.49 ms, validation FIT
//! 77.6 % (27.1 % without the compensation).

use crate::data::dsp::{central_diff, filtfilt_lowpass};
use crate::data::{Dataset, IdData};
use crate::ident::linalg::solve_spd;
use crate::model::effects::CoulombFriction;
use nalgebra::DMatrix;

/// Low-pass cut-off of the level's regression [Hz] (the rigid-body band of step 1).
pub const CUTOFF_HZ: f64 = 8.0;

/// Share of the regression's level taken off the torque. The regression reads high
/// (+17 % on the case above, +31 % at `F_c` = 0.06 N·m: the counts that did not change give
/// `s = 0` where the motor still slides), and too much taken off is worse than too little:
/// the over-compensated FRF shows a negative damping that the fit puts into `f_m` and the
/// lag, both driven to their floor, where the log-parameters of the output-error fit stay
/// (seed 001's reference problem: `f_m` 1.7e-6, 60 iterations, with the whole level taken
/// off); a level left on acts as viscous friction at the lines, which the fit removes.
pub const SHARE: f64 = 0.7;

/// The Coulomb level's estimate from the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Level {
    /// `F̂_c` [N·m]
    pub fc: f64,
    /// its standard deviation [N·m] (white-residual formula: optimistic)
    pub std: f64,
    /// relative torque error of the regression without the friction regressor [%]
    pub error_without: f64,
    /// the same with it [%]
    pub error_with: f64,
}

/// The friction's shape `s(k)` ∈ [−1, 1] per sample: the law `law` at level 1 on the
/// backward-difference motor velocity `d` samples ahead (module documentation).
pub fn shape(y: &[f64], ts: f64, d: usize, law: &CoulombFriction) -> Vec<f64> {
    let n = y.len();
    let unit = unit_law(law);
    (0..n)
        .map(|k| {
            let j = (k + d).min(n - 1);
            if j == 0 {
                return 0.0;
            }
            let w = (y[j] - y[j - 1]) / ts;
            if w == 0.0 {
                0.0
            } else {
                unit.torque(w)
            }
        })
        .collect()
}

/// `law` scaled to `F_c` = 1 (its Stribeck bump and backward level scaled alike).
fn unit_law(law: &CoulombFriction) -> CoulombFriction {
    let s = if law.fc > 0.0 { 1.0 / law.fc } else { 1.0 };
    CoulombFriction {
        fc: 1.0,
        fs: if law.fs > law.fc { law.fs * s } else { 1.0 },
        fc_neg: law.fc_neg.map(|f| f * s),
        fv_neg_extra: None,
        ..*law
    }
}

/// `F̂_c` of `data` by the regression of the module documentation with the shape of
/// `law` `d` samples ahead. `None` when the regression is singular or the record short.
pub fn level(data: &IdData, d: usize, law: &CoulombFriction) -> Option<Level> {
    let n = data.len();
    let ts = data.ts;
    let edge = (2.0 / (CUTOFF_HZ * ts)).ceil() as usize;
    if n < 4 * edge + 10 {
        return None;
    }
    let s = shape(&data.y, ts, d, law);
    let yf = filtfilt_lowpass(&data.y, 4, CUTOFF_HZ, ts);
    let uf = filtfilt_lowpass(&data.u, 4, CUTOFF_HZ, ts);
    let sf = filtfilt_lowpass(&s, 4, CUTOFF_HZ, ts);
    let qdd = central_diff(&central_diff(&yf, ts), ts);
    // [J, offset] and [J, F_c, offset]
    let solve = |with: bool| -> Option<(Vec<f64>, f64, f64)> {
        let p = if with { 3 } else { 2 };
        let mut m = DMatrix::<f64>::zeros(p, p);
        let mut rhs = DMatrix::<f64>::zeros(p, 1);
        let mut uu = 0.0;
        let rows = (edge..n - edge).map(|t| {
            let phi = if with {
                vec![qdd[t], sf[t], 1.0]
            } else {
                vec![qdd[t], 1.0]
            };
            (phi, uf[t])
        });
        let rows: Vec<(Vec<f64>, f64)> = rows.collect();
        for (phi, u) in &rows {
            for i in 0..p {
                for j in 0..p {
                    m[(i, j)] += phi[i] * phi[j];
                }
                rhs[(i, 0)] += phi[i] * u;
            }
            uu += u * u;
        }
        let th = solve_spd(&m, &rhs, 0.0)?;
        let th: Vec<f64> = (0..p).map(|i| th[(i, 0)]).collect();
        let ssr: f64 = rows
            .iter()
            .map(|(phi, u)| {
                let e = u - phi.iter().zip(&th).map(|(a, b)| a * b).sum::<f64>();
                e * e
            })
            .sum();
        let var = ssr / (rows.len() - p) as f64;
        let std = if with {
            m.clone()
                .try_inverse()
                .map_or(f64::NAN, |inv| (var * inv[(1, 1)]).max(0.0).sqrt())
        } else {
            f64::NAN
        };
        Some((th, 100.0 * (ssr / uu).sqrt(), std))
    };
    let (_, error_without, _) = solve(false)?;
    let (th, error_with, std) = solve(true)?;
    Some(Level {
        fc: th[1],
        std,
        error_without,
        error_with,
    })
}

/// `ds` with the friction `fc · shape` taken off its torque (`shape` from [`shape`]).
pub fn compensated(ds: &Dataset, fc: f64, d: usize, law: &CoulombFriction) -> Dataset {
    let s = shape(&ds.data.y, ds.data.ts, d, law);
    let mut out = ds.clone();
    for (u, s) in out.data.u.iter_mut().zip(&s) {
        *u -= fc * s;
    }
    out
}
