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
//! periods, and [`crate::ident::sml::fit_frf`] on it gives both modes within 0.2 % and
//! the inertias and stiffnesses within about 1 % (the window's smearing biases the damping
//! high, `d_a` +17 %). So:
//!
//! 1. the Welch FRF of the record at the capture rate and the model fitted to it
//!    ([`welch_start`]), refined in the time domain on the motor velocity
//!    ([`velocity_refined`]): the nonlinear engine with no effect attached
//!    ([`crate::ident::nonlinear::identify`]), output error on the interval-mean velocity
//!    through its second-order high-pass prefilter at
//!    [`crate::ident::nonlinear::output_error::DEFAULT_HIGHPASS_HZ`], the torque offset and the
//!    initial velocity estimated. This is the treatment of the rigid-body integrator: on
//!    the velocity the drift is one integration smaller and the prefilter removes what is
//!    left below the resonances; the current-loop lag starts from the FRF fit's and is
//!    estimated (held when the spec holds it);
//! 2. when that refinement converged, its response lies within [`DRIFT_COST_RATIO`] times
//!    the FRF fit's weighted distance `V(G) = Σ_k |Ĝ_k − G_k|² / σ_k²` from the FRF, its
//!    toolbox FIT of the angle is below [`DRIFT_ANGLE_FIT`] (a drift dominates the angle)
//!    and its velocity FIT reaches [`MIN_VELOCITY_FIT`], it is the model: the angle's
//!    output error, which would follow the drift and took most of the time (about 12.5 s of the
//!    13.9 s the whole fit took on `simulate --excitation noise` seed 1), is not run;
//! 3. otherwise the time-domain fit on the angle of [`super::fit_grey`] runs as before and
//!    is compared with the FRF by `V`: within [`DRIFT_COST_RATIO`] times the FRF fit's it
//!    is kept (data without a drift, where the angle's fit is the better one: the velocity
//!    of a noisy angle is mostly noise); beyond that, and more than [`DRIFT_COST_RATIO`]
//!    times the refinement's `V` (not the window's bias, which both share, but a model
//!    that followed the drift), it is replaced by the refinement.
//!
//! A model from the velocity reports the velocity FIT
//! ([`super::VELOCITY_FIT_NAME`], [`super::FitMetric::Velocity`],
//! [`super::Fitted::velocity_fit_segments`]): the model driven from rest by the measured
//! torque, its interval-mean velocity against the measured one, both through the same
//! prefilter. That is the criterion the refinement minimised (the same figure to 0.01 %
//! on the module tests, where the refinement also estimated an offset and an initial
//! velocity), and it needs nothing of the estimation record, so `validate` computes it
//! alike on new data. The toolbox FIT of the angle stays beside it: the drift dominates it
//! (−4,900 to −3,200 % for the true model on the module tests' records). A model from the
//! velocity whose angle FIT on the estimation record is not below [`DRIFT_ANGLE_FIT`] (a
//! record without a drift, where the angle's own fit ended in a basin far from the FRF)
//! reports the angle's FIT instead ([`with_reported_fit`]): there it measures the model,
//! and the velocity of a quantised angle is mostly noise (measured: `jointid simulate
//! --periods 2 --ideal-sensors` with encoder-sized noise, three-mass: angle FIT 99.7 % on
//! validation, velocity FIT 83.4 %, which the message had blamed on a drift there was not).
//!
//! Several gap-free segments (`--segment all`): the longest is fitted as above; when its
//! model came from the velocity, all segments are refined together by the same output
//! error on the velocity ([`velocity_refined_segments`], each segment its own initial
//! velocity), since the angle's output error over them would follow the drift again. The
//! check itself runs on the longest segment's Welch FRF only: the FRF of one segment is
//! enough to tell a drift, and [`welch_start`] takes one record. `--domain time` on
//! periodic data takes this same path (the check does not need whole periods).
//!
//! Measured on the records of the module tests (the default three-mass joint and sensors
//! under band-limited noise with no repeated period, seeds 1–3): the velocity refinement
//! lies 1.15 times the FRF fit's distance from the FRF after 4 iterations, every
//! identifiable parameter within 2 %, both modes within 0.05 %, velocity FIT 80.2–80.6 %
//! (the true model's the same to 0.01 point); the angle's fit, when it ran, lay
//! 8,900–10,800 times that distance. The angle's output error started from the FRF fit
//! was tried instead and not kept: with no bounds it had not converged after 25 minutes
//! on those 24,000 samples (shared 2-core machine). A record too short for Welch to
//! resolve the modes (9,000 samples at 2 kHz: 63 lines 2 Hz apart against modes 2 Hz
//! apart) fails the check and goes to step 3; both fits can then be wrong.
//!
//! Time (release, shared 2-core machine, `jointid fit --model three-mass --domain time`):
//! 0.7–1.6 s on `jointid simulate --excitation noise` seeds 1 and 3 (13.2–13.7 s when
//! the angle's fit ran first), 6.3 s on the default multisine simulation (18.4 s before),
//! of which 6.0 s is the fit to the Welch FRF: 72 starts from its resonances there
//! against 4 on the noise records.

