//! Where the nominal model's residual lies: in the operating region (motor velocity near
//! zero, torque sign changes, large gearbox deflection, a pattern against the motor
//! angle) and in frequency (bands of the residual's spectrum against the measured one).
//!
//! The residual is the band-passed velocity residual of the gap metric
//! ([`super::metric`]); regions are read on the scored range only.

use rustfft::{num_complex::Complex, FftPlanner};

use crate::data::Dataset;
use crate::ident::frf::{analyze_dataset, ClassLevel};
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

/// A model's residual at the non-excited odd lines must stand this far above the noise
/// [dB] before the share of it another model removes is read ([`odd_explained`]).
pub const ODD_RESIDUAL_ABOVE_NOISE_DB: f64 = 10.0;

/// The residual `θ_m − θ̂_m` of a model's simulation `theta_sim` [rad] at the non-excited
/// odd lines of the periodic capture `val` (seed 000 §3, Fig. 3): what an odd nonlinearity
/// (friction, backlash, a stiffening spring) makes and a linear model cannot follow.
/// `None` when `val` states no excitation or holds too few periods.
pub fn odd_residual(val: &Dataset, theta_sim: &[f64], settle_periods: usize) -> Option<ClassLevel> {
    if val.excitation.is_none() || theta_sim.len() != val.data.len() {
        return None;
    }
    let mut residual = val.clone();
    residual.data.y = val
        .data
        .y
        .iter()
        .zip(theta_sim)
        .map(|(y, s)| y - s)
        .collect();
    analyze_dataset(&residual, settle_periods)
        .ok()
        .map(|a| a.linearity_y.odd)
}

/// Share of the nominal's odd-line residual above the noise that `model`'s residual no
/// longer holds [-] (1: all of it explained, 0: none, below 0: more left); `None` when the
/// nominal's stands less than [`ODD_RESIDUAL_ABOVE_NOISE_DB`] above the noise. The noise is
/// the nominal's (the measurement's period-to-period spread): a simulation that does not
/// repeat from period to period spreads its own residual, and that is no explanation
/// (bench case 10, an extra mode 60 points below the nominal).
pub fn odd_explained(nominal: &ClassLevel, model: &ClassLevel) -> Option<f64> {
    let noise = 10f64.powf(nominal.noise_db / 10.0);
    let excess = |c: &ClassLevel| 10f64.powf(c.level_db / 10.0) - noise;
    (nominal.vs_noise_db >= ODD_RESIDUAL_ABOVE_NOISE_DB && excess(nominal) > 0.0)
        .then(|| 1.0 - excess(model).max(0.0) / excess(nominal))
}

/// The odd-line residual a model leaves against the noise [dB], when the nominal's stands
/// `nominal_db` above it and the model removes `share` of the nominal's excess
/// ([`odd_explained`]): `10 log10(1 + (1 − share)(10^(nominal_db/10) − 1))`.
pub fn odd_left_db(nominal_db: f64, share: f64) -> f64 {
    let excess = 10f64.powf(nominal_db / 10.0) - 1.0;
    10.0 * (1.0 + (1.0 - share.clamp(0.0, 1.0)) * excess.max(0.0)).log10()
}

/// Below this share of the nominal's odd-line residual removed ([`odd_explained`]) an
/// answer leaves the odd distortion of the data unexplained. The right answers of the
/// bench's nonlinear cases remove 47 % (backlash at 0.014 rad RMS, case 21) to 100 %; a
/// backlash answered for a stiffening spring whose simulation is chaotic removes 3 %
/// (case 72).
pub const ODD_EXPLAINED_DOUBT: f64 = 0.25;

/// From this share of the nominal's odd-line residual removed ([`odd_explained`]) a single
/// explains the odd distortion of the data: most of it.
pub const ODD_EXPLAINED_MOST: f64 = 0.5;

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

    /// A stiffening spring's odd distortion: the linear joint's simulation leaves it at the
    /// non-excited odd lines far above the noise, the true model's removes it.
    #[test]
    fn the_true_model_removes_the_odd_residual_the_linear_one_leaves() {
        use crate::data::ExcitationConfig;
        use crate::diagnose::metric::{DrivenModel, Measured, DEFAULT_BAND_HZ};
        use crate::model::effects::{Effect, NonlinearStiffness};
        use crate::sim::SimConfig;
        let cfg = SimConfig {
            effects: vec![Effect::NonlinearStiffness(NonlinearStiffness { k3: 3e13 })],
            ..SimConfig::default()
        };
        let exc = ExcitationConfig {
            periods: 3,
            rms_rad: 0.05,
            ..ExcitationConfig::paper_default()
        };
        let (_, val) = crate::test_support::est_val_captures(&cfg, &exc, 7);
        let theta_of = |effects: Vec<Effect>| {
            let model = DrivenModel {
                plant: cfg.plant,
                effects,
                tau_c: cfg.controller.current_loop_tau,
                offset: 0.0,
            };
            Measured::new(&val.data, DEFAULT_BAND_HZ, 1000)
                .score(&model, &val.data, 1)
                .unwrap()
                .driven
                .theta_m
        };
        let linear = odd_residual(&val, &theta_of(Vec::new()), 1).unwrap();
        let truth = odd_residual(&val, &theta_of(cfg.effects.clone()), 1).unwrap();
        assert!(
            linear.vs_noise_db > ODD_RESIDUAL_ABOVE_NOISE_DB,
            "{linear:?}"
        );
        let share = odd_explained(&linear, &truth).unwrap();
        assert!(share > 0.8, "true model removes {share}");
        let none = odd_explained(&linear, &linear).unwrap();
        assert!(none.abs() < 1e-9, "{none}");
        // a capture without the excitation it states has no lines to read
        let mut bare = val.clone();
        bare.excitation = None;
        assert!(odd_residual(&bare, &theta_of(Vec::new()), 1).is_none());
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

    /// What a model leaves of the nominal's odd distortion: all of it when it removes
    /// nothing, the noise alone when it removes all, and about 3 dB less when it removes
    /// half of a residual far above the noise (the loop is then still needed).
    #[test]
    fn the_odd_distortion_left_falls_with_the_share_removed() {
        assert!((odd_left_db(22.3, 0.0) - 22.3).abs() < 1e-9);
        assert!(odd_left_db(22.3, 1.0).abs() < 1e-9);
        let half = odd_left_db(22.3, 0.5);
        assert!((half - (22.3 - 3.0103)).abs() < 0.05, "{half}");
        assert!(half >= ODD_RESIDUAL_ABOVE_NOISE_DB);
        assert!(odd_left_db(12.0, 0.5) < ODD_RESIDUAL_ABOVE_NOISE_DB);
        assert_eq!(odd_left_db(22.3, -0.4), odd_left_db(22.3, 0.0));
    }
}
