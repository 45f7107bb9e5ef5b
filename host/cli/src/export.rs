//! `jointid export RUN.jcap --csv RUN.csv`: the capture CSV of DESIGN.md §5.
//!
//! Writes only the samples that arrived; the `# gaps=` comment lists what did not (see
//! [`jointid::capture::export`]). An existing CSV is replaced only with `--force`; the CSV
//! is written to a temporary file beside it and renamed, so a half-written export never
//! looks complete ([`jointid::data::output`]); `--csv -` writes to stdout.
//! Exit status: 0 exported, 1 `--strict` and something is missing or damaged, 2 error.

use std::io::Write;
use std::path::PathBuf;

use super::{CmdResult, Context, Outcome};
use jointid::capture::{export, read_jcap_session, session_ids};

/// Arguments of `jointid export`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct ExportArgs {
    /// Capture file to read
    #[arg(value_name = "RUN.jcap")]
    pub input: PathBuf,
    /// CSV file to write (`-` for stdout)
    #[arg(long, value_name = "RUN.csv")]
    pub csv: PathBuf,
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

/// Runs `jointid export`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged. With `--json`, a summary object goes to the output (not with
/// `--csv -`, where the output is the CSV).
///
/// # Errors
/// Reading the capture ([`jointid::capture::CaptureError::Jcap`], [`jointid::capture::CaptureError::NoHeader`],
/// [`jointid::capture::CaptureError::Excitation`]) or writing the CSV ([`jointid::capture::CaptureError::Output`]).
pub fn run(args: &ExportArgs, ctx: &mut Context<'_>) -> CmdResult {
    let to_stdout = args.csv.as_os_str() == "-";
    if !to_stdout {
        jointid::data::output::check_output(&args.csv, args.force)?;
    }
    let record = read_jcap_session(&args.input, args.session)?;
    if to_stdout {
        let mut w = std::io::BufWriter::new(&mut *ctx.out);
        // errors name standard output (see main.rs)
        export::write_csv(&record, &mut w)?;
        w.into_inner().map_err(|e| e.into_error())?;
    } else {
        export::export_csv(&record, &args.csv, args.force)?;
    }
    let r = &record.report;
    let ids = session_ids(r);
    if args.session.is_none() && ids.len() > 1 {
        let list: Vec<String> = ids.iter().map(u32::to_string).collect();
        let _ = writeln!(
            std::io::stderr(),
            "note: {} holds {} sessions ({}); exported session {} (choose another with --session K)",
            args.input.display(),
            ids.len(),
            list.join(", "),
            record.header.session_id
        );
    }
    let _ = writeln!(
        std::io::stderr(),
        "exported {} samples to {} ({} gaps, {} samples missing, {} damaged frames)",
        record.samples.len(),
        args.csv.display(),
        r.gaps.len(),
        r.missing_samples,
        r.damaged_frames.len()
    );
    if ctx.json && !to_stdout {
        super::print_json(
            ctx.out,
            &serde_json::json!({
                "file": args.input.display().to_string(),
                "csv": args.csv.display().to_string(),
                "session_id": record.header.session_id,
                "rows": record.samples.len(),
                "samples": r.samples,
                "gaps": r.gaps,
                "missing_samples": r.missing_samples,
                "damaged_frames": r.damaged_frames,
                "overruns": r.overruns,
            }),
        )?;
    }
    Ok(if args.strict && !r.is_clean() {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}
