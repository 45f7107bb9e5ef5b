//! The whole nonlinear identification as a user runs it, one path for `jointid fit` and
//! `diagnose`: on periodic data the frequency-domain linear start ([`linear_start`]), or
//! when the motor sticks the start grown in the time domain ([`super::grow`]), the
//! automatic start (or a given one), the values the user holds or gives, the output-error
//! fit (refitted with the friction's level alone when its breakaway ends below it), the
//! checks that turn a doubtful result into warnings, and the validation with the
//! simulator's exact laws ([`crate::sim::simulate_driven`]).

use std::sync::OnceLock;

use thiserror::Error;

use super::init::{automatic_start_with, start_head, LinearFit, RippleOrder, Step};
use super::model::{sim_plant, NlModel, Owner};
use super::output_error::{
    fit_output_error_segments, interval_velocities, interval_velocity, simulate_velocity, NlParam,
    VelocityFitSums,
};
use super::{NlError, NlFit, NlOptions};
use crate::data::{Dataset, IdData};
use crate::ident::frf::FrfError;
use crate::ident::lm::Termination;
use crate::ident::parallel::{join, machine_threads, parallel};
use crate::ident::sml::{Drive, FrfFit, FrfFitError, FrfFitOptions, FrfStart};
use crate::model::effects::Effect;
use crate::model::spec::Structure;
use crate::sim::{simulate_driven, DrivenStart};

/// Largest current-loop lag a request may hold [s] (the layout's upper bound).
pub const MAX_TAU_C: f64 = 0.1;

/// A frequency-domain lag below this is read as none [s].
const MIN_LAG: f64 = 2e-6;

/// Where the fit starts.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum NlStart {
    /// seed 001's three steps, from [`NlRequest::linear`] when given
    #[default]
    Automatic,
    /// the whole start in layout order ([`NlModel::layout`])
    Values(Vec<f64>),
    /// a previous fit of the same structure and effects (a saved model): its values
    Previous(Box<NlFit>),
}

/// What to identify and how.
#[derive(Clone, Debug, PartialEq)]
pub struct NlRequest {
    /// mechanical structure
    pub structure: Structure,
    /// gear ratio `r` [-]
    pub r: f64,
    /// effects to attach (their parameter values are ignored unless the start is given; an
    /// extra mode's attachment is taken as it is, and so is the ripple's order when
    /// [`NlRequest::given`] holds its `order` or the start is given; else the automatic
    /// start finds the order in the data)
    pub effects: Vec<Effect>,
    /// current-loop lag `tau_c` [s] to start from when not held (estimated); 0: none
    pub tau_c: f64,
    /// the current-loop lag held [s] (0: the model has none); `None`: not held
    pub held_tau_c: Option<f64>,
    /// where the fit starts
    pub start: NlStart,
    /// the structure's values from a linear fit the caller trusts (step 3 of the start)
    pub linear: Option<Vec<f64>>,
    /// [`NlRequest::linear`] explains the FRF to within a few times its noise
    /// ([`super::init::LinearFit::at_noise`])
    pub linear_at_noise: bool,
    /// values held by name: a structure's parameter, `tau_c`, `offset` or an effect's key
    /// [SI]
    pub fixed: Vec<(String, f64)>,
    /// per effect (in `effects` order), keys given a start value [SI]; a held name wins
    pub given: Vec<Vec<(String, f64)>>,
    /// options of the fit (fixed parameters by name among them)
    pub options: NlOptions,
    /// the torque ripple's order searched in the data is the search's best candidate even
    /// when it falls short of [`super::ripple::SIGNIFICANT_Z`], when it is coherent along
    /// the record: for a caller that has shown that order apart on another record
    /// (`diagnose` on the validation record, [`super::ripple::replication`])
    pub ripple_best_order: bool,
}

impl NlRequest {
    /// The request for `structure` and `effects` with the defaults: automatic start, no
    /// lag, nothing held or given.
    pub fn new(structure: Structure, r: f64, effects: Vec<Effect>) -> Self {
        NlRequest {
            structure,
            r,
            effects,
            tau_c: 0.0,
            held_tau_c: None,
            start: NlStart::Automatic,
            linear: None,
            linear_at_noise: false,
            fixed: Vec::new(),
            given: Vec::new(),
            options: NlOptions::default(),
            ripple_best_order: false,
        }
    }

    /// The model's name: the structure's label and the effects' names joined by `+`.
    pub fn model_name(&self) -> String {
        model_name(self.structure, &self.effects)
    }

    /// The lag held: `tau_c` among [`NlRequest::fixed`], else [`NlRequest::held_tau_c`].
    pub fn held(&self) -> Option<f64> {
        self.fixed
            .iter()
            .find(|(n, _)| n == "tau_c")
            .map(|(_, v)| *v)
            .or(self.held_tau_c)
    }

    /// Checks what can be checked before the work: the held lag's range and that every
    /// held name is a parameter of the model.
    ///
    /// # Errors
    /// [`NlRunError::LagRange`], [`NlRunError::UnknownParameter`].
    pub fn check(&self) -> Result<(), NlRunError> {
        if let Some(t) = self.held() {
            if !(0.0..MAX_TAU_C).contains(&t) {
                return Err(NlRunError::LagRange(t));
            }
        }
        // a model with a current loop: its layout names every parameter that can be held
        let probe = NlModel {
            structure: self.structure,
            r: self.r,
            effects: self.effects.clone(),
            tau_c: 1e-3,
            v_eps: 0.01,
            dz_eps: 1e-7,
            substeps: 1,
        };
        let mut known: Vec<&str> = Vec::new();
        for d in probe
            .layout()
            .iter()
            .filter(|d| d.owner != Owner::InitialVelocity)
        {
            if !known.contains(&d.name) {
                known.push(d.name);
            }
        }
        match self
            .fixed
            .iter()
            .find(|(n, _)| !known.contains(&n.as_str()))
        {
            Some((name, _)) => Err(NlRunError::UnknownParameter {
                name: name.clone(),
                model: self.model_name(),
                known: known.join(", "),
            }),
            None => Ok(()),
        }
    }
}

/// `structure` and `effects` as one name (`two-mass+nonlinear_stiffness`).
pub fn model_name(structure: Structure, effects: &[Effect]) -> String {
    std::iter::once(structure.label())
        .chain(effects.iter().map(|e| e.name()))
        .collect::<Vec<_>>()
        .join("+")
}

/// Why a nonlinear identification could not be run.
#[derive(Debug, Error)]
pub enum NlRunError {
    /// a held name is no parameter of the model
    #[error("`{name}`: no such parameter in {model} (known: {known})")]
    UnknownParameter {
        /// the name held
        name: String,
        /// the model ([`model_name`])
        model: String,
        /// the names that can be held
        known: String,
    },
    /// the held current-loop lag [s] is out of range
    #[error("tau_c = {0} s: a current-loop lag is within [0, 0.1) s")]
    LagRange(f64),
    /// the previous fit given as start is of another model
    #[error("the start holds {holds}, the fit asks for {asks}")]
    StartMismatch {
        /// the start's model
        holds: String,
        /// the model asked for
        asks: String,
    },
    /// the start, the fit or the validation on the estimation record
    #[error(transparent)]
    Estimation(NlError),
    /// the validation on the validation record
    #[error(transparent)]
    Validation(NlError),
}

impl From<NlError> for NlRunError {
    fn from(e: NlError) -> Self {
        NlRunError::Estimation(e)
    }
}

/// Result of [`identify`].
#[derive(Clone, Debug, PartialEq)]
pub struct NlResult {
    /// the steps of the start (empty with a given start)
    pub steps: Vec<Step>,
    /// the fit
    pub fit: NlFit,
    /// what makes the fit doubtful, in words (empty when nothing does)
    pub warnings: Vec<String>,
    /// the options the fit ran with (the held names among `fixed`)
    pub options: NlOptions,
    /// the method, in words
    pub method: String,
    /// the last search of the torque ripple's order in the data
    /// ([`super::init::Start::ripple_search`]; none with a given start)
    pub ripple_search: Option<super::ripple::OrderSearch>,
}

/// Validation of a fitted model on data that played no part in the fit (the `validation`
/// of `fit --json` and `validate --json` for a model with effects).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct NlValidation {
    /// FIT of the interval-mean motor velocity through the fit's high-pass prefilter, the
    /// model simulated with the simulator's exact laws [%]
    pub velocity_fit_percent: f64,
    /// the same with the estimator's smooth laws [%]
    pub velocity_fit_smooth_percent: f64,
    /// toolbox FIT of the motor angle, exact laws, unfiltered [%] (the rigid-body mode and
    /// any drift dominate it)
    pub angle_fit_percent: f64,
}

