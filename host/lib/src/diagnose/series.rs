//! The series behind the figures of a diagnosis report ([`DiagnosisSeries`]): kept apart
//! from [`super::Diagnosis`] so that its JSON stays small. Everything here is computed
//! from the fits and records the diagnosis already holds; nothing is fitted again.
//!
//! - the measured FRF with its σ and the nominal's response ([`nominal_response`]: the
//!   continuous linear model of the structure and current-loop lag, ZOH-sampled, `θ_m[k]`
//!   the response to `u[..k]` as in the driven simulation);
//! - the amplitude spectral densities of the measured band-passed velocity and of the
//!   residuals ([`asd`], Welch, Hann window, half overlap);
//! - the residual binned against motor velocity, gearbox deflection and motor angle
//!   ([`residual_map`]);
//! - the moving RMS of the residuals and the stretch where the nominal's is largest.

use nalgebra::RowDVector;
use rustfft::{num_complex::Complex64, FftPlanner};

use super::fits::Fitted;
use super::metric::{DrivenModel, Measured};
use crate::data::Dataset;
use crate::ident::frf::FrfAnalysis;
use crate::ident::ss::ContinuousSs;
use crate::ident::validate::{BodeCurve, FrfBand};
use crate::model::plant::Mechanism;

/// Bins of a [`ResidualMap`].
pub const MAP_BINS: usize = 40;
/// Fewest samples for a bin of a [`ResidualMap`] to be shown.
pub const MAP_MIN_COUNT: usize = 10;
/// Window of the moving RMS [s].
pub const MOVING_RMS_S: f64 = 0.05;
/// Length of the stretch shown in the before/after time plot [s].
pub const WINDOW_S: f64 = 1.0;

/// The measured FRF of one periodic capture and the nominal's response over it.
#[derive(Clone, Debug, PartialEq)]
pub struct FrfFigure {
    /// capture name
    pub capture: String,
    /// FRF u → θ_m at the excited lines with its σ [rad/(N·m)]
    pub frf: FrfBand,
    /// the nominal's response on a log grid over the FRF's band [rad/(N·m)]
    pub nominal: BodeCurve,
}

/// Amplitude spectral densities on one frequency grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Spectra {
    /// frequency [Hz]
    pub freq_hz: Vec<f64>,
    /// measured band-passed motor velocity [rad/s/√Hz]
    pub measured: Vec<f64>,
    /// residual of the nominal [rad/s/√Hz]
    pub nominal: Vec<f64>,
    /// residual of the best model, when one is named [rad/s/√Hz]
    pub best: Option<Vec<f64>>,
}

/// The residual binned against one operating variable.
#[derive(Clone, Debug, PartialEq)]
pub struct ResidualMap {
    /// the variable with its unit, as an axis label
    pub variable: String,
    /// bin centres [variable unit]
    pub centers: Vec<f64>,
    /// mean residual per bin [rad/s] (NaN below [`MAP_MIN_COUNT`] samples)
    pub mean: Vec<f64>,
    /// RMS residual per bin [rad/s] (NaN below [`MAP_MIN_COUNT`] samples)
    pub rms: Vec<f64>,
    /// RMS residual over all samples [rad/s]
    pub overall_rms: f64,
}

