//! `jointid`: the command line of the `jointid` library. Parse (clap derive),
//! validate, dispatch; exit codes 0 ok, 1 a check failed, 2 error (printed on one
//! line, or as `{"error": ...}` with `--json`).
//!
//! Layers (as ripgrep's `flags/`): each subcommand has one module here with
//! its `clap::Args` struct and a `run(args, ctx)` that loads data, calls the
//! estimators (which do no IO) and prints a table or JSON. Shared argument
//! groups (data file + column mapping, preparation) live in `args`.
//!
//! Adding a subcommand (`capture`, `export`, `info`, `simulate`, `fit`,
//! `demo`, …): create `src/<name>.rs` with `pub struct <Name>Args` (derive
//! `clap::Args`) and `pub fn run(args: &<Name>Args, ctx: &mut Context<'_>)
//! -> CmdResult`; add `mod <name>;`, one [`Command`] variant and one arm in
//! [`run`]. Nothing else changes.
//!
//! Exit codes ([`Outcome::code`]): 0 ok, 1 a check failed, 2 error.
//!
//! The binary (`src/main.rs`) parses the command line, calls [`run`] and prints
//! [`error_message`]; the Python package (`python/`) calls the same [`run`] with
//! `--json` into a buffer, so its results are the `--json` documents themselves.
// Units in brackets (`[s]`, `[Hz]`, `[dB]`) are not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

use std::io::Write;

use clap::{Parser, Subcommand};
use jointid::data::output::{check_output, OutputError};
use jointid::data::Loaders;

mod analyze;
mod args;
mod capture;
mod demo;
mod diagnose;
mod experiment;
mod export;
mod export_model;
mod fit;
mod fit_report;
mod info;
pub mod interrupt;
mod print;
pub mod progress;
mod simulate;
mod validate;
mod validate_simulated;
mod views;

/// `jointid`: identification of one robot joint, from capture to validated models.
#[derive(Debug, Parser)]
#[command(name = "jointid", version, about, long_about = None)]
pub struct Cli {
    /// machine-readable JSON output (results and errors)
    #[arg(long, global = true)]
    pub json: bool,
    /// the subcommand
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands, in the order of the user's path.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// record the board's stream (serial, CAN, slcan adapter, candump log, TCP or file) into a .jcap capture
    Capture(capture::CaptureArgs),
    /// what a capture or data file holds: board, excitation, samples, rate, columns, gaps, damaged frames
    Info(info::InfoArgs),
    /// write a .jcap capture as the capture CSV (t,theta_ref,u,theta_m) or a MATLAB file
    Export(export::ExportArgs),
    /// a model file of `fit --save` as state space or transfer functions (JSON, MATLAB, python-control)
    ExportModel(export_model::ExportModelArgs),
    /// nonparametric FRF, noise level and nonlinear distortion of periodic data
    Analyze(analyze::AnalyzeArgs),
    /// fit a black-box or physical model: parameters, FIT, resonances, residual tests
    Fit(fit::FitArgs),
    /// FIT and residual tests of a saved model (or a simulated column) on data
    Validate(validate::ValidateArgs),
    /// the whole path on the simulated joint, through the wire encoder (no board needed)
    Demo(demo::DemoArgs),
    /// seed 000 Table 2 on simulated IRB1400-like data (FIT of black box 11, three-, four-mass)
    Experiment(experiment::ExperimentArgs),
    /// closed-loop joint simulator with switchable effects; writes a .jcap capture or a capture CSV
    Simulate(simulate::SimulateArgs),
    /// which unmodelled effect makes the simulated joint depart from the measured one
    Diagnose(diagnose::DiagnoseArgs),
}

/// How a command ended when it did not fail with an error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// everything ran and every check passed (exit 0)
    Ok,
    /// ran, but a check the user asked for failed (exit 1)
    CheckFailed,
}

impl Outcome {
    /// process exit code
    pub fn code(self) -> u8 {
        match self {
            Outcome::Ok => 0,
            Outcome::CheckFailed => 1,
        }
    }
}

/// Result of a subcommand; any error ends the process with exit code 2.
pub type CmdResult = Result<Outcome, Box<dyn std::error::Error + Send + Sync>>;

/// What every subcommand gets besides its arguments.
pub struct Context<'a> {
    /// print JSON instead of tables
    pub json: bool,
    /// file loaders by extension (CSV built in)
    pub loaders: &'a Loaders,
    /// where results go (stdout in the binary, a buffer in tests)
    pub out: &'a mut dyn Write,
    /// the linear model a linear `fit` produced (set by `fit`; the Python package reads
    /// its state-space form)
    pub fitted: Option<jointid::ident::fit::Fitted>,
}

