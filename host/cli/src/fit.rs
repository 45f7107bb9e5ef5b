//! `jointid fit DATA --model KIND`: fit a black-box or physical model
//! ([`jointid::ident::fit`]) and report parameters with standard deviations and
//! units, FIT (toolbox `compare` definition) on estimation and validation
//! data, resonance and anti-resonance frequencies, residual tests, and
//! optionally Bode plots over the measured FRF (seed 000 Figs. 5–6) and the
//! model file.
//!
//! With `--decimate N > 1` the black box is fitted on the decimated data;
//! a physical model is started there and refined at the capture rate, and
//! every FIT is computed on the decimated data ([`jointid::ident::fit::FitData`]);
//! the model file records both rates, so `jointid validate` does the same.
//!
//! Column mapping: DATA is a capture CSV, a `.jcap` capture (once its loader
//! is registered) or any CSV with `--time/--input/--output` (as every
//! analysis command; `--output-col` is accepted too); `--output-kind` says
//! whether that column is an angle or a velocity.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Args, ValueEnum};
use serde::Serialize;

use super::args::{DataArgs, PrepArgs, ReadArgs};
use super::views::{
    frf_label, write_views, CompareRecord, Signals, Views, PERIODIC_COMPARED, VELOCITY_COMPARED,
    VIEW_FILES,
};
use super::{check_plot_files, print_json, write_svg, CmdResult, Context, Outcome};
use jointid::data::output::check_output;
use jointid::data::Dataset;
use jointid::ident::fit::{
    below_frf, default_f_min, fit_frequency_domain, fit_prepared, fit_prepared_segments, log_grid,
    param_map, FitData, FitMetric, FitOptions, Fitted, ParamJson, VELOCITY_FIT_NAME,
};
use jointid::ident::frf::{analyze_dataset, analyze_segments, FrfAnalysis};
use jointid::ident::frf_fit::{self, PERIODIC_FIT_NAME};
use jointid::ident::grey_box::{Output, DEFAULT_GEAR_RATIO};
use jointid::ident::ss::Resonances;
use jointid::ident::subspace::Method;
use jointid::ident::validate::{
    BodeCurve, CorrelationTest, FrfBand, Validation, DEFAULT_LAGS, FIT_NAME,
};
use jointid::model::spec::{Family, ModelSpec, SpecError, Structure, NONLINEAR_TWO_MASS};
use jointid::report::plot::bode_svg_in;

/// Friction model of the rigid body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FrictionArg {
    /// viscous only
    Viscous,
    /// viscous and Coulomb, plus a torque offset (inverse-dynamics LS)
    Coulomb,
    /// viscous and Coulomb each with its own coefficient forward and backward (Fv, Fc,
    /// Fv_neg, Fc_neg; inverse-dynamics LS, no offset: EMPS's asymmetric reference model)
    CoulombAsymmetric,
}

/// Which motor signal the output column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutputArg {
    /// motor angle [rad] (or position [m])
    Angle,
    /// motor velocity [rad/s] (or [m/s])
    Velocity,
}

impl From<OutputArg> for Output {
    fn from(o: OutputArg) -> Self {
        match o {
            OutputArg::Angle => Output::Angle,
            OutputArg::Velocity => Output::Velocity,
        }
    }
}

/// Subspace method of the black box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// predictor-based subspace identification (closed-loop consistent)
    Pbsid,
    /// PO-MOESP (open loop)
    Moesp,
}

/// A data file with the column mapping of `fit`: the same flags as every
/// analysis command, `--output-col` accepted as another name of `--output`.
#[derive(Debug, Clone, Args)]
pub struct FitDataArgs {
    /// data file: capture CSV (`t,theta_ref,u,theta_m`), a mapped CSV, or `.jcap`
    #[arg(value_name = "DATA")]
    pub path: PathBuf,
    /// time column [s] (with --input and --output)
    #[arg(long, value_name = "COL", requires_all = ["input", "output_col"])]
    pub time: Option<String>,
    /// input column (torque [N·m] or force [N])
    #[arg(long, value_name = "COL", requires_all = ["time", "output_col"])]
    pub input: Option<String>,
    /// output column (motor angle [rad] or position [m]; see --output-kind)
    #[arg(
        long = "output",
        visible_alias = "output-col",
        value_name = "COL",
        requires_all = ["time", "input"]
    )]
    pub output_col: Option<String>,
    /// reference column (default: the capture CSV's `theta_ref`)
    #[arg(long, value_name = "COL")]
    pub reference: Option<String>,
    /// how to read the files and which part to use
    #[command(flatten)]
    pub read: ReadArgs,
}

impl FitDataArgs {
    /// the same mapping as analysis' [`DataArgs`] for `path`
    pub fn data_args(&self, path: &Path) -> DataArgs {
        DataArgs {
            path: path.to_path_buf(),
            time: self.time.clone(),
            input: self.input.clone(),
            output: self.output_col.clone(),
            reference: self.reference.clone(),
            read: self.read.clone(),
        }
    }
}

/// Where the model is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DomainArg {
    /// frequency domain for physical models on periodic data, else time
    Auto,
    /// the FRF at the excited lines (periodic data, physical models)
    Frequency,
    /// output error on the time record
    Time,
}

