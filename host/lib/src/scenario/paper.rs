//! The identification experiment of seed 000 §6 (Table 2) on the simulated
//! IRB1400-like joint, and the software-in-the-loop path the demo takes:
//! simulator → firmware wire encoder → byte stream → decoder → dataset.
//!
//! Experiment (seed 000 §6): the joint runs in its own position loop; the
//! estimation run is excited by the special odd multisine (seed 000 eq. (4),
//! f0 = 0.4 Hz, lines up to 121.6 Hz, first-order Butterworth amplitude
//! shape with 50 Hz cut-off), the validation run by Gaussian band-limited
//! noise of the same RMS and band; both 7.5 s at 2 kHz (the paper's "one
//! period" of 7.5 s is three periods of the 0.4 Hz multisine here, one more
//! period before them is dropped as transient), decimated by 10 before
//! identification. Fitted: the 11th-order black box on the decimated data;
//! the three-mass (eq. (6)) and four-mass (eq. (7)) models, as `jointid fit`
//! does by default, on the FRF of the estimation run at the capture rate
//! ([`crate::ident::sml`], sample maximum likelihood, the σ that `fit`
//! reports) behind the simulator's known current-loop lag (the gear ratio is
//! taken as known the same way; the delay is estimated), or, when the
//! estimation run is not periodic, in the time domain, started on the
//! decimated data and refined at the capture rate
//! ([`crate::ident::fit::FitData`], [`crate::ident::fit::DrivenModel`]);
//! every FIT on the decimated data; printed: FIT (toolbox `compare`
//! definition) on estimation and validation data, as in Table 2, plus the
//! resonance / anti-resonance frequencies against the simulator's truth
//! and, where the model structure is the simulator's, parameter errors in
//! per cent and in reported standard deviations.
//!
//! Truth: the simulator's default four-mass joint ([`crate::model::params`];
//! the parallel mass makes the double notch near 17 Hz that needs a black
//! box of order 11 in the paper), default controller and encoder (2^17
//! counts per revolution, white noise on θm), current loop. Two defaults of
//! the simulator are switched off, because the FIT of an angle output is a
//! simulation of a double integrator from `u`: the low-frequency torque
//! disturbance and white noise on the recorded `u` are integrated twice and
//! swamp every FIT, the true model's included (measured on seed 1 with
//! both on: true model −3000 %; with the disturbance off and `u` noise on:
//! −270 %). The torque reference `u` is the controller's own number, so no
//! measurement noise on it is also the physical case of seed 000 Fig. 2.
//! The numbers are those of this simulated joint, not the paper's robot:
//! the paper's 57.8 / 58.0 / 74.8 come from a real arm with more dynamics
//! than any of the three models.
//!
//! Wire path (../shared/DESIGN.md §8, software in the loop): the simulated samples
//! become counts with the session's [`Scale`] and are streamed by the
//! simulated board ([`crate::sim::board::encode_session`] with
//! [`wire_options`]), written as a `.jcap` by the capture module's writer
//! ([`crate::capture::jcap::write_stream`]) and decoded back by the
//! capture module (the reference regenerated from the header's excitation
//! and checked against each batch's reference CRC), exactly as a capture
//! from a board is.
// Units in brackets (`[s]`, `[Hz]`, `[%]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::path::Path;
use std::time::Instant;

use jointid_core::excitation::{ExcitationConfig, SignalKind};
use jointid_core::wire::Scale;
use nalgebra::{DMatrix, DVector, RowDVector};
use serde::Serialize;
use thiserror::Error;

use crate::data::{Dataset, Detrend, IdData, Prep};
use crate::ident::fit::{
    default_f_min, fit_frequency_domain, fit_prepared, FitData, FitOptions, Fitted,
};
use crate::ident::frf::analyze_dataset;
use crate::ident::grey_box::Output;
use crate::ident::ss::StateSpace;
use crate::ident::validate::fit_percent;
use crate::model::spec::{Family, ModelSpec, Structure};
use crate::sim::board::{encode_session, BoardStreamError, WireOptions};
use crate::sim::{self, Mechanism, SimConfig, SimOutput};

/// timer rate of the simulated board [Hz]
pub const TIMER_HZ: u32 = 1_000_000;

