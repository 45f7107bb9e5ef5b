//! `jointid fit DATA --model STRUCTURE --effect SPEC...` (or `--model nonlinear-two-mass`):
//! a physical model with the simulator's effects attached, fitted by the nonlinear
//! grey-box engine in one call of [`jointid::ident::nonlinear::run`] (the
//! frequency-domain linear start on periodic data, seed 001's automatic start or
//! `--start MODEL.json`, `--fix` and the keys given in `--effect`, output error, the
//! validation with the simulator's exact laws). Here: the flags, reading the `--start`
//! file, the request, the report.
//!
//! Every `fit --json` field that has a meaning here keeps its name (`model`, `parameters`
//! with the structure, `tau_c` and `offset`, `fit_name`, `fit_estimation`,
//! `fit_validation`, `warnings`, ...); `effects`, `steps`, `validation` and
//! `simulate_command` are added.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use super::fit::{save_model, DomainArg, FitArgs, OutputArg, SegmentJson};
use super::{print_json, write_svg, CmdResult, Context, Outcome};
use jointid::data::output::check_output;
use jointid::data::{Dataset, Detrend, IdData};
use jointid::ident::fit::ParamJson;
use jointid::ident::model_file::SavedModel;
use jointid::ident::nonlinear::{
    interval_velocity, run as run_nl, simulate_args, simulate_exact, NlData, NlFit, NlOptions,
    NlRequest, NlRunError, NlStart, NlValidation, Owner,
};
use jointid::model::spec::{Family, ModelSpec, Structure};
use jointid::report::plot::{time_svg, TimeSeries};

/// The plot `--plot DIR` writes for a nonlinear fit.
pub const PLOT_FILE: &str = "velocity.svg";

/// Name of the FIT the nonlinear fit reports first (`fit_name`).
pub const NL_FIT_NAME: &str =
    "velocity FIT [%] (interval-mean motor velocity through the high-pass prefilter, simulator's exact laws)";

/// `--fix` and `--start` belong to the nonlinear fit; refused without an effect.
///
/// # Errors
/// The flag, in words.
pub fn refuse_nonlinear_flags(args: &FitArgs) -> Result<(), String> {
    if !args.fix.is_empty() || args.start.is_some() {
        return Err(
            "--fix and --start belong to the nonlinear fit: attach an effect with --effect \
             NAME[:key=value,...] or use --model nonlinear-two-mass"
                .into(),
        );
    }
    Ok(())
}

/// One parameter of a step of the start.
#[derive(Debug, Serialize)]
struct StepValue {
    value: f64,
    unit: String,
}

/// One step of the start in JSON.
#[derive(Debug, Serialize)]
struct StepJson {
    name: String,
    values: BTreeMap<String, StepValue>,
    detail: String,
}

/// One fitted effect in JSON.
#[derive(Debug, Serialize)]
struct EffectJson {
    name: String,
    /// the spec `simulate --effect` reads
    spec: String,
    parameters: BTreeMap<String, ParamJson>,
}

/// The FITs of the fitted model on one record ([`NlValidation`]).
#[derive(Clone, Copy, Debug, Serialize)]
pub(crate) struct FitsJson {
    /// velocity FIT, simulator's exact laws [%]
    pub velocity_fit_percent: f64,
    /// velocity FIT, estimator's smooth laws [%]
    pub velocity_fit_smooth_percent: f64,
    /// toolbox FIT of the motor angle, exact laws, unfiltered [%]
    pub angle_fit_percent: f64,
}

impl From<NlValidation> for FitsJson {
    fn from(v: NlValidation) -> Self {
        FitsJson {
            velocity_fit_percent: v.velocity_fit_percent,
            velocity_fit_smooth_percent: v.velocity_fit_smooth_percent,
            angle_fit_percent: v.angle_fit_percent,
        }
    }
}

