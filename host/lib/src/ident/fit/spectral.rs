//! The time-domain fit of a flexible physical model checked against, and if need be
//! replaced by, a fit started from the FRF of the record itself: the path of
//! `jointid fit --domain time` and of non-periodic data (no whole excitation periods).
//!
//! Why: an output-error fit on the motor angle, driven by the measured torque, integrates
//! every unmodelled slow torque (the disturbance the position loop rejects) into a drift of
//! the simulated angle, and from a start read off a subspace model it can end in a minimum
//! that follows the drift (measured on `jointid simulate --model three-mass --excitation
//! noise`, default sensors, `--domain time`, seed 1: `k_g` 4,363 N·m/rad against 127,500,
//! FIT 6.9 %). The FRF of the same record is not hurt by the drift: Welch's averaged
//! spectra with the reference as instrument ([`crate::ident::frf::welch`]) need no whole
//! periods, and [`crate::ident::frf_fit::fit_frf`] on it gives both modes within 0.2 % and
//! the inertias and stiffnesses within about 1 % (the window's smearing biases the damping
//! high, `d_a` +17 %). So:
//!
//! 1. the time-domain fit of [`super::fit_grey`] runs as before;
//! 2. its response is compared with the Welch FRF by the weighted distance
//!    `V(G) = Σ_k |Ĝ_k − G_k|² / σ_k²` over the FRF's lines, against `V` of the FRF fit;
//! 3. above [`DRIFT_COST_RATIO`] times, the FRF fit is refined in the time domain on the
//!    motor velocity, and when the angle's fit lies also more than [`DRIFT_COST_RATIO`]
//!    times that refinement's `V` from the FRF (not the window's bias, which both share,
//!    but a model that followed the drift), it is replaced by the refinement. The
//!    refinement is the nonlinear engine with no effect attached
//!    ([`crate::ident::nonlinear::identify`]), output error on the interval-mean velocity
//!    through its second-order high-pass prefilter at
//!    [`crate::ident::nonlinear::fit::DEFAULT_HIGHPASS_HZ`], the torque offset and the
//!    initial velocity estimated. This is the treatment of the rigid-body integrator: on
//!    the velocity the drift is one integration smaller and the prefilter removes what is
//!    left below the resonances; the current-loop lag starts from the FRF fit's and is
//!    estimated (held when the spec holds it).
//!
//! Measured on the records of the module tests (the default three-mass joint and sensors
//! under band-limited noise with no repeated period, seeds 1–3): the angle's fit lies
//! 8,900–10,800 times the FRF fit's distance from the FRF, the velocity refinement 1.15
//! times after 4 iterations, every identifiable parameter within 2 %, both modes within
//! 0.05 %. The angle's output error started from the FRF fit was tried instead and not
//! kept: with no bounds it had not converged after 25 minutes on those 24,000 samples
//! (shared 2-core machine).

use crate::data::IdData;
use crate::ident::frf::{welch_frf, Frf, WelchOptions};
use crate::ident::frf_fit::{self, Drive, FrfFit, FrfFitOptions};
use crate::ident::grey_box::{self, PhysParam};
use crate::ident::nonlinear::{self, NlRequest, NlStart};
use crate::model::spec::Structure;

use super::{canonical_branches, DrivenModel, FitError, FitOptions, Fitted};

/// A time-domain fit whose Welch-FRF distance exceeds this multiple of the FRF fit's, and
/// of the velocity refinement's, is replaced (module documentation). The FRF fit minimises
/// that distance and its damping absorbs the window's bias, so a right model lies a little
/// above it (measured: the velocity refinement 1.15 times on the three-mass joint of the
/// module tests); a model that follows the drift lies orders of magnitude above
/// (8,900–10,800 times there).
pub const DRIFT_COST_RATIO: f64 = 10.0;

/// The physical model fitted to the Welch FRF of a record, and that FRF.
pub(super) struct WelchStart {
    pub(super) frf: Frf,
    pub(super) fit: FrfFit,
    /// segments averaged
    segments: usize,
    /// `V` of [`Self::fit`] on [`Self::frf`]
    pub(super) cost: f64,
}

/// `V(G) = Σ |Ĝ − G|²/σ²` over the lines of `frf` (module documentation)
pub(super) fn frf_distance(frf: &Frf, g: &[rustfft::num_complex::Complex64]) -> f64 {
    frf.g
        .iter()
        .zip(g)
        .zip(&frf.sigma)
        .map(|((a, b), s)| (a - b).norm_sqr() / (s * s).max(f64::MIN_POSITIVE))
        .sum()
}