/// The note that says a fit took its input as sampled ([`crate::data::IdData::input_as_sampled`]):
/// with the input held the lag came out nought; `what` (held `held`, so `sampled` [%]) is
/// the figure that chose.
pub fn sampled_input_note(what: &str, held: f64, sampled: f64) -> String {
    format!(
        "the input is taken as samples of a signal that moves between them, not as values \
         held over each sample interval (a drive's torque reference): with the input held, \
         the current-loop lag came out nought, less delay than holding adds; driven by the \
         input taken as a band-limited signal (each sample replaced by the value whose hold \
         passes it with no delay), {what} is {sampled:.1} % against {held:.1} % held"
    )
}

/// A lag to start from below this share of the sample interval is left out of the model
/// (no current loop): RK4 samples the torque at its steps' ends and middle, and a torque
/// that settles within a few per cent of a step is seen late by a sixth of the input's
/// change, an error of first order in the step (an open-loop grounded mass at 610 Hz with a
/// 6.4 µs lag from its frequency-domain start: its true values scored 94.3 % with two RK4
/// steps per sample, 97.2 % with four and 98.6 % with eight, against 99.7 % without the
/// lag).
pub const UNRESOLVED_LAG: f64 = 0.1;

/// The model the estimator integrates for `req` (smoothing of the non-smooth laws, RK4
/// steps per sample; a lag to start from below [`UNRESOLVED_LAG`] of a sample left out).
pub fn model_of(req: &NlRequest, data: &IdData) -> NlModel {
    let v_rms = velocity_rms(data);
    let delay = req
        .effects
        .iter()
        .any(|e| matches!(e, Effect::TimeDelay(_)));
    NlModel {
        structure: req.structure,
        r: req.r,
        effects: req.effects.clone(),
        tau_c: if req.tau_c < UNRESOLVED_LAG * data.ts {
            0.0
        } else {
            req.tau_c
        },
        // a few per cent of the motion's velocity: small against it, large enough that
        // RK4 at the sample rate stays stable on the friction's slope
        v_eps: (0.05 * v_rms).clamp(5e-3, 0.05),
        dz_eps: 1e-7,
        substeps: if delay { 2 } else { 1 },
    }
}

