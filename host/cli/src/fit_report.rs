//! The reports of `jointid fit` ([`jointid::ident::fit::run`]): the text or `--json`
//! document, the Bode plot and the toolbox's views of a linear model, and for a physical
//! model with the simulator's effects attached (`--effect SPEC`, `--model
//! nonlinear-two-mass`, fitted by [`jointid::ident::nonlinear::run`]) its own report
//! and the motor-velocity plot. Only printing and writing.
//!
//! The nonlinear report keeps the name of every `fit --json` field that has a meaning
//! there (`model`, `parameters` with the structure, `tau_c` and `offset`, `fit_name`,
//! `fit_estimation`, `fit_validation`, `warnings`, ...); `effects`, `steps`, `validation`
//! and `simulate_command` are added.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::print::{print_tests, std_percent};
use super::views::{
    frf_label, write_bode_figure, write_views, Signals, Views, PERIODIC_COMPARED, VELOCITY_COMPARED,
};
use super::{print_json, write_svg};
use jointid::data::input::path_text;
use jointid::data::Percent;
use jointid::ident::fit::{
    param_map, Compared, FitOutcome, LinearFit, NonlinearFit, ParamJson, SegmentJson,
    VelocityFigure,
};
use jointid::ident::grey_box::Output;
use jointid::ident::nonlinear::{model_name, simulate_args, NlFit, NlParam, NlValidation, Owner};
use jointid::ident::validate::{Validation, FIT_NAME};
use jointid::report::plot::{time_svg, TimeSeries};

/// Everything `fit --json` prints.
#[derive(Debug, Serialize)]
pub struct FitReport {
    /// model family
    pub model: String,
    /// how it was estimated
    pub method: String,
    /// estimation data file
    pub file: String,
    /// validation data file
    pub validation_file: Option<String>,
    /// model sample interval [s]
    pub ts: f64,
    /// estimation samples (after preparation)
    pub samples: usize,
    /// the gap-free segments of DATA the fit used (one entry for a record without gaps or
    /// one segment), each with the model's FIT on it alone
    pub segments: Vec<SegmentJson>,
    /// parameters by name (empty for a black box)
    pub parameters: std::collections::BTreeMap<String, ParamJson>,
    /// how the records' input samples were read (`sampled`: a signal that moves between
    /// them); the model file records it and `validate` reads its data so
    pub input: jointid::data::InputTaken,
    /// name of the FIT definition
    pub fit_name: String,
    /// which FIT `fit_estimation` and `fit_validation` are: `toolbox` (the output's),
    /// `periodic` (the period-averaged steady state's) or `velocity` (the prefiltered motor
    /// velocity's, for a model fitted on it: the angle's drift dominates the toolbox FIT)
    pub fit_metric: &'static str,
    /// FIT on the estimation data [%]
    pub fit_estimation: f64,
    /// FIT on the validation data [%]
    pub fit_validation: Option<f64>,
    /// with `fit_metric` `velocity`: the toolbox FIT of the angle on the estimation data [%]
    /// (secondary: the drift dominates it)
    pub fit_toolbox_estimation: Option<f64>,
    /// as `fit_toolbox_estimation`, on the validation data [%]
    pub fit_toolbox_validation: Option<f64>,
    /// why the FIT shown is not the one the fit's domain reports, and what it measures
    /// (the text report's; `fit_name` says it in `--json`)
    #[serde(skip)]
    pub fit_note: Option<String>,
    /// identified resonance frequencies [Hz]
    pub resonances_hz: Vec<f64>,
    /// identified anti-resonance frequencies [Hz]
    pub antiresonances_hz: Vec<f64>,
    /// residual tests on estimation (and validation) data
    pub residual_tests: ResidualTests,
    /// wall time of the fit [s]
    #[serde(rename = "elapsed_s")]
    pub seconds: f64,
    /// files written
    pub files: Vec<String>,
    /// estimator notes
    pub warnings: Vec<String>,
}

/// Residual tests per data set.
#[derive(Debug, Serialize)]
pub struct ResidualTests {
    /// on the estimation data
    pub estimation: Validation,
    /// on the validation data
    pub validation: Option<Validation>,
}

