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
use jointid::capture::{read_jcap_session_reports, segments_of, CaptureReport};
use jointid::data::{fmt_sig, SegmentInfo};

/// Arguments of `jointid info`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct InfoArgs {
    /// Capture file to read
    #[arg(value_name = "RUN.jcap")]
    pub input: PathBuf,
    /// Report only this session, by its id (default: every session, the first one on top)
    #[arg(long, value_name = "K")]
    pub session: Option<u32>,
    /// Exit with status 1 when anything is missing or damaged
    #[arg(long)]
    pub strict: bool,
}

/// One session of `info --json`'s `per_session`.
#[derive(Debug, Serialize)]
pub struct SessionInfo {
    /// the session's header (null when no session header arrived)
    pub header: Option<SessionHeader>,
    /// the session's report
    #[serde(flatten)]
    pub report: CaptureReport,
    /// the session's gap-free segments (what `--segment N` of the analysis commands picks)
    pub segments: Vec<SegmentInfo>,
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
    /// the reported session's gap-free segments
    pub segments: Vec<SegmentInfo>,
    /// every session (or the one asked for), in stream order, each with its own report
    pub per_session: Vec<SessionInfo>,
}

/// Runs `jointid info`: [`Outcome::CheckFailed`] with `--strict` when anything is
/// missing or damaged.
///
/// # Errors
/// [`jointid::capture::CaptureError::Jcap`] when the file cannot be read or is no jcap
/// file; output errors.
pub fn run(args: &InfoArgs, ctx: &mut Context<'_>) -> CmdResult {
    let mut all = read_jcap_session_reports(&args.input, args.session)?;
    let clean = all.iter().all(|(r, _)| r.is_clean());
    let segs = |r: &CaptureReport, h: &Option<SessionHeader>| {
        h.as_ref().map_or_else(Vec::new, |h| segments_of(r, h))
    };
    let (report, header) = all.remove(0);
    let segments = segs(&report, &header);
    let mut per_session = vec![SessionInfo {
        header,
        report: report.clone(),
        segments: segments.clone(),
    }];
    per_session.extend(all.into_iter().map(|(report, header)| SessionInfo {
        segments: segs(&report, &header),
        header,
        report,
    }));
    let summary = InfoSummary {
        file: args.input.display().to_string(),
        header,
        report,
        segments,
        per_session,
    };
    if ctx.json {
        print_json(ctx.out, "info", &summary)?;
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
    if s.per_session.len() > 1 {
        out.push_str(&format!("{} sessions\n", s.per_session.len()));
        for (i, p) in s.per_session.iter().enumerate() {
            let id = p
                .report
                .session_id
                .map_or_else(|| "-".to_string(), |id| id.to_string());
            out.push_str(&format!(
                "\n== session {id} ({} of {})\n",
                i + 1,
                s.per_session.len()
            ));
            describe_session(&mut out, p.header.as_ref(), &p.report, &p.segments);
        }
        return out;
    }
    describe_session(&mut out, s.header.as_ref(), &s.report, &s.segments);
    out
}

fn describe_session(
    out: &mut String,
    header: Option<&SessionHeader>,
    report: &CaptureReport,
    segments: &[SegmentInfo],
) {
    match header {
        None => out.push_str("no session header: counts cannot be scaled to SI\n"),
        Some(h) => {
            let x = &h.excitation;
            let duration =
                report.last_seq.map_or(0.0, |l| f64::from(l) + 1.0) / f64::from(h.sample_rate_hz);
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
    out.push_str(&report.to_string());
    if !segments.is_empty() {
        out.push_str(&format!(
            "\nsegments         {} gap-free (--segment N of analyze, fit, validate, diagnose)\n",
            segments.len()
        ));
        for g in segments {
            out.push_str(&format!(
                "  {:>3}  from {} s, {} s, {} samples, {} whole periods\n",
                g.index,
                fmt_sig(g.start_s, 6),
                fmt_sig(g.length_s, 6),
                g.samples,
                g.whole_periods.unwrap_or(0)
            ));
        }
    }
    out.push('\n');
}
