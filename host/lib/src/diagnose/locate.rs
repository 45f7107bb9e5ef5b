//! Where the nominal model's residual lies: in the operating region (motor velocity near
//! zero, torque sign changes, large gearbox deflection, a pattern against the motor
//! angle) and in frequency (bands of the residual's spectrum against the measured one).
//!
//! The residual is the band-passed velocity residual of the gap metric
//! ([`super::metric`]); regions are read on the scored range only.

use rustfft::{num_complex::Complex, FftPlanner};
use serde::Serialize;

/// Bands of the frequency split of the residual [Hz].
pub const BANDS_HZ: [(f64, f64); 5] = [
    (1.0, 5.0),
    (5.0, 15.0),
    (15.0, 30.0),
    (30.0, 60.0),
    (60.0, 150.0),
];

/// "Near zero velocity": `|ω_m|` below this share of its RMS.
pub const ZERO_VELOCITY_SHARE: f64 = 0.1;
/// Samples either side of a torque sign change counted in that region.
pub const SIGN_CHANGE_HALF_WIDTH: usize = 10;
/// "Large deflection": the top share of `|δ|`.
pub const LARGE_DEFLECTION_SHARE: f64 = 0.2;
/// Highest order per motor revolution searched for a pattern against the angle.
pub const MAX_ANGLE_ORDER: u32 = 200;

/// The residual's energy in one region.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Region {
    /// share of the scored samples in the region [-]
    pub samples_share: f64,
    /// mean square of the residual in the region / mean square overall [-] (1: no
    /// concentration; NaN when the region is empty)
    pub energy_ratio: f64,
}

/// A periodic pattern of the residual against the motor angle.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AnglePattern {
    /// periods per motor revolution of the best sin/cos regression
    pub order: u32,
    /// share of the residual's energy it explains [-]
    pub share: f64,
    /// the share two regressors explain in white noise of this length, for scale [-]
    pub chance_share: f64,
}

/// Regions of the residual.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Regions {
    /// `|ω_m| <` [`ZERO_VELOCITY_SHARE`] × RMS (ω_m from the nominal's driven simulation)
    pub near_zero_velocity: Region,
    /// within [`SIGN_CHANGE_HALF_WIDTH`] samples of a sign change of the measured torque
    pub torque_sign_change: Region,
    /// top [`LARGE_DEFLECTION_SHARE`] of `|δ|` (gearbox deflection of the nominal's
    /// driven simulation)
    pub large_deflection: Region,
    /// the best pattern against the measured motor angle
    pub angle_pattern: AnglePattern,
}

/// The residual against the measured velocity in one band.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Band {
    /// lower edge [Hz]
    pub lo_hz: f64,
    /// upper edge [Hz]
    pub hi_hz: f64,
    /// residual energy / measured energy in the band [-] (0: the model explains the band,
    /// 1: as large as the motion itself)
    pub residual_ratio: f64,
}

fn region(res2: &[f64], mask: &[bool], overall: f64) -> Region {
    let n = mask.iter().filter(|m| **m).count();
    let e: f64 = res2
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|(r, _)| r)
        .sum();
    Region {
        samples_share: n as f64 / mask.len().max(1) as f64,
        energy_ratio: if n > 0 && overall > 0.0 {
            e / n as f64 / overall
        } else {
            f64::NAN
        },
    }
}

/// The regions of `residual` (scored range), with the torque `u`, the motor angle
/// `theta`, the simulated motor velocity `omega` and gearbox deflection `delta` of the
/// same samples.
pub fn regions(
    residual: &[f64],
    u: &[f64],
    theta: &[f64],
    omega: &[f64],
    delta: &[f64],
) -> Regions {
    let n = residual.len();
    let res2: Vec<f64> = residual.iter().map(|r| r * r).collect();
    let overall = res2.iter().sum::<f64>() / n.max(1) as f64;
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    let w_rms = rms(omega);
    let zero: Vec<bool> = omega
        .iter()
        .map(|w| w.abs() < ZERO_VELOCITY_SHARE * w_rms)
        .collect();
    let mut sign = vec![false; n];
    for k in 1..n {
        if u[k].signum() != u[k - 1].signum() {
            let a = k.saturating_sub(SIGN_CHANGE_HALF_WIDTH);
            let b = (k + SIGN_CHANGE_HALF_WIDTH).min(n - 1);
            sign[a..=b].iter_mut().for_each(|s| *s = true);
        }
    }
    let mut d: Vec<f64> = delta.iter().map(|x| x.abs()).collect();
    d.sort_by(f64::total_cmp);
    let cut = d
        .get(((1.0 - LARGE_DEFLECTION_SHARE) * n as f64) as usize)
        .copied()
        .unwrap_or(f64::INFINITY);
    let large: Vec<bool> = delta.iter().map(|x| x.abs() >= cut).collect();
    Regions {
        near_zero_velocity: region(&res2, &zero, overall),
        torque_sign_change: region(&res2, &sign, overall),
        large_deflection: region(&res2, &large, overall),
        angle_pattern: angle_pattern(residual, theta),
    }
}