/// Arguments of `jointid fit`.
#[derive(Debug, Clone, Args)]
pub struct FitArgs {
    /// estimation data and columns
    #[command(flatten)]
    pub data: FitDataArgs,
    /// model: black-box:ORDER, rigid, two-mass, three-mass, four-mass, or
    /// nonlinear-two-mass (seed 001: two-mass with nonlinear_stiffness and coulomb_friction)
    #[arg(long, value_name = "KIND", value_parser = parse_kind)]
    pub model: FitModel,
    /// attach an effect to the physical model, repeatable, spelled as `simulate --effect`
    /// (`name` or `name:key=value,...`; names: coulomb_friction, backlash,
    /// nonlinear_stiffness, extra_mode, time_delay, torque_ripple); sends the fit to the
    /// nonlinear grey-box engine. Estimated keys given a value start there; an extra
    /// mode's `attach` and a given ripple `order` are taken as given (without `order=`
    /// the ripple's order is found in the data, step `torque_ripple order`)
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// nonlinear fit: hold a parameter at this value (`J_m`, `k_g`, `tau_c`, `offset`, an
    /// effect's key such as `k3` or `fc`), repeatable
    #[arg(long = "fix", value_name = "NAME=VALUE")]
    pub fix: Vec<String>,
    /// nonlinear fit: start from this model file (written by `fit --save` with effects)
    /// instead of the automatic start
    #[arg(long, value_name = "MODEL.json")]
    pub start: Option<PathBuf>,
    /// friction of the rigid model
    #[arg(long, value_enum, default_value_t = FrictionArg::Viscous)]
    pub friction: FrictionArg,
    /// validation data (same columns and preparation)
    #[arg(long, value_name = "VAL")]
    pub validation: Option<PathBuf>,
    /// without --validation: estimate on this first fraction of DATA
    /// (after preparation) and validate on the rest
    #[arg(long, value_name = "F", conflicts_with = "validation", value_parser = parse_fraction)]
    pub estimation_fraction: Option<f64>,
    /// store the model (everything needed to simulate it again); a name ending in `.mat`
    /// writes a MATLAB file instead (matrices, transfer functions, parameters, FIT)
    #[arg(long, value_name = "MODEL.json")]
    pub save: Option<PathBuf>,
    /// write into this directory bode.svg (model over the FRF with ±2σ) and the toolbox's
    /// views: compare.svg (measured vs simulated output, FIT in the legend), resid.svg
    /// (residual tests with their bands), pzmap.svg and step.svg
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// replace the --save file and the plot when they exist (without it they are refused
    /// before any fitting)
    #[arg(long)]
    pub force: bool,
    /// which motor signal the output column holds
    #[arg(long, value_enum, default_value_t = OutputArg::Angle)]
    pub output_kind: OutputArg,
    /// subspace method of the black box
    #[arg(long, value_enum, default_value_t = MethodArg::Pbsid)]
    pub method: MethodArg,
    /// keep the subspace black box (no output-error refinement)
    #[arg(long)]
    pub no_refine: bool,
    /// black box with a direct feed-through D (e.g. an acceleration output)
    #[arg(long)]
    pub feedthrough: bool,
    /// gear ratio r (arm angle per motor angle) of the physical models
    #[arg(long, value_name = "R", default_value_t = DEFAULT_GEAR_RATIO)]
    pub gear_ratio: f64,
    /// time constant [s] of the drive's current loop, a first-order lag in
    /// front of the physical models; default: estimated in the frequency
    /// domain, 0 (neglected, as in seed 000) in the time domain
    #[arg(long, value_name = "S", value_parser = parse_tau)]
    pub current_loop_tau: Option<f64>,
    /// transport delay of the torque [samples] (frequency domain);
    /// default: estimated
    #[arg(long, value_name = "SAMPLES", value_parser = parse_delay)]
    pub delay: Option<f64>,
    /// where to fit: auto (frequency domain for physical models on periodic
    /// data), frequency or time
    #[arg(long, value_enum, default_value_t = DomainArg::Auto)]
    pub domain: DomainArg,
    /// exit 1 when the fit raised any warning
    #[arg(long)]
    pub strict: bool,
    /// lags M of the residual tests (each record they run on needs more than 2M samples)
    #[arg(long, value_name = "M", default_value_t = DEFAULT_LAGS, value_parser = parse_lags)]
    pub lags: usize,
    /// the axis is linear (force [N] → position [m]): units kg, N·s/m, N, N/m
    #[arg(long)]
    pub linear_axis: bool,
    /// the plots' units of input and output for other data, e.g. `V,m` (default: N·m and
    /// rad, or N and m with --linear-axis; an output velocity per second)
    #[arg(long, value_name = "IN,OUT", value_parser = super::views::parse_units)]
    pub units: Option<(String, String)>,
    /// whole periods dropped as transient before the FRF of the plot
    #[arg(long, value_name = "P", default_value_t = 1)]
    pub settle_periods: usize,
    /// decimation and detrending
    #[command(flatten)]
    pub prep: PrepArgs,
}

/// the linear-axis unit of a rotary one
pub fn linear_unit(rotary: &str) -> &str {
    match rotary {
        "kg·m²" => "kg",
        "N·m·s/rad" => "N·s/m",
        "N·m/rad" => "N/m",
        "N·m" => "N",
        o => o,
    }
}

fn parse_fraction(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(f) if f > 0.0 && f < 1.0 => Ok(f),
        _ => Err(format!("`{s}` is not a fraction strictly between 0 and 1")),
    }
}

fn parse_tau(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if (0.0..1.0).contains(&t) => Ok(t),
        _ => Err(format!(
            "`{s}` is not a time constant in seconds, 0 ≤ τ < 1"
        )),
    }
}

fn parse_delay(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(d) if (0.0..=frf_fit::MAX_DRIVE_SAMPLES).contains(&d) => Ok(d),
        _ => Err(format!(
            "`{s}` is not a delay in samples, 0 ≤ D ≤ {}",
            frf_fit::MAX_DRIVE_SAMPLES
        )),
    }
}

/// `--lags M`: at least 1 (the residual tests need one lag)
pub(crate) fn parse_lags(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(m) if m >= 1 => Ok(m),
        _ => Err(format!("`{s}` is not a number of lags ≥ 1")),
    }
}

/// `--lags M` against a record of `samples` samples that the residual tests run on
/// (`what`): they need more than 2M.
pub(crate) fn check_lags(lags: usize, what: &str, samples: usize) -> Result<(), String> {
    if samples > 2 * lags {
        return Ok(());
    }
    Err(format!(
        "--lags {lags}: the residual tests on {what} have {samples} samples, they need more than \
         2 × {lags} = {}",
        2 * lags
    ))
}

/// The column mapping names three (or four) different columns: one column cannot be two
/// signals.
pub(crate) fn check_columns(data: &DataArgs) -> Result<(), String> {
    let named = [
        ("--time", &data.time),
        ("--input", &data.input),
        ("--output", &data.output),
        ("--reference", &data.reference),
    ];
    for (i, (fa, a)) in named.iter().enumerate() {
        for (fb, b) in &named[i + 1..] {
            if let (Some(a), Some(b)) = (a, b) {
                if a == b {
                    return Err(format!(
                        "{fa} and {fb} both name column `{a}`: one column cannot be two signals"
                    ));
                }
            }
        }
    }
    Ok(())
}

/// `other` (a validation record) has the sample interval of `first`.
pub(crate) fn check_same_rate(first: &Dataset, other: &Dataset, flag: &str) -> Result<(), String> {
    let (a, b) = (first.data.ts, other.data.ts);
    if jointid::data::same_rate(a, b) {
        return Ok(());
    }
    Err(format!(
        "{flag} {}: sampled at {} Hz, {} at {} Hz; the validation record needs the estimation \
         record's sample rate",
        other.name,
        jointid::data::fmt_sig(1.0 / b, 6),
        first.name,
        jointid::data::fmt_sig(1.0 / a, 6)
    ))
}

