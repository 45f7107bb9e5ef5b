//! `jointid simulate`: runs the closed-loop joint simulator ([`jointid::sim`]) on the
//! firmware's excitation and writes the run as a board would have delivered it.
//!
//! ```text
//! jointid simulate --model rigid|two-mass|three-mass|four-mass|nonlinear-two-mass
//!     [--param NAME=VALUE]... [--effect SPEC]... [--excitation odd-multisine|random-odd|noise]
//!     [--rms RAD] [--periods N] [--seed N] --out FILE.jcap|FILE.csv [--params-out FILE.json]
//!     [--force]
//! ```
//!
//! - `--out RUN.jcap` puts the run through the real wire encoder
//!   (`jointid_core::wire`: session header with the excitation config and the scale,
//!   delta-coded sample batches from `BatchBuilder` with the reference CRC, a `Status`
//!   every [`WireOptions::status_every`] batches, `End`; [`jointid::sim::board`]) into a
//!   `.jcap` written by [`jointid::capture::jcap::write_stream_with`], so `jointid info`,
//!   `export`, `analyze` and `fit` read it exactly like a board capture. The wire carries integer counts: `u` and `θm` are rounded to the
//!   scale of [`WireOptions::for_sim`] (at most half a count from the simulator's value),
//!   the reference is regenerated from the header bit-exactly.
//! - `--out RUN.csv` writes the capture CSV (../shared/DESIGN.md §5) with the simulator's values
//!   unquantised, the excitation config and `sim_*` keys in its comments.
//! - Both outputs follow the one rule of every output file ([`jointid::data::output`]): an
//!   existing file is replaced only with `--force`, checked before the simulation; each
//!   appears whole or not at all.
//! - The run's size is known before it starts (the ramps and `--periods` whole periods,
//!   [`OutFormat::bytes_per_sample`] each): a run that would not fit in the free space of
//!   `--out`'s file system is refused before the simulation
//!   ([`jointid::data::output::check_room`]), not after filling it. A device or pipe is a
//!   stream and is not checked.
//! - A device or pipe (`/dev/stdout`, a named pipe, [`jointid::data::output::is_stream`])
//!   is written in place, as the capture CSV unless its name ends in `.jcap`; what it got
//!   cannot be taken back, so the run is simulated once before it is written (twice the
//!   time, constant memory) and a run that stops writes nothing there either. With
//!   `--out /dev/stdout` the report (text or `--json`) goes to standard error.
//! - The run is streamed: each sample is simulated ([`jointid::sim::Simulation`]), encoded
//!   ([`jointid::sim::board::stream_session`]) or formatted ([`TableWriter`]) and written
//!   as it comes, so memory does not grow with `--periods`; a simulation that stops (its
//!   first non-finite sample, named with the effects) leaves no file.
//!
//! `--param NAME=VALUE` overrides one physical parameter of the chosen model, named as in
//! seed 000 Table 1 (`J_m, J_a1, J_a2, J_p, k_g, k_a, k_p, d_g, d_a, d_p, f_m, r`) plus
//! seed 001's `k3`, `F_c` for the nonlinear two-mass (see [`jointid::model::params`]); only
//! the names the model uses are accepted ([`jointid::model::params::model_params`],
//! [`jointid::model::params::seed_001_params`]), each value within the parameter's
//! physical range ([`jointid::model::params::param_range`]: `J_m` 1e-7 … 1e4 kg·m², ...).
//!
//! `--model` and `--effect` resolve into the one model description, a
//! [`jointid::model::spec::ModelSpec`], by [`jointid::model::params::sim_spec`] over the
//! effect list `fit` resolves ([`jointid::model::spec::ModelSpec::effect_specs`]):
//! `nonlinear-two-mass` is the two-mass with seed 001's `nonlinear_stiffness` (`k3`) and
//! pure `coulomb_friction` (`F_c`) attached, as `fit --model nonlinear-two-mass` fits it.
// Units in brackets (`[s]`, `[rad]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::path::{Path, PathBuf};

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Args, ValueEnum};
use jointid_core::excitation::{ExcitationError, SafetyLimits};
use jointid_core::wire::Scale;
use serde::Serialize;

use super::{print_json, CmdResult, Context, Outcome};
use jointid::capture::jcap::{write_stream_with, JcapError};
use jointid::data::input::{input_name, path_text, read_input_text};
use jointid::data::output::{
    check_distinct, check_output, check_room, io_msg, is_stream, names_standard_output, write_file,
    OutputError,
};
use jointid::data::{capture_csv_comments, ExcitationConfig, SignalKind, TableWriter};
use jointid::ident::model_file::SavedModel;
use jointid::ident::nonlinear::sim_plant;
use jointid::model::params::{
    model_params, param_range, seed_001_params, sim_spec, ParamField, ParamRange,
};
use jointid::model::spec::{Structure, NONLINEAR_TWO_MASS};
use jointid::sim::board::{stream_session, BoardStreamError, StreamError, WireOptions};
use jointid::sim::{
    parse_effects, stream_excitation, Integrator, JointParams, Mechanism, Plant, RunSummary,
    Sample, SensorConfig, SimConfig, MAX_SUBSTEPS,
};

