//! `jointid export RUN.jcap --csv RUN.csv`: the capture CSV of DESIGN.md §5.
//!
//! Writes only the samples that arrived; the `# gaps=` comment lists what did not (see
//! [`crate::capture::export`]). The CSV is written to `RUN.csv.tmp` and renamed, so a
//! half-written export never looks complete; `--csv -` writes to stdout.
//! Exit status: 0 exported, 1 `--strict` and something is missing or damaged, 2 error.

use std::path::PathBuf;

use crate::capture::{export, read_jcap, CaptureError};

/// Arguments of `jointid export`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct ExportArgs {
    /// Capture file to read
    #[arg(value_name = "RUN.jcap")]
    pub input: PathBuf,
    /// CSV file to write (`-` for stdout)
    #[arg(long, value_name = "RUN.csv")]
    pub csv: PathBuf,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
}

/// Runs `jointid export`; returns the exit status.
///
/// # Errors
/// Reading the capture ([`CaptureError::Jcap`], [`CaptureError::NoHeader`],
/// [`CaptureError::Excitation`]) or writing the CSV ([`CaptureError::Export`]).
pub fn run(args: &ExportArgs) -> Result<u8, CaptureError> {
    let record = read_jcap(&args.input)?;
    if args.csv.as_os_str() == "-" {
        let stdout = std::io::stdout();
        let mut lock = std::io::BufWriter::new(stdout.lock());
        export::write_csv(&record, &mut lock).map_err(|source| CaptureError::Export {
            path: args.csv.clone(),
            err: source,
        })?;
    } else {
        export::export_csv(&record, &args.csv)?;
    }
    let r = &record.report;
    eprintln!(
        "exported {} samples to {} ({} gaps, {} samples missing, {} damaged frames)",
        record.samples.len(),
        args.csv.display(),
        r.gaps.len(),
        r.missing_samples,
        r.damaged_frames.len()
    );
    Ok(u8::from(args.strict && !r.is_clean()))
}