/// Series of a diagnosis for its report ([`super::diagnose_with_series`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnosisSeries {
    /// sample interval [s]
    pub ts: f64,
    /// time of the first scored sample [s]
    pub t0: f64,
    /// validation capture name
    pub validation: String,
    /// measured band-passed motor velocity over the scored range [rad/s]
    pub measured: Vec<f64>,
    /// the nominal's band-passed velocity over the scored range [rad/s]
    pub nominal: Vec<f64>,
    /// the best model's name and band-passed velocity over the scored range [rad/s]
    pub best: Option<(String, Vec<f64>)>,
    /// FRF of the validation capture (else of the first estimation capture) when periodic
    pub frf: Option<FrfFigure>,
    /// the line analysis of each periodic capture (name, analysis)
    pub lines: Vec<(String, FrfAnalysis)>,
    /// residual and measured spectra
    pub spectra: Spectra,
    /// the nominal's residual against motor velocity, gearbox deflection, motor angle
    pub maps: Vec<ResidualMap>,
    /// moving-RMS step [s] (window [`MOVING_RMS_S`])
    pub rms_step_s: f64,
    /// moving RMS of the nominal's residual [rad/s]
    pub nominal_rms: Vec<f64>,
    /// moving RMS of the best model's residual [rad/s]
    pub best_rms: Option<Vec<f64>>,
    /// the stretch of [`WINDOW_S`] (indices into the scored range) where the nominal's
    /// residual is largest
    pub window: std::ops::Range<usize>,
}

/// Frequency response u → θ_m [rad/(N·m)] of the linear part of `model` (structure,
/// extra modes, current-loop lag) sampled with a ZOH every `ts` [s], at `f_hz` [Hz].
pub fn nominal_response(model: &DrivenModel, ts: f64, f_hz: &[f64]) -> Vec<Complex64> {
    let mech = Mechanism::new(&model.plant, &model.effects);
    let tc = if model.tau_c > 0.0 { model.tau_c } else { 1e-9 };
    let (f, g) = mech.linear_model(tc);
    let n = f.nrows();
    let mut h = RowDVector::zeros(n);
    h[0] = 1.0;
    ContinuousSs {
        f,
        g: g.column(0).into_owned(),
        h,
        d: 0.0,
    }
    .zoh(ts)
    .freq_response(f_hz)
}

/// `n` frequencies spaced evenly on a log axis from `lo` to `hi` [Hz].
pub fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n.max(2) - 1) as f64).exp())
        .collect()
}

/// Welch amplitude spectral density of `x` sampled every `ts` [s]: Hann-windowed segments
/// of `seg` samples (at most the record), half overlap; (frequencies [Hz], ASD [x unit/√Hz]).
pub fn asd(x: &[f64], ts: f64, seg: usize) -> (Vec<f64>, Vec<f64>) {
    let seg = seg.min(x.len()).max(2);
    let w: Vec<f64> = (0..seg)
        .map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / seg as f64).cos())
        .collect();
    let w2: f64 = w.iter().map(|v| v * v).sum();
    let fft = FftPlanner::new().plan_fft_forward(seg);
    let mut psd = vec![0.0; seg / 2 + 1];
    let mut count = 0usize;
    let mut start = 0;
    while start + seg <= x.len() {
        let mut buf: Vec<Complex64> = x[start..start + seg]
            .iter()
            .zip(&w)
            .map(|(v, w)| Complex64::new(v * w, 0.0))
            .collect();
        fft.process(&mut buf);
        for (p, b) in psd.iter_mut().zip(&buf) {
            *p += b.norm_sqr();
        }
        count += 1;
        start += seg / 2;
    }
    let scale = 2.0 * ts / (w2 * count.max(1) as f64);
    let freq = (0..psd.len())
        .map(|k| k as f64 / (seg as f64 * ts))
        .collect();
    (freq, psd.iter().map(|p| (p * scale).sqrt()).collect())
}