/// Writes the Bode plot and the toolbox's views of a linear fit into `dir`; the paths
/// written.
pub(crate) fn plot_linear(
    dir: &Path,
    out: &FitOutcome,
    l: &LinearFit,
    signals: Signals,
    force: bool,
) -> Result<Vec<String>, Box<dyn std::error::Error + Send + Sync>> {
    let fitted = &l.fitted;
    let mut files = Vec::new();
    if let Some(fig) = &l.bode {
        let io = frf_label(&signals);
        let p = write_bode_figure(dir, "bode.svg", fig, &out.name, &io, force)?;
        files.push(path_text(&p));
    }
    let mut tests = vec![("estimation", &l.tests)];
    if let Some(v) = &l.validation_tests {
        tests.push(("validation", v));
    }
    let (compared, records) = l
        .compare
        .clone()
        .unwrap_or((Compared::Simulated, Vec::new()));
    let (fit_label, compared_label) = match compared {
        Compared::Simulated => ("FIT", "simulated"),
        Compared::SimulatedToolbox => ("toolbox FIT", "simulated"),
        Compared::Periodic => ("periodic FIT", PERIODIC_COMPARED),
        Compared::Velocity => ("velocity FIT", VELOCITY_COMPARED),
    };
    let views = Views {
        fitted,
        fit_label,
        compared: compared_label,
        records,
        compare_rate: compared == Compared::Velocity && fitted.output == Output::Angle,
        tests,
        signals,
        record_s: l.record_s,
        file: &out.name,
    };
    for p in write_views(dir, &views, force)? {
        files.push(path_text(&p));
    }
    Ok(files)
}

/// Prints the report of the linear fit `l` (`out`'s model): as `fit` JSON with `json`,
/// else as text; units of a linear axis with `linear_axis`, `files` the files written.
///
/// # Errors
/// Write and serialisation errors.
pub(crate) fn print_linear(
    w: &mut dyn Write,
    json: bool,
    out: &FitOutcome,
    l: &LinearFit,
    linear_axis: bool,
    files: Vec<String>,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let report = linear_report(out, l, linear_axis, files);
    if json {
        print_json(w, "fit", &report)?;
    } else {
        print_linear_text(w, &report)?;
    }
    Ok(())
}

/// `fit --json`'s document of a linear fit (and the text report's contents).
fn linear_report(
    out: &FitOutcome,
    l: &LinearFit,
    linear_axis: bool,
    files: Vec<String>,
) -> FitReport {
    let fitted = &l.fitted;
    let mut parameters = param_map(&fitted.params);
    if linear_axis {
        for v in parameters.values_mut() {
            v.unit = linear_unit(&v.unit).into();
        }
    }
    FitReport {
        model: fitted.spec.name(),
        method: fitted.method.clone(),
        file: out.name.clone(),
        validation_file: out.validation_name.clone(),
        ts: out.ts,
        samples: out.samples,
        segments: out.segments.clone(),
        parameters,
        input: out.input,
        fit_name: out.fit.name.into(),
        fit_metric: out.fit.metric,
        fit_estimation: out.fit.estimation,
        fit_validation: out.fit.validation,
        fit_toolbox_estimation: out.fit.toolbox.map(|t| t.0),
        fit_toolbox_validation: out.fit.toolbox.and_then(|t| t.1),
        fit_note: out.fit.note.clone(),
        resonances_hz: l.resonances.resonances.iter().map(|r| r.freq_hz).collect(),
        antiresonances_hz: l
            .resonances
            .anti_resonances
            .iter()
            .map(|r| r.freq_hz)
            .collect(),
        residual_tests: ResidualTests {
            estimation: l.tests.clone(),
            validation: l.validation_tests.clone(),
        },
        seconds: out.seconds,
        files,
        warnings: out.warnings.clone(),
    }
}

/// The first lines of both reports: model, file, method, record and fitting time.
fn print_heading(
    out: &mut dyn Write,
    (model, file, method): (&str, &str, &str),
    samples: usize,
    ts: f64,
    seconds: f64,
) -> std::io::Result<()> {
    writeln!(out, "jointid fit: {model} on {file}")?;
    writeln!(out, "  method: {method}")?;
    writeln!(
        out,
        "  {samples} samples, Ts = {} s, fitted in {seconds:.2} s",
        jointid::data::fmt_sig(ts, 4)
    )
}

