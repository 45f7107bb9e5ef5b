//! The whole nonlinear identification as a user runs it: the automatic start (or a given
//! one), the output-error fit, the checks that turn a doubtful result into warnings, and
//! the validation with the simulator's exact laws ([`crate::sim::simulate_driven`]).

use super::fit::{fit_output_error, interval_velocity, simulate_velocity, velocity_fit};
use super::init::{automatic_start, Step};
use super::model::{NlModel, Owner};
use super::{NlError, NlFit, NlOptions};
use crate::data::IdData;
use crate::ident::lm::Termination;
use crate::ident::validate::fit_percent;
use crate::model::effects::Effect;
use crate::model::params::{model_params, JointParams, Plant};
use crate::model::spec::Structure;
use crate::sim::{simulate_driven, DrivenStart};

/// What to identify and how.
#[derive(Clone, Debug, PartialEq)]
pub struct NlRequest {
    /// mechanical structure
    pub structure: Structure,
    /// gear ratio `r` [-]
    pub r: f64,
    /// effects to attach (their parameter values are ignored unless `start` is given;
    /// the ripple's order and an extra mode's attachment are taken as they are)
    pub effects: Vec<Effect>,
    /// current-loop lag `tau_c` [s] to start from (estimated unless fixed); 0: none
    pub tau_c: f64,
    /// the whole start in layout order ([`NlModel::layout`]); `None`: the automatic start
    pub start: Option<Vec<f64>>,
    /// the structure's values from a linear fit the caller trusts (step 3 of the start)
    pub linear: Option<Vec<f64>>,
    /// options of the fit (fixed parameters by name among them)
    pub options: NlOptions,
}

/// Result of [`identify`].
#[derive(Clone, Debug, PartialEq)]
pub struct NlResult {
    /// the steps of the automatic start (empty with a given start)
    pub steps: Vec<Step>,
    /// the fit
    pub fit: NlFit,
    /// what makes the fit doubtful, in words (empty when nothing does)
    pub warnings: Vec<String>,
}

/// Validation of a fitted model on data that played no part in the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
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

/// The model the estimator integrates for `req` (smoothing of the non-smooth laws, RK4
/// steps per sample).
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
        tau_c: req.tau_c,
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

/// Identifies `req` on `data`: the automatic start (seed 001's three steps) unless a start
/// is given, then the output-error fit, then its checks. The rigid structure is fitted
/// without the high-pass prefilter (its information lies below it).
///
/// # Errors
/// [`NlError`] when the data or the start cannot be used.
pub fn identify(data: &IdData, req: &NlRequest) -> Result<NlResult, NlError> {
    let model = model_of(req, data);
    let (steps, start_model, start) = match &req.start {
        Some(s) => (Vec::new(), model.clone(), s.clone()),
        None => {
            let st = automatic_start(data, &model, req.linear.as_deref())?;
            (st.steps, st.model, st.values)
        }
    };
    let options = req.options.clone().for_structure(req.structure);
    let start_model = start_model.refined_for(&start, velocity_rms(data), data.ts);
    let fit = fit_output_error(data, &start_model, &start, &options)?;
    let warnings = checks(&fit);
    Ok(NlResult {
        steps,
        fit,
        warnings,
    })
}