/// `--model`: a model family, or seed 001's nonlinear two-mass (the two-mass with
/// `nonlinear_stiffness` and `coulomb_friction` attached).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FitModel {
    /// the family (the two-mass for `nonlinear-two-mass`)
    pub kind: Family,
    /// `nonlinear-two-mass` was asked for
    pub nonlinear_two_mass: bool,
}

fn parse_kind(s: &str) -> Result<FitModel, String> {
    if s.trim().to_ascii_lowercase().replace('_', "-") == NONLINEAR_TWO_MASS {
        return Ok(FitModel {
            kind: Family::Physical(Structure::TwoMass),
            nonlinear_two_mass: true,
        });
    }
    s.parse()
        .map(|kind| FitModel {
            kind,
            nonlinear_two_mass: false,
        })
        .map_err(|e: String| match e.strip_suffix(')') {
            Some(head) if head.contains("(known:") => format!("{head}, nonlinear-two-mass)"),
            _ => e,
        })
}

impl FitArgs {
    /// The model flags (`--model`, `--effect`, `--friction`, `--current-loop-tau`,
    /// `--delay`) resolved into the one [`ModelSpec`].
    ///
    /// # Errors
    /// An `--effect` spec that does not parse.
    pub fn spec(&self) -> Result<ModelSpec, SpecError> {
        let mut spec = ModelSpec::resolve(
            self.model.kind,
            self.model.nonlinear_two_mass,
            &self.effects,
            self.friction != FrictionArg::Viscous,
            self.current_loop_tau,
            self.delay,
        )?;
        spec.coulomb_asymmetric = self.friction == FrictionArg::CoulombAsymmetric;
        Ok(spec)
    }
}

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

/// One estimation segment in `fit --json`.
#[derive(Debug, Clone, Serialize)]
pub struct SegmentJson {
    /// number of the segment (from 1, as `jointid info` lists them)
    pub segment: usize,
    /// its samples at the capture rate
    pub samples: usize,
    /// the model's FIT on this segment alone, the report's FIT definition [%] (null when it
    /// cannot be computed: a segment with fewer than two steady-state periods for the
    /// periodic FIT)
    pub fit: Option<f64>,
}

impl SegmentJson {
    /// One line of the per-segment FIT list, indented by `indent`.
    pub fn write_line(&self, out: &mut dyn Write, indent: &str) -> std::io::Result<()> {
        match self.fit {
            Some(f) => writeln!(
                out,
                "{indent}segment {} ({} samples): {f:.2}",
                self.segment, self.samples
            ),
            None => writeln!(
                out,
                "{indent}segment {} ({} samples): not computed (fewer than two steady-state \
                 periods)",
                self.segment, self.samples
            ),
        }
    }
}

/// Least samples of a segment that a time-domain fit with `--segment all` takes; shorter
/// ones are left out with a note (their initial state would cost more than they tell).
pub const MIN_SEGMENT_SAMPLES: usize = 200;

/// Residual tests per data set.
#[derive(Debug, Serialize)]
pub struct ResidualTests {
    /// on the estimation data
    pub estimation: Validation,
    /// on the validation data
    pub validation: Option<Validation>,
}