/// Loaders the binary uses: CSV (built in) and the native capture, told by its magic
/// bytes whatever the file is called.
pub fn default_loaders() -> Loaders {
    let mut l = Loaders::default();
    l.register(
        "jcap",
        jointid::data::JCAP_MAGIC_PREFIX,
        Box::new(|input, _| jointid::capture::load_record(input).map_err(Into::into)),
    );
    l
}

/// Runs the parsed command line.
///
/// # Errors
/// Whatever the subcommand reports; main.rs prints it on one line (or as
/// JSON with `--json`) and exits with 2.
pub fn run(cli: &Cli, ctx: &mut Context<'_>) -> CmdResult {
    let done = match &cli.command {
        Command::Capture(a) => capture::run(a, ctx),
        Command::Info(a) => info::run(a, ctx),
        Command::Export(a) => export::run(a, ctx),
        Command::ExportModel(a) => export_model::run(a, ctx),
        Command::Analyze(a) => analyze::run(a, ctx),
        Command::Fit(a) => fit::run(a, ctx),
        Command::Validate(a) => validate::run(a, ctx),
        Command::Demo(a) => demo::run(a, ctx),
        Command::Experiment(a) => experiment::run(a, ctx),
        Command::Simulate(a) => simulate::run(a, ctx),
        Command::Diagnose(a) => diagnose::run(a, ctx),
    };
    // a command that ended early (an error) leaves no progress line behind
    progress::finish();
    done
}

/// Ends a command's text output with the files it wrote, under `wrote:`, one a line
/// (nothing when it wrote none): the one place that lists them. `--json` lists them in the
/// document instead (`files`, `out`, `csv`).
///
/// # Errors
/// Write errors.
pub fn print_written(out: &mut dyn Write, files: &[String]) -> std::io::Result<()> {
    if files.is_empty() {
        return Ok(());
    }
    writeln!(out, "wrote:")?;
    for f in files {
        writeln!(out, "  {f}")?;
    }
    Ok(())
}

/// Writes an SVG string (from [`jointid::report::plot`]) to `path` under the one rule of
/// every output file ([`jointid::data::output`]: an existing file only with `--force`,
/// whole or not at all).
///
/// # Errors
/// [`OutputError`] naming the file.
pub fn write_svg(path: &std::path::Path, svg: &str, force: bool) -> Result<(), OutputError> {
    jointid::data::output::write_file(path, force, |w| w.write_all(svg.as_bytes()))
}

/// Why a `--plot DIR` cannot take its figures ([`check_plot_files`]).
#[derive(Debug, thiserror::Error)]
pub enum PlotDirError {
    /// the directory does not exist and cannot be created
    #[error("{}: cannot create the directory: {}", dir.display(), jointid::data::output::io_msg(err))]
    Create {
        /// the directory
        dir: std::path::PathBuf,
        /// what the operating system said
        err: std::io::Error,
    },
    /// a figure's file cannot be written there (exists, directory not writable, ...):
    /// the rule of output files that refused it, naming the file and its directory
    #[error(transparent)]
    File(#[from] OutputError),
}

/// Checks, before any work, that the files `names` can be written into the plot directory
/// `dir` ([`jointid::data::output::check_output`], which creates and removes a probe file
/// there): a directory that does not exist is created now, with its parents, so that one
/// that cannot be (a read-only parent, a file in the way) is refused before the work too.
///
/// # Errors
/// [`PlotDirError`] naming the directory, and the first file that cannot be written.
pub fn check_plot_files(
    dir: &std::path::Path,
    names: &[&str],
    force: bool,
) -> Result<(), PlotDirError> {
    std::fs::create_dir_all(dir).map_err(|err| PlotDirError::Create {
        dir: dir.to_path_buf(),
        err,
    })?;
    names
        .iter()
        .try_for_each(|n| check_output(&dir.join(n), force))
        .map_err(PlotDirError::from)
}

/// Version of a `--json` document's shape: `"schema": "jointid-<kind>/<version>"`. A field
/// renamed or removed, or a type changed, raises its kind's; the schema file
/// `host/cli/schema/<kind>.schema.json` changes with it. `diagnose` is at 2: its FITs
/// took back the names the diagnosis's contract gives them (`fit_nominal_val`,
/// `fit_augmented_val`, `fit_val`, `seconds`), `fit_validation` and `elapsed_s` kept
/// beside the last two.
pub fn schema_version(kind: &str) -> u32 {
    match kind {
        "diagnose" => 2,
        _ => 1,
    }
}

/// The name of a `--json` document's schema, `jointid-<kind>/<version>`
/// ([`schema_version`]); `kind` is the command, or the command and the document's variant
/// (`fit-nonlinear`).
pub fn schema_name(kind: &str) -> String {
    format!("jointid-{kind}/{}", schema_version(kind))
}

/// A `--json` document: its `schema` first, then the command's own fields.
#[derive(serde::Serialize)]
struct Document<'a, T> {
    schema: String,
    #[serde(flatten)]
    body: &'a T,
}