/// RMS of the interval-mean motor velocity [rad/s].
pub fn velocity_rms(data: &IdData) -> f64 {
    let v = interval_velocity(&data.y, data.ts);
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Identifies `req` on `data`: the start (automatic, seed 001's three steps, unless
/// given), the held values and the given keys put into it, then the output-error fit and
/// its checks. The rigid structure is fitted without the high-pass prefilter (its
/// information lies below it, [`NlOptions::for_structure`]).
///
/// # Errors
/// [`NlRunError`]: a request that does not fit the model, or the data or the start
/// cannot be used.
pub fn identify(data: &IdData, req: &NlRequest) -> Result<NlResult, NlRunError> {
    identify_segments(std::slice::from_ref(data), req)
}

/// Where the automatic start takes the torque ripple's order from: the data, unless the
/// request gives the ripple an `order` ([`NlRequest::given`]).
fn ripple_order_of(req: &NlRequest) -> RippleOrder {
    let given = req.effects.iter().enumerate().any(|(i, e)| {
        matches!(e, Effect::TorqueRipple(_))
            && req
                .given
                .get(i)
                .is_some_and(|keys| keys.iter().any(|(k, _)| k == "order"))
    });
    if given {
        RippleOrder::Given
    } else if req.ripple_best_order {
        RippleOrder::BestFromData
    } else {
        RippleOrder::FromData
    }
}

/// The longest of `data` (the first of equal length).
fn longest(data: &[IdData]) -> Option<&IdData> {
    data.iter()
        .enumerate()
        .max_by_key(|(i, d)| (d.len(), usize::MAX - i))
        .map(|(_, d)| d)
}

/// As [`identify`] on several records taken as separate experiments (the gap-free segments
/// of one capture, [`fit_output_error_segments`]): the start found on the longest record,
/// the fit on all of them, each with its own initial state.
///
/// # Errors
/// As [`identify`]; [`NlRunError::Estimation`] for no record.
pub fn identify_segments(all: &[IdData], req: &NlRequest) -> Result<NlResult, NlRunError> {
    req.check()?;
    let data = longest(all).ok_or(NlError::NoRecord)?;
    let held = req.held();
    let mut model = model_of(req, data);
    if let Some(t) = held {
        model.tau_c = t;
    }
    let mut options = req.options.clone().for_structure(req.structure);
    let mut start_warnings = Vec::new();
    let mut ripple_search = None;
    let mut at_peaks = Vec::new();
    let (mut steps, start_model, mut start) = match &req.start {
        NlStart::Automatic => {
            let linear = req.linear.as_deref().map(|values| LinearFit {
                values,
                at_noise: req.linear_at_noise,
            });
            let st = automatic_start_with(data, &model, linear, ripple_order_of(req), &options)?;
            options.fixed.extend(st.held);
            start_warnings = st.warnings;
            ripple_search = st.ripple_search;
            at_peaks = st.at_peaks;
            (st.steps, st.model, st.values)
        }
        NlStart::Values(v) => (Vec::new(), model.clone(), v.clone()),
        NlStart::Previous(prev) => {
            let same = prev.model.structure == req.structure
                && prev.model.effects.len() == req.effects.len()
                && prev
                    .model
                    .effects
                    .iter()
                    .zip(&req.effects)
                    .all(|(a, b)| a.name() == b.name());
            if !same {
                return Err(NlRunError::StartMismatch {
                    holds: model_name(prev.model.structure, &prev.model.effects),
                    asks: req.model_name(),
                });
            }
            model.effects = prev.model.effects.clone();
            if held.is_none() {
                model.tau_c = prev.model.tau_c;
            }
            let offset = prev.get("offset").unwrap_or(0.0);
            let values = model.values(&prev.plant, offset, 0.0);
            (Vec::new(), model.clone(), values)
        }
    };
    let layout = start_model.layout();
    // an asymmetric Coulomb level takes the offset's place (`init::holds_offset`), unless
    // the offset is held at a value of the user's
    if super::init::holds_offset(&start_model) && !req.fixed.iter().any(|(n, _)| n == "offset") {
        if let Some(i) = layout.iter().position(|d| d.owner == Owner::Offset) {
            start[i] = 0.0;
            options.fixed.push("offset".into());
        }
    }
    // held values (the lag below, with the lag held)
    for (name, value) in req.fixed.iter().filter(|(n, _)| n != "tau_c") {
        for (i, d) in layout.iter().enumerate() {
            if d.name == name && d.owner != Owner::InitialVelocity {
                start[i] = *value;
            }
        }
        options.fixed.push(name.clone());
    }
    // the lag held (0: the model has none, and no `tau_c` in the layout)
    if let Some(t) = held {
        if let Some(i) = layout.iter().position(|d| d.name == "tau_c") {
            start[i] = t;
            options.fixed.push("tau_c".into());
        }
    }
    // the keys given per effect, unless held
    for (i, keys) in req.given.iter().enumerate().take(req.effects.len()) {
        for (key, value) in keys {
            if req.fixed.iter().any(|(n, _)| n == key) {
                continue;
            }
            if let Some(j) = layout
                .iter()
                .position(|d| d.owner == Owner::Effect(i) && d.name == key)
            {
                start[j] = *value;
            }
        }
    }
    let (fit_model, _) = start_model.with_values(&start);
    let fit_model = fit_model.refined_for(&start, velocity_rms(data), data.ts);
    // a start found by the data on the record's head ([`start_head`]): the whole model
    // fitted there first, and the fit on every record goes on from that estimate when it
    // explains the whole record better than the start (within the bounds of the start's
    // values)
    if let (NlStart::Automatic, Some(part)) = (&req.start, start_head(data)) {
        let head = NlOptions {
            cov_lags: 0,
            exact_correction: false,
            smoothing_sigma: false,
            rel_cost_tol: super::init::start_tolerance(&part),
            ..options.clone()
        };
        let on_head = super::output_error::fit_output_error(&part, &fit_model, &start, &head);
        if let Ok(f) = on_head {
            let whole = |v: &[f64]| {
                super::output_error::cost_at(data, &fit_model, v).unwrap_or(f64::INFINITY)
            };
            let (there, here) = join(machine_threads(), || whole(&f.values), || whole(&start));
            if there < here {
                steps.push(Step {
                    name: "whole model, head of the record".into(),
                    values: Step::values_of(&f),
                    detail: format!(
                        "output error on the first {} of {} samples: {} iterations, FIT \
                         {:.2} %; the fit on every sample starts here",
                        part.len(),
                        data.len(),
                        f.iterations,
                        f.fit_velocity_percent
                    ),
                });
                if options.range_from.is_none() {
                    options.range_from = Some(start.clone());
                }
                start = f.values;
            }
        }
    }
    let mut fit = fit_output_error_segments(all, &fit_model, &start, &options)?;
    let mut warnings = start_warnings;
    let mut fit_model = fit_model;
    if let Some((fs, fc)) = breakaway_below_level(&fit, &options) {
        // the nested law from the same start: the path of the fits that end physical is
        // left as it was
        let (nested, from) = level_alone(&fit_model, &start);
        let nested_options = NlOptions {
            range_from: (options.range_from.as_deref()).map(|r| level_alone(&fit_model, r).1),
            ..options.clone()
        };
        let below = format!(
            "the friction's breakaway level F_s ended at {fs:.3e} N·m, below its sliding \
             level F_c = {fc:.3e} N·m, which no friction law has (the simulator's exact law \
             refuses it)"
        );
        match fit_output_error_segments(all, &nested, &from, &nested_options) {
            Ok(f) => {
                warnings.push(format!(
                    "{below}: refitted from the same start with the level alone (F_s = F_c, \
                     no Stribeck bump)"
                ));
                (fit, fit_model, options) = (f, nested, nested_options);
            }
            Err(e) => warnings.push(format!(
                "{below}, and its refit with the level alone failed ({e}): the fit cannot be \
                 validated with the exact law"
            )),
        }
    }
    warnings.extend(checks(&fit));
    let method = method(&options, &fit_model, held.is_some(), fit.model.tau_c > 0.0);
    let result = NlResult {
        steps,
        fit,
        warnings,
        options,
        method,
        ripple_search,
    };
    Ok(best_of_peaks(all, req, result, at_peaks))
}

/// The fit `from_grid` of a single extra mode from the automatic start, or the fit from
/// one of the start's residual peaks `at_peaks` ([`super::init::Start::at_peaks`]) when it
/// ends at a lower cost, its steps those of the automatic start and one that says so.
///
/// Why: the grid ranks the mode's frequencies by the cost at the start, and a fit without
/// the mode has moved its other values to make up for it, so even the mode at its right
/// frequency can cost more there than without it. Other-joints bench (`JOINTS=1 HARD=1`,
/// case 23): the grid's choice (3 Hz, below the cost's high-pass) grew into a 690 kg·m²
/// body at 0.6 Hz the cost does not see, 98.26 % on validation; from the residual's peak
/// at 15 Hz the fit reached the true joint's arm mode, 99.84 %.
fn best_of_peaks(
    all: &[IdData],
    req: &NlRequest,
    from_grid: NlResult,
    at_peaks: Vec<(crate::model::effects::ExtraMode, f64, Vec<f64>)>,
) -> NlResult {
    let mut best = from_grid;
    // a mode the user placed (a key given or held) starts where the user put it
    let placed = req.given.iter().any(|keys| !keys.is_empty())
        || req
            .fixed
            .iter()
            .any(|(n, _)| matches!(n.as_str(), "j" | "k" | "d"));
    if placed {
        return best;
    }
    let mut kept = None;
    let grid_ssr = best.fit.ssr;
    // on a long record the start's steps ran on its head, and so does the first weighing:
    // a peak whose fit there does not beat the grid's fit on the same samples goes no
    // further (the measured Silverbox, 78,000 samples: each full fit from a peak took 15 s)
    let head = longest(all).and_then(start_head);
    for (mode, f_hz, values) in at_peaks {
        let mut peak = NlRequest {
            effects: vec![Effect::ExtraMode(mode)],
            start: NlStart::Values(values),
            ..req.clone()
        };
        if let Some(part) = &head {
            let Ok(h) = identify_segments(std::slice::from_ref(part), &peak) else {
                continue;
            };
            let on_head = |f: &NlFit| {
                super::output_error::cost_at(part, &f.model, &f.values).unwrap_or(f64::INFINITY)
            };
            if on_head(&h.fit) >= on_head(&best.fit) {
                continue;
            }
            peak.start = NlStart::Values(h.fit.values);
        }
        if let Ok(r) = identify_segments(all, &peak) {
            if r.fit.ssr < best.fit.ssr {
                kept = Some((mode, f_hz, r.fit.ssr));
                best = NlResult {
                    steps: std::mem::take(&mut best.steps),
                    ..r
                };
            }
        }
    }
    if let Some((mode, f_hz, ssr)) = kept {
        best.steps.push(Step {
            name: "extra_mode at a residual peak".into(),
            values: vec![
                ("j".into(), mode.j, "kg·m²"),
                ("k".into(), mode.k, "N·m/rad"),
                ("d".into(), mode.d, "N·m·s/rad"),
            ],
            detail: format!(
                "the mode started at {f_hz:.1} Hz, where the linear fit's residual peaks, its \
                 inertia taken from the mass it hangs on: the fit from there ends at a cost of \
                 {ssr:.4e} against {grid_ssr:.4e} from the grid's start, and is the fit"
            ),
        });
    }
    best
}

/// The fitted breakaway and sliding levels `(F_s, F_c)` [N·m] of `fit`'s Coulomb law when
/// the breakaway ended below the sliding level and the user held neither the bump's
/// shape nor its level; `None` otherwise.
///
/// Why: the estimator's smooth law is defined for `F_s < F_c` (a dip at rest instead of a
/// bump), so the optimiser can end there, but no friction law has it and the simulator's
/// exact law refuses it. Held at `F_s ≥ F_c` along the whole path, the fits that end
/// physical moved too (`diagnose::tests::pairs`, a sticking motor with a soft parallel
/// mode: `F_c` 0.0100 against 0.0252 N·m); so only a fit that ends outside is refitted, with
/// the law nested in its own ([`level_alone`]). Regular bench case 37 (a parallel mode with
/// Coulomb friction, the motor stuck on 51 % of the samples): the friction's fit ended at
/// `F_s` 0.0038, `F_c` 0.235 N·m, the candidate could not be scored, and the answer was
/// `none`, 36.6 points below the true model.
fn breakaway_below_level(fit: &NlFit, options: &NlOptions) -> Option<(f64, f64)> {
    if options.fixed.iter().any(|n| n == "fs" || n == "v_stribeck") {
        return None;
    }
    fit.model.effects.iter().find_map(|e| match e {
        Effect::CoulombFriction(f) if f.fs < f.fc => Some((f.fs, f.fc)),
        _ => None,
    })
}

/// `model` with every Coulomb law's Stribeck bump taken away (`F_s = F_c`, the law nested
/// in it), and `values` (in `model`'s layout) laid out for it.
fn level_alone(model: &NlModel, values: &[f64]) -> (NlModel, Vec<f64>) {
    let (offset, v0) = super::model::offset_and_v0(&model.layout(), values);
    let (mut nested, plant) = model.with_values(values);
    for e in &mut nested.effects {
        if let Effect::CoulombFriction(f) = e {
            f.fs = f.fc;
        }
    }
    let laid = nested.values(&plant, offset, v0);
    (nested, laid)
}

/// The method of a fit with `options` of `model` (the model the fit integrates), in words.
fn method(options: &NlOptions, model: &NlModel, lag_held: bool, lag: bool) -> String {
    format!(
        "nonlinear grey box: output error on the interval-mean motor velocity from the measured \
         torque ({}, RK4 with {} step(s) per sample, smooth Coulomb law v_eps = {:.3} rad/s), \
         Levenberg-Marquardt with exact derivatives by dual numbers, σ by the sandwich \
         covariance for coloured residuals{}; current-loop lag {}",
        if options.highpass_hz <= 0.0 {
            "no prefilter: a rigid body's information lies at the low frequencies".to_string()
        } else if options.highpass_order == 2 {
            format!(
                "second-order Butterworth high-pass prefilter at {} Hz",
                options.highpass_hz
            )
        } else {
            format!(
                "Butterworth high-pass prefilter at {} Hz",
                options.highpass_hz
            )
        },
        model.substeps,
        model.v_eps,
        if model
            .effects
            .iter()
            .any(|e| matches!(e, Effect::CoulombFriction(_)))
        {
            "; with Coulomb friction, Gauss-Newton steps on the exact stick-slip law's cost \
             after the smooth fit, and the smooth law's remaining bias (the change of the \
             estimate when v_eps is doubled, x1.66) added to the σ"
        } else {
            ""
        },
        match (lag_held, lag) {
            (true, true) => "fixed",
            (_, false) => "left out",
            (false, true) => "estimated",
        }
    )
}

/// The records of [`run`].
#[derive(Clone, Copy, Debug)]
pub struct NlData<'a> {
    /// the estimation records: one, or the gap-free segments of one capture, fitted as
    /// separate experiments ([`identify_segments`])
    pub estimation: &'a [IdData],
    /// the periodic capture the estimation records are (its segments), and the periods
    /// each skips as settling; with it (and the automatic start, no
    /// [`NlRequest::linear`]) the frequency-domain linear start is tried on the FRF
    /// averaged over them ([`linear_start_segments`])
    pub periodic: Option<(&'a [Dataset], usize)>,
    /// the validation record
    pub validation: Option<&'a IdData>,
}

/// Result of [`run`].
#[derive(Clone, Debug, PartialEq)]
pub struct NlRun {
    /// the fit, its start's steps (the frequency-domain linear fit first when there was
    /// one), warnings, options and method
    pub result: NlResult,
    /// the FITs on the estimation records (pooled over them), exact laws
    pub estimation: NlValidation,
    /// the FITs on each estimation record, in order (one entry for one record)
    pub estimation_segments: Vec<NlValidation>,
    /// the FITs on the validation record, exact laws
    pub validation: Option<NlValidation>,
}

/// The whole nonlinear identification: [`linear_start`] on periodic data (its failure a
/// warning; data that are not periodic skip it), with Coulomb friction on a flexible
/// structure and a motor that sticks the start grown in the time domain instead
/// ([`super::grow`], a step per stage and a warning that says so), [`identify`], then
/// [`validate`] on the estimation and the validation record.
///
/// # Errors
/// [`NlRunError`] as [`identify`]; [`NlRunError::Validation`] when the validation record
/// cannot be used.
pub fn run(data: NlData<'_>, req: &NlRequest) -> Result<NlRun, NlRunError> {
    req.check()?;
    let mut req = req.clone();
    let mut steps = Vec::new();
    let mut warnings = Vec::new();
    // the start is the data's own: not given, and no linear fit of the caller's
    let own_start = req.start == NlStart::Automatic && req.linear.is_none();
    // a capture that says its excitation, and a model that stays linear: the residual
    // low-passed at the band's top ([`NlOptions::lowpass_hz`]), unless the caller chose a
    // low-pass (a nonlinear effect's own distortion above the band is what its fit needs,
    // unless the motor sticks, [`grow_if_sticking`])
    let linear = req
        .effects
        .iter()
        .all(crate::model::effects::Effect::is_linear);
    let band_top = match (data.periodic, req.options.lowpass_hz) {
        (Some((ds, _)), 0.0) => ds
            .iter()
            .find_map(|d| d.excitation)
            .zip(ds.first())
            .and_then(|(c, d)| crate::data::excited_band_top(&c, d.data.ts)),
        _ => None,
    };
    if let (Some(top), true) = (band_top, linear) {
        req.options.lowpass_hz = top;
    }
    let mut compensation = None;
    if let (Some((ds, settle)), NlStart::Automatic, None) = (data.periodic, &req.start, &req.linear)
    {
        match linear_start_segments(ds, settle, &req) {
            Ok(ls) => {
                if req.held().is_none() {
                    req.tau_c = ls.tau_c;
                }
                req.linear = Some(ls.values);
                req.linear_at_noise = ls.at_noise;
                compensation.clone_from(&ls.compensation);
                steps.extend(ls.compensation);
                steps.push(ls.step);
            }
            Err(LinearStartError::NotPeriodic(_)) => {}
            Err(e @ LinearStartError::Fit(_)) => warnings.push(format!(
                "the frequency-domain linear fit failed ({e}): the start is found in the \
                 time domain and the model starts without current-loop lag"
            )),
        }
    }
    if own_start {
        if let Some(note) =
            grow_if_sticking(data.estimation, compensation.as_ref(), band_top, &mut req)
        {
            match note {
                Growth::Grown { steps: grown, note } => {
                    steps.extend(grown);
                    warnings.push(note);
                }
                Growth::Failed { note } => warnings.push(note),
            }
        }
    }
    let mut result = identify_segments(data.estimation, &req)?;
    // the estimation and validation records simulated side by side
    let (estimation, validation) = join(
        machine_threads(),
        || validate_segments(&result.fit, data.estimation, &result.options),
        || {
            data.validation
                .map(|v| validate(&result.fit, v, &result.options))
        },
    );
    let estimation = estimation?;
    let estimation_segments = if data.estimation.len() > 1 {
        data.estimation
            .iter()
            .map(|d| validate(&result.fit, d, &result.options))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        vec![estimation]
    };
    let validation = validation.transpose().map_err(NlRunError::Validation)?;
    steps.append(&mut result.steps);
    result.steps = steps;
    warnings.append(&mut result.warnings);
    for (what, v) in [
        ("estimation", Some(&estimation)),
        ("validation", validation.as_ref()),
    ] {
        if v.is_some_and(|v| !v.velocity_fit_percent.is_finite()) {
            warnings.push(format!(
                "the model simulated with the exact laws is not finite on the {what} record"
            ));
        }
    }
    result.warnings = warnings;
    Ok(NlRun {
        result,
        estimation,
        estimation_segments,
        validation,
    })
}

/// The friction level stick-slip is judged against [N·m]: the held `fc`, else the level
/// the compensation's regression found (its step's `fc` over
/// [`super::compensate::SHARE`]), else on data that gave no compensation the regression
/// itself on the longest record ([`super::compensate::level`], one sample ahead), when
/// significant (above 3 σ). The diagnosis judges stick-slip by the same level
/// (`diagnose::starts`), so `fit` and `diagnose` grow the same start on the same data.
pub fn friction_level(
    data: &[IdData],
    req: &NlRequest,
    compensation: Option<&Step>,
) -> Option<f64> {
    if let Some((_, v)) = req.fixed.iter().find(|(n, _)| n == "fc") {
        return Some(*v);
    }
    if let Some(c) = compensation {
        let taken = c.values.iter().find(|v| v.0 == "fc")?.1;
        let regressed = c.values.iter().any(|v| v.0 == "fc_std");
        return regressed.then_some(taken / super::compensate::SHARE);
    }
    let law = req.effects.iter().find_map(|e| match e {
        Effect::CoulombFriction(c) => Some(*c),
        _ => None,
    })?;
    let d = longest(data)?;
    let law = crate::model::effects::CoulombFriction {
        v_smooth: model_of(req, d).v_eps,
        ..law
    };
    let l = super::compensate::level(d, 1, &law)?;
    (l.fc > 3.0 * l.std).then_some(l.fc)
}

/// When `req` has Coulomb friction on a flexible structure and the motor sticks on `data`
/// (the torque below [`friction_level`] on more than [`super::grow::STICK_SHARE`] of the
/// samples), the start grown in the time domain ([`super::grow`]) put into `req`: with the
/// friction alone, the whole start (plant, lag, offset and friction); with other effects,
/// the plant, the lag and the friction's keys, the others from their own automatic start
/// on that plant. Where it sticks, the residual is low-passed at `band_top` (the excited
/// band's top, when the capture says its excitation and the caller chose no low-pass).
/// `None` when the motor does not stick (`req` untouched); else the grown stages' steps
/// and the note that says so, or the note of a growth that failed (`req` untouched but
/// for its low-pass).
fn grow_if_sticking(
    data: &[IdData],
    compensation: Option<&Step>,
    band_top: Option<f64>,
    req: &mut NlRequest,
) -> Option<Growth> {
    use super::grow::{grow_with, stick_share, Seed, STICK_SHARE};
    // (grown from the two-mass: a structure with an arm mass)
    if req.structure.masses() < 2 {
        return None;
    }
    let (ci, law) = req.effects.iter().enumerate().find_map(|(i, e)| match e {
        Effect::CoulombFriction(c) => Some((i, *c)),
        _ => None,
    })?;
    let level = friction_level(data, req, compensation)?;
    let share = stick_share(data, level);
    if share <= STICK_SHARE {
        return None;
    }
    // the angle rests within an encoder count for long stretches: its quantisation error
    // is coloured, and the loop's reaction to it above the band draws the fit away from
    // the joint; the growth and the fit are band-limited as a linear model's are (the
    // diagnosis does the same, `diagnose::inputs::nl_options`)
    if let Some(top) = band_top {
        req.options.lowpass_hz = top;
    }
    let longest = longest(data)?;
    let ts = longest.ts;
    let held = req.held();
    let given = req.given.get(ci).cloned().unwrap_or_default();
    let seed = Seed {
        structure: req.structure,
        r: req.r,
        tau_c: held.unwrap_or(if req.tau_c > 0.0 { req.tau_c } else { ts }),
        held_tau_c: held,
        law,
        given,
        fixed: req.fixed.clone(),
        options: req.options.clone(),
    };
    let sticks = format!(
        "the motor sticks: the torque stays below the friction level {level:.3e} N·m on \
         {:.0} % of the estimation samples, so the FRF is the friction's and not the \
         structure's{}",
        100.0 * share,
        match band_top {
            Some(top) => format!(
                ", and the residual is low-passed at the excited band's top ({top:.0} Hz): \
                 above it the measured torque holds the loop's reaction to the encoder's \
                 quantisation, coloured while the motor rests"
            ),
            None => String::new(),
        }
    );
    let g = match grow_with(data, &seed) {
        Ok(g) => g,
        Err(e) => {
            return Some(Growth::Failed {
                note: format!(
                    "{sticks}; the start grown in the time domain failed ({e}), the fit starts \
                     from the frequency-domain linear fit"
                ),
            })
        }
    };
    req.tau_c = g.tau_c;
    req.effects[ci] = g.coulomb;
    req.linear = Some(g.plant.clone());
    req.linear_at_noise = false;
    // the friction's given keys started the growth; from here on its own values
    req.given.resize(req.effects.len(), Vec::new());
    let others = req.effects.len() > 1;
    if others {
        req.given[ci] = super::grow::friction_keys_of(&g.coulomb);
    } else {
        req.given[ci].clear();
        req.start = NlStart::Values(model_of(req, longest).values(&g.plant, g.offset, 0.0));
    }
    let stages = g.steps.len();
    Some(Growth::Grown {
        steps: g.steps,
        note: format!(
            "{sticks}; the start was grown in the time domain instead: the two-mass with \
             Coulomb friction by output error{}, {}",
            match stages {
                2 =>
                    ", then the arm's second mass as an extra mode in series (the three-mass \
                      chain)",
                3 =>
                    ", then the arm's second mass as an extra mode in series (the three-mass \
                      chain), then the parallel mass as an extra mode in parallel (the \
                      four-mass)",
                _ => "",
            },
            if others {
                "the other effects from their automatic start on it"
            } else {
                "the fit starts from its plant, lag, offset and friction"
            }
        ),
    })
}

/// What [`grow_if_sticking`] did when the motor sticks.
enum Growth {
    /// the start was grown: its stages, and the note that says so
    Grown {
        /// the grown stages
        steps: Vec<Step>,
        /// for the user
        note: String,
    },
    /// the growth failed; the note says why and where the fit starts instead
    Failed {
        /// for the user
        note: String,
    },
}

/// The linear start of step 3 from periodic data ([`linear_start`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearStart {
    /// the structure's values ([`Structure::param_names`] order) [SI]
    pub values: Vec<f64>,
    /// the current-loop lag it estimated [s] (0 when none or below 2 µs; the held one
    /// when held)
    pub tau_c: f64,
    /// the step as the start's steps report it (`frequency-domain linear fit`)
    pub step: Step,
    /// with Coulomb friction in the request: the friction compensation's step
    /// ([`super::compensate`]; its value `used` 1 when the start is the compensated FRF's)
    pub compensation: Option<Step>,
    /// the fit's cost is within a few times the noise's
    /// ([`crate::ident::sml::GOOD_START_RATIO`])
    pub at_noise: bool,
    /// with lag and delay both estimated: the likelihood-ratio evidence of a transport delay
    /// on the excited lines ([`DelayLines`]); `None` when either was held or a fit failed
    pub delay_lines: Option<DelayLines>,
}

/// How much a transport delay beside the current-loop lag lowers the SML cost of the
/// structure's frequency-domain fit: the lag-only fit's cost less the free fit's. The SML
/// cost is a chi-squared sum over the excited lines with the per-line noise variances of
/// the periods, consistent in a closed loop since the FRF is read through the periodic
/// reference; one parameter more lowers it, when the delay is not there, by a chi-squared
/// of one degree of freedom scaled by `ν/(ν − 2)` for the estimated variances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DelayLines {
    /// the drop of the SML cost [-]
    pub drop: f64,
    /// the delay the free fit found [samples]
    pub delay: f64,
    /// degrees of freedom ν of the per-line noise variances
    pub noise_dof: f64,
    /// the lag-only fit's SML cost above what the noise leaves (its expected cost) [-]: the
    /// misfit of the lines a delay would have to explain
    pub misfit: f64,
}