/// Everything `fit --json` prints for a nonlinear fit.
#[derive(Debug, Serialize)]
struct NlReport {
    model: String,
    method: String,
    file: String,
    validation_file: Option<String>,
    ts: f64,
    samples: usize,
    /// the gap-free segments fitted (as separate experiments), each with the velocity FIT
    /// on it alone
    segments: Vec<SegmentJson>,
    /// the structure's parameters, `tau_c` (when there is a lag) and `offset`
    parameters: BTreeMap<String, ParamJson>,
    effects: Vec<EffectJson>,
    /// the start: its steps (empty with --start)
    start: String,
    steps: Vec<StepJson>,
    /// parameters held at their value (--fix, --current-loop-tau)
    fixed: Vec<String>,
    iterations: usize,
    termination: String,
    fit_name: String,
    /// exact-law velocity FIT on the estimation record [%]
    fit_estimation: f64,
    /// exact-law velocity FIT on the validation record [%]
    fit_validation: Option<f64>,
    /// the fit's own measure: velocity FIT with the estimator's smooth laws [%]
    fit_estimation_smooth: f64,
    /// the validation FITs
    validation: Option<FitsJson>,
    /// cut-off of the high-pass prefilter [Hz]
    highpass_hz: f64,
    /// the `jointid simulate` command line that rebuilds the plant and its effects
    simulate_command: String,
    /// the model file written (--save), which `simulate --model-file` reads
    saved_model: Option<String>,
    /// wall time of the fit [s]
    #[serde(rename = "elapsed_s")]
    seconds: f64,
    files: Vec<String>,
    warnings: Vec<String>,
}

/// The flags of `fit` that have no meaning for the nonlinear fit.
fn check_flags(args: &FitArgs, spec: &ModelSpec) -> Result<Structure, String> {
    let structure =
        match spec.family {
            Family::BlackBox(_) => return Err(
                "--effect attaches to a physical model: --model rigid, two-mass, three-mass or \
                 four-mass"
                    .into(),
            ),
            Family::Physical(s) => s,
        };
    let refuse = |cond: bool, msg: &str| if cond { Err(msg.to_string()) } else { Ok(()) };
    refuse(
        spec.coulomb,
        "--friction coulomb is the linear engine's rigid model; with effects use --effect \
         coulomb_friction",
    )?;
    refuse(
        args.domain == DomainArg::Frequency,
        "a model with effects is fitted in the time domain (--domain frequency is linear only)",
    )?;
    refuse(
        args.output_kind != OutputArg::Angle,
        "the nonlinear fit needs the motor angle as output (--output-kind angle)",
    )?;
    refuse(
        args.prep.decimate > 1 || args.prep.detrend != Detrend::None,
        "the nonlinear fit runs on the raw record at the capture rate: --decimate and \
         --detrend are not available with effects",
    )?;
    refuse(
        spec.delay.is_some(),
        "--delay belongs to the frequency-domain fit; with effects use --effect time_delay",
    )?;
    refuse(
        args.linear_axis,
        "--linear-axis is not available with effects",
    )?;
    if !(args.gear_ratio.is_finite() && args.gear_ratio > 0.0) {
        return Err(format!(
            "--gear-ratio {}: must be finite and > 0",
            args.gear_ratio
        ));
    }
    Ok(structure)
}

/// Keys given a value in each `--effect` spec (`name:key=value,...`).
fn given_keys(spec: &str) -> Vec<(String, f64)> {
    let Some((_, rest)) = spec.split_once(':') else {
        return Vec::new();
    };
    rest.split(',')
        .filter_map(|item| {
            let (k, v) = item.split_once('=')?;
            Some((k.trim().to_string(), v.trim().parse().ok()?))
        })
        .collect()
}

/// `--fix NAME=VALUE` items.
fn parse_fixes(fix: &[String]) -> Result<Vec<(String, f64)>, String> {
    fix.iter()
        .map(|s| {
            let (n, v) = s
                .split_once('=')
                .ok_or_else(|| format!("--fix `{s}`: expected NAME=VALUE"))?;
            match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok((n.trim().to_string(), x)),
                _ => Err(format!(
                    "--fix `{s}`: `{}` is not a finite number",
                    v.trim()
                )),
            }
        })
        .collect()
}

/// The previous fit in the model file `--start PATH`.
fn read_start(path: &Path) -> Result<NlFit, String> {
    let text =
        std::fs::read_to_string(path).map_err(|e| format!("--start {}: {e}", path.display()))?;
    let saved: SavedModel = serde_json::from_str(&text)
        .map_err(|e| format!("--start {}: not a jointid model file: {e}", path.display()))?;
    saved
        .to_nonlinear()
        .map_err(|e| format!("--start {}: {e}", path.display()))
}