use crate::data::IdData;
use crate::ident::frf::{welch_frf, Frf, WelchOptions};
use crate::ident::grey_box::{self, PhysParam};
use crate::ident::nonlinear::{self, NlRequest, NlStart};
use crate::ident::sml::{self, Drive, FrfFit, FrfFitOptions};
use crate::model::spec::Structure;

use super::{canonical_branches, DrivenModel, FitError, FitMetric, FitOptions, Fitted};

/// A time-domain fit whose Welch-FRF distance exceeds this multiple of the FRF fit's, and
/// of the velocity refinement's, is replaced; a velocity refinement within this multiple of
/// the FRF fit's may be taken without the angle's fit (module documentation). The FRF fit minimises
/// that distance and its damping absorbs the window's bias, so a right model lies a little
/// above it (measured: the velocity refinement 1.15 times on the three-mass joint of the
/// module tests); a model that follows the drift lies orders of magnitude above
/// (8,900–10,800 times there).
pub const DRIFT_COST_RATIO: f64 = 10.0;

/// A converged velocity refinement that lies within [`DRIFT_COST_RATIO`] times the FRF
/// fit's distance from the FRF is taken without running the angle's output error when its
/// toolbox FIT of the angle is below this [%] (the model explains less of the angle than
/// the angle's mean: a drift it does not explain dominates the angle, and the angle's fit
/// would follow it) and its velocity FIT is at least [`MIN_VELOCITY_FIT`] (module
/// documentation). Measured on the right model of the default
/// three-mass simulation with noise excitation: −4,900 to −3,700 %; on the open-loop
/// two-mass of the segment tests (white torque, no drift), whose angle fit is right: 9 to
/// 80 %.
pub const DRIFT_ANGLE_FIT: f64 = 0.0;

/// The velocity FIT [%] a refinement needs to be taken without the angle's output error
/// ([`DRIFT_ANGLE_FIT`]): the velocity, not its noise, is what it explains. Measured: 80–81 % on the three-mass simulation above, 0.1–0.7 %
/// on the open-loop two-mass (1 % angle noise, differenced).
pub const MIN_VELOCITY_FIT: f64 = 50.0;

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
        fo.lag = Drive::Fixed((tau / raw.ts).clamp(0.0, sml::MAX_DRIVE_SAMPLES));
    }
    let fit = sml::fit_frf(&w.frf, &fo)?;
    let cost = frf_distance(&w.frf, &fit.freq_response(&w.frf.freq_hz));
    Ok(WelchStart {
        frf: w.frf,
        fit,
        segments: w.segments,
        cost,
    })
}