/// Prints `value`, a command's `--json` document of kind `kind` (the command's name, or
/// its name and the document's variant: `fit-nonlinear`), as pretty JSON on `out`, with
/// `"schema": "jointid-<kind>/1"` as its first field. The one place that prints a JSON
/// document; its shape is pinned by `host/cli/schema/<kind>.schema.json`.
///
/// The document is serialised first and then written, so a write error reaches the
/// caller as the [`std::io::Error`] itself (a closed pipe stays recognisable) rather than
/// inside a `serde_json::Error`.
///
/// # Errors
/// Serialisation or write errors.
pub fn print_json<T: serde::Serialize>(
    out: &mut dyn Write,
    kind: &str,
    value: &T,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let doc = Document {
        schema: schema_name(kind),
        body: value,
    };
    let mut text = serde_json::to_vec_pretty(&doc)?;
    text.push(b'\n');
    out.write_all(&text)?;
    Ok(())
}

/// The one-line JSON document of an error: `{"schema": "jointid-error/1", "error": msg}`.
pub fn error_json(msg: &str) -> String {
    #[derive(serde::Serialize)]
    struct Error<'a> {
        error: &'a str,
    }
    let doc = Document {
        schema: schema_name("error"),
        body: &Error { error: msg },
    };
    // a struct of two strings always serialises
    serde_json::to_string(&doc).unwrap_or_default()
}

/// The one line a command's error is printed as (after `jointid: error: `, or as the
/// `error` of [`error_json`]): the error, then each cause it does not already state, without
/// the standard library's ` (os error N)` codes, newlines as spaces.
pub fn error_message(e: Box<dyn std::error::Error + Send + Sync>) -> String {
    let e = anyhow::Error::from_boxed(e);
    // the chain, skipping causes the message already states
    let mut msg = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        // an I/O error's text without its `(os error N)` suffix counts as stated, as does
        // its phrase as `data::output::io_msg` gives it (lowercase)
        let plain = c.find(" (os error ").map_or(c.as_str(), |i| &c[..i]);
        let phrase = plain.get(..1).map_or(String::new(), |first| {
            first.to_lowercase() + &plain[first.len()..]
        });
        if !msg.contains(plain) && !msg.contains(&phrase) {
            msg = format!("{msg}: {c}");
        }
    }
    without_os_error_codes(&msg.replace('\n', " "))
}

/// The one line a command-line parse error is printed as with `--json`: clap's message
/// without its `error: ` prefix and usage lines.
pub fn parse_error_message(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .take_while(|l| !l.starts_with("Usage:"))
        .filter(|l| !l.is_empty())
        .collect();
    lines.join(" ").trim_start_matches("error: ").to_string()
}

/// True when `e` or one of its causes is a closed pipe.
pub fn is_broken_pipe(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur = Some(e);
    while let Some(c) = cur {
        if c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
        {
            return true;
        }
        cur = c.source();
    }
    false
}

/// `msg` without the ` (os error N)` that the standard library appends to I/O errors.
fn without_os_error_codes(msg: &str) -> String {
    let mut out = String::with_capacity(msg.len());
    let mut rest = msg;
    while let Some(i) = rest.find(" (os error ") {
        out.push_str(&rest[..i]);
        let tail = &rest[i + " (os error ".len()..];
        let digits = tail.bytes().take_while(u8::is_ascii_digit).count();
        if digits > 0 && tail[digits..].starts_with(')') {
            rest = &tail[digits + 1..];
        } else {
            out.push_str(" (os error ");
            rest = tail;
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn json_documents_name_their_schema_first() {
        #[derive(serde::Serialize)]
        struct X {
            a: u8,
        }
        let mut out = Vec::new();
        print_json(&mut out, "info", &X { a: 1 }).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "{\n  \"schema\": \"jointid-info/1\",\n  \"a\": 1\n}\n"
        );
        assert_eq!(
            error_json("no \"x\""),
            r#"{"schema":"jointid-error/1","error":"no \"x\""}"#
        );
    }

    #[test]
    fn json_flag_is_global() {
        let c = Cli::try_parse_from(["jointid", "analyze", "x.csv", "--json"]).unwrap();
        assert!(c.json);
        let c = Cli::try_parse_from([
            "jointid",
            "--json",
            "validate",
            "x.csv",
            "--simulated",
            "ys",
        ])
        .unwrap();
        assert!(c.json && matches!(c.command, Command::Validate(_)));
    }
}
