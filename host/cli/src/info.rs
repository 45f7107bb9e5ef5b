//! `jointid info RUN.jcap [--json]`: what a capture holds.
//!
//! Board, session, sample rate, excitation, scale, then the report: samples, gaps, damaged
//! frames with byte offsets, board counters, link events. `--json` prints one object with
//! the same report fields as `capture --json`, plus `file` and `header` (null when no
//! session header arrived). Works on a capture without a header and on one whose
//! excitation cannot be regenerated (the reference check is then skipped).
//! Exit status: 0, 1 with `--strict` when anything is missing or damaged, 2 error.

use std::path::PathBuf;

use jointid_core::wire::SessionHeader;
use serde::Serialize;

use super::{print_json, CmdResult, Context, Outcome};
use jointid::capture::export::kind_name;
use jointid::capture::{read_jcap_report, CaptureReport};

/// Arguments of `jointid info`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct InfoArgs {
    /// Capture file to read
    #[arg(value_name = "RUN.jcap")]
    pub input: PathBuf,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
}

/// What `info --json` prints.
#[derive(Debug, Serialize)]
pub struct InfoSummary {
    /// the capture file
    pub file: String,
    /// the reported session's header
    pub header: Option<SessionHeader>,
    /// the report
    #[serde(flatten)]
    pub report: CaptureReport,
}

/// Runs `jointid info`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged.
///
/// # Errors
/// [`jointid::capture::CaptureError::Jcap`] when the file cannot be read or is no jcap
/// file; output errors.
pub fn run(args: &InfoArgs, ctx: &mut Context<'_>) -> CmdResult {
    let (report, header) = read_jcap_report(&args.input)?;
    let clean = report.is_clean();
    let summary = InfoSummary {
        file: args.input.display().to_string(),
        header,
        report,
    };
    if ctx.json {
        print_json(ctx.out, &summary)?;
    } else {
        write!(ctx.out, "{}", describe(&summary))?;
    }
    Ok(if args.strict && !clean {
        Outcome::CheckFailed
    } else {
        Outcome::Ok
    })
}

/// The human-readable description `info` prints.
pub fn describe(s: &InfoSummary) -> String {
    let mut out = format!("{}\n", s.file);
    match &s.header {
        None => out.push_str("no session header: counts cannot be scaled to SI\n"),
        Some(h) => {
            let x = &h.excitation;
            let duration =
                s.report.last_seq.map_or(0.0, |l| f64::from(l) + 1.0) / f64::from(h.sample_rate_hz);
            out.push_str(&format!(
                "board {:#010x}  session {}  protocol {}\n\
                 sampling    {} Hz (timer {} Hz), {duration:.3} s up to the last sample\n\
                 scale       {} N·m/count, {} rad/count\n\
                 excitation  {} fs={} Hz N={} F={} cutoff={} Hz rms={} rad seed={} ramp={} periods={}\n",
                h.board_id,
                h.session_id,
                h.protocol_version,
                h.sample_rate_hz,
                h.timer_hz,
                h.scale.torque_nm_per_count,
                h.scale.angle_rad_per_count,
                kind_name(x.kind),
                x.fs_hz,
                x.period_samples,
                x.max_line,
                x.cutoff_hz,
                x.rms_rad,
                x.seed,
                x.ramp_samples,
                x.periods,
            ));
        }
    }
    out.push_str(&s.report.to_string());
    out.push('\n');
    out
}