/// Why the experiment or the wire round trip failed.
#[derive(Debug, Error)]
pub enum ExperimentError {
    /// the simulator refused the configuration
    #[error("simulation: {0}")]
    Sim(#[from] sim::SimError),
    /// a frame could not be encoded
    #[error(transparent)]
    Encode(#[from] BoardStreamError),
    /// the capture could not be written or decoded
    #[error(transparent)]
    Capture(#[from] crate::capture::CaptureError),
    /// a fit failed
    #[error("{model}: {source}")]
    Fit {
        /// model name
        model: String,
        /// the fit error
        source: crate::ident::fit::FitError,
    },
    /// data preparation failed
    #[error("data: {0}")]
    Data(#[from] crate::data::DataError),
}

/// The estimation excitation: special odd multisine of seed 000 with
/// `periods` full periods (one of them is dropped as transient).
pub fn estimation_excitation(seed: u64) -> ExcitationConfig {
    ExcitationConfig {
        seed,
        periods: 4,
        ..ExcitationConfig::paper_default()
    }
}

/// The validation excitation: band-limited Gaussian noise of the same RMS,
/// amplitude shape and band as `est`, one period of three estimation
/// periods (7.5 s), other seed.
pub fn validation_excitation(est: &ExcitationConfig) -> ExcitationConfig {
    ExcitationConfig {
        kind: SignalKind::BandLimitedNoise,
        period_samples: 3 * est.period_samples,
        max_line: 3 * est.max_line,
        periods: 1,
        seed: est.seed ^ 0x5A5A_5A5A,
        ..*est
    }
}

/// Scale of the simulated board: 1e-6 N·m (the controller's torque
/// reference is a number, streamed at a resolution far below the sensor
/// noise) and 2π/2^17 rad (the encoder count) per count.
pub fn default_scale() -> Scale {
    Scale {
        torque_nm_per_count: 1e-6,
        angle_rad_per_count: (2.0 * std::f64::consts::PI / f64::from(1u32 << 17)) as f32,
    }
}

/// How the experiment's simulated board streams a run ([`crate::sim::board`]): board
/// id `0x51`, `session_id`, a [`TIMER_HZ`] timer, batches of 32 samples, no `Status`
/// messages, [`default_scale`].
pub fn wire_options(session_id: u32) -> WireOptions {
    WireOptions {
        board_id: 0x51,
        session_id,
        timer_hz: TIMER_HZ,
        batch_len: 32,
        status_every: 0,
        scale: default_scale(),
    }
}

/// Decodes a byte stream with the capture module's decoder (the path every
/// `.jcap` takes: header scale to SI, reference regenerated from the
/// header's excitation and checked against each batch's CRC) into a dataset
/// named `name`.
///
/// # Errors
/// [`ExperimentError::Capture`]: no header, excitation not regenerable, or
/// samples missing (gaps are never filled).
pub fn decode_session(stream: &[u8], name: &str) -> Result<Dataset, ExperimentError> {
    Ok(crate::capture::decode_stream(stream, &[])?.to_dataset(Path::new(name))?)
}

/// The simulated joint of the experiment (see the module docs).
pub fn paper_sim(seed: u64) -> SimConfig {
    let mut cfg = SimConfig {
        plant: sim::Plant::new(Structure::FourMass),
        seed,
        ..SimConfig::default()
    };
    cfg.sensors.disturbance = sim::Disturbance::none();
    cfg.sensors.u_noise_std = 0.0;
    cfg
}

/// The two simulated runs of the experiment.
#[derive(Clone, Debug)]
pub struct PaperRuns {
    /// the simulator configuration (the truth)
    pub sim: SimConfig,
    /// estimation excitation
    pub est_excitation: ExcitationConfig,
    /// validation excitation
    pub val_excitation: ExcitationConfig,
    /// estimation run
    pub est: SimOutput,
    /// validation run
    pub val: SimOutput,
}

/// Simulates the estimation and validation runs for `seed`.
///
/// # Errors
/// [`ExperimentError::Sim`].
pub fn paper_runs(seed: u64) -> Result<PaperRuns, ExperimentError> {
    let sim = paper_sim(seed);
    let est_excitation = estimation_excitation(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD5EE);
    let val_excitation = validation_excitation(&est_excitation);
    let est = sim::simulate_excitation(&sim, &est_excitation)?;
    let val = sim::simulate_excitation(
        &SimConfig {
            seed: seed ^ 0xABCD,
            ..sim.clone()
        },
        &val_excitation,
    )?;
    Ok(PaperRuns {
        sim,
        est_excitation,
        val_excitation,
        est,
        val,
    })
}

/// The sample range used for identification: the whole steady-state
/// periods of a periodic run (after `settle_periods`), or the full-amplitude
/// part of a noise run.
pub fn steady_range(ds: &Dataset, settle_periods: usize) -> std::ops::Range<usize> {
    match ds.excitation {
        Some(cfg) if cfg.kind == SignalKind::BandLimitedNoise => {
            let s = cfg.ramp_samples as usize;
            let n = (cfg.period_samples as usize * cfg.periods.max(1) as usize)
                .min(ds.data.len().saturating_sub(s));
            s..s + n
        }
        _ => match ds.period_layout(settle_periods) {
            Ok(l) => l.range(),
            Err(_) => 0..ds.data.len(),
        },
    }
}

/// Prepared record: the steady part, decimated by `q`.
///
/// # Errors
/// [`ExperimentError::Data`] when the part is too short to decimate.
pub fn prepared(ds: &Dataset, settle: usize, q: usize) -> Result<IdData, ExperimentError> {
    Ok(ds.data.slice(steady_range(ds, settle)).decimate(q)?)
}

/// Prepared record at both rates: the steady part at the capture rate and
/// decimated by `q` ([`FitData`]; no detrending).
///
/// # Errors
/// [`ExperimentError::Fit`] when the part is too short to decimate.
pub fn prepared_both(ds: &Dataset, settle: usize, q: usize) -> Result<FitData, ExperimentError> {
    let prep = Prep {
        decimate: q,
        detrend: Detrend::None,
    };
    FitData::new(&ds.data.slice(steady_range(ds, settle)), prep).map_err(|source| {
        ExperimentError::Fit {
            model: "data".into(),
            source,
        }
    })
}

/// The simulator's linear joint `u → θm` (mechanics plus current loop),
/// discretised at `ts` [s]: the true model of a run without nonlinear
/// effects.
pub fn true_model(cfg: &SimConfig, ts: f64) -> StateSpace {
    let mech = Mechanism::new(&cfg.plant, &cfg.effects);
    let (f, g) = mech.linear_model(cfg.controller.current_loop_tau);
    let n = f.nrows();
    let mut h = RowDVector::zeros(n);
    h[0] = 1.0;
    let c = crate::ident::ss::ContinuousSs {
        f: DMatrix::from_fn(n, n, |i, j| f[(i, j)]),
        g: DVector::from_fn(n, |i, _| g[(i, 0)]),
        h,
        d: 0.0,
    };
    c.zoh(ts)
}

/// Output of the true model driven by the recorded `u` of the whole run
/// from rest (the simulator's initial state), then cut and decimated like
/// the data: what a perfect model would print.
///
/// # Errors
/// [`ExperimentError::Data`].
pub fn true_output(
    cfg: &SimConfig,
    ds: &Dataset,
    settle: usize,
    q: usize,
) -> Result<Vec<f64>, ExperimentError> {
    let m = true_model(cfg, ds.data.ts);
    let mut x0 = DVector::zeros(m.order());
    x0[0] = ds
        .data
        .r
        .as_ref()
        .and_then(|r| r.first().copied())
        .unwrap_or(0.0);
    // the motor starts at the first reference, arm-side bodies at r θm: zero deflection
    let mech = Mechanism::new(&cfg.plant, &cfg.effects);
    for (i, b) in mech.bodies.iter().enumerate().skip(1) {
        x0[i] = mech.bodies[0].gain * x0[0] / b.gain;
    }
    let yh = m.simulate(&ds.data.u, Some(&x0));
    Ok(crate::data::decimate(&yh[steady_range(ds, settle)], q)?)
}

/// One estimated parameter against the simulator's truth.
#[derive(Clone, Debug, Serialize)]
pub struct ParamError {
    /// name (seed 000 Table 1)
    pub name: String,
    /// estimate (SI)
    pub estimate: f64,
    /// reported standard deviation (same unit)
    pub std: f64,
    /// true value (same unit)
    pub truth: f64,
    /// (estimate − truth) / truth [%]
    pub error_percent: f64,
}

impl ParamError {
    /// error in reported standard deviations, (estimate − truth) / σ
    pub fn z(&self) -> f64 {
        (self.estimate - self.truth) / self.std
    }
}

/// One row of the Table-2-like comparison.
#[derive(Clone, Debug, Serialize)]
pub struct ModelRow {
    /// model name
    pub model: String,
    /// FIT on estimation data [%]
    pub fit_estimation: f64,
    /// FIT on validation data [%]
    pub fit_validation: f64,
    /// identified resonances [Hz]
    pub resonances_hz: Vec<f64>,
    /// identified anti-resonances [Hz]
    pub antiresonances_hz: Vec<f64>,
    /// parameter errors where the structure is the simulator's
    pub parameter_errors: Vec<ParamError>,
    /// fit time [s] (JSON `elapsed_s`, as every command's wall time)
    #[serde(rename = "elapsed_s")]
    pub seconds: f64,
}

/// The comparison of seed 000 Table 2 on one simulated experiment.
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    /// one row per model
    pub rows: Vec<ModelRow>,
    /// the true linear model's FIT on estimation and validation data [%] (in JSON
    /// `{"estimation", "validation"}`)
    #[serde(serialize_with = "estimation_validation")]
    pub true_fit: (f64, f64),
    /// undamped resonances of the simulated joint [Hz]
    pub truth_resonances_hz: Vec<f64>,
    /// undamped anti-resonances of the simulated joint [Hz]
    pub truth_antiresonances_hz: Vec<f64>,
    /// sample interval after decimation [s]
    pub ts: f64,
    /// decimation of the records the models are fitted and scored on (1: the capture rate)
    pub decimate: usize,
    /// estimation and validation samples after decimation (in JSON
    /// `{"estimation", "validation"}`)
    #[serde(serialize_with = "estimation_validation")]
    pub samples: (usize, usize),
}

/// An (estimation, validation) pair as the labelled object
/// `{"estimation": .., "validation": ..}`.
fn estimation_validation<S: serde::Serializer, T: Serialize>(
    v: &(T, T),
    s: S,
) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeStruct;
    let mut st = s.serialize_struct("EstimationValidation", 2)?;
    st.serialize_field("estimation", &v.0)?;
    st.serialize_field("validation", &v.1)?;
    st.end()
}

/// The fitted models of [`table`], for plots.
pub struct TableModels {
    /// the fits, in the order of the rows
    pub fitted: Vec<Fitted>,
}

/// settle periods dropped from the estimation run
pub const SETTLE_PERIODS: usize = 1;
/// decimation of seed 000 §6
pub const DECIMATE: usize = 10;

/// Fits `models` on the estimation dataset and evaluates them on both, as in
/// Table 2 (decimated by [`DECIMATE`]); `truth` gives the true model and parameters.
///
/// # Errors
/// [`ExperimentError`] from preparation or a fit.
pub fn table(
    est_ds: &Dataset,
    val_ds: &Dataset,
    truth: &SimConfig,
    models: &[Family],
) -> Result<(Table, TableModels), ExperimentError> {
    table_at(est_ds, val_ds, truth, models, DECIMATE, None)
}

/// [`table`] on the records decimated by `q` (1: at the capture rate, undecimated). The
/// physical models are fitted at the capture rate either way; with `reuse` (the models of
/// another [`table`] of the same records, in the order of `models`) they are scored again
/// instead of fitted again, and only the black boxes are fitted (their time is then 0 for
/// the reused rows).
///
/// # Errors
/// [`ExperimentError`] from preparation or a fit.
pub fn table_at(
    est_ds: &Dataset,
    val_ds: &Dataset,
    truth: &SimConfig,
    models: &[Family],
    q: usize,
    reuse: Option<&TableModels>,
) -> Result<(Table, TableModels), ExperimentError> {
    let q = q.max(1);
    let est_fd = prepared_both(est_ds, SETTLE_PERIODS, q)?;
    let val_fd = prepared_both(val_ds, SETTLE_PERIODS, q)?;
    let (est, val) = (est_fd.prepared(), val_fd.prepared());
    let yt_est = true_output(truth, est_ds, SETTLE_PERIODS, q)?;
    let yt_val = true_output(truth, val_ds, SETTLE_PERIODS, q)?;
    let true_fit = (
        fit_percent(&est.y, &yt_est).unwrap_or(f64::NAN),
        fit_percent(&val.y, &yt_val).unwrap_or(f64::NAN),
    );
    let modal = Mechanism::new(&truth.plant, &truth.effects).modal_frequencies();
    let truth_struct = match truth.plant.kind {
        Structure::Rigid => None,
        s => Some(Family::Physical(s)),
    };
    let tp = truth.plant.params.table();
    let analysis = analyze_dataset(est_ds, SETTLE_PERIODS).ok();
    let mut rows = Vec::new();
    let mut fitted = Vec::new();
    for (i, &kind) in models.iter().enumerate() {
        let t0 = Instant::now();
        let fit_err = |source| ExperimentError::Fit {
            model: kind.name(),
            source,
        };
        let opts = FitOptions {
            spec: ModelSpec {
                current_loop_tau: Some(truth.controller.current_loop_tau),
                ..ModelSpec::linear(kind)
            },
            output: Output::Angle,
            r: truth.plant.params.r,
            ..FitOptions::default()
        };
        // as `jointid fit --domain auto`: physical models of periodic data on the FRF
        let reused = reuse.and_then(|r| r.fitted.get(i)).filter(|f| {
            kind.structure().is_some() && f.spec.family == kind && f.ts == est_ds.data.ts
        });
        let f = match (kind, &analysis, reused) {
            (Family::Physical(_), _, Some(f)) => Ok(Fitted {
                decimate: q,
                ..f.clone()
            }),
            (Family::Physical(_), Some(a), None) => {
                fit_frequency_domain(a, est_ds.data.ts, &opts, q)
            }
            _ => fit_prepared(&est_fd, &opts),
        }
        .map_err(fit_err)?;
        // a reused fit: no time of its own, its parameters printed with the first table
        let seconds = if reused.is_some() {
            0.0
        } else {
            t0.elapsed().as_secs_f64()
        };
        let fe = fit_percent(&est.y, &f.simulate_on(&est_fd).map_err(fit_err)?).unwrap_or(f64::NAN);
        let fv = fit_percent(&val.y, &f.simulate_on(&val_fd).map_err(fit_err)?).unwrap_or(f64::NAN);
        let res = f.resonances(default_f_min(est.len(), est.ts));
        let parameter_errors = if Some(kind) == truth_struct && reused.is_none() {
            f.params
                .iter()
                .filter_map(|p| {
                    tp.iter()
                        .find(|(n, _, _)| *n == p.name)
                        .map(|(_, t, _)| ParamError {
                            name: p.name.clone(),
                            estimate: p.value,
                            std: p.std,
                            truth: *t,
                            error_percent: 100.0 * (p.value - t) / t,
                        })
                })
                .collect()
        } else {
            Vec::new()
        };
        rows.push(ModelRow {
            model: kind.name(),
            fit_estimation: fe,
            fit_validation: fv,
            resonances_hz: res.resonances.iter().map(|m| m.freq_hz).collect(),
            antiresonances_hz: res.anti_resonances.iter().map(|m| m.freq_hz).collect(),
            parameter_errors,
            seconds,
        });
        fitted.push(f);
    }
    Ok((
        Table {
            rows,
            true_fit,
            truth_resonances_hz: modal.resonances_hz,
            truth_antiresonances_hz: modal.anti_resonances_hz,
            ts: est.ts,
            decimate: q,
            samples: (est.len(), val.len()),
        },
        TableModels { fitted },
    ))
}

/// The three models of seed 000 Table 2.
pub const PAPER_MODELS: [Family; 3] = [
    Family::BlackBox(11),
    Family::Physical(Structure::ThreeMass),
    Family::Physical(Structure::FourMass),
];

/// One experiment of seed 000 Table 2 for `seed`: the runs of [`paper_runs`] streamed by
/// the simulated board ([`wire_options`] 1 and 2) and decoded back as captures are, then
/// the [`table`] of [`PAPER_MODELS`].
///
/// # Errors
/// Simulation, wire, decoding and fit errors ([`ExperimentError`]).
pub fn experiment(seed: u64) -> Result<Table, ExperimentError> {
    let runs = paper_runs(seed)?;
    let est = decode_session(
        &encode_session(&runs.est, &runs.est_excitation, &wire_options(1))?,
        "estimation",
    )?;
    let val = decode_session(
        &encode_session(&runs.val, &runs.val_excitation, &wire_options(2))?,
        "validation",
    )?;
    Ok(table(&est, &val, &runs.sim, &PAPER_MODELS)?.0)
}

/// Prints `t` as seed 000 Table 2 (plus the true model's column).
pub fn write_table(out: &mut dyn std::io::Write, t: &Table) -> std::io::Result<()> {
    use crate::data::Percent;
    let name = |m: &str| match m {
        "black-box:11" => "11th order".to_string(),
        "three-mass" => "3 mass".to_string(),
        "four-mass" => "4 mass".to_string(),
        o => o.to_string(),
    };
    write!(out, "  {:<12}", "Data set")?;
    for r in &t.rows {
        write!(out, " {:>11}", name(&r.model))?;
    }
    writeln!(out, " {:>11}", "true model")?;
    write!(out, "  {:<12}", "Est. data")?;
    for r in &t.rows {
        write!(out, " {:>11.1}", Percent(r.fit_estimation))?;
    }
    writeln!(out, " {:>11.1}", Percent(t.true_fit.0))?;
    write!(out, "  {:<12}", "Val. data")?;
    for r in &t.rows {
        write!(out, " {:>11.1}", Percent(r.fit_validation))?;
    }
    writeln!(out, " {:>11.1}", Percent(t.true_fit.1))?;
    writeln!(
        out,
        "  ({}, {} / {} samples at Ts = {} s{})",
        crate::ident::validate::FIT_NAME,
        t.samples.0,
        t.samples.1,
        crate::data::fmt_sig(t.ts, 4),
        if t.decimate > 1 {
            format!(" after decimation by {}", t.decimate)
        } else {
            ", the capture rate, undecimated".into()
        }
    )?;
    let hz = |v: &[f64]| {
        v.iter()
            .map(|f| format!("{f:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    writeln!(
        out,
        "  truth (undamped): resonances [Hz] {}; anti-resonances [Hz] {}",
        hz(&t.truth_resonances_hz),
        hz(&t.truth_antiresonances_hz)
    )?;
    for r in &t.rows {
        writeln!(
            out,
            "  {:<12} resonances [Hz] {}; anti-resonances [Hz] {} ({})",
            name(&r.model),
            hz(&r.resonances_hz),
            hz(&r.antiresonances_hz),
            if r.seconds > 0.0 {
                format!("{:.2} s", r.seconds)
            } else {
                "the fit above, scored here".into()
            }
        )?;
        for p in &r.parameter_errors {
            writeln!(
                out,
                "      {:<6} {:>12.4e} ± {:>9.2e} vs true {:>12.4e}  ({:+6.1} %, {:+6.1} σ)",
                p.name,
                p.estimate,
                p.std,
                p.truth,
                Percent(p.error_percent),
                p.z()
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn short_excitation() -> ExcitationConfig {
        ExcitationConfig {
            period_samples: 1000,
            max_line: 60,
            periods: 2,
            ramp_samples: 200,
            ..ExcitationConfig::paper_default()
        }
    }

    #[test]
    fn wire_round_trip_is_lossless_to_the_count() {
        let exc = short_excitation();
        let run = sim::simulate_excitation(&SimConfig::default(), &exc).unwrap();
        let scale = default_scale();
        let stream = encode_session(&run, &exc, &wire_options(7)).unwrap();
        let ds = decode_session(&stream, "mem").unwrap();
        assert_eq!(ds.data.len(), run.len());
        assert_eq!(ds.excitation, Some(exc));
        let lsb = f64::from(scale.angle_rad_per_count);
        for k in 0..run.len() {
            assert!(
                (ds.data.y[k] - run.theta_m[k]).abs() <= 0.5 * lsb + 1e-12,
                "{k}"
            );
            assert!((ds.data.u[k] - run.u[k]).abs() <= 0.5e-6 + 1e-9, "{k}");
            assert_eq!(ds.data.r.as_ref().unwrap()[k], run.theta_ref[k]);
        }
    }

    #[test]
    fn true_output_matches_noise_free_run() {
        let exc = short_excitation();
        let cfg = SimConfig {
            sensors: sim::SensorConfig::ideal(),
            ..SimConfig::default()
        };
        let run = sim::simulate_excitation(&cfg, &exc).unwrap();
        let ds = Dataset {
            name: "x".into(),
            data: run.to_id_data(),
            t0: 0.0,
            excitation: Some(exc),
            meta: Default::default(),
        };
        let yt = true_output(&cfg, &ds, 0, 1).unwrap();
        let y = &ds.data.y[steady_range(&ds, 0)];
        let err = yt
            .iter()
            .zip(y)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-9, "max error {err}");
    }
}
