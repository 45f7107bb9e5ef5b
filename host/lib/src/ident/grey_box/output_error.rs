//! The time-domain output-error fit of a structure ([`fit`]): initial values from
//! [`super::init`], then prediction-error refinement, best of the starts.

use super::*;

/// Options of [`fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct GreyBoxOptions {
    /// mechanical structure
    pub structure: Structure,
    /// output signal of the data
    pub output: Output,
    /// gear ratio `r` (fixed)
    pub r: f64,
    /// order of the subspace model the frequencies are read from; 0 picks
    /// `2·masses + 2`
    pub subspace_order: usize,
    /// lowest frequency considered a resonance [Hz]; 0 picks `20/(N Ts)`
    pub f_min_hz: f64,
    /// options of the prediction-error step
    pub pem: PemOptions,
}

impl Default for GreyBoxOptions {
    fn default() -> Self {
        Self {
            structure: Structure::ThreeMass,
            output: Output::Angle,
            r: DEFAULT_GEAR_RATIO,
            subspace_order: 0,
            f_min_hz: 0.0,
            pem: PemOptions::with_max_iter(60),
        }
    }
}

/// Result of [`fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct GreyBoxFit {
    /// model family
    pub model: GreyBoxModel,
    /// estimated parameters with std (delta method) and units
    pub params: Vec<PhysParam>,
    /// the initial values derived from the data
    pub initial: Vec<PhysParam>,
    /// features the initial values came from
    pub features: Features,
    /// discrete model at the estimate
    pub discrete: StateSpace,
    /// continuous model at the estimate
    pub continuous: ContinuousSs,
    /// the prediction-error result (log-parameters)
    pub pem: PemFit,
    /// simulation FIT on the estimation data (toolbox definition) [%]
    pub fit_percent: f64,
    /// notes on fallbacks used
    pub warnings: Vec<String>,
}

/// Fit a grey-box model with initial values derived from the data (module
/// docs), then refine by output error in log-parameters.
///
/// # Errors
/// [`GreyBoxError`] when the data are unusable or a step fails.
pub fn fit(data: &IdData, opts: &GreyBoxOptions) -> Result<GreyBoxFit, GreyBoxError> {
    let masses = opts.structure.masses();
    let (feat, mut warnings) = features(
        data,
        opts.output,
        masses.max(2),
        opts.subspace_order,
        opts.f_min_hz,
    )?;
    let p0 = initial_values(opts.structure, opts.r, &feat);
    let model = GreyBoxModel {
        structure: opts.structure,
        output: opts.output,
        r: opts.r,
        ts: data.ts,
    };
    let th0: Vec<f64> = p0.iter().map(|v| v.ln()).collect();
    let mut popts = opts.pem.clone();
    if popts.lm.lower.is_empty() {
        popts.lm.lower = th0.iter().map(|t| t - (1e4f64).ln()).collect();
    }
    if popts.lm.upper.is_empty() {
        popts.lm.upper = th0.iter().map(|t| t + (1e4f64).ln()).collect();
    }
    // Two automatic staged starts, the lower final cost wins:
    // (a) dampings and friction first (the frequencies from the data are
    //     close), then everything;
    // (b) damping continuation: springs, masses and friction first with the
    //     dampings raised to ζ ≈ 0.15 (broad peaks smooth the output-error
    //     cost, whose minima in a resonance frequency are otherwise only a
    //     half-power bandwidth wide), then everything.
    let names = opts.structure.param_names();
    let is_damping = |n: &str| n.starts_with('d');
    let is_loss = |n: &str| is_damping(n) || n.starts_with('f') || n == "Fv";
    let mut best: Option<PemFit> = None;
    let has_dampings = names.iter().any(|n| is_damping(n));
    let strategies: &[u8] = if has_dampings { &[0, 1] } else { &[0] };
    for &strategy in strategies {
        let (start, fixed): (Vec<f64>, Vec<bool>) = match strategy {
            0 => (th0.clone(), names.iter().map(|n| !is_loss(n)).collect()),
            _ => {
                let boost = (0.15 / feat.zeta1.clamp(1e-3, 0.5)).max(1.0).ln();
                let st = th0
                    .iter()
                    .zip(names)
                    .map(|(t, n)| if is_damping(n) { t + boost } else { *t })
                    .collect();
                (st, names.iter().map(|n| is_damping(n)).collect())
            }
        };
        let mut start = start;
        clamp_vec(&mut start, &popts.lm.lower, &popts.lm.upper);
        let s1 = pem::fit(
            &model,
            &start,
            data,
            &PemOptions {
                lm: LmOptions {
                    fixed,
                    max_iter: 15,
                    ..popts.lm.clone()
                },
                ..popts.clone()
            },
        )?;
        let pf = pem::fit(&model, &s1.theta, data, &popts)?;
        let better = best
            .as_ref()
            .is_none_or(|b| pf.cost_history.last() < b.cost_history.last());
        if better {
            best = Some(pf);
        }
    }
    let pf = best.expect("at least one strategy ran");
    if pf.termination == pem::Termination::MaxIterations {
        warnings.push("prediction-error search stopped at the iteration limit".into());
    }
    let params = phys_params(names, &pf.theta, &pf.std);
    let initial = names
        .iter()
        .zip(&p0)
        .map(|(n, &v)| PhysParam {
            name: n.to_string(),
            value: v,
            std: 0.0,
            unit: unit_of(n),
        })
        .collect();
    let pvals: Vec<f64> = pf.theta.iter().map(|t| t.exp()).collect();
    let continuous = model.continuous(&pvals);
    let yh = pf.model.simulate(&data.u, Some(&pf.x0));
    let fitp = crate::ident::validate::fit_percent(&data.y, &yh)?;
    Ok(GreyBoxFit {
        model,
        params,
        initial,
        features: feat,
        discrete: pf.model.clone(),
        continuous,
        pem: pf,
        fit_percent: fitp,
        warnings,
    })
}