/// The order `n` in 1..=[`MAX_ANGLE_ORDER`] whose regression of the residual on
/// `sin(n θ)`, `cos(n θ)` explains the most of its energy.
pub fn angle_pattern(residual: &[f64], theta: &[f64]) -> AnglePattern {
    let total: f64 = residual.iter().map(|r| r * r).sum();
    let mut best = AnglePattern {
        order: 0,
        share: 0.0,
        chance_share: 2.0 / residual.len().max(1) as f64,
    };
    if total <= 0.0 {
        return best;
    }
    for order in 1..=MAX_ANGLE_ORDER {
        let (mut ss, mut cc, mut sc, mut sr, mut cr) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (r, th) in residual.iter().zip(theta) {
            let (s, c) = (order as f64 * th).sin_cos();
            ss += s * s;
            cc += c * c;
            sc += s * c;
            sr += s * r;
            cr += c * r;
        }
        let det = ss * cc - sc * sc;
        if det <= 1e-12 * (ss * cc).max(1e-300) {
            continue;
        }
        // explained energy bᵀ Xᵀ r with b = (XᵀX)⁻¹ Xᵀ r
        let bs = (cc * sr - sc * cr) / det;
        let bc = (ss * cr - sc * sr) / det;
        let share = (bs * sr + bc * cr) / total;
        if share > best.share {
            best.order = order;
            best.share = share;
        }
    }
    best
}

fn band_energies(x: &[f64], ts: f64, bands: &[(f64, f64)]) -> Vec<f64> {
    let n = x.len();
    let mut buf: Vec<Complex<f64>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let df = 1.0 / (n as f64 * ts);
    bands
        .iter()
        .map(|&(lo, hi)| {
            (1..=n / 2)
                .filter(|&k| {
                    let f = k as f64 * df;
                    f >= lo && f < hi
                })
                .map(|k| buf[k].norm_sqr())
                .sum()
        })
        .collect()
}

/// Residual energy against the measured energy in each of [`BANDS_HZ`] (both the
/// band-passed velocities of the scored range).
pub fn bands(residual: &[f64], measured: &[f64], ts: f64) -> Vec<Band> {
    let r = band_energies(residual, ts, &BANDS_HZ);
    let m = band_energies(measured, ts, &BANDS_HZ);
    BANDS_HZ
        .iter()
        .zip(r.iter().zip(&m))
        .map(|(&(lo_hz, hi_hz), (r, m))| Band {
            lo_hz,
            hi_hz,
            residual_ratio: if *m > 0.0 { r / m } else { f64::NAN },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pattern_of_order_36_is_found_against_the_angle() {
        let n = 8000;
        let theta: Vec<f64> = (0..n).map(|k| 0.3 * (k as f64 * 1e-3).sin()).collect();
        let mut g = crate::ident::linalg::GaussRng::new(3);
        let res: Vec<f64> = theta
            .iter()
            .map(|t| (36.0 * t + 0.4).sin() + 0.3 * g.normal())
            .collect();
        let p = angle_pattern(&res, &theta);
        assert_eq!(p.order, 36);
        assert!(p.share > 0.8, "{p:?}");
    }

    #[test]
    fn residual_concentrated_near_zero_velocity_shows_in_its_region() {
        let n = 10000;
        let omega: Vec<f64> = (0..n).map(|k| (k as f64 * 0.01).sin()).collect();
        let res: Vec<f64> = omega
            .iter()
            .map(|w| if w.abs() < 0.05 { 1.0 } else { 0.01 })
            .collect();
        let r = regions(&res, &omega, &omega, &omega, &omega);
        assert!(r.near_zero_velocity.energy_ratio > 5.0, "{r:?}");
        assert!(r.large_deflection.energy_ratio < 0.1, "{r:?}");
    }
}