/// Runs `jointid fit`.
///
/// # Errors
/// Loading, fitting, plotting and output errors.
pub fn run(args: &FitArgs, ctx: &mut Context<'_>) -> CmdResult {
    // what can be checked before the work is checked first: the outputs, the columns,
    // the validation record's rate, the lags
    if let Some(path) = &args.save {
        check_output(path, args.force)?;
    }
    let spec = args.spec()?;
    let nonlinear = spec.nonlinear();
    if let Some(dir) = &args.plot {
        let mut names = vec![super::fit_nl::PLOT_FILE];
        if !nonlinear {
            names = vec!["bode.svg"];
            names.extend(VIEW_FILES);
        }
        check_plot_files(dir, &names, args.force)?;
    }
    if !nonlinear {
        super::fit_nl::refuse_nonlinear_flags(args)?;
    }
    check_columns(&args.data.data_args(&args.data.path))?;
    let sel = args.data.data_args(&args.data.path).select(ctx.loaders)?;
    let numbers = sel.segments.clone();
    let mut segs = sel.datasets;
    let ds = longest_segment(&segs).clone();
    let val_ds = match &args.validation {
        Some(p) => Some(args.data.data_args(p).load(ctx.loaders)?),
        None => None,
    };
    if let Some(v) = &val_ds {
        check_same_rate(&ds, v, "--validation")?;
    }
    if segs.len() > 1 && args.estimation_fraction.is_some() {
        return Err(format!(
            "--estimation-fraction splits one record; {} segments ({}) were selected: give \
             --validation, or --segment longest or N",
            segs.len(),
            list(&numbers)
        )
        .into());
    }
    if nonlinear {
        if segs.len() > 1 {
            let (used, used_numbers) =
                usable_segments(&mut segs, &numbers, &ds.name, FITTING_NOTES);
            return super::fit_nl::run(args, &spec, ctx, &used, &used_numbers, val_ds.as_ref());
        }
        return super::fit_nl::run(args, &spec, ctx, &segs, &numbers, val_ds.as_ref());
    }
    let prep = args.prep.prep();
    let prepare = |d: &jointid::data::IdData, name: &str| {
        FitData::new(d, prep).map_err(|e| format!("{name}: {e}"))
    };
    let (est, val, val_name) = match (args.estimation_fraction, &val_ds) {
        (Some(frac), _) => {
            // split at the capture rate, then prepare each part
            let (a, b) = ds.data.split(frac);
            let vn = format!("{} (last {:.0} %)", ds.name, 100.0 * (1.0 - frac));
            let b = prepare(&b, &vn)?;
            (prepare(&a, &ds.name)?, Some(b), Some(vn))
        }
        (None, Some(v)) => (
            prepare(&ds.data, &ds.name)?,
            Some(prepare(&v.data, &v.name)?),
            Some(v.name.clone()),
        ),
        (None, None) => (prepare(&ds.data, &ds.name)?, None, None),
    };
    let opts = FitOptions {
        spec: spec.clone(),
        method: match args.method {
            MethodArg::Pbsid => Method::Pbsid,
            MethodArg::Moesp => Method::Moesp,
        },
        output: args.output_kind.into(),
        r: args.gear_ratio,
        refine: !args.no_refine,
        feedthrough: args.feedthrough,
    };
    if segs.len() > 1 {
        return run_segments(
            args,
            &opts,
            ctx,
            segs,
            &numbers,
            &val,
            val_ds.as_ref(),
            val_name,
        );
    }
    let periodic = match (args.domain, args.estimation_fraction) {
        (DomainArg::Time, _) => None,
        (DomainArg::Frequency, _) if spec.coulomb => {
            return Err(
                "--friction coulomb is nonlinear: the rigid model with Coulomb friction is fitted \
                 in the time domain"
                    .into(),
            )
        }
        (DomainArg::Frequency, Some(_)) => {
            return Err(
                "--domain frequency takes the whole record: give --validation \
                        instead of --estimation-fraction"
                    .into(),
            )
        }
        (DomainArg::Frequency, None) => Some(
            analyze_dataset(&ds, args.settle_periods)
                .map_err(|e| format!("{}: --domain frequency needs periodic data: {e}", ds.name))?,
        ),
        (DomainArg::Auto, None) if !spec.coulomb => analyze_dataset(&ds, args.settle_periods).ok(),
        (DomainArg::Auto, _) => None,
    };
    if let Some(a) = &periodic {
        // a validation record that is not periodic (band-limited noise,
        // say) is compared in the time domain, and so is the estimation
        // record then, so that both FITs share one definition
        let vp = val_ds
            .as_ref()
            .and_then(|v| analyze_dataset(v, args.settle_periods).ok());
        match (&val_ds, &vp) {
            // residual tests on one period of the steady state
            (None, _) | (Some(_), Some(_)) => {
                check_lags(
                    args.lags,
                    &format!("one period of {}", ds.name),
                    a.layout.period,
                )?;
                if let (Some(v), Some(p)) = (&val_ds, &vp) {
                    let what = format!("one period of {}", v.name);
                    check_lags(args.lags, &what, p.layout.period)?;
                }
            }
            (Some(_), None) => check_records_lags(args, &ds.name, &est, val.as_ref(), &val_name)?,
        }
        return run_frequency_domain(
            args,
            &opts,
            ctx,
            std::slice::from_ref(&ds),
            &numbers,
            a,
            a,
            &est,
            val.as_ref(),
            val_ds.as_ref(),
            vp.as_ref(),
            val_name,
        );
    }
    check_records_lags(args, &ds.name, &est, val.as_ref(), &val_name)?;
    let t0 = Instant::now();
    let mut fitted = fit_prepared(&est, &opts).map_err(|e| format!("{}: {e}", ds.name))?;
    let seconds = t0.elapsed().as_secs_f64();
    if spec.coulomb {
        // nonlinear: no frequency-domain reference
    } else if let Some(w) = analyze_dataset(&ds, args.settle_periods)
        .ok()
        .and_then(|a| below_frf(&a, ds.data.ts, &opts, &fitted))
    {
        fitted.warnings.push(w.to_string());
    }
    let ev = fitted
        .evaluate_on(&est, args.lags)
        .map_err(|e| format!("{}: {e}", ds.name))?;
    let vv = on_validation(&fitted, val.as_ref(), val_name.as_deref(), args.lags)?;
    let fig = time_domain_figures(
        &fitted,
        std::slice::from_ref(&est),
        val.as_ref(),
        (&ev, vv.as_ref()),
    )
    .map_err(|e| format!("{}: {e}", ds.name))?;
    let mut compare = Vec::new();
    let on_velocity = fig.metric == "velocity";
    if args.plot.is_some() {
        // the headline FIT's signals: the velocity's, else the output's
        let record =
            |d: &FitData, title: String, toolbox: f64, velocity: Option<f64>| match velocity {
                Some(fit) if on_velocity => velocity_record(&fitted, d, title, fit),
                _ => simulated_record(&fitted, d, title, toolbox),
            };
        let title = format!("estimation: {}", ds.name);
        compare.push(record(&est, title, ev.fit, Some(fig.estimation))?);
        if let (Some(v), Some(n), Some(vv)) = (&val, &val_name, &vv) {
            compare.push(record(
                v,
                format!("validation: {n}"),
                vv.fit,
                fig.validation,
            )?);
        }
    }
    let est = &est.prepared;
    let measured = Measured {
        compare,
        fit_label: if on_velocity { "velocity FIT" } else { "FIT" },
        compared: if on_velocity {
            VELOCITY_COMPARED
        } else {
            "simulated"
        },
        compare_rate: on_velocity && fitted.output == Output::Angle,
        segments: vec![SegmentJson {
            segment: numbers[0],
            samples: ds.data.len(),
            fit: Some(fig.estimation),
        }],
        val_name,
        ts: est.ts,
        samples: est.len(),
        fit_name: fig.name,
        fit_metric: fig.metric,
        fit_estimation: fig.estimation,
        fit_validation: fig.validation,
        toolbox: fig.toolbox,
        res: fitted.resonances(default_f_min(est.len(), est.ts)),
        ev,
        vv,
        seconds,
    };
    finish(args, ctx, &ds, &fitted, measured)
}

/// The longest of the selected segments (the first of equal length); the record a fit
/// over several segments names, plots and starts from.
pub(crate) fn longest_segment(segs: &[Dataset]) -> &Dataset {
    segs.iter()
        .enumerate()
        .max_by_key(|(i, d)| (d.data.len(), usize::MAX - i))
        .map_or(&segs[0], |(_, d)| d)
}