/// `residual` binned in [`MAP_BINS`] equal bins of `x` between its 0.5 % and 99.5 %
/// quantiles; `variable` names `x` with its unit.
pub fn residual_map(variable: &str, x: &[f64], residual: &[f64]) -> ResidualMap {
    let mut s: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| s.get((p * (s.len().max(1) - 1) as f64) as usize).copied();
    let (lo, hi) = match (q(0.005), q(0.995)) {
        (Some(a), Some(b)) if b > a => (a, b),
        (Some(a), _) => (a - 0.5, a + 0.5),
        _ => (0.0, 1.0),
    };
    let width = (hi - lo) / MAP_BINS as f64;
    let mut sum = vec![0.0; MAP_BINS];
    let mut sum2 = vec![0.0; MAP_BINS];
    let mut n = vec![0usize; MAP_BINS];
    for (v, r) in x.iter().zip(residual) {
        if !(v.is_finite() && r.is_finite()) || *v < lo || *v > hi {
            continue;
        }
        let b = (((v - lo) / width) as usize).min(MAP_BINS - 1);
        sum[b] += r;
        sum2[b] += r * r;
        n[b] += 1;
    }
    let stat = |f: &dyn Fn(usize) -> f64| -> Vec<f64> {
        (0..MAP_BINS)
            .map(|b| {
                if n[b] >= MAP_MIN_COUNT {
                    f(b)
                } else {
                    f64::NAN
                }
            })
            .collect()
    };
    ResidualMap {
        variable: variable.into(),
        centers: (0..MAP_BINS)
            .map(|b| lo + (b as f64 + 0.5) * width)
            .collect(),
        mean: stat(&|b| sum[b] / n[b] as f64),
        rms: stat(&|b| (sum2[b] / n[b] as f64).sqrt()),
        overall_rms: (residual.iter().map(|r| r * r).sum::<f64>() / residual.len().max(1) as f64)
            .sqrt(),
    }
}

/// Moving RMS of `x` over windows of `win` samples, one value every `step` samples.
pub fn moving_rms(x: &[f64], win: usize, step: usize) -> Vec<f64> {
    let (win, step) = (win.max(1), step.max(1));
    (0..x.len().saturating_sub(win - 1))
        .step_by(step)
        .map(|i| (x[i..i + win].iter().map(|v| v * v).sum::<f64>() / win as f64).sqrt())
        .collect()
}

/// The `len` consecutive samples of `x` with the largest energy.
pub fn loudest_window(x: &[f64], len: usize) -> std::ops::Range<usize> {
    let len = len.min(x.len());
    if len == 0 {
        return 0..0;
    }
    let mut e: f64 = x[..len].iter().map(|v| v * v).sum();
    let (mut best, mut at) = (e, 0);
    for i in len..x.len() {
        e += x[i] * x[i] - x[i - len] * x[i - len];
        if e > best {
            best = e;
            at = i + 1 - len;
        }
    }
    at..at + len
}

