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

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use super::args::{check_columns, one_of, parse_lags, screen_for_fit, FitDataArgs, PrepArgs};
use super::print::{pieces_phrase, print_notes, share, share_warning};
use super::views::{Signals, VIEW_FILES};
use super::{check_plot_files, fit_report, CmdResult, Context, Outcome};
use jointid::data::input::path_text;
use jointid::data::output::{check_distinct, check_output};
use jointid::data::segment::whole_periods;
use jointid::data::Selected;
use jointid::ident::fit::{
    self as library, Domain, FitOptions, FitRecords, FitRequest, FitRunError, FittedModel,
    NlInputs, RequestError,
};
use jointid::ident::grey_box::{Output, DEFAULT_GEAR_RATIO};
use jointid::ident::model_file::SavedModel;
use jointid::ident::nonlinear::NlRunError;
use jointid::ident::sml;
use jointid::ident::subspace::Method;
use jointid::ident::validate::DEFAULT_LAGS;
use jointid::model::effects::parse_given;
use jointid::model::spec::{
    Family, FamilyParseError, ModelSpec, SpecError, Structure, NONLINEAR_TWO_MASS,
};

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
    /// model: black-box:ORDER, rigid, two-mass, three-mass, four-mass, grounded, or
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
    /// nonlinear fit: start from this model file (written by `fit --save` with effects;
    /// `-` for standard input) instead of the automatic start
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
        Ok(d) if (0.0..=sml::MAX_DRIVE_SAMPLES).contains(&d) => Ok(d),
        _ => Err(format!(
            "`{s}` is not a delay in samples, 0 ≤ D ≤ {}",
            sml::MAX_DRIVE_SAMPLES
        )),
    }
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
        .map_err(|e| match e {
            FamilyParseError::Unknown(name) => format!(
                "unknown model `{name}` (known: black-box:ORDER, rigid, two-mass, three-mass, \
                 four-mass, {NONLINEAR_TWO_MASS})"
            ),
            e => e.to_string(),
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

impl From<DomainArg> for Domain {
    fn from(d: DomainArg) -> Self {
        match d {
            DomainArg::Auto => Domain::Auto,
            DomainArg::Frequency => Domain::Frequency,
            DomainArg::Time => Domain::Time,
        }
    }
}

impl FitArgs {
    /// The request of these arguments for `spec` ([`FitArgs::spec`]); `--start` is read
    /// later ([`read_start`]).
    ///
    /// # Errors
    /// A `--fix` item that is not `NAME=VALUE` with a finite value.
    fn request(&self, spec: ModelSpec) -> Result<FitRequest, String> {
        // the keys given a value in each `--effect` spec (seed 001's two, then the user's;
        // one effect per spec, `none` gives none)
        let effects = spec.effects.as_ref().map_or(0, Vec::len);
        let specs = ModelSpec::effect_specs(self.model.nonlinear_two_mass, &self.effects);
        let given = specs
            .iter()
            .take(effects)
            .map(|s| parse_given(s).map(|(_, given)| given))
            .collect::<Result<_, _>>()
            .map_err(|e| e.to_string())?;
        let options = FitOptions {
            spec,
            method: match self.method {
                MethodArg::Pbsid => Method::Pbsid,
                MethodArg::Moesp => Method::Moesp,
            },
            output: self.output_kind.into(),
            r: self.gear_ratio,
            refine: !self.no_refine,
            feedthrough: self.feedthrough,
        };
        Ok(FitRequest {
            prep: self.prep.prep(),
            domain: self.domain.into(),
            settle_periods: self.settle_periods,
            lags: self.lags,
            estimation_fraction: self.estimation_fraction,
            nonlinear: NlInputs {
                fixed: parse_fixes(&self.fix)?,
                given,
                start: None,
            },
            figures: self.plot.is_some(),
            ..FitRequest::new(options)
        })
    }

    /// The library's error in the words of these flags (`--fix`, `--start PATH`).
    fn flagged(&self, e: FitRunError) -> Box<dyn std::error::Error + Send + Sync> {
        let nl = match &e {
            FitRunError::Request(RequestError::Nonlinear(n)) => n,
            FitRunError::Nonlinear(n) => &**n,
            _ => return e.into(),
        };
        match (nl, &self.start) {
            (NlRunError::UnknownParameter { .. }, _) => format!("--fix {e}").into(),
            (NlRunError::StartMismatch { .. }, Some(p)) => {
                format!("--start {}: {e}", p.display()).into()
            }
            _ => e.into(),
        }
    }
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
fn read_start(path: &Path) -> Result<jointid::ident::nonlinear::NlFit, String> {
    let name = jointid::data::input::input_name(path);
    let text = jointid::data::input::read_input_text(path)
        .map_err(|e| format!("--start {name}: {}", jointid::data::output::io_msg(&e)))?;
    let saved: SavedModel = serde_json::from_str(&text)
        .map_err(|e| format!("--start {name}: not a jointid model file: {e}"))?;
    saved
        .to_nonlinear()
        .map_err(|e| format!("--start {name}: {e}"))
}

/// Runs `jointid fit`: the request from the flags, the records, one call of
/// [`jointid::ident::fit::run`], then the model file, the plots and the report.
///
/// # Errors
/// Loading, fitting, plotting and output errors.
pub fn run(args: &FitArgs, ctx: &mut Context<'_>) -> CmdResult {
    // what can be checked before the work is checked first: the outputs, the request, the
    // columns (the library checks the validation record's rate and the lags before it fits)
    if let Some(path) = &args.save {
        check_output(path, args.force)?;
    }
    let spec = args.spec()?;
    let nonlinear = spec.nonlinear();
    if let Some(dir) = &args.plot {
        let mut names = vec![fit_report::PLOT_FILE];
        if !nonlinear {
            names = vec!["bode.svg"];
            names.extend(VIEW_FILES);
        }
        check_plot_files(dir, &names, args.force)?;
        if let Some(path) = &args.save {
            // the model file is no figure of the plot directory
            let mut outputs = vec![("--save".to_string(), path.clone())];
            outputs.extend(names.iter().map(|n| (format!("--plot's {n}"), dir.join(n))));
            check_distinct(&outputs)?;
        }
    }
    let mut req = args.request(spec)?;
    req.check().map_err(|e| args.flagged(e.into()))?;
    if nonlinear && args.linear_axis {
        return Err("--linear-axis is not available with effects".into());
    }
    if let Some(path) = &args.start {
        req.nonlinear.start = Some(read_start(path)?);
    }
    check_columns(&args.data.data_args(&args.data.path))?;
    // the estimation and validation files read side by side
    let loaders = ctx.loaders;
    let (sel, val) = std::thread::scope(|s| {
        let val = args
            .validation
            .as_ref()
            .map(|p| s.spawn(move || args.data.data_args(p).select(loaders)));
        let sel = args.data.data_args(&args.data.path).select(loaders);
        (
            sel,
            val.map(|h| h.join().expect("reading a file does not panic")),
        )
    });
    let sel = sel?;
    let map = args.data.data_args(&args.data.path).column_map();
    let mut screened: Vec<String> = screen_for_fit(&sel, &map, "fit")?.into_iter().collect();
    check_whole_periods(&sel)?;
    let val = match val {
        Some(v) => {
            let v = v?;
            screened.extend(screen_for_fit(&v, &map, "fit")?);
            // a validation FIT on a scrap of a damaged capture says as little as a fit
            screened.extend(share_warning(&v, "validation"));
            Some(one_of(v)?)
        }
        None => None,
    };
    let records = FitRecords {
        estimation: &sel.datasets,
        numbers: &sel.segments,
        validation: val.as_ref(),
    };
    super::progress::step(format!(
        "fitting {} on {} samples",
        req.options.spec.name(),
        sel.datasets.iter().map(|d| d.data.len()).sum::<usize>()
    ));
    let mut out = library::run(&req, records).map_err(|e| args.flagged(e))?;
    super::progress::finish();
    out.warnings.extend(share_warning(&sel, "fit"));
    out.warnings.extend(screened);
    print_notes(&out.notes);
    let mut files = Vec::new();
    if let Some(path) = &args.save {
        save_model(path, &out.to_saved(req.prep), args.force)?;
        files.push(path_text(path));
    }
    match &out.model {
        FittedModel::Nonlinear(nl) => {
            if let (Some(dir), Some(fig)) = (&args.plot, &nl.velocity) {
                let p = fit_report::write_velocity_plot(dir, fig, args.force)?;
                files.push(path_text(&p));
            }
            let (start, saved) = (args.start.as_deref(), args.save.as_deref());
            fit_report::print_nonlinear(ctx.out, ctx.json, &out, nl, start, saved, files)?;
        }
        FittedModel::Linear(l) => {
            if let Some(dir) = &args.plot {
                let signals = Signals::new(args.linear_axis, l.fitted.output, args.units.as_ref());
                files.extend(fit_report::plot_linear(dir, &out, l, signals, args.force)?);
            }
            ctx.fitted = Some(l.fitted.clone());
            fit_report::print_linear(ctx.out, ctx.json, &out, l, args.linear_axis, files)?;
        }
    }
    if args.strict && !out.warnings.is_empty() {
        return Ok(Outcome::CheckFailed);
    }
    Ok(Outcome::Ok)
}

/// Fewest whole excitation periods a fit takes from data whose excitation is stated (a
/// periodic record): one period holds each excited line once; a second is what tells the
/// joint's response from noise and transient. Less is a scrap (a segment between gaps of
/// a damaged capture) whose fit looks confident and is not.
pub const MIN_FIT_PERIODS: usize = 2;

/// Refuses a selection of periodic data (its excitation stated) that holds fewer than
/// [`MIN_FIT_PERIODS`] whole periods, naming the file, the segments, their periods and
/// their share of the file.
fn check_whole_periods(sel: &Selected) -> Result<(), String> {
    let Some(periods) = sel
        .datasets
        .iter()
        .map(whole_periods)
        .sum::<Option<usize>>()
    else {
        return Ok(());
    };
    if periods >= MIN_FIT_PERIODS {
        return Ok(());
    }
    let d = &sel.datasets[0];
    let n = d.excitation.map_or(0, |c| c.period_samples);
    let (used, pct) = share(sel);
    let (what, hint) = if sel.record_pieces > 1 {
        (
            pieces_phrase(sel),
            format!(
                "; the file has {} gap-free segments (`jointid info` lists them)",
                sel.record_pieces
            ),
        )
    } else {
        (
            "the data selected".to_string(),
            "; give a longer record or a wider --from/--to".to_string(),
        )
    };
    Err(format!(
        "{}: {what} holds {periods} whole excitation period{} of {n} samples ({used} samples: \
         {pct}); a fit needs at least {MIN_FIT_PERIODS}{hint}",
        d.name,
        if periods == 1 { "" } else { "s" },
    ))
}

/// Writes the model file `path` ([`jointid::data::output`]: an existing file only with
/// `force`, whole or not at all): JSON, or a MATLAB Level-5 file when the name ends in
/// `.mat` ([`jointid::ident::model_export::model_mat`]: the matrices, transfer functions,
/// parameters, FIT and a description; `validate` reads only the JSON).
///
/// # Errors
/// Serialisation and [`jointid::data::output::OutputError`]s naming the file.
fn save_model(
    path: &Path,
    saved: &SavedModel,
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