/// segment numbers as `1, 3`
pub(crate) fn list(numbers: &[usize]) -> String {
    numbers
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The segments a time-domain fit takes ([`MIN_SEGMENT_SAMPLES`] or more) and their
/// numbers; notes on standard error name those left out and why and say how the others
/// are used ([`SegmentNotes`]).
pub(crate) fn usable_segments(
    segs: &mut Vec<Dataset>,
    numbers: &[usize],
    name: &str,
    notes: SegmentNotes,
) -> (Vec<Dataset>, Vec<usize>) {
    let mut used = Vec::new();
    let mut used_numbers = Vec::new();
    let mut left = Vec::new();
    for (d, &k) in segs.drain(..).zip(numbers) {
        if d.data.len() >= MIN_SEGMENT_SAMPLES {
            used.push(d);
            used_numbers.push(k);
        } else {
            left.push(format!("segment {k} ({} samples)", d.data.len()));
        }
    }
    if !left.is_empty() {
        let _ = writeln!(
            std::io::stderr(),
            "note: {name}: {}",
            (notes.leaving)(&left.join(", "))
        );
    }
    let _ = writeln!(
        std::io::stderr(),
        "note: {name}: {}",
        (notes.using)(&list(&used_numbers))
    );
    (used, used_numbers)
}

/// The two notes of a command on several segments ([`usable_segments`]).
#[derive(Clone, Copy)]
pub(crate) struct SegmentNotes {
    /// from the segments left out, listed
    pub leaving: fn(&str) -> String,
    /// from the numbers of the segments used, listed
    pub using: fn(&str) -> String,
}

/// The notes of a fit over several segments ([`usable_segments`]): the segments it leaves
/// out, the segments it fits.
pub(crate) const FITTING_NOTES: SegmentNotes = SegmentNotes {
    leaving: |left| {
        format!(
            "the time-domain fit leaves out {left}: shorter than {MIN_SEGMENT_SAMPLES} samples, \
             each would add an initial state for little data"
        )
    },
    using: |list| {
        format!(
            "fitting segments {list} as separate experiments (one parameter vector, each \
             segment its own initial state)"
        )
    },
};

/// `jointid fit --segment all` with more than one segment, linear models: the
/// frequency-domain fit on the FRF averaged over every segment's whole periods
/// ([`analyze_segments`], as `analyze`), or the time-domain fit with the segments as
/// separate experiments ([`fit_prepared_segments`]); FIT pooled and per segment.
#[allow(clippy::too_many_arguments)]
fn run_segments(
    args: &FitArgs,
    opts: &FitOptions,
    ctx: &mut Context<'_>,
    mut segs: Vec<Dataset>,
    numbers: &[usize],
    val: &Option<FitData>,
    val_ds: Option<&Dataset>,
    val_name: Option<String>,
) -> CmdResult {
    let name = longest_segment(&segs).name.clone();
    let pooled = match args.domain {
        DomainArg::Time => None,
        DomainArg::Frequency if opts.spec.coulomb => {
            return Err(
                "--friction coulomb is nonlinear: the rigid model with Coulomb friction is fitted \
                 in the time domain"
                    .into(),
            )
        }
        DomainArg::Frequency => Some(
            analyze_segments(&segs, args.settle_periods)
                .map_err(|e| format!("{name}: --domain frequency needs periodic data: {e}"))?,
        ),
        DomainArg::Auto if !opts.spec.coulomb => analyze_segments(&segs, args.settle_periods).ok(),
        DomainArg::Auto => None,
    };
    if let Some(pooled) = &pooled {
        // the residual tests run on one period of one segment's steady state: the segment
        // with the most steady-state periods of its own
        let Some((ds, own)) = segs
            .iter()
            .filter_map(|d| analyze_dataset(d, args.settle_periods).ok().map(|a| (d, a)))
            .max_by_key(|(_, a)| a.layout.count)
        else {
            return Err(format!(
                "{name}: the FRF averages the segments, but no segment alone holds two \
                 steady-state periods for the residual tests; give --domain time"
            )
            .into());
        };
        let vp = val_ds.and_then(|v| analyze_dataset(v, args.settle_periods).ok());
        check_lags(
            args.lags,
            &format!("one period of {}", ds.name),
            own.layout.period,
        )?;
        let est =
            FitData::new(&ds.data, args.prep.prep()).map_err(|e| format!("{}: {e}", ds.name))?;
        if val_ds.is_some() && vp.is_none() {
            check_records_lags(args, &ds.name, &est, val.as_ref(), &val_name)?;
        }
        let _ = writeln!(
            std::io::stderr(),
            "note: {name}: the FRF averages the whole periods of segments {}",
            list(numbers)
        );
        return run_frequency_domain(
            args,
            opts,
            ctx,
            &segs,
            numbers,
            pooled,
            &own,
            &est,
            val.as_ref(),
            val_ds,
            vp.as_ref(),
            val_name,
        );
    }
    let (used, used_numbers) = usable_segments(&mut segs, numbers, &name, FITTING_NOTES);
    if used.is_empty() {
        return Err(format!(
            "{name}: no segment has {MIN_SEGMENT_SAMPLES} samples or more for a time-domain fit"
        )
        .into());
    }
    let prep = args.prep.prep();
    let est: Vec<FitData> = used
        .iter()
        .map(|d| FitData::new(&d.data, prep).map_err(|e| format!("{}: {e}", d.name)))
        .collect::<Result<_, _>>()?;
    let total: usize = est.iter().map(|e| e.prepared.len()).sum();
    check_lags(args.lags, &name, total)?;
    if let (Some(v), Some(vn)) = (val, &val_name) {
        check_lags(args.lags, vn, v.prepared.len())?;
    }
    let t0 = Instant::now();
    let mut fitted = fit_prepared_segments(&est, opts).map_err(|e| format!("{name}: {e}"))?;
    let seconds = t0.elapsed().as_secs_f64();
    if !opts.spec.coulomb {
        if let Some(w) = analyze_segments(&used, args.settle_periods)
            .ok()
            .and_then(|a| below_frf(&a, used[0].data.ts, opts, &fitted))
        {
            fitted.warnings.push(w.to_string());
        }
    }
    let (ev, each) = fitted
        .evaluate_segments(&est, args.lags)
        .map_err(|e| format!("{name}: {e}"))?;
    let vv = on_validation(&fitted, val.as_ref(), val_name.as_deref(), args.lags)?;
    let ts = est[0].prepared.ts;
    let mut fig = time_domain_figures(&fitted, &est, val.as_ref(), (&ev, vv.as_ref()))
        .map_err(|e| format!("{name}: {e}"))?;
    let mut compare = Vec::new();
    if args.plot.is_some() {
        // the longest segment, under the toolbox FIT printed for it
        let i = (0..used.len())
            .max_by_key(|&i| (used[i].data.len(), usize::MAX - i))
            .unwrap_or(0);
        let title = format!("estimation: {} (segment {})", used[i].name, used_numbers[i]);
        compare = compare_records(
            &fitted,
            (&est[i], title, each[i]),
            val.as_ref(),
            &val_name,
            &vv,
        )?;
    }
    let fit_label = if fig.each.is_some() {
        "toolbox FIT"
    } else {
        "FIT"
    };
    let each = fig.each.take().unwrap_or(each);
    let measured = Measured {
        compare,
        fit_label,
        compared: "simulated",
        compare_rate: false,
        segments: used
            .iter()
            .zip(&used_numbers)
            .zip(&each)
            .map(|((d, &k), &f)| SegmentJson {
                segment: k,
                samples: d.data.len(),
                fit: Some(f),
            })
            .collect(),
        val_name,
        ts,
        samples: total,
        fit_name: fig.name,
        fit_metric: fig.metric,
        fit_estimation: fig.estimation,
        fit_validation: fig.validation,
        toolbox: fig.toolbox,
        res: fitted.resonances(default_f_min(total, ts)),
        ev,
        vv,
        seconds,
    };
    finish(args, ctx, longest_segment(&used), &fitted, measured)
}

/// `--lags` against the prepared estimation and validation records.
fn check_records_lags(
    args: &FitArgs,
    name: &str,
    est: &FitData,
    val: Option<&FitData>,
    val_name: &Option<String>,
) -> Result<(), String> {
    check_lags(args.lags, name, est.prepared.len())?;
    if let (Some(v), Some(vn)) = (val, val_name) {
        check_lags(args.lags, vn, v.prepared.len())?;
    }
    Ok(())
}

/// prints the report; with `strict`, any warning fails the run
fn emit(ctx: &mut Context<'_>, report: &FitReport, strict: bool) -> CmdResult {
    if ctx.json {
        print_json(ctx.out, "fit", report)?;
    } else {
        print_report(ctx.out, report)?;
    }
    if strict && !report.warnings.is_empty() {
        return Ok(Outcome::CheckFailed);
    }
    Ok(Outcome::Ok)
}

/// The frequency-domain path of `run` ([`jointid::ident::frf_fit`]).
#[allow(clippy::too_many_arguments)]
fn run_frequency_domain(
    args: &FitArgs,
    opts: &FitOptions,
    ctx: &mut Context<'_>,
    segs: &[Dataset],
    numbers: &[usize],
    pooled: &FrfAnalysis,
    analysis: &FrfAnalysis,
    est: &FitData,
    val: Option<&FitData>,
    val_ds: Option<&Dataset>,
    val_analysis: Option<&FrfAnalysis>,
    val_name: Option<String>,
) -> CmdResult {
    // `analysis` is the FRF of `ds`, the longest segment (its residual tests); `pooled`
    // averages over every segment's whole periods (the fit and its FIT)
    let ds = longest_segment(segs);
    let ts = ds.data.ts;
    let t0 = Instant::now();
    let fitted = fit_frequency_domain(pooled, ts, opts, est.decimate)
        .map_err(|e| format!("{}: {e}", ds.name))?;
    let seconds = t0.elapsed().as_secs_f64();
    let respond = |f: &[f64]| fitted.model.freq_response(f);
    let f_min = pooled.frf.freq_hz.first().copied().unwrap_or(0.0);
    let res = fitted.resonances(f_min);
    // residual tests: input independence on one period of the steady state (slow
    // disturbances and drift averaged out), at the capture rate; the residuals the fit
    // weighted, line by line, against their bound
    let tests = |d: &Dataset, a: &FrfAnalysis| -> Result<Validation, String> {
        let s = frf_fit::periodic_steady_state(&d.data, &a.layout, respond)
            .map_err(|e| format!("{}: {e}", d.name))?;
        let (line_e, nu) = frf_fit::line_residuals(&a.frf, respond);
        jointid::ident::validate::validate_periodic(&s.u, &s.y, &s.y_hat, &line_e, nu, args.lags)
            .map_err(|e| format!("{}: {e}", d.name))
    };
    let periodic_fit =
        |a: &FrfAnalysis| frf_fit::periodic_fit_percent(&a.frf, &respond(&a.frf.freq_hz));
    let periodic = val_ds.is_none() || val_analysis.is_some();
    let mut compare = Vec::new();
    let (ev, vv) = if periodic {
        // what the periodic FIT printed for each record compares: one averaged period
        // at the reliable lines, measured against the model's response
        let mut record = |title: String, a: &FrfAnalysis, period: usize| {
            let g = respond(&a.frf.freq_hz);
            if let Some((y, y_hat)) = frf_fit::periodic_fit_signals(&a.frf, &g, period) {
                compare.push(CompareRecord {
                    title,
                    ts,
                    y,
                    y_hat,
                    fit: periodic_fit(a),
                });
            }
        };
        record(
            format!("estimation: {}", ds.name),
            pooled,
            analysis.layout.period,
        );
        let vv = match (val_ds, val_analysis) {
            (Some(v), Some(a)) => {
                record(format!("validation: {}", v.name), a, a.layout.period);
                Some(tests(v, a)?)
            }
            _ => None,
        };
        (tests(ds, analysis)?, vv)
    } else {
        let ev = fitted
            .evaluate_on(est, args.lags)
            .map_err(|e| format!("{}: {e}", ds.name))?;
        let vv = on_validation(&fitted, val, val_name.as_deref(), args.lags)?;
        if args.plot.is_some() {
            let title = format!("estimation: {}", ds.name);
            compare = compare_records(&fitted, (est, title, ev.fit), val, &val_name, &vv)?;
        }
        (ev, vv)
    };
    let (fit_name, fit_estimation, fit_validation) = if periodic {
        (
            PERIODIC_FIT_NAME,
            periodic_fit(pooled),
            val_analysis.map(periodic_fit),
        )
    } else {
        (FIT_NAME, ev.fit, vv.as_ref().map(|v| v.fit))
    };
    let segments = if segs.len() == 1 {
        vec![SegmentJson {
            segment: numbers[0],
            samples: ds.data.len(),
            fit: Some(if periodic {
                periodic_fit(analysis)
            } else {
                ev.fit
            }),
        }]
    } else {
        segs.iter()
            .zip(numbers)
            .map(|(d, &k)| SegmentJson {
                segment: k,
                samples: d.data.len(),
                fit: analyze_dataset(d, args.settle_periods)
                    .ok()
                    .map(|a| periodic_fit(&a)),
            })
            .collect()
    };
    let measured = Measured {
        compare,
        fit_label: if periodic { "periodic FIT" } else { "FIT" },
        compare_rate: false,
        compared: if periodic {
            PERIODIC_COMPARED
        } else {
            "simulated"
        },
        segments,
        val_name,
        ts,
        samples: segs.iter().map(|d| d.data.len()).sum(),
        fit_name,
        fit_metric: if periodic { "periodic" } else { "toolbox" },
        fit_estimation,
        fit_validation,
        toolbox: None,
        res,
        ev,
        vv,
        seconds,
    };
    finish(args, ctx, ds, &fitted, measured)
}

/// What a fit path measured, for the report.
struct Measured {
    /// the records of `compare.svg` (filled with `--plot` only)
    compare: Vec<CompareRecord>,
    /// name of their FIT in the legend
    fit_label: &'static str,
    /// what the model's output in `compare.svg` is
    compared: &'static str,
    /// `compare.svg` draws the output's rate (the velocity FIT's signals)
    compare_rate: bool,
    /// the estimation segments and the FIT on each
    segments: Vec<SegmentJson>,
    /// name of the validation record
    val_name: Option<String>,
    /// sample interval of the compared records [s]
    ts: f64,
    /// samples of the estimation record
    samples: usize,
    /// which FIT the figures are
    fit_name: &'static str,
    /// its short name ([`FitReport::fit_metric`])
    fit_metric: &'static str,
    /// FIT on the estimation data [%]
    fit_estimation: f64,
    /// FIT on the validation data [%]
    fit_validation: Option<f64>,
    /// the toolbox FIT on estimation and validation data when it is not the headline [%]
    toolbox: Option<(f64, Option<f64>)>,
    /// the fitted model's resonances
    res: Resonances,
    /// residual tests on the estimation data
    ev: Validation,
    /// residual tests on the validation data
    vv: Option<Validation>,
    /// wall time of the fit [s]
    seconds: f64,
}

/// The one end of both paths of `run`: saves the model (the periodic FIT named in the
/// file when it is the one reported), writes the Bode plot, prints the report.
fn finish(
    args: &FitArgs,
    ctx: &mut Context<'_>,
    ds: &Dataset,
    fitted: &Fitted,
    mut m: Measured,
) -> CmdResult {
    let mut files = Vec::new();
    if let Some(path) = &args.save {
        let mut saved = fitted.to_saved(args.prep.prep(), &ds.name, m.fit_estimation);
        if m.fit_name == PERIODIC_FIT_NAME {
            saved.fit_name = Some(PERIODIC_FIT_NAME.to_string());
        }
        save_model(path, &saved, args.force)?;
        files.push(path.display().to_string());
    }
    if let Some(dir) = &args.plot {
        let signals = Signals::new(args.linear_axis, fitted.output, args.units.as_ref());
        let p = write_bode(
            dir,
            "bode.svg",
            ds,
            args.settle_periods,
            &[fitted],
            &frf_label(&signals),
            args.force,
        )?;
        files.push(p.display().to_string());
        let mut tests = vec![("estimation", &m.ev)];
        if let Some(v) = &m.vv {
            tests.push(("validation", v));
        }
        let views = Views {
            fitted,
            fit_label: m.fit_label,
            compared: m.compared,
            records: std::mem::take(&mut m.compare),
            compare_rate: m.compare_rate,
            tests,
            signals,
            record_s: ds.data.len() as f64 * ds.data.ts,
            file: &ds.name,
        };
        for p in write_views(dir, &views, args.force)? {
            files.push(p.display().to_string());
        }
    }
    let report = FitReport {
        model: fitted.spec.name(),
        method: fitted.method.clone(),
        file: ds.name.clone(),
        validation_file: m.val_name,
        ts: m.ts,
        samples: m.samples,
        segments: m.segments,
        parameters: {
            let mut p = param_map(&fitted.params);
            if args.linear_axis {
                for v in p.values_mut() {
                    v.unit = linear_unit(&v.unit).into();
                }
            }
            p
        },
        fit_name: m.fit_name.into(),
        fit_metric: m.fit_metric,
        fit_estimation: m.fit_estimation,
        fit_validation: m.fit_validation,
        fit_toolbox_estimation: m.toolbox.map(|t| t.0),
        fit_toolbox_validation: m.toolbox.and_then(|t| t.1),
        resonances_hz: m.res.resonances.iter().map(|r| r.freq_hz).collect(),
        antiresonances_hz: m.res.anti_resonances.iter().map(|r| r.freq_hz).collect(),
        residual_tests: ResidualTests {
            estimation: m.ev,
            validation: m.vv,
        },
        seconds: m.seconds,
        files,
        warnings: fitted.warnings.clone(),
    };
    ctx.fitted = Some(fitted.clone());
    emit(ctx, &report, args.strict)
}

/// A record of `compare.svg` under the velocity FIT `fit`: the signals it compares
/// ([`Fitted::velocity_fit_signals`]).
pub(crate) fn velocity_record(
    fitted: &Fitted,
    data: &FitData,
    title: String,
    fit: f64,
) -> Result<CompareRecord, String> {
    let (y, y_hat) = fitted
        .velocity_fit_signals(data)
        .map_err(|e| format!("{title}: {e}"))?;
    Ok(CompareRecord {
        title,
        ts: fitted.ts,
        y,
        y_hat,
        fit,
    })
}

/// A record of `compare.svg`: `data`'s prepared output and `fitted`'s simulation on it
/// ([`Fitted::simulate_on`], the one the toolbox FIT `fit` is computed from).
/// The records of compare.svg: the estimation record `(data, title, FIT)`, then the
/// validation record when there is one.
fn compare_records(
    fitted: &Fitted,
    (data, title, fit): (&FitData, String, f64),
    val: Option<&FitData>,
    val_name: &Option<String>,
    vv: &Option<Validation>,
) -> Result<Vec<CompareRecord>, String> {
    let mut out = vec![simulated_record(fitted, data, title, fit)?];
    if let (Some(v), Some(n), Some(vv)) = (val, val_name, vv) {
        out.push(simulated_record(
            fitted,
            v,
            format!("validation: {n}"),
            vv.fit,
        )?);
    }
    Ok(out)
}

fn simulated_record(
    fitted: &Fitted,
    data: &FitData,
    title: String,
    fit: f64,
) -> Result<CompareRecord, String> {
    let y_hat = fitted
        .simulate_on(data)
        .map_err(|e| format!("{title}: {e}"))?;
    Ok(CompareRecord {
        title,
        ts: data.prepared.ts,
        y: data.prepared.y.clone(),
        y_hat,
        fit,
    })
}

/// The FIT figures of a time-domain fit ([`time_domain_figures`]).
struct Figures {
    name: &'static str,
    metric: &'static str,
    estimation: f64,
    validation: Option<f64>,
    /// each estimation record's, when not the toolbox FIT's
    each: Option<Vec<f64>>,
    /// the toolbox FIT on estimation and validation data, when it is not the headline
    toolbox: Option<(f64, Option<f64>)>,
}

/// The FIT a time-domain fit reports on `est` and `val`: the toolbox FIT (`toolbox`: its
/// residual tests there), or for a model fitted on the motor velocity
/// ([`FitMetric::Velocity`]) the velocity FIT, the toolbox FIT beside it.
fn time_domain_figures(
    fitted: &Fitted,
    est: &[FitData],
    val: Option<&FitData>,
    toolbox: (&Validation, Option<&Validation>),
) -> Result<Figures, jointid::ident::fit::FitError> {
    let (ev, vv) = (toolbox.0.fit, toolbox.1.map(|v| v.fit));
    if fitted.fit_metric != FitMetric::Velocity {
        return Ok(Figures {
            name: FIT_NAME,
            metric: "toolbox",
            estimation: ev,
            validation: vv,
            each: None,
            toolbox: None,
        });
    }
    let (estimation, each) = fitted.velocity_fit_segments(est)?;
    let validation = match val {
        Some(v) => Some(fitted.velocity_fit_segments(std::slice::from_ref(v))?.0),
        None => None,
    };
    Ok(Figures {
        name: VELOCITY_FIT_NAME,
        metric: "velocity",
        estimation,
        validation,
        each: Some(each),
        toolbox: Some((ev, vv)),
    })
}

/// `fitted` evaluated on the validation record, when there is one (errors name it).
fn on_validation(
    fitted: &Fitted,
    val: Option<&FitData>,
    name: Option<&str>,
    lags: usize,
) -> Result<Option<Validation>, String> {
    match (val, name) {
        (Some(v), Some(n)) => fitted
            .evaluate_on(v, lags)
            .map(Some)
            .map_err(|e| format!("{n}: {e}")),
        _ => Ok(None),
    }
}

/// Writes the model file `path` ([`jointid::data::output`]: an existing file only with
/// `force`, whole or not at all): JSON, or a MATLAB Level-5 file when the name ends in
/// `.mat` ([`jointid::ident::model_export::model_mat`]: the matrices, transfer functions,
/// parameters, FIT and a description; `validate` reads only the JSON).
///
/// # Errors
/// Serialisation and [`jointid::data::output::OutputError`]s naming the file.
pub(crate) fn save_model(
    path: &Path,
    saved: &jointid::ident::model_file::SavedModel,
    force: bool,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let is_mat = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"));
    let bytes = if is_mat {
        jointid::ident::model_export::model_mat(saved)
            .map_err(|e| format!("{}: {e}", path.display()))?
    } else {
        (serde_json::to_string_pretty(saved)? + "\n").into_bytes()
    };
    jointid::data::output::write_file(path, force, |w| w.write_all(&bytes))?;
    Ok(())
}

/// Writes `name` into `dir`: Bode plot of `models` over the FRF of `ds` (its signals and
/// units `io`, [`frf_label`])
/// (when `ds` is periodic) with ±2σ, up to 0.45 / Ts of the coarsest model;
/// an existing file only with `force`.
///
/// # Errors
/// Directory, plot and write errors.
pub fn write_bode(
    dir: &Path,
    name: &str,
    ds: &Dataset,
    settle_periods: usize,
    models: &[&Fitted],
    io: &(String, String),
    force: bool,
) -> Result<PathBuf, Box<dyn std::error::Error + Send + Sync>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let fmax = models
        .iter()
        .map(|m| 0.45 / m.ts)
        .fold(0.45 / ds.data.ts, f64::min);
    let band = analyze_dataset(ds, settle_periods).ok().map(|a| {
        let b = FrfBand::from(&a.frf);
        let keep: Vec<usize> = (0..b.freq_hz.len())
            .filter(|&i| b.freq_hz[i] > 0.0 && b.freq_hz[i] <= fmax)
            .collect();
        FrfBand {
            freq_hz: keep.iter().map(|&i| b.freq_hz[i]).collect(),
            g: keep.iter().map(|&i| b.g[i]).collect(),
            sigma: keep.iter().map(|&i| b.sigma[i]).collect(),
        }
    });
    let fmin = band
        .as_ref()
        .and_then(|b| b.freq_hz.first().copied())
        .unwrap_or(0.1);
    let grid = log_grid(fmin, fmax, 400);
    let curves: Vec<BodeCurve> = models
        .iter()
        .map(|m| BodeCurve {
            name: m.spec.name(),
            freq_hz: grid.clone(),
            response: m.freq_response(&grid),
        })
        .collect();
    let path = dir.join(name);
    let title = format!(
        "models over the FRF {}: {}",
        io.0,
        super::views::short_name(&ds.name)
    );
    write_svg(
        &path,
        &bode_svg_in(&title, Some(&io.1), band.as_ref(), &curves)?,
        force,
    )?;
    Ok(path)
}

