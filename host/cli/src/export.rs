//! `jointid export RUN.jcap --csv RUN.csv`: the capture CSV of ../shared/DESIGN.md §5
//! (`-` reads the capture from standard input, whole);
//! `--mat RUN.mat`: the same columns as MATLAB vectors ([`jointid::capture::export::export_mat`]).
//!
//! Writes only the samples that arrived; the `# gaps=` comment lists what did not (see
//! [`jointid::capture::export`]). An existing CSV is replaced only with `--force`; the CSV
//! is written to a temporary file beside it and renamed, so a half-written export never
//! looks complete ([`jointid::data::output`]); `--csv -` writes to stdout (and `--json`'s
//! document then goes to stderr), as does `--csv /dev/stdout`, written in place.
//! Exit status: 0 exported, 1 `--strict` and something is missing or damaged, 2 error.

use std::io::Write;
use std::path::PathBuf;

use serde::Serialize;

use super::{CmdResult, Context, Outcome};
use jointid::capture::{export, read_jcap_session, session_ids, DamagedFrame, SeqGap};

use jointid::data::input::{input_name, path_text};
use jointid::data::output::{check_distinct, check_output, names_standard_output};

/// Arguments of `jointid export`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
#[command(group(clap::ArgGroup::new("to").required(true).multiple(true).args(["csv", "mat"])))]
pub struct ExportArgs {
    /// Capture file to read (`-` for standard input)
    #[arg(value_name = "RUN.jcap")]
    pub input: PathBuf,
    /// CSV file to write (`-` for stdout)
    #[arg(long, value_name = "RUN.csv")]
    pub csv: Option<PathBuf>,
    /// MATLAB Level-5 file to write: column vectors t, theta_ref, u, theta_m and the CSV's
    /// comment lines as the text `comments`
    #[arg(long, value_name = "RUN.mat")]
    pub mat: Option<PathBuf>,
    /// Session to export, by its id as `jointid info` lists it (default: the first)
    #[arg(long, value_name = "K")]
    pub session: Option<u32>,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
    /// Replace existing output files (without it, an existing file is refused)
    #[arg(long)]
    pub force: bool,
}

/// What `export --json` prints: on standard output, or on standard error with `--csv -`
/// (standard output then carries the CSV).
#[derive(Serialize)]
struct ExportSummary<'a> {
    /// the capture read
    file: String,
    /// the CSV written (`-`: standard output)
    #[serde(skip_serializing_if = "Option::is_none")]
    csv: Option<String>,
    /// the MATLAB file written
    #[serde(skip_serializing_if = "Option::is_none")]
    mat: Option<String>,
    /// the exported session
    session_id: u32,
    /// CSV rows written (samples that arrived)
    rows: usize,
    samples: u64,
    gaps: &'a [SeqGap],
    missing_samples: u64,
    damaged_frames: &'a [DamagedFrame],
    overruns: u32,
    /// what the text output prints as notes (other sessions in the capture)
    notes: Vec<String>,
}

/// Runs `jointid export`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged. With `--json`, a summary document goes to the output; with
/// `--csv -`, where the output is the CSV, it goes to standard error instead, as the only
/// thing written there.
///
/// # Errors
/// Reading the capture ([`jointid::capture::CaptureError::Jcap`], [`jointid::capture::CaptureError::NoHeader`],
/// [`jointid::capture::CaptureError::Excitation`]) or writing the CSV ([`jointid::capture::CaptureError::Output`]).
pub fn run(args: &ExportArgs, ctx: &mut Context<'_>) -> CmdResult {
    let to_stdout = args.csv.as_ref().is_some_and(|c| c.as_os_str() == "-");
    // standard output carries an export (`--csv -`, or a file named `/dev/stdout`): the
    // report goes to standard error
    let stdout_taken = to_stdout
        || [&args.csv, &args.mat]
            .into_iter()
            .flatten()
            .any(|p| names_standard_output(p));
    if let Some(csv) = args.csv.as_ref().filter(|_| !to_stdout) {
        check_output(csv, args.force)?;
    }
    if let Some(mat) = &args.mat {
        check_output(mat, args.force)?;
        if let Some(csv) = args.csv.as_ref().filter(|_| !to_stdout) {
            check_distinct(&[
                ("--csv".to_string(), csv.clone()),
                ("--mat".to_string(), mat.clone()),
            ])?;
        }
    }
    let record = read_jcap_session(&args.input, args.session)?;
    if to_stdout {
        let mut w = std::io::BufWriter::new(&mut *ctx.out);
        // errors name standard output (see main.rs)
        export::write_csv(&record, &mut w)?;
        w.into_inner().map_err(|e| e.into_error())?;
    } else if let Some(csv) = &args.csv {
        export::export_csv(&record, csv, args.force)?;
    }
    if let Some(mat) = &args.mat {
        export::export_mat(&record, mat, args.force)?;
    }
    let written: Vec<String> = [&args.csv, &args.mat]
        .into_iter()
        .flatten()
        .map(|p| path_text(p))
        .collect();
    let r = &record.report;
    let ids = session_ids(r);
    let mut notes = Vec::new();
    if args.session.is_none() && ids.len() > 1 {
        let list: Vec<String> = ids.iter().map(u32::to_string).collect();
        notes.push(format!(
            "{} holds {} sessions ({}); exported session {} (choose another with --session K)",
            input_name(&args.input),
            ids.len(),
            list.join(", "),
            record.header.session_id
        ));
    }
    // with `--csv - --json` standard error carries the JSON document alone
    if !(ctx.json && stdout_taken) {
        for n in &notes {
            let _ = writeln!(std::io::stderr(), "note: {n}");
        }
        let _ = writeln!(
            std::io::stderr(),
            "exported {} samples{} ({} gaps, {} samples missing, {} damaged frames)",
            record.samples.len(),
            if stdout_taken {
                format!(" to {}", written.join(" and "))
            } else {
                String::new()
            },
            r.gaps.len(),
            r.missing_samples,
            r.damaged_frames.len()
        );
        // standard output lists the files, unless it carries the CSV
        if !ctx.json && !stdout_taken {
            super::print_written(ctx.out, &written)?;
        }
    }
    if ctx.json {
        let summary = ExportSummary {
            file: input_name(&args.input),
            csv: args.csv.as_ref().map(|p| path_text(p)),
            mat: args.mat.as_ref().map(|p| path_text(p)),
            session_id: record.header.session_id,
            rows: record.samples.len(),
            samples: r.samples,
            gaps: &r.gaps,
            missing_samples: r.missing_samples,
            damaged_frames: &r.damaged_frames,
            overruns: r.overruns,
            notes,
        };
        if stdout_taken {
            super::print_json(&mut std::io::stderr().lock(), "export", &summary)?;
        } else {
            super::print_json(ctx.out, "export", &summary)?;
        }
    }
    Ok(if args.strict && !r.is_clean() {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}