/// The values of `structure` ([`Structure::param_names`] order) and its lag [s] fitted to
/// the Welch FRF of `raw` (the record's own FRF, the reference as instrument where
/// recorded): the start `fit --domain time` refines; `None` when that fit fails.
pub(crate) fn welch_structure(
    raw: &IdData,
    structure: Structure,
    r: f64,
) -> Option<(Vec<f64>, f64)> {
    let opts = FitOptions {
        r,
        ..FitOptions::default()
    };
    let w = welch_start(raw, structure, &opts).ok()?;
    let lag = (w.fit.lag.value + w.fit.delay.value) * raw.ts;
    Some((w.fit.values(), lag))
}

/// The velocity refinement of a Welch start ([`velocity_refined`]).
pub(super) struct Refined {
    /// the refined model, its FIT the velocity's ([`super::FitMetric::Velocity`])
    pub(super) fitted: Fitted,
    /// the output-error search ended before its iteration limit
    pub(super) converged: bool,
    /// its velocity FIT on the record, with the estimated torque offset and initial
    /// velocity [%]
    pub(super) velocity_fit: f64,
}

/// Output error on the prefiltered motor velocity of `records` (capture rate, separate
/// experiments) from the structure's values `plant` and the current-loop lag `tau_c` [s]
/// (module documentation); the lag held when the spec holds it.
fn refine(
    records: &[IdData],
    structure: Structure,
    plant: &[f64],
    tau_c: f64,
    opts: &FitOptions,
) -> Result<nonlinear::NlResult, FitError> {
    let longest = records
        .iter()
        .max_by_key(|d| d.len())
        .ok_or(FitError::VelocityNoRecord)?;
    let mut req = NlRequest::new(structure, opts.r, Vec::new());
    req.tau_c = tau_c;
    req.held_tau_c = opts.spec.current_loop_tau;
    let model = nonlinear::model_of(&req, longest);
    // a spring or damper of the FRF fit that the integrator's step cannot follow would not
    // simulate (measured: a Welch fit in the other branch with `d_g` 3.6·10⁴ N·m·s/rad on
    // `J_m` 7·10⁻⁴ kg·m², drift-free noise record of the default three-mass joint): brought
    // to the fastest the step holds, as the automatic start does
    let mut plant = plant.to_vec();
    let _ = nonlinear::init::resolvable(structure, opts.r, &mut plant, longest.ts);
    req.start = NlStart::Values(model.values(&plant, 0.0, 0.0));
    nonlinear::identify_segments(records, &req)
        .map_err(|e| FitError::VelocityRefinement(Box::new(e)))
}

/// The [`Fitted`] of a velocity refinement `res` at the capture rate `ts` [s], compared with
/// data decimated `decimate`-fold: the structure's parameters and the lag `tau_c` [s], the
/// velocity FIT as its figure.
fn refined_fitted(
    res: &nonlinear::NlResult,
    opts: &FitOptions,
    ts: f64,
    decimate: usize,
    (warnings, method): (Vec<String>, String),
) -> Fitted {
    let fit = &res.fit;
    let structure = fit.model.structure;
    let names = structure.param_names();
    let std_of = |n: &str| {
        fit.params
            .iter()
            .find(|p| p.name == n)
            .map_or(0.0, |p| p.std)
    };
    let std: Vec<f64> = names.iter().map(|n| std_of(n)).collect();
    let log: Vec<f64> = fit.plant.iter().map(|v| v.ln()).collect();
    let log_std: Vec<f64> = std.iter().zip(&fit.plant).map(|(s, v)| s / v).collect();
    let gm = DrivenModel::new(structure, opts, ts, fit.model.tau_c);
    let mut model = pem_model(&gm, &log);
    model.k = None;
    let mut params = canonical_branches(grey_box::phys_params(names, &log, &log_std));
    params.push(PhysParam {
        name: "tau_c".into(),
        value: gm.current_loop_tau,
        std: std_of("tau_c"),
        unit: "s",
    });
    Fitted {
        spec: opts.spec.clone(),
        output: opts.output,
        ts,
        model,
        continuous: Some(gm.continuous(&fit.plant)),
        params,
        friction: None,
        warnings,
        method,
        decimate,
        fit_metric: FitMetric::Velocity,
    }
}