/// The least share of the lag-only fit's misfit above the noise ([`DelayLines::misfit`])
/// that a delay the lines show must remove to be taken for a transport delay
/// ([`DelayLines::explains`]).
///
/// Why: anything that turns the phase of the excited lines a little more with frequency
/// than the first-order lag does gives a delay a drop above the test's threshold; a
/// transport delay is the cause only when it accounts for a good part of the misfit. Joints
/// from `jointid simulate` and the diagnose bench: true delays of 0.15–1.4 samples remove
/// 46 % (the simulator's fractional delay interpolates, which also lowers the magnitude at
/// the top of the band; the model's delay does not) to 100 %; a torque ripple of 2, 5 and
/// 20 mN·m on the default joint with no delay, whose describing function puts a phase on the
/// lines (drops 16, 166 and 578), 11–17 %. The test:
/// `diagnose::tests::a_ripple_that_turns_the_lines_phase_is_not_taken_for_a_delay`. The
/// margin on the side of the delays is thin (46 % against 33 %), and a drive with more
/// dynamics than a first-order lag is not covered: its phase looks like a delay's.
pub const DELAY_MIN_SHARE: f64 = 1.0 / 3.0;

/// The 99 % point of a chi-squared of one degree of freedom.
const CHI2_1_99: f64 = 6.635;

