//! The frequency-domain path of [`super`]: the model of a [`FitOptions`] fitted to the FRF
//! of periodic data at its excited lines, as a [`Fitted`]. A physical model goes to
//! [`sml`] (sample maximum likelihood, exact ZOH with the current-loop lag and a
//! fractional delay); the black box to [`black_box_frf`] (frequency-domain subspace,
//! McKelvey et al. 1996, refined by the same cost), for an angle with the rigid-body
//! integrator exact when that reaches the noise level ([`black_box_frf_integrating`]). [`below_frf`] checks a time-domain fit
//! against the frequency-domain fit of the same family.

use crate::ident::frf::FrfAnalysis;
use crate::ident::frf_subspace::{black_box_frf, black_box_frf_integrating, FrfBlackBox};
use crate::ident::grey_box::Output;
use crate::ident::grey_box::PhysParam;
use crate::ident::sml::COST_RATIO_WARN;
use crate::ident::sml::{self, Drive, DriveEstimate, FitWarning, FrfFit, FrfFitOptions};
use crate::model::spec::{Family, Structure};

use super::{FitError, FitMetric, FitOptions, Fitted};

/// How the method of a fit made here begins ([`Fitted::method`]), which
/// [`Fitted::in_frequency_domain`] reads.
pub(super) const FREQUENCY_DOMAIN: &str = "frequency domain";

/// Iterations of the black box's refinement by sample maximum likelihood.
const BLACK_BOX_ITERATIONS: usize = 40;

/// The options of [`sml::fit_frf`] for `structure` at sample interval `ts` [s]: the
/// output and gear ratio of `opts`; with `held`, the lag [s] and delay [samples] the spec
/// holds (the others estimated).
fn frf_options(structure: Structure, opts: &FitOptions, ts: f64, held: bool) -> FrfFitOptions {
    let mut o = FrfFitOptions::new(structure, ts);
    o.output = opts.output;
    o.r = opts.r;
    if held {
        if let Some(tau) = opts.spec.current_loop_tau {
            o.lag = Drive::Fixed(tau / ts);
        }
        if let Some(d) = opts.spec.delay {
            o.delay = Drive::Fixed(d);
        }
    }
    o
}

/// Fits the model of `opts` to the FRF of `analysis`, sampled every `ts` [s]; `decimate`
/// is the decimation between the model and the prepared data it is compared with
/// ([`Fitted::decimate`]). A physical model carries its lag as `tau_c` [s] and its delay
/// as `delay` [s] among the parameters; the black box is refined unless `opts.refine` is
/// off.
///
/// # Errors
/// [`FitError::Frf`] or [`FitError::FrfBlackBox`] when the fit cannot be made.
pub fn fit_frequency_domain(
    analysis: &FrfAnalysis,
    ts: f64,
    opts: &FitOptions,
    decimate: usize,
) -> Result<Fitted, FitError> {
    match opts.spec.family {
        Family::Physical(structure) => {
            let ff = sml::fit_frf(&analysis.frf, &frf_options(structure, opts, ts, true))?;
            Ok(fitted_of(opts, &ff, analysis, decimate))
        }
        Family::BlackBox(n) => {
            let iters = if opts.refine { BLACK_BOX_ITERATIONS } else { 0 };
            let free = black_box_frf(&analysis.frf, n, ts, opts.feedthrough, iters)?;
            let (bb, structure) = match angle_integrating(analysis, n, ts, opts, iters) {
                Some(bi) if bi.cost_ratio() <= COST_RATIO_WARN => (
                    bi,
                    format!(
                        "{} free states on the differenced output and the rigid-body \
                         integrator exact (at the noise level with two parameters fewer than \
                         the free model, whose cost is {:.1})",
                        n - 1,
                        free.cost
                    ),
                ),
                _ => (free, format!("order {n}")),
            };
            Ok(Fitted {
                spec: opts.spec.clone(),
                output: opts.output,
                ts,
                method: format!(
                    "{FREQUENCY_DOMAIN}: subspace on {} excited lines of {} periods (McKelvey et al. 1996, \
                     bilinear map), {structure}, refined by sample maximum likelihood ({} \
                     iterations); cost {:.1} = {:.2} × its noise level",
                    analysis.frf.g.len(),
                    analysis.layout.count,
                    bb.iterations,
                    bb.cost,
                    bb.cost_ratio()
                ),
                model: bb.model,
                continuous: None,
                params: Vec::new(),
                friction: None,
                warnings: bb.warnings.iter().map(|w| w.to_string()).collect(),
                decimate,
                fit_metric: FitMetric::Output,
            })
        }
    }
}