/// The Welch start refined by output error on the prefiltered motor velocity at the capture
/// rate (module documentation), as a [`Fitted`] compared with data decimated `decimate`-fold.
pub(super) fn velocity_refined(
    raw: &IdData,
    start: &WelchStart,
    opts: &FitOptions,
    decimate: usize,
) -> Result<Refined, FitError> {
    let res = refine(
        std::slice::from_ref(raw),
        start.fit.model.structure,
        &start.fit.values(),
        start.fit.lag.value * raw.ts,
        opts,
    )?;
    let fit = &res.fit;
    let mut warnings = res.warnings.clone();
    warnings.extend(start.fit.warnings.iter().map(|w| format!("FRF start: {w}")));
    let method = format!(
        "the fit to the record's own FRF (Welch, {} segments, {} lines {:.1} to {:.1} Hz, \
         reference as instrument where recorded) refined by output error on the high-pass \
         prefiltered motor velocity at the capture rate ({} iterations, current-loop lag \
         {:.3} ms {}, velocity FIT {:.2} % with the estimated torque offset and initial \
         velocity)",
        start.segments,
        start.frf.g.len(),
        start.frf.freq_hz.first().copied().unwrap_or(0.0),
        start.frf.freq_hz.last().copied().unwrap_or(0.0),
        fit.iterations,
        1e3 * fit.model.tau_c,
        if opts.spec.current_loop_tau.is_some() {
            "held"
        } else {
            "estimated"
        },
        fit.fit_velocity_percent,
    );
    let mut fitted = refined_fitted(&res, opts, raw.ts, decimate, (warnings, method));
    let v = frf_distance(&start.frf, &fitted.freq_response(&start.frf.freq_hz));
    fitted.method.push_str(&format!(
        "; its FRF distance {:.2} × the FRF fit's",
        v / start.cost.max(f64::MIN_POSITIVE)
    ));
    Ok(Refined {
        converged: fit.termination != crate::ident::lm::Termination::MaxIterations,
        velocity_fit: fit.fit_velocity_percent,
        fitted,
    })
}

/// `fitted`, a velocity refinement ([`velocity_refined`]) whose toolbox FIT of the angle on
/// its estimation record is `angle_fit` [%], with the FIT it reports: the velocity's when a
/// drift dominates the angle (below [`DRIFT_ANGLE_FIT`]), else the angle's, which then
/// measures the model as on any record without a drift.
pub(super) fn with_reported_fit(mut fitted: Fitted, angle_fit: f64) -> Fitted {
    if angle_fit >= DRIFT_ANGLE_FIT {
        fitted.fit_metric = FitMetric::Output;
        fitted.method.push_str(&format!(
            ". Its toolbox FIT of the angle on the estimation record is {angle_fit:.1} %: no \
             drift dominates the angle, so the FIT reported is the angle's"
        ));
    } else {
        fitted.fit_metric = FitMetric::Velocity;
        fitted.method.push_str(&format!(
            ". Its toolbox FIT of the angle on the estimation record is {angle_fit:.0} %: the \
             angle simulated from the measured torque integrates the slow disturbance the \
             loop rejects and does not measure this model on such data, so the FIT reported \
             is the velocity's"
        ));
    }
    fitted
}

