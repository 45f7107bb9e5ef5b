//! The gap metric of the diagnosis, one definition used everywhere ([`METRIC_NAME`]): the
//! toolbox FIT `100·(1 − ‖y − ŷ‖/‖y − mean y‖)` of the motor velocity (backward difference
//! of `θ_m`) after one causal Butterworth band-pass ([`band_pass`], [`DEFAULT_BAND_HZ`])
//! applied alike to the measured and the simulated velocity; the simulated one comes from
//! the simulator's exact laws driven by the measured torque ([`simulate_fit`]).

use crate::data::IdData;
use crate::ident::linalg::{butter_highpass_sos, butter_lowpass_sos, SosBank};
use crate::ident::nonlinear::{interval_velocity, sim_plant, NlFit};
use crate::ident::validate::fit_percent;
use crate::model::effects::Effect;
use crate::model::params::Plant;
use crate::sim::{simulate_driven, DrivenOutput, DrivenStart};

/// Name of the gap metric, as every output states it.
pub const METRIC_NAME: &str = "band-passed motor-velocity FIT [%]: toolbox FIT of the motor \
     velocity (backward difference of θ_m) through a causal Butterworth band-pass 1–150 Hz \
     applied to measured and simulated alike, the model simulated with the simulator's exact \
     laws from the measured torque";

/// Band of the gap metric [Hz]: above the slow torque disturbances a position loop rejects
/// (and the drift they leave in an open-loop simulation), below the encoder's quantisation
/// noise that the velocity's difference amplifies.
pub const DEFAULT_BAND_HZ: (f64, f64) = (1.0, 150.0);

/// The band-pass of the gap metric: a second-order Butterworth high-pass at `band.0`
/// followed by a second-order Butterworth low-pass at `band.1`, causal, each section
/// started in the steady state of the first sample. The low-pass is left out when
/// `band.1` is at or above 0.45 of the sample rate.
pub fn band_pass(x: &[f64], ts: f64, band: (f64, f64)) -> Vec<f64> {
    let mut sos = Vec::new();
    if band.0 > 0.0 {
        sos.extend(butter_highpass_sos(2, band.0, ts));
    }
    if band.1 * ts < 0.45 {
        sos.extend(butter_lowpass_sos(2, band.1, ts));
    }
    let mut bank = SosBank::new(sos, 1);
    x.iter()
        .map(|&v| {
            let mut s = [v];
            bank.push(&mut s);
            s[0]
        })
        .collect()
}

/// The band-passed motor velocity of a motor-angle record.
pub fn velocity_band(theta: &[f64], ts: f64, band: (f64, f64)) -> Vec<f64> {
    band_pass(&interval_velocity(theta, ts), ts, band)
}

/// A plant with effects as the simulator runs it open loop.
#[derive(Clone, Debug, PartialEq)]
pub struct DrivenModel {
    /// the simulator's plant
    pub plant: Plant,
    /// its effects
    pub effects: Vec<Effect>,
    /// current-loop lag [s] (0: none)
    pub tau_c: f64,
    /// constant torque offset added to the measured torque [N·m]
    pub offset: f64,
}

impl DrivenModel {
    /// The model of a nonlinear fit (structure, effects, lag, offset).
    pub fn of_fit(fit: &NlFit) -> DrivenModel {
        DrivenModel {
            plant: sim_plant(&fit.model, &fit.plant),
            effects: fit.model.effects.clone(),
            tau_c: fit.model.tau_c,
            offset: fit.get("offset").unwrap_or(0.0),
        }
    }
}

/// `model` driven by the measured torque of `data` (plus its offset), from rest at the
/// first measured angle, with the simulator's exact laws.
///
/// # Errors
/// The simulator's refusal, in words.
pub fn simulate_fit(model: &DrivenModel, data: &IdData) -> Result<DrivenOutput, String> {
    let u: Vec<f64> = data.u.iter().map(|u| u + model.offset).collect();
    // no current loop in the model: a lag far below the sample interval
    let tc = if model.tau_c > 0.0 { model.tau_c } else { 1e-9 };
    let start = DrivenStart::Rest {
        theta_m: data.y.first().copied().unwrap_or(0.0),
    };
    let out = simulate_driven(&model.plant, &model.effects, tc, data.ts, &u, &start)
        .map_err(|e| format!("simulation with the exact laws: {e}"))?;
    if out.theta_m.iter().any(|v| !v.is_finite()) {
        return Err("the simulation with the exact laws is not finite".into());
    }
    Ok(out)
}