impl DelayLines {
    /// The drop a delay that is not there stays below with 99 % probability [-].
    pub fn threshold(&self) -> f64 {
        let nu = self.noise_dof;
        if nu > 2.0 {
            CHI2_1_99 * nu / (nu - 2.0)
        } else {
            f64::INFINITY
        }
    }

    /// Whether the lines show a delay beside the lag.
    pub fn shown(&self) -> bool {
        self.drop > self.threshold()
    }

    /// The delays the lines hold at 99 % [samples]: those whose cost, the lag refitted,
    /// stays within [`DelayLines::threshold`] of the free fit's. The profile of the cost
    /// over the delay is taken as the parabola through its minimum at [`DelayLines::delay`]
    /// and its rise [`DelayLines::drop`] at nought (the delay enters the model as the phase
    /// `ωT`, on which the cost is quadratic near its minimum), so the interval is `T̂ (1 ±
    /// √(threshold/drop))`. A delay fitted in the time domain outside it is not the delay
    /// the lines show (a joint with a torque ripple of 2 mN·m and no delay: the lines' delay
    /// 0.07 samples at a drop of 16.1, the time-domain fit's 0.35).
    pub fn interval(&self) -> (f64, f64) {
        let h = self.delay.abs() * (self.threshold() / self.drop).sqrt();
        (self.delay - h, self.delay + h)
    }

    /// The share of the lag-only fit's misfit above the noise that the delay removes [-]:
    /// 1 when the delay brings the lines' cost down to the noise's.
    pub fn share(&self) -> f64 {
        if self.misfit <= self.drop {
            1.0
        } else {
            self.drop / self.misfit
        }
    }

    /// Whether the lines show a delay that explains them: shown, and removing at least
    /// [`DELAY_MIN_SHARE`] of their misfit.
    pub fn explains(&self) -> bool {
        self.shown() && self.share() >= DELAY_MIN_SHARE
    }

    /// Whether the delay `samples` lies in [`DelayLines::interval`] of lines whose delay
    /// explains them ([`DelayLines::explains`]).
    pub fn holds(&self, samples: f64) -> bool {
        let (lo, hi) = self.interval();
        self.explains() && (lo..=hi).contains(&samples)
    }
}

