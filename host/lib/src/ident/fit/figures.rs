//! The data behind the figures of a fit (`jointid fit --plot`, `validate --plot`, `demo`):
//! the records `compare.svg` draws ([`CompareRecord`]: measured against the model's
//! output under the FIT printed for them), the Bode plot's measured FRF and model curves
//! ([`bode_figure`]) and the nonlinear fit's motor-velocity window ([`VelocityFigure`]).
//! Only numbers: the command line draws and writes them (`jointid::report` has the SVG).
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use thiserror::Error;

use super::{log_grid, FitData, FitError, Fitted};
use crate::data::{Dataset, IdData};
use crate::ident::frf::analyze_dataset;
use crate::ident::nonlinear::{interval_velocity, simulate_exact, NlError, NlFit};
use crate::ident::validate::{BodeCurve, FrfBand};

/// One record of `compare.svg`: measured and simulated output and the FIT the command
/// printed for them.
#[derive(Clone, Debug, PartialEq)]
pub struct CompareRecord {
    /// `estimation: FILE`, `validation: FILE`
    pub title: String,
    /// sample interval [s]
    pub ts: f64,
    /// measured output (or its rate, [`Compared::Velocity`])
    pub y: Vec<f64>,
    /// the model's output (or its rate)
    pub y_hat: Vec<f64>,
    /// the FIT [%] printed for it
    pub fit: f64,
}

/// What the model's output in `compare.svg` is, and under which FIT it is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compared {
    /// the output simulated from the measured input, under the toolbox FIT (the headline)
    Simulated,
    /// as [`Compared::Simulated`], the toolbox FIT beside a velocity FIT headline
    SimulatedToolbox,
    /// one averaged period at the reliable excited lines, under the periodic FIT
    Periodic,
    /// the interval-mean velocity simulated from rest, both through the fit's high-pass,
    /// under the velocity FIT ([`Fitted::velocity_fit_signals`])
    Velocity,
}

/// A figure's record could not be computed.
#[derive(Debug, Error)]
#[error("{title}: {source}")]
pub struct FigureError {
    /// the record's title (`estimation: FILE`)
    pub title: String,
    /// why
    #[source]
    pub source: FitError,
}

/// A record of `compare.svg` under the velocity FIT `fit` [%]: the signals it compares
/// ([`Fitted::velocity_fit_signals`]).
///
/// # Errors
/// [`FigureError`] naming `title` when the record cannot be simulated.
pub fn velocity_record(
    fitted: &Fitted,
    data: &FitData,
    title: String,
    fit: f64,
) -> Result<CompareRecord, FigureError> {
    match fitted.velocity_fit_signals(data) {
        Ok((y, y_hat)) => Ok(CompareRecord {
            title,
            ts: fitted.ts,
            y,
            y_hat,
            fit,
        }),
        Err(source) => Err(FigureError { title, source }),
    }
}

/// A record of `compare.svg`: `data`'s prepared output and `fitted`'s simulation on it
/// ([`Fitted::simulate_on`], the one the toolbox FIT `fit` [%] is computed from).
///
/// # Errors
/// [`FigureError`] naming `title` when the record cannot be simulated.
pub fn simulated_record(
    fitted: &Fitted,
    data: &FitData,
    title: String,
    fit: f64,
) -> Result<CompareRecord, FigureError> {
    match fitted.simulate_on(data) {
        Ok(y_hat) => Ok(CompareRecord {
            title,
            ts: data.prepared().ts,
            y: data.prepared().y.clone(),
            y_hat,
            fit,
        }),
        Err(source) => Err(FigureError { title, source }),
    }
}

/// The Bode plot's contents: the measured FRF with its σ (periodic data only) and the
/// models' responses on a logarithmic grid.
#[derive(Clone, Debug, PartialEq)]
pub struct BodeFigure {
    /// the FRF of the record at its lines up to the highest frequency drawn (`None` when
    /// the record holds no whole periods)
    pub band: Option<FrfBand>,
    /// each model's response on 400 frequencies from the FRF's first line (else 0.1 Hz)
    /// up to 0.45 / Ts of the coarsest model
    pub curves: Vec<BodeCurve>,
}

/// The Bode plot of `models` over the FRF of `ds` (`settle_periods` whole periods dropped
/// as transient; no FRF when `ds` is not periodic), up to 0.45 / Ts of the coarsest model.
pub fn bode_figure(ds: &Dataset, settle_periods: usize, models: &[&Fitted]) -> BodeFigure {
    let fmax = models
        .iter()
        .map(|m| 0.45 / m.ts)
        .fold(0.45 / ds.data.ts, f64::min);
    let band = analyze_dataset(ds, settle_periods).ok().map(|a| {
        let b = FrfBand::from(&a.frf);
        let keep: Vec<usize> = (0..b.freq_hz.len())
            .filter(|&i| b.freq_hz[i] > 0.0 && b.freq_hz[i] <= fmax)
            .collect();
        FrfBand {
            freq_hz: keep.iter().map(|&i| b.freq_hz[i]).collect(),
            g: keep.iter().map(|&i| b.g[i]).collect(),
            sigma: keep.iter().map(|&i| b.sigma[i]).collect(),
        }
    });
    let fmin = band
        .as_ref()
        .and_then(|b| b.freq_hz.first().copied())
        .unwrap_or(0.1);
    let grid = log_grid(fmin, fmax, 400);
    let curves = models
        .iter()
        .map(|m| BodeCurve {
            name: m.spec.name(),
            freq_hz: grid.clone(),
            response: m.freq_response(&grid),
        })
        .collect();
    BodeFigure { band, curves }
}

/// One second of a nonlinear fit's motor velocity: measured against the fitted model's,
/// simulated with the simulator's exact laws from the measured torque.
#[derive(Clone, Debug, PartialEq)]
pub struct VelocityFigure {
    /// the record drawn (the validation record when there is one)
    pub record: String,
    /// time of the first sample drawn, from the record's start [s]
    pub start_s: f64,
    /// sample interval [s]
    pub ts: f64,
    /// measured interval-mean motor velocity [rad/s]
    pub measured: Vec<f64>,
    /// the model's [rad/s]
    pub model: Vec<f64>,
    /// measured − model [rad/s]
    pub residual: Vec<f64>,
}

impl VelocityFigure {
    /// The window of one second (at least two samples) in the middle of `data` (the
    /// record `record`) for the fit `fit`.
    ///
    /// # Errors
    /// [`NlError`] when the model cannot be simulated on `data`.
    pub fn new(fit: &NlFit, data: &IdData, record: &str) -> Result<Self, NlError> {
        let theta = simulate_exact(fit, data)?;
        let v = interval_velocity(&data.y, data.ts);
        let vh = interval_velocity(&theta, data.ts);
        let n = v.len();
        let w = ((1.0 / data.ts).round() as usize).clamp(2, n.max(2));
        let a = (n / 2).saturating_sub(w / 2);
        let b = (a + w).min(n);
        Ok(VelocityFigure {
            record: record.to_string(),
            start_s: a as f64 * data.ts,
            ts: data.ts,
            measured: v[a..b].to_vec(),
            model: vh[a..b].to_vec(),
            residual: v[a..b].iter().zip(&vh[a..b]).map(|(x, y)| x - y).collect(),
        })
    }
}