pub(crate) fn print_report(out: &mut dyn Write, r: &FitReport) -> std::io::Result<()> {
    writeln!(out, "jointid fit: {} on {}", r.model, r.file)?;
    writeln!(out, "  method: {}", r.method)?;
    writeln!(
        out,
        "  {} samples, Ts = {} s, fitted in {:.2} s",
        r.samples,
        jointid::data::fmt_sig(r.ts, 4),
        r.seconds
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
                "  {:<8} {:>14.6e} {:>12.3e} {:>8.2}  {}",
                name,
                p.value,
                p.std,
                100.0 * p.std / p.value.abs().max(f64::MIN_POSITIVE),
                p.unit
            )?;
        }
    }
    writeln!(out, "  {}:", r.fit_name)?;
    writeln!(
        out,
        "    estimation: {:.2}{}",
        r.fit_estimation,
        if r.segments.len() > 1 {
            " (pooled over the segments)"
        } else {
            ""
        }
    )?;
    if r.segments.len() > 1 {
        for sg in &r.segments {
            sg.write_line(out, "      ")?;
        }
    }
    if let Some(v) = r.fit_validation {
        writeln!(out, "    validation: {v:.2}")?;
    }
    if let Some(e) = r.fit_toolbox_estimation {
        writeln!(
            out,
            "  {FIT_NAME} of the simulated output (the drift of the rigid-body integrator \
             dominates it):"
        )?;
        writeln!(out, "    estimation: {e:.2}")?;
        if let Some(v) = r.fit_toolbox_validation {
            writeln!(out, "    validation: {v:.2}")?;
        }
    }
    let hz = |v: &[f64]| {
        if v.is_empty() {
            "none".to_string()
        } else {
            v.iter()
                .map(|f| format!("{f:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
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

pub(crate) fn print_tests(out: &mut dyn Write, label: &str, v: &Validation) -> std::io::Result<()> {
    for t in [&v.whiteness, &v.independence] {
        print_test(out, label, t)?;
    }
    Ok(())
}

fn print_test(out: &mut dyn Write, label: &str, t: &CorrelationTest) -> std::io::Result<()> {
    writeln!(
        out,
        "    {label:<10} {:<40} {}: max |r| {:.3} vs bound {:.3} ({} of {} {} outside, {} {} allowed), χ² {:.1} {} {:.1}",
        t.name,
        verdict(t),
        t.max_abs,
        t.bound,
        t.outside,
        t.lags.len(),
        t.unit,
        if t.outside <= t.allowed { "≤" } else { ">" },
        t.allowed,
        t.statistic,
        if t.statistic <= t.critical { "≤" } else { ">" },
        t.critical
    )
}

/// `pass`, `FAIL`, or `FAIL (N residual samples are NaN or infinite)`: the figures
/// printed beside it (lags outside against those allowed, χ² against its 99 % point)
/// say which criterion failed.
pub(crate) fn verdict(t: &CorrelationTest) -> String {
    match (t.pass, t.non_finite) {
        (true, _) => "pass".into(),
        (false, 0) => "FAIL".into(),
        (false, _) => format!("FAIL ({})", t.failure().unwrap_or_default()),
    }
}