/// The estimation and validation records (`--estimation-fraction` splits DATA).
fn records(
    args: &FitArgs,
    ds: &Dataset,
    val_ds: Option<&Dataset>,
) -> (IdData, Option<(IdData, String)>) {
    match (args.estimation_fraction, val_ds) {
        (Some(f), _) => {
            let (a, b) = ds.data.split(f);
            let vn = format!("{} (last {:.0} %)", ds.name, 100.0 * (1.0 - f));
            (a, Some((b, vn)))
        }
        (None, Some(v)) => (ds.data.clone(), Some((v.data.clone(), v.name.clone()))),
        (None, None) => (ds.data.clone(), None),
    }
}

/// Runs the nonlinear `jointid fit` on the loaded records.
///
/// # Errors
/// Bad flags, effects or fixes (exit 2 naming them), the engine's errors, output errors.
pub fn run(
    args: &FitArgs,
    spec: &ModelSpec,
    ctx: &mut Context<'_>,
    segs: &[Dataset],
    numbers: &[usize],
    val_ds: Option<&Dataset>,
) -> CmdResult {
    if segs.is_empty() {
        return Err("no segment to fit".into());
    }
    let ds = super::fit::longest_segment(segs);
    let structure = check_flags(args, spec)?;
    if let Some(p) = &args.save {
        check_output(p, args.force)?;
    }
    // the effects as resolved (seed 001's two, then the user's) and their specs, whose
    // given keys start there (one effect per spec; `none` gives none)
    let effects = spec.effects.clone().unwrap_or_default();
    let specs = ModelSpec::effect_specs(args.model.nonlinear_two_mass, &args.effects);
    let req = NlRequest {
        held_tau_c: spec.current_loop_tau,
        fixed: parse_fixes(&args.fix)?,
        given: specs
            .iter()
            .take(effects.len())
            .map(|s| given_keys(s))
            .collect(),
        options: NlOptions::default(),
        ..NlRequest::new(structure, args.gear_ratio, effects)
    };
    let (est, val) = records(args, ds, val_ds);
    // the segments as separate experiments (one record: `est` alone)
    let est_all: Vec<IdData> = if segs.len() > 1 {
        segs.iter().map(|d| d.data.clone()).collect()
    } else {
        vec![est.clone()]
    };
    let val_name = val.as_ref().map_or("validation", |(_, n)| n.as_str());
    let why = |e: NlRunError| -> String {
        match &e {
            NlRunError::UnknownParameter { .. } => format!("--fix {e}"),
            NlRunError::StartMismatch { .. } => match &args.start {
                Some(p) => format!("--start {}: {e}", p.display()),
                None => e.to_string(),
            },
            NlRunError::LagRange(_) => e.to_string(),
            NlRunError::Estimation(_) => format!("{}: {e}", ds.name),
            NlRunError::Validation(_) => format!("{val_name}: {e}"),
        }
    };
    req.check().map_err(why)?;
    let mut req = req;
    if let Some(path) = &args.start {
        req.start = NlStart::Previous(Box::new(read_start(path)?));
    }
    let ts = est.ts;
    let t0 = Instant::now();
    let done = run_nl(
        NlData {
            estimation: &est_all,
            // whole periods of DATA: the frequency-domain fit gives the linear start
            periodic: args
                .estimation_fraction
                .is_none()
                .then_some((segs, args.settle_periods)),
            validation: val.as_ref().map(|(v, _)| v),
        },
        &req,
    )
    .map_err(why)?;
    let seconds = t0.elapsed().as_secs_f64();
    let (est_v, val_v) = (done.estimation, done.validation);
    let segments: Vec<SegmentJson> = segs
        .iter()
        .zip(numbers)
        .zip(&done.estimation_segments)
        .map(|((d, &k), v)| SegmentJson {
            segment: k,
            samples: d.data.len(),
            fit: Some(v.velocity_fit_percent),
        })
        .collect();
    let res = done.result;
    let (fit, method, options, warnings) = (res.fit, res.method, res.options, res.warnings);
    let simulate_command = format!(
        "jointid simulate {} --out RUN.jcap",
        simulate_args(&fit)
            .iter()
            .map(|a| a.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let mut files = Vec::new();
    if let Some(path) = &args.save {
        let saved = SavedModel::from_nonlinear(
            &fit,
            ts,
            &method,
            &ds.name,
            est_v.velocity_fit_percent,
            NL_FIT_NAME,
            options.highpass_hz,
        );
        save_model(path, &saved, args.force)?;
        files.push(path.display().to_string());
    }
    if let Some(dir) = &args.plot {
        let (data, name) = match &val {
            Some((v, n)) => (v, n.as_str()),
            None => (&est, ds.name.as_str()),
        };
        let p = write_velocity_plot(dir, data, name, &fit, args.force)?;
        files.push(p.display().to_string());
    }
    let report = NlReport {
        model: jointid::ident::nonlinear::model_name(structure, &fit.model.effects),
        method,
        file: ds.name.clone(),
        validation_file: val.as_ref().map(|(_, n)| n.clone()),
        ts,
        samples: est_all.iter().map(IdData::len).sum(),
        segments,
        parameters: fit
            .params
            .iter()
            .filter(|p| matches!(p.owner, Owner::Plant | Owner::CurrentLoop | Owner::Offset))
            .map(|p| (p.name.to_string(), pj(p)))
            .collect(),
        effects: fit
            .model
            .effects
            .iter()
            .enumerate()
            .map(|(i, e)| EffectJson {
                name: e.name().into(),
                spec: e.to_string(),
                parameters: fit
                    .params
                    .iter()
                    .filter(|p| p.owner == Owner::Effect(i))
                    .map(|p| (p.name.to_string(), pj(p)))
                    .collect(),
            })
            .collect(),
        start: match &args.start {
            Some(p) => format!("from {}", p.display()),
            None => "automatic (seed 001's three steps)".into(),
        },
        steps: res
            .steps
            .iter()
            .map(|s| StepJson {
                name: s.name.clone(),
                values: s
                    .values
                    .iter()
                    .map(|(n, v, u)| {
                        (
                            n.clone(),
                            StepValue {
                                value: *v,
                                unit: u.to_string(),
                            },
                        )
                    })
                    .collect(),
                detail: s.detail.clone(),
            })
            .collect(),
        fixed: fit
            .params
            .iter()
            .filter(|p| p.fixed)
            .map(|p| p.name.to_string())
            .collect(),
        iterations: fit.iterations,
        termination: fit.termination.describe().into(),
        fit_name: NL_FIT_NAME.into(),
        fit_estimation: est_v.velocity_fit_percent,
        fit_validation: val_v.map(|v| v.velocity_fit_percent),
        fit_estimation_smooth: fit.fit_velocity_percent,
        validation: val_v.map(FitsJson::from),
        highpass_hz: options.highpass_hz,
        simulate_command,
        saved_model: args.save.as_ref().map(|p| p.display().to_string()),
        seconds,
        files,
        warnings,
    };
    if ctx.json {
        print_json(ctx.out, "fit-nonlinear", &report)?;
    } else {
        print_report(ctx.out, &report, &fit)?;
    }
    if args.strict && !report.warnings.is_empty() {
        return Ok(Outcome::CheckFailed);
    }
    Ok(Outcome::Ok)
}

fn pj(p: &jointid::ident::nonlinear::NlParam) -> ParamJson {
    ParamJson {
        value: p.value,
        std: p.std,
        unit: p.unit.into(),
    }
}

/// Writes [`PLOT_FILE`] into `dir`: the measured interval-mean motor velocity of `data`
/// against the fitted model's, simulated with the exact laws from the measured torque,
/// over one second in the middle of the record.
///
/// # Errors
/// Directory, simulation, plot and write errors.
fn write_velocity_plot(
    dir: &Path,
    data: &IdData,
    name: &str,
    fit: &NlFit,
    force: bool,
) -> Result<std::path::PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let theta = simulate_exact(fit, data)?;
    let v = interval_velocity(&data.y, data.ts);
    let vh = interval_velocity(&theta, data.ts);
    let n = v.len();
    let w = ((1.0 / data.ts).round() as usize).clamp(2, n.max(2));
    let a = (n / 2).saturating_sub(w / 2);
    let b = (a + w).min(n);
    let err: Vec<f64> = v[a..b].iter().zip(&vh[a..b]).map(|(x, y)| x - y).collect();
    let title = format!("motor velocity on {name}: measured and the fitted model (exact laws)");
    let svg = time_svg(
        &title,
        "interval-mean motor velocity [rad/s]",
        a as f64 * data.ts,
        data.ts,
        &[
            TimeSeries {
                name: "measured",
                values: &v[a..b],
            },
            TimeSeries {
                name: "model, simulated from the measured torque",
                values: &vh[a..b],
            },
            TimeSeries {
                name: "measured - model",
                values: &err,
            },
        ],
    )?;
    let path = dir.join(PLOT_FILE);
    write_svg(&path, &svg, force)?;
    Ok(path)
}

fn print_report(out: &mut dyn Write, r: &NlReport, fit: &NlFit) -> std::io::Result<()> {
    writeln!(out, "jointid fit: {} on {}", r.model, r.file)?;
    writeln!(out, "  method: {}", r.method)?;
    writeln!(
        out,
        "  {} samples, Ts = {} s, fitted in {:.2} s",
        r.samples,
        jointid::data::fmt_sig(r.ts, 4),
        r.seconds
    )?;
    writeln!(out, "  start: {}", r.start)?;
    for s in &r.steps {
        let vals = s
            .values
            .iter()
            .map(|(n, v)| format!("{n} = {:.4e} {}", v.value, v.unit))
            .collect::<Vec<_>>()
            .join(", ");
        writeln!(out, "    {}: {vals}", s.name)?;
        writeln!(out, "      ({})", s.detail)?;
    }
    let row = |out: &mut dyn Write, p: &jointid::ident::nonlinear::NlParam| {
        let std = if p.fixed {
            "fixed".to_string()
        } else {
            format!("± {:.3e}", p.std)
        };
        let pct = if p.fixed || p.value == 0.0 {
            String::new()
        } else {
            format!("({:.2} %)", 100.0 * p.std / p.value.abs())
        };
        writeln!(
            out,
            "    {:<10} {:>14.6e} {:<14} {:<11} {}",
            p.name, p.value, std, pct, p.unit
        )
    };
    writeln!(out, "  plant ({}):", fit.model.structure.label())?;
    for p in fit
        .params
        .iter()
        .filter(|p| matches!(p.owner, Owner::Plant | Owner::CurrentLoop | Owner::Offset))
    {
        row(out, p)?;
    }
    for (i, e) in fit.model.effects.iter().enumerate() {
        writeln!(out, "  effect {}:", e.name())?;
        for p in fit.params.iter().filter(|p| p.owner == Owner::Effect(i)) {
            row(out, p)?;
        }
    }
    writeln!(out, "  {} iterations ({})", r.iterations, r.termination)?;
    writeln!(
        out,
        "  velocity FIT [%]: interval-mean motor velocity (θ_m[k] − θ_m[k−1])/Ts, measured \
         against the model driven by the measured torque, both through the {} Hz high-pass \
         prefilter:",
        r.highpass_hz
    )?;
    writeln!(
        out,
        "    estimation, estimator's smooth laws (the fit's cost): {:.2}",
        r.fit_estimation_smooth
    )?;
    writeln!(
        out,
        "    estimation, simulator's exact laws:                   {:.2}",
        r.fit_estimation
    )?;
    if r.segments.len() > 1 {
        for sg in &r.segments {
            writeln!(
                out,
                "      segment {} ({} samples), exact laws:             {:.2}",
                sg.segment,
                sg.samples,
                sg.fit.unwrap_or(f64::NAN)
            )?;
        }
    }
    if let Some(v) = &r.validation {
        writeln!(
            out,
            "    validation, simulator's exact laws:                   {:.2}",
            v.velocity_fit_percent
        )?;
        writeln!(
            out,
            "    validation, estimator's smooth laws:                  {:.2}",
            v.velocity_fit_smooth_percent
        )?;
        writeln!(
            out,
            "  motor-angle FIT [%] on the validation record (toolbox compare, exact laws, \
             unfiltered; drift of the rigid-body mode included): {:.2}",
            v.angle_fit_percent
        )?;
    }
    writeln!(out, "  the fitted plant and effects in the simulator:")?;
    writeln!(out, "    {}", r.simulate_command)?;
    if let Some(m) = &r.saved_model {
        writeln!(
            out,
            "    or: jointid simulate --model-file {m} --out RUN.jcap"
        )?;
    }
    let tau = fit.model.tau_c;
    let offset = fit.get("offset").unwrap_or(0.0);
    writeln!(
        out,
        "    (the simulator closes its own position and current loops; not in the command: \
         current-loop lag tau_c = {}, torque offset = {offset:.3e} N·m)",
        if tau > 0.0 {
            format!("{tau:.3e} s")
        } else {
            "none".into()
        }
    )?;
    for f in &r.files {
        writeln!(out, "  wrote {f}")?;
    }
    for w in &r.warnings {
        writeln!(out, "  note: {w}")?;
    }
    Ok(())
}