/// The report's series of one diagnosis ([`DiagnosisSeries`]); `residual` is the nominal's
/// over the scored range, `angle_order` the order of its pattern against the motor angle.
pub(super) fn series_of(
    measured: &Measured,
    nominal: &Fitted,
    best: Option<(String, Vec<f64>)>,
    val: &Dataset,
    analyses: &[(String, FrfAnalysis)],
    residual: &[f64],
    angle_order: u32,
) -> DiagnosisSeries {
    let s = measured.skip;
    let ts = val.data.ts;
    let meas = measured.velocity[s..].to_vec();
    let best = best.map(|(n, v)| (n, v[s..].to_vec()));
    let best_res: Option<Vec<f64>> = best
        .as_ref()
        .map(|(_, v)| meas.iter().zip(v).map(|(a, b)| a - b).collect());
    // 2 s segments: 0.5 Hz lines, below the metric's 1 Hz edge
    let seg = ((2.0 / ts) as usize).min(meas.len() / 2).max(16);
    let (freq_hz, measured_asd) = asd(&meas, ts, seg);
    let spectra = Spectra {
        freq_hz,
        measured: measured_asd,
        nominal: asd(residual, ts, seg).1,
        best: best_res.as_ref().map(|r| asd(r, ts, seg).1),
    };
    let model = DrivenModel::of_fit(&nominal.fit);
    let frf = analyses
        .iter()
        .rev()
        .find(|(n, _)| *n == val.name)
        .or(analyses.first())
        .and_then(|(name, a)| {
            let frf = crate::ident::validate::FrfBand::from(&a.frf);
            let pos = frf.freq_hz.iter().copied().filter(|f| *f > 0.0);
            let lo = pos.clone().fold(f64::INFINITY, f64::min);
            let hi = pos.fold(0.0, f64::max);
            if !(lo.is_finite() && hi > lo) {
                return None;
            }
            let grid = log_grid(lo / 1.1, (hi * 1.1).min(0.49 / ts), 400);
            let response = nominal_response(&model, ts, &grid);
            Some(FrfFigure {
                capture: name.clone(),
                frf,
                nominal: crate::ident::validate::BodeCurve {
                    name: format!("nominal {}", model.plant.kind.label()),
                    freq_hz: grid,
                    response,
                },
            })
        });
    let driven = &nominal.scored.driven;
    let mut maps = vec![residual_map(
        "motor velocity ω_m of the nominal [rad/s]",
        &driven.omega_m[s..],
        residual,
    )];
    if driven.gearbox_deflection[s..].iter().any(|d| *d != 0.0) {
        maps.push(residual_map(
            "gearbox deflection δ of the nominal [rad]",
            &driven.gearbox_deflection[s..],
            residual,
        ));
    }
    let (angle, label) = if angle_order > 0 {
        let p = 2.0 * std::f64::consts::PI / angle_order as f64;
        (
            val.data.y[s..].iter().map(|t| t.rem_euclid(p)).collect::<Vec<_>>(),
            format!("measured motor angle θ_m modulo 2π/{angle_order} (the residual's order-{angle_order} pattern) [rad]"),
        )
    } else {
        (
            val.data.y[s..].to_vec(),
            "measured motor angle θ_m [rad]".to_string(),
        )
    };
    maps.push(residual_map(&label, &angle, residual));
    let win = ((MOVING_RMS_S / ts).round() as usize).max(1);
    let step = (win / 2).max(1);
    DiagnosisSeries {
        ts,
        t0: s as f64 * ts,
        validation: val.name.clone(),
        nominal: nominal.scored.velocity[s..].to_vec(),
        best,
        frf,
        lines: analyses.to_vec(),
        spectra,
        maps,
        rms_step_s: step as f64 * ts,
        nominal_rms: moving_rms(residual, win, step),
        best_rms: best_res.as_ref().map(|r| moving_rms(r, win, step)),
        window: loudest_window(residual, (WINDOW_S / ts).round() as usize),
        measured: meas,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asd_of_a_tone_integrates_to_its_power() {
        let ts = 5e-4;
        let x: Vec<f64> = (0..20000)
            .map(|k| 2.0 * (2.0 * std::f64::consts::PI * 40.0 * k as f64 * ts).sin())
            .collect();
        let (f, a) = asd(&x, ts, 2048);
        let df = f[1] - f[0];
        let power: f64 = a.iter().map(|v| v * v * df).sum();
        // a sine of amplitude 2 has power 2
        assert!((power / 2.0 - 1.0).abs() < 0.02, "{power}");
        let peak = (0..a.len()).max_by(|&i, &j| a[i].total_cmp(&a[j])).unwrap();
        assert!((f[peak] - 40.0).abs() < df, "{}", f[peak]);
    }

    #[test]
    fn residual_map_shows_where_the_residual_sits() {
        let x: Vec<f64> = (0..10000).map(|k| (k as f64 * 0.001).sin()).collect();
        let r: Vec<f64> = x
            .iter()
            .map(|v| if v.abs() < 0.1 { 1.0 } else { 0.0 })
            .collect();
        let m = residual_map("x [-]", &x, &r);
        let mid = m
            .centers
            .iter()
            .position(|c| c.abs() < 0.05)
            .expect("a bin near zero");
        assert!((m.rms[mid] - 1.0).abs() < 1e-12, "{m:?}");
        assert_eq!(m.rms[0], 0.0);
        assert_eq!(loudest_window(&r, 10).len(), 10);
        assert!(r[loudest_window(&r, 10)].iter().all(|v| *v == 1.0));
    }
}