/// `--model`: a structure, or seed 001's nonlinear two-mass (the two-mass with
/// `nonlinear_stiffness` and `coulomb_friction` attached, [`sim_spec`]), as `fit --model`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimModel {
    /// the mechanical structure (the two-mass for `nonlinear-two-mass`)
    pub structure: Structure,
    /// `nonlinear-two-mass` was asked for
    pub nonlinear_two_mass: bool,
}

impl SimModel {
    /// Every `--model` value, in the order of the help.
    pub const ALL: [SimModel; 6] = [
        SimModel::of(Structure::Rigid),
        SimModel::of(Structure::TwoMass),
        SimModel::of(Structure::ThreeMass),
        SimModel::of(Structure::FourMass),
        SimModel {
            structure: Structure::TwoMass,
            nonlinear_two_mass: true,
        },
        SimModel::of(Structure::Grounded),
    ];

    /// The plain structure `s`.
    pub const fn of(s: Structure) -> SimModel {
        SimModel {
            structure: s,
            nonlinear_two_mass: false,
        }
    }

    /// Name on the command line (`three-mass`, `nonlinear-two-mass`).
    pub fn label(self) -> &'static str {
        if self.nonlinear_two_mass {
            NONLINEAR_TWO_MASS
        } else {
            self.structure.label()
        }
    }

    /// The JSON spelling (`three_mass`), an alias on the command line.
    fn name(self) -> &'static str {
        if self.nonlinear_two_mass {
            "nonlinear_two_mass"
        } else {
            self.structure.name()
        }
    }

    /// The help of the value.
    fn describe(self) -> &'static str {
        if self.nonlinear_two_mass {
            "seed 001: two-mass with cubic spring and Coulomb friction"
        } else {
            self.structure.describe()
        }
    }

    /// The parameters `--param` may set: the structure's, and seed 001's `k3`, `F_c` for
    /// the nonlinear two-mass.
    pub fn params(self) -> Vec<(&'static str, ParamField)> {
        let mut v = model_params(self.structure);
        if self.nonlinear_two_mass {
            v.extend(seed_001_params());
        }
        v
    }
}

/// The `--model` values: every model by its label (`two-mass`), its JSON name
/// (`two_mass`) as alias, with [`SimModel::describe`] as help.
fn plant_parser() -> impl TypedValueParser<Value = SimModel> {
    PossibleValuesParser::new(SimModel::ALL.map(|k| {
        let v = PossibleValue::new(k.label()).help(k.describe());
        if k.name() == k.label() {
            v
        } else {
            v.alias(k.name())
        }
    }))
    .map(|s| {
        SimModel::ALL
            .into_iter()
            .find(|k| k.label() == s || k.name() == s)
            .expect("a possible value")
    })
}

/// Excitation signal kind on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExcitationArg {
    /// special odd multisine (seed 000 eq. (4)), for the linearity check
    #[value(alias = "special-odd")]
    OddMultisine,
    /// random-phase full odd multisine
    RandomOdd,
    /// band-limited noise (validation data)
    Noise,
}

impl ExcitationArg {
    /// The generator's signal kind.
    pub fn kind(self) -> SignalKind {
        match self {
            ExcitationArg::OddMultisine => SignalKind::SpecialOddMultisine,
            ExcitationArg::RandomOdd => SignalKind::RandomOddMultisine,
            ExcitationArg::Noise => SignalKind::BandLimitedNoise,
        }
    }
}

/// Arguments of `jointid simulate`.
#[derive(Debug, Clone, Args)]
pub struct SimulateArgs {
    /// plant model
    #[arg(long, visible_alias = "plant", value_parser = plant_parser(), value_name = "MODEL",
          default_value = "three-mass")]
    pub model: SimModel,
    /// override a physical parameter of the model, repeatable (`k_g=1.3e5`); names as in
    /// seed 000 Table 1 (J_m, J_a1, J_a2, J_p, k_g, k_a, k_p, d_g, d_a, d_p, f_m, r) and
    /// seed 001 (k3, F_c), those the model uses
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// the plant and effects of a model fitted with effects (`jointid fit --effect ...
    /// --save MODEL.json`, `-` for standard input) instead of --model; --param and --effect
    /// apply on top of it
    #[arg(long, value_name = "MODEL.json")]
    pub model_file: Option<PathBuf>,
    /// effect spec, repeatable: `name` or `name:key=value,...` (e.g. `backlash:width=2e-5`),
    /// or `none`; names: coulomb_friction, backlash, nonlinear_stiffness, extra_mode,
    /// time_delay, torque_ripple
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// excitation signal
    #[arg(long, visible_alias = "kind", value_enum, value_name = "KIND",
          default_value_t = ExcitationArg::OddMultisine)]
    pub excitation: ExcitationArg,
    /// RMS of the motor-angle reference [rad] (default: core's paper default, 0.02); > 0,
    /// and the excitation must keep within the board's safety limits (peak angle 0.5 rad,
    /// peak velocity 100 rad/s, `SafetyLimits::default_joint`) as on the board
    #[arg(long, value_name = "RAD", value_parser = parse_rms)]
    pub rms: Option<f32>,
    /// full-amplitude excitation periods (default: core's paper default, 4)
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub periods: Option<u32>,
    /// seed of the run: the simulator's noise and disturbance (default 1) and, unless
    /// --excitation-seed is given, the excitation's phases / noise (default: core's)
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// excitation seed (phases / noise), when it should differ from --seed
    #[arg(long, value_name = "N")]
    pub excitation_seed: Option<u64>,
    /// output: RUN.jcap (through the wire encoder, read like a board capture) or RUN.csv
    /// (capture CSV)
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// also write every parameter used (the whole simulator configuration) as JSON here
    #[arg(long, visible_alias = "params-json", value_name = "FILE.json")]
    pub params_out: Option<PathBuf>,
    /// replace --out and --params-out when they exist (without it they are refused before
    /// the simulation)
    #[arg(long)]
    pub force: bool,
    /// perfect sensors: no quantisation, no noise, no disturbance
    #[arg(long)]
    pub ideal_sensors: bool,
    /// velocity and torque feedforward in the robot's controller
    #[arg(long)]
    pub feedforward: bool,
    /// event-aware RK4 substeps per sample when the plant is nonlinear (used in the samples
    /// with contact or stick–slip events; the others take one exponential step); 1 to 1000
    #[arg(long, value_name = "M",
          value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SUBSTEPS)))]
    pub substeps: Option<u32>,
}

