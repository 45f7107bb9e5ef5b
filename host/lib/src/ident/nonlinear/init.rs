//! Starting values from the data, never from the user (seed 001 §4, its three steps):
//! 1. **rigid body**: total inertia `J` and viscous friction `F_v` by inverse-dynamics least
//!    squares on low-passed data ([`grey_box::rigid_idim`]);
//! 2. **friction**: `F_v`, `F_c` and a torque offset from the same torque–velocity relation
//!    with the Coulomb regressor `sgn(ω)`; for an asymmetric Coulomb friction (`fc_neg`,
//!    `fv_neg_extra` given) also each direction's levels, by the asymmetric regression
//!    ([`IdimOptions::asymmetric`]);
//! 3. **flexibility**: the linear structure (the caller's linear fit, e.g. the
//!    frequency-domain one, or modal features of a subspace model,
//!    [`grey_box::features`]), refined by the output-error fit with friction only; then each
//!    remaining effect's size from a one-dimensional search of the output-error cost over a
//!    grid scaled by the data (cubic term against the deflection level, backlash width
//!    against it, delay in samples with its time taken from the lag of the linear fit, the
//!    extra mode's frequency against the first resonance; a single extra mode is also
//!    started at each peak of the linear fit's residual, [`Start::at_peaks`], and the fit
//!    keeps the lower cost). A linear start with a mode or
//!    damper faster than the RK4 step integrates is brought to the fastest it holds
//!    ([`resolvable`]) first: as it came, it would not simulate.
//!
//! Each step's result is kept ([`Step`]) and reported, as seed 001 reports them.

use super::model::NlModel;
use super::output_error::{fit_output_error, NlError, NlFit, NlOptions, DEFAULT_HIGHPASS_HZ};
use crate::data::{rms_about_mean, IdData};
use crate::ident::grey_box::{self, IdimOptions, Output};
use crate::ident::parallel::{machine_threads, parallel};
use crate::model::effects::{Attach, Effect, ExtraMode};
use crate::model::spec::Structure;

/// Low-pass cut-off of the rigid-body and friction regressions [Hz]: below the first
/// anti-resonance of a robot joint (seed 000: 17 Hz; seed 001: 15 Hz), where the joint moves
/// as one body, and above the rigid-body corner of the closed loop.
const RIGID_CUTOFF_HZ: f64 = 8.0;

/// The grounded mass's inverse-dynamics low-pass, as a share of the sample rate (0.1: a
/// fifth of the Nyquist band, 200 Hz at 2 kHz), so that its resonance lies in the band.
const GROUNDED_CUTOFF: f64 = 0.1;

/// One step of the automatic start and what it found.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// what the step does (`rigid body`, `friction`, `flexibility`, an effect's name)
    pub name: String,
    /// (name, value, unit) it found
    pub values: Vec<(String, f64, &'static str)>,
    /// how well: the cost measure the step used, in words
    pub detail: String,
}

impl Step {
    /// The values a fit found, as a step reports them: every parameter but the initial
    /// velocity (a nuisance of the record, not of the joint).
    pub fn values_of(fit: &NlFit) -> Vec<(String, f64, &'static str)> {
        fit.params
            .iter()
            .filter(|p| p.name != "v0")
            .map(|p| (p.name.to_string(), p.value, p.unit))
            .collect()
    }
}

/// The automatic start and the record of its steps.
#[derive(Clone, Debug, PartialEq)]
pub struct Start {
    /// physical values in the layout order of [`NlModel::layout`]
    pub values: Vec<f64>,
    /// the model with the start's effect values
    pub model: NlModel,
    /// the steps, in order
    pub steps: Vec<Step>,
    /// layout names the fit must hold at the start's values (a ripple whose order the data
    /// do not show: its amplitude at 0 and its phase)
    pub held: Vec<String>,
    /// what the start could not find, in words
    pub warnings: Vec<String>,
    /// the last search of the torque ripple's order in the data (none with the order given
    /// or without a ripple)
    pub ripple_search: Option<super::ripple::OrderSearch>,
    /// for a model whose one effect is an extra mode, the start again with the mode at each
    /// peak of the linear fit's residual ([`modes_at_residual_peaks`]): the mode, its peak
    /// [Hz] and the values, for the fit to weigh against the grid's start
    pub at_peaks: Vec<(ExtraMode, f64, Vec<f64>)>,
}

/// Where the torque ripple's order comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RippleOrder {
    /// the order the model's ripple carries
    #[default]
    Given,
    /// searched in the data ([`super::ripple::search_order`]) on the linear start, and again
    /// on the linear fit with the ripple
    FromData,
    /// searched as [`RippleOrder::FromData`], the best candidate taken even short of its
    /// z-score when it is coherent along the record ([`super::ripple::OrderSearch::best_taken`])
    BestFromData,
}

/// A linear fit the automatic start builds on (step 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearFit<'a> {
    /// the structure's values ([`Structure::param_names`] order) [SI]
    pub values: &'a [f64],
    /// it explains the FRF's excited lines to within a few times their noise
    /// ([`crate::ident::sml::GOOD_START_RATIO`]): a start in the right basin, which the
    /// two-mass grid (a rescue for a linear fit that missed it) cannot better
    pub at_noise: bool,
}

/// The automatic start of `model` on `data` (module documentation). `linear`: the
/// structure's values from a linear fit the caller trusts (in
/// [`Structure::param_names`] order), used for step 3 instead of the subspace features.
///
/// # Errors
/// [`NlError::StartStep`], [`NlError::NoInertia`] or [`NlError::NoFlexibleStart`] when a
/// step cannot read the data.
pub fn automatic_start(
    data: &IdData,
    model: &NlModel,
    linear: Option<&[f64]>,
) -> Result<Start, NlError> {
    let linear = linear.map(|values| LinearFit {
        values,
        at_noise: false,
    });
    automatic_start_with(
        data,
        model,
        linear,
        RippleOrder::Given,
        &NlOptions::default(),
    )
}