fn print_linear_text(out: &mut dyn Write, r: &FitReport) -> std::io::Result<()> {
    print_heading(
        out,
        (&r.model, &r.file, &r.method),
        r.samples,
        r.ts,
        r.seconds,
    )?;
    if !r.parameters.is_empty() {
        writeln!(
            out,
            "  {:<8} {:>14} {:>12} {:>8}  unit",
            "param", "value", "std", "std %"
        )?;
        for (name, p) in &r.parameters {
            writeln!(
                out,
                "  {:<8} {:>14.6e} {:>12.3e} {:>8}  {}",
                name,
                p.value,
                p.std,
                std_percent(p.value, p.std),
                p.unit
            )?;
        }
    }
    writeln!(out, "  {}:", r.fit_name)?;
    let pooled = r.segments.len() > 1;
    let how = if pooled {
        " (pooled over the segments)"
    } else {
        ""
    };
    writeln!(out, "    estimation: {:.2}{how}", Percent(r.fit_estimation))?;
    if pooled {
        for sg in &r.segments {
            writeln!(out, "      {sg}")?;
        }
    }
    if let Some(v) = r.fit_validation {
        writeln!(out, "    validation: {:.2}", Percent(v))?;
    }
    if let Some(n) = &r.fit_note {
        writeln!(out, "    note: {n}")?;
    }
    if let Some(e) = r.fit_toolbox_estimation {
        writeln!(
            out,
            "  {FIT_NAME} of the simulated output (the drift of the rigid-body integrator \
             dominates it):"
        )?;
        writeln!(out, "    estimation: {:.2}", Percent(e))?;
        if let Some(v) = r.fit_toolbox_validation {
            writeln!(out, "    validation: {:.2}", Percent(v))?;
        }
    }
    let hz = |v: &[f64]| {
        if v.is_empty() {
            return "none".to_string();
        }
        let each: Vec<String> = v.iter().map(|f| format!("{f:.2}")).collect();
        each.join(", ")
    };
    writeln!(out, "  resonances [Hz]: {}", hz(&r.resonances_hz))?;
    writeln!(out, "  anti-resonances [Hz]: {}", hz(&r.antiresonances_hz))?;
    writeln!(out, "  residual tests (99 %):")?;
    print_tests(out, "estimation", &r.residual_tests.estimation)?;
    if let Some(v) = &r.residual_tests.validation {
        print_tests(out, "validation", v)?;
    }
    for f in &r.files {
        writeln!(out, "  wrote {f}")?;
    }
    for w in &r.warnings {
        writeln!(out, "  note: {w}")?;
    }
    Ok(())
}

/// the linear-axis unit of a rotary one
fn linear_unit(rotary: &str) -> &str {
    match rotary {
        "kg·m²" => "kg",
        "N·m·s/rad" => "N·s/m",
        "N·m/rad" => "N/m",
        "N·m" => "N",
        o => o,
    }
}

/// The plot `--plot DIR` writes for a nonlinear fit.
pub const PLOT_FILE: &str = "velocity.svg";

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

/// Everything `fit --json` prints for a nonlinear fit.
#[derive(Debug, Serialize)]
struct NlReport<'a> {
    model: String,
    method: &'a str,
    file: &'a str,
    validation_file: Option<&'a str>,
    ts: f64,
    samples: usize,
    /// the gap-free segments fitted (as separate experiments), each with the velocity FIT
    /// on it alone
    segments: &'a [SegmentJson],
    /// the structure's parameters, `tau_c` (when there is a lag) and `offset`
    parameters: BTreeMap<String, ParamJson>,
    effects: Vec<EffectJson>,
    /// how the records' input samples were read (`sampled`: a signal that moves between
    /// them); the model file records it and `validate` reads its data so
    input: jointid::data::InputTaken,
    /// the start: its steps (empty with --start)
    start: String,
    steps: Vec<StepJson>,
    /// parameters held at their value (--fix, --current-loop-tau)
    fixed: Vec<String>,
    iterations: usize,
    termination: String,
    fit_name: &'a str,
    /// exact-law velocity FIT on the estimation record [%]
    fit_estimation: f64,
    /// exact-law velocity FIT on the validation record [%]
    fit_validation: Option<f64>,
    /// the fit's own measure: velocity FIT with the estimator's smooth laws [%]
    fit_estimation_smooth: f64,
    /// the validation FITs
    validation: Option<NlValidation>,
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
    warnings: &'a [String],
}