fn parse_rms(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not an RMS in rad > 0")),
    }
}

/// Errors of `jointid simulate` before or after the simulation itself.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimulateError {
    /// `--param` without `=`
    #[error("--param `{spec}`: expected NAME=VALUE (valid names for {model}: {valid})")]
    ParamSyntax {
        /// the argument as given
        spec: String,
        /// model name
        model: &'static str,
        /// the names the model accepts, comma separated
        valid: String,
    },
    /// `--param` naming a parameter the model does not have
    #[error("--param `{name}`: unknown parameter for {model} (valid: {valid})")]
    UnknownParam {
        /// the name given
        name: String,
        /// model name
        model: &'static str,
        /// the names the model accepts, comma separated
        valid: String,
    },
    /// `--param` with a value that is not a finite number
    #[error(
        "--param `{name}`: `{value}` is not a finite number (valid names for {model}: {valid})"
    )]
    BadValue {
        /// parameter name
        name: String,
        /// the value as given
        value: String,
        /// model name
        model: &'static str,
        /// the names the model accepts, comma separated
        valid: String,
    },
    /// `--param` with a value outside the parameter's physical range
    #[error("--param `{name}`: `{value}` is outside its physical range: {range}")]
    OutOfRange {
        /// parameter name
        name: String,
        /// the value as given
        value: String,
        /// its range and unit
        range: ParamRange,
    },
    /// `--out` with an extension other than `.jcap` or `.csv`, and no device or pipe
    #[error(
        "{path}: --out must end in .jcap or .csv (or be a device or a pipe, which takes the \
         capture CSV)"
    )]
    OutExtension {
        /// the path given
        path: PathBuf,
    },
    /// the excitation breaks the board's safety limits
    #[error("excitation (--rms {rms_rad} rad): {err}; the board refuses it (SafetyLimits::default_joint)")]
    Unsafe {
        /// the excitation's RMS [rad]
        rms_rad: f32,
        /// which limit, the value and the bound
        err: ExcitationError,
    },
    /// a message did not fit a wire frame (a bug of the encoder's limits)
    #[error(transparent)]
    Encode(#[from] BoardStreamError),
    /// the `.jcap` could not be written
    #[error(transparent)]
    Jcap(#[from] JcapError),
    /// a CSV or JSON output could not be written, or exists
    #[error(transparent)]
    Output(#[from] OutputError),
    /// the run would not fit where `--out` goes
    #[error("--periods {periods}: {samples} samples: {err}")]
    TooLarge {
        /// the whole periods asked for
        periods: u32,
        /// the run's samples (ramps included)
        samples: u64,
        /// [`OutputError::NoRoom`] with the figures
        err: OutputError,
    },
    /// the run is longer than a capture can number ([`MAX_SAMPLES`])
    #[error(
        "--periods {periods}: {samples} samples, more than the {MAX_SAMPLES} a run may hold: \
         a capture numbers its samples with the board's 32-bit counter (seq), {days} days at \
         {fs_hz} Hz"
    )]
    TooLong {
        /// the whole periods asked for
        periods: u32,
        /// the run's samples (ramps included)
        samples: u64,
        /// the sample rate [Hz]
        fs_hz: u32,
        /// [`MAX_SAMPLES`] in days at that rate, for people
        days: String,
    },
}

/// Most samples one run may hold: a capture numbers its samples with the board's 32-bit
/// counter (`seq` of the wire), 24.9 days at 2 kHz. The stated maximum of a run whose
/// size no free space bounds (a device or pipe: `--out /dev/null` ran 100,000,000
/// periods, hours of simulation, into nothing).
pub const MAX_SAMPLES: u64 = 1 << 32;