/// The Welch FRF of `raw` (capture rate) and `structure` fitted to it; the delay is held at
/// 0 (the time-domain model has none), the lag estimated unless `opts` holds it.
pub(super) fn welch_start(
    raw: &IdData,
    structure: Structure,
    opts: &FitOptions,
) -> Result<WelchStart, FitError> {
    let w = welch_frf(raw, &WelchOptions::default())?;
    let mut fo = FrfFitOptions::new(structure, raw.ts);
    fo.output = opts.output;
    fo.r = opts.r;
    fo.delay = Drive::Fixed(0.0);
    if let Some(tau) = opts.spec.current_loop_tau {
        fo.lag = Drive::Fixed((tau / raw.ts).clamp(0.0, frf_fit::MAX_DRIVE_SAMPLES));
    }
    let fit = frf_fit::fit_frf(&w.frf, &fo)?;
    let cost = frf_distance(&w.frf, &fit.freq_response(&w.frf.freq_hz));
    Ok(WelchStart {
        frf: w.frf,
        fit,
        segments: w.segments,
        cost,
    })
}

/// The Welch start refined by output error on the prefiltered motor velocity at the capture
/// rate (module documentation), as a [`Fitted`] compared with data decimated `decimate`-fold.
pub(super) fn velocity_refined(
    raw: &IdData,
    start: &WelchStart,
    opts: &FitOptions,
    decimate: usize,
) -> Result<Fitted, FitError> {
    let structure = start.fit.model.structure;
    let held = opts.spec.current_loop_tau;
    let mut req = NlRequest::new(structure, opts.r, Vec::new());
    req.tau_c = start.fit.lag.value * raw.ts;
    req.held_tau_c = held;
    let model = nonlinear::model_of(&req, raw);
    req.start = NlStart::Values(model.values(&start.fit.values(), 0.0, 0.0));
    let res =
        nonlinear::identify(raw, &req).map_err(|e| FitError::VelocityRefinement(e.to_string()))?;
    let fit = &res.fit;
    let names = structure.param_names();
    let std: Vec<f64> = names
        .iter()
        .map(|n| {
            fit.params
                .iter()
                .find(|p| p.name == *n)
                .map_or(0.0, |p| p.std)
        })
        .collect();
    let log: Vec<f64> = fit.plant.iter().map(|v| v.ln()).collect();
    let log_std: Vec<f64> = std.iter().zip(&fit.plant).map(|(s, v)| s / v).collect();
    let params: Vec<PhysParam> = grey_box::phys_params(names, &log, &log_std);
    let gm = DrivenModel {
        mechanics: grey_box::GreyBoxModel {
            structure,
            output: opts.output,
            r: opts.r,
            ts: raw.ts,
        },
        current_loop_tau: fit.model.tau_c.max(0.0),
    };
    let mut model = pem_model(&gm, &log);
    model.k = None;
    let continuous = gm.continuous(&fit.plant);
    let v = frf_distance(&start.frf, &model.freq_response(&start.frf.freq_hz));
    let mut warnings = res.warnings.clone();
    warnings.extend(start.fit.warnings.iter().map(|w| format!("FRF start: {w}")));
    Ok(Fitted {
        spec: opts.spec.clone(),
        output: opts.output,
        ts: raw.ts,
        model,
        continuous: Some(continuous),
        params: canonical_branches(params),
        friction: None,
        warnings,
        method: format!(
            "the fit to the record's own FRF (Welch, {} segments, {} lines {:.1} to {:.1} Hz, \
             reference as instrument where recorded) refined by output error on the \
             high-pass prefiltered motor velocity at the capture rate ({} iterations, \
             current-loop lag {:.3} ms {}); its FRF distance {:.2} × the FRF fit's. The \
             toolbox FIT of the angle simulated from the measured torque integrates the slow \
             disturbance the loop rejects and does not measure this model on such data (on \
             the default three-mass simulation with noise excitation: −3,200 to −5,400 % with \
             every identifiable parameter within 2 %)",
            start.segments,
            start.frf.g.len(),
            start.frf.freq_hz.first().copied().unwrap_or(0.0),
            start.frf.freq_hz.last().copied().unwrap_or(0.0),
            fit.iterations,
            1e3 * fit.model.tau_c,
            if held.is_some() { "held" } else { "estimated" },
            v / start.cost.max(f64::MIN_POSITIVE)
        ),
        decimate,
    })
}