/// Prints the report of the nonlinear fit `nl` (`out`'s model): as `fit-nonlinear` JSON
/// with `json`, else as text; `start` is the `--start` file, `saved` the `--save` file,
/// `files` the files written.
///
/// # Errors
/// Write and serialisation errors.
pub(crate) fn print_nonlinear(
    w: &mut dyn Write,
    json: bool,
    out: &FitOutcome,
    nl: &NonlinearFit,
    start: Option<&Path>,
    saved: Option<&Path>,
    files: Vec<String>,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let res = &nl.run.result;
    let fit = &res.fit;
    let simulate_command = format!(
        "jointid simulate {} --out RUN.jcap",
        simulate_args(fit).join(" ")
    );
    let report = NlReport {
        model: model_name(nl.structure, &fit.model.effects),
        method: &res.method,
        file: &out.name,
        validation_file: out.validation_name.as_deref(),
        ts: out.ts,
        samples: out.samples,
        segments: &out.segments,
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
        input: out.input,
        start: match start {
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
                        let value = StepValue {
                            value: *v,
                            unit: u.to_string(),
                        };
                        (n.clone(), value)
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
        fit_name: out.fit.name,
        fit_estimation: out.fit.estimation,
        fit_validation: out.fit.validation,
        fit_estimation_smooth: fit.fit_velocity_percent,
        validation: nl.run.validation,
        highpass_hz: res.options.highpass_hz,
        simulate_command,
        saved_model: saved.map(path_text),
        seconds: out.seconds,
        files,
        warnings: &out.warnings,
    };
    if json {
        print_json(w, "fit-nonlinear", &report)?;
    } else {
        print_nonlinear_text(w, &report, fit)?;
    }
    Ok(())
}

fn pj(p: &NlParam) -> ParamJson {
    ParamJson {
        value: p.value,
        std: p.std,
        unit: p.unit.into(),
    }
}

/// Writes [`PLOT_FILE`] into `dir`: the measured interval-mean motor velocity against the
/// fitted model's, simulated with the exact laws from the measured torque, over one second
/// in the middle of the record ([`VelocityFigure`]).
///
/// # Errors
/// Directory, plot and write errors.
pub(crate) fn write_velocity_plot(
    dir: &Path,
    fig: &VelocityFigure,
    force: bool,
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let title = format!(
        "motor velocity on {}: measured and the fitted model (exact laws)",
        fig.record
    );
    let svg = time_svg(
        &title,
        "interval-mean motor velocity [rad/s]",
        fig.start_s,
        fig.ts,
        &[
            TimeSeries {
                name: "measured",
                values: &fig.measured,
            },
            TimeSeries {
                name: "model, simulated from the measured torque",
                values: &fig.model,
            },
            TimeSeries {
                name: "measured - model",
                values: &fig.residual,
            },
        ],
    )?;
    let path = dir.join(PLOT_FILE);
    write_svg(&path, &svg, force)?;
    Ok(path)
}

fn print_nonlinear_text(out: &mut dyn Write, r: &NlReport<'_>, fit: &NlFit) -> std::io::Result<()> {
    print_heading(
        out,
        (&r.model, r.file, r.method),
        r.samples,
        r.ts,
        r.seconds,
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
    let row = |out: &mut dyn Write, p: &NlParam| {
        let std = if p.fixed {
            "fixed".to_string()
        } else {
            format!("± {:.3e}", p.std)
        };
        let pct = if p.fixed {
            String::new()
        } else {
            format!("({} %)", std_percent(p.value, p.std))
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
        Percent(r.fit_estimation_smooth)
    )?;
    writeln!(
        out,
        "    estimation, simulator's exact laws:                   {:.2}",
        Percent(r.fit_estimation)
    )?;
    if r.segments.len() > 1 {
        for sg in r.segments {
            writeln!(
                out,
                "      segment {} ({} samples), exact laws:             {:.2}",
                sg.segment,
                sg.samples,
                Percent(sg.fit.unwrap_or(f64::NAN))
            )?;
        }
    }
    if let Some(v) = &r.validation {
        writeln!(
            out,
            "    validation, simulator's exact laws:                   {:.2}",
            Percent(v.velocity_fit_percent)
        )?;
        writeln!(
            out,
            "    validation, estimator's smooth laws:                  {:.2}",
            Percent(v.velocity_fit_smooth_percent)
        )?;
        writeln!(
            out,
            "  motor-angle FIT [%] on the validation record (toolbox compare, exact laws, \
             unfiltered; drift of the rigid-body mode included): {:.2}",
            Percent(v.angle_fit_percent)
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
    for w in r.warnings {
        writeln!(out, "  note: {w}")?;
    }
    Ok(())
}