/// Applies `NAME=VALUE` overrides to the parameters of model `model`, each within its
/// physical range ([`param_range`]).
///
/// # Errors
/// [`SimulateError::ParamSyntax`], [`SimulateError::UnknownParam`] or
/// [`SimulateError::BadValue`], each naming the parameter and listing the valid names;
/// [`SimulateError::OutOfRange`] naming the parameter, the value and the range.
pub fn apply_params(
    model: SimModel,
    specs: &[String],
    params: &mut JointParams,
) -> Result<(), SimulateError> {
    let fields = model.params();
    let valid = || {
        fields
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", ")
    };
    for spec in specs {
        let Some((name, value)) = spec.split_once('=') else {
            return Err(SimulateError::ParamSyntax {
                spec: spec.clone(),
                model: model.label(),
                valid: valid(),
            });
        };
        let (name, value) = (name.trim(), value.trim());
        let Some((_, field)) = fields.iter().find(|(n, _)| *n == name) else {
            return Err(SimulateError::UnknownParam {
                name: name.to_string(),
                model: model.label(),
                valid: valid(),
            });
        };
        match value.parse::<f64>() {
            Ok(v) if v.is_finite() => {
                // every name `model.params()` gives has a range
                if let Some(range) = param_range(name).filter(|r| !r.contains(v)) {
                    return Err(SimulateError::OutOfRange {
                        name: name.to_string(),
                        value: value.to_string(),
                        range,
                    });
                }
                *field(params) = v;
            }
            _ => {
                return Err(SimulateError::BadValue {
                    name: name.to_string(),
                    value: value.to_string(),
                    model: model.label(),
                    valid: valid(),
                })
            }
        }
    }
    Ok(())
}

/// What `--out` writes, from its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutFormat {
    /// `.jcap`: the wire stream of a board
    Jcap,
    /// `.csv`: the capture CSV
    Csv,
}

impl OutFormat {
    /// Bytes one sample takes in the file, about (the header, comments and the `.jcap`'s
    /// status and end messages are spread over the samples). Measured on `simulate
    /// --periods 1, 2, 4` of the three-mass joint with the paper's excitation: the `.jcap`
    /// grows by 5.49–5.52 bytes a sample (a 16-sample delta-coded batch in its frame), the
    /// CSV by 72.2–72.5 (four numbers in shortest round-trip form).
    pub fn bytes_per_sample(self) -> f64 {
        match self {
            OutFormat::Jcap => 5.5,
            OutFormat::Csv => 72.0,
        }
    }
}

/// The format `path` asks for: its extension `.jcap` or `.csv` (any case), else the
/// capture CSV when it is a `stream` (a device, a pipe, `/dev/stdout`:
/// [`jointid::data::output::is_stream`]), the text a terminal shows and `jointid info -`
/// reads.
///
/// # Errors
/// [`SimulateError::OutExtension`] for anything else.
pub fn out_format(path: &Path, stream: bool) -> Result<OutFormat, SimulateError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
    {
        Some(e) if e == "jcap" => Ok(OutFormat::Jcap),
        Some(e) if e == "csv" => Ok(OutFormat::Csv),
        _ if stream => Ok(OutFormat::Csv),
        _ => Err(SimulateError::OutExtension {
            path: path.to_path_buf(),
        }),
    }
}

/// The simulator configuration and the excitation these arguments describe.
///
/// # Errors
/// Bad `--param` or `--effect` specs.
pub fn configure(
    args: &SimulateArgs,
) -> Result<(SimConfig, ExcitationConfig), Box<dyn std::error::Error + Send + Sync>> {
    let (plant, effects) = match &args.model_file {
        Some(path) => {
            let (mut plant, mut effects) = fitted_plant(path)?;
            apply_params(SimModel::of(plant.kind), &args.params, &mut plant.params)?;
            effects.extend(parse_effects(&args.effects)?);
            (plant, effects)
        }
        None => {
            let mut plant = Plant::new(args.model.structure);
            apply_params(args.model, &args.params, &mut plant.params)?;
            let spec = sim_spec(
                plant.kind,
                args.model.nonlinear_two_mass,
                &args.effects,
                &plant.params,
            )?;
            (plant, spec.effects.unwrap_or_default())
        }
    };
    let mut cfg = SimConfig {
        plant,
        effects,
        ..SimConfig::default()
    };
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    if args.ideal_sensors {
        cfg.sensors = SensorConfig::ideal();
    }
    cfg.controller.feedforward = args.feedforward;
    if let Some(m) = args.substeps {
        cfg.integration.substeps = m;
    }
    let mut exc = ExcitationConfig::paper_default();
    exc.kind = args.excitation.kind();
    if let Some(r) = args.rms {
        exc.rms_rad = r;
    }
    if let Some(p) = args.periods {
        exc.periods = p;
    }
    if let Some(s) = args.excitation_seed.or(args.seed) {
        exc.seed = s;
    }
    cfg.sample_rate_hz = f64::from(exc.fs_hz);
    // what the board checks before it drives the joint (firmware/app/src/app.rs)
    exc.validate(&SafetyLimits::default_joint())
        .map_err(|err| SimulateError::Unsafe {
            rms_rad: exc.rms_rad,
            err,
        })?;
    Ok((cfg, exc))
}

/// The simulator's plant and effects of a model file written by `fit --save` for a model
/// with effects ([`SavedModel::to_nonlinear`], [`sim_plant`]).
///
/// # Errors
/// The file cannot be read, is not a model file, or holds a linear model.
fn fitted_plant(
    path: &Path,
) -> Result<(Plant, Vec<jointid::model::effects::Effect>), Box<dyn std::error::Error + Send + Sync>>
{
    let name = input_name(path);
    let text = read_input_text(path).map_err(|e| format!("--model-file {name}: {}", io_msg(&e)))?;
    let saved: SavedModel = serde_json::from_str(&text)
        .map_err(|e| format!("--model-file {name}: not a jointid model file: {e}"))?;
    let fit = saved.to_nonlinear().map_err(|e| {
        format!(
            "--model-file {name}: {e} (a linear model file has no plant for the simulator; \
             use --model and --param)"
        )
    })?;
    Ok((sim_plant(&fit.model, &fit.plant), fit.model.effects.clone()))
}