/// The raw fits of `frf` ([`RawFrfFits`]): with the options `o` and, when given, with the
/// lag alone (`lag_only`); the better kept, and the lines' evidence of a delay from the two.
fn raw_fits(
    frf: &crate::ident::frf::Frf,
    o: &FrfFitOptions,
    lag_only: Option<&FrfFitOptions>,
) -> RawFits {
    // the fits of the measured FRF are independent: on threads, each result in its place
    let mut raw_opts = vec![o];
    raw_opts.extend(lag_only);
    let mut raws = parallel(&raw_opts, machine_threads(), |opts| {
        crate::ident::sml::fit_frf(frf, opts)
    })
    .into_iter();
    let mut raw = raws.next().expect("the free fit is the first job");
    let mut delay_lines = None;
    if let Some(Ok(l)) = raws.next() {
        if let Ok(free) = &raw {
            // the free model holds the lag-only one: a free fit that costs more ended in a
            // worse basin, and is made again from the lag-only fit for the drop, so that the
            // drop measures the delay, not the search (hard bench of `diagnose`, an extra
            // mode with friction: the free fit 12.4 above the lag-only one, 0.4 below it
            // made again). Not for less than one unit of the χ² cost, one degree of
            // freedom's worth, which the test's threshold of about 8 does not see: there the
            // two ended in the same minimum (three-mass joints, 1e-8 apart), and the refit
            // is a second's CPU for nothing. The start below is chosen as before, from the
            // two first fits.
            let mut nested = (free.cost, free.delay.value);
            if free.cost > l.cost + 1.0 {
                let again = FrfFitOptions {
                    start: Some(l.as_start()),
                    ..o.clone()
                };
                if let Ok(f) = crate::ident::sml::fit_frf(frf, &again) {
                    if f.cost < nested.0 {
                        nested = (f.cost, f.delay.value);
                    }
                }
            }
            let mut lines = DelayLines {
                drop: l.cost - nested.0,
                delay: nested.1,
                noise_dof: free.noise_dof,
                misfit: l.cost - l.expected_cost(),
            };
            // and the other way: a drop the test counts must not come from a lag-only fit
            // in a worse basin. The lag-only model holds the free fit with its delay's
            // time put on the lag (the two phases agree below the lag's corner), so that
            // start is tried before the drop is counted (hard bench, an extra mode and no
            // delay: the free fit at a delay of 0, which the lag-only model holds exactly,
            // 4000 below the lag-only fit). Only when the drop would show a delay: a
            // structure's fit from a start is a second of CPU.
            if let Some(lo) = lag_only.filter(|_| lines.shown()) {
                let mut theta = free.lm.theta.clone();
                let n = theta.len();
                theta[n - 2] += theta[n - 1];
                theta[n - 1] = 0.0;
                let again = FrfFitOptions {
                    start: Some(FrfStart {
                        theta,
                        reached: free.cost_ratio(),
                    }),
                    ..lo.clone()
                };
                if let Ok(f) = crate::ident::sml::fit_frf(frf, &again) {
                    lines.drop = lines.drop.min(f.cost - nested.0);
                    lines.misfit = lines.misfit.min(f.cost - f.expected_cost());
                }
            }
            delay_lines = Some(lines);
        }
        raw = match raw {
            Ok(free) if free.cost_ratio() < l.cost_ratio() => Ok(free),
            _ => Ok(l),
        };
    }
    (raw, delay_lines)
}