/// A model's score on one record under the gap metric.
#[derive(Clone, Debug, PartialEq)]
pub struct Scored {
    /// band-passed simulated velocity over the whole record [rad/s]
    pub velocity: Vec<f64>,
    /// gap metric over the scored range [%]
    pub fit: f64,
    /// gap metric on each of the equal segments of the scored range [%]
    pub segments: Vec<f64>,
    /// toolbox FIT of `θ_m` (exact laws, unfiltered) over the whole record [%]
    pub angle_fit: f64,
    /// the driven simulation (deflection, velocity)
    pub driven: DrivenOutput,
}

/// The measured side of the gap metric on one record.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// band-passed measured velocity [rad/s]
    pub velocity: Vec<f64>,
    /// first scored sample (the start-up of the filters and of the simulation left out)
    pub skip: usize,
    /// band [Hz]
    pub band: (f64, f64),
}

impl Measured {
    /// The measured band-passed velocity of `data`, scored from `skip` on.
    pub fn new(data: &IdData, band: (f64, f64), skip: usize) -> Measured {
        Measured {
            velocity: velocity_band(&data.y, data.ts, band),
            skip: skip.min(data.len().saturating_sub(2)),
            band,
        }
    }

    /// The `k` equal segments of the scored range.
    pub fn segment_ranges(&self, k: usize) -> Vec<std::ops::Range<usize>> {
        let n = self.velocity.len() - self.skip;
        let k = k.max(1);
        (0..k)
            .map(|i| self.skip + i * n / k..self.skip + (i + 1) * n / k)
            .collect()
    }

    /// Scores `model` on `data` (the record `self` was made from).
    ///
    /// # Errors
    /// The simulator's refusal or a constant record, in words.
    pub fn score(&self, model: &DrivenModel, data: &IdData, k: usize) -> Result<Scored, String> {
        let driven = simulate_fit(model, data)?;
        let velocity = velocity_band(&driven.theta_m, data.ts, self.band);
        let s = self.skip;
        let fit = fit_percent(&self.velocity[s..], &velocity[s..]).map_err(|e| e.to_string())?;
        let segments = self
            .segment_ranges(k)
            .into_iter()
            .map(|r| fit_percent(&self.velocity[r.clone()], &velocity[r]).unwrap_or(f64::NAN))
            .collect();
        let angle_fit = fit_percent(&data.y, &driven.theta_m).unwrap_or(f64::NAN);
        Ok(Scored {
            velocity,
            fit,
            segments,
            angle_fit,
            driven,
        })
    }
}

/// Gain of `better` over `base` on the segments: (mean, standard error of the mean).
pub fn segment_gain(better: &[f64], base: &[f64]) -> (f64, f64) {
    let g: Vec<f64> = better.iter().zip(base).map(|(a, b)| a - b).collect();
    let k = g.len().max(1) as f64;
    let mean = g.iter().sum::<f64>() / k;
    let var = if g.len() > 1 {
        g.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (k - 1.0)
    } else {
        f64::INFINITY
    };
    (mean, (var / k).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_pass_keeps_the_band_and_removes_a_constant() {
        let ts = 5e-4;
        let n = 20000;
        let tone = |f: f64| -> Vec<f64> {
            (0..n)
                .map(|k| (2.0 * std::f64::consts::PI * f * k as f64 * ts).sin())
                .collect()
        };
        let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
        let mid = band_pass(&tone(20.0), ts, DEFAULT_BAND_HZ);
        assert!((rms(&mid[4000..]) / rms(&tone(20.0)) - 1.0).abs() < 0.02);
        let high = band_pass(&tone(600.0), ts, DEFAULT_BAND_HZ);
        assert!(rms(&high[4000..]) < 0.1);
        let dc = band_pass(&vec![3.0; n], ts, DEFAULT_BAND_HZ);
        assert!(dc.iter().all(|v| v.abs() < 1e-9));
    }

    #[test]
    fn segment_gain_is_the_mean_and_its_standard_error() {
        let (m, se) = segment_gain(&[12.0, 13.0, 11.0, 12.0], &[10.0; 4]);
        assert!((m - 2.0).abs() < 1e-12);
        assert!((se - (2.0f64 / 3.0).sqrt() / 2.0).abs() < 1e-12);
    }
}