/// The `sim_plant`, `sim_effects`, `sim_seed` meta of the run's capture CSV.
fn csv_meta(cfg: &SimConfig) -> std::collections::BTreeMap<String, String> {
    [
        ("sim_plant", cfg.plant.kind.name().to_string()),
        ("sim_effects", effects_text(cfg, ";")),
        ("sim_seed", cfg.seed.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

fn effects_text(cfg: &SimConfig, sep: &str) -> String {
    if cfg.effects.is_empty() {
        "none".to_string()
    } else {
        cfg.effects
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join(sep)
    }
}

#[derive(Serialize)]
struct Report<'a> {
    /// the file written (`--out`), as `capture --json`'s `out`
    #[serde(rename = "out")]
    file: String,
    format: OutFormat,
    model: &'static str,
    effects: Vec<String>,
    samples: usize,
    duration_s: f64,
    params_out: Option<String>,
    /// wire scale (`.jcap` only)
    scale: Option<Scale>,
    stream_bytes: Option<u64>,
    integrator: Integrator,
    saturated_samples: u64,
    u_rms: f64,
    theta_m_rms: f64,
    resonances_hz: Vec<f64>,
    #[serde(rename = "antiresonances_hz")]
    anti_resonances_hz: Vec<f64>,
    config: &'a SimConfig,
}

/// Running mean and spread of a signal (Welford), for its RMS about the mean without
/// keeping it.
#[derive(Clone, Copy, Debug, Default)]
struct Moments {
    n: f64,
    mean: f64,
    m2: f64,
}

impl Moments {
    fn push(&mut self, v: f64) {
        self.n += 1.0;
        let d = v - self.mean;
        self.mean += d / self.n;
        self.m2 += d * (v - self.mean);
    }

    /// RMS about the mean (0 without samples) [the signal's unit]
    fn rms(&self) -> f64 {
        (self.m2 / self.n.max(1.0)).sqrt()
    }
}

/// Streams the run of `cfg` on `exc` into `path` as `.jcap` or capture CSV, each sample
/// written as it is simulated (constant memory), `each` seeing every sample. A stop of the
/// simulation or of the wire is returned as its own error, and leaves no file.
///
/// # Errors
/// The simulation's ([`StreamError`]), the output's.
fn write_run(
    args: &SimulateArgs,
    format: OutFormat,
    cfg: &SimConfig,
    exc: &ExcitationConfig,
    mut each: impl FnMut(&Sample<'_>),
) -> Result<(RunSummary, Option<u64>), Box<dyn std::error::Error + Send + Sync>> {
    // why the writer stopped when it was the simulation, not the file
    let mut stopped: Option<StreamError> = None;
    let mut summary = None;
    let mut keep = |r: Result<RunSummary, StreamError>, stopped: &mut Option<StreamError>| match r {
        Ok(s) => {
            summary = Some(s);
            Ok(())
        }
        Err(StreamError::Io(e)) => Err(e),
        Err(e) => {
            *stopped = Some(e);
            Err(std::io::Error::other("the simulation stopped"))
        }
    };
    let written = match format {
        OutFormat::Jcap => {
            let opts = WireOptions::for_sim(cfg);
            let written = write_stream_with(&args.out, args.force, |w| {
                let r = stream_session(cfg, exc, &opts, w, &mut each);
                let bytes = r.as_ref().map_or(0, |(_, n)| *n);
                keep(r.map(|(s, _)| s), &mut stopped).map(|()| bytes)
            });
            match (stopped, written) {
                (Some(e), _) => return Err(e.into()),
                (None, w) => Some(w.map_err(SimulateError::from)?),
            }
        }
        OutFormat::Csv => {
            let ts = 1.0 / cfg.sample_rate_hz;
            let comments = capture_csv_comments(Some(exc), ts, &csv_meta(cfg));
            let written = write_file(&args.out, args.force, |w| {
                let mut table = TableWriter::new(w, &comments)?;
                let r = stream_excitation(cfg, exc, |s: &Sample<'_>| {
                    each(s);
                    table
                        .row([s.t_s, s.theta_ref, s.u, s.theta_m])
                        .map_err(StreamError::Io)
                });
                keep(r, &mut stopped)?;
                table.finish()
            });
            match (stopped, written) {
                (Some(e), _) => return Err(e.into()),
                (None, w) => w.map_err(SimulateError::from)?,
            }
            None
        }
    };
    Ok((summary.expect("a run that was written"), written))
}

/// Simulates the run of `cfg` on `exc` as [`write_run`] does, writing nothing: its first
/// non-finite sample or a sample the wire cannot carry (`.jcap`) is the error.
///
/// # Errors
/// The simulation's ([`StreamError`]).
fn dry_run(
    format: OutFormat,
    cfg: &SimConfig,
    exc: &ExcitationConfig,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    match format {
        OutFormat::Jcap => {
            let opts = WireOptions::for_sim(cfg);
            stream_session(cfg, exc, &opts, &mut std::io::sink(), |_| {})?;
        }
        OutFormat::Csv => {
            stream_excitation(cfg, exc, |_| Ok::<(), StreamError>(()))?;
        }
    }
    Ok(())
}

/// Runs `jointid simulate`.
///
/// # Errors
/// Bad `--param`, `--effect` or `--out`, invalid configuration or excitation, write errors.
pub fn run(args: &SimulateArgs, ctx: &mut Context<'_>) -> CmdResult {
    let stream = is_stream(&args.out)?;
    let format = out_format(&args.out, stream)?;
    // both outputs are checked before the work, so that neither is written when the other
    // cannot be
    check_output(&args.out, args.force)?;
    if let Some(p) = &args.params_out {
        check_distinct(&[
            ("--out".to_string(), args.out.clone()),
            ("--params-out".to_string(), p.clone()),
        ])?;
        check_output(p, args.force)?;
    }
    let (cfg, exc) = configure(args)?;
    // the size is known now: refused here rather than after filling the file system
    let samples = exc.total_samples().unwrap_or(0);
    let bytes = (samples as f64 * format.bytes_per_sample()).ceil() as u64;
    check_room(&args.out, bytes).map_err(|err| SimulateError::TooLarge {
        periods: exc.periods,
        samples,
        err,
    })?;
    // a stream has no free space to bound it: the stated maximum does
    if samples > MAX_SAMPLES {
        let days = MAX_SAMPLES as f64 / f64::from(exc.fs_hz.max(1)) / 86_400.0;
        return Err(SimulateError::TooLong {
            periods: exc.periods,
            samples,
            fs_hz: exc.fs_hz,
            days: jointid::data::fmt_sig(days, 3),
        }
        .into());
    }
    let params = cfg.params_json()? + "\n";
    if stream {
        // a device or pipe cannot take back what it got: the run must complete before any
        // of it goes there (simulated twice, in constant memory)
        dry_run(format, &cfg, &exc)?;
    }
    let (mut u, mut theta_m) = (Moments::default(), Moments::default());
    let (summary, stream_bytes) = write_run(args, format, &cfg, &exc, |s| {
        u.push(s.u);
        theta_m.push(s.theta_m);
    })?;
    let scale = (format == OutFormat::Jcap).then(|| WireOptions::for_sim(&cfg).scale);
    if let Some(p) = &args.params_out {
        write_file(p, args.force, |w| w.write_all(params.as_bytes()))
            .map_err(SimulateError::from)?;
    }
    let modes = Mechanism::new(&cfg.plant, &cfg.effects).modal_frequencies();
    let report = Report {
        file: path_text(&args.out),
        format,
        model: cfg.plant.kind.label(),
        effects: cfg.effects.iter().map(|e| e.to_string()).collect(),
        samples: summary.samples,
        duration_s: summary.samples as f64 * summary.sample_interval_s,
        params_out: args.params_out.as_ref().map(|p| path_text(p)),
        scale,
        stream_bytes,
        integrator: summary.integrator,
        saturated_samples: summary.saturated_samples,
        u_rms: u.rms(),
        theta_m_rms: theta_m.rms(),
        resonances_hz: modes.resonances_hz,
        anti_resonances_hz: modes.anti_resonances_hz,
        config: &cfg,
    };
    // with the run on standard output, the report goes to standard error
    let mut stderr = std::io::stderr().lock();
    let o: &mut dyn std::io::Write = if names_standard_output(&args.out) {
        &mut stderr
    } else {
        &mut *ctx.out
    };
    if ctx.json {
        print_json(o, "simulate", &report)?;
        return Ok(Outcome::Ok);
    }
    writeln!(
        o,
        "simulated {} samples, {:.2} s at {} Hz",
        report.samples, report.duration_s, exc.fs_hz
    )?;
    if let Some(s) = &report.scale {
        writeln!(
            o,
            "wire scale {:e} N·m/count, {:e} rad/count",
            s.torque_nm_per_count, s.angle_rad_per_count
        )?;
    }
    writeln!(
        o,
        "model {}, effects: {}",
        report.model,
        effects_text(&cfg, " ")
    )?;
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|f| format!("{f:.2}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    writeln!(
        o,
        "modes seen from the motor: resonances [{}] Hz, anti-resonances [{}] Hz",
        fmt(&report.resonances_hz),
        fmt(&report.anti_resonances_hz)
    )?;
    writeln!(
        o,
        "integrator {}, u rms {:.4} N·m, theta_m rms {:.5} rad, saturated samples {}",
        report.integrator, report.u_rms, report.theta_m_rms, report.saturated_samples
    )?;
    let files: Vec<String> = std::iter::once(report.file.clone())
        .chain(report.params_out.clone())
        .collect();
    super::print_written(o, &files)?;
    Ok(Outcome::Ok)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{default_loaders, Cli, Command};
    use clap::Parser;
    use jointid::data::{load_csv, ColumnMap};
    use jointid::sim::simulate_excitation;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("jointid-sim-{}-{name}", std::process::id()))
    }

    /// Runs `cli` as the binary does (JSON when `--json` was given); the result and the output.
    fn run_cli(cli: &Cli) -> (crate::CmdResult, Vec<u8>) {
        let loaders = default_loaders();
        let mut buf = Vec::new();
        let result = crate::run(
            cli,
            &mut Context {
                json: cli.json,
                loaders: &loaders,
                out: &mut buf,
                fitted: None,
            },
        );
        (result, buf)
    }

    #[test]
    fn simulate_writes_a_capture_csv_that_data_reads_back() {
        let csv = temp("out.csv");
        let json = temp("params.json");
        let cli = Cli::try_parse_from([
            "jointid",
            "simulate",
            "--out",
            csv.to_str().unwrap(),
            "--effect",
            "backlash:width=3e-5",
            "--effect",
            "time_delay",
            "--periods",
            "1",
            "--params-json",
            json.to_str().unwrap(),
        ])
        .unwrap();
        let Command::Simulate(args) = &cli.command else {
            panic!("parsed {:?}", cli.command)
        };
        let (result, buf) = run_cli(&cli);
        let outcome = result.unwrap();
        assert_eq!(outcome, Outcome::Ok);
        let text = String::from_utf8(buf).unwrap();
        assert!(
            text.contains("effects: backlash:width=0.00003 time_delay:samples=1.5"),
            "{text}"
        );
        let ds = load_csv(&csv, &ColumnMap::capture()).unwrap();
        let (cfg, exc) = configure(args).unwrap();
        assert_eq!(ds.excitation, Some(exc));
        assert_eq!(
            ds.meta.get("sim_plant").map(String::as_str),
            Some("three_mass")
        );
        let direct = simulate_excitation(&cfg, &exc).unwrap();
        assert_eq!(ds.data.u, direct.u);
        assert_eq!(ds.data.y, direct.theta_m);
        assert_eq!(ds.data.r.as_deref(), Some(&direct.theta_ref[..]));
        assert!((ds.data.ts - 5e-4).abs() < 1e-15);
        let back: SimConfig =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(back, cfg);
        std::fs::remove_file(&csv).unwrap();
        std::fs::remove_file(&json).unwrap();
    }

    #[test]
    fn simulate_rejects_a_bad_effect_spec() {
        let cli = Cli::try_parse_from([
            "jointid",
            "simulate",
            "--out",
            temp("never.csv").to_str().unwrap(),
            "--effect",
            "backlash:widht=1",
        ])
        .unwrap();
        let err = run_cli(&cli).0.unwrap_err();
        assert!(err.to_string().contains("unknown key `widht`"), "{err}");
        assert!(!temp("never.csv").exists());
    }

    fn parse(args: &[&str]) -> SimulateArgs {
        let mut v = vec!["jointid", "simulate"];
        v.extend_from_slice(args);
        match Cli::try_parse_from(v).unwrap().command {
            Command::Simulate(a) => a,
            c => panic!("parsed {c:?}"),
        }
    }

    #[test]
    fn simulate_accepts_the_issue_interface_and_the_old_aliases() {
        let a = parse(&[
            "--model",
            "three_mass",
            "--excitation",
            "random-odd",
            "--seed",
            "9",
            "--out",
            "a.jcap",
            "--params-out",
            "p.json",
        ]);
        assert_eq!(a.model, SimModel::of(Structure::ThreeMass));
        assert_eq!(a.excitation, ExcitationArg::RandomOdd);
        assert_eq!(a.params_out, Some(PathBuf::from("p.json")));
        let (cfg, exc) = configure(&a).unwrap();
        assert_eq!((cfg.seed, exc.seed), (9, 9));
        let b = parse(&[
            "--plant",
            "nonlinear-two-mass",
            "--kind",
            "special-odd",
            "--out",
            "b.csv",
            "--params-json",
            "q.json",
            "--seed",
            "3",
            "--excitation-seed",
            "4",
        ]);
        assert_eq!(b.model, SimModel::ALL[4]);
        assert_eq!(b.excitation, ExcitationArg::OddMultisine);
        assert_eq!(b.params_out, Some(PathBuf::from("q.json")));
        let (cfg, exc) = configure(&b).unwrap();
        assert_eq!((cfg.seed, exc.seed), (3, 4));
        // the alias is the two-mass with seed 001's two effects, as `fit` resolves it
        assert_eq!(cfg.plant.kind, Structure::TwoMass);
        let names: Vec<&str> = cfg.effects.iter().map(|e| e.name()).collect();
        assert_eq!(names, ["nonlinear_stiffness", "coulomb_friction"]);
        let d = parse(&["--out", "c.csv"]);
        let (cfg, exc) = configure(&d).unwrap();
        assert_eq!(cfg.plant.kind, Structure::ThreeMass);
        assert!(cfg.effects.is_empty());
        assert_eq!(exc, ExcitationConfig::paper_default());
        assert_eq!(cfg.seed, SimConfig::default().seed);
        assert!(Cli::try_parse_from([
            "jointid",
            "simulate",
            "--model",
            "five-mass",
            "--out",
            "x.csv"
        ])
        .is_err());
    }

    #[test]
    fn param_overrides_the_named_parameter_and_rejects_names_the_model_lacks() {
        let a = parse(&[
            "--model",
            "four-mass",
            "--param",
            "k_g=1.3e5",
            "--param",
            "J_p = 2",
            "--out",
            "x.csv",
        ]);
        let (cfg, _) = configure(&a).unwrap();
        assert_eq!(cfg.plant.params.k_g, 1.3e5);
        assert_eq!(cfg.plant.params.j_p, 2.0);
        assert_eq!(cfg.plant.params.k_a, JointParams::default().k_a);
        let mut p = JointParams::default();
        let err = apply_params(
            SimModel::of(Structure::ThreeMass),
            &["J_p=2".into()],
            &mut p,
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "--param `J_p`: unknown parameter for three-mass (valid: J_m, J_a1, J_a2, k_g, d_g, k_a, d_a, f_m, r)"
        );
        let err =
            apply_params(SimModel::of(Structure::Rigid), &["k_g=1".into()], &mut p).unwrap_err();
        assert!(
            err.to_string().contains("(valid: J_m, J_a1, J_a2, f_m, r)"),
            "{err}"
        );
        let err = apply_params(SimModel::ALL[4], &["k3=abc".into()], &mut p).unwrap_err();
        assert_eq!(
            err.to_string(),
            "--param `k3`: `abc` is not a finite number (valid names for nonlinear-two-mass: J_m, J_a1, J_a2, k_g, d_g, f_m, r, k3, F_c)"
        );
        let two = SimModel::of(Structure::TwoMass);
        let err = apply_params(two, &["k_g".into()], &mut p).unwrap_err();
        assert!(matches!(err, SimulateError::ParamSyntax { .. }), "{err}");
        let err = apply_params(two, &["k_g=inf".into()], &mut p).unwrap_err();
        assert!(matches!(err, SimulateError::BadValue { .. }), "{err}");
        let err = apply_params(two, &["J_m=1e-30".into()], &mut p).unwrap_err();
        assert_eq!(
            err.to_string(),
            "--param `J_m`: `1e-30` is outside its physical range: must be within [1e-7, 10000] kg·m²"
        );
        assert_eq!(p, JointParams::default(), "nothing applied on error");
        apply_params(
            SimModel::ALL[4],
            &["F_c=0.05".into(), "k3=1e12".into()],
            &mut p,
        )
        .unwrap();
        assert_eq!((p.f_c, p.k3), (0.05, 1e12));
        // and they reach seed 001's effects of the alias (pure Coulomb friction)
        let a = parse(&[
            "--model",
            "nonlinear_two_mass",
            "--param",
            "k3=1e12",
            "--param",
            "F_c=0.05",
            "--effect",
            "backlash",
            "--out",
            "x.csv",
        ]);
        let (cfg, _) = configure(&a).unwrap();
        let specs: Vec<String> = cfg.effects.iter().map(|e| e.to_string()).collect();
        assert_eq!(specs[0], "nonlinear_stiffness:k3=1000000000000");
        assert!(
            specs[1].starts_with("coulomb_friction:fc=0.05,fs=0.05,"),
            "{specs:?}"
        );
        assert!(specs[2].starts_with("backlash:"), "{specs:?}");
        // every name the models accept is a name of the parameter table
        let table: Vec<&str> = JointParams::default().table().iter().map(|t| t.0).collect();
        for k in SimModel::ALL {
            for (n, _) in k.params() {
                assert!(table.contains(&n), "{n}");
            }
        }
    }

    #[test]
    fn simulate_refuses_an_out_extension_other_than_jcap_or_csv() {
        let out = temp("run.txt");
        let cli =
            Cli::try_parse_from(["jointid", "simulate", "--out", out.to_str().unwrap()]).unwrap();
        let err = run_cli(&cli).0.unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "{}: --out must end in .jcap or .csv (or be a device or a pipe, which takes \
                 the capture CSV)",
                out.display()
            )
        );
        assert!(!out.exists());
        assert_eq!(
            out_format(Path::new("A.JCAP"), false).unwrap(),
            OutFormat::Jcap
        );
        assert!(out_format(Path::new("run"), false).is_err());
        // a device or pipe without an extension takes the capture CSV
        assert_eq!(
            out_format(Path::new("/dev/stdout"), true).unwrap(),
            OutFormat::Csv
        );
        assert_eq!(
            out_format(Path::new("fifo.jcap"), true).unwrap(),
            OutFormat::Jcap
        );
    }

    #[test]
    fn simulate_jcap_reads_back_as_a_board_capture() {
        let jcap = temp("run.jcap");
        let cli = Cli::try_parse_from([
            "jointid",
            "--json",
            "simulate",
            "--model",
            "two-mass",
            "--periods",
            "1",
            "--out",
            jcap.to_str().unwrap(),
        ])
        .unwrap();
        let Command::Simulate(args) = &cli.command else {
            unreachable!()
        };
        let (result, buf) = run_cli(&cli);
        result.unwrap();
        let summary: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        let rec = jointid::capture::read_jcap(&jcap).unwrap();
        let (cfg, exc) = configure(args).unwrap();
        let direct = simulate_excitation(&cfg, &exc).unwrap();
        assert_eq!(summary["samples"], direct.len());
        assert_eq!(summary["model"], "two-mass");
        assert_eq!(summary["format"], "jcap");
        assert_eq!(rec.header, WireOptions::for_sim(&cfg).header(&exc));
        assert_eq!(rec.samples.len(), direct.len());
        assert!(rec.report.damaged_frames.is_empty() && rec.report.gaps.is_empty());
        assert!(rec.report.reference_mismatches.is_empty());
        let half = 0.5 * f64::from(jointid::sim::board::SIM_TORQUE_NM_PER_COUNT) * (1.0 + 1e-9);
        for (s, u) in rec.samples.iter().zip(&direct.u) {
            assert!((s.u - u).abs() <= half, "{} vs {u}", s.u);
        }
        std::fs::remove_file(&jcap).unwrap();
    }
}