/// the discrete model of `gm` at log-parameters `log`
fn pem_model(gm: &DrivenModel, log: &[f64]) -> crate::ident::ss::StateSpace {
    crate::ident::pem::ParamModel::to_ss(gm, log)
}

/// `V` of `fitted` on the Welch FRF of `start` (module documentation); `None` when the model
/// runs at another rate than the FRF's record.
pub(super) fn distance(start: &WelchStart, fitted: &Fitted) -> Option<f64> {
    ((fitted.ts - start.fit.model.ts).abs() <= 1e-9 * fitted.ts)
        .then(|| frf_distance(&start.frf, &fitted.freq_response(&start.frf.freq_hz)))
        .map(|v| if v.is_nan() { f64::INFINITY } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Dataset, Prep};
    use crate::ident::fit::{fit_prepared, FitData};
    use crate::ident::frf::{analyze_dataset, FrfError};
    use crate::sim::{simulate_excitation, SimConfig};
    use jointid_core::excitation::{ExcitationConfig, SignalKind};

    /// The simulator's default three-mass joint and sensors (quantised encoder, white
    /// noise, slow torque disturbance, 0.5 ms current loop) under band-limited noise whose
    /// one 10 s period fills the record: 24,000 samples at 2 kHz with no repeated period,
    /// no excitation metadata.
    fn non_periodic(seed: u64) -> (Dataset, SimConfig) {
        let cfg = SimConfig {
            seed,
            ..SimConfig::default()
        };
        let exc = ExcitationConfig {
            kind: SignalKind::BandLimitedNoise,
            period_samples: 20_000,
            max_line: 1216,
            periods: 1,
            seed: 100 + seed,
            ..ExcitationConfig::paper_default()
        };
        let out = simulate_excitation(&cfg, &exc).expect("simulation");
        let ds = Dataset {
            name: "noise".into(),
            data: out.to_id_data(),
            t0: 0.0,
            excitation: None,
            meta: Default::default(),
        };
        (ds, cfg)
    }

    /// Issue 10, deliverable 2: on a record without whole periods the time-domain path
    /// gives the seven identifiable parameters within 3 % and both modes within 0.5 %
    /// (before: the angle's output error followed the drift, `k_g` off by up to ×30).
    #[test]
    fn three_mass_on_a_non_periodic_record_is_right_in_the_time_domain() {
        for seed in 1..=3 {
            let (ds, cfg) = non_periodic(seed);
            // no whole periods: the frequency-domain path cannot take it
            assert!(matches!(
                analyze_dataset(&ds, 0),
                Err(FrfError::NoPeriod { .. } | FrfError::TooFewPeriods { .. })
            ));
            let fd = FitData::new(&ds.data, Prep::default()).unwrap();
            let fit = fit_prepared(&fd, &FitOptions::default()).unwrap();
            let p = cfg.plant.params;
            let truth = [
                ("J_m", p.j_m),
                ("J_a1", p.j_a1),
                ("J_a2", p.j_a2),
                ("k_g", p.k_g),
                ("k_a", p.k_a),
                ("d_g", p.d_g),
                ("d_a", p.d_a),
            ];
            for (name, t) in truth {
                let v = fit.params.iter().find(|q| q.name == name).unwrap().value;
                assert!(
                    (v / t - 1.0).abs() < 0.03,
                    "seed {seed}: {name} {v:.5e} (truth {t:.5e}); {}",
                    fit.method
                );
            }
            let values = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m];
            let true_modes = grey_box::GreyBoxModel {
                structure: Structure::ThreeMass,
                output: grey_box::Output::Angle,
                r: p.r,
                ts: ds.data.ts,
            }
            .continuous(&values)
            .resonances(0.4, 0.5)
            .resonances;
            let modes = fit.resonances(0.4).resonances;
            assert_eq!(modes.len(), 2, "seed {seed}: {modes:?}");
            for (m, t) in modes.iter().zip(&true_modes) {
                assert!(
                    (m.freq_hz / t.freq_hz - 1.0).abs() < 0.005,
                    "seed {seed}: mode {:.3} Hz (truth {:.3} Hz)",
                    m.freq_hz,
                    t.freq_hz
                );
            }
        }
    }
}