/// As [`automatic_start`], the torque ripple's order taken from `order`; the start's own
/// refinements low-pass the residual at the band of `fit`, the fit's options
/// ([`NlOptions::lowpass_hz`]).
///
/// # Errors
/// As [`automatic_start`].
pub fn automatic_start_with(
    data: &IdData,
    model: &NlModel,
    linear: Option<LinearFit<'_>>,
    order: RippleOrder,
    fit: &NlOptions,
) -> Result<Start, NlError> {
    let mut steps = Vec::new();
    let mut held: Vec<String> = Vec::new();
    let mut warnings: Vec<String> = Vec::new();
    // step 1: rigid body (the grounded mass with its spring, on a band that holds its
    // resonance: below it the spring alone carries the torque and the inertia is not seen)
    let grounded = model.structure == Structure::Grounded;
    let cutoff_hz = if grounded {
        GROUNDED_CUTOFF / data.ts
    } else {
        RIGID_CUTOFF_HZ
    };
    let rigid = grey_box::rigid_idim(
        data,
        &IdimOptions {
            cutoff_hz,
            coulomb: false,
            offset: true,
            spring: grounded,
            ..IdimOptions::default()
        },
    )?;
    let j_total = rigid.get("J").unwrap_or(f64::NAN);
    if j_total.is_nan() || j_total <= 0.0 {
        // what the data show instead: a mass held by a spring to the frame?
        let held = grey_box::rigid_idim(
            data,
            &IdimOptions {
                cutoff_hz: GROUNDED_CUTOFF / data.ts,
                coulomb: false,
                offset: true,
                spring: true,
                ..IdimOptions::default()
            },
        );
        let positive = |f: &grey_box::RigidFit, n: &str| f.get(n).is_some_and(|v| v > 0.0);
        let grounded = !grounded && held.is_ok_and(|f| positive(&f, "J") && positive(&f, "K"));
        return Err(NlError::NoInertia { grounded });
    }
    steps.push(Step {
        name: "rigid body".into(),
        values: rigid
            .params
            .iter()
            .map(|p| (p.name.clone(), p.value, p.unit))
            .collect(),
        detail: format!(
            "inverse-dynamics least squares, torque error {:.1} %",
            rigid.rel_error_percent
        ),
    });
    // step 2: friction (and ripple by the same regression)
    let has_coulomb = model
        .effects
        .iter()
        .any(|e| matches!(e, Effect::CoulombFriction(_)));
    let friction = grey_box::rigid_idim(
        data,
        &IdimOptions {
            cutoff_hz,
            coulomb: true,
            offset: true,
            spring: grounded,
            ..IdimOptions::default()
        },
    )?;
    let mut fv = friction.get("Fv").unwrap_or(0.0);
    let mut fc = friction.get("Fc").unwrap_or(0.0);
    // the regression's offset is on the torque side (`u = … + offset`); the model's adds
    // to the motor torque
    let mut offset = -friction.get("offset").unwrap_or(0.0);
    steps.push(Step {
        name: "friction".into(),
        values: friction
            .params
            .iter()
            .map(|p| (p.name.clone(), p.value, p.unit))
            .collect(),
        detail: format!(
            "torque-velocity least squares, torque error {:.1} %",
            friction.rel_error_percent
        ),
    });
    // each direction's levels: `fc_neg` as a share of `fc` (the Coulomb grid below scales
    // both alike) and the backward viscous extra
    let asym_spec = model.effects.iter().find_map(|e| match e {
        Effect::CoulombFriction(c) if c.is_asymmetric() => Some(*c),
        _ => None,
    });
    let mut asym: Option<Asym> = None;
    if let Some(spec) = asym_spec {
        let a = grey_box::rigid_idim(
            data,
            &IdimOptions {
                cutoff_hz: RIGID_CUTOFF_HZ,
                coulomb: true,
                asymmetric: true,
                ..IdimOptions::default()
            },
        )?;
        let (fcp, fcn) = (a.get("Fc").unwrap_or(0.0), a.get("Fc_neg").unwrap_or(0.0));
        let (fvp, fvn) = (a.get("Fv").unwrap_or(0.0), a.get("Fv_neg").unwrap_or(0.0));
        if fcp > 0.0 && fcn > 0.0 {
            if spec.fc_neg.is_some() {
                // the levels replace the offset (held at 0, `run::identify`)
                fc = fcp;
                offset = 0.0;
            } else {
                // their mean is the level, half their difference the offset
                fc = 0.5 * (fcp + fcn);
                offset = -0.5 * (fcp - fcn);
            }
            if spec.fv_neg_extra.is_some() {
                fv = fvp;
            }
            asym = Some(Asym {
                neg_ratio: fcn / fc,
                fv_extra: fvn - fvp,
            });
        }
        steps.push(Step {
            name: "friction, each direction".into(),
            values: a
                .params
                .iter()
                .map(|p| (p.name.clone(), p.value, p.unit))
                .collect(),
            detail: format!(
                "torque-velocity least squares with each direction's levels, torque error \
                 {:.1} %",
                a.rel_error_percent
            ),
        });
    }
    let j_used = if has_coulomb {
        friction.get("J").unwrap_or(j_total)
    } else {
        j_total
    };
    let fv_used = if has_coulomb {
        fv
    } else {
        rigid.get("Fv").unwrap_or(fv)
    };
    // a positive floor keeps the log-parameters finite when friction is not seen
    let fv_used = fv_used.max(1e-6 * j_used);
    let u_rms = torque_rms(data);
    let fc_used = if fc > 0.0 { fc } else { 0.01 * u_rms };

    // the output-error steps below (each linear start's refinement, the grids of the
    // Coulomb level, the ripple and every further effect) on the record's head
    let head = start_head(data);
    let part = head.as_ref().unwrap_or(data);
    let on_part = if head.is_some() {
        format!(" on the first {} of {} samples", part.len(), data.len())
    } else {
        String::new()
    };

    // step 3: flexibility, linear; every start the data offer (the caller's linear fit, the
    // subspace model's modal features, for the two-mass a grid unless the caller's fit is
    // at the noise level), each refined, the best kept
    let mut plants: Vec<Vec<f64>> = Vec::new();
    if let Some(p) = linear {
        plants.push(p.values.to_vec());
    }
    match model.structure {
        Structure::Rigid => plants.push(vec![j_used, fv_used]),
        Structure::Grounded => {
            let source = if has_coulomb { &friction } else { &rigid };
            let k = source.get("K").unwrap_or(f64::NAN);
            if k > 0.0 && k.is_finite() {
                plants.push(vec![j_used, fv_used, k]);
            }
        }
        // (seed 001: the frequency-domain fit at 1.3 times the noise's cost; the grid's
        // start, 0.3 s of the fit's 1.5, lost the race at 9.31·10³ against 7.06·10³)
        Structure::TwoMass if linear.is_some_and(|l| l.at_noise) => {}
        Structure::TwoMass => {
            plants.push(two_mass_grid(
                part, model, j_used, fv_used, fc_used, offset, asym,
            ));
        }
        s => plants.extend(modal_start(data, s, model.r, (j_used, fv_used))),
    }
    if plants.is_empty() {
        return Err(NlError::NoFlexibleStart);
    }
    let h = data.ts / model.substeps.max(1) as f64;
    for plant in &mut plants {
        if let Some(w) = resolvable(model.structure, model.r, plant, h) {
            warnings.push(w);
        }
    }
    let with_fc = |fc: f64| -> Vec<Effect> {
        model
            .effects
            .iter()
            .filter_map(|e| match e {
                Effect::CoulombFriction(c) => {
                    Some(Effect::CoulombFriction(friction_at(c, fc, asym)))
                }
                _ => None,
            })
            .collect()
    };
    // the ripple's order from the data: on the linear start that explains the data best
    let mut ripple = model.effects.iter().find_map(|e| match e {
        Effect::TorqueRipple(r) => Some(*r),
        _ => None,
    });
    let mut searched: Option<super::ripple::OrderSearch> = None;
    // where the warning of an order below the candidates is (the search again on the
    // linear fit rewrites it)
    let mut short_warning: Option<usize> = None;
    let from_data = matches!(order, RippleOrder::FromData | RippleOrder::BestFromData);
    let taken = |f: Option<super::ripple::OrderSearch>| match order {
        RippleOrder::BestFromData => f.map(super::ripple::OrderSearch::best_taken),
        _ => f,
    };
    if let (Some(r), true) = (ripple.as_mut(), from_data) {
        let m = NlModel {
            effects: with_fc(fc_used),
            ..model.clone()
        };
        let best_plant = plants
            .iter()
            .filter_map(|p| {
                let v = m.values(p, offset, 0.0);
                super::output_error::cost_at(data, &m, &v).map(|c| (c, v))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let found = taken(match best_plant {
            Some((_, v)) => super::ripple::search_order(data, &m, &v)?,
            None => None,
        });
        match &found {
            Some(f) if f.order.is_some() => {
                r.order = f.order.map_or(0.0, f64::from);
                r.amplitude = f.amplitude;
                r.phase = f.phase;
                if f.short() {
                    short_warning = Some(warnings.len());
                    warnings.push(short_order_warning(f));
                }
                // one more linear start: the structure's modal features with the ripple
                // taken off the torque (over a short travel the ripple is a stiffness to the
                // ground, which bends every start from the raw torque); its spring is only
                // brought to what the simulation integrates, without a word, as a start
                // among others
                if f.short() && model.structure.masses() > 1 {
                    let comp = super::ripple::compensated(data, r);
                    let s = model.structure;
                    if let Some(mut p) = modal_start(&comp, s, model.r, (j_used, fv_used)) {
                        resolvable(s, model.r, &mut p, h);
                        plants.push(p);
                    }
                }
            }
            _ => {
                warnings.push(order_warning(found.as_ref()));
                held.extend(["amplitude".to_string(), "phase".to_string()]);
            }
        }
        steps.push(order_step(found.as_ref(), "on the linear start"));
        searched = found;
    }
    let ripple_found = ripple.is_some() && held.is_empty();
    // each linear start refined on its own thread for a few iterations (a race), the one of
    // lowest cost (the first on a tie, as on one thread) then to its end; with one start,
    // that one to its end. On a record's head the race's leader is not taken further: the
    // whole model's fit on the same head goes on from it, with the effects in
    let refining = |max_iter: usize| NlOptions {
        max_iter,
        cov_lags: 0,
        exact_correction: false,
        smoothing_sigma: false,
        rel_cost_tol: start_tolerance(part),
        fixed: if holds_offset(model) {
            vec!["offset".into()]
        } else {
            Vec::new()
        },
        lowpass_hz: fit.lowpass_hz,
        ..NlOptions::default()
    };
    let first_iter = if plants.len() > 1 || head.is_some() {
        RACE_ITER
    } else {
        START_ITER
    };
    let refine = |plant: &Vec<f64>| -> Option<(super::output_error::NlFit, Vec<f64>)> {
        // the Coulomb level: the regression's, or the grid value that explains the data best
        // with this linear start (the regression misses friction that shows only at reversals)
        let mut fc = fc_used;
        if has_coulomb {
            let mut best = f64::INFINITY;
            for f in [fc_used, 0.03 * u_rms, 0.1 * u_rms, 0.3 * u_rms, 0.6 * u_rms] {
                let m = NlModel {
                    effects: with_fc(f),
                    ..model.clone()
                };
                if let Some(c) =
                    super::output_error::cost_at(part, &m, &m.values(plant, offset, 0.0))
                {
                    if c < best {
                        best = c;
                        fc = f;
                    }
                }
            }
        }
        // a torque ripple is a torque at the measured angle, like an input: its size and
        // phase from a grid on this linear start, so that the linear fit does not bend
        // the structure to explain it
        let mut effects = with_fc(fc);
        if let Some(r) = ripple.filter(|_| ripple_found) {
            let mut best: Option<(f64, Effect)> = None;
            // the search's own amplitude and phase among the grid's
            let own = searched.is_some().then_some(Effect::TorqueRipple(r));
            for cand in candidates(&Effect::TorqueRipple(r), plant, model, 0.0, u_rms)
                .into_iter()
                .chain(own)
            {
                let mut with = effects.clone();
                with.push(cand);
                let m = NlModel {
                    effects: with,
                    ..model.clone()
                };
                if let Some(c) =
                    super::output_error::cost_at(part, &m, &m.values(plant, offset, 0.0))
                {
                    if best.as_ref().is_none_or(|(b, _)| c < *b) {
                        best = Some((c, cand));
                    }
                }
            }
            if let Some((_, cand)) = best {
                effects.push(cand);
            }
        }
        let lin_model = NlModel {
            effects,
            ..model.clone()
        };
        let lin_start = lin_model.values(plant, offset, 0.0);
        fit_output_error(part, &lin_model, &lin_start, &refining(first_iter))
            .ok()
            .map(|f| (f, lin_start))
    };
    let mut lin: Option<(super::output_error::NlFit, Vec<f64>)> = None;
    for (f, from) in parallel(&plants, machine_threads(), refine)
        .into_iter()
        .flatten()
    {
        if lin.as_ref().is_none_or(|(l, _)| f.ssr < l.ssr) {
            lin = Some((f, from));
        }
    }
    // the leader of the race goes on alone, within the bounds of its start
    if let Some((l, from)) = lin.as_mut().filter(|(l, _)| {
        first_iter < START_ITER
            && head.is_none()
            && l.termination == crate::ident::lm::Termination::MaxIterations
    }) {
        let opts = NlOptions {
            range_from: Some(from.clone()),
            ..refining(START_ITER - first_iter)
        };
        if let Ok(f) = fit_output_error(part, &l.model, &l.values, &opts) {
            if f.ssr <= l.ssr {
                *l = f;
            }
        }
    }
    let lin = lin.map(|(l, _)| l).ok_or(NlError::Unstable)?;
    steps.push(Step {
        name: "flexibility".into(),
        values: Step::values_of(&lin),
        detail: format!(
            "linear {} by output error on the motor velocity{on_part}, {} iterations, FIT {:.2} %",
            model.structure.label(),
            lin.iterations,
            lin.fit_velocity_percent
        ),
    });

    // the remaining effects, one at a time, on the linear fit
    let mut lin_plant = lin.plant.clone();
    let lin_offset = lin.get("offset").unwrap_or(offset);
    let lin_fc = lin.get("fc").unwrap_or(fc_used);
    let mut current: Vec<Effect> = Vec::with_capacity(model.effects.len());
    for e in &model.effects {
        current.push(match *e {
            Effect::CoulombFriction(c) => lin
                .model
                .effects
                .iter()
                .find(|e| matches!(e, Effect::CoulombFriction(_)))
                .copied()
                .unwrap_or(Effect::CoulombFriction(friction_at(&c, lin_fc, asym))),
            Effect::TorqueRipple(r) => lin
                .model
                .effects
                .iter()
                .find(|e| matches!(e, Effect::TorqueRipple(_)))
                .copied()
                .unwrap_or(neutral(Effect::TorqueRipple(ripple.unwrap_or(r)))),
            other => neutral(other),
        });
    }
    // the order again on the linear fit with the ripple (a better residual than the linear
    // start's): the travel tells neighbouring orders apart only where the model is good
    if ripple_found && from_data {
        let m = NlModel {
            effects: lin
                .model
                .effects
                .iter()
                .filter(|e| !matches!(e, Effect::TorqueRipple(_)))
                .copied()
                .collect(),
            ..lin.model.clone()
        };
        let v = m.values(&lin_plant, lin_offset, lin.get("v0").unwrap_or(0.0));
        if let Some(f) = taken(super::ripple::search_order(data, &m, &v)?) {
            if let Some(n) = f.order {
                let text = f.short().then(|| short_order_warning(&f));
                match (short_warning, text) {
                    (Some(i), Some(t)) => warnings[i] = t,
                    (Some(i), None) => {
                        warnings.remove(i);
                    }
                    (None, Some(t)) => warnings.push(t),
                    (None, None) => {}
                }
                for e in current.iter_mut() {
                    if let Effect::TorqueRipple(r) = e {
                        if r.order != f64::from(n) {
                            *r = crate::model::effects::TorqueRipple {
                                amplitude: f.amplitude,
                                order: f64::from(n),
                                phase: f.phase,
                            };
                        }
                    }
                }
            }
            steps.push(order_step(Some(&f), "again on the linear fit"));
            searched = Some(f);
        }
    }
    let spring_at = stiffened_spring(model);
    let delta = deflection_level(model, &lin_plant, data, u_rms);
    // the lag the linear fit refined with the structure's values; a delay takes its time
    // from it (below)
    let mut tau_c = lin.model.tau_c;
    for i in 0..model.effects.len() {
        if matches!(model.effects[i], Effect::TorqueRipple(_)) {
            continue; // sized with the linear fit of step 3
        }
        let grid: Vec<Effect> = candidates(&model.effects[i], &lin_plant, model, delta, u_rms);
        if grid.is_empty() {
            continue;
        }
        let mut best: Option<(f64, Effect, f64, Vec<f64>)> = None;
        let at_spring = |cand: &Effect| split_spring(cand, &lin_plant, spring_at);
        for (cand, plant) in grid.iter().flat_map(|c| {
            std::iter::once((*c, lin_plant.clone()))
                .chain(at_spring(c).into_iter().map(|p| (*c, p)))
        }) {
            let mut effects = current.clone();
            effects[i] = cand;
            // below the resonances a delay and the lag shift the phase alike, and the
            // linear fit gave the lag all of it: each delay of the grid takes its time from
            // the lag (down to a tenth of it, which keeps the lag in the model), so that
            // the search weighs how the phase is shared, not a delay on top of the whole
            // lag (bench case 4 of `diagnose`, a 1.9-sample delay behind a 0.5 ms lag, from
            // a linear start whose lag held the whole phase: 0.15 samples with the delay
            // added on top, 1.86 with its time taken from the lag)
            let lag = match cand {
                Effect::TimeDelay(d) if tau_c > 0.0 => {
                    (tau_c - d.samples * data.ts).max(0.1 * tau_c)
                }
                _ => tau_c,
            };
            let m = NlModel {
                effects,
                tau_c: lag,
                ..model.clone()
            };
            let values = m.values(&plant, lin_offset, 0.0);
            if let Some(cost) = super::output_error::cost_at(part, &m, &values) {
                if best.as_ref().is_none_or(|(c, ..)| cost < *c) {
                    best = Some((cost, cand, lag, plant));
                }
            }
        }
        if let Some((cost, cand, lag, plant)) = best {
            current[i] = cand;
            tau_c = lag;
            lin_plant = plant;
            let m = NlModel {
                effects: vec![cand],
                tau_c: lag,
                ..model.clone()
            };
            let layout = m.layout();
            let vals = m.values(&lin_plant, lin_offset, 0.0);
            // a delay reports the lag it left
            let lag_too = matches!(cand, Effect::TimeDelay(_));
            steps.push(Step {
                name: cand.name().into(),
                values: layout
                    .iter()
                    .zip(&vals)
                    .filter(|(d, _)| {
                        matches!(d.owner, super::model::Owner::Effect(_))
                            || lag_too && d.owner == super::model::Owner::CurrentLoop
                    })
                    .map(|(d, &v)| (d.name.to_string(), v, d.unit))
                    .collect(),
                detail: format!("best of a grid on the output-error cost{on_part} ({cost:.4e})"),
            });
        }
    }
    let start_model = NlModel {
        effects: current,
        tau_c,
        ..model.clone()
    };
    let v0 = lin.get("v0").unwrap_or(0.0);
    let values = start_model.values(&lin_plant, lin_offset, v0);
    // a single extra mode: the grid ranks its frequencies by the cost at the start, which a
    // fit without the mode has already lowered, so the mode is also started where the
    // linear fit leaves its residual peaks, for the fit to weigh
    let at_peaks = match start_model.effects[..] {
        [Effect::ExtraMode(x)] => modes_at_residual_peaks(part, &lin, x)
            .into_iter()
            .map(|(at, f_hz, plant)| {
                let m = NlModel {
                    effects: vec![Effect::ExtraMode(at)],
                    ..start_model.clone()
                };
                (at, f_hz, m.values(&plant, lin_offset, v0))
            })
            .collect(),
        _ => Vec::new(),
    };
    Ok(Start {
        values,
        model: start_model,
        steps,
        held,
        warnings,
        ripple_search: searched,
        at_peaks,
    })
}

/// The step of an order search (`on`: what it searched on).
fn order_step(found: Option<&super::ripple::OrderSearch>, on: &str) -> Step {
    match found {
        Some(f) if f.short() => Step {
            name: "torque_ripple order".into(),
            values: vec![
                ("order".into(), f.order.map_or(0.0, f64::from), "-"),
                ("periods".into(), f.periods, "-"),
                ("coherence".into(), f.coherence, "-"),
                ("amplitude".into(), f.amplitude, "N·m"),
                ("phase".into(), f.phase, "rad"),
            ],
            detail: format!(
                "found below the candidates: the ripple of order {} removes {:.1} % of the \
                 velocity cost {on}{}; the travel covers {:.2} of its periods, too few to \
                 tell it from its neighbours, so it stands for a torque against the motor \
                 angle over the travel",
                f.order.unwrap_or(0),
                100.0 * f.share,
                match (f.range, f.below) {
                    (Some((lo, hi)), Some((_, z))) =>
                        format!(", more than every candidate of {lo}–{hi} (robust z-score {z:.1})"),
                    _ => String::new(),
                },
                f.periods
            ),
        },
        Some(f) => Step {
            name: "torque_ripple order".into(),
            values: vec![
                ("order".into(), f.best as f64, "-"),
                ("z".into(), f.z, "-"),
                ("coherence".into(), f.coherence, "-"),
                ("amplitude".into(), f.amplitude, "N·m"),
                ("phase".into(), f.phase, "rad"),
            ],
            detail: format!(
                "{}: the ripple of order {} removes {:.1} % of the velocity cost {on}, robust \
                 z-score {:.1} against the orders of {} a period or more apart from it \
                 over the travel (significant from {}){}",
                if f.order.is_some() {
                    "found".to_string()
                } else if f.range.is_none() {
                    format!(
                        "no significant order (the travel covers two periods of too few orders \
                         to rank them; the best's ripple removes less than {:.0} % of the cost \
                         or is not alike along the record)",
                        100.0 * super::ripple::MIN_SHORT_SHARE
                    )
                } else if f.z >= super::ripple::SIGNIFICANT_Z {
                    format!(
                        "no significant order (order {}'s ripple is not alike on the parts of \
                         the record, coherence {:.2} below {}: a torque periodic in time, not \
                         in the angle)",
                        f.best,
                        f.coherence,
                        super::ripple::MIN_COHERENCE
                    )
                } else {
                    "no significant order".to_string()
                },
                f.best,
                100.0 * f.share,
                f.z,
                orders_text(f),
                super::ripple::SIGNIFICANT_Z,
                if f.range.is_some_and(|r| r.1 == f.best) {
                    "; it is the highest order the motor's speed lets the search reach, and the \
                     ripple's order may lie above it"
                } else {
                    ""
                }
            ),
        },
        None => Step {
            name: "torque_ripple order".into(),
            values: Vec::new(),
            detail: "no order searched: the motor's travel and speed leave no candidate \
                     (the travel must cover two periods of the ripple)"
                .into(),
        },
    }
}

/// The orders an order search ranked: its candidates, else the orders it searched.
fn orders_text(f: &super::ripple::OrderSearch) -> String {
    match f.range {
        Some((lo, hi)) => format!("{lo}–{hi}"),
        None => format!(
            "{}–{} (the travel covers two periods of too few orders)",
            f.searched.0, f.searched.1
        ),
    }
}

/// The warning when the order found lies below the candidates ([`OrderSearch::short`]).
///
/// [`OrderSearch::short`]: super::ripple::OrderSearch::short
fn short_order_warning(f: &super::ripple::OrderSearch) -> String {
    format!(
        "the torque ripple's order {} is not fixed by these data: the motor's travel covers \
         {:.2} of its periods (two or more tell an order from its neighbours); the ripple \
         stands for a torque against the motor angle over the travel, its order and amplitude \
         trade against each other (move the joint further, or give `order=`)",
        f.order.unwrap_or(f.best),
        f.periods
    )
}

/// The index in the structure's values of the spring a cubic term stiffens: the
/// gearbox's (its index differs between the structures), or the grounded mass's spring.
fn stiffened_spring(model: &NlModel) -> Option<usize> {
    model
        .structure
        .param_names()
        .iter()
        .position(|n| *n == "k_g" || *n == "k_0")
}

/// The deflection level [rad] the sizes of a gap and a stiffening spring are laid on: the
/// arm-side torque the motor torque implies (`u_rms` [N·m]) over the stiffness of the
/// structure's values `plant`; the motion itself for a spring to ground; nought where
/// there is no spring.
fn deflection_level(model: &NlModel, plant: &[f64], data: &IdData, u_rms: f64) -> f64 {
    let kg = stiffened_spring(model)
        .and_then(|i| plant.get(i))
        .copied()
        .unwrap_or(0.0);
    match model.structure {
        // the spring to ground deflects by the motion itself
        Structure::Grounded => rms_about_mean(&data.y),
        Structure::Rigid => 0.0,
        _ if kg <= 0.0 => 0.0,
        _ => u_rms / model.r / kg,
    }
}

/// The automatic start's grid over the size of a gap or a stiffening spring `e`
/// ([`candidates`], each stiffening also with the linear spring split, [`split_spring`]),
/// laid on the structure's values `plant` of `model` and the record `data`: each size with
/// the structure's values it goes with. Empty for another effect. The diagnosis searches it
/// in the controller's loop where the open-loop fit of the effect came out of no size
/// (`diagnose::loop_answer`).
pub(crate) fn size_grid(
    e: &Effect,
    plant: &[f64],
    model: &NlModel,
    data: &IdData,
) -> Vec<(Effect, Vec<f64>)> {
    if !matches!(e, Effect::Backlash(_) | Effect::NonlinearStiffness(_)) {
        return Vec::new();
    }
    let u_rms = torque_rms(data);
    let delta = deflection_level(model, plant, data, u_rms);
    let spring_at = stiffened_spring(model);
    candidates(e, plant, model, delta, u_rms)
        .into_iter()
        .flat_map(|c| {
            std::iter::once((c, plant.to_vec())).chain(
                split_spring(&c, plant, spring_at)
                    .into_iter()
                    .map(move |p| (c, p)),
            )
        })
        .collect()
}

/// RMS of the measured torque of `data` [N·m]: with the gearbox stiffness, the scale of
/// the deflection (`u_rms / r / k_g`) the effects' grids are laid on.
pub(crate) fn torque_rms(data: &IdData) -> f64 {
    (data.u.iter().map(|u| u * u).sum::<f64>() / data.u.len().max(1) as f64).sqrt()
}

/// The linear start of `structure` (gear ratio `r`) from the modal features of the
/// subspace model of `data`, with the rigid body's inertia and the motor's viscous
/// friction of steps 1–2 (`j_total` [kg·m²], `f_m` [N·m·s/rad]); `None` when the data
/// give no features.
fn modal_start(
    data: &IdData,
    structure: Structure,
    r: f64,
    (j_total, f_m): (f64, f64),
) -> Option<Vec<f64>> {
    let (mut feat, _) = grey_box::features(data, Output::Angle, structure.masses(), 0, 0.0).ok()?;
    feat.j_total = j_total;
    feat.f_m = f_m;
    Some(grey_box::initial_values(structure, r, &feat))
}

/// The warning when the data show no ripple order.
fn order_warning(found: Option<&super::ripple::OrderSearch>) -> String {
    match found {
        Some(f) => format!(
            "the data show no torque ripple: no order in {} lowers the cost significantly \
             with the same ripple along the record (best {} at z-score {:.1}, significant \
             from {}, removing {:.1} % of the cost; coherence {:.2}, a ripple of the angle \
             from {}), and none down to order {} (a quarter of its period over the travel) \
             beats them; the ripple is held at amplitude 0 (give `order=` to fit one)",
            orders_text(f),
            f.best,
            f.z,
            super::ripple::SIGNIFICANT_Z,
            100.0 * f.share,
            f.coherence,
            super::ripple::MIN_COHERENCE,
            f.searched.0
        ),
        None => "no torque ripple order can be searched: the motor's travel covers a quarter \
                 period of too few orders up to the speed's limit; the ripple is held at \
                 amplitude 0 (give `order=` to fit one)"
            .into(),
    }
}

/// Samples of the record the two-mass grid ranks its points on: 8 s at 2 kHz, a
/// resolution of 0.12 Hz against the grid's 43 % steps in frequency. (Seed 001: the same
/// start as on the whole 60,000 samples, in a quarter of the time.)
const GRID_SAMPLES: usize = 16_384;

/// The two-mass start with the lowest output-error cost (friction at its step-2 value) on a
/// grid of total inertia around the step-1 value, motor share of it, and first resonance
/// from 3 to 150 Hz (10 % damping): the inverse-dynamics inertia is only as good as the
/// rigid-body assumption below its low-pass cut-off, and closed-loop data carry little
/// low-frequency torque, so the grid does not trust it within a factor 2.
fn two_mass_grid(
    data: &IdData,
    model: &NlModel,
    j: f64,
    fv: f64,
    fc: f64,
    offset: f64,
    asym: Option<Asym>,
) -> Vec<f64> {
    let r2 = model.r * model.r;
    let friction: Vec<Effect> = model
        .effects
        .iter()
        .filter_map(|e| match e {
            Effect::CoulombFriction(c) => Some(Effect::CoulombFriction(friction_at(c, fc, asym))),
            _ => None,
        })
        .collect();
    let m = NlModel {
        effects: friction,
        ..model.clone()
    };
    let mut grid: Vec<Vec<f64>> = Vec::new();
    for js in [0.5, 0.7, 1.0, 1.4, 2.0] {
        let jt = j * js;
        for alpha in [0.25, 0.5, 0.75] {
            let jm = alpha * jt;
            let ja = (1.0 - alpha) * jt / r2;
            for i in 0..12 {
                let f_r = 3.0 * (50.0f64).powf(i as f64 / 11.0);
                let w = 2.0 * std::f64::consts::PI * f_r;
                let mu = 1.0 / (1.0 / ja + r2 / jm);
                let kg = w * w * mu;
                let dg = 2.0 * 0.1 * w * mu;
                grid.push(vec![jm, ja, kg, dg, fv]);
            }
        }
    }
    // the grid's simulations on threads, on the record's first `GRID_SAMPLES`; the lowest
    // cost in grid order wins, as on one
    let n = data.len().min(GRID_SAMPLES);
    let head = IdData {
        ts: data.ts,
        u: data.u[..n].to_vec(),
        y: data.y[..n].to_vec(),
        r: None,
    };
    let costs = parallel(&grid, machine_threads(), |plant| {
        super::output_error::cost_at(&head, &m, &m.values(plant, offset, 0.0))
    });
    let mut best: Option<(f64, Vec<f64>)> = None;
    for (plant, cost) in grid.into_iter().zip(costs) {
        if let Some(cost) = cost {
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                best = Some((cost, plant));
            }
        }
    }
    best.map_or_else(|| vec![0.5 * j, 0.5 * j / r2, 1.0, 1.0, fv], |(_, p)| p)
}

/// Samples of the head of a long record the start's output-error steps run on (the linear
/// starts' refinement, the effects' grids) and the whole model is first fitted on
/// ([`start_head`]) [-]. A start has to land in the basin of the minimum, which the joint's
/// dynamics decide, not the noise a longer record averages away, while every step's cost
/// grows with the samples. 2¹⁴ samples are 8.2 s at 2 kHz, more than three periods of the
/// board's default excitation (5,000 samples a period). Seed 001's reference problem
/// (60,000 samples): the linear start's refinement took 0.43 s on the whole record, 0.07 s
/// on the head; the fit on every sample then needs 2 iterations instead of 5 and ends at
/// the same estimate (`seed001_fitted_from_the_records_head_ends_where_the_fit_from_the_truth_does`).
pub const START_SAMPLES: usize = 1 << 14;

/// The head of `data` the start works on ([`START_SAMPLES`]), when the record holds at
/// least twice as many samples; else `None`: the start works on the whole record. Below
/// twice the head the saving is under half the start's work, and the start would not see
/// most of the record the fit weighs: on the diagnosis bench's records of 22,000 samples
/// the head saved no time and changed the path of cases whose answer depends on it (regular
/// case 2, a stiffening spring answered in the loop, became a pair with a backlash of no
/// width).
pub fn start_head(data: &IdData) -> Option<IdData> {
    (data.len() >= 2 * START_SAMPLES).then(|| data.slice(0..START_SAMPLES))
}

/// Most iterations of a linear start's refinement.
const START_ITER: usize = 30;

/// Iterations every linear start is refined before only the one of lowest cost goes on.
/// A start's cost after a few iterations tells the basins apart: seed 001's two starts
/// stand at 7.06·10³ (the frequency-domain fit's) and 9.31·10³ (the grid's) after five and
/// at 7.05·10³ and 9.28·10³ after thirty. On a record's head ([`start_head`]) the leader
/// stops there too: the whole model's fit on the same samples follows, which refines the
/// structure with the effects in (seed 001: the linear start refined to its end, 13
/// iterations, and the fits after it took 0.14 s and 0.12 s; after six, 0.06 s and 0.11 s,
/// every estimate the same to six digits). Without a head the fit on the whole record
/// starts from the linear start itself, and one stopped after six iterations left a
/// poorly determined parameter behind: the nominal of a two-period three-mass capture
/// (`a_nominal_started_in_the_time_domain_carries_the_current_loop_lag`) ended with the
/// drive's lag at 0.617 ± 0.050 ms against the true 0.5 ms.
const RACE_ITER: usize = 6;

/// The share of its cost below which a step of a start's refinement stops it: one
/// noise variance, `1/N` of the cost `Σ e²` of `N` residuals. Near the minimum a
/// Gauss–Newton step lowers the cost by `Δθᵀ JᵀJ Δθ`, `σ²` times the step's length in
/// standard deviations squared; a step that gains less than `σ²` moves the start by less
/// than one standard deviation, which the final fit from it makes up in one iteration.
/// (Seed 001: the linear starts gain 10⁻⁵–10⁻⁶ of the cost an iteration after their
/// sixth and stop at 30 without it, 1.2 s of the fit's 2.8 s.)
pub(crate) fn start_tolerance(data: &IdData) -> f64 {
    1.0 / data.u.len().max(1) as f64
}

/// Largest `|λ| h` the start gives a spring of the plant, `λ` its two bodies' natural
/// frequency `√(k (g_a²/J_a + g_b²/J_b))` or their damper's decay rate `d (g_a²/J_a +
/// g_b²/J_b)` [1/s], `h` the RK4 step [s]. RK4 is stable below 2.8 on the imaginary axis and
/// 2.78 on the real one; 1.5 leaves the fit room, as [`NlModel::refined_for`] does for the
/// Coulomb slope. At the default 2 kHz and one step, a mode up to 480 Hz.
pub const RESOLVABLE_STEP: f64 = 1.5;

/// Brings each spring of `plant` (values in [`Structure::param_names`] order, gear ratio
/// `r`) whose mode or damper the RK4 step `h` [s] cannot integrate
/// ([`RESOLVABLE_STEP`]) down to what it can: the stiffness to the fastest mode it
/// holds, the damping to the fastest decay. Such a spring is a linear fit's reading of
/// a joint that is rigid in the band (a friction-dominated FRF hides the arm's
/// resonance: `k_a` 3·10⁹ N·m/rad and `d_a` 7.5·10⁵ N·m·s/rad from a sticking motor),
/// and as a start it does not simulate. The words say what was changed; `None` when
/// nothing was.
pub fn resolvable(structure: Structure, r: f64, plant: &mut [f64], h: f64) -> Option<String> {
    let names = structure.param_names();
    if plant.len() != names.len() || h.is_nan() || h <= 0.0 {
        return None;
    }
    let at = |n: &str| names.iter().position(|m| *m == n);
    // (stiffness, damping, [(inertia, coordinate gain)] of its two bodies)
    type Spring = (&'static str, &'static str, [(&'static str, f64); 2]);
    let springs: Vec<Spring> = match structure {
        Structure::Rigid => Vec::new(),
        // the frame does not move: the mass's mobility alone, its damper `Fv`
        Structure::Grounded => vec![("k_0", "Fv", [("J", 1.0), ("J", 0.0)])],
        Structure::TwoMass | Structure::ThreeMass | Structure::FourMass => {
            let mut v = vec![("k_g", "d_g", [("J_m", r), ("J_a1", 1.0)])];
            if structure != Structure::TwoMass {
                v.push(("k_a", "d_a", [("J_a1", 1.0), ("J_a2", 1.0)]));
            }
            if structure == Structure::FourMass {
                v.push(("k_p", "d_p", [("J_a1", 1.0), ("J_p", 1.0)]));
            }
            v
        }
    };
    let mut changed = Vec::new();
    for (k, d, bodies) in springs {
        let (Some(ik), Some(id)) = (at(k), at(d)) else {
            continue;
        };
        let mut mobility = 0.0;
        for (j, g) in bodies {
            let Some(ij) = at(j) else {
                continue;
            };
            if plant[ij] > 0.0 {
                mobility += g * g / plant[ij];
            }
        }
        if !(mobility > 0.0 && mobility.is_finite()) {
            continue;
        }
        let k_max = (RESOLVABLE_STEP / h).powi(2) / mobility;
        let d_max = RESOLVABLE_STEP / h / mobility;
        if plant[ik] > k_max {
            changed.push(format!("`{k}` {:.3e} → {k_max:.3e} N·m/rad", plant[ik]));
            plant[ik] = k_max;
        }
        if plant[id] > d_max {
            changed.push(format!("`{d}` {:.3e} → {d_max:.3e} N·m·s/rad", plant[id]));
            plant[id] = d_max;
        }
    }
    (!changed.is_empty()).then(|| {
        format!(
            "a linear start put a mode or a damper beyond what the simulation's step of {h:.2e} \
             s integrates (the joint is rigid there in the data); started at the fastest it \
             holds: {}",
            changed.join(", ")
        )
    })
}

/// Each direction's friction from step 2's asymmetric regression.
#[derive(Clone, Copy, Debug)]
struct Asym {
    /// `F_c− / F_c` [-]
    neg_ratio: f64,
    /// `F_v− − F_v` [N·m·s/rad]
    fv_extra: f64,
}

/// Whether the model's offset is held at 0: an asymmetric Coulomb level `fc_neg` takes its
/// place (while the motor moves, an offset is half the difference of the two levels; only
/// the stuck phases would tell them apart, and the smooth law hardly sees those).
pub(crate) fn holds_offset(model: &NlModel) -> bool {
    model
        .effects
        .iter()
        .any(|e| matches!(e, Effect::CoulombFriction(c) if c.fc_neg.is_some()))
}

/// Coulomb friction `c` at level `fc` [N·m], its Stribeck bump (if any) scaled alike, and
/// its asymmetric keys (those `c` has) from step 2 when it found them.
fn friction_at(
    c: &crate::model::effects::CoulombFriction,
    fc: f64,
    asym: Option<Asym>,
) -> crate::model::effects::CoulombFriction {
    let fs = if super::model::has_bump(c) && c.fc > 0.0 {
        fc * c.fs / c.fc
    } else {
        fc
    };
    let mut out = crate::model::effects::CoulombFriction { fc, fs, ..*c };
    if let Some(a) = asym {
        out.fc_neg = c.fc_neg.map(|_| fc * a.neg_ratio);
        out.fv_neg_extra = c.fv_neg_extra.map(|_| a.fv_extra);
    }
    out
}

/// An effect at a size that leaves the linear model unchanged (or nearly: a log-parameter
/// cannot be zero) until its search sets it.
fn neutral(e: Effect) -> Effect {
    match e {
        Effect::NonlinearStiffness(mut s) => {
            s.k3 = 0.0;
            Effect::NonlinearStiffness(s)
        }
        Effect::TorqueRipple(mut r) => {
            r.amplitude = 0.0;
            Effect::TorqueRipple(r)
        }
        Effect::TimeDelay(mut t) => {
            t.samples = 0.0;
            Effect::TimeDelay(t)
        }
        Effect::Backlash(mut b) => {
            b.width = 1e-9;
            Effect::Backlash(b)
        }
        e => e,
    }
}

/// Shares of the linear fit's spring that [`split_spring`] leaves to the linear term: from
/// a half to a sixteenth, in steps of two.
const SPRING_SHARES: [f64; 4] = [0.5, 0.25, 0.125, 0.0625];

/// The linear fit's structure `plant` with the spring at `spring_at` at each of
/// [`SPRING_SHARES`] of its value, for a stiffening cubic `cand` (none for another
/// effect).
///
/// Why: a linear fit sees a stiffening spring at its equivalent stiffness, `k + 3 k3 σ²`
/// for a deflection of RMS `σ` (statistical linearisation of a cubic restoring force), so a
/// cubic started on top of the fitted spring counts its stiffness twice. How the two terms
/// share it depends on `σ`, which the quasi-static level `δ` of the grid misses by the
/// modes' amplification (by a factor of two on seed 001's two-mass with its cubic 30 times
/// stronger), so the shares are searched with the cubic's sizes rather than set from `δ`.
/// Regular bench case 32 (a stiffening spring at 0.34 rad RMS): the linear fit put the
/// gearbox at 1.96·10⁶ N·m/rad against the true 1.29·10⁵, the cubic's fit and its
/// refinement in the loop kept it there, and the answer ended 9.1 points below the true
/// model (`diagnose::tests`); the share set from `δ` closed that case but left hard case 12
/// under weak friction (`HARD=1 SMALL=1 FRICTION=1`) 10.4 points short, the shares close
/// both.
fn split_spring(cand: &Effect, plant: &[f64], spring_at: Option<usize>) -> Vec<Vec<f64>> {
    let (Effect::NonlinearStiffness(s), Some(i)) = (cand, spring_at) else {
        return Vec::new();
    };
    if s.k3 <= 0.0 || i >= plant.len() {
        return Vec::new();
    }
    SPRING_SHARES
        .iter()
        .map(|share| {
            let mut p = plant.to_vec();
            p[i] *= share;
            p
        })
        .collect()
}

/// A fitted structure `plant` with an extra mode's inertia `cand` taken from the mass it
/// hangs on (none for another effect, or when that mass is not heavier than it).
///
/// Why: below its resonance a mode on a spring moves with the mass it hangs on, so a fit
/// without the mode counts its inertia in that mass. Added on top, the mode's mass is
/// counted twice and every line below its resonance moves by its share; taken from the
/// mass, the structure keeps its rigid-body inertia and the start differs from the fit only
/// where the mode resonates ([`modes_at_residual_peaks`]).
fn split_mass(cand: &Effect, plant: &[f64], structure: Structure) -> Option<Vec<f64>> {
    let Effect::ExtraMode(x) = cand else {
        return None;
    };
    // the mass it hangs on, as the simulation attaches it; a rigid joint's one mass is the
    // motor, whose inertia the torque sees whole
    if structure == Structure::Rigid {
        return None;
    }
    let at = structure.mode_host(x, structure.masses());
    let m = *plant.get(at)?;
    (m > x.j && x.j > 0.0).then(|| {
        let mut p = plant.to_vec();
        p[at] = m - x.j;
        p
    })
}

/// The span of an extra mode's grid over its frequency with the mass it hangs on held
/// still [Hz].
const MODE_GRID_HZ: (f64, f64) = (3.0, 40.0);

/// How many of a fit's residual peaks start an extra mode ([`modes_at_residual_peaks`]).
const RESIDUAL_PEAKS: usize = 2;

/// Bands per octave of [`residual_peaks`]: a sixth of an octave (12 %), wide enough to hold
/// several lines of a multisine and a lightly damped mode's peak, narrow enough to start the
/// fit inside that mode's basin.
const PEAK_BANDS_PER_OCTAVE: f64 = 6.0;

/// The centres [Hz] of the bands of `span` where the velocity residual of `model` at
/// `values` on `data` stands highest against the measured velocity, at most `count`, the
/// highest first; each a local maximum of that ratio over [`PEAK_BANDS_PER_OCTAVE`] bands.
///
/// Why: a mode the structure lacks leaves its resonance and anti-resonance in the residual,
/// a narrow band where the model misses most of the motion. The bands are read through the
/// cost's high-pass, above which a mode is seen at all.
fn residual_peaks(
    data: &IdData,
    model: &NlModel,
    values: &[f64],
    (lo, hi): (f64, f64),
    count: usize,
) -> Vec<f64> {
    use rustfft::{num_complex::Complex64, FftPlanner};
    let v = super::output_error::interval_velocity(&data.y, data.ts);
    let Some(vh) = super::output_error::simulate_velocity(
        model,
        values,
        &data.u,
        data.ts,
        data.y[0],
        Some(&data.y),
    ) else {
        return Vec::new();
    };
    let n = v.len();
    if n < 16 || data.ts <= 0.0 {
        return Vec::new();
    }
    // through the cost's high-pass, which leaves the slow drift of a free rigid body out
    // of the fit, and a Hann window, so that what remains of it does not leak into the
    // bands above
    let (v, vh) = super::output_error::highpassed_pair(&v, &vh, data.ts, DEFAULT_HIGHPASS_HZ);
    let hann = |k: usize| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / n as f64).cos();
    let fft = FftPlanner::new().plan_fft_forward(n);
    let power = |x: &mut Vec<Complex64>| {
        fft.process(x);
        x.iter().map(|c| c.norm_sqr()).collect::<Vec<f64>>()
    };
    let mut measured: Vec<Complex64> = v
        .iter()
        .enumerate()
        .map(|(k, &x)| Complex64::new(hann(k) * x, 0.0))
        .collect();
    let mut residual: Vec<Complex64> = v
        .iter()
        .zip(&vh)
        .enumerate()
        .map(|(k, (a, b))| Complex64::new(hann(k) * (a - b), 0.0))
        .collect();
    let (pm, pr) = (power(&mut measured), power(&mut residual));
    let df = 1.0 / (n as f64 * data.ts);
    let step = 2f64.powf(1.0 / PEAK_BANDS_PER_OCTAVE);
    // below the high-pass the cost does not see a mode
    let lo = lo.max(DEFAULT_HIGHPASS_HZ);
    // (centre [Hz], residual over measured energy) per band
    let mut bands: Vec<(f64, f64)> = Vec::new();
    let mut f = lo;
    while f * step <= hi {
        let (a, b) = ((f / df).ceil() as usize, ((f * step) / df).floor() as usize);
        let (e, m) = (a..=b.min(n / 2)).fold((0.0, 0.0), |(e, m), k| (e + pr[k], m + pm[k]));
        if m > 0.0 {
            bands.push((f * step.sqrt(), e / m));
        }
        f *= step;
    }
    let mut peaks: Vec<(f64, f64)> = (0..bands.len())
        .filter(|&i| {
            let r = bands[i].1;
            i > 0 && bands[i - 1].1 < r && bands.get(i + 1).is_some_and(|b| b.1 <= r)
        })
        .map(|i| bands[i])
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks.into_iter().take(count).map(|(f, _)| f).collect()
}

/// An extra mode like `mode` at each of `base`'s residual peaks on `data`
/// ([`residual_peaks`] over the span of the mode's grid), the peak [Hz], and the structure
/// it hangs on: `base`'s, the mode's inertia ([`LIGHT_MODE_SHARE`] of the first arm mass,
/// or of the grounded mass) taken from the mass it hangs on ([`split_mass`]), 5 % damping.
///
/// Why: the automatic start's grid over the mode's frequency (a step of 50 %) ranks its
/// points by the cost at the start, and a fit that lacks a mode has moved its other values
/// to make up for it, so even the mode put in at its right frequency can cost more there
/// than the fit without it: it must be fitted from there to show what it gains.
/// Other-joints bench (`JOINTS=1 HARD=1`, case 23): a mode of 6.8 kg·m² at 8.3 Hz beside an
/// arm mass of 1.07 kg·m² at 14.3 Hz; the three-mass nominal took the extra body for its
/// arm and lacked the light one. Every grid point cost more than the nominal at the start,
/// the grid's choice (3 Hz, under the high-pass) grew into a body the cost does not see,
/// and the answer was `none` (the true model +1.86 points). The residual peaked at 15 Hz;
/// fitted from there, the mode reached the true structure (+1.8 points, `j` and `k` within
/// 2.5 %).
pub(super) fn modes_at_residual_peaks(
    data: &IdData,
    base: &NlFit,
    mode: ExtraMode,
) -> Vec<(ExtraMode, f64, Vec<f64>)> {
    let structure = base.model.structure;
    let arm_at = usize::from(structure != Structure::Grounded);
    let Some(&arm) = base.plant.get(arm_at) else {
        return Vec::new();
    };
    let j = LIGHT_MODE_SHARE * arm;
    residual_peaks(
        data,
        &base.model,
        &base.values,
        MODE_GRID_HZ,
        RESIDUAL_PEAKS,
    )
    .into_iter()
    .filter_map(|f_hz| {
        let w = 2.0 * std::f64::consts::PI * f_hz;
        let k = j * w * w;
        let at = ExtraMode {
            j,
            k,
            d: 2.0 * 0.05 * (k * j).sqrt(),
            ..mode
        };
        let plant = split_mass(&Effect::ExtraMode(at), &base.plant, structure)?;
        Some((at, f_hz, plant))
    })
    .collect()
}

/// The inertia of a light extra mode's start as a share of the first arm mass (of the
/// grounded mass) [-]: a twenty-fifth, a body that resonates where a heavy one would shift
/// every line below it ([`split_mass`]).
const LIGHT_MODE_SHARE: f64 = 0.04;

/// The grid of one effect's sizes to search, scaled by the linear fit and the deflection
/// level `delta` [rad] and the torque level `u_rms` [N·m].
fn candidates(e: &Effect, plant: &[f64], model: &NlModel, delta: f64, u_rms: f64) -> Vec<Effect> {
    match *e {
        Effect::NonlinearStiffness(_) if delta > 0.0 => {
            // the cubic term's size where it equals the linear spring at the deflection level;
            // near nought a thousandth of it, not 0: the fit scales `k3` by its start, and a
            // start of 0 gave a unit scale, a step of 1 N·m/rad³ against 10¹³ (a grounded
            // mass's σ of `k3` came out 10⁻¹³ and its covariance degenerate)
            // (the spring's coordinate gain at the motor: `r`, 1 for the gearless grounded
            // mass)
            let gain = if model.structure == Structure::Grounded {
                1.0
            } else {
                model.r
            };
            let unit = u_rms / gain / (delta * delta * delta);
            [-0.1, -0.03, 0.001, 0.03, 0.1, 0.3, 1.0, 3.0]
                .iter()
                .map(|f| {
                    Effect::NonlinearStiffness(crate::model::effects::NonlinearStiffness {
                        k3: f * unit,
                    })
                })
                .collect()
        }
        Effect::Backlash(_) if delta > 0.0 => [0.01, 0.03, 0.1, 0.3, 1.0]
            .iter()
            .map(|f| Effect::Backlash(crate::model::effects::Backlash { width: f * delta }))
            .collect(),
        Effect::TimeDelay(_) => [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0]
            .iter()
            .map(|&s| Effect::TimeDelay(crate::model::effects::TimeDelay { samples: s }))
            .collect(),
        Effect::TorqueRipple(r) => {
            let mut v = Vec::new();
            for a in [0.003, 0.01, 0.03, 0.1] {
                let a = a * u_rms;
                for k in 0..4 {
                    v.push(Effect::TorqueRipple(crate::model::effects::TorqueRipple {
                        amplitude: a,
                        phase: k as f64 * std::f64::consts::FRAC_PI_2,
                        ..r
                    }));
                }
            }
            v
        }
        Effect::ExtraMode(x) if model.structure != Structure::Rigid => {
            // the extra mass a quarter of the first arm mass (of the grounded mass), its
            // frequency spread around the first resonance with the arm held
            // still, 5 % damping
            let j = if model.structure == Structure::Grounded {
                0.25 * plant[0]
            } else {
                0.25 * plant[1]
            };
            let mut v = Vec::new();
            let (lo, hi) = MODE_GRID_HZ;
            for f_hz in [lo, 5.0, 8.0, 12.0, 18.0, 27.0, hi] {
                let w = 2.0 * std::f64::consts::PI * f_hz;
                let k = j * w * w;
                v.push(Effect::ExtraMode(ExtraMode {
                    j,
                    k,
                    d: 2.0 * 0.05 * (k * j).sqrt(),
                    attach: if x.attach == Attach::Serial {
                        Attach::Serial
                    } else {
                        Attach::Parallel
                    },
                }));
            }
            v
        }
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{Backlash, CoulombFriction, NonlinearStiffness};

    /// The loop's search over a gap's or a stiffening spring's size (`size_grid`) is laid on
    /// the deflection the torque implies through the structure's own gearbox, and a
    /// stiffening spring also takes its stiffness from the linear spring it would otherwise
    /// count twice; another law has no such grid.
    #[test]
    fn a_size_grid_is_laid_on_the_deflection_of_the_structure_given() {
        let cfg = crate::sim::SimConfig::default();
        let gap = Effect::Backlash(Backlash { width: 1e-5 });
        let (model, values) = crate::test_support::three_mass_truth(&cfg, gap, 1);
        let plant = values[..8].to_vec();
        let u: Vec<f64> = (0..2000).map(|k| 0.3 * (k as f64 * 0.01).sin()).collect();
        let data = IdData {
            ts: 5e-4,
            y: vec![0.0; u.len()],
            u,
            r: None,
        };
        let delta = torque_rms(&data) / model.r / plant[3];
        let grid = size_grid(&gap, &plant, &model, &data);
        let widths: Vec<f64> = grid
            .iter()
            .map(|(e, _)| match e {
                Effect::Backlash(b) => b.width / delta,
                e => panic!("{e:?} in a gap's grid"),
            })
            .collect();
        assert_eq!(widths.len(), 5, "{widths:?}");
        assert!((widths[0] - 0.01).abs() < 1e-12 && (widths[4] - 1.0).abs() < 1e-12);
        // a stiffer gearbox deflects less: the widths follow it
        let mut stiff = plant.clone();
        stiff[3] *= 4.0;
        let first = |g: &[(Effect, Vec<f64>)]| match g[0].0 {
            Effect::Backlash(b) => b.width,
            _ => f64::NAN,
        };
        let ratio = first(&grid) / first(&size_grid(&gap, &stiff, &model, &data));
        assert!((ratio - 4.0).abs() < 1e-9, "{ratio}");
        // a stiffening spring: each size on the structure as given and with k_g split
        let cubic = Effect::NonlinearStiffness(NonlinearStiffness { k3: 1e13 });
        let grid = size_grid(&cubic, &plant, &model, &data);
        let kept = grid.iter().filter(|(_, p)| p[3] == plant[3]).count();
        assert!(
            kept > 0 && grid.len() > kept,
            "{} sizes, {kept} unsplit",
            grid.len()
        );
        assert!(grid
            .iter()
            .all(|(_, p)| p[3] <= plant[3] && p[4] == plant[4]));
        // friction has no such grid
        let friction = Effect::CoulombFriction(CoulombFriction::default());
        assert!(size_grid(&friction, &plant, &model, &data).is_empty());
    }
}