/// A velocity-refined model `start` (fitted on one record, [`velocity_refined`]) refined
/// again on all of `records` (capture rate, separate experiments, each its own initial
/// velocity) by the same output error on the prefiltered motor velocity: the path of
/// `--segment all` once the longest record's angle fit was replaced.
pub(super) fn velocity_refined_segments(
    records: &[IdData],
    start: &Fitted,
    opts: &FitOptions,
    decimate: usize,
) -> Result<Fitted, FitError> {
    let structure = start
        .spec
        .family
        .structure()
        .ok_or(FitError::VelocityBlackBox)?;
    let value = |n: &str| {
        start
            .params
            .iter()
            .find(|p| p.name == n)
            .map(|p| p.value)
            .ok_or_else(|| FitError::VelocityStartLacks {
                name: n.to_string(),
            })
    };
    let plant = structure
        .param_names()
        .iter()
        .map(|n| value(n))
        .collect::<Result<Vec<f64>, _>>()?;
    let res = refine(records, structure, &plant, value("tau_c")?, opts)?;
    let mut warnings = start.warnings.clone();
    warnings.extend(res.warnings.iter().cloned());
    warnings.dedup();
    let method = format!(
        "{}; then output error on the prefiltered motor velocity over {} records as separate \
         experiments (each its own initial velocity, {} iterations)",
        start.method,
        records.len(),
        res.fit.iterations
    );
    Ok(refined_fitted(
        &res,
        opts,
        records[0].ts,
        decimate,
        (warnings, method),
    ))
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
    use crate::ident::fit::{fit_prepared, FitData, FitMetric};
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

    /// Records without a drift (the encoder and its noise, no torque disturbance, no noise
    /// on `u`), 14,000 samples: the angle's FIT measures the model and is the FIT reported.
    /// Seed 1 is band-limited noise: its Welch FRF fit ended in another branch at 4 times
    /// the noise level (`k_g` 6·10³ against 1.3·10⁵ N·m/rad), which the search took as
    /// good enough because the FRF showed both peaks, and the fit kept was the angle's at
    /// 90.7 %; the two odd-multisine periods (one left after the settling one) reported the
    /// velocity FIT, about 83 %, blaming a drift there was not.
    #[test]
    fn a_record_without_a_drift_reports_the_angle_fit() {
        let mut cfg = SimConfig::default();
        cfg.sensors.disturbance = crate::sim::Disturbance::none();
        cfg.sensors.u_noise_std = 0.0;
        let noise = ExcitationConfig {
            kind: SignalKind::BandLimitedNoise,
            period_samples: 14_000,
            max_line: 851,
            periods: 1,
            seed: 201,
            ..ExcitationConfig::paper_default()
        };
        let multisine = ExcitationConfig {
            periods: 2,
            ..ExcitationConfig::paper_default()
        };
        for (what, exc) in [("noise", noise), ("two periods", multisine)] {
            let data = simulate_excitation(&cfg, &exc)
                .expect("simulation")
                .to_id_data();
            let fd = FitData::new(&data, Prep::default()).unwrap();
            let fit = fit_prepared(&fd, &FitOptions::default()).unwrap();
            assert_eq!(fit.fit_metric, FitMetric::Output, "{what}: {}", fit.method);
            let angle = crate::ident::validate::fit_percent(&data.y, &fit.simulate(&data)).unwrap();
            assert!(
                angle > 97.0,
                "{what}: angle FIT {angle:.2} %: {}",
                fit.method
            );
            assert_within_3_percent(&fit, &cfg, what);
        }
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
            assert_within_3_percent(&fit, &cfg, &format!("seed {seed}"));
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
            reports_the_velocity_fit(&fit, &fd, &cfg, seed);
        }
    }

    /// The model with the true values of `cfg`'s three-mass joint and current loop, in the
    /// form of `fit` (same rate and output).
    /// The seven identifiable three-mass parameters of `fit` within 3 % of `cfg`'s.
    fn assert_within_3_percent(fit: &Fitted, cfg: &SimConfig, what: &str) {
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
                "{what}: {name} {v:.5e} (truth {t:.5e}); {}",
                fit.method
            );
        }
    }

    fn true_model(fit: &Fitted, cfg: &SimConfig) -> Fitted {
        let p = cfg.plant.params;
        let values = [p.j_m, p.j_a1, p.j_a2, p.k_g, p.k_a, p.d_g, p.d_a, p.f_m];
        let gm = DrivenModel {
            mechanics: grey_box::GreyBoxModel {
                structure: Structure::ThreeMass,
                output: grey_box::Output::Angle,
                r: p.r,
                ts: fit.ts,
            },
            current_loop_tau: cfg.controller.current_loop_tau,
        };
        let log: Vec<f64> = values.iter().map(|v| v.ln()).collect();
        let mut model = pem_model(&gm, &log);
        model.k = None;
        Fitted {
            model,
            ..fit.clone()
        }
    }

    /// Issue 10 item 2 follow-up: a model fitted on the velocity reports the velocity FIT,
    /// within a point of the true model's, where the angle's toolbox FIT of the same right
    /// model is far below zero (the drift); the saved model says the same.
    fn reports_the_velocity_fit(fit: &Fitted, fd: &FitData, cfg: &SimConfig, seed: u64) {
        assert_eq!(
            fit.fit_metric,
            FitMetric::Velocity,
            "seed {seed}: {}",
            fit.method
        );
        // the reordered path: the angle's output error never ran
        assert!(
            fit.method.contains("was not run"),
            "seed {seed}: {}",
            fit.method
        );
        let data = std::slice::from_ref(fd);
        let (v, each) = fit.velocity_fit_segments(data).unwrap();
        let (v_true, _) = true_model(fit, cfg).velocity_fit_segments(data).unwrap();
        assert_eq!(each, vec![v]);
        assert!(
            v > 75.0 && v >= v_true - 1.0,
            "seed {seed}: velocity FIT {v:.2} %, true model's {v_true:.2} %"
        );
        let angle = fit.evaluate_on(fd, 10).unwrap().fit;
        assert!(angle < 0.0, "seed {seed}: angle FIT {angle:.1} %");
        let saved = fit.to_saved(Prep::default(), "noise", v);
        assert_eq!(
            saved.fit_name.as_deref(),
            Some(crate::ident::fit::VELOCITY_FIT_NAME)
        );
        let back = saved.to_fitted().unwrap();
        assert_eq!(back.fit_metric, FitMetric::Velocity);
        let (v_back, _) = back.velocity_fit_segments(data).unwrap();
        assert!((v_back - v).abs() < 1e-9, "{v_back} vs {v}");
    }

    /// `--segment all` on a non-periodic record with a gap: the longest piece's model,
    /// fitted on the velocity, is refined on the velocity over both pieces (the angle's
    /// output error over them would follow the drift again); the seven identifiable
    /// parameters within 3 %.
    #[test]
    fn segments_of_a_non_periodic_record_are_fitted_on_the_velocity() {
        let (ds, cfg) = non_periodic(2);
        let record = crate::test_support::with_gap(&ds, 10_000..12_000);
        let data: Vec<FitData> = record
            .pieces
            .iter()
            .map(|d| FitData::new(&d.data, Prep::default()).unwrap())
            .collect();
        assert_eq!(data.len(), 2);
        let fit = crate::ident::fit::fit_prepared_segments(&data, &FitOptions::default()).unwrap();
        assert_eq!(fit.fit_metric, FitMetric::Velocity, "{}", fit.method);
        assert!(
            fit.method
                .contains("motor velocity over 2 records as separate experiments"),
            "{}",
            fit.method
        );
        assert_within_3_percent(&fit, &cfg, "two segments");
        let (pooled, each) = fit.velocity_fit_segments(&data).unwrap();
        let (truth_pooled, _) = true_model(&fit, &cfg).velocity_fit_segments(&data).unwrap();
        assert_eq!(each.len(), 2);
        assert!(
            pooled >= truth_pooled - 1.0,
            "velocity FIT {pooled:.2} %, true model's {truth_pooled:.2} %"
        );
    }
}