/// The black box of order `n` of an angle output (no feed-through) with the rigid-body
/// integrator exact ([`black_box_frf_integrating`]); `None` for other outputs or when it
/// cannot be fitted. Where it reaches the noise level it is the model: it explains the
/// lines as the free model does with two parameters fewer, and the free model spends them
/// below the lowest reliable line (measured, `cargo bench -p jointid --bench ident`, the
/// default three-mass joint at 15,000 samples: free model cost 178 (0.91 × the noise level)
/// with a mode at 0.80 Hz no line holds, validation FIT 96.14 %; with the integrator cost
/// 227 (1.15 ×), 98.50 %, the true model 98.54 %).
fn angle_integrating(
    analysis: &FrfAnalysis,
    n: usize,
    ts: f64,
    opts: &FitOptions,
    iters: usize,
) -> Option<FrfBlackBox> {
    (opts.output == Output::Angle && !opts.feedthrough && n >= 2)
        .then(|| black_box_frf_integrating(&analysis.frf, n, ts, iters).ok())
        .flatten()
}

/// A frequency-domain fit as a [`Fitted`]: the sampled model with the lag
/// and the delay, the lag as `tau_c` [s] and the delay as `delay` [s] among
/// the parameters.
fn fitted_of(opts: &FitOptions, ff: &FrfFit, analysis: &FrfAnalysis, decimate: usize) -> Fitted {
    let ts = ff.model.ts;
    let mut params = ff.params.clone();
    for (name, d) in [("tau_c", ff.lag), ("delay", ff.delay)] {
        params.push(PhysParam {
            name: name.into(),
            value: d.value * ts,
            std: d.std * ts,
            unit: "s",
        });
    }
    let drive = |d: &DriveEstimate| match (d.estimated, d.value > 0.0) {
        (true, _) => "estimated",
        (false, true) => "fixed",
        (false, false) => "left out",
    };
    Fitted {
        spec: opts.spec.clone(),
        output: opts.output,
        ts,
        model: ff.discrete(),
        continuous: Some(ff.continuous()),
        params,
        friction: None,
        warnings: ff.warnings.iter().map(|w| w.to_string()).collect(),
        method: format!(
            "{FREQUENCY_DOMAIN}: sample maximum likelihood on {} excited lines of {} periods \
             ({:.1} to {:.1} Hz), current-loop lag {}, delay {}; cost {:.1} = {:.2} × its noise level; \
             best of {} starts from the FRF's resonances",
            ff.lines,
            analysis.layout.count,
            analysis.frf.freq_hz.first().map_or(0.0, |f| *f),
            analysis.frf.freq_hz.last().map_or(0.0, |f| *f),
            drive(&ff.lag),
            drive(&ff.delay),
            ff.cost,
            ff.cost_ratio(),
            ff.starts
        ),
        decimate,
        fit_metric: FitMetric::Output,
    }
}

/// A time-domain fit on periodic data checked against the frequency-domain
/// fit of the same model family (lag and delay estimated, the black box refined) on
/// `analysis`, sampled every `ts` [s]: when its periodic steady-state FIT on the
/// estimation record is more than 10 points below, the time-domain fit has followed
/// something else than the joint (drift, a slow disturbance). `None` when the fitted model
/// runs at another rate or the reference fit fails.
pub fn below_frf(
    analysis: &FrfAnalysis,
    ts: f64,
    opts: &FitOptions,
    fitted: &Fitted,
) -> Option<FitWarning> {
    if (fitted.ts - ts).abs() > 1e-9 * ts {
        return None;
    }
    let a = analysis;
    let reference = match opts.spec.family {
        Family::Physical(structure) => {
            let ff = sml::fit_frf(&a.frf, &frf_options(structure, opts, ts, false)).ok()?;
            ff.freq_response(&a.frf.freq_hz)
        }
        Family::BlackBox(n) => black_box_frf(&a.frf, n, ts, opts.feedthrough, BLACK_BOX_ITERATIONS)
            .ok()?
            .model
            .freq_response(&a.frf.freq_hz),
    };
    let sml = sml::periodic_fit_percent(&a.frf, &reference);
    let fit = sml::periodic_fit_percent(&a.frf, &fitted.model.freq_response(&a.frf.freq_hz));
    (fit < sml - 10.0).then_some(FitWarning::FitBelowFrf { fit, sml })
}