/// Why [`linear_start`] gave none.
#[derive(Debug, Error)]
pub enum LinearStartError {
    /// the data are not whole periods of a known excitation
    #[error(transparent)]
    NotPeriodic(#[from] FrfError),
    /// the frequency-domain fit failed
    #[error(transparent)]
    Fit(#[from] FrfFitError),
}

/// The linear start of step 3 from periodic data: the frequency-domain fit of the
/// request's structure to the FRF of `ds` (`settle` periods skipped) at the excited lines
/// ([`crate::ident::sml`]), which transients, drift and the nonlinear distortion at
/// the non-excited lines leave alone; the current-loop lag held when the request holds
/// it, the delay held at 0 when an effect is a `time_delay`; otherwise the lag-only fit
/// too, kept unless the fit with the delay free costs less, and the delay's time put on
/// the lag (the nonlinear model carries no frequency-domain delay).
///
/// # Errors
/// [`LinearStartError`].
pub fn linear_start(
    ds: &Dataset,
    settle: usize,
    req: &NlRequest,
) -> Result<LinearStart, LinearStartError> {
    linear_start_segments(std::slice::from_ref(ds), settle, req)
}

/// As [`linear_start`] on the FRF averaged over the whole periods of several gap-free
/// segments of one capture ([`crate::ident::frf::analyze_segments`]).
///
/// # Errors
/// [`LinearStartError`].
pub fn linear_start_segments(
    segments: &[Dataset],
    settle: usize,
    req: &NlRequest,
) -> Result<LinearStart, LinearStartError> {
    linear_start_shared(
        segments,
        settle,
        req,
        (&RawFrfFits::default(), None),
        StartSearch::Full,
    )
}

/// The two fits of a structure's measured FRF that every linear start of it begins with:
/// the lag and delay free, and the lag alone (the better kept as the raw fit, the two
/// compared for [`DelayLines`]). They depend on the record and the fit's options only, not
/// on the effects a start is for, so the starts of one structure on one record share them
/// ([`linear_start_shared`]): made once, by whichever start asks first; a start whose
/// options or record differ makes its own. (The diagnosis's starts: the structure's and
/// the friction-compensated one's, and the extra mode's with and without friction, each
/// pair on the same fits: made twice, they were about a tenth of hard bench case 8's CPU.)
#[derive(Debug, Default)]
pub struct RawFrfFits {
    cell: OnceLock<(RawKey, RawFits)>,
}

/// What the raw fits were made from: the fit's options, the settling periods skipped and
/// the segments' lengths.
type RawKey = (FrfFitOptions, usize, Vec<usize>);

/// The raw fit (the better of the two) and the lines' evidence of a delay.
type RawFits = (Result<FrfFit, FrfFitError>, Option<DelayLines>);

impl RawFrfFits {
    /// The raw fits for `key`, made by `make` unless this cell holds them.
    fn get(&self, key: RawKey, make: impl Fn() -> RawFits) -> RawFits {
        let (made_for, fits) = self.cell.get_or_init(|| (key.clone(), make()));
        if *made_for == key {
            fits.clone()
        } else {
            make()
        }
    }
}

/// How far [`linear_start_shared`] searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartSearch {
    /// the lag alone and the lag with the delay free, the cheaper by AIC kept, with the
    /// lines' evidence of a delay ([`LinearStart::delay_lines`]); every start searched
    Full,
    /// a candidate's start, which its time-domain fit refines: the lag alone (its delay
    /// held at nought), one search instead of two and no evidence of a delay
    /// ([`LinearStart::delay_lines`] `None`), since the nonlinear fit takes the FRF's
    /// delay on its lag anyway; and the search over the FRF's peaks ends after
    /// [`CANDIDATE_PATIENCE`] starts in a row that did not lower its best cost
    /// ([`FrfFitOptions::patience`]). Diagnose's extra mode starts from the structure with
    /// one more mass, whose search took 242 starts on the speed bench's joint (3.6–4.0 s;
    /// 4.2 s more with the delay free); with the patience, 81 starts (1.3 s) and the same
    /// best start
    Candidate,
}

/// Starts in a row without progress that end a candidate's search ([`StartSearch::Candidate`])
pub const CANDIDATE_PATIENCE: usize = 48;

/// As [`linear_start_segments`], the raw fits of the FRF taken from `shared` when it holds
/// them for the same options and record ([`RawFrfFits`]); `start`, when given, the
/// optimiser's coordinates of a nearby fit of the structure that the raw fits try first
/// ([`FrfFitOptions::start`]); `search`, how far the search goes ([`StartSearch`]).
///
/// # Errors
/// [`LinearStartError`].
pub fn linear_start_shared(
    segments: &[Dataset],
    settle: usize,
    req: &NlRequest,
    (shared, start): (&RawFrfFits, Option<FrfStart>),
    search: StartSearch,
) -> Result<LinearStart, LinearStartError> {
    let analysis = crate::ident::frf::analyze_segments(segments, settle)?;
    let ts = analysis_ts(segments);
    let held = req.held();
    let mut o = FrfFitOptions::new(req.structure, ts);
    o.r = req.r;
    o.start = start;
    if let Some(t) = held {
        o.lag = Drive::Fixed(t / ts);
    }
    if search == StartSearch::Candidate {
        o.patience = Some(CANDIDATE_PATIENCE);
    }
    if search == StartSearch::Candidate
        || req
            .effects
            .iter()
            .any(|e| matches!(e, Effect::TimeDelay(_)))
    {
        o.delay = Drive::Fixed(0.0);
    }
    // the nonlinear model carries no frequency-domain delay (the FRF's delay goes to the
    // lag, below), and the search with the delay free can end in a worse basin than the
    // lag alone: with a lag to estimate and no `time_delay`, the lag-only search is made
    // too and kept when its cost is not above the free one's (the free model holds the
    // lag-only one, so in the same basin its cost can only be lower). Bench case 6 of
    // `diagnose`, a stiffening spring behind a 1.7-sample delay: the free search ended
    // with a 2.6-sample delay, no lag and a wrong arm at 3.2 times the noise's cost, the
    // lag-only one near the true arm at 2.7; the nominal fitted from the first stopped at
    // its iteration limit at twice the SSR of the second's minimum.
    let lag_only = (held.is_none() && o.delay == Drive::Estimate).then(|| FrfFitOptions {
        delay: Drive::Fixed(0.0),
        ..o.clone()
    });
    let law = req.effects.iter().find_map(|e| match e {
        Effect::CoulombFriction(c) => Some(*c),
        _ => None,
    });
    let key = (
        o.clone(),
        settle,
        segments.iter().map(|d| d.data.u.len()).collect(),
    );
    let (raw, delay_lines) = shared.get(key, || raw_fits(&analysis.frf, &o, lag_only.as_ref()));
    // then the compensated FRFs, one per lead, on threads, each fit started from the raw
    // FRF's
    let from_raw = FrfFitOptions {
        start: raw.as_ref().ok().map(FrfFit::as_start),
        ..o.clone()
    };
    let leads: Vec<Lead> = match law {
        Some(law) => parallel(
            &compensation_leads(segments, req, raw.as_ref().ok()),
            machine_threads(),
            |&lead| {
                let o = (&from_raw, analysis.layout.period);
                compensated_fit(segments, settle, req, o, law, lead)
            },
        ),
        None => Vec::new(),
    };
    // a lead whose level is no evidence of friction leaves out the compensation; else the
    // lowest cost relative to the noise, the first lead on a tie
    let comp = if law.is_none() || leads.iter().any(|c| matches!(c, Lead::NoEvidence)) {
        None
    } else {
        leads
            .into_iter()
            .filter_map(|c| match c {
                Lead::Fitted(c) => Some(*c),
                _ => None,
            })
            .fold(None, |best: Option<Compensated>, c| match best {
                Some(b) if b.fit.cost_ratio() <= c.fit.cost_ratio() => Some(b),
                _ => Some(c),
            })
    };
    let (ff, compensation) = match (raw, comp) {
        (Ok(raw), Some(c)) if c.fit.cost_ratio() < clear_drop(&raw) => {
            let before = raw.cost_ratio();
            let step = c.step(Some(before), true);
            (c.fit, Some(step))
        }
        (Ok(raw), Some(c)) => {
            let step = c.step(Some(raw.cost_ratio()), false);
            (raw, Some(step))
        }
        (Err(_), Some(c)) => {
            let step = c.step(None, true);
            (c.fit, Some(step))
        }
        (Ok(raw), None) => (raw, None),
        (Err(e), None) => return Err(e.into()),
    };
    // the delay's time on the lag: below the resonances the two shift the phase alike
    let lag = (ff.lag.value + ff.delay.value) * ts;
    let mut values: Vec<(String, f64, &'static str)> = ff
        .params
        .iter()
        .map(|p| (p.name.clone(), p.value, p.unit))
        .collect();
    values.push(("tau_c".into(), lag, "s"));
    let step = Step {
        name: "frequency-domain linear fit".into(),
        values,
        detail: format!(
            "sample maximum likelihood on {} excited lines{}; the linear {} {} the steps below \
             start from",
            ff.lines,
            if compensation
                .as_ref()
                .is_some_and(|c| c.values.iter().any(|v| v.0 == "used" && v.1 > 0.0))
            {
                " of the friction-compensated FRF"
            } else {
                ""
            },
            req.structure.label(),
            if held.is_some() {
                "(current-loop lag held)"
            } else {
                "and the current-loop lag"
            }
        ),
    };
    Ok(LinearStart {
        at_noise: ff.cost_ratio() <= crate::ident::sml::GOOD_START_RATIO,
        values: ff.values(),
        tau_c: match held {
            Some(t) => t,
            None if lag >= MIN_LAG => lag,
            None => 0.0,
        },
        step,
        compensation,
        delay_lines,
    })
}

/// The cost ratio a compensated fit must stay below to replace the fit `raw`: lower by
/// twice the ratio's spread for a right model, `√(2/2F)` relative over `F` lines (2F real
/// residuals, chi-squared), so that a compensation the data do not ask for (seed 001's
/// reference problem: 1.31 → 1.30) leaves the start alone.
fn clear_drop(raw: &crate::ident::sml::FrfFit) -> f64 {
    let f = raw.lines.max(1) as f64;
    raw.cost_ratio() * (1.0 - 2.0 * (1.0 / f).sqrt())
}

/// The frequency-domain fit of the friction-compensated FRF ([`super::compensate`]).
struct Compensated {
    fit: crate::ident::sml::FrfFit,
    fc: f64,
    level: Option<super::compensate::Level>,
    lead: usize,
}

impl Compensated {
    /// The step that reports it: the level taken off, the lead, the cost relative to the
    /// noise before (`before`, the uncompensated FRF's) and after, and whether it was used.
    fn step(&self, before: Option<f64>, used: bool) -> Step {
        let mut values = vec![("fc".to_string(), self.fc, "N·m")];
        if let Some(l) = &self.level {
            values.push(("fc_std".into(), l.std, "N·m"));
        }
        values.push(("lead".into(), self.lead as f64, "samples"));
        if let Some(b) = before {
            values.push(("cost_ratio_before".into(), b, "-"));
        }
        values.push(("cost_ratio_after".into(), self.fit.cost_ratio(), "-"));
        values.push(("used".into(), f64::from(u8::from(used)), "-"));
        Step {
            name: "friction compensation".into(),
            values,
            detail: format!(
                "F_c = {:.4e} N·m{} taken off the torque at the sign of the motor velocity {} \
                 sample(s) ahead before the FRF; the structure's fit to the excited lines costs \
                 {} times the noise's{}",
                self.fc,
                match &self.level {
                    Some(l) => format!(
                        " (inverse dynamics on the low-passed sign, torque error {:.1} % → \
                         {:.1} %)",
                        l.error_without, l.error_with
                    ),
                    None => " (held)".into(),
                },
                self.lead,
                match before {
                    Some(b) => format!("{:.2} → {:.2}", b, self.fit.cost_ratio()),
                    None => format!("{:.2}", self.fit.cost_ratio()),
                },
                if used {
                    ": the compensated fit is the start"
                } else {
                    ": no better than without, the uncompensated fit is the start"
                }
            ),
        }
    }
}

/// A compensated fit at one lead.
enum Lead {
    /// the regression's level is not above 3 σ: no evidence of friction
    NoEvidence,
    /// no level, FRF or fit came of it
    Failed,
    Fitted(Box<Compensated>),
}

/// The leads [samples] the friction compensation tries: one sample beyond the held lag,
/// else beyond the drive's lag and delay the fit of the measured FRF found when that fit
/// is at the noise level (in the right basin, its drive is the joint's: seed 001, three
/// leads 0.31 s of CPU, one 0.08 s), else 1–3 (a fit bent by the friction says nothing of
/// the drive: a three-mass joint with `F_c` half the torque ended at `J_m` −95 %).
fn compensation_leads(segments: &[Dataset], req: &NlRequest, raw: Option<&FrfFit>) -> Vec<usize> {
    let ts = segments.first().map_or(1.0, |d| d.data.ts);
    match (req.held(), raw) {
        (Some(t), _) => vec![1 + (t / ts).round() as usize],
        (None, Some(f)) if f.cost_ratio() <= crate::ident::sml::GOOD_START_RATIO => {
            let drive = (f.lag.value + f.delay.value).max(0.0);
            vec![1 + drive.round() as usize]
        }
        (None, _) => vec![1, 2, 3],
    }
}

/// The frequency-domain fit of the FRF with Coulomb friction of the shape `law` taken off
/// the torque `lead` samples ahead ([`super::compensate`]): the level held in the request,
/// else the regression's when significant (above 3 σ). `o`: the raw FRF's fit options, its
/// fit as the start; `period`: the raw FRF's period [samples].
fn compensated_fit(
    segments: &[Dataset],
    settle: usize,
    req: &NlRequest,
    (o, period): (&FrfFitOptions, usize),
    law: crate::model::effects::CoulombFriction,
    lead: usize,
) -> Lead {
    use super::compensate;
    let Some(longest) = segments
        .iter()
        .enumerate()
        .max_by_key(|(i, d)| (d.data.len(), usize::MAX - i))
        .map(|(_, d)| d)
    else {
        return Lead::Failed;
    };
    let law = crate::model::effects::CoulombFriction {
        v_smooth: model_of(req, &longest.data).v_eps,
        ..law
    };
    let fixed_fc = req.fixed.iter().find(|(n, _)| n == "fc").map(|(_, v)| *v);
    let (fc, level) = match fixed_fc {
        Some(f) => (f, None),
        None => {
            let Some(l) = compensate::level(&longest.data, lead, &law) else {
                return Lead::NoEvidence;
            };
            // a level not above 3 σ (or a NaN σ) is no evidence of friction
            let significant = l.fc > 3.0 * l.std;
            if !significant {
                return Lead::NoEvidence;
            }
            (compensate::SHARE * l.fc, Some(l))
        }
    };
    // the torque changed, not the reference: the period the raw FRF found holds (stated,
    // so that it is not detected again)
    let comp: Vec<Dataset> = segments
        .iter()
        .map(|d| {
            let mut c = compensate::compensated(d, fc, lead, &law);
            if c.stated_period().is_none() {
                c.meta.insert("period_samples".into(), period.to_string());
            }
            c
        })
        .collect();
    let Ok(a) = crate::ident::frf::analyze_segments(&comp, settle) else {
        return Lead::Failed;
    };
    match crate::ident::sml::fit_frf(&a.frf, o) {
        Ok(fit) => Lead::Fitted(Box::new(Compensated {
            fit,
            fc,
            level,
            lead,
        })),
        Err(_) => Lead::Failed,
    }
}

fn analysis_ts(segments: &[Dataset]) -> f64 {
    segments.first().map_or(1.0, |d| d.data.ts)
}

/// Warnings of a finished fit: iteration limit, parameters on a bound, parameters the data
/// do not determine (σ above half the value), and pairs the data hardly tell apart
/// (`|ρ| ≥ 0.98` with either σ above 5 % of its value: a current-loop lag and a delay
/// under a soft controller, whose phase lags look alike below the loop's bandwidth).
pub fn checks(fit: &NlFit) -> Vec<String> {
    let mut w = Vec::new();
    if fit.termination == Termination::MaxIterations {
        w.push(format!(
            "the fit stopped at its iteration limit ({} iterations): not a minimum",
            fit.iterations
        ));
    }
    for p in &fit.params {
        if p.owner == Owner::InitialVelocity || p.fixed {
            continue;
        }
        if p.at_bound {
            w.push(format!(
                "`{}` = {:.4e} {} lies on a bound of the search",
                p.name, p.value, p.unit
            ));
        }
        if p.owner != Owner::Offset && p.std > 0.5 * p.value.abs() {
            w.push(if unbounded(p.std, p.value) {
                format!(
                    "`{}` = {:.4e} {} is not determined by these data at all (its standard \
                     deviation is unbounded: the simulation does not depend on it here)",
                    p.name, p.value, p.unit
                )
            } else {
                format!(
                    "`{}` = {:.4e} ± {:.1e} {} is poorly determined by these data",
                    p.name, p.value, p.std, p.unit
                )
            });
        }
    }
    // a Jacobian of rank one or nought (a simulation gone flat or unstable on the way)
    // gives standard deviations of nought and every pair a correlation of ±1
    let degenerate = fit.params.iter().any(|p| {
        !p.fixed
            && p.owner != Owner::InitialVelocity
            && (p.std.is_nan() || p.std <= 1e-9 * p.value.abs())
    });
    if degenerate {
        w.push(
            "the covariance is degenerate (a standard deviation of nought): the model's \
             sensitivity to its parameters vanished at this point; the estimates are not to \
             be trusted"
                .to_string(),
        );
    }
    let param = |name: &str| fit.params.iter().find(|p| p.name == name);
    let relative_std = |name: &str| param(name).map_or(0.0, |p| p.std / p.value.abs());
    for c in fit.correlated.iter().filter(|c| c.rho.abs() >= 0.98) {
        let (sa, sb) = (relative_std(c.a), relative_std(c.b));
        // NaN (a σ of nought at a value of nought) is no spread
        if sa.max(sb) > 0.05 {
            let alone = |name: &str| param(name).map_or(String::new(), spread);
            w.push(format!(
                "`{}` and `{}` trade against each other (correlation {:+.3}): the data fix a \
                 combination of them, each alone only to {} and {}; fix one (`--fix`) if it \
                 is known",
                c.a,
                c.b,
                c.rho,
                alone(c.a),
                alone(c.b)
            ));
        }
    }
    w
}

/// Whether a standard deviation `std` says nothing of the value `value` it belongs to: not
/// finite, or beyond [`UNBOUNDED_STD`] times the value (a parameter the simulation does not
/// depend on gives a σ of 1e183 from a nearly singular information matrix, not a figure).
fn unbounded(std: f64, value: f64) -> bool {
    !std.is_finite() || std > UNBOUNDED_STD * value.abs().max(f64::MIN_POSITIVE)
}

/// The ratio of a standard deviation to its value beyond which [`unbounded`] holds.
const UNBOUNDED_STD: f64 = 1e6;

/// How far the data fix parameter `p` alone: its standard deviation relative to its value
/// (`±12 %`), in its unit when the value is nought, or `not at all` when [`unbounded`].
fn spread(p: &NlParam) -> String {
    if p.value == 0.0 && p.std.is_finite() {
        format!("±{:.1e} {}", p.std, p.unit)
    } else if unbounded(p.std, p.value) {
        "not at all".to_string()
    } else {
        format!("±{:.0} %", 100.0 * p.std / p.value.abs())
    }
}

/// Validates `fit` on `val` (module documentation): the model simulated from the measured
/// torque (plus the fitted offset) with the simulator's exact laws, from rest at the
/// first measured angle with the fitted initial velocity.
///
/// # Errors
/// [`NlError::Record`] for a short record, [`NlError::Unstable`] when the simulation is not
/// finite.
pub fn validate(fit: &NlFit, val: &IdData, opts: &NlOptions) -> Result<NlValidation, NlError> {
    validate_segments(fit, std::slice::from_ref(val), opts)
}

/// As [`validate`] on several records (the gap-free segments of one capture), each
/// simulated from rest at its own first angle and through its own prefilter, the FITs
/// pooled over all of them.
///
/// # Errors
/// As [`validate`], for any record; [`NlError::NoValidationRecord`] for no record.
pub fn validate_segments(
    fit: &NlFit,
    vals: &[IdData],
    opts: &NlOptions,
) -> Result<NlValidation, NlError> {
    if vals.is_empty() {
        return Err(NlError::NoValidationRecord);
    }
    let model = &fit.model;
    let offset = fit.get("offset").unwrap_or(0.0);
    let plant = sim_plant(model, &fit.plant);
    // no current loop in the model: a lag far below the sample interval
    let tc = if model.tau_c > 0.0 { model.tau_c } else { 1e-9 };
    // the estimation record's initial velocity means nothing here: from rest, as below
    let mut values = fit.values.clone();
    if let Some(v0) = values.last_mut() {
        *v0 = 0.0;
    }
    // the FITs' sums record by record, sample by sample (a long record is not copied into
    // pairs: issue 37 item 9), in the order of the FITs of the records laid end to end
    let ts = vals[0].ts;
    let mut exact = VelocityFitSums::new(ts, opts.highpass_hz);
    let mut smooth = VelocityFitSums::new(ts, opts.highpass_hz);
    // `Σ (θ_m − θ̂_m)²` of the angle over every record
    let mut angle_ssr = 0.0;
    let mut angle_lengths_agree = true;
    for val in vals {
        val.check(20).map_err(NlError::Record)?;
        let u: Vec<f64> = val.u.iter().map(|u| u + offset).collect();
        let out = simulate_driven(
            &plant,
            &model.effects,
            tc,
            val.ts,
            &u,
            &DrivenStart::Rest { theta_m: val.y[0] },
        )
        .map_err(NlError::ValidationSimulation)?;
        drop(u);
        exact.push(interval_velocities(&val.y, ts).zip(interval_velocities(&out.theta_m, ts)));
        angle_lengths_agree &= out.theta_m.len() == val.y.len();
        for (y, yh) in val.y.iter().zip(&out.theta_m) {
            angle_ssr += (y - yh).powi(2);
        }
        drop(out);
        let vh = simulate_velocity(model, &values, &val.u, val.ts, val.y[0], None)
            .ok_or(NlError::Unstable)?;
        smooth.push(interval_velocities(&val.y, ts).zip(vh[1..].iter().copied()));
    }
    let measured = || vals.iter().flat_map(|v| v.y.iter());
    let angle_fit_percent = if angle_lengths_agree {
        let mean = measured().sum::<f64>() / measured().count().max(1) as f64;
        let den: f64 = measured().map(|y| (y - mean).powi(2)).sum();
        (den != 0.0).then(|| crate::ident::validate::fit_from_sums(angle_ssr, den))
    } else {
        None
    };
    Ok(NlValidation {
        velocity_fit_percent: exact.pooled().unwrap_or(f64::NAN),
        velocity_fit_smooth_percent: smooth.pooled().unwrap_or(f64::NAN),
        angle_fit_percent: angle_fit_percent.unwrap_or(f64::NAN),
    })
}

#[cfg(test)]
mod spread_tests {
    use super::{spread, NlParam, Owner};

    fn param(value: f64, std: f64) -> NlParam {
        NlParam {
            name: "f_m",
            owner: Owner::Plant,
            value,
            std,
            unit: "N·m·s/rad",
            fixed: false,
            at_bound: false,
            at_lower: false,
        }
    }

    /// A parameter's spread is read as a share of its value; a σ of 1e183 on a value of
    /// 1e-5 (a nearly singular information matrix) is no figure, and a value of nought has
    /// its σ in its unit, not as ±inf %.
    #[test]
    fn a_spread_is_a_share_of_the_value_unless_it_is_unbounded() {
        assert_eq!(spread(&param(2.0, 0.5)), "±25 %");
        assert_eq!(spread(&param(1.2e-5, 3.8e183)), "not at all");
        assert_eq!(spread(&param(1.2e-5, f64::NAN)), "not at all");
        assert_eq!(spread(&param(0.0, 3.7e-2)), "±3.7e-2 N·m·s/rad");
    }
}