/// The linear start of step 3 from periodic data: the frequency-domain fit of `structure`
/// to the FRF at the excited lines ([`crate::ident::frf_fit`]), which transients, drift
/// and the nonlinear distortion at the non-excited lines leave alone. Returns the
/// structure's values and the current-loop lag `tau_c` [s] it estimated (0 when none).
///
/// # Errors
/// In words, when the data are not periodic or the fit fails.
pub fn linear_start(
    ds: &crate::data::Dataset,
    structure: Structure,
    r: f64,
) -> Result<(Vec<f64>, f64), String> {
    use crate::ident::frf_fit::{fit_frf, FrfFitOptions};
    let analysis = crate::ident::frf::analyze_dataset(ds, 1).map_err(|e| e.to_string())?;
    let ts = ds.data.ts;
    let opts = FrfFitOptions {
        r,
        ..FrfFitOptions::new(structure, ts)
    };
    let fit = fit_frf(&analysis.frf, &opts).map_err(|e| e.to_string())?;
    let values = structure
        .param_names()
        .iter()
        .map(|n| {
            fit.params
                .iter()
                .find(|p| p.name == *n)
                .map(|p| p.value)
                .ok_or_else(|| format!("the frequency-domain fit has no `{n}`"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    let tau_c = if fit.lag.value > 0.0 {
        fit.lag.value * ts
    } else {
        0.0
    };
    Ok((values, tau_c))
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
            w.push(format!(
                "`{}` = {:.4e} ± {:.1e} {} is poorly determined by these data",
                p.name, p.value, p.std, p.unit
            ));
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
    let relative_std = |name: &str| {
        fit.params
            .iter()
            .find(|p| p.name == name)
            .map_or(0.0, |p| p.std / p.value.abs())
    };
    for c in fit.correlated.iter().filter(|c| c.rho.abs() >= 0.98) {
        let (sa, sb) = (relative_std(c.a), relative_std(c.b));
        if sa.max(sb) > 0.05 {
            w.push(format!(
                "`{}` and `{}` trade against each other (correlation {:+.3}): the data fix a \
                 combination of them, each alone only to ±{:.0} % and ±{:.0} %; fix one \
                 (`--fix`) if it is known",
                c.a,
                c.b,
                c.rho,
                100.0 * sa,
                100.0 * sb
            ));
        }
    }
    w
}

/// The simulator's plant for the structure's values `plant` (in
/// [`Structure::param_names`] order) of `model`.
pub fn sim_plant(model: &NlModel, plant: &[f64]) -> Plant {
    let names = model.structure.param_names();
    let mut p = JointParams {
        r: model.r,
        j_a1: 0.0,
        j_a2: 0.0,
        ..JointParams::default()
    };
    let kind = model.structure;
    if model.structure == Structure::Rigid {
        p.j_m = plant[0];
        p.f_m = plant[1];
    } else {
        for (name, field) in model_params(kind) {
            if let Some(i) = names.iter().position(|n| *n == name) {
                *field(&mut p) = plant[i];
            }
        }
    }
    Plant { kind, params: p }
}

/// Validates `fit` on `val` (module documentation): the model simulated from the measured
/// torque (plus the fitted offset) with the simulator's exact laws, from rest at the
/// first measured angle with the fitted initial velocity.
///
/// # Errors
/// [`NlError::Data`] for a short record, [`NlError::Unstable`] when the simulation is not
/// finite.
pub fn validate(fit: &NlFit, val: &IdData, opts: &NlOptions) -> Result<NlValidation, NlError> {
    val.check(20).map_err(|e| NlError::Data(e.to_string()))?;
    let model = &fit.model;
    let offset = fit.get("offset").unwrap_or(0.0);
    let u: Vec<f64> = val.u.iter().map(|u| u + offset).collect();
    let plant = sim_plant(model, &fit.plant);
    // no current loop in the model: a lag far below the sample interval
    let tc = if model.tau_c > 0.0 { model.tau_c } else { 1e-9 };
    let out = simulate_driven(
        &plant,
        &model.effects,
        tc,
        val.ts,
        &u,
        &DrivenStart::Rest { theta_m: val.y[0] },
    )
    .map_err(|e| NlError::Data(format!("validation simulation: {e}")))?;
    let v = interval_velocity(&val.y, val.ts);
    let vh = interval_velocity(&out.theta_m, val.ts);
    // the estimation record's initial velocity means nothing here: from rest, as above
    let mut values = fit.values.clone();
    if let Some(v0) = values.last_mut() {
        *v0 = 0.0;
    }
    let smooth = simulate_velocity(model, &values, &val.u, val.ts, val.y[0], None)
        .ok_or(NlError::Unstable)?;
    Ok(NlValidation {
        velocity_fit_percent: velocity_fit(&v[1..], &vh[1..], val.ts, opts.highpass_hz)
            .unwrap_or(f64::NAN),
        velocity_fit_smooth_percent: velocity_fit(&v[1..], &smooth[1..], val.ts, opts.highpass_hz)
            .unwrap_or(f64::NAN),
        angle_fit_percent: fit_percent(&val.y, &out.theta_m).unwrap_or(f64::NAN),
    })
}
